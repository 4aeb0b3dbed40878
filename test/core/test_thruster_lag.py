"""The thrusters' first-order lag (#29 item 1) and the propeller torque in the model: a lagged
simulation against the lag written as states of an ODE, the time constant's column of the
filter's Jacobian (through the carried thrust) against finite differences, a zero time constant
bit-identical to the vehicle without one, the file's keys checked; and a BlueROV2 Heavy with a
0.15 s motor lag identified with its time constant."""
import dataclasses
import math

import numpy as np
import pytest
import yaml

from auv_ident.analysis import results
from auv_ident.core.errors import ConfigError, DivergenceError
from auv_ident.core.filter import ekf
from auv_ident.core.identification.pipeline import identify_with_diagnosis
from auv_ident.core.identification.results import Record
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.integrators import rk4_step
from auv_ident.core.model.sensors import ar1_noise, DEFAULT_NOISE_STD
from auv_ident.core.model.state import N_INPUT, N_STATE
from auv_ident.core.model.thruster_lag import L_SN, L_SP, lag_advance, lag_settle
from auv_ident.core.model.thrusters import configuration_matrix, steady_thrusts
from auv_ident.core.model.vehicle import vehicle_from_file, VehicleFileProblems
from auv_ident.core.simulation.simulate import simulate
from auv_ident.core.vehicle_files import read_yaml_file
from auv_ident.vehicles import load_vehicle, resolve_vehicle_path

TAU = 0.15      # s, the truth's motor lag
LAG = 'thrust_time_constant'


def _rov_file(tmp_path, tau=TAU, name='rov_lag', **thruster_keys):
    raw = read_yaml_file(resolve_vehicle_path('bluerov2_heavy'))
    if tau is not None:
        raw['coefficients'][LAG] = [tau, 'XYZKMN', 0, 'thruster_lag']
    raw['thrusters'] = [dict(t, **thruster_keys) for t in raw['thrusters']]
    p = tmp_path / f'{name}.yaml'
    p.write_text(yaml.safe_dump(raw))
    return str(p)


def test_lagged_simulation_is_the_lag_ode(tmp_path):
    """Our simulator's RK4 steps with the exact lag inside them against RK4 at a 20 times finer
    step of the augmented ODE [x; f] with tau f_dot = f_ss - f: the same run to 1e-4 of the
    lag's own effect."""
    v = vehicle_from_file(_rov_file(tmp_path))
    run = simulate(Model(v), 'tank', duration=20.0, T=0.05, noise_std=np.zeros(12))
    T = configuration_matrix(v.thrusters)
    Minv = np.linalg.inv(v.mass_matrix())
    steady = Model(v)

    def f_aug(z, u):
        u0 = u.copy()
        u0[N_INPUT:] = 1500.0           # thrusters neutral: the thrust comes from z
        xd = steady.f(z[:12], u0)
        xd[:6] += Minv @ (T @ z[12:])
        return np.concatenate([xd, (steady_thrusts(v.thrusters, u[N_INPUT:]) - z[12:]) / TAU])

    z = np.concatenate([run.x[0], steady_thrusts(v.thrusters, run.u[0, N_INPUT:])])
    X = [run.x[0]]
    for k in range(len(run.t) - 1):
        for _ in range(20):
            z = rk4_step(f_aug, z, run.u[k], 0.05 / 20)
        X.append(z[:12])
    no_lag = simulate(Model(load_vehicle('bluerov2_heavy')), 'tank', duration=20.0, T=0.05,
                      noise_std=np.zeros(12))
    effect = np.abs(no_lag.x[:, :6] - run.x[:, :6]).max()
    assert effect > 0.05                # m/s: the lag matters in this run
    assert np.abs(np.array(X)[:, :6] - run.x[:, :6]).max() < 1e-4 * effect


def test_time_constant_column_of_the_jacobian(tmp_path):
    """dPhi/dtau of one filter step, with a carried thrust that itself depends on tau (S from
    an earlier step), against central differences of the step and of that thrust."""
    v = vehicle_from_file(_rov_file(tmp_path))
    names = [LAG, 'X_u', 'thrust_gain_fwd']
    m = Model(v, names)
    cm = m.compiled
    n = N_STATE + m.p
    u0 = np.concatenate([np.zeros(N_INPUT), [1700, 1300, 1650, 1400, 1600, 1560, 1450, 1380.]])
    u1 = np.concatenate([np.zeros(N_INPUT), [1300, 1700, 1500, 1800, 1420, 1600, 1700, 1500.]])
    xa = np.concatenate([[0.3, -0.1, 0.05, 0.1, -0.05, 0.2, 0, 0, 1.5, 0.05, -0.03, 0.4],
                         m.theta_file])
    ws = ekf.workspace_for(n, cm)
    lag_settle(cm, u0, ws.lag, ws.lag_ok)
    tmp = np.empty(n)
    ekf.rk4_step_into(xa, u1, cm, 0.1, False, tmp, ws.Fa, ws)
    lag_advance(cm, ws.c, u1, ws.lag, ws.lag_ok, 0.1)     # S != 0 from here on
    assert np.abs(ws.lag[[L_SP, L_SN]]).max() > 1.0
    lag0 = ws.lag.copy()
    out = np.empty(n)
    Fa = np.empty((n, n))
    ekf.rk4_step_into(xa, u0, cm, 0.1, True, out, Fa, ws)
    eps = 1e-6
    col = []
    for sgn in (1.0, -1.0):
        x = xa.copy()
        x[N_STATE] += sgn * eps
        ws.lag[:] = lag0
        ws.lag[:2] += sgn * eps * lag0[2:]       # the carried thrust at tau +- eps
        ekf.rk4_step_into(x, u0, cm, 0.1, False, out, np.empty((n, n)), ws)
        col.append(out[:N_STATE].copy())
    fd = (col[0] - col[1]) / (2 * eps)
    np.testing.assert_allclose(Fa[:N_STATE, N_STATE], fd, rtol=1e-5, atol=1e-9)
    assert np.abs(fd[:6]).max() > 1e-2


def test_zero_time_constant_is_the_vehicle_without_a_lag(tmp_path):
    """A `thruster_lag` coefficient at 0: the simulation and one identification through the
    lag's code path (the carried thrust, the extended inputs) are bit for bit those of the same
    file read without a lag (its steady kernel, which the shipped files take)."""
    v = vehicle_from_file(_rov_file(tmp_path, tau=0.0))
    steady = dataclasses.replace(v, lag_idx=-1)
    assert v.lagged and not steady.lagged
    a = simulate(Model(steady), 'tank', duration=30.0, seed=3)
    b = simulate(Model(v), 'tank', duration=30.0, seed=3)
    assert np.array_equal(a.x, b.x) and np.array_equal(a.y, b.y)
    names = ['thrust_gain_fwd', 'X_udot', 'X_u', 'Z_ww']
    ra = identify_with_diagnosis(Model(steady, names), results.make_config(names),
                                 [Record(a.t, a.y, a.u)], T=a.T)
    rb = identify_with_diagnosis(Model(v, names), results.make_config(names),
                                 [Record(b.t, b.y, b.u)], T=b.T)
    assert np.array_equal(ra.estimate, rb.estimate) and np.array_equal(ra.cov, rb.cov)


def test_propeller_torque_turns_about_the_thruster_axis(tmp_path):
    """torque_ratio k_q: the thruster's moment gains k_q f d (N m), nothing else changes."""
    v0 = load_vehicle('bluerov2_heavy')
    v = vehicle_from_file(_rov_file(tmp_path, tau=None, torque_ratio=-0.02))
    T0, T1 = configuration_matrix(v0.thrusters), configuration_matrix(v.thrusters)
    d = np.array([t.direction for t in v.thrusters]).T
    np.testing.assert_array_equal(T1[:3], T0[:3])
    np.testing.assert_allclose(T1[3:] - T0[3:], -0.02 * d, atol=1e-15)
    u = np.concatenate([np.zeros(N_INPUT), [1700, 1500, 1500, 1500, 1500, 1500, 1500, 1500.]])
    x = np.zeros(12)
    dM = (Model(v).f(x, u) - Model(v0).f(x, u))[:6]
    f1 = v.thrusters[0].thrust(1700.0)
    np.testing.assert_allclose(v0.mass_matrix() @ dM, np.r_[0, 0, 0, -0.02 * f1 * d[:, 0]],
                               atol=1e-12)


@pytest.mark.parametrize('change, message', [
    (lambda r: r['coefficients'].__setitem__('tc', [-0.1, 'XYZKMN', 0, 'thruster_lag']),
     'time constant -0.1 s must be >= 0'),
    (lambda r: r['coefficients'].__setitem__('tc', [0.1, 'XY', 0, 'thruster_lag']),
     'give [tau_s, XYZKMN, 0, thruster_lag]'),
    (lambda r: r['coefficients'].__setitem__('tc2', [0.1, 'XYZKMN', 0, 'thruster_lag']),
     "are each the thrusters' time constant"),
    (lambda r: r['thrusters'][2].__setitem__('time_constant', 0.2),
     'thrusters t3 give their own time_constant'),
    (lambda r: r['thrusters'][1].__setitem__('torque_ratio', 'left'),
     "torque_ratio = 'left' is not a finite number"),
])
def test_lag_and_torque_keys_are_checked(tmp_path, change, message):
    raw = read_yaml_file(_rov_file(tmp_path))
    change(raw)
    p = tmp_path / 'bad.yaml'
    p.write_text(yaml.safe_dump(raw))
    with pytest.raises((ConfigError, VehicleFileProblems)) as err:
        vehicle_from_file(str(p))
    assert message in str(err.value)


@pytest.mark.slow
def test_bluerov2_heavy_with_a_motor_lag_identifies_it(tmp_path):
    """A 10-minute tank session of our simulator with a 0.15 s motor lag (RK4 at T/4, coloured
    noise at twice the configured level, as test_rov_identification without a lag): the file's
    set and the time constant, each started 50 % off, come back within 5 %, the time constant
    within 3 sigma, the truth inside 3 sigma for at least 90 % of them."""
    v = vehicle_from_file(_rov_file(tmp_path))
    run = simulate(Model(v), 'tank', duration=600.0, seed=1, substeps=4,
                   noise_std=np.zeros(12))
    y = run.y + ar1_noise(np.random.default_rng([1, 1]), len(run.t), 2 * DEFAULT_NOISE_STD,
                          0.5, run.T)
    names = list(v.identify_default) + [LAG]
    m = Model(v, names)
    res = identify_with_diagnosis(m, results.make_config(names), [Record(run.t, y, run.u)],
                                  T=run.T)
    true = m.theta_file
    err = res.estimate / true - 1.0
    sd = np.sqrt(np.diag(res.cov))
    i = names.index(LAG)
    assert abs(res.estimate[i] - TAU) <= 3 * sd[i], (res.estimate[i], sd[i])
    assert np.all(np.abs(err) < 0.05), dict(zip(names, np.round(100 * err, 2)))
    inside = np.abs(res.estimate - true) <= 3 * sd
    assert inside.mean() >= 0.9, dict(zip(names, np.round((res.estimate - true) / sd, 1)))
    assert math.isfinite(sd[i]) and sd[i] < 0.1 * TAU


def test_vehicle_check_states_the_lag_and_the_torque(tmp_path):
    """`vehicle check` says the lag (the identifiable coefficient, or none) and the torque
    ratios; a negative time constant is an error of the file (exit 2)."""
    from auv_ident.analysis.vehicle_check import check_vehicle
    good = check_vehicle(_rov_file(tmp_path, torque_ratio=0.02))
    text = '\n'.join(good.facts)
    assert ('thruster lag: first order, tau = 0.15 s for every thruster (coefficient '
            'thrust_time_constant, identifiable)') in text
    assert 'torque_ratio): t1 +0.02, t2 +0.02' in text
    shipped = check_vehicle('bluerov2_heavy')
    assert 'thruster lag: none (the thrust follows the commands at once)' in shipped.facts
    bad = check_vehicle(_rov_file(tmp_path, tau=-0.1, name='neg'))
    assert any('time constant -0.1 s must be >= 0' in e for e in bad.errors)


def test_live_filter_carries_the_lag_as_the_compiled_loop(tmp_path):
    """The per-message filter (AugmentedEKF.step: the live node's) and the compiled loop of
    identify run the same lagged filter, the time constant identified: the thrust settled at the
    first command, carried over each step, moved at each update by dP/dtau dtau. Without the
    carried thrust (a settled one every step) the two differ."""
    from test_ekf import per_message_and_loop

    from auv_ident.core.filter.augmented import AugmentedEKF, FilterConfig
    v = vehicle_from_file(_rov_file(tmp_path))
    run = simulate(Model(v), 'tank', duration=30.0, seed=4)
    m = Model(v, ['thrust_gain_fwd', 'X_udot', 'X_u', LAG])
    g, f = per_message_and_loop(m, run)
    cfg = FilterConfig(coefficients=m.theta_names, initial_offset=0.5)
    np.testing.assert_allclose(g.xa, f.xa, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(g.P, f.P, rtol=1e-7, atol=1e-15)
    h = AugmentedEKF(m, cfg, run.T)
    h.start(run.y[0], run.u[0, 5])
    try:
        for k in range(1, len(run.t)):
            h.ws.lag_ok[0] = 0          # forget the carried thrust
            h.step(run.u[k - 1], run.y[k])
        assert abs(h.xa[N_STATE + 3] - f.xa[N_STATE + 3]) > 1e-3
    except DivergenceError:
        pass                            # the settled thrust's filter does not even finish


def test_equation_error_refuses_the_time_constant_and_the_advice_names_steps(tmp_path):
    """The equation error's regression is of F at one instant: it refuses the time constant
    (the thrust depends on the command history through it); the diagnosis advises stick
    steps for it, not a surge manoeuvre (its equation letter is only a placeholder)."""
    from auv_ident.core.identification.diagnosis import excitation_advice, PILOT_LAG
    from auv_ident.core.identification.equation_error import refusals
    v = vehicle_from_file(_rov_file(tmp_path))
    assert 'command history' in refusals(Model(v, [LAG, 'X_u']), np.ones(12, bool))[LAG]
    assert excitation_advice(v, LAG) == PILOT_LAG


def test_export_gives_every_thruster_the_identified_time_constant(tmp_path):
    """uuv_simulator's thrusters get the time constant of c (the identified one) as FirstOrder
    dynamics; the shipped file (no lag) stays ZeroOrder."""
    from auv_ident.analysis.export_gz_thrusters import uuv_thruster_lines, with_gains
    v = vehicle_from_file(_rov_file(tmp_path))
    c = v.values.copy()
    c[v.lag_idx] = 0.123
    thrusters, _ = with_gains(v, c)
    assert [t.time_constant for t in thrusters] == [0.123] * 8
    text = '\n'.join(uuv_thruster_lines(thrusters)[1])
    assert text.count('<timeConstant>0.123</timeConstant>') == 8
    v0 = load_vehicle('bluerov2_heavy')
    text0 = '\n'.join(uuv_thruster_lines(with_gains(v0, v0.values)[0])[1])
    assert 'FirstOrder' not in text0 and text0.count('ZeroOrder') == 8
