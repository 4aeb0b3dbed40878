"""Tier 1: the generated monomial kernel against a plain reading of the vehicle's term table,
and its file cache."""
import os

import numpy as np
import pytest

from auv_ident.core.errors import ConfigError
from auv_ident.core.model import monomials
from auv_ident.core.model.monomials import kernel_source, monomial_kernel, NZ
from auv_ident.core.safe_files import make_private
from auv_ident.vehicles import available_vehicles, load_vehicle


def _factors(rng):
    """zz = [z, dz/dx, dU/dv] as the model builds it: dz/dx is 1 for u..r, sign for |u|..|r|,
    0 for the fins and their sums and the thrust, the propeller's d eps/du for eps, and u/U
    (v/U last) for the speed U."""
    x = rng.uniform(-2.0, 2.0, 6)
    fins = rng.uniform(-0.3, 0.3, 5)
    U = np.hypot(x[0], x[1])
    z = np.concatenate([x, np.abs(x), fins, [fins[3] + fins[4]], [rng.uniform(-1.0, 1.0)],
                        [U, rng.uniform(10.0, 50.0)]])
    dz = np.concatenate([np.ones(6), np.sign(x), np.zeros(6), [rng.uniform(-3.0, 3.0)],
                         [x[0] / U, 0.0]])
    return np.concatenate([z, dz, [x[1] / U]])


def _by_the_table(v, c, zz):
    """F's monomial part, dF/dx and dF/dc read term by term from the table, in Python."""
    z, dz = zz[:NZ], zz[NZ:2 * NZ]
    xdot, A, dprod = np.zeros(12), np.zeros((12, 12)), np.zeros(len(c))
    for (eq, ci, *fs), s in zip(v.terms_i, v.terms_s):
        fs = [f for f in fs if f >= 0]
        k = s * (c[ci] if ci >= 0 else 1.0)
        xdot[eq] += k * np.prod(z[fs])
        for j, f in enumerate(fs):
            rest = k * np.prod(np.delete(z[fs], j))
            if f == monomials.Z_SPEED:          # U = sqrt(u^2 + v^2): columns u and v
                A[eq, 0] += rest * dz[f]
                A[eq, 1] += rest * zz[monomials.ZZ_DU_DV]
            elif f < monomials.Z_EPS or f == monomials.Z_EPS:
                A[eq, f % 6] += rest * dz[f]
        if ci >= 0:
            dprod[ci] = s * np.prod(z[fs])
    return xdot, A, dprod


@pytest.mark.parametrize('name', available_vehicles())
def test_kernel_equals_the_term_table(name):
    v = load_vehicle(name)
    kernel = monomial_kernel(v.terms_i, v.terms_s)
    rng = np.random.default_rng(7)
    for _ in range(5):
        c = v.values * rng.uniform(0.5, 1.5, len(v.values))
        zz = _factors(rng)
        want = _by_the_table(v, c, zz)
        xdot, A, dprod = rng.standard_normal(12), rng.standard_normal((12, 12)), np.zeros(len(c))
        start = xdot.copy(), A.copy()
        kernel(c, zz, True, xdot, A, dprod)
        assert np.allclose(xdot - start[0], want[0], rtol=1e-12,
                           atol=1e-12 * np.abs(want[0]).max())
        assert np.allclose(A - start[1], want[1], rtol=1e-9, atol=1e-12 * np.abs(want[1]).max())
        has_term = v.terms_i[v.terms_i[:, 1] >= 0, 1]
        assert np.allclose(dprod[has_term], want[2][has_term], rtol=1e-12, atol=0.0)
        assert np.array_equal(A[6:] - start[1][6:], np.zeros((6, 12)))   # kinematics rows
        x_only, A_only = start[0].copy(), start[1].copy()
        kernel(c, zz, False, x_only, A_only, np.zeros(len(c)))
        assert np.array_equal(x_only, xdot) and np.array_equal(A_only, start[1])


def test_kernel_is_built_once_per_table_and_loaded_from_its_file(tmp_path, monkeypatch):
    v = load_vehicle('isimi')
    monkeypatch.setenv('AUV_IDENT_KERNEL_CACHE', str(tmp_path))
    monkeypatch.setattr(monomials, '_loaded', {})
    first = monomial_kernel(v.terms_i, v.terms_s)
    assert monomial_kernel(v.terms_i, v.terms_s) is first
    files = list(tmp_path.glob('auv_ident_monomials_*.py'))
    assert len(files) == 1 and kernel_source(v.terms_i, v.terms_s) in files[0].read_text()
    assert not list(tmp_path.glob('*.tmp'))          # written through a temporary file


def test_generated_kernels_go_to_a_private_folder_of_the_user(tmp_path, monkeypatch):
    """By default the kernels go to the user's cache folder, made 0700, never into the
    package; a folder that is a symbolic link or writable by others is refused."""
    monkeypatch.delenv('AUV_IDENT_KERNEL_CACHE', raising=False)
    monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path / 'cache'))
    path = monomials._write_source('k', 'x = 1\n')
    folder = tmp_path / 'cache' / 'auv_ident' / 'kernels'
    assert path == str(folder / 'k.py')
    assert folder.stat().st_mode & 0o777 == 0o700
    assert folder.parent.stat().st_mode & 0o777 == 0o700
    package = os.path.dirname(os.path.dirname(os.path.abspath(monomials.__file__)))
    assert all(not d.startswith(package) for d in monomials._cache_dirs())
    for bad, why in (('link', 'a symbolic link'), ('open', 'writable by other users')):
        root = tmp_path / bad / 'auv_ident'
        root.parent.mkdir()
        if bad == 'link':
            root.symlink_to(folder.parent)
        else:
            root.mkdir()
            os.chmod(root, 0o777)
        with pytest.raises(PermissionError, match=why):
            make_private(str(root / 'kernels'))


def test_unwritable_cache_folders_fall_back_then_fail_clearly(tmp_path, monkeypatch):
    blocked = tmp_path / 'file'
    blocked.write_text('not a folder')
    monkeypatch.setattr(monomials, '_cache_dirs',
                        lambda: iter([str(blocked / 'a'), str(tmp_path / 'ok')]))
    path = monomials._write_source('k', 'x = 1\n')
    assert path == str(tmp_path / 'ok' / 'k.py')
    monkeypatch.setattr(monomials, '_cache_dirs', lambda: iter([str(blocked / 'a')]))
    with pytest.raises(ConfigError, match='AUV_IDENT_KERNEL_CACHE'):
        monomials._write_source('k', 'x = 1\n')


def test_a_coefficient_with_two_terms_is_refused():
    v = load_vehicle('nps_auv2')
    ti = v.terms_i.copy()
    ti[1, 1] = ti[0, 1]
    with pytest.raises(ConfigError, match='more than one term'):
        kernel_source(ti, v.terms_s)


def test_a_non_finite_scale_is_refused_not_written_as_inf():
    """A term table built without the vehicle file's checks (#27 item 6: numba's "name 'inf'
    is not defined" from generated code)."""
    v = load_vehicle('nps_auv2')
    ts = v.terms_s.copy()
    ts[3] = np.inf
    with pytest.raises(ConfigError, match=r'term 3 of the term table has the scale inf'):
        kernel_source(v.terms_i, ts)
