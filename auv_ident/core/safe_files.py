"""Files the package writes at run time, written so that another user of the machine cannot
redirect or plant them.

Two rules:

- :func:`write_atomic`: a file is written to a fresh temporary name made with ``mkstemp``
  (O_CREAT | O_EXCL: it never opens what someone else created or linked there), then renamed
  over the target in one step, so a reader sees the old file or the new one, never half of
  one, and a symlink planted at a predictable temporary name redirects nothing.
- :func:`private_folder` / :func:`private_dir`: what the package keeps between runs (vehicle
  files sent to campaign workers, generated model kernels, numba's cache) lives in a folder of
  the user's own ($AUV_IDENT_CACHE, else ~/.cache/auv_ident, else <temp>/auv_ident-<uid>),
  created 0700 and checked before use: owned by this user, not a symlink, writable by no one
  else. A folder under a shared /tmp whose name anyone can guess is refused when it fails the
  check, never trusted.
"""
from collections.abc import Iterator
import os
from pathlib import Path
import stat
import tempfile

from auv_ident.core.errors import ConfigError

CACHE_ENV = 'AUV_IDENT_CACHE'      # the first place private folders are made


def _umask() -> int:
    """The process's umask, read without changing it (os.umask would, for every thread)."""
    try:
        with open('/proc/self/status', encoding='ascii') as fh:
            for line in fh:
                if line.startswith('Umask:'):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    return 0o022


def write_atomic(path: str | os.PathLike[str], data: str | bytes, mode: int | None = None) -> Path:
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


def unwritable_reason(path: str | os.PathLike[str], folder: bool = False) -> str | None:
    """Why :func:`write_atomic` could not write `path` (folder: a folder to be created with its
    parents, e.g. a report's), or None. Checked when the settings enter, so that a missing or
    read-only folder is said at start-up, not after an hour of work (or at a mission's end)."""
    path = Path(os.path.abspath(path))
    if path.is_dir() and not folder:
        return 'is a folder, not a file'
    parent = path.parent
    if folder:                      # makedirs creates the missing ones: the first that exists
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
    elif not parent.exists():
        return f'its folder {parent} does not exist'
    if not parent.is_dir():
        return f'{parent} is not a folder'
    # write_atomic makes a file in the folder and renames it: write and search permission
    if not os.access(parent, os.W_OK | os.X_OK):
        return f'its folder {parent} is not writable by this user'
    return None


def ensure_content(path: str | os.PathLike, text: str, mode: int | None = None) -> Path:
    """`path` holding `text`: left as it is when it already does (read as UTF-8), else written
    with :func:`write_atomic` (a file changed behind our back, or unreadable, is written
    again). Returns the path."""
    path = Path(path)
    try:
        if path.read_text(encoding='utf-8') == text:
            return path
    except (OSError, UnicodeDecodeError):
        pass                # absent or unreadable: written below
    return write_atomic(path, text, mode)


def _unsafe(path: str) -> str | None:
    """Why `path` is no private folder of this user's (None if it is one)."""
    st = os.lstat(path)
    if stat.S_ISLNK(st.st_mode):
        return 'a symbolic link'
    if not stat.S_ISDIR(st.st_mode):
        return 'not a folder'
    if st.st_uid != os.geteuid():
        return f'owned by another user (uid {st.st_uid})'
    if st.st_mode & 0o022:
        return f'writable by other users (mode {stat.S_IMODE(st.st_mode):o})'
    return None


def private_candidates(name: str) -> Iterator[str]:
    """The places of the private folder `name`, best first: $AUV_IDENT_CACHE/name if set, the
    user's cache folder ($XDG_CACHE_HOME or ~/.cache)/auv_ident/name, then
    <temp>/auv_ident-<uid>/name."""
    env = os.environ.get(CACHE_ENV, '').strip()
    if env:
        yield os.path.join(env, name)
    xdg = os.environ.get('XDG_CACHE_HOME', '')
    cache = xdg if os.path.isabs(xdg) else os.path.join(os.path.expanduser('~'), '.cache')
    yield os.path.join(cache, 'auv_ident', name)
    yield os.path.join(tempfile.gettempdir(), f'auv_ident-{os.geteuid()}', name)


def make_private(path: str, parent: bool = True) -> None:
    """Create the folder `path` (and its parent, with `parent`) with mode 0700 where missing,
    and check that it (and its parent) is a folder of this user's, no symbolic link, writable
    by no one else; PermissionError naming it and why if not (OSError if it cannot be made)."""
    for p in (os.path.dirname(path), path) if parent else (path,):
        os.makedirs(p, mode=0o700, exist_ok=True)
        why = _unsafe(p)
        if why is not None:
            raise PermissionError(f'{p} is {why}')


def private_folder(name: str, tried: list[str] | None = None) -> str | None:
    """The first usable private folder `name` of :func:`private_candidates` (made if missing),
    or None; the refused places, with why, are appended to `tried`."""
    for path in private_candidates(name):
        try:
            make_private(path)
            return path
        except OSError as err:
            if tried is not None:
                tried.append(f'{path} ({err.strerror or err})')
    return None


def private_dir(name: str, *parts: str) -> Path:
    """A private folder for what the package keeps between runs: :func:`private_folder`
    `name`, then the sub-folders `parts`, each made 0700 and checked; ConfigError naming every
    place tried when none is usable."""
    for part in (name, *parts):
        if part in ('', '.', '..') or '/' in part or os.sep in part:
            raise ConfigError(f'private folder name {part!r}: one plain name expected')
    tried: list[str] = []
    folder = private_folder(name, tried)
    if folder is None:
        raise ConfigError(f'no usable private folder for {name!r} (tried: {"; ".join(tried)}); '
                          f'set {CACHE_ENV} to a folder of your own')
    for part in parts:
        folder = os.path.join(folder, part)
        try:
            make_private(folder, parent=False)
        except OSError as err:
            raise ConfigError(f'{folder}: not usable as a private folder '
                              f'({err.strerror or err})') from err
    return Path(folder)
