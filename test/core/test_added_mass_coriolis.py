"""`added_mass_coriolis: fossen` (docs/vehicles.md): the model computes the Coriolis and
centripetal forces of the added mass, -C_A(nu) nu (Fossen 2021, eq. 6.43; eq. 6.51 for a
diagonal M_A), from the file's added-mass coefficients, so that they follow an identified
added mass; their derivatives by the states and by the added-mass coefficients are analytic.
A file without the key is the model it was."""
import re

import numpy as np
import pytest
from rov_munk import ADDED_MASS, fixed_munk_file

from auv_ident.core.errors import ConfigError
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.vehicle import vehicle_from_file
from auv_ident.vehicles import load_vehicle


def _states(rng, n, n_thrusters):
    for _ in range(n):
        x = np.concatenate([rng.normal(0, 0.4, 6), rng.normal(0, 1, 3), rng.normal(0, 0.3, 3)])
        ui = np.concatenate([np.zeros(7), rng.uniform(1100.0, 1900.0, n_thrusters)])
        yield x, ui


def test_the_bluerov2s_added_mass_coriolis_follows_its_added_mass(tmp_path):
    """The shipped file (the key) against the file written with fixed terms X_vr .. N_pq of the
    same added mass: equal at the file's added mass and at an identified one (the fixed terms
    then rewritten for it, as the key does by itself)."""
    v = load_vehicle('bluerov2_heavy')
    assert v.ca_i.shape[0] > 0
    rng = np.random.default_rng(5)
    other = {n: v.values[v.index(n)] * f
             for n, f in zip(ADDED_MASS, (1.07, 0.93, 1.04, 1.2, 0.8, 1.1))}
    for added in (None, other):
        fixed = Model(vehicle_from_file(str(fixed_munk_file(tmp_path / 'f.yaml', added))))
        theta = ([v.values[v.index(n)] for n in ADDED_MASS] if added is None
                 else [added[n] for n in ADDED_MASS])
        ours = Model(v, ADDED_MASS)
        for x, ui in _states(rng, 5, 8):
            want = fixed.f(x, ui)
            got = ours.f(x, ui, theta)
            assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max(), (added, got - want)
        (tmp_path / 'f.yaml').unlink()
    # and the file's fixed terms at its own added mass differ from an identified one's
    stale = Model(vehicle_from_file(str(fixed_munk_file(tmp_path / 's.yaml'))), ADDED_MASS)
    x = np.array([0.3, 0.2, -0.2, 0.3, -0.2, 0.4, 0, 0, 0, 0, 0, 0])
    ui = np.concatenate([np.zeros(7), np.full(8, 1500.0)])
    theta = [other[n] for n in ADDED_MASS]
    assert np.abs(stale.f(x, ui, theta) - Model(v, ADDED_MASS).f(x, ui, theta)).max() > 1e-3


# a dimensional test vehicle with off-diagonal added mass (Y_rdot = N_vdot, Z_qdot = M_wdot):
# Fossen's eq. 6.43 in general, not only the diagonal eq. 6.51
COUPLED = """
name: coupled_added_mass
scaling: dimensional
rho: 1000.0
L: 1.0
mass: 20.0
W: 196.2
B: 196.2
r_G: [0.0, 0.0, 0.02]
r_B: [0.0, 0.0, 0.0]
inertia: {{Ix: 0.3, Iy: 1.2, Iz: 1.3}}
limits: {{fin_rad: 0.1, n_rpm: 1.0}}
mass_inverse: exact
{key}
coefficients:
  X_udot: [-1.5, X, 0, udot]
  Y_vdot: [-18.0, Y, 0, vdot]
  Z_wdot: [-17.0, Z, 0, wdot]
  K_pdot: [-0.05, K, 0, pdot]
  M_qdot: [-1.1, M, 0, qdot]
  N_rdot: [-1.0, N, 0, rdot]
  Y_rdot: [1.3, Y, 0, rdot]
  N_vdot: [1.3, N, 0, vdot]
  Z_qdot: [-1.2, Z, 0, qdot]
  M_wdot: [-1.2, M, 0, wdot]
  X_u: [-4.0, X, 0, u]
  Y_v: [-30.0, Y, 0, v]
  Z_w: [-30.0, Z, 0, w]
  M_q: [-3.0, M, 0, q]
  N_r: [-3.0, N, 0, r]
"""
COUPLED_AM = ('X_udot', 'Y_vdot', 'Z_wdot', 'K_pdot', 'M_qdot', 'N_rdot', 'Y_rdot', 'N_vdot',
              'Z_qdot', 'M_wdot')


def _skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def _fossen_C_A(M_A, nu):
    """Fossen 2021, eq. 6.43: C_A = [[0, -S(A11 v + A12 w)], [-S(A11 v + A12 w),
    -S(A21 v + A22 w)]] for a symmetric M_A."""
    a1 = M_A[:3, :3] @ nu[:3] + M_A[:3, 3:] @ nu[3:]
    a2 = M_A[3:, :3] @ nu[:3] + M_A[3:, 3:] @ nu[3:]
    C = np.zeros((6, 6))
    C[:3, 3:] = -_skew(a1)
    C[3:, :3] = -_skew(a1)
    C[3:, 3:] = -_skew(a2)
    return C


def _coupled(tmp_path, key):
    path = tmp_path / f'coupled_{bool(key)}.yaml'
    path.write_text(COUPLED.format(key=key), encoding='utf-8')
    return vehicle_from_file(str(path))


def test_a_coupled_added_mass_gets_fossens_C_A(tmp_path):
    """The key's forces are -C_A(nu) nu of the file's M_A, off-diagonal entries included, at
    the file's values and at others: the same file without the key plus the test's C_A."""
    with_key = _coupled(tmp_path, 'added_mass_coriolis: fossen')
    without = _coupled(tmp_path, '')
    assert without.ca_i.shape[0] == 0
    rng = np.random.default_rng(2)
    theta = np.array([with_key.values[with_key.index(n)] for n in COUPLED_AM])
    for scale in (1.0, 1.15):
        th = theta * scale
        ours, plain = Model(with_key, COUPLED_AM), Model(without, COUPLED_AM)
        M = with_key.mass_matrix(ours.coefficients_with(th))
        M_A = M - with_key.M_RB
        for x, ui in _states(rng, 5, 0):
            F = M @ ours.f(x, ui, th)[:6]
            F_plain = M @ plain.f(x, ui, th)[:6]
            want = -_fossen_C_A(M_A, x[:6]) @ x[:6]
            assert np.allclose(F - F_plain, want, rtol=1e-10, atol=1e-12 * np.abs(want).max())


@pytest.mark.parametrize('current', [None, (0.3, -0.2, 0.05)])
def test_the_added_mass_coriolis_jacobians_are_analytic(tmp_path, current):
    """df/dx and df/d(added mass) against central differences, in still water and in a
    current over ground (the forces act on nu_r)."""
    v = _coupled(tmp_path, 'added_mass_coriolis: fossen')
    m = Model(v, COUPLED_AM, current=current)
    th = m.theta_file
    rng = np.random.default_rng(9)
    for x, ui in _states(rng, 4, 0):
        _, A, Bt = m.jacobians(x, ui, th)
        for j in range(12):
            e = np.zeros(12)
            e[j] = 1e-6
            fd = (m.f(x + e, ui, th) - m.f(x - e, ui, th)) / 2e-6
            assert np.allclose(A[:, j], fd, rtol=1e-6, atol=1e-7 * np.abs(fd).max() + 1e-10)
        for j in range(m.p):
            e = np.zeros(m.p)
            e[j] = 1e-6 * abs(th[j])
            fd = (m.f(x, ui, th + e) - m.f(x, ui, th - e)) / (2 * e[j])
            assert np.allclose(Bt[:, j], fd, rtol=1e-6, atol=1e-7 * np.abs(fd).max() + 1e-12), \
                m.theta_names[j]


def test_the_shipped_fin_vehicles_write_their_own():
    """NPS AUV II, REMUS 100, ISIMI and KVLCC2 lump their Munk moments with viscous terms in
    coefficients of their own: they do not opt in (their model is unchanged)."""
    for name in ('nps_auv2', 'remus100', 'isimi', 'kvlcc2_hsva'):
        assert load_vehicle(name).ca_i.shape == (0, 4), name


RR = '  N_rr: [-1.500, N, 5, r*|r|]\n'


@pytest.mark.parametrize('old, new, words', [
    ('added_mass_coriolis: fossen', 'added_mass_coriolis: diagonal',
     "added_mass_coriolis = 'diagonal'; use none"),
    # a fixed term the key computes would count twice, whichever way its factors are written
    (RR, RR + '  X_vr: [7.1, X, 3, v*r]\n',
     'coefficient X_vr (X, v*r) is a term of the added-mass Coriolis forces'),
    (RR, RR + '  M_wu: [12.3, M, 3, w*u]\n',
     'coefficient M_wu (M, w*u) is a term of the added-mass Coriolis forces'),
])
def test_a_bad_added_mass_coriolis_is_refused_by_name(tmp_path, old, new, words):
    text = open(load_vehicle('bluerov2_heavy').path, encoding='utf-8').read()
    assert old in text
    path = tmp_path / 'bad.yaml'
    path.write_text(text.replace(old, new), encoding='utf-8')
    with pytest.raises(ConfigError, match=re.escape(words)):
        vehicle_from_file(str(path))


def test_the_key_needs_added_mass(tmp_path):
    text = COUPLED.format(key='added_mass_coriolis: fossen')
    text = '\n'.join(ln for ln in text.splitlines() if 'dot:' not in ln)
    path = tmp_path / 'no_added_mass.yaml'
    path.write_text(text, encoding='utf-8')
    with pytest.raises(ConfigError, match='needs added-mass coefficients'):
        vehicle_from_file(str(path))
