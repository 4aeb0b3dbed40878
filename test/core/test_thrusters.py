"""Thrusters in the vehicle file (#29 item 1): the thrust curve (dead band, forward and reverse
polynomial, saturation), the lag and the body wrench tau = sum [f d; r x f d], checked against
hand-computed values; the loader reads the list and reports every bad thruster at once."""
import math

import numpy as np
import pytest

from auv_ident.core.model.thrusters import (
    configuration_matrix,
    lagged_thrusts,
    steady_thrusts,
    thrusters_from_file,
    wrench,
)
from auv_ident.core.model.vehicle import vehicle_from_file, VehicleFileProblems
from auv_ident.vehicles import resolve_vehicle_path

S = math.sqrt(0.5)
PWM = {'name': 'h1', 'r': [0.1, 0.2, 0.0], 'd': [S, S, 0.0], 'command': 'pwm_us',
       'dead_band': 25, 'forward': [0.01, 1e-4], 'reverse': [0.02, 2e-4]}
FORCE = {'name': 'v1', 'r': [0.0, -0.2, -0.1], 'd': [0, 0, 1], 'command': 'force',
         'thrust_max_forward': 30.0, 'thrust_max_reverse': 20.0, 'time_constant': 0.1}


def _two():
    th, problems = thrusters_from_file([PWM, FORCE], 'test')
    assert problems == []
    return th


@pytest.mark.parametrize('command, thrust', [
    (1500.0, 0.0), (1520.0, 0.0), (1475.0, 0.0),        # inside the dead band
    (1600.0, 0.01 * 75 + 1e-4 * 75 ** 2),               # e_d = 100 - 25 forward
    (1400.0, -(0.02 * 75 + 2e-4 * 75 ** 2)),            # reverse coefficients
    (2100.0, 0.01 * 375 + 1e-4 * 375 ** 2),             # command saturated at 1500 + 400
])
def test_thrust_curve(command, thrust):
    assert _two()[0].thrust(command) == pytest.approx(thrust, rel=1e-14, abs=1e-15)


def test_force_command_is_saturated_only():
    v1 = _two()[1]
    assert v1.thrust(12.5) == 12.5
    assert v1.thrust(50.0) == 30.0
    assert v1.thrust(-50.0) == -20.0


def test_wrench_is_the_sum_of_force_and_moment():
    th = _two()
    f1 = 0.01 * 75 + 1e-4 * 75 ** 2
    f2 = -7.0
    # h1: d = (S, S, 0) at r = (0.1, 0.2, 0): r x d = (0, 0, 0.1 S - 0.2 S)
    # v1: d = (0, 0, 1) at r = (0, -0.2, -0.1): r x d = (-0.2, 0, 0)
    want = np.array([f1 * S, f1 * S, f2, -0.2 * f2, 0.0, f1 * (0.1 * S - 0.2 * S)])
    np.testing.assert_allclose(wrench(th, [1600.0, f2]), want, rtol=0, atol=1e-14)
    T = configuration_matrix(th)
    assert T.shape == (6, 2)
    np.testing.assert_allclose(T @ steady_thrusts(th, [1600.0, f2]), want, atol=1e-14)


def test_lag_is_first_order():
    th = _two()
    f = lagged_thrusts(th, np.array([0.0, 0.0]), np.array([3.0, 10.0]), 0.1)
    # h1 has no lag: its steady value; v1 (0.1 s) reaches 1 - e^-1 of the step after 0.1 s
    np.testing.assert_allclose(f, [3.0, 10.0 * (1.0 - math.exp(-1.0))], rtol=1e-14)


def test_every_bad_thruster_is_reported_at_once():
    bad = [dict(PWM, d=[1.0, 1.0, 0.0]), dict(FORCE, command='volts'),
           dict(PWM, forward=[0.01]), dict(PWM, dead_band=500)]
    th, problems = thrusters_from_file(bad, 'test')
    assert th == []
    assert len(problems) == 4
    assert 'unit vector' in problems[0]
    assert "command = 'volts'" in problems[1]
    assert 'forward' in problems[2]
    assert 'dead_band = 500 is not below command_max = 400' in problems[3]


def _with_thrusters(tmp_path, block):
    text = open(resolve_vehicle_path('nps_auv2'), encoding='utf-8').read() + block
    path = tmp_path / 'with_thrusters.yaml'
    path.write_text(text, encoding='utf-8')
    return str(path)


def test_the_file_loads_its_thrusters(tmp_path):
    v = vehicle_from_file(_with_thrusters(tmp_path, """
thrusters:
  - {name: h1, r: [0.1, 0.2, 0.0], d: [0.7071067811865476, 0.7071067811865476, 0.0],
     command: pwm_us, dead_band: 25, forward: [0.01, 1.0e-4], reverse: [0.02, 2.0e-4]}
  - {name: v1, r: [0.0, -0.2, -0.1], d: [0, 0, 1], command: force}
"""))
    assert [t.name for t in v.thrusters] == ['h1', 'v1']
    assert v.thrusters[0].thrust(1600.0) == pytest.approx(0.01 * 75 + 1e-4 * 75 ** 2)
    assert vehicle_from_file(resolve_vehicle_path('nps_auv2')).thrusters == ()


def test_the_loader_collects_thruster_problems_with_the_others(tmp_path):
    path = _with_thrusters(tmp_path, """
thrusters:
  - {name: h1, r: [0.1, 0.2], d: [1, 0, 0], command: pwm_us, forward: [1, 0], reverse: [1, 0]}
  - {name: h1, r: [0, 0, 0], d: [1, 0, 0], command: rpm, forward: [1, 0], reverse: [1, 0]}
""")
    text = open(path, encoding='utf-8').read().replace('rho: 1000.0', 'rho: -1.0', 1)
    open(path, 'w', encoding='utf-8').write(text)
    with pytest.raises(VehicleFileProblems) as err:
        vehicle_from_file(path)
    joined = '\n'.join(err.value.problems)
    assert 'rho' in joined
    assert 'thrusters[0] (h1): r = [0.1, 0.2]' in joined


# Fossen's standard ROV model (Fossen 2021, sec. 7.5; the form von Benzon et al. 2022 use for
# the BlueROV2) in a `scaling: dimensional` file: diagonal added mass (multiplier `udot` ..),
# linear damping (`u`) and quadratic damping (`u*|u|`), restoring from W, B, r_G, r_B
ROV = """
name: rov_terms
scaling: dimensional
rho: 1000.0
L: 0.46
mass: 11.5
W: 112.815
B: {B}
r_G: [0.0, 0.0, 0.0]
r_B: [0.0, 0.0, 0.0]
inertia: {{Ix: 0.16, Iy: 0.16, Iz: 0.16}}
limits: {{fin_rad: 0.1, n_rpm: 1.0}}
mass_inverse: exact
coefficients:
  X_udot: [-5.5, X, 0, udot]
  Y_vdot: [-12.7, Y, 0, vdot]
  Z_wdot: [-14.57, Z, 0, wdot]
  N_rdot: [-0.12, N, 0, rdot]
  X_u: [-4.03, X, 0, u]
  Y_v: [-6.22, Y, 0, v]
  Z_w: [-5.18, Z, 0, w]
  N_r: [-0.07, N, 0, r]
  X_uu: [-18.18, X, 0, u*|u|]
  Y_vv: [-21.66, Y, 0, v*|v|]
  Z_ww: [-36.99, Z, 0, w*|w|]
  N_rr: [-1.55, N, 0, r*|r|]
"""


@pytest.mark.parametrize('state, value, mass, lin, quad', [
    (0, 0.4, 11.5 + 5.5, -4.03, -18.18), (0, -0.3, 11.5 + 5.5, -4.03, -18.18),
    (1, 0.3, 11.5 + 12.7, -6.22, -21.66), (2, -0.2, 11.5 + 14.57, -5.18, -36.99),
    (5, 0.5, 0.16 + 0.12, -0.07, -1.55)])
def test_fossen_rov_model_is_terms_of_a_dimensional_file(tmp_path, state, value, mass, lin,
                                                          quad):
    from auv_ident.core.model.hydrodynamics import Model
    path = tmp_path / 'rov_terms.yaml'
    path.write_text(ROV.format(B=112.815), encoding='utf-8')
    x = np.zeros(12)
    x[state] = value
    xdot = Model(vehicle_from_file(str(path))).f(x, np.zeros(7))
    # one velocity alone: no Coriolis, (m + A) nu_dot = D_lin nu + D_quad nu |nu|
    assert xdot[state] == pytest.approx((lin * value + quad * value * abs(value)) / mass,
                                        rel=1e-12)
    assert np.abs(np.delete(xdot[:6], state)).max() < 1e-12


def test_rov_restoring_from_weight_and_buoyancy(tmp_path):
    from auv_ident.core.model.hydrodynamics import Model
    path = tmp_path / 'rov_terms.yaml'
    path.write_text(ROV.format(B=114.8), encoding='utf-8')
    xdot = Model(vehicle_from_file(str(path))).f(np.zeros(12), np.zeros(7))
    # positively buoyant: Z = W - B < 0 (FRD, z down), the vehicle rises
    assert xdot[2] == pytest.approx((112.815 - 114.8) / (11.5 + 14.57), rel=1e-12)


def test_vehicle_check_names_what_the_thrusters_cannot_push(tmp_path):
    from auv_ident.analysis.vehicle_check import check_vehicle
    # two horizontal thrusters side by side (port, starboard), pushing forward: surge and yaw
    check = check_vehicle(_with_thrusters(tmp_path, """
thrusters:
  - {name: port, r: [-0.2, -0.1, 0.0], d: [1, 0, 0], command: force}
  - {name: stbd, r: [-0.2, 0.1, 0.0], d: [1, 0, 0], command: force}
"""))
    assert '2 thrusters, configuration matrix of rank 2; they push alone: surge yaw' in check.facts
    assert any('cannot push sway heave roll pitch alone' in w for w in check.warnings)


# --- the thrusters in the compiled model (#29 item 2) ---

# the BlueROV2 Heavy with the polynomial the file stated before its table (least squares on
# ten of the T200 16 V table's points): the polynomial form's figures below are hand-computed
POLY_T200 = {'dead_band': 28, 'forward': [0.075984, 1.7580e-4], 'reverse': [0.063798, 1.1891e-4],
             'thrust_max_forward': 51.4, 'thrust_max_reverse': 39.9}


@pytest.fixture(scope='module')
def poly_rov(tmp_path_factory):
    """Path of config/bluerov2_heavy.yaml with POLY_T200 in place of each thruster's table."""
    import yaml

    from auv_ident.core.vehicle_files import read_yaml_file
    raw = read_yaml_file(resolve_vehicle_path('bluerov2_heavy'))
    raw['thrusters'] = [dict({k: v for k, v in t.items() if k != 'table'}, **POLY_T200)
                        for t in raw['thrusters']]
    path = tmp_path_factory.mktemp('poly') / 'bluerov2_heavy_poly.yaml'
    path.write_text(yaml.safe_dump(raw), encoding='utf-8')
    return str(path)


def _rov_model(theta=(), path='bluerov2_heavy'):
    from auv_ident.core.model.hydrodynamics import Model
    from auv_ident.vehicles import load_vehicle
    return Model(load_vehicle(path), list(theta))


def _pwm(horizontal, vertical):
    """The input vector of the BlueROV2 Heavy: 7 channels of state.Input, then t1..t8 (us)."""
    return np.r_[np.zeros(7), horizontal, vertical]


def test_bluerov2_wrench_in_the_model_is_the_hand_computed_one(poly_rov):
    # t3, t4 (aft, pushing forward-out at 45 deg) at 1700 us: e = 200 - 28 = 172 us on the
    # forward side, f = 0.075984 172 + 1.7580e-4 172^2 = 18.2703 N each; their sway and yaw
    # cancel, X = 2 f cos 45. t5..t8 (vertical, d down) at 1300 us: reverse side, f =
    # -(0.063798 172 + 1.1891e-4 172^2) = -14.4911 N each, Z = 4 f (up); roll and pitch cancel
    f_fwd = 0.075984 * 172 + 1.7580e-4 * 172 ** 2
    f_rev = -(0.063798 * 172 + 1.1891e-4 * 172 ** 2)
    _check_wrench(_rov_model(path=poly_rov), f_fwd, f_rev)


def test_bluerov2_table_wrench_in_the_model_is_the_tables_points():
    # the file's T200 table at two of its points: 1700 us 1.82 kgf, 1300 us -1.44 kgf (the
    # interpolant passes through every point)
    _check_wrench(_rov_model(), 1.82 * 9.80665, -1.44 * 9.80665)


def _check_wrench(m, f_fwd, f_rev):
    ui = _pwm([1500, 1500, 1700, 1700], [1300] * 4)
    x = np.zeros(12)
    M = m.vehicle.mass_matrix()
    tau = M @ (m.f(x, ui)[:6] - m.f(x, _pwm([1500] * 4, [1500] * 4))[:6])
    assert tau == pytest.approx([2 * f_fwd * S, 0, 4 * f_rev, 0, 0, 0], abs=1e-9)
    # and the yaw pair: t1 (front right, d back-right) and t4 (rear left, d forward-left) at
    # 1700 us push opposite ways along the same diagonal's normal: a pure yaw moment
    # N = f (x1 dy1 - y1 dx1 + x4 dy4 - y4 dx4) = f S (0.14 + 0.092 + 0.15 + 0.092)
    tau = M @ (m.f(x, _pwm([1700, 1500, 1500, 1700], [1500] * 4))[:6]
               - m.f(x, _pwm([1500] * 4, [1500] * 4))[:6])
    assert tau == pytest.approx([0, 0, 0, 0, 0, f_fwd * S * 0.474], abs=1e-9)


@pytest.mark.parametrize('curve, top', [('poly', 51.4), ('table', 5.25 * 9.80665)])
def test_dead_band_and_saturation_in_the_model(poly_rov, curve, top):
    m = _rov_model(path=poly_rov if curve == 'poly' else 'bluerov2_heavy')
    x = np.zeros(12)
    rest = m.f(x, _pwm([1500] * 4, [1500] * 4))
    assert m.f(x, _pwm([1527, 1473, 1528, 1472], [1520] * 4)) == pytest.approx(rest, abs=0)
    # 1900 us: the polynomial gives 52.6 N, the table's 51.4 N saturates it; the table ends at
    # its 1900 us point, and a command beyond the range is the range's end
    M = m.vehicle.mass_matrix()
    for pwm in (1900, 2000):
        tau = M @ (m.f(x, _pwm([1500] * 4, [pwm] * 4))[:6] - rest[:6])
        assert tau[2] == pytest.approx(4 * top, rel=1e-12)


@pytest.mark.parametrize('curve', ['poly', 'table'])
def test_thrust_gains_scale_each_side_of_the_curves_and_their_jacobian_is_analytic(poly_rov,
                                                                                    curve):
    m = _rov_model(['thrust_gain_fwd', 'thrust_gain_rev', 'X_udot', 'Z_ww'],
                   poly_rov if curve == 'poly' else 'bluerov2_heavy')
    x = np.array([0.2, -0.1, 0.15, 0.05, -0.02, 0.3, 0, 0, 2, 0.05, -0.03, 1.0])
    ui = _pwm([1700, 1350, 1620, 1440], [1560, 1380, 1900, 1100])
    th = m.theta_file
    xd, A, Bt = m.jacobians(x, ui, th)
    M = m.vehicle.mass_matrix()
    rest = m.f(x, _pwm([1500] * 4, [1500] * 4), th)[:6]
    # the forward side 10 % stronger: M nu_dot grows by 0.1 times the forward thrusts' wrench
    from auv_ident.core.model.thrusters import configuration_matrix, steady_thrusts
    f = steady_thrusts(m.vehicle.thrusters, ui[7:])
    T = configuration_matrix(m.vehicle.thrusters)
    th2 = th.copy()
    th2[0] = 1.1
    assert M @ (m.f(x, ui, th2)[:6] - xd[:6]) == pytest.approx(
        0.1 * T @ np.where(f > 0, f, 0.0), rel=1e-9, abs=1e-9)
    assert M @ (xd[:6] - rest) == pytest.approx(T @ f, rel=1e-9, abs=1e-9)
    for j in range(m.p):
        h = 1e-6 * max(1.0, abs(th[j]))
        tp, tm = th.copy(), th.copy()
        tp[j] += h
        tm[j] -= h
        fd = (m.f(x, ui, tp) - m.f(x, ui, tm)) / (2 * h)
        assert Bt[:, j] == pytest.approx(fd, rel=1e-6, abs=1e-8), m.theta_names[j]
    for k in range(12):
        h = 1e-7
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        fd = (m.f(xp, ui, th) - m.f(xm, ui, th)) / (2 * h)
        assert A[:, k] == pytest.approx(fd, rel=1e-5, abs=1e-6), k


def test_thruster_vehicle_needs_its_thruster_commands():
    from auv_ident.core.errors import DimensionError
    m = _rov_model()
    with pytest.raises(DimensionError, match='15 entries'):
        m.f(np.zeros(12), np.zeros(7))


def test_a_thrust_gain_names_its_equations(tmp_path):
    from auv_ident.core.errors import ConfigError
    text = open(resolve_vehicle_path('bluerov2_heavy'), encoding='utf-8').read()
    bad = text.replace('thrust_gain_fwd: [1.0, XYZKMN, 0, thrusters_forward]',
                       'thrust_gain_fwd: [1.0, XXY, 0, thrusters_forward]')
    p = tmp_path / 'rov.yaml'
    p.write_text(bad)
    with pytest.raises(ConfigError, match='each once'):
        vehicle_from_file(str(p))
    # a gain of both sides on top of the forward one: two gains of one force
    both = text.replace('  thrust_gain_rev: [1.0, XYZKMN, 0, thrusters_reverse]',
                        '  thrust_gain_rev: [1.0, XYZKMN, 0, thrusters_reverse]\n'
                        '  thrust_gain: [1.0, Z, 0, thrusters]')
    p.write_text(both)
    with pytest.raises(ConfigError, match='both scale the forward thrust in Z'):
        vehicle_from_file(str(p))


def test_a_hovering_vehicle_gets_a_pilots_advice():
    from auv_ident.core.identification.diagnosis import excitation_advice
    from auv_ident.vehicles import load_vehicle
    rov, auv = load_vehicle('bluerov2_heavy'), load_vehicle('remus100')
    assert excitation_advice(rov, 'X_uu').startswith('surge stick steps')
    assert excitation_advice(rov, 'Z_wdot').startswith('quick stick reversals')
    assert 'forward and the reverse side' in excitation_advice(rov, 'thrust_gain_rev')
    assert excitation_advice(auv, 'X_uu').startswith('speed changes')   # a fin AUV's as before


# --- a thrust curve given as a table (#29: the T200's published points) ---

TABLE = {'name': 'tb', 'r': [0.0, 0.0, 0.0], 'd': [1, 0, 0], 'command': 'pwm_us',
         'table': {'unit': 'kgf', 'command': [1100, 1300, 1468, 1472, 1528, 1532, 1700, 1900],
                   'thrust': [-4.07, -1.44, -0.04, 0.0, 0.0, 0.04, 1.82, 5.25]}}


def test_table_curve_is_the_monotone_cubic_through_its_points():
    """Through every point (kgf to N), scipy's PCHIP between them (the same curve, so the
    generator's independent copy can use scipy), exactly 0 in the dead band, never falling,
    the ends beyond the range; the compiled kernel evaluates the same numbers."""
    from scipy.interpolate import PchipInterpolator

    from auv_ident.core.model.hydrodynamics import thrust_of
    from auv_ident.core.model.thrusters import THR_COLS, thruster_table
    th, problems = thrusters_from_file([TABLE, PWM], 'test')
    assert problems == []
    t = th[0]
    x = np.array(TABLE['table']['command'], float)
    f = 9.80665 * np.array(TABLE['table']['thrust'])
    assert [t.thrust(c) for c in x] == pytest.approx(f, abs=1e-14)
    cmd = np.linspace(1000.0, 2000.0, 4001)
    ours = np.array([t.thrust(c) for c in cmd])
    np.testing.assert_allclose(ours, PchipInterpolator(x, f)(np.clip(cmd, 1100, 1900)),
                               rtol=0, atol=1e-12)
    assert np.all(np.diff(ours) >= 0.0)
    assert np.all(ours[(cmd >= 1472) & (cmd <= 1528)] == 0.0)
    thr = thruster_table(th)
    assert thr.shape == (2, THR_COLS + 3 * 8)
    for i, th_i in enumerate(th):
        assert [thrust_of(thr, i, c) for c in cmd[::7]] == pytest.approx(
            [th_i.thrust(c) for c in cmd[::7]], rel=1e-14, abs=1e-14)


def test_a_table_within_thrust_limits_and_in_newton():
    t = thrusters_from_file([dict(TABLE, thrust_max_forward=10.0, table=dict(
        TABLE['table'], unit='N'))], 'test')[0][0]
    assert t.thrust(1900) == 5.25 and t.thrust(1100) == -4.07
    t = thrusters_from_file([dict(TABLE, thrust_max_forward=10.0)], 'test')[0][0]
    assert t.thrust(1900) == 10.0


@pytest.mark.parametrize('change, words', [
    ({'command': [1100, 1300, 1468, 1472, 1528, 1528, 1700, 1900]},
     'table.command is not increasing (1528 then 1528)'),
    ({'thrust': [-4.07, -1.44, -0.04, 0.0, 0.0, 0.04, 1.82, 1.5]},
     'table.thrust falls from 1.82 to 1.5 kgf (commands 1700 to 1900)'),
    ({'thrust': [-4.07, -1.44, -0.04, 0.0, 0.0, 0.04, 1.82, float('nan')]},
     'table.thrust is not a list of at least two finite numbers'),
    ({'thrust': [-4.07, -1.44, -0.04, 0.0, 0.0, 0.04, 1.82]},
     'table.command has 8 points and table.thrust 7'),
    ({'unit': 'kg'}, "table.unit = 'kg'; the thrust unit is one of N, kgf, lbf"),
    ({'command': [-1.0, -0.5, -0.1, 0.0, 0.05, 0.1, 0.5, 1.0]},
     'table.command spans -1..1, not inside the command range 1100..1900 around neutral 1500'),
    ({'thrust': [-4.07, -1.44, 0.5, 0.5, 0.5, 0.5, 1.82, 5.25]},
     'table.thrust is not <= 0 below neutral 1500 and >= 0 above it'),
    ({'scale': 2.0}, 'table: unknown key(s) scale'),
])
def test_a_bad_table_is_one_error_naming_the_key(change, words):
    _, problems = thrusters_from_file([dict(TABLE, table=dict(TABLE['table'], **change))],
                                      'test')
    assert len(problems) == 1
    assert problems[0].startswith('thrusters[0] (tb): table')
    assert words in problems[0]


def test_a_table_with_a_polynomial_or_on_a_force_thruster_is_refused():
    _, problems = thrusters_from_file([dict(TABLE, dead_band=28), dict(FORCE, table=TABLE[
        'table']), dict(TABLE, table=[[1100, -4.0], [1900, 5.0]])], 'test')
    assert 'table and dead_band: give the curve one way' in problems[0]
    assert 'a `command: force` thruster takes its thrust as the command' in problems[1]
    assert 'table = [[1100, -4.0], [1900, 5.0]]; give table: {unit:' in problems[2]


def test_scaled_curves_scale_each_side_of_table_and_polynomial():
    from auv_ident.core.model.thrusters import scaled_curves
    raw = [TABLE, dict(PWM, thrust_max_forward=50.0, thrust_max_reverse=40.0)]
    th = thrusters_from_file(scaled_curves(raw, 1.1, 0.9), 'test')[0]
    base = thrusters_from_file(raw, 'test')[0]
    for c in (1100, 1250, 1490, 1510, 1650, 1900, 2000):
        for t, b in zip(th, base):
            k = 1.1 if b.thrust(c) > 0 else 0.9
            assert t.thrust(c) == pytest.approx(k * b.thrust(c), rel=1e-12, abs=1e-15)
    assert raw[0]['table']['thrust'][-1] == 5.25     # the caller's entries are unchanged


def test_vehicle_check_states_the_table_and_names_a_bad_one(tmp_path):
    from auv_ident.analysis.vehicle_check import check_vehicle
    from auv_ident.core.vehicle_files import read_yaml_file
    check = check_vehicle(resolve_vehicle_path('bluerov2_heavy'))
    assert ('thrust curves: t1 t2 t3 t4 t5 t6 t7 t8: e = pwm_us - 1500 saturated to +-400; table '
            'of 201 points, 1100..1900 -> -39.91..51.48 N, monotone cubic (PCHIP) between them, '
            'its end values beyond') in check.facts
    import yaml
    raw = read_yaml_file(resolve_vehicle_path('bluerov2_heavy'))
    raw['thrusters'][3] = dict(raw['thrusters'][3], table=dict(raw['thrusters'][3]['table'],
                                                               unit='newton'))
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump(raw), encoding='utf-8')
    check = check_vehicle(str(path))
    assert any("thrusters[3] (t4): table.unit = 'newton'" in e for e in check.errors), check.errors
