"""Files the package writes at run time, written so that another user of the machine cannot
redirect or plant them.

Two rules:

- :func:`write_atomic`: a file is written to a fresh temporary name made with ``mkstemp``
  (O_CREAT | O_EXCL: it never opens what someone else created or linked there), then renamed
  over the target in one step, so a reader sees the old file or the new one, never half of
  one, and a symlink planted at a predictable temporary name redirects nothing.
- :func:`private_dir`: what the package keeps between runs (vehicle files sent to campaign
  workers, compiled kernels) lives in a folder of the user's own, created 0700 and checked
  before use: owned by this user, not a symlink, no access for others. A folder under a shared
  /tmp whose name anyone can guess is refused when it fails the check, never trusted.
"""
import os
from pathlib import Path
import stat
import tempfile

from auv_ident.core.errors import ConfigError

CACHE_ENV = 'AUV_IDENT_CACHE'      # overrides where private_dir's folders are


def _umask():
    """The process's umask, read without changing it (os.umask would, for every thread)."""
    try:
        with open('/proc/self/status', encoding='ascii') as fh:
            for line in fh:
                if line.startswith('Umask:'):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    return 0o022


def write_atomic(path, data, mode=None):
    """Write `data` (str: UTF-8 text, or bytes) to `path` through a fresh temporary file in the
    same folder and one rename. mode: the file's permissions (default 0o666 less the umask,
    what a plain open() gives). Returns the path. OSError as the system gives it."""
    path = Path(path)
    raw = data.encode('utf-8') if isinstance(data, str) else bytes(data)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f'.{path.name}.', suffix='.tmp')
    try:
        with os.fdopen(fd, 'wb') as fh:
            fh.write(raw)
            os.fchmod(fh.fileno(), 0o666 & ~_umask() if mode is None else mode)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return path


def _cache_root():
    env = os.environ.get(CACHE_ENV, '').strip()
    if env:
        return Path(env)
    xdg = os.environ.get('XDG_CACHE_HOME', '').strip()
    home = Path(xdg) if xdg else Path.home() / '.cache'
    return home / 'auv_ident'


def check_private(folder):
    """ConfigError naming `folder` unless it is a real folder (not a symlink) owned by this
    user with no permissions for group or others."""
    folder = Path(folder)
    try:
        st = os.lstat(folder)
    except OSError as err:
        raise ConfigError(f'{folder}: cannot use it as a private folder ({err.strerror})'
                          ) from err
    if stat.S_ISLNK(st.st_mode) or not stat.S_ISDIR(st.st_mode):
        raise ConfigError(f'{folder}: not a folder of its own (a symlink or a file); '
                          'refusing to use it: remove it')
    if st.st_uid != os.geteuid():
        raise ConfigError(f'{folder}: owned by user id {st.st_uid}, not by this user '
                          f'({os.geteuid()}); refusing to use what another user made')
    if st.st_mode & 0o077:
        raise ConfigError(f'{folder}: permissions {stat.S_IMODE(st.st_mode):o} let others in '
                          '(0700 expected); refusing to use it: chmod 700 it or remove it')
    return folder


def private_dir(*parts):
    """A folder of this user's own for what the package keeps between runs:
    $AUV_IDENT_CACHE, else $XDG_CACHE_HOME/auv_ident, else ~/.cache/auv_ident, then `parts`.
    Every level from the root down is created 0700 if absent and checked (check_private);
    ConfigError naming the folder if it cannot be made or fails the check."""
    folder = _cache_root()
    for part in ('',) + tuple(parts):
        if part:
            if part in ('.', '..') or '/' in part or os.sep in part:
                raise ConfigError(f'private folder name {part!r}: one plain name expected')
            folder = folder / part
        try:
            folder.mkdir(mode=0o700, parents=not part, exist_ok=True)
        except OSError as err:
            raise ConfigError(f'{folder}: cannot create a private folder ({err.strerror}); '
                              f'set {CACHE_ENV} to a folder of your own') from err
        check_private(folder)
    return folder
