"""identify --bag with a raw-sensor input map (analysis/raw_identify.py) on a run of the
independent generator (offline/independent_data.py generate_raw) written as a bag."""
import dataclasses
import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
import yaml

from auv_ident.analysis.raw_comparison import sensors_of
from auv_ident.analysis.raw_identify import drop_repeats
from auv_ident.cli import main
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.identification.raw import identify_raw
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.offline.independent_data import DataConfig, generate_raw, RawConfig
from auv_ident.offline.raw_bag import raw_bag_records, raw_sensor_config

# the example bag's message writer (python -m auv_ident.offline.raw_example)
from auv_ident.offline.raw_example import _v3, record_message as _message
from auv_ident.offline.sim_bag import _header, _STORE, write_message_bag
from auv_ident.offline.tf_static import tf_mountings
from auv_ident.session.input_map import InputMapError, parse_input_map
from auv_ident.vehicles import load_vehicle

T = _STORE.types
NAMES = ['Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v']
EPOCH = 1_700_000_000 * 10**9
TOPICS = {'/imu': 'sensor_msgs/msg/Imu', '/dvl': 'geometry_msgs/msg/TwistWithCovarianceStamped',
          '/pressure': 'sensor_msgs/msg/FluidPressure', '/actuators': 'sensor_msgs/msg/JointState'}


def _map(cfg, drop=()):
    actuators = yaml.safe_load(open('config/inputs/odom_actuators.yaml'))['inputs']['actuators']
    inputs = {
        'imu': {'topic': '/imu', 'type': TOPICS['/imu'], 'frame': 'ned',
                'fields': ['orientation', 'angular_velocity']},
        'dvl': {'topic': '/dvl', 'type': TOPICS['/dvl'], 'frame': 'ned', 'reference': 'ground',
                'mounting': {'lever_arm': list(cfg.dvl_lever_arm),
                             'rotation': [0, 0, cfg.dvl_yaw_deg], 'unit': 'deg'}},
        'pressure': {'topic': '/pressure', 'type': TOPICS['/pressure'],
                     'mounting': {'lever_arm': list(cfg.pressure_lever_arm)}},
        'actuators': dict(actuators, topic='/actuators')}
    for k in drop:
        inputs[k]['topic'] = '/not_recorded'
    return {'version': 1, 'body_frame': 'frd', 'inputs': inputs}


@pytest.fixture(scope='module')
def raw_bag(tmp_path_factory):
    cfg = RawConfig(data=DataConfig(duration=20.0, seed=5, integrator='rk4', rk4_dt=0.005),
                    noise_level=(0.01, 0.01), noise_tau=(0.0, 0.0))
    run = generate_raw(cfg)
    d = tmp_path_factory.mktemp('raw')
    # the metadata our simulators write: the truth is the vehicle file's values
    bag = write_message_bag(d / 'bag', TOPICS, {'auv_ident.simulated': 'true'},
                            (_message(r) for r in run.records), None)
    maps = {}
    for key, drop in (('good', ()), ('no_dvl', ('dvl',))):
        maps[key] = d / f'{key}.yaml'
        maps[key].write_text(yaml.safe_dump(_map(cfg, drop)))
    # the same bag read with the other frame convention (REP-103 ENU for NED data)
    enu = _map(cfg)
    for k in ('imu', 'dvl'):
        enu['inputs'][k]['frame'] = 'enu'
    maps['enu'] = d / 'enu.yaml'
    maps['enu'].write_text(yaml.safe_dump(enu))
    return cfg, run, bag, maps


def _stuck_imu(records, since=8.0, until=12.0):
    """records with the IMU's message at `since` (s) republished unchanged until `until`."""
    held, out = None, []
    for r in records:
        if r.kind == 'imu' and since <= r.t <= until:
            held = held or r
            r = dataclasses.replace(held, t=r.t)
        out.append(r)
    return out


@pytest.mark.slow
def test_identify_bag_with_a_raw_map_is_identify_raw_on_the_records(raw_bag, tmp_path, capsys):
    cfg, run, bag, maps = raw_bag
    out = tmp_path / 'r.json'
    code = main(['identify', '--bag', str(bag), '--input-map', str(maps['good']),
                 '--coefficients', ','.join(NAMES), '--json', str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert text.startswith('consistent: ')
    assert 'dvl_misalignment (sensor)' in text
    assert 'truth' in text.splitlines()[4]
    doc = json.loads(out.read_text())
    for n in NAMES:
        assert doc['coefficients'][n]['truth'] == pytest.approx(run.truth['coefficients'][n])
    est = np.array([doc['coefficients'][n]['estimate'] for n in NAMES])
    std = np.array([doc['coefficients'][n]['std'] for n in NAMES])
    truth = np.array([run.truth['coefficients'][n] for n in NAMES])
    assert np.all(np.abs(est - truth) < 3 * std), (est, truth, std)
    ref = identify_raw(Model(load_vehicle('nps_auv2'), NAMES), FilterConfig(), run.records,
                       sensors_of(cfg), passes=2)
    np.testing.assert_allclose(est, ref.estimate, rtol=1e-6)
    assert doc['fused']['dvl'] == run.truth['counts']['dvl']


def test_a_raw_map_topic_the_bag_lacks_is_exit_2(raw_bag, capsys):
    _, _, bag, maps = raw_bag
    code = main(['identify', '--bag', str(bag), '--input-map', str(maps['no_dvl'])])
    assert code == 2
    assert '/not_recorded' in capsys.readouterr().err


@pytest.mark.parametrize('option, value', [('--frame', 'enu'), ('--warm-start', 'e.json'),
                                           ('--tau', '5')])
def test_a_setting_the_raw_path_does_not_use_is_exit_2_naming_it(raw_bag, capsys, option,
                                                                  value):
    """A setting the raw-sensor filter does not use (its map says frames and units) was
    silently ignored: --frame enu then identified in the map's frame as if told nothing."""
    _, _, bag, maps = raw_bag
    code = main(['identify', '--bag', str(bag), '--input-map', str(maps['enu']),
                 '--coefficients', ','.join(NAMES), option, value])
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith(f'error: {option}: not used with raw sensors') and err.count('\n') == 1


def test_a_raw_bag_read_in_the_wrong_frame_is_not_consistent_exit_3(raw_bag, capsys):
    _, _, bag, maps = raw_bag
    code = main(['identify', '--bag', str(bag), '--input-map', str(maps['enu']),
                 '--coefficients', ','.join(NAMES)])
    assert code == 3
    out = capsys.readouterr().out
    assert out.startswith('NOT consistent: ') and 'frame' in out.splitlines()[0]


def test_a_stuck_imu_is_not_consistent_exit_3(raw_bag, tmp_path, capsys):
    cfg, run, _, maps = raw_bag
    bag = write_message_bag(tmp_path / 'stuck', TOPICS, {},
                            (_message(r) for r in _stuck_imu(run.records)), None)
    out = tmp_path / 'r.json'
    code = main(['identify', '--bag', str(bag), '--input-map', str(maps['good']),
                 '--coefficients', ','.join(NAMES), '--json', str(out)])
    assert code == 3
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith('NOT consistent: imu repeated exactly for 4.0 s'), first
    # a bag without our simulator's metadata has no known truth
    doc = json.loads(out.read_text())
    assert all(c['truth'] is None and c['error_pct'] is None
               for c in doc['coefficients'].values())


def test_drop_repeats_keeps_each_sensors_new_values_and_names_a_stuck_one(raw_bag):
    _, run, _, _ = raw_bag
    kept, spans = drop_repeats(_stuck_imu(run.records))
    assert [s.group for s in spans] == ['imu']
    assert spans[0].since == pytest.approx(8.0, abs=0.02) and spans[0].seconds >= 3.9
    assert len(run.records) - len(kept) == spans[0].repeats
    # a good run: nothing dropped, no fault (no false alarm)
    kept, spans = drop_repeats(run.records)
    assert spans == [] and len(kept) == len(run.records)


def _navsat(ns, lat, lon, status=0):
    return T['sensor_msgs/msg/NavSatFix'](
        header=_header(ns, 'gps'), status=T['sensor_msgs/msg/NavSatStatus'](status=status,
                                                                            service=1),
        latitude=lat, longitude=lon, altitude=0.0, position_covariance=np.diag([4.0, 9.0, 1.0])
        .ravel(), position_covariance_type=2)


def test_navsatfix_in_a_bag_is_a_position_fix_about_the_first_fix(raw_bag, tmp_path):
    cfg, run, _, _ = raw_bag
    fixes = [(1.0, 0.0, 0.0, -1), (2.0, 36.6, -121.9, 0), (3.0, 36.601, -121.9, 0),
             (4.0, 36.6, -121.899, 0)]
    msgs = [_message(r) for r in run.records if r.kind == 'command' and r.t < 5.0]
    msgs += [('/fix', EPOCH + int(t * 1e9), _navsat(EPOCH + int(t * 1e9), la, lo, st))
             for t, la, lo, st in fixes]
    msgs.sort(key=lambda m: m[1])
    bag = write_message_bag(tmp_path / 'gps', {'/fix': 'sensor_msgs/msg/NavSatFix',
                                               '/actuators': TOPICS['/actuators']}, {}, msgs,
                            None)
    imap = parse_input_map({'version': 1, 'inputs': {
        'gps': {'topic': '/fix', 'type': 'sensor_msgs/msg/NavSatFix',
                'mounting': {'lever_arm': [0.0, 0.0, -0.3]}},
        'actuators': _map(cfg)['inputs']['actuators']}})
    records, _ = raw_bag_records(bag, imap, load_vehicle('nps_auv2'))
    pos = [r for r in records if r.kind == 'position']
    assert len(pos) == 4 and np.all(np.isnan(pos[0].values))     # no fix yet: not fused
    np.testing.assert_allclose(pos[1].values, [0.0, 0.0])         # the first fix: the origin
    np.testing.assert_allclose(pos[2].values, [110.98, 0.0], atol=0.05)
    np.testing.assert_allclose(pos[3].values, [0.0, 89.51], atol=0.05)
    np.testing.assert_allclose(pos[2].covariance, np.diag([9.0, 4.0]))


def _tf(parent, child, xyz, rpy):
    q = Rotation.from_euler('xyz', rpy).as_quat()
    return T['geometry_msgs/msg/TransformStamped'](
        header=_header(EPOCH, parent), child_frame_id=child,
        transform=T['geometry_msgs/msg/Transform'](
            translation=_v3(xyz), rotation=T['geometry_msgs/msg/Quaternion'](
                x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))))


def _tf_bag(run, path, dvl_frame='dvl_link'):
    """The run's first 3 s with the DVL messages in frame dvl_frame and /tf_static chaining
    dvl_link -> sensors_link (0.1 m forward) -> base_link (yaw 2 deg, 0.4 m back, 0.2 m up:
    REP-103 FLU)."""
    tf = T['tf2_msgs/msg/TFMessage'](transforms=[
        _tf('base_link', 'sensors_link', [-0.4, 0.0, 0.2], [0.0, 0.0, math.radians(2.0)]),
        _tf('sensors_link', 'dvl_link', [0.1, 0.0, 0.0], [0.0, 0.0, 0.0])])
    msgs = [('/tf_static', EPOCH, tf)]
    for r in run.records:
        if r.t < 3.0:
            topic, ns, m = _message(r)
            if topic == '/dvl':
                m.header.frame_id = dvl_frame
            msgs.append((topic, ns, m))
    msgs.sort(key=lambda m: m[1])
    return write_message_bag(path, dict(TOPICS, **{'/tf_static': 'tf2_msgs/msg/TFMessage'}),
                             {}, msgs, None)


def test_tf_static_gives_a_sensors_mounting_and_a_disagreeing_map_is_an_error(
        raw_bag, tmp_path, monkeypatch):
    cfg, run, _, _ = raw_bag
    # the bag writer embeds each type's .msg text; tf2_msgs is not installed here, so its
    # one-line definition is given as a package share of its own
    share = tmp_path / 'prefix' / 'share' / 'tf2_msgs' / 'msg'
    share.mkdir(parents=True)
    (share / 'TFMessage.msg').write_text('geometry_msgs/TransformStamped[] transforms\n')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path / 'prefix'))
    bag = _tf_bag(run, tmp_path / 'tf')
    doc = _map(cfg)
    del doc['inputs']['dvl']['mounting']
    doc['body_frame'] = 'flu'         # REP-103, as the tf tree
    imap = parse_input_map(doc)
    tf = tf_mountings(bag, imap)
    # FLU: 0.1 m along sensors_link's x, turned 2 deg left, plus (-0.4, 0, 0.2); in FRD y and
    # z change sign, and 2 deg left (FLU) is 2 deg right (FRD)
    c, s = math.cos(math.radians(2.0)), math.sin(math.radians(2.0))
    arm = [-0.4 + 0.1 * c, -0.1 * s, -0.2]
    np.testing.assert_allclose(tf['dvl'].lever_arm, arm, atol=1e-12)
    yaw = math.degrees(math.atan2(tf['dvl'].matrix[1, 0], tf['dvl'].matrix[0, 0]))
    assert yaw == pytest.approx(-2.0, abs=1e-9)
    assert 'imu' not in tf                            # its frame id is empty: the map's
    cfg_raw = raw_sensor_config(imap, tf)
    np.testing.assert_allclose(cfg_raw.mountings['dvl'].lever_arm, arm)
    # the map's own mounting, where it agrees, stays; where it does not, one clear error
    flu = [-0.4 + 0.1 * c, 0.1 * s, 0.2]
    doc['inputs']['dvl']['mounting'] = {'lever_arm': flu, 'rotation': [0, 0, 2]}
    raw_sensor_config(parse_input_map(doc), tf)
    doc['inputs']['dvl']['mounting'] = {'lever_arm': flu, 'rotation': [0, 0, 0]}
    with pytest.raises(InputMapError, match="'dvl'.*tf_static.*2.00 deg apart"):
        raw_sensor_config(parse_input_map(doc), tf)
    # a frame /tf_static does not reach keeps the map's mounting
    assert tf_mountings(_tf_bag(run, tmp_path / 'tf2', 'elsewhere'), imap) == {}
