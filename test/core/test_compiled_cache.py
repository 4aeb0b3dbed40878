"""Tier 1: where the compiled code goes. numba's cache of the core and the generated model
kernels live in private folders of the user's, keyed on what they were compiled from; no file of
the package is written at run time. (The group key itself: test_ekf.py.)"""
import importlib
import os
import pathlib
import shutil
import stat
import subprocess
import sys
import time

import numba
import pytest

import auv_ident.core as core
from auv_ident.core import compiled_cache, safe_files

REPO = pathlib.Path(core.__file__).parents[2]
_TINY = ('from auv_ident.core.compiled_cache import cached_njit\n\n\n'
         '@cached_njit()\ndef f(x):\n    return x + 1\n')


def test_old_group_folders_of_the_package_are_pruned(tmp_path, monkeypatch):
    """A new group folder deletes the package's group folders unused for PRUNE_DAYS days, and
    nothing else in the cache folder."""
    base = tmp_path / 'numba'
    old, recent, other = (base / ('auv_ident-' + '0' * 20), base / ('auv_ident-' + '1' * 20),
                          base / 'someone-elses')
    for d in (old, recent, other):
        d.mkdir(parents=True)
    long_ago = time.time() - (compiled_cache.PRUNE_DAYS + 1) * 86400.0
    for d in (old, other):
        os.utime(d, (long_ago, long_ago))
    group = tmp_path / 'src'
    group.mkdir()
    (group / 'tiny.py').write_text(_TINY)
    monkeypatch.setattr(numba.config, 'CACHE_DIR', str(base))
    compiled_cache.register(str(group), ('tiny.py',))
    made = pathlib.Path(compiled_cache.cache_folder_of(str(group / 'tiny.py')))
    assert made.parent == base and made.is_dir()
    assert sorted(p.name for p in base.iterdir()) == sorted([made.name, recent.name, other.name])


def test_without_a_usable_cache_folder_the_group_is_compiled_without_cache(tmp_path,
                                                                            monkeypatch):
    """No private folder can be made (here: each place is a file): a warning names the places
    tried, the function still compiles and runs, and nothing is written beside it."""
    blocked = tmp_path / 'file'
    blocked.write_text('')
    monkeypatch.setattr(numba.config, 'CACHE_DIR', '')
    monkeypatch.setattr(safe_files, 'private_candidates',
                        lambda name: iter([str(blocked / name)]))
    pkg = tmp_path / 'nocache_pkg'
    pkg.mkdir()
    (pkg / 'tiny.py').write_text(_TINY)
    compiled_cache.register(str(pkg), ('tiny.py',))
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.warns(RuntimeWarning, match='no usable folder for numba.s cache.*file/numba'):
        f = importlib.import_module('nocache_pkg.tiny').f
    assert f(1) == 2
    assert sorted(p.name for p in pkg.iterdir()) in (['tiny.py'], ['__pycache__', 'tiny.py'])
    assert not list(pkg.rglob('*.nb[ic]'))


def test_the_cache_folders_are_outside_the_package():
    from auv_ident.core.filter import ekf
    from auv_ident.core.model import monomials
    package = REPO / 'auv_ident'
    assert not pathlib.Path(compiled_cache.cache_folder_of(ekf.__file__)).is_relative_to(package)
    assert all(not pathlib.Path(d).is_relative_to(package) for d in monomials._cache_dirs())


_RUN = """
from auv_ident.core.filter.augmented import AugmentedEKF, FilterConfig
from auv_ident.core.identification.batch import run_ekf
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.simulation.simulate import simulate
from auv_ident.vehicles import load_vehicle
v = load_vehicle('isimi')
names = list(v.identify_default)
run = simulate(Model(v), 'ident', duration=2.0, seed=1)
run_ekf(AugmentedEKF(Model(v, names), FilterConfig(coefficients=names), run.T),
        run.t, run.y, run.u)
"""


def _tree(root):
    return {p.relative_to(root).as_posix(): (p.stat().st_mode, p.stat().st_mtime_ns)
            for p in [root, *root.rglob('*')]}


@pytest.mark.slow      # compiles the core and a vehicle's kernel from cold caches (about 1 min)
def test_no_file_of_the_package_is_written_at_run_time(tmp_path):
    """A read-only copy of the package and its vehicle files, fresh caches: a vehicle's model
    kernel is generated and compiled, the EKF compiled and run; the copy is unchanged (not a
    file added, removed or touched), and the compiled code went to the user's cache folder."""
    copy = tmp_path / 'install'
    shutil.copytree(REPO / 'auv_ident', copy / 'auv_ident',
                    ignore=shutil.ignore_patterns('__pycache__'))
    shutil.copytree(REPO / 'config', copy / 'config')
    for p in [copy, *copy.rglob('*')]:
        os.chmod(p, stat.S_IMODE(p.stat().st_mode) & ~0o222)
    before = _tree(copy)
    env = {k: v for k, v in os.environ.items()
           if k not in ('NUMBA_CACHE_DIR', 'AUV_IDENT_KERNEL_CACHE', 'PYTHONPATH')}
    env.update(PYTHONPATH=str(copy), XDG_CACHE_HOME=str(tmp_path / 'cache'),
               PYTHONDONTWRITEBYTECODE='1')
    try:
        r = subprocess.run([sys.executable, '-c', _RUN], capture_output=True, text=True,
                           env=env, cwd=tmp_path, timeout=900)
        assert r.returncode == 0, r.stderr
        assert _tree(copy) == before
    finally:
        for p in [copy, *copy.rglob('*')]:
            os.chmod(p, stat.S_IMODE(p.stat().st_mode) | 0o200)
    cache = tmp_path / 'cache' / 'auv_ident'
    assert list((cache / 'kernels').glob('auv_ident_monomials_*.py'))
    assert list((cache / 'numba').rglob('ekf.run_filter-*.nbi'))
