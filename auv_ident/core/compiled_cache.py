"""numba's on-disk cache of the core, keyed on a group of source files together, through numba's
documented cache folder setting only (NUMBA_CACHE_DIR, read by numba as numba.config.CACHE_DIR).

numba (0.68) stamps a function it caches with the hash of the function's own source file. But
a compiled function keeps the code of what it calls from other files (ekf.run_filter inlines
hydrodynamics.py's kernels, and those freeze vehicle.py's constants): after an edit of
hydrodynamics.py alone, a cached run_filter would go on running the old model.

:func:`register` names a group of files; :func:`cached_njit` is ``numba.njit(cache=True)`` for
the functions of those files, with numba.config.CACHE_DIR pointed, while numba sets up the
function's cache, at a folder named after the digest of all the group's files
(:func:`group_folder`). An edit of any file of the group gives a new folder, where nothing is
cached yet, and numba compiles the whole group afresh on first use. The setting is restored
right after, so numba code of other packages in the process keeps numba's own cache places.

The group folders live in NUMBA_CACHE_DIR if the user set it, else in a private folder of the
user's (core/safe_files.py :func:`private_folder`: ``$XDG_CACHE_HOME/auv_ident/numba`` or
``~/.cache/auv_ident/numba``), never beside the package's files. A folder of the package's own
that no process has used for PRUNE_DAYS days is deleted when a new one is made. If no folder
is usable, the group is compiled without a cache (correct, only slower to start).
"""
from collections.abc import Callable, Sequence
import hashlib
import inspect
import os
import re
import shutil
import time
from typing import Any, TypeVar
import warnings

import numba

from auv_ident.core.errors import ConfigError
from auv_ident.core.safe_files import make_private, private_folder

PRUNE_DAYS = 30
_GROUP_NAME = re.compile(r'^auv_ident-[0-9a-f]{20}$')
_GROUPS: dict[str, tuple[str, ...]] = {}   # absolute root folder -> the group's files in it
_FOLDERS: dict[str, str | None] = {}       # root folder -> its group folder (None: no cache)

F = TypeVar('F', bound=Callable[..., Any])


def register(folder: str, sources: Sequence[str]) -> None:
    """Name a group: the files `sources` (paths relative to `folder`, '/' separated), whose
    functions are compiled with :func:`cached_njit` (module docstring)."""
    root = os.path.abspath(folder)
    _GROUPS[root] = tuple(sources)
    _FOLDERS.pop(root, None)


def group_digest(folder: str, sources: Sequence[str]) -> str:
    """sha256 (hex) of the files `sources` (paths relative to `folder`), each with its path and
    length."""
    h = hashlib.sha256()
    for name in sources:
        with open(os.path.join(folder, name), 'rb') as f:
            data = f.read()
        h.update(f'{name}\0{len(data)}\0'.encode())
        h.update(data)
    return h.hexdigest()


def group_folder(base: str, folder: str, sources: Sequence[str]) -> str:
    """The cache folder, below `base`, of the group `sources` in `folder` as they are now."""
    return os.path.join(base, 'auv_ident-' + group_digest(folder, sources)[:20])


def _prune(base: str, keep: str) -> None:
    """Delete the package's group folders in `base` other than `keep` that no process has
    used for PRUNE_DAYS days (each use touches its folder)."""
    limit = time.time() - PRUNE_DAYS * 86400.0
    try:
        names = os.listdir(base)
    except OSError:
        return
    for name in names:
        path = os.path.join(base, name)
        if name == os.path.basename(keep) or not _GROUP_NAME.match(name):
            continue
        try:
            old = os.lstat(path).st_mtime < limit
        except OSError:
            continue
        if old:
            shutil.rmtree(path, ignore_errors=True)


def _folder_of(root: str) -> str | None:
    """The group folder of the group registered at `root`, made (and touched) once a process;
    None if no cache folder is usable."""
    if root in _FOLDERS:
        return _FOLDERS[root]
    tried: list[str] = []
    user_dir = numba.config.CACHE_DIR
    base = user_dir or private_folder('numba', tried)
    path = None
    if base:
        path = group_folder(base, root, _GROUPS[root])
        try:
            if user_dir:
                os.makedirs(path, exist_ok=True)
            else:
                make_private(path)
            os.utime(path)
            _prune(base, path)
        except OSError as err:
            tried.append(f'{path} ({err.strerror or err})')
            path = None
    if path is None:
        warnings.warn("auv_ident: no usable folder for numba's cache, compiling without it "
                      '(tried: ' + ', '.join(tried) + ')', RuntimeWarning, stacklevel=3)
    _FOLDERS[root] = path
    return path


def cache_folder_of(py_file: str) -> str | None:
    """The cache folder of the functions of `py_file` (a file of a registered group)."""
    path = os.path.abspath(py_file)
    for root, sources in _GROUPS.items():
        if os.path.relpath(path, root).replace(os.sep, '/') in sources:
            return _folder_of(root)
    raise ConfigError(f'{py_file} is in no registered group of compiled sources '
                      '(auv_ident.core.compiled_cache.register)')


def cached_njit(**options: Any) -> Callable[[F], F]:
    """``numba.njit(cache=True, **options)`` for a function of a registered group: its cache in
    the group's folder (module docstring)."""
    def decorate(py_func: F) -> F:
        folder = cache_folder_of(inspect.getfile(py_func))
        if folder is None:
            return numba.njit(**options)(py_func)
        saved = numba.config.CACHE_DIR
        numba.config.CACHE_DIR = folder
        try:
            return numba.njit(cache=True, **options)(py_func)
        finally:
            numba.config.CACHE_DIR = saved
    return decorate
