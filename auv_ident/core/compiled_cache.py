"""numba's on-disk cache keyed on a group of source files together, not on each file alone.

numba (0.68) stamps a function it caches with the hash of the function's own source file. But
a compiled function keeps the code of what it calls from other files (ekf.run_filter inlines
model.py's kernels, and model.py's kernels freeze vehicle.py's constants): after an edit of
model.py alone, a cached run_filter would go on running the old model.

:func:`register` names a group of files; every function numba caches from one of them gets
as its source stamp the digest of all of them (:class:`GroupStampLocator`). An edit of any file
of the group makes the cached code of the whole group stale, and numba recompiles it on first
use; stale entries are overwritten by numba as usual (nothing is deleted here). Where the cache
lives stays numba's choice (NUMBA_CACHE_DIR, else ``__pycache__`` beside the file, else the
user's cache folder). numba's NUMBA_CACHE_LOCATOR_CLASSES setting, if used, replaces this.
"""
import hashlib
import os

from numba.core import caching

_GROUPS = {}        # absolute root folder -> paths of the group's files, relative to it


def register(folder, sources):
    """Key numba's cache of every function in `sources` (paths relative to `folder`, '/'
    separated) on the digest of all of them (module docstring)."""
    _GROUPS[os.path.abspath(folder)] = tuple(sources)
    if GroupStampLocator not in caching.CacheImpl._locator_classes:
        caching.CacheImpl._locator_classes.insert(0, GroupStampLocator)


def group_digest(folder, sources):
    """sha256 (hex) of the files `sources` (paths relative to `folder`), each with its path and
    length."""
    h = hashlib.sha256()
    for name in sources:
        with open(os.path.join(folder, name), 'rb') as f:
            data = f.read()
        h.update(f'{name}\0{len(data)}\0'.encode())
        h.update(data)
    return h.hexdigest()


class GroupStampLocator(caching._CacheLocator):
    """numba cache locator for the functions of a registered group of files: numba's own
    locator decides the folder, the stamp is the group's digest."""

    _numba_locators = (caching.UserProvidedCacheLocator, caching.InTreeCacheLocator,
                       caching.UserWideCacheLocator)

    def __init__(self, base, stamp):
        self._base = base
        self._stamp = stamp

    def ensure_cache_path(self):
        self._base.ensure_cache_path()

    def get_cache_path(self):
        return self._base.get_cache_path()

    def get_disambiguator(self):
        return self._base.get_disambiguator()

    def get_source_stamp(self):
        return self._stamp

    @classmethod
    def from_function(cls, py_func, py_file):
        path = os.path.abspath(py_file)
        for folder, sources in _GROUPS.items():
            name = os.path.relpath(path, folder).replace(os.sep, '/')
            if name in sources:
                break
        else:
            return None           # not ours: numba's next locator takes it
        try:
            stamp = group_digest(folder, sources)
        except OSError:
            return None
        for locator in cls._numba_locators:
            base = locator.from_function(py_func, py_file)
            if base is not None:
                return cls(base, stamp)
        return None
