"""The ROS-free core: vehicle data, model, integrators, EKF, noise adaptation, identification."""
import hashlib
import os

# Files holding numba functions compiled with cache=True (paths inside the package).
_COMPILED_SOURCES = ('core/model.py', 'core/ekf.py', 'analysis/bench.py')
_STAMP = 'numba_sources.sha256'


def _drop_stale_compiled_code(pkg=None):
    """Key numba's on-disk cache on all compiled sources together.

    numba checks a cached function against its own file only, but a compiled function keeps
    the code of what it calls from other files (ekf.run_filter inlines model.py's kernel): after
    an edit of model.py a cached run_filter would go on running the old model. So when any of
    these sources changed, every cached entry of them is dropped and numba recompiles on first
    use. A read-only install is left alone (there the files only change on reinstall, which
    renews every file's time stamp, and numba's own check catches that).
    """
    if pkg is None:   # the auv_ident package folder
        pkg = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    h = hashlib.sha256()
    for rel in _COMPILED_SOURCES:
        try:
            with open(os.path.join(pkg, rel), 'rb') as f:
                h.update(f.read())
        except OSError:
            return
    digest = h.hexdigest()
    stamp = os.path.join(pkg, 'core', '__pycache__', _STAMP)
    try:
        with open(stamp) as f:
            if f.read().strip() == digest:
                return
    except OSError:
        pass
    try:
        for rel in _COMPILED_SOURCES:
            cache = os.path.join(pkg, os.path.dirname(rel), '__pycache__')
            if os.path.isdir(cache):
                for name in os.listdir(cache):
                    if name.endswith(('.nbi', '.nbc')):
                        os.remove(os.path.join(cache, name))
        os.makedirs(os.path.dirname(stamp), exist_ok=True)
        with open(stamp, 'w') as f:
            f.write(digest + '\n')
    except OSError:
        pass


_drop_stale_compiled_code()
