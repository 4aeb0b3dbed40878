"""Importing measured runs (offline/importers.py, column_map.py, import_bag.py, `import`): the HSVA
KVLCC2 files checked against the data themselves (independent parse with numpy), the bag they
become (strictly decodable, read by today's readers, replayed without a rejection), a CSV
round trip through column maps in other units, signs and frames, and every bad-input error.

The HSVA files are public SIMMAN data we may not commit: they are read from ../shared/realdata
(relative to the repository root) and the tests that need them skip when it is absent."""
from collections import Counter
import csv
import hashlib
import json
import math
from pathlib import Path

import helpers
from mcap.reader import make_reader
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores
import yaml

from auv_ident.bags.info import bag_info
from auv_ident.bags.reader import read_bag
from auv_ident.cli import main as cli_main
from auv_ident.core.model.state import Input, State
from auv_ident.offline.column_map import ColumnMap, ColumnMapError
from auv_ident.offline.import_bag import (
    HSVA_EPOCH,
    parse_epoch,
    TOPIC_TYPES,
    UNMEASURED_VARIANCE,
    write_imported_bag,
)
from auv_ident.offline.importers import read_csv_run, read_hsva, RunFileError, white_noise_std
from auv_ident.offline.replay import bag_custom_data, replay_bag
from auv_ident.session.messages import (
    JOINT_NAMES,
    joint_state_to_actuators,
    NS_PER_S,
    odometry_to_state,
    odometry_variances,
    RPM_TO_RAD_S,
)
from auv_ident.session.settings import IdentifierSettings

REPO = Path(helpers.REPO)
DATA = REPO.parent / 'shared' / 'realdata' / 'kvlcc2_hsva'
# file -> (data rows, sign of the first rudder deflection: starboard first is negative)
HSVA = {'HSVA_CPMC_KVLCC2_Z_10_10_S.dat': (1341, -1), 'HSVA_CPMC_KVLCC2_Z_10_10_P.dat': (1321, 1),
        'HSVA_CPMC_KVLCC2_Z_20_10_S.dat': (3801, -1), 'HSVA_CPMC_KVLCC2_Z_20_10_P.dat': (3801, 1)}
JAZZY = get_typestore(Stores.ROS2_JAZZY)
MEASURED = ['u', 'v', 'r', 'x', 'y', 'phi', 'psi']


def hsva_file(name):
    path = DATA / name
    if not path.is_file():
        pytest.skip(f'{path} absent: the HSVA KVLCC2 data are not ours to commit; they are read '
                    'from ../shared/realdata (relative to the repository root)')
    return path


def raw(path):
    """The file's 12 columns, parsed independently of the importer."""
    return np.loadtxt(path, skiprows=4, encoding='iso-8859-1')


@pytest.fixture(scope='module')
def s_run():
    return read_hsva(hsva_file('HSVA_CPMC_KVLCC2_Z_10_10_S.dat'))


@pytest.fixture(scope='module')
def s_bag(s_run, tmp_path_factory):
    return write_imported_bag(s_run, tmp_path_factory.mktemp('imp') / 'z10s')


# --- the HSVA files -------------------------------------------------------------------------


@pytest.mark.parametrize('name', sorted(HSVA))
def test_hsva_file_reads_into_our_state(name):
    path = hsva_file(name)
    rows, _ = HSVA[name]
    run = read_hsva(path)
    a = raw(path)
    assert len(run.t_ns) == rows == len(a)
    assert run.t_ns[0] == 0 and np.all(np.diff(run.t_ns) == NS_PER_S // 20)    # 20 Hz, t=0 kept
    assert run.measured_names == MEASURED
    u, v = run.x[:, State.U], run.x[:, State.V]
    assert u[0] == pytest.approx(1.18, abs=0.005) and abs(v[0]) < 0.005
    # independent: u, v from the earth-fixed columns; angles and rates in rad
    psi = np.radians(a[:, 3])
    np.testing.assert_allclose(u, a[:, 4] * np.cos(psi) + a[:, 5] * np.sin(psi), atol=1e-12)
    np.testing.assert_allclose(v, -a[:, 4] * np.sin(psi) + a[:, 5] * np.cos(psi), atol=1e-12)
    np.testing.assert_allclose(run.x[:, State.PSI], psi, atol=1e-12)
    np.testing.assert_allclose(run.x[:, State.R], np.radians(a[:, 6]), atol=1e-15)
    np.testing.assert_allclose(run.x[:, State.PHI], np.radians(a[:, 7]), atol=1e-15)
    np.testing.assert_allclose(run.x[:, [State.X, State.Y]], a[:, 1:3], atol=0)
    assert not np.any(run.x[:, [State.W, State.P, State.Q, State.Z, State.THETA]])
    np.testing.assert_allclose(run.inputs['rudder'], np.radians(a[:, 8]), atol=1e-15)
    np.testing.assert_array_equal(run.inputs['thrust'], a[:, 10])
    np.testing.assert_allclose(run.inputs['shaft'], 60.0 * 10.2295, rtol=1e-15)
    assert run.sha256 == hashlib.sha256(path.read_bytes()).hexdigest()
    # the noise estimate: positive, far below each channel's motion
    std = run.noise_std[run.measured]
    spread = np.ptp(run.x[:, run.measured], axis=0)
    assert np.all(std > 0) and np.all(std < 1e-2 * spread)
    assert np.all(np.isnan(run.noise_std[~run.measured]))


@pytest.mark.parametrize('name', sorted(HSVA))
def test_rudder_sign_is_ours_a_positive_rudder_turns_to_port(name):
    """The first deflection of a starboard-first zigzag is negative (delta positive to port, as
    our delta_r: N_dr < 0), and the heading then turns the way the rudder says: to starboard
    (psi and r growing) for a negative rudder."""
    run = read_hsva(hsva_file(name))
    _, first_sign = HSVA[name]
    rud = run.inputs['rudder']
    k = int(np.flatnonzero(np.abs(rud) > math.radians(5.0))[0])
    assert np.sign(rud[k]) == first_sign
    later = k + 60                              # 3 s on, before the rudder is reversed
    assert np.sign(run.x[later, State.R]) == -first_sign
    assert np.sign(run.x[later, State.PSI] - run.x[k, State.PSI]) == -first_sign


@pytest.mark.parametrize('name', sorted(HSVA))
def test_heading_position_and_velocities_are_consistent(name):
    """Back to the world with psi (NED: x north-like, y east-like, psi positive to starboard),
    the body velocities integrate to the measured track (3 mm over 66-190 s; a left-handed
    reading would run off by metres), the course follows psi within the drift angle, and r is
    dpsi/dt."""
    run = read_hsva(hsva_file(name))
    t, x = run.t, run.x
    psi, u, v = x[:, State.PSI], x[:, State.U], x[:, State.V]
    xdot = u * np.cos(psi) - v * np.sin(psi)
    ydot = u * np.sin(psi) + v * np.cos(psi)
    steps = 0.5 * np.diff(t)
    xi = x[0, State.X] + np.concatenate([[0.0], np.cumsum(steps * (xdot[1:] + xdot[:-1]))])
    yi = x[0, State.Y] + np.concatenate([[0.0], np.cumsum(steps * (ydot[1:] + ydot[:-1]))])
    assert np.max(np.abs(xi - x[:, State.X])) < 0.005
    assert np.max(np.abs(yi - x[:, State.Y])) < 0.005
    mirrored = x[0, State.Y] + np.concatenate(
        [[0.0], np.cumsum(steps * (-(ydot[1:] + ydot[:-1])))])
    assert np.max(np.abs(mirrored - x[:, State.Y])) > 1.0
    drift = np.angle(np.exp(1j * (np.arctan2(ydot, xdot) - psi)))
    assert np.max(np.abs(drift)) < math.radians(15.0)     # 11.7 deg at most, 20/10 runs
    rms = np.sqrt(np.mean((np.gradient(psi, t) - x[:, State.R]) ** 2))
    assert rms < 0.05 * np.sqrt(np.mean(x[:, State.R] ** 2))


# --- the bag ---------------------------------------------------------------------------------


def test_hsva_bag_topics_stamps_and_messages(s_run, s_bag):
    path = hsva_file('HSVA_CPMC_KVLCC2_Z_10_10_S.dat')
    a = raw(path)
    n = len(a)
    epoch = parse_epoch(HSVA_EPOCH)
    assert epoch == 1_136_073_600 * NS_PER_S
    counts = Counter()
    with open(s_bag / 'z10s_0.mcap', 'rb') as fh:      # strict rosbags decoding, no fallback
        for _, channel, message in make_reader(fh).iter_messages(log_time_order=True):
            JAZZY.deserialize_cdr(message.data, TOPIC_TYPES[channel.topic])
            counts[channel.topic] += 1
    assert counts == {'/odom': n, '/actuators': n}
    odom, act = [], []
    for topic, t_ns, msg in read_bag(s_bag):
        (odom if topic == '/odom' else act).append((t_ns, msg))
    for k in (0, 1, 700, n - 1):
        t_ns, msg = odom[k]
        assert t_ns == epoch + round(a[k, 0] * 20) * NS_PER_S // 20
        t_sec, x12, _, _ = odometry_to_state(msg)
        assert t_sec == t_ns / NS_PER_S
        assert msg.header.frame_id == 'odom_ned' and msg.child_frame_id == 'base_link_frd'
        np.testing.assert_allclose(x12, s_run.x[k], atol=1e-12)
        var = odometry_variances(msg)
        meas = s_run.measured
        np.testing.assert_allclose(var[meas], s_run.noise_std[meas] ** 2, rtol=1e-12)
        assert np.all(var[~meas] == UNMEASURED_VARIANCE)
        ta, js = act[k]
        assert ta == t_ns and list(js.name) == list(JOINT_NAMES)
        _, u7 = joint_state_to_actuators(js)            # today's reader
        assert u7[Input.DELTA_R] == pytest.approx(math.radians(a[k, 8]), abs=1e-15)
        assert not np.any(u7[1:5])
        assert u7[Input.N_RPM] == pytest.approx(613.77, rel=1e-12)
        assert js.velocity[5] == pytest.approx(10.2295 * 2 * math.pi, rel=1e-12)
        assert list(js.effort) == [0.0] * 5 + [a[k, 10]]          # thrust (N), propeller
        assert u7[Input.THRUST] == a[k, 10]                       # read as the thrust input
        assert js.velocity[5] / RPM_TO_RAD_S == pytest.approx(u7[Input.N_RPM])


def test_hsva_bag_metadata_and_bag_info(s_run, s_bag):
    path = hsva_file('HSVA_CPMC_KVLCC2_Z_10_10_S.dat')
    meta = bag_custom_data(s_bag)
    assert meta['auv_ident.vehicle'] == 'kvlcc2_hsva'
    assert meta['auv_ident.simulated'] == 'false' and meta['auv_ident.format'] == 'hsva'
    assert meta['auv_ident.frame'] == 'ned'
    assert meta['auv_ident.source'] == path.name
    assert meta['auv_ident.source_sha256'] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert meta['auv_ident.stamp_epoch'] == HSVA_EPOCH
    assert meta['auv_ident.stamp_epoch_nominal'] == 'true'
    assert meta['auv_ident.measured'] == ' '.join(MEASURED)
    assert meta['auv_ident.measured_inputs'] == 'rudder shaft thrust'
    cmap = json.loads(meta['auv_ident.column_map'])
    assert cmap['xdot'] == {'column': 'xdot0', 'unit': 'm/s', 'frame': 'earth'}
    assert cmap['rudder'] == {'column': 'delta', 'unit': 'deg'}
    ColumnMap(cmap)                                     # the stored map is a valid map
    info = bag_info(s_bag)
    assert info.message_count == 2 * len(s_run.t_ns)
    assert info.start_ns == parse_epoch(HSVA_EPOCH)
    assert info.duration_ns == 67 * NS_PER_S
    assert {t.name: t.count for t in info.topics} == {'/odom': 1341, '/actuators': 1341}


def test_replay_reads_every_message_without_a_rejection(s_run, s_bag):
    """Through the identifier's own per-message logic (frame ids, finiteness, plausibility,
    command screening, time line): every odometry and every command accepted. The model is
    NPS AUV II's with a wide noise and the file's measured channels, so that no innovation gate
    (a model question, not a reading one) can reject anything."""
    res = replay_bag(s_bag, IdentifierSettings.from_values(vehicle='nps_auv2',
                                                           other_vehicle=True,
                                                           noise_source='parameter',
                                                           noise_std=np.full(12, 10.0),
                                                           measured=tuple(MEASURED)))
    n = len(s_run.t_ns)
    assert (res.accepted, res.rejected, res.commands, res.errors) == (n, 0, n, 0)
    assert not res.reasons
    np.testing.assert_allclose(res.t, s_run.t, atol=1e-9)
    np.testing.assert_allclose(res.Y[:, s_run.measured], s_run.x[:, s_run.measured],
                               atol=1e-12)


def test_start_option_sets_the_stamps(s_run, tmp_path):
    bag = write_imported_bag(s_run, tmp_path / 'b', start='2006-05-17T10:00:00.5+02:00')
    meta = bag_custom_data(bag)
    epoch = 1_147_852_800 * NS_PER_S + NS_PER_S // 2     # 2006-05-17T08:00:00.5Z
    assert int(meta['auv_ident.stamp_epoch_ns']) == epoch
    assert meta['auv_ident.stamp_epoch_nominal'] == 'false'
    assert bag_info(bag).start_ns == epoch


def test_cli_import_hsva(tmp_path, capsys):
    path = hsva_file('HSVA_CPMC_KVLCC2_Z_10_10_P.dat')
    out = tmp_path / 'p'
    assert cli_main(['import', '--format', 'hsva', str(path), '--out', str(out)]) == 0
    text = capsys.readouterr().out
    assert '1321 samples' in text and 'measured: u v r x y phi psi' in text
    assert bag_info(out).message_count == 2 * 1321
    assert cli_main(['import', '--format', 'hsva', str(path), '--out', str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'exists already' in err[0]


# --- CSV: round trip -------------------------------------------------------------------------


def _write_csv(path, header, rows, delimiter=','):
    with open(path, 'w', newline='', encoding='utf-8') as fh:
        w = csv.writer(fh, delimiter=delimiter)
        w.writerow(header)
        w.writerows(rows)
    return path


def _write_map(path, doc):
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding='utf-8')
    return path


def test_csv_round_trip_body_velocities_other_units_and_signs(s_run, tmp_path):
    """An HSVA run written as a log in ms, knots, deg, kN, a heading and a rudder of the other
    sign, ';'-separated, reads back to the same state, inputs and stamps."""
    x, inp = s_run.x, s_run.inputs
    kn = 1852.0 / 3600.0
    rows = [[str(int(s_run.t_ns[k]) / 1e6)]
            + [repr(float(val)) for val in (
                x[k, State.X], x[k, State.Y], -math.degrees(x[k, State.PSI]),
                x[k, State.U] / kn, x[k, State.V] / kn, math.degrees(x[k, State.R]),
                math.degrees(x[k, State.PHI]), -math.degrees(inp['rudder'][k]),
                inp['thrust'][k] / 1000.0, inp['shaft'][k])] + ['note']
            for k in range(len(s_run.t_ns))]
    csv_path = _write_csv(tmp_path / 'log.csv', ['time_ms', 'north', 'east', 'hdg_port',
                                                 'u_kn', 'v_kn', 'yaw_rate', 'roll',
                                                 'rudder_stbd', 'T_kN', 'rpm', 'comment'],
                          rows, delimiter=';')
    map_path = _write_map(tmp_path / 'map.yaml', {
        'delimiter': ';',
        'time': {'column': 'time_ms', 'unit': 'ms'},
        'x': {'column': 'north', 'unit': 'm'}, 'y': {'column': 'east', 'unit': 'm'},
        'psi': {'column': 'hdg_port', 'unit': 'deg', 'sign': -1},
        'u': {'column': 'u_kn', 'unit': 'kn', 'frame': 'body'},
        'v': {'column': 'v_kn', 'unit': 'kn'},
        'r': {'column': 'yaw_rate', 'unit': 'deg/s'},
        'phi': {'column': 'roll', 'unit': 'deg'},
        'rudder': {'column': 'rudder_stbd', 'unit': 'deg', 'sign': -1},
        'thrust': {'column': 'T_kN', 'unit': 'kN'},
        'shaft': {'column': 'rpm', 'unit': 'rpm'}})
    run = read_csv_run(csv_path, map_path)
    np.testing.assert_array_equal(run.t_ns, s_run.t_ns)
    np.testing.assert_array_equal(run.measured, s_run.measured)
    np.testing.assert_allclose(run.x, s_run.x, rtol=1e-13, atol=1e-15)
    for key in ('rudder', 'thrust', 'shaft'):
        np.testing.assert_allclose(run.inputs[key], inp[key], rtol=1e-13, atol=1e-16)
    np.testing.assert_allclose(run.noise_std, s_run.noise_std, rtol=1e-6)
    bag = write_imported_bag(run, tmp_path / 'bag', vehicle='kvlcc2_hsva',
                             start=HSVA_EPOCH)
    meta = bag_custom_data(bag)
    assert meta['auv_ident.format'] == 'csv' and meta['auv_ident.source'] == 'log.csv'
    assert json.loads(meta['auv_ident.column_map'])['psi']['sign'] == -1
    msgs = [m for topic, _, m in read_bag(bag) if topic == '/odom']
    np.testing.assert_allclose(odometry_to_state(msgs[500])[1], s_run.x[500], atol=1e-12)


def test_csv_round_trip_enu_world_and_earth_velocities(s_run, tmp_path):
    """The same run logged in ENU (x east, y north, yaw counterclockwise from east), with
    earth-fixed velocities and unix-second stamps."""
    x = s_run.x
    psi, u, v = x[:, State.PSI], x[:, State.U], x[:, State.V]
    vn, ve = u * np.cos(psi) - v * np.sin(psi), u * np.sin(psi) + v * np.cos(psi)
    t0 = 1_700_000_000
    rows = [[f'{t0 + s_run.t_ns[k] / 1e9:.2f}']
            + [repr(float(val)) for val in (x[k, State.Y], x[k, State.X], math.pi / 2 - psi[k],
                                            ve[k], vn[k], -x[k, State.R])]
            for k in range(len(psi))]
    csv_path = _write_csv(tmp_path / 'enu.csv', ['stamp', 'e', 'n', 'yaw', 've', 'vn', 'wz'],
                          rows)
    map_path = _write_map(tmp_path / 'map.yaml', {
        'world': 'enu', 'time': {'column': 'stamp', 'unit': 's', 'base': 'unix'},
        'x': {'column': 'e', 'unit': 'm'}, 'y': {'column': 'n', 'unit': 'm'},
        'psi': {'column': 'yaw', 'unit': 'rad'},
        'xdot': {'column': 've', 'unit': 'm/s', 'frame': 'earth'},
        'ydot': {'column': 'vn', 'unit': 'm/s', 'frame': 'earth'},
        'r': {'column': 'wz', 'unit': 'rad/s'}})
    run = read_csv_run(csv_path, map_path)
    assert run.absolute
    np.testing.assert_array_equal(run.t_ns, t0 * NS_PER_S + s_run.t_ns)
    assert run.measured_names == ['u', 'v', 'r', 'x', 'y', 'psi']
    cols = [State.U, State.V, State.R, State.X, State.Y, State.PSI]
    np.testing.assert_allclose(run.x[:, cols], x[:, cols], atol=1e-12)
    assert run.inputs == {}
    bag = write_imported_bag(run, tmp_path / 'bag', vehicle='nps_auv2')
    assert bag_info(bag).start_ns == t0 * NS_PER_S
    with pytest.raises(ColumnMapError, match='absolute'):
        write_imported_bag(run, tmp_path / 'bag2', vehicle='nps_auv2', start=HSVA_EPOCH)


def test_earth_velocities_with_zdot_use_the_full_rotation(tmp_path):
    """With zdot, nu = R(phi, theta, psi)^T v_n: a body velocity rotated out comes back."""
    rng = np.random.default_rng(3)
    n = 50
    ang = rng.uniform(-0.5, 0.5, (n, 3))
    nu = rng.uniform(-2.0, 2.0, (n, 3))
    from auv_ident.session.messages import euler_to_rotation_matrix
    vn = np.array([euler_to_rotation_matrix(*ang[k]) @ nu[k] for k in range(n)])
    rows = [[k * 0.1] + [repr(float(val)) for val in (*ang[k], *vn[k])] for k in range(n)]
    csv_path = _write_csv(tmp_path / 'a.csv', ['t', 'r', 'p', 'y', 'vx', 'vy', 'vz'], rows)
    doc = {'time': {'column': 't', 'unit': 's'}, 'phi': {'column': 'r', 'unit': 'rad'},
           'theta': {'column': 'p', 'unit': 'rad'}, 'psi': {'column': 'y', 'unit': 'rad'},
           'xdot': {'column': 'vx', 'unit': 'm/s'}, 'ydot': {'column': 'vy', 'unit': 'm/s'},
           'zdot': {'column': 'vz', 'unit': 'm/s'}}
    run = read_csv_run(csv_path, ColumnMap(doc))
    np.testing.assert_allclose(run.x[:, State.U:State.W + 1], nu, atol=1e-12)
    assert run.measured_names == ['u', 'v', 'w', 'phi', 'theta', 'psi']


def test_the_documented_example_map_is_valid():
    """docs/bags.md's complete example column map is a valid map, in ENU, every quantity."""
    text = (REPO / 'docs' / 'bags.md').read_text(encoding='utf-8')
    section = text[text.index('### CSV logs and the column map'):]
    block = section[section.index('```yaml') + len('```yaml'):]
    doc = yaml.safe_load(block[:block.index('```')])
    cmap = ColumnMap(doc)
    assert cmap.world == 'enu' and cmap.time_base == 'unix'
    assert set(doc) - {'world', 'delimiter'} == {'time', 'x', 'y', 'z', 'phi', 'theta', 'psi',
                                                 'xdot', 'ydot', 'r', 'rudder', 'thrust',
                                                 'shaft'}


def test_white_noise_std_of_a_smooth_signal_with_white_noise():
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 200.0, 0.05)
    clean = 0.3 * np.sin(2 * np.pi * t / 30.0) + 0.01 * t
    est = white_noise_std(clean + 2e-3 * rng.standard_normal(t.size))
    assert est == pytest.approx(2e-3, rel=0.05)
    assert white_noise_std(clean) < 2e-5       # the motion's own second differences
    assert white_noise_std(np.full(100, 0.2)) == 0.0
    assert white_noise_std([1.0, 2.0, 3.0]) == 0.0


# --- bad input: one error naming the culprit ----------------------------------------------------

GOOD_MAP = {'time': {'column': 't', 'unit': 's'}, 'psi': {'column': 'hdg', 'unit': 'deg'},
            'u': {'column': 'u', 'unit': 'm/s'}, 'rudder': {'column': 'd', 'unit': 'deg'}}
GOOD_ROWS = [['0.0', '1.0', '1.2', '0.0'], ['0.05', '1.1', '1.2', '0.5'],
             ['0.10', '1.2', '1.2', '1.0'], ['0.15', '1.3', '1.2', '1.5']]


def _case(tmp_path, doc=None, rows=None, header=('t', 'hdg', 'u', 'd')):
    csv_path = _write_csv(tmp_path / 'run.csv', list(header), GOOD_ROWS if rows is None else rows)
    map_path = _write_map(tmp_path / 'map.yaml', GOOD_MAP if doc is None else doc)
    return csv_path, map_path


def test_good_case_reads(tmp_path):
    run = read_csv_run(*_case(tmp_path))
    assert len(run.t_ns) == 4 and run.measured_names == ['u', 'psi']


def _with(**changes):
    doc = {k: dict(v) for k, v in GOOD_MAP.items()}
    for key, val in changes.items():
        if val is None:
            doc.pop(key)
        else:
            doc[key] = val
    return doc


BAD_MAPS = [
    (_with(speed={'column': 'u', 'unit': 'm/s'}), r"map.yaml: unknown quantity 'speed'; known:"),
    (_with(psi={'column': 'hdg', 'unit': 'grad'}),
     r"map.yaml: psi: unknown unit 'grad'; psi takes rad, deg"),
    (_with(psi={'column': 'hdg'}), r'map.yaml: psi: give its unit \(one of rad, deg\)'),
    (_with(psi={'column': 'heading', 'unit': 'deg'}),
     r"map.yaml: column\(s\) 'heading' not in .*run.csv; its columns: t, hdg, u, d"),
    (_with(u={'column': 'u', 'unit': 'm/s', 'frame': 'earth'}),
     r"map.yaml: u: frame 'earth', but u is a body-frame quantity: for an earth-fixed "
     r'velocity use xdot'),
    (_with(psi={'column': 'hdg', 'unit': 'deg', 'frame': 'body'}),
     r'map.yaml: psi: frame does not apply to psi'),
    (_with(psi={'column': 'hdg', 'unit': 'deg', 'sign': 2}),
     r'map.yaml: psi: sign must be 1 or -1, got 2'),
    (_with(psi={'column': 'hdg', 'unit': 'deg', 'scale': 2}),
     r'map.yaml: psi: unknown field\(s\) scale'),
    (_with(time=None), r'map.yaml: no time entry'),
    (_with(time={'column': 't', 'unit': 's', 'base': 'gps'}),
     r"map.yaml: time: base must be run or unix, got 'gps'"),
    (_with(xdot={'column': 'u', 'unit': 'm/s'}, ydot={'column': 'u', 'unit': 'm/s'}),
     r'map.yaml: both u and xdot'),
    (_with(u=None, psi=None, xdot={'column': 'u', 'unit': 'm/s'},
           ydot={'column': 'u', 'unit': 'm/s'}), r'map.yaml: earth-fixed velocities need the '
                                                 r'heading psi'),
    (_with(u=None, psi=None), r'map.yaml: no state quantity mapped'),
    (dict(GOOD_MAP, world='nwu'), r"map.yaml: world must be ned or enu, got 'nwu'"),
    (['time'], r'map.yaml: must be a mapping'),
]


@pytest.mark.parametrize('doc, message', BAD_MAPS)
def test_bad_column_map_is_one_clear_error(tmp_path, doc, message):
    with pytest.raises(ColumnMapError, match=message):
        read_csv_run(*_case(tmp_path, doc=doc))


BAD_ROWS = [
    ([GOOD_ROWS[0], ['0.05', 'abc', '1.2', '0.5']], RunFileError,
     r"run.csv: line 3, column 'hdg': 'abc' is not a finite number"),
    ([GOOD_ROWS[0], ['0.05', '1,5', '1.2', '0.5']], RunFileError,
     r"run.csv: line 3, column 'hdg': '1,5' has a decimal comma; write numbers with a decimal "
     r'point \(1.5\)'),
    ([GOOD_ROWS[0], ['0,05', '1.0', '1.2', '0.5']], ColumnMapError,
     r"run.csv: line 3, column 't': '0,05' has a decimal comma"),
    ([GOOD_ROWS[0], ['0.05', '1.0', '-', '0.5']], RunFileError,
     r"run.csv: line 3, column 'u': '-' is not a finite number"),
    ([['0.0', 'nan', '1.2', '0.0'], ['0.05', '1.0', 'inf', '0.5']], RunFileError,
     r'run.csv: every data row has a NaN or Inf'),
    ([['0.0', '', '1.2', '0.0'], ['0.05', '', '1.2', '0.5']], RunFileError,
     r"run.csv: column 'hdg' \(psi\) has no value in any row"),
    ([GOOD_ROWS[0], ['', '1.0', '1.2', '0.5']], ColumnMapError,
     r"run.csv: line 3, column 't': time '' is not a finite number"),
    ([GOOD_ROWS[0], ['x', '1.0', '1.2', '0.5']], ColumnMapError,
     r"run.csv: line 3, column 't': time 'x' is not a finite number"),
    ([GOOD_ROWS[0], GOOD_ROWS[1], ['0.05', '1.0', '1.2', '0.5']], RunFileError,
     r"run.csv: line 4, column 't': time does not increase \(0.05 s on line 3, then 0.05 s\)"),
    ([GOOD_ROWS[0], ['0.05', '1.0', '1.2']], RunFileError,
     r'run.csv: line 3: 3 fields, the header has 4'),
    ([], RunFileError, r'run.csv: no data rows'),
]


@pytest.mark.parametrize('rows, error, message', BAD_ROWS)
def test_bad_csv_is_one_clear_error(tmp_path, rows, error, message):
    with pytest.raises(error, match=message):
        read_csv_run(*_case(tmp_path, rows=rows))


def test_decimal_commas_in_a_comma_separated_file_are_named(tmp_path):
    path = tmp_path / 'dc.csv'
    path.write_text('t,hdg,u,d\n0.0,1.0,1.2,0.0\n0.05,1,1,1.2,0.5\n', encoding='utf-8')
    with pytest.raises(RunFileError, match=r'line 3: 5 fields, the header has 4 \(decimal '
                                           r'commas\? write numbers with a decimal point\)'):
        read_csv_run(path, _case(tmp_path)[1])
    semi = _write_csv(tmp_path / 'semi.csv', ['t', 'hdg', 'u', 'd'], GOOD_ROWS, delimiter=';')
    with pytest.raises(ColumnMapError, match=r"the fields are separated by ';', not ',' \(set "
                                             r"delimiter: ';'"):
        read_csv_run(semi, _case(tmp_path)[1])


def test_blank_cells_and_nan_rows(tmp_path):
    """A blank cell is no sample at that row; a row with a NaN is skipped and counted; an input
    logged on change holds its value."""
    rows = [['0.0', '1.0', '1.2', '0.0'], ['0.05', '1.1', '', ''], ['0.10', 'NaN', '1.2', ''],
            ['0.15', '1.3', '', '1.5'], ['0.20', '1.4', '1.3', '']]
    run = read_csv_run(*_case(tmp_path, rows=rows))
    assert run.skipped == (4,) and len(run.t_ns) == 4
    assert run.samples == {'u': 2, 'psi': 4}
    assert np.isnan(run.x[1, State.U]) and run.x[3, State.U] == 1.3
    np.testing.assert_allclose(np.degrees(run.inputs['rudder']), [0.0, 0.0, 1.5, 1.5])
    bag = write_imported_bag(run, tmp_path / 'bag', vehicle='kvlcc2_hsva')
    odom = [odometry_to_state(m)[1] for t, _, m in read_bag(bag) if t == '/odom']
    var = [odometry_variances(m) for t, _, m in read_bag(bag) if t == '/odom']
    assert [v[State.U] == UNMEASURED_VARIANCE for v in var] == [False, True, True, False]
    assert [x[State.U] for x in odom] == [1.2, 0.0, 0.0, 1.3]
    meta = bag_custom_data(bag)
    assert meta['auv_ident.skipped_rows'] == '1'
    assert meta['auv_ident.channel_samples'] == 'u:2 psi:4'


def _multi_rate_rows(run):
    """A log of a simulated nps_auv2 run as a vehicle writes one: the attitude and rates
    (IMU) every 0.05 s, the DVL's u v w every 0.2 s, depth every 0.1 s, position never, the
    six actuators only when they change (fins in deg), one isolated NaN row."""
    header = ['time', 'roll', 'pitch', 'yaw', 'p', 'q', 'r', 'dvl_u', 'dvl_v', 'dvl_w', 'depth',
              'rudder', 'stern', 'bow', 'bow_p', 'bow_s', 'rpm']
    rows, last = [], None
    for k, t in enumerate(run.t):
        y, u = run.y[k], run.u[k]
        row = [f'{t:.2f}'] + [repr(float(v)) for v in (y[State.PHI], y[State.THETA],
                                                        y[State.PSI], y[State.P], y[State.Q],
                                                        y[State.R])]
        row += ([repr(float(y[i])) for i in (State.U, State.V, State.W)] if k % 4 == 0
                else ['', '', ''])
        row += [repr(float(y[State.Z]))] if k % 2 == 0 else ['']
        cmd = [repr(math.degrees(float(v))) for v in u[:5]] + [repr(float(u[Input.N_RPM]))]
        row += [c if last is None or c != last[i] else '' for i, c in enumerate(cmd)]
        last = cmd
        rows.append(row)
    rows[501][1] = 'nan'
    return header, rows


MULTI_RATE_MAP = {
    'time': {'column': 'time', 'unit': 's'},
    'phi': {'column': 'roll', 'unit': 'rad'}, 'theta': {'column': 'pitch', 'unit': 'rad'},
    'psi': {'column': 'yaw', 'unit': 'rad'}, 'p': {'column': 'p', 'unit': 'rad/s'},
    'q': {'column': 'q', 'unit': 'rad/s'}, 'r': {'column': 'r', 'unit': 'rad/s'},
    'u': {'column': 'dvl_u', 'unit': 'm/s'}, 'v': {'column': 'dvl_v', 'unit': 'm/s'},
    'w': {'column': 'dvl_w', 'unit': 'm/s'}, 'z': {'column': 'depth', 'unit': 'm'},
    'rudder': {'column': 'rudder', 'unit': 'deg'},
    'stern_planes': {'column': 'stern', 'unit': 'deg'},
    'bow_planes': {'column': 'bow', 'unit': 'deg'},
    'bow_plane_port': {'column': 'bow_p', 'unit': 'deg'},
    'bow_plane_starboard': {'column': 'bow_s', 'unit': 'deg'},
    'shaft': {'column': 'rpm', 'unit': 'rpm'}}


def test_a_multi_rate_log_with_every_actuator_is_identified(tmp_path, capsys):
    """IMU at 20 Hz, DVL at 5 Hz, depth at 10 Hz, the stern and bow planes among the actuators
    logged on change, one NaN row: imported, every accepted sample uses only what was sampled,
    and the replay identifies the coefficients near the truth (blank cells taken as zeros
    would not)."""
    from auv_ident.core.model.hydrodynamics import Model
    from auv_ident.core.simulation.simulate import simulate
    from auv_ident.vehicles import load_vehicle
    run = simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=120.0, seed=4)
    header, rows = _multi_rate_rows(run)
    csv_path = _write_csv(tmp_path / 'auv.csv', header, rows)
    map_path = _write_map(tmp_path / 'auv.yaml', MULTI_RATE_MAP)
    assert cli_main(['import', '--format', 'csv', str(csv_path), '--columns', str(map_path),
                     '--vehicle', 'nps_auv2', '--out', str(tmp_path / 'bag')]) == 0
    out = capsys.readouterr().out
    n = len(run.t)
    assert f'samples per channel: u {(n + 3) // 4}, v {(n + 3) // 4}' in out
    assert 'skipped 1 rows with NaN or Inf (lines 503)' in out and 'note:' not in out
    imported = read_csv_run(csv_path, map_path)
    np.testing.assert_allclose(imported.inputs['stern_planes'],
                               np.delete(run.u[:, Input.DELTA_S], 501), atol=1e-12)
    res = replay_bag(tmp_path / 'bag', warn=False)
    assert res.accepted == n - 1 and res.rejected == 0
    np.testing.assert_allclose(res.U, np.delete(run.u, 501, axis=0), atol=1e-12)
    truth = res.truth[:4]       # Z_ds Z_q Z_w M_ds
    assert np.all(np.abs(res.estimate[:4] / truth - 1) < 0.1), res.estimate[:4]


def test_bad_files_and_options(tmp_path, s_run):
    csv_path, map_path = _case(tmp_path)
    with pytest.raises(RunFileError, match=r"header names column\(s\) 'u' more than once"):
        read_csv_run(_write_csv(tmp_path / 'dup.csv', ['t', 'hdg', 'u', 'u'], GOOD_ROWS),
                     map_path)
    (tmp_path / 'empty.csv').write_text('\n\n', encoding='utf-8')
    with pytest.raises(RunFileError, match='empty.csv: empty file'):
        read_csv_run(tmp_path / 'empty.csv', map_path)
    (tmp_path / 'bad.yaml').write_text('time: {column: t\n', encoding='utf-8')
    with pytest.raises(ColumnMapError, match='bad.yaml: not a YAML column map'):
        read_csv_run(csv_path, tmp_path / 'bad.yaml')
    with pytest.raises(ColumnMapError, match='nomap.yaml: cannot read the column map'):
        read_csv_run(csv_path, tmp_path / 'nomap.yaml')
    hsva = tmp_path / 'short.dat'
    hsva.write_bytes(b' HSVA\n KVLCC2\n Z10\xb0/10\xb0\n Time series\n'
                     b' .0 1 2 3 4 5 6 7 8 9 10 11\n .05 1 2 3 4 5 6 7 8 9 10\n')
    with pytest.raises(RunFileError, match=r'short.dat: line 6: 11 fields, an HSVA row has 12'):
        read_hsva(hsva)
    hsva.write_bytes(b' HSVA\n KVLCC2\n Z10\n T\n .0 1 2 3 4 5 6 7 8 9 10 11\n'
                     b' .05 1 2 3 4 5 6 7 D 9 10 11\n')
    with pytest.raises(RunFileError, match=r"short.dat: line 6, column 'delta': 'D' is not a"):
        read_hsva(hsva)
    run = read_csv_run(csv_path, map_path)
    with pytest.raises(ColumnMapError, match='give the vehicle'):
        write_imported_bag(run, tmp_path / 'b1')
    with pytest.raises(ColumnMapError, match='give the UTC offset'):
        write_imported_bag(s_run, tmp_path / 'b2', start='2006-01-01T00:00:00')
    with pytest.raises(ColumnMapError, match="--start 'yesterday': not an ISO 8601 time"):
        write_imported_bag(s_run, tmp_path / 'b3', start='yesterday')
    assert not any((tmp_path / b).exists() for b in ('b1', 'b2', 'b3'))


def test_cli_errors_are_one_line(tmp_path, capsys):
    csv_path, _ = _case(tmp_path)
    map_path = _write_map(tmp_path / 'm2.yaml', _with(psi={'column': 'hdg', 'unit': 'grad'}))
    argv = ['import', '--format', 'csv', str(csv_path), '--columns', str(map_path),
            '--vehicle', 'x', '--out', str(tmp_path / 'o')]
    assert cli_main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown unit 'grad'" in err[0]
    assert cli_main(argv[:4] + argv[6:]) == 2
    assert 'needs --columns' in capsys.readouterr().err
    assert not (tmp_path / 'o').exists()


def test_the_ardusub_style_example_log_imports_with_the_documented_map(tmp_path, capsys):
    """docs/your_data.md's ArduSub-style log (tools/ardusub_style_log.py: IMU 25 Hz, baro
    20 Hz, DVL 5 Hz with dropouts, RCOU PWM 10 Hz) through docs/examples/ardusub_columns.yaml:
    the PWM outputs become the fin angles and shaft speed, every row is fused."""
    import importlib.util
    spec = importlib.util.spec_from_file_location('ardusub_style_log',
                                                  REPO / 'tools' / 'ardusub_style_log.py')
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    log = tmp_path / 'log.csv'
    assert tool.main(['--out', str(log), '--duration', '20']) == 0
    columns = REPO / 'docs' / 'examples' / 'ardusub_columns.yaml'
    run = read_csv_run(log, columns)
    counts = run.samples
    assert counts['phi'] == 501 and counts['z'] == 401 and 90 <= counts['u'] <= 101
    assert 'x' not in counts and run.skipped == ()
    rudder = run.inputs['rudder']
    assert np.nanmax(np.abs(rudder)) == pytest.approx(math.radians(20.0))
    bag = write_imported_bag(run, tmp_path / 'bag', vehicle='nps_auv2')
    res = replay_bag(bag, warn=False)
    assert res.accepted == len(run.t_ns) and res.rejected == 0
    # the DVL rows carry u, the others do not (skipped, not fused as 0)
    assert np.isnan(res.Y[:, State.U]).sum() == len(run.t_ns) - counts['u']


def test_pwm_inputs_of_a_column_map():
    doc = {'time': {'column': 't', 'unit': 'us'}, 'psi': {'column': 'y', 'unit': 'deg'},
           'shaft': {'column': 'esc', 'unit': 'us',
                     'pwm': {'neutral': 1000, 'half_range': 500, 'full_scale': 25, 'unit': 'rps'}}}
    cmap = ColumnMap(doc)
    _, _, inputs = cmap.to_ned({'psi': np.zeros(2), 'shaft': np.array([1000.0, 1250.0])})
    np.testing.assert_allclose(inputs['shaft'], [0.0, 750.0])     # half of 25 rps, in rpm
    for bad, message in (
            ({'unit': 'us'}, r'shaft: unit us \(a PWM pulse width\) needs pwm'),
            ({'unit': 'rpm', 'pwm': {}}, 'pwm applies to unit us only'),
            ({'unit': 'us', 'pwm': {'full_scale': 1, 'unit': 'deg'}}, "pwm unit 'deg'"),
            ({'unit': 'us', 'pwm': {'full_scale': 0, 'unit': 'rpm'}}, 'full_scale = 0')):
        with pytest.raises(ColumnMapError, match=message):
            ColumnMap(dict(doc, shaft={'column': 'esc', **bad}))
    with pytest.raises(ColumnMapError, match=r"psi: unknown unit 'us'"):
        ColumnMap(dict(doc, psi={'column': 'y', 'unit': 'us'}))
