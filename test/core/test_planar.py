"""Tier 1: a planar vehicle (dofs: [surge, sway, yaw]) holds heave, roll and pitch in the model,
the simulator and the EKF; the measured thrust input; one model from several runs."""
import numpy as np
import pytest

from auv_ident.core.errors import ConfigError, DimensionError
from auv_ident.core.filter.augmented import AugmentedEKF, FilterConfig
from auv_ident.core.identification.batch import identify
from auv_ident.core.identification.results import Record
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import Input, N_INPUT, N_STATE, State
from auv_ident.core.model.vehicle import _build
from auv_ident.core.simulation.simulate import simulate
from auv_ident.session.messages import actuator_joint_fields, joint_state_to_actuators
from auv_ident.vehicles import load_vehicle

SHIP = 'kvlcc2_hsva'
HELD = [State.W, State.P, State.Q, State.Z, State.PHI, State.THETA]
FREE = [State.U, State.V, State.R, State.X, State.Y, State.PSI]


def _ship_input(delta=0.1, thrust=41.0):
    ui = np.zeros(N_INPUT)
    ui[Input.DELTA_R], ui[Input.N_RPM], ui[Input.THRUST] = delta, 613.77, thrust
    return ui


def _state(rng):
    x = np.zeros(N_STATE)
    x[State.U], x[State.V], x[State.R] = rng.uniform(0.8, 1.2), rng.normal(0, 0.05), \
        rng.normal(0, 0.02)
    x[State.X], x[State.Y], x[State.PSI] = rng.normal(0, 10, 2).tolist() + [rng.uniform(-3, 3)]
    return x


def test_held_states_have_zero_rates_and_do_not_enter_the_model():
    v = load_vehicle(SHIP)
    assert sorted(v.held.tolist()) == sorted(int(i) for i in HELD)
    m = Model(v, v.identify_default)
    rng = np.random.default_rng(3)
    for _ in range(5):
        x = _state(rng)
        xd, A, Bt = m.jacobians(x, _ship_input())
        assert np.all(xd[HELD] == 0.0) and np.all(A[HELD] == 0.0) and np.all(Bt[HELD] == 0.0)
        assert np.all(A[:, HELD] == 0.0)
        assert np.any(xd[FREE] != 0.0)
        # whatever the held states hold (a heel, a depth, a pitch rate), f is the same
        y = x.copy()
        y[HELD] = rng.normal(0, 0.3, len(HELD))
        assert np.array_equal(m.f(y, _ship_input()), xd)


def test_simulator_keeps_the_held_states_and_the_ekf_does_not_move_them():
    v = load_vehicle(SHIP)
    m = Model(v)
    run = simulate(m, 'zigzag', duration=60.0, T=0.1, seed=2)
    assert np.all(run.x[:, HELD] == run.x[0, HELD]) and np.all(run.x[0, HELD] == 0.0)
    assert np.ptp(run.x[:, State.R]) > 0.02 and np.ptp(run.x[:, State.V]) > 0.02
    f = AugmentedEKF(Model(v, ['N_r']), FilterConfig(coefficients=['N_r']), run.T)
    assert not f.measured[HELD].any() and np.all(np.diag(f.Q0)[HELD] == 0.0)
    y = run.y.copy()
    y[:, State.PHI] = 0.3          # a measured heel must not leak into a held state
    f.start(y[0], v.cruise_rpm)
    for k in range(1, 100):
        f.step(run.u[k - 1], y[k])
        assert np.all(f.xa[HELD] == 0.0)
        assert np.all(f.P[HELD][:, [i for i in range(f.n) if i not in HELD]] == 0.0)


def test_thrust_flows_from_the_joint_state_effort_into_surge():
    """The thrust written into the propeller joint's effort comes back as Input.THRUST and
    enters the model through the thrust terms (X_T T, and the rudder's T delta terms): the
    accelerations change by M^-1 times their forces."""
    v = load_vehicle(SHIP)
    m = Model(v)

    class Msg:      # a JointState as a bag reader returns it (duck-typed, as messages reads)
        class header:
            class stamp:
                sec, nanosec = 12, 500_000_000
    from auv_ident.session.messages import JOINT_NAMES
    Msg.name = list(JOINT_NAMES)
    ui = _ship_input(delta=0.05, thrust=47.5)
    Msg.position, Msg.velocity, Msg.effort = actuator_joint_fields(ui)
    t, back = joint_state_to_actuators(Msg)
    assert t == 12.5 and back[Input.THRUST] == 47.5
    np.testing.assert_allclose(back, ui, rtol=1e-14)
    x = np.zeros(N_STATE)
    x[State.U] = 1.1
    d = m.f(x, back) - m.f(x, _ship_input(delta=0.05, thrust=40.0))
    # the thrust terms: X_T T, Y_Tdr T delta, N_Tdr L T delta (vehicle file, scale L^k)
    c = dict(zip(v.names, v.values))
    dF = np.array([c['X_T'], c['Y_Tdr'] * 0.05, 0, 0, 0, c['N_Tdr'] * 7.0 * 0.05]) * 7.5
    want = np.linalg.solve(v.mass_matrix(), dF)
    np.testing.assert_allclose(d[:6], want, rtol=1e-11, atol=1e-15)
    # an AUV has no thrust term: the thrust input changes nothing
    nps = Model(load_vehicle('nps_auv2'))
    xa = np.zeros(N_STATE)
    xa[State.U], xa[State.Z] = 1.5, 10.0
    ua = np.zeros(N_INPUT)
    ua[Input.N_RPM] = 1000.0
    ub = ua.copy()
    ub[Input.THRUST] = 50.0
    assert np.array_equal(nps.f(xa, ua), nps.f(xa, ub))
    with pytest.raises(DimensionError, match='7 entries'):
        nps.f(xa, ua[:6])


def test_bad_dofs_and_held_added_mass_are_one_clear_error(tmp_path):
    raw = dict(load_vehicle(SHIP).raw)
    with pytest.raises(ConfigError, match='dofs'):
        _build(dict(raw, dofs=['surge', 'drift']), str(tmp_path / 'a.yaml'))
    coefs = dict(raw['coefficients'], Z_wdot=[-0.01, 'Z', 3, 'wdot'])
    with pytest.raises(ConfigError, match='Z_wdot: added mass of a held degree of freedom'):
        _build(dict(raw, coefficients=coefs), str(tmp_path / 'b.yaml'))
    with pytest.raises(ConfigError, match='mss_literal is a 6-DOF inverse'):
        _build(dict(raw, mass_inverse='mss_literal', mss_inverse=np.eye(6).tolist()),
               str(tmp_path / 'c.yaml'))


NAMES = ['X_uu', 'Y_v', 'Y_r', 'N_v', 'N_r', 'Y_dr', 'N_dr']


def _runs():
    """Two simulated planar runs of the ship (different seeds and rudder amplitudes)."""
    v = load_vehicle(SHIP)
    truth = Model(v)
    noise = np.zeros(N_STATE)
    noise[[State.U, State.V]] = 0.003
    noise[State.R] = 5e-4
    noise[[State.X, State.Y]] = 0.01
    noise[State.PSI] = 1e-3
    runs = []
    for seed in (1, 2):
        run = simulate(truth, 'zigzag', duration=80.0, T=0.1, seed=seed, noise_std=noise)
        runs.append(Record(run.t, run.y, run.u))
    return v, noise, runs


def test_one_model_from_two_simulated_planar_runs_recovers_the_truth():
    v, noise, runs = _runs()
    m = Model(v, NAMES)
    measured = np.zeros(N_STATE, dtype=bool)
    measured[FREE] = True
    cfg = FilterConfig(coefficients=NAMES, initial_offset=0.2, p0_rel=0.5, noise_std=noise,
                       measured=measured)
    both = identify(m, runs, cfg, truth=m.theta_file)
    z = (both.estimate - m.theta_file) / both.std
    assert np.all(np.abs(z) < 4.0), dict(zip(NAMES, z))
    assert np.all(np.abs(both.error_pct()) < 5.0), dict(zip(NAMES, both.error_pct()))
    # the error bars use both runs: narrower than from either run alone
    one = identify(m, runs[:1], cfg)
    assert np.all(both.std < one.std)
    assert both.steps == sum(r.samples for r in runs)
