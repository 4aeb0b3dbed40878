"""Tests of the independent BlueROV2 Heavy generator (offline/independent_rov.py): its own
physics (energy, terminal heave speed, thruster wrench), the bag (strict decoding, commands on
change, frames) and the truth in truth.json. Short runs only."""
import dataclasses
import json

import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_typestore, Stores

from auv_ident.offline import independent_rov as rov
from auv_ident.session.messages import odometry_to_state


@pytest.fixture(scope='module')
def run(tmp_path_factory):
    cfg = rov.RovConfig(duration=40.0, seed=5)
    out = tmp_path_factory.mktemp('rov') / 'run'
    doc = rov.generate(cfg, out)
    return cfg, out, doc


def test_energy_decays_without_thrust_when_neutral():
    """W = B at one point: only damping acts, so 0.5 nu^T M nu never grows (C is skew)."""
    truth = dataclasses.replace(rov.RovTruth(), volume=13.5 / 1000.0, r_b=(0.0, 0.0, 0.0))
    model = rov.RovModel(truth)
    y0 = np.zeros(12)
    y0[:6] = (0.5, -0.3, 0.2, 0.4, -0.3, 0.8)
    t = np.linspace(0, 10, 201)
    Y = rov.integrate(model, y0, np.array([0.0]), np.full((1, 8), 1500.0), 1.0, t, 10.0, 1e-9)
    E = np.array([model.energy(y[:6]) for y in Y])
    assert np.all(np.diff(E) <= 1e-12)
    assert E[-1] < 0.05 * E[0]


def test_coriolis_is_skew_symmetric():
    """C_RB(nu) + C_A(nu) does no work: C = -C^T for any nu, also with r_G off the origin."""
    rng = np.random.default_rng(0)
    for r_g in ((0.0, 0.0, 0.0), (0.01, -0.02, 0.03)):
        model = rov.RovModel(dataclasses.replace(rov.RovTruth(), r_g=r_g))
        for _ in range(5):
            C = model.coriolis(rng.normal(size=6))
            np.testing.assert_allclose(C, -C.T, atol=1e-12)
    # and it is not zero: the added-mass Munk moment in pitch, (a3 - a1) u w
    nu = np.array([0.3, 0.0, 0.1, 0.0, 0.0, 0.0])
    assert -(rov.RovModel(rov.RovTruth()).coriolis(nu) @ nu)[4] == pytest.approx(
        (18.6863 - 6.3567) * 0.3 * 0.1)


def test_heavy_vehicle_sinks_at_the_terminal_speed():
    """W - B = Z_w w + Z_ww w|w| at the terminal heave speed (level, no thrust)."""
    truth = rov.RovTruth()
    model = rov.RovModel(truth)
    dw = truth.W - truth.B
    a, b = truth.quadratic_damping[2], truth.linear_damping[2]
    w_term = (-b + np.sqrt(b * b + 4 * a * dw)) / (2 * a)
    Y = rov.integrate(model, np.zeros(12), np.array([0.0]), np.full((1, 8), 1500.0), 1.0,
                      np.array([30.0]), 30.0, 1e-10)
    assert dw == pytest.approx(13.5 * 9.81 - 1000 * 9.81 * 0.0134)
    assert Y[0, 2] == pytest.approx(w_term, rel=1e-4)
    assert w_term == pytest.approx(0.02587, abs=1e-5)   # 190 w^2 + 33 w = 0.981 N


def test_thruster_wrench_by_hand():
    # t1 alone at 1900 us: 5.25 kgf along (-1, 1, 0)/sqrt(2) at (0.14, 0.092, 0)
    f = 5.25 * 9.80665
    pwm = np.full(8, 1500.0)
    pwm[0] = 1900
    tau = rov.thruster_wrench(rov.t200_thrust(pwm))
    s = np.sqrt(0.5)
    np.testing.assert_allclose(tau, [-s * f, s * f, 0, 0, 0, (0.14 * s + 0.092 * s) * f],
                               atol=1e-9)
    # all four verticals at 1100 us (reverse, up): -4.07 kgf each, no moment (symmetric)
    pwm = np.full(8, 1500.0)
    pwm[4:] = 1100
    tau = rov.thruster_wrench(rov.t200_thrust(pwm, 1.1))
    np.testing.assert_allclose(tau, [0, 0, -4 * 4.07 * 9.80665 * 1.1, 0, 0, 0], atol=1e-9)
    # the table itself: dead band and the points the vehicle file's fit quotes
    assert rov.t200_thrust([1472, 1500, 1528]).tolist() == [0.0, 0.0, 0.0]
    kgf = rov.t200_thrust([1184, 1308, 1624, 1728, 1840, 1864]) / 9.80665
    np.testing.assert_allclose(kgf, [-2.94, -1.35, 0.87, 2.22, 4.25, 4.71], atol=1e-12)
    assert len(rov.T200_KGF) == len(rov.T200_PWM) == 201


def test_mixer_surge_pushes_forward_and_yaw_turns_starboard():
    fwd = rov.thruster_wrench(rov.t200_thrust(rov.pwm_of(rov.mix((0.5, 0, 0, 0)))))
    assert fwd[0] > 0 and abs(fwd[1]) < 1e-9 and abs(fwd[5]) < 1e-9
    yaw = rov.thruster_wrench(rov.t200_thrust(rov.pwm_of(rov.mix((0, 0, 0, 0.5)))))
    assert yaw[5] > 0 and abs(yaw[0]) < 1e-9
    down = rov.thruster_wrench(rov.t200_thrust(rov.pwm_of(rov.mix((0, 0, 0.5, 0)))))
    assert down[2] > 0 and np.allclose(down[3:], 0, atol=1e-9)


def _read(bag):
    store = get_typestore(Stores.ROS2_JAZZY)
    out = {rov.ODOM_TOPIC: [], rov.THRUSTER_TOPIC: []}
    with Reader(bag) as r:
        types = {c.topic: c.msgtype for c in r.connections}
        for conn, t_ns, raw in r.messages():
            out[conn.topic].append((t_ns, store.deserialize_cdr(raw, conn.msgtype)))
    return types, out


def test_bag_decodes_strictly(run):
    cfg, out, doc = run
    types, msgs = _read(out / 'bag')
    assert types == {'/odom': 'nav_msgs/msg/Odometry',
                     '/thrusters': 'std_msgs/msg/Float64MultiArray'}
    odom, cmds = msgs['/odom'], msgs['/thrusters']
    assert len(odom) == doc['counts']['odom'] and len(cmds) == doc['counts']['commands']
    assert all(m.header.frame_id == 'odom' and m.child_frame_id == 'base_link' for _, m in odom)
    assert all(len(m.data) == 8 and m.layout.dim[0].size == 8 for _, m in cmds)
    pwm = np.array([m.data for _, m in cmds])
    assert np.all(pwm == np.round(pwm)) and pwm.min() >= 1100 and pwm.max() <= 1900
    stamps = np.array([m.header.stamp.sec * rov.NS + m.header.stamp.nanosec for _, m in odom])
    dt = np.diff(stamps) / rov.NS
    assert dt.std() > 0.005 and abs(dt.mean() - 1 / cfg.odom_rate) < 0.002   # irregular
    # ENU/FLU: the truth's NED depth comes back as -z, FLU sway as -v
    st = np.load(out / 'truth_states.npz')
    k = len(odom) // 2
    m = odom[k][1]
    assert m.pose.pose.position.z == pytest.approx(-st['y'][k, 8])
    assert m.twist.twist.linear.y == pytest.approx(-st['y'][k, 1])
    # the package's ENU reader gives back the generator's NED/FRD measurements
    x = np.array([odometry_to_state(m, 'enu')[1] for _, m in odom])
    err = x - st['y']
    err[:, 9:] = (err[:, 9:] + np.pi) % (2 * np.pi) - np.pi
    assert np.abs(err).max() < 1e-9


def test_commands_only_on_change(run):
    cfg, out, doc = run
    _, msgs = _read(out / 'bag')
    t = np.array([t for t, _ in msgs['/thrusters']]) / rov.NS
    pwm = np.array([m.data for _, m in msgs['/thrusters']])
    same = np.all(pwm[1:] == pwm[:-1], axis=1)
    assert same.any() and (~same).any()
    # a repeat comes only after repeat_period of silence (less the transport delay)
    assert np.all(np.diff(t)[same] >= cfg.repeat_period - cfg.command_delay[1])
    assert doc['counts']['commands'] < doc['counts']['ticks']


def test_truth_in_metadata(run):
    _, out, doc = run
    saved = json.loads((out / 'truth.json').read_text())
    c = saved['coefficients']
    assert c['X_udot'] == -6.3567 and c['N_rr'] == -1.5 and c['Z_w'] == -33.0
    assert c['thrust_gain_fwd'] == pytest.approx(1.1)
    assert saved['perturbed']['thrust_gain_rev'] == pytest.approx(1.1)
    assert set(saved['noise']['sigma']) == set(rov.CHANNELS)
    assert not (out / 'bag' / 'truth.json').exists()


def test_bad_option_is_named(tmp_path):
    with pytest.raises(ValueError, match='frame'):
        rov.generate(rov.RovConfig(duration=1.0, frame='xyz'), tmp_path / 'x')
    assert rov.main(['--out', str(tmp_path / 'y'), '--duration', '-1']) == 2


def test_file_curve_is_the_vehicle_files_thrust_and_is_chosen_by_curve():
    """curve 'file' is the vehicle file's curve (checked against the file's own entries
    through our loader here, in the test only), the table stays the default (the same points,
    interpolated linearly: within 0.12 N of the file's cubic, not equal), a bad name is
    refused."""
    from auv_ident.core.model.thrusters import steady_thrusts
    from auv_ident.vehicles import load_vehicle
    pwm = np.array([1100.0, 1300, 1471, 1500, 1529, 1600, 1750, 1900, 1950])
    file_thrusters = load_vehicle('bluerov2_heavy').thrusters
    ours = steady_thrusts(file_thrusters[:1] * len(pwm), pwm)
    assert np.allclose(rov.file_curve_thrust(pwm), ours, rtol=1e-12, atol=1e-12)
    assert np.allclose(rov.file_curve_thrust(pwm, 1.1), 1.1 * ours)
    fine = np.arange(1100.0, 1900.0, 0.5)
    gap = np.abs(rov.t200_thrust(fine) - rov.file_curve_thrust(fine))
    assert 0.05 < gap.max() <= 0.12
    assert rov.RovConfig().curve == 'table'
    with pytest.raises(ValueError, match='curve'):
        rov.RovConfig(curve='spline').validate()


def test_motor_lag_is_a_first_order_thrust_and_is_in_the_truth(tmp_path):
    """--motor-lag: the truth's thrust rises as 1 - e^(-t/tau) after a step of the command (its
    own ODE states), and truth.json names the time constant as the file's lag coefficient."""
    model = rov.RovModel(rov.RovTruth(), lag=0.15)
    model.thrust_cmd = rov.t200_thrust(np.full(8, 1700.0))
    y0 = np.zeros(20)
    y0[8] = 1.5
    out = rov.integrate(model, y0, np.array([0.0]), np.array([np.full(8, 1700.0)]), 1.0,
                        np.array([0.15]), 0.15, 1e-10)
    np.testing.assert_allclose(out[0, 12:20], rov.t200_thrust(np.full(8, 1700.0))
                               * (1.0 - np.exp(-1.0)), rtol=1e-6)
    doc = rov.generate(rov.RovConfig(duration=2.0, seed=1, motor_lag=0.15), tmp_path / 'lag')
    assert doc['coefficients']['thrust_time_constant'] == 0.15
    assert 'thrust_time_constant' not in rov.generate(
        rov.RovConfig(duration=2.0, seed=1), tmp_path / 'nolag')['coefficients']
