"""Tier 1: the physics core against MSS reference rows, invariants and finite differences."""
import subprocess
import sys

import numpy as np
import pytest

from auv_ident.core.errors import ConfigError, DomainError
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.trim import rest_inputs
from auv_ident.vehicles import available_vehicles, load_vehicle

# shared/reference/vehicles.md section 1.7: classic MSS npsauv.m run in GNU Octave
ROW_A_IN = [2, 0, 0, 0, 0, 0, 0, 0, 10, 0, 0, 0], [0, 0, 0, 0, 0, 1000, 0]
ROW_A_OUT = [-0.021756235860269393, -2.4164868470551921e-08, -1.7056784191294235e-05,
             -4.8774810358221266e-07, 1.481832671108601e-04, -9.5821688626457246e-08,
             2, 0, 0, 0, 0, 0]
ROW_B_IN = ([2, 0.1, 0.05, 0.01, 0.02, 0.03, 0, 0, 10, 0.05, 0.1, 0.2],
            [0.1, -0.05, 0, 0.02, 0.02, 1000, 0])
ROW_B_OUT = [-0.021861095083037838, -0.037730935114397672, -0.019599861875375876,
             -0.061940570958785787, 0.00095644987213640992, -0.045024682578655321,
             1.9363700851950405, 0.49187823304319112, -0.14500585167523505,
             0.013106571267357153, 0.018475630129778976, 0.031117549330671464]
VEHICLES = available_vehicles()
# the vehicles that roll and pitch (a planar one holds them: test_planar.py)
SIX_DOF = [n for n in VEHICLES if load_vehicle(n).free_states.all()]


@pytest.mark.parametrize('row_in,row_out', [(ROW_A_IN, ROW_A_OUT), (ROW_B_IN, ROW_B_OUT)])
def test_nps_matches_mss_reference_rows(row_in, row_out):
    m = Model(load_vehicle('nps_auv2'))
    got = m.f(np.array(row_in[0], float), np.array(row_in[1], float))
    ref = np.array(row_out)
    nz = ref != 0
    assert np.all(np.abs(got[nz] - ref[nz]) <= 1e-12 * np.abs(ref[nz]))
    assert np.all(got[~nz] == 0.0)


def test_nps_has_all_81_terms_and_14_added_mass():
    v = load_vehicle('nps_auv2')
    am = [c for c in v.coefficients if c.is_added_mass]
    # 80 coefficient terms in the file + Xprop in the propulsion block = 81
    assert len(am) == 14 and len(v.coefficients) - len(am) == 80


def test_nps_literal_inverse_is_inverse_of_mass_matrix():
    v = load_vehicle('nps_auv2')
    Minv_exact = np.linalg.inv(v.mass_matrix())
    # the MSS literal has 4 significant digits
    big = np.abs(v.Minv_literal) > 1e-6
    rel = np.abs(Minv_exact[big] - v.Minv_literal[big]) / np.abs(v.Minv_literal[big])
    assert rel.max() < 1e-3


def test_exact_inverse_option_close_to_literal():
    v = load_vehicle('nps_auv2')
    x, ui = np.array(ROW_B_IN[0], float), np.array(ROW_B_IN[1], float)
    a = Model(v).f(x, ui)
    b = Model(v, mass_inverse='exact').f(x, ui)
    assert np.allclose(a, b, rtol=2e-3, atol=1e-6)
    assert not np.array_equal(a, b)


@pytest.mark.parametrize('name', VEHICLES)
def test_mass_matrix_symmetric_positive_definite(name):
    M = load_vehicle(name).mass_matrix()
    assert np.allclose(M, M.T)
    assert np.all(np.linalg.eigvalsh(M) > 0)


@pytest.mark.parametrize('name', SIX_DOF)
def test_restoring_moment_rights_a_heeled_vehicle(name):
    m = Model(load_vehicle(name))
    for phi, theta in [(0.2, 0.0), (-0.2, 0.0), (0.0, 0.15), (0.0, -0.15)]:
        x = np.zeros(12)
        x[0] = 1.0
        x[9], x[10] = phi, theta
        xd = m.f(x, rest_inputs(m))
        if phi:
            assert np.sign(xd[3]) == -np.sign(phi), (phi, xd[3])
        if theta:
            assert np.sign(xd[4]) == -np.sign(theta), (theta, xd[4])


def _random_states(rng, n, u_range=(0.5, 2.0), n_thrusters=0):
    """n random (x, ui); a thruster vehicle's ui also gets PWM commands (us) over the whole
    range (dead band and saturation included)."""
    for _ in range(n):
        x = np.concatenate([
            [rng.uniform(*u_range)], rng.normal(0, 0.1, 2), rng.normal(0, 0.05, 3),
            rng.normal(0, 10, 3), rng.uniform(-0.5, 0.5, 2), rng.uniform(-3, 3, 1)])
        ui = np.concatenate([rng.uniform(-0.3, 0.3, 5), [rng.uniform(300, 1400)],
                             [rng.uniform(10.0, 60.0)]])
        if n_thrusters:
            ui = np.concatenate([ui, rng.uniform(1050.0, 1950.0, n_thrusters)])
        yield x, ui


@pytest.mark.parametrize('name', VEHICLES)
def test_jacobians_match_finite_differences(name):
    v = load_vehicle(name)
    # every coefficient identified at once, so each one's column is checked
    m = Model(v, v.names, mass_inverse='exact')
    rng = np.random.default_rng(7)
    for x, ui in _random_states(rng, 5, n_thrusters=len(v.thrusters)):
        th = m.theta_file
        _, A, Bt = m.jacobians(x, ui, th)
        for j in range(12):
            h = 1e-6 * max(1.0, abs(x[j]))
            e = np.zeros(12)
            e[j] = h
            fd = (m.f(x + e, ui, th) - m.f(x - e, ui, th)) / (2 * h)
            assert np.allclose(A[:, j], fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max() + 1e-9), \
                (name, 'x', j)
        for j in range(m.p):
            # most coefficients enter linearly (big h: no roundoff); added mass enters through M^-1
            am = v.coefficients[v.index(m.theta_names[j])].is_added_mass
            h = (1e-5 if am else 1e-3) * max(1e-2, abs(th[j]))
            e = np.zeros(m.p)
            e[j] = h
            fd = (m.f(x, ui, th + e) - m.f(x, ui, th - e)) / (2 * h)
            assert np.allclose(Bt[:, j], fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max() + 1e-12), \
                (name, m.theta_names[j])


def test_inputs_are_saturated():
    m = Model(load_vehicle('nps_auv2'))
    x = np.array(ROW_B_IN[0], float)
    a = m.f(x, np.array([1.0, -1.0, 0.0, 0.5, -0.5, 5000.0, 0.0]))
    lim = np.deg2rad(20.0)
    b = m.f(x, np.array([lim, -lim, 0.0, lim, -lim, 1500.0, 0.0]))
    assert np.array_equal(a, b)


def _strip_sum(par, v, w, q, r):
    """MSS classic cross-flow (Y, Z, M, N), station by station in numpy, skipping U = 0."""
    from auv_ident.core.model.vehicle import P_CF_CY, P_CF_CZ, P_CF_N, P_L, P_RHO
    L, ns = par[P_L], int(par[P_CF_N])
    out = np.zeros(4)
    for xl in np.linspace(-L / 2, L / 2, ns):
        a, b = v + xl * r, w - xl * q
        U = np.hypot(a, b)
        if U > 0:
            g = (par[P_CF_CY] * a * a + par[P_CF_CZ] * b * b) / U
            out += 0.5 * par[P_RHO] * (L / (ns - 1)) * np.array(
                [-g * a, g * b, -g * (w + xl * q) * xl, -g * a * xl])
    return out


def test_crossflow_station_at_rest_adds_nothing():
    """A station with zero cross-flow speed (here the seventh: v = r = 0, w = x_7 q, with
    q = 1 so that x_7 q is exact and U is exactly 0 there) is a 0/0 in the strip formula; it
    must add nothing rather than a NaN."""
    from auv_ident.core.model.hydrodynamics import _crossflow
    from auv_ident.core.model.vehicle import P_CF_N, P_L
    v = load_vehicle('nps_auv2')
    L, ns = v.par[P_L], int(v.par[P_CF_N])
    q = 1.0
    w = (-L / 2 + 6 * (L / (ns - 1))) * q
    xdot, A = np.zeros(12), np.zeros((12, 12))
    _crossflow(v.par, 0.0, w, q, 0.0, True, xdot, A)
    assert np.all(np.isfinite(xdot)) and np.all(np.isfinite(A))
    assert np.allclose(xdot[[1, 2, 4, 5]], _strip_sum(v.par, 0.0, w, q, 0.0), rtol=1e-12,
                       atol=1e-15)


@pytest.mark.parametrize('x_mod,ui_mod,needle', [
    ({0: 0.0}, {}, 'propeller ratio'),
    ({0: -0.5}, {5: 1500.0}, 'complex'),
    ({10: np.pi / 2}, {}, '90 deg'),
    ({1: np.nan}, {}, 'NaN'),
    ({}, {0: np.inf}, 'NaN or Inf'),
])
def test_domain_errors_are_clear(x_mod, ui_mod, needle):
    m = Model(load_vehicle('nps_auv2'))
    x = np.array(ROW_B_IN[0], float)
    ui = np.array(ROW_B_IN[1], float)
    for k, val in x_mod.items():
        x[k] = val
    for k, val in ui_mod.items():
        ui[k] = val
    with pytest.raises(DomainError, match=needle):
        m.f(x, ui)


def test_unknown_coefficient_name_is_a_clear_error():
    with pytest.raises(ConfigError, match="unknown coefficient 'Z_www'"):
        Model(load_vehicle('nps_auv2'), ['Z_www'])


def test_added_mass_identification_needs_exact_inverse():
    v = load_vehicle('nps_auv2')
    with pytest.raises(ConfigError, match='mass-inverse exact'):
        Model(v, ['Z_wdot'])
    m = Model(v, ['Z_wdot'], mass_inverse='exact')
    assert m.theta_names == ['Z_wdot'] and m.mass_inverse == 'exact'
    assert m.theta_file.tolist() == [v.coefficients[v.index('Z_wdot')].value] == [-0.24]


def test_a_vehicle_with_another_mass_inverse_is_a_copy_every_model_follows():
    v = load_vehicle('nps_auv2')
    assert v.with_mass_inverse('default') is v and v.with_mass_inverse('mss_literal') is v
    exact = v.with_mass_inverse('exact')
    assert exact is not v and exact.mass_inverse == 'exact' and v.mass_inverse == 'mss_literal'
    assert Model(exact).mass_inverse == 'exact' and Model(exact, ['Z_wdot']).p == 1
    x = np.zeros(12)
    x[0] = 1.5
    u = np.array([0.1, 0.05, 0.0, 0.0, 0.0, 500.0, 0.0])
    np.testing.assert_array_equal(Model(exact).f(x, u), Model(v, mass_inverse='exact').f(x, u))
    with pytest.raises(ConfigError, match='no MSS literal inverse'):
        load_vehicle('remus100').with_mass_inverse('mss_literal')
    with pytest.raises(ConfigError, match='use default, exact or mss_literal'):
        v.with_mass_inverse('approximate')


def test_importing_the_core_does_not_import_rclpy():
    code = ('import sys, pkgutil, importlib, auv_ident.core as c\n'
            'for m in pkgutil.iter_modules(c.__path__):\n'
            '    importlib.import_module("auv_ident.core." + m.name)\n'
            'bad = [m for m in sys.modules if m.split(".")[0] in '
            '("rclpy", "nav_msgs", "sensor_msgs", "std_msgs", "rosbags", "mcap")]\n'
            'assert not bad, bad\n')
    subprocess.run([sys.executable, '-c', code], check=True)
