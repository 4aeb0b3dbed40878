"""Tests of the independent test-data generator (offline/independent_data.py) itself: its stamps,
commands, bag layout, noise, current, truth vehicle and integrator. Short runs only."""
import json
import math

from mcap.reader import make_reader
import numpy as np
import pytest
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import get_typestore, Stores
import yaml

from auv_ident.bags.reader import read_bag
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.trim import trim_speed
from auv_ident.core.model.vehicle import vehicle_from_file
from auv_ident.offline import independent_data as gen
from auv_ident.offline.independent_data import DataConfig, generate
from auv_ident.session.messages import joint_state_to_actuators, odometry_to_state
from auv_ident.vehicles import load_vehicle

PAPER_SET = ('Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v')
EPOCH_2025_06_03_09 = 1748941200 * gen.NS


def _realistic(**kw):
    base = dict(duration=60.0, seed=3, odom_rate=10.0, odom_jitter=0.1, dropout=0.1,
                gaps=((30.0, 4.0),), commands='on_change', command_rate=20.0,
                odom_delay=(0.001, 0.004), command_delay=(0.001, 0.030), noise='white')
    base.update(kw)
    return DataConfig(**base)


@pytest.fixture(scope='module')
def real(tmp_path_factory):
    """One realistic bag: 10 Hz +-10 % jitter, 10 % dropouts, a 4 s gap, on-change commands."""
    cfg = _realistic()
    return cfg, generate(cfg, tmp_path_factory.mktemp('real') / 'run')


def _bag_messages(bag):
    odom, cmds = [], []
    for topic, t_ns, msg in read_bag(bag):
        stamp = int(msg.header.stamp.sec) * gen.NS + int(msg.header.stamp.nanosec)
        (odom if topic == gen.ODOM_TOPIC else cmds).append((t_ns, stamp, msg))
    return odom, cmds


# --------------------------------------------------------------------------------- stamps


def test_odometry_stamp_statistics(real):
    cfg, data = real
    odom, _ = _bag_messages(data.bag)
    stamps = np.array([s for _, s, _ in odom])
    assert stamps[0] >= EPOCH_2025_06_03_09 and stamps[0] - EPOCH_2025_06_03_09 < gen.NS
    np.testing.assert_array_equal(stamps, data.odom_stamp_ns)
    assert np.all(np.diff(stamps) > 0)
    period = 1.0 / cfg.odom_rate
    t = (stamps - EPOCH_2025_06_03_09) / gen.NS
    k = np.round(t / period)
    jitter = t - k * period
    assert np.all(np.abs(jitter) <= cfg.odom_jitter * period + 2e-9)
    assert np.abs(jitter).max() > 0.8 * cfg.odom_jitter * period   # the whole range is used
    assert abs(np.mean(jitter)) < 0.01 * period
    # nominal rate: the median spacing is one period; dropouts and the gap make longer ones
    assert np.median(np.diff(t)) == pytest.approx(period, rel=0.05)
    in_gap = (k * period >= 30.0) & (k * period < 34.0)
    assert not in_gap.any()
    n_nominal = data.nominal_odom
    n_outside_gap = n_nominal - 40
    kept = len(stamps) / n_outside_gap
    sd = math.sqrt(cfg.dropout * (1 - cfg.dropout) / n_outside_gap)
    assert abs((1 - kept) - cfg.dropout) < 4 * sd
    # the gap itself: no odometry for ~4 s
    assert np.diff(t).max() >= 4.0 - 2 * cfg.odom_jitter * period


def test_gap_and_dropout_off_gives_every_sample(tmp_path):
    cfg = DataConfig(duration=5.0, odom_rate=200.0, noise='none')
    data = generate(cfg, tmp_path / 'r')
    t = data.t_odom
    assert len(t) == 1001 and data.nominal_odom == 1001
    np.testing.assert_allclose(np.diff(t), 1 / 200.0, atol=1e-9)


# --------------------------------------------------------------------------------- commands


def test_commands_only_on_change_and_every_change_published(real):
    cfg, data = real
    _, cmds = _bag_messages(data.bag)
    stamps = np.array([s for _, s, _ in cmds])
    u = np.array([joint_state_to_actuators(m)[1] for _, _, m in cmds])
    order = np.argsort(stamps, kind='stable')
    stamps, u = stamps[order], u[order]
    assert np.all(np.diff(stamps) > 0)
    # nothing is published twice: every message changes at least one channel
    assert np.all(np.any(np.abs(np.diff(u, axis=0)) > 1e-12, axis=1))
    # every change of the driver's command sequence is in the bag: the zero-order hold of the
    # published commands reproduces the command at every tick of the driver's clock
    tick_ns = data.t0_ns + np.round(data.tick_t * gen.NS).astype(np.int64)
    idx = np.searchsorted(stamps, tick_ns, side='right') - 1
    assert np.all(idx >= 0)
    np.testing.assert_allclose(u[idx], data.tick_values, atol=1e-12)
    # commands are sparse while the fins are held: far fewer messages than ticks, and holds
    # of several seconds without any message
    assert len(stamps) < 0.9 * len(data.tick_t)
    assert np.diff(stamps).max() > 1.0 * gen.NS
    # rate limit: no fin moves faster than fin_rate_deg
    dt = np.diff(data.tick_t)
    rate = np.abs(np.diff(data.tick_values[:, :5], axis=0)) / dt[:, None]
    assert rate.max() <= math.radians(cfg.fin_rate_deg) * (1 + 1e-9)
    # shaft speed: the configured rpm, in rad/s in JointState.velocity
    np.testing.assert_allclose(u[:, 5], cfg.rpm, rtol=1e-12)
    for _, _, m in cmds[:3]:
        assert list(m.name) == list(gen.JOINT_NAMES)
        assert m.position[5] == 0.0 and list(m.velocity[:5]) == [0.0] * 5
        assert list(m.effort) == [0.0] * 6
    # the truth input is the zero-order hold of these commands at each odometry stamp
    idx = np.searchsorted(stamps, data.odom_stamp_ns, side='right') - 1
    np.testing.assert_allclose(data.u_true, u[idx], atol=0)


def test_periodic_commands_every_tick(tmp_path):
    cfg = DataConfig(duration=10.0, commands='periodic', command_rate=20.0, noise='none',
                     compress=True)
    data = generate(cfg, tmp_path / 'r')
    assert len(data.cmd_stamp_ns) == len(data.tick_t) == 201
    _, cmds = _bag_messages(data.bag)                # zstd chunks read back
    assert len(cmds) == 201
    np.testing.assert_allclose(np.diff(data.cmd_stamp_ns) / gen.NS, 0.05, atol=1e-9)


def test_log_time_order_and_late_commands(real):
    cfg, data = real
    log_ns = [t for _, t, _ in read_bag(data.bag)]
    assert log_ns == sorted(log_ns)
    # the MCAP file itself holds the messages in log-time order
    mcap = next(data.bag.glob('*.mcap'))
    with open(mcap, 'rb') as fh:
        file_order = [m.log_time for _, _, m in make_reader(fh).iter_messages(
            log_time_order=False)]
    assert file_order == sorted(file_order)
    odom, cmds = _bag_messages(data.bag)
    for log, stamp, _ in odom + cmds:
        assert 0 < log - stamp <= 0.031 * gen.NS
    # some command stamped before an odometry sample arrives after it
    odom_log = {s: t for t, s, _ in odom}
    o_stamps = np.array(sorted(odom_log))
    late = 0
    for t_log, s, _ in cmds:
        i = np.searchsorted(o_stamps, s, side='left')   # first odometry stamped >= s
        if i < len(o_stamps) and odom_log[o_stamps[i]] < t_log:
            late += 1
    assert late > 0


# --------------------------------------------------------------------------------- decoding


def test_every_message_decodes_strictly_and_with_the_package_reader(real):
    cfg, data = real
    store = get_typestore(Stores.ROS2_JAZZY)
    n = 0
    with RosbagsReader(data.bag) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == {
            '/odom': 'nav_msgs/msg/Odometry', '/actuators': 'sensor_msgs/msg/JointState'}
        for conn, _, raw in reader.messages():
            msg = store.deserialize_cdr(raw, conn.msgtype)   # raises on any size mismatch
            assert len(store.serialize_cdr(msg, conn.msgtype)) == len(raw)
            n += 1
    meta = yaml.safe_load((data.bag / 'metadata.yaml').read_text())
    info = meta['rosbag2_bagfile_information']
    assert info['version'] == 9 and info['storage_identifier'] == 'mcap'
    assert info['message_count'] == n == len(data.odom_stamp_ns) + len(data.cmd_stamp_ns)
    # no truth inside the bag directory
    assert sorted(p.name for p in data.bag.iterdir()) == ['bag.mcap', 'metadata.yaml']
    assert 'truth' not in json.dumps(info.get('custom_data') or {})
    # the package's reader and message conversions give back what was generated
    odom, cmds = _bag_messages(data.bag)
    assert len(odom) == len(data.odom_stamp_ns) and len(cmds) == len(data.cmd_stamp_ns)
    for k, (_, _, msg) in enumerate(odom):
        assert msg.header.frame_id == 'odom_ned' and msg.child_frame_id == 'base_link_frd'
        t, x12, pcov, tcov = odometry_to_state(msg)
        assert t == pytest.approx(data.odom_stamp_ns[k] / gen.NS, abs=1e-6)   # float s at 2025
        np.testing.assert_allclose(x12[:9], data.y[k, :9], atol=1e-12)
        dang = gen.wrap(x12[9:] - data.y[k, 9:])
        assert np.abs(dang).max() < 1e-12
        assert not pcov.any() and not tcov.any()


def test_true_covariance_fields(tmp_path):
    cfg = DataConfig(duration=2.0, covariance='true', noise_level=2.0)
    data = generate(cfg, tmp_path / 'r')
    _, _, msg = next(iter(read_bag(data.bag, ['/odom'])))
    _, _, pcov, tcov = odometry_to_state(msg)
    sig = 2.0 * np.array(gen.DOCUMENTED_SIGMA)
    np.testing.assert_allclose(np.diag(tcov), sig[:6] ** 2, rtol=1e-12)
    np.testing.assert_allclose(np.diag(pcov), sig[6:] ** 2, rtol=1e-12)
    assert not (tcov - np.diag(np.diag(tcov))).any()


def test_documented_sigmas_match_the_package():
    from auv_ident.core.model.sensors import DEFAULT_NOISE_STD
    np.testing.assert_array_equal(np.array(gen.DOCUMENTED_SIGMA), DEFAULT_NOISE_STD)


# --------------------------------------------------------------------------------- noise


def test_coloured_noise_autocorrelation():
    tau, dt, n = 1.0, 0.05, 40000
    t = np.arange(n) * dt
    sigma = np.array(gen.DOCUMENTED_SIGMA)
    e = gen.colored_noise(t, sigma, np.full(12, tau), np.random.default_rng(1), 'ar1') / sigma
    r1 = np.mean(e[1:] * e[:-1], axis=0) / np.mean(e * e, axis=0)
    a = math.exp(-dt / tau)
    se = math.sqrt((1 - a * a) / n) * 3      # generous: the estimate is itself correlated
    assert np.all(np.abs(r1 - a) < max(se, 0.006)), r1
    var = np.mean(e * e, axis=0)
    assert abs(var.mean() - 1.0) < 0.08   # stationary variance sigma^2 (pooled)
    # irregular stamps: E[e_k e_{k-1}] = exp(-dt_k / tau) sigma^2
    rng = np.random.default_rng(2)
    t = np.cumsum(rng.choice([0.02, 0.5], n))
    e = gen.colored_noise(t, np.ones(12), np.full(12, tau), np.random.default_rng(3), 'ar1')
    dts = np.diff(t)
    for d in (0.02, 0.5):
        sel = np.isclose(dts, d)
        r = np.mean(e[1:][sel] * e[:-1][sel]) / np.mean(e * e)
        assert r == pytest.approx(math.exp(-d / tau), abs=0.02)
    # white noise: no correlation
    w = gen.colored_noise(np.arange(n) * dt, np.ones(12), np.full(12, tau),
                          np.random.default_rng(4), 'white')
    assert np.abs(np.mean(w[1:] * w[:-1], axis=0)).max() < 4 / math.sqrt(n)


def test_bag_holds_truth_plus_noise(tmp_path):
    cfg = DataConfig(duration=20.0, noise='ar1', noise_tau=1.0, noise_level=2.0,
                     odom_rate=20.0)
    data = generate(cfg, tmp_path / 'r')
    diff = data.y - data.x_true
    diff[:, 9:] = gen.wrap(diff[:, 9:])
    np.testing.assert_allclose(diff, data.noise, atol=1e-9)
    assert data.truth['noise']['sigma']['x'] == pytest.approx(1.0)
    assert data.truth['noise']['tau_s']['psi'] == 1.0


# --------------------------------------------------------------------------------- current


def test_current_changes_ground_velocity_by_rotated_current(tmp_path):
    vc = (0.1 / math.sqrt(2), 0.1 / math.sqrt(2), 0.0)   # 0.1 m/s towards the north-east
    common = dict(duration=8.0, lead_in=100.0, noise='none', heading0_deg=30.0, odom_rate=10)
    still = generate(DataConfig(**common), tmp_path / 'still')
    ground = generate(DataConfig(current_ned=vc, **common), tmp_path / 'ground')
    water = generate(DataConfig(current_ned=vc, dvl='water', **common), tmp_path / 'water')
    R = gen.rotation(0.0, 0.0, math.radians(30.0))
    vb = R.T @ np.array(vc)
    # t0: relative velocity unchanged (the trim run through the water), over ground + R^T v_c
    np.testing.assert_allclose(ground.nu_r[0], still.nu_r[0], atol=1e-15)
    np.testing.assert_allclose(ground.x_true[0, :3] - still.x_true[0, :3], vb, atol=1e-14)
    np.testing.assert_allclose(ground.x_true[0, 3:6], still.x_true[0, 3:6], atol=1e-15)
    # the DVL option: twist over ground, or through the water
    np.testing.assert_allclose(ground.y[:, :3], ground.x_true[:, :3], atol=0)
    np.testing.assert_allclose(water.y[:, :3], water.nu_r[:, :3], atol=0)
    np.testing.assert_allclose(water.y[:, 6:], ground.y[:, 6:], atol=0)
    # the steady run stays steady through the water; the water carries the vehicle along
    np.testing.assert_allclose(ground.nu_r, still.nu_r, atol=1e-8)
    drift = ground.x_true[:, 6:9] - still.x_true[:, 6:9]
    np.testing.assert_allclose(drift, np.outer(ground.t_odom, vc), atol=1e-7)
    assert ground.truth['current_ned'] == pytest.approx(list(vc))
    assert ground.truth['current_body_t0'] == pytest.approx(list(vb))


# --------------------------------------------------------------------------------- vehicle


def test_perturbed_vehicle_differs_only_outside_the_kept_list(tmp_path):
    cfg = DataConfig(duration=2.0, perturb=0.2, perturb_keep=PAPER_SET, seed=7)
    data = generate(cfg, tmp_path / 'r')
    file_v = load_vehicle('nps_auv2')
    truth_v = vehicle_from_file(data.truth_vehicle)
    assert truth_v.names == file_v.names
    fv, tv = dict(zip(file_v.names, file_v.values)), dict(zip(truth_v.names, truth_v.values))
    changed = 0
    for name in file_v.names:
        if name in PAPER_SET or fv[name] == 0.0:
            assert tv[name] == fv[name], name
            continue
        ratio = tv[name] / fv[name]
        assert 0.8 <= ratio <= 1.2, name
        assert ratio != 1.0, name
        assert ratio == pytest.approx(data.factors[name], rel=1e-12)
        changed += 1
    assert changed > 60
    # added-mass pairs keep M symmetric (one factor per pair); the exact inverse is used
    assert data.factors['Y_pdot'] == data.factors['K_vdot']
    assert data.factors['M_wdot'] == data.factors['Z_qdot']
    assert truth_v.mass_inverse == 'exact'
    assert data.truth['coefficients'] == {n: float(v) for n, v in tv.items()}
    assert set(data.truth['perturbed']).isdisjoint(PAPER_SET)
    # the truth vehicle's file sits beside the bag, not inside it
    assert data.truth_json.parent == data.bag.parent
    # the factors do not depend on the keep list (one draw per coefficient, in file order)
    _, f2, _ = gen.perturbed_vehicle(DataConfig(perturb=0.2, seed=7),
                                     gen._streams(7)['perturb'], tmp_path)
    for name in file_v.names:
        if name not in PAPER_SET:
            assert f2[name] == data.factors[name]


def test_unperturbed_truth_is_the_file(tmp_path):
    data = generate(DataConfig(duration=1.0), tmp_path / 'r')
    v = load_vehicle('nps_auv2')
    assert data.truth['coefficients'] == dict(zip(v.names, map(float, v.values)))
    assert data.truth['perturbed'] == []
    assert not (tmp_path / 'r' / 'truth_vehicle.yaml').exists()


# --------------------------------------------------------------------------------- integrator


@pytest.mark.parametrize('rpm', [500.0, 1200.0])
def test_straight_run_reaches_trim_speed(tmp_path, rpm):
    """From half the trim speed, the straight run settles at trim_speed(model, rpm)."""
    v = load_vehicle('nps_auv2')
    u_trim = trim_speed(Model(v), rpm)
    cfg = DataConfig(duration=3000.0, rpm=rpm, u0=0.5 * u_trim, lead_in=1e9, noise='none',
                     odom_rate=0.2)
    data = generate(cfg, tmp_path / 'r')
    u = data.x_true[:, 0]
    assert u[0] == pytest.approx(0.5 * u_trim)
    assert np.all(np.diff(u) > -1e-12)               # accelerates monotonically
    assert u[-1] == pytest.approx(u_trim, rel=1e-7)
    # (MSS's 4-digit inverse of M couples surge into heave/pitch while accelerating: small)
    np.testing.assert_allclose(data.x_true[-1, 1:6], 0.0, atol=1e-9)
    # position = the integral of the surge speed (Simpson on 5 s samples, smooth)
    from scipy.integrate import simpson
    assert data.x_true[-1, 6] == pytest.approx(simpson(u, x=data.t_odom), rel=1e-6)


def test_own_kinematics_match_the_model_rows():
    v = load_vehicle('nps_auv2')
    model = Model(v)
    rng = np.random.default_rng(0)
    dyn = gen.Dynamics(model, (0.0, 0.0, 0.0))
    for _ in range(50):
        x = np.concatenate([[rng.uniform(0.3, 1.5)], rng.normal(0, 0.1, 5),
                            rng.normal(0, 10, 3), rng.uniform(-0.5, 0.5, 2),
                            [rng.uniform(-3, 3)]])
        dyn.u[:] = [*rng.uniform(-0.3, 0.3, 5), 500.0, 0.0]
        mine = dyn(0.0, x)
        ref = model.f(x, dyn.u)
        np.testing.assert_allclose(mine, ref, rtol=1e-12, atol=1e-14)
    # quaternion of Rz Ry Rx against the rotation matrix
    for _ in range(20):
        phi, th, psi = rng.uniform(-1, 1, 3)
        qx, qy, qz, qw = gen.quaternion(phi, th, psi)
        x, y, z, w = qx, qy, qz, qw
        Rq = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                       [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                       [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        np.testing.assert_allclose(Rq, gen.rotation(phi, th, psi), atol=1e-14)


def test_dop853_and_rk4_agree_on_a_manoeuvre(tmp_path):
    common = dict(duration=40.0, lead_in=1.0, noise='none', odom_rate=5.0, odom_jitter=0.2,
                  rudder_hold=(8.0, 10.0), current_ned=(0.05, -0.1, 0.0))
    a = generate(DataConfig(integrator='dop853', **common), tmp_path / 'a')
    b = generate(DataConfig(integrator='rk4', rk4_dt=0.002, **common), tmp_path / 'b')
    assert np.abs(a.x_true[:, 11]).max() > 0.1       # it did turn
    assert np.abs(a.x_true[:, 4]).max() > 0.005      # and pitch
    scale = np.maximum(np.abs(a.x_true).max(axis=0), 1e-3)
    assert np.max(np.abs(a.x_true - b.x_true) / scale) < 1e-7


# --------------------------------------------------------------------------------- command line


def test_command_line(tmp_path, capsys):
    out = tmp_path / 'cli'
    rc = gen.main(['--out', str(out), '--duration', '3', '--odom-rate', '5', '--gaps', '1:0.5',
                   '--current-ned', '0.1,0,0', '--perturb', '0.1', '--perturb-keep', 'Z_w,K_v',
                   '--noise', 'ar1', '--noise-tau', '2', '--commands', 'periodic'])
    assert rc == 0
    assert 'wrote' in capsys.readouterr().out
    doc = json.loads((out / 'truth.json').read_text())
    assert doc['config']['gaps'] == [[1.0, 0.5]]
    assert doc['config']['perturb_keep'] == ['Z_w', 'K_v']
    assert doc['current_ned'] == [0.1, 0.0, 0.0]
    assert doc['factors']['Z_w'] == 1.0 and doc['factors']['M_ds'] != 1.0
    assert (out / 'bag' / 'metadata.yaml').is_file() and (out / 'truth_vehicle.yaml').is_file()
    with pytest.raises(FileExistsError):
        gen.main(['--out', str(out), '--duration', '1'])
