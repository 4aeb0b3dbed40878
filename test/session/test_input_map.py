"""The input map (session/input_map.py) and commands of any form (session/inputs.py), without a
ROS graph: the shipped default map is today's layout, every bad map is one InputMapError naming
the entry, a map that does not fit the vehicle is refused, and each command form (JointState by
name and field, Float64MultiArray by index, Float64, WrenchStamped) is read, converted (units,
scale, offset, PWM) and held on change."""
import math
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from auv_ident.core.model.state import Input, INPUT_NAMES
from auv_ident.session.input_map import (
    ACTUATORS,
    InputMapError,
    load_input_map,
    parse_input_map,
    vehicle_actuators,
)
from auv_ident.session.inputs import CommandHolder, read_channels
from auv_ident.session.messages import (
    actuator_joint_fields,
    ConversionError,
    JOINT_NAMES,
    joint_state_to_actuators,
)
from auv_ident.session.session import IdentSession
from auv_ident.session.settings import IdentifierSettings
from auv_ident.vehicles import load_vehicle

ODOM = {'topic': 'odom', 'type': 'nav_msgs/msg/Odometry'}
NPS_FINS = ['delta_r', 'delta_s', 'delta_b', 'delta_bp', 'delta_bs']


def _map(**inputs):
    return {'version': 1, 'inputs': {'odom': dict(ODOM), **inputs}}


def _floats(names=ACTUATORS[:6], unit=None):
    """One Float64 input per actuator (topics cmd/NAME)."""
    out = {}
    for name in names:
        out[name] = {'topic': f'cmd/{name}', 'type': 'std_msgs/Float64', 'actuator': name,
                     'unit': unit or ('rpm' if name == 'n_rpm' else 'rad')}
    return out


def _header(ns):
    return SimpleNamespace(stamp=SimpleNamespace(sec=ns // 10**9, nanosec=ns % 10**9),
                           frame_id='')


def _joint_state(names, position, velocity, effort=(), ns=0):
    return SimpleNamespace(header=_header(ns), name=list(names), position=list(position),
                           velocity=list(velocity), effort=list(effort))


def test_the_default_map_is_todays_layout():
    m = load_input_map()
    assert m.topic_types == {'/odom': 'nav_msgs/msg/Odometry',
                             '/actuators': 'sensor_msgs/msg/JointState'}
    assert m.odometry.frame == 'auto' and m.odometry.topic == 'odom'
    (cmd,) = m.commands
    assert [c.joint for c in cmd.channels] == list(JOINT_NAMES) + ['propeller']
    assert [c.name for c in cmd.channels] == list(INPUT_NAMES)
    assert IdentifierSettings().input_map == 'odom_actuators'
    # the map reads a default-layout JointState exactly as the fixed reader does
    u7 = np.array([0.1, -0.2, 0.03, -0.04, 0.05, 1234.5, 17.0])
    pos, vel, eff = actuator_joint_fields(u7)
    for effort in (eff, []):
        msg = _joint_state(JOINT_NAMES, pos, vel, effort)
        holder = CommandHolder.of(m, load_vehicle('nps_auv2'))
        got = holder.update(cmd, msg, 5)
        _, want = joint_state_to_actuators(msg)
        assert np.array_equal(got, want), (got, want)


@pytest.mark.parametrize('doc, message', [
    ({'inputs': {}}, 'version = None'),
    ({'version': 2, 'inputs': {}}, 'version = 2'),
    ({'version': 1, 'inputs': {'odom': ODOM}, 'extra': 1}, 'unknown key(s) extra'),
    (_map(), 'no command input'),
    (_map(a={'topic': 'x', 'type': 'sensor_msgs/Temperature'}),
     "input 'a': type 'sensor_msgs/Temperature' is not read"),
    (_map(a={'type': 'std_msgs/Float64'}), "input 'a': topic = None"),
    (_map(a={'topic': 'x', 'type': 'std_msgs/Float64', 'actuator': 'thruster_1',
             'unit': 'kgf'}), "'thruster_1' is no actuator of state.Input"),
    (_map(a={'topic': 'x', 'type': 'std_msgs/Float64', 'actuator': 't1', 'unit': 'us',
             'pwm': {'neutral': 1500}}), 'leave pwm out'),
    (_map(a={'topic': 'x', 'type': 'std_msgs/Float64', 'actuator': 'delta_r'}),
     'give the unit of delta_r'),
    (_map(a={'topic': 'x', 'type': 'std_msgs/Float64', 'actuator': 'delta_r',
             'unit': 'rpm'}), "unit 'rpm' does not fit delta_r"),
    (_map(a={'topic': 'x', 'type': 'std_msgs/Float64', 'actuator': 'delta_r',
             'unit': 'rad', 'scale': 0}), 'scale 0'),
    (_map(a={'topic': 'x', 'type': 'sensor_msgs/JointState', 'channels': [
        {'joint': 'r', 'actuator': 'delta_r'}, {'joint': 'r', 'actuator': 'delta_s'}]}),
     'joint r field position is read twice'),
    (_map(a={'topic': 'x', 'type': 'sensor_msgs/JointState', 'channels': [
        {'joint': 'r', 'actuator': 'delta_r'}, {'joint': 's', 'actuator': 'delta_r'}]}),
     'actuator delta_r is fed by two channels'),
    (_map(a={'topic': 'x', 'type': 'std_msgs/Float64MultiArray', 'channels': [
        {'index': -1, 'actuator': 'delta_r', 'unit': 'rad'}]}), 'index = -1'),
    (_map(a={'topic': 'odom', 'type': 'std_msgs/Float64', 'actuator': 'delta_r',
             'unit': 'rad'}), 'topic /odom is read by two inputs'),
    (_map(a={'topic': 'x', 'type': 'geometry_msgs/WrenchStamped', 'channels': [
        {'field': 'force.w', 'actuator': 'thrust'}]}), "field = 'force.w'"),
    (_map(a={'topic': 'x', 'type': 'std_msgs/Float64', 'actuator': 'n_rpm', 'unit': 'us',
             'pwm': {'neutral': 1500, 'half_range': 0}}), 'half_range = 0'),
    (_map(o={'topic': 'odom2', 'type': 'nav_msgs/Odometry'}, **_floats()),
     'more than one nav_msgs/msg/Odometry'),
    (dict(_map(**_floats()), inputs={**_map(**_floats())['inputs'],
                                     'imu': {'topic': 'imu', 'type': 'sensor_msgs/Imu',
                                             'mounting': {'lever_arm': [1, 2]}}}),
     'lever_arm = [1, 2]'),
    (dict(_map(**_floats()), inputs={**_map(**_floats())['inputs'],
                                     'depth': {'topic': 'd', 'type':
                                               'geometry_msgs/PoseWithCovarianceStamped'}}),
     'give measures: depth or position'),
    (dict(_map(**_floats()), inputs={**_map(**_floats())['inputs'],
                                     'gps': {'topic': 'fix', 'type': 'sensor_msgs/NavSatFix',
                                             'datum': {'latitude': 95, 'longitude': 0}}}),
     'is not a latitude'),
])
def test_a_bad_map_is_one_error_naming_the_entry(doc, message):
    with pytest.raises(InputMapError) as info:
        parse_input_map(doc, 'my_map.yaml')
    assert message in str(info.value) and str(info.value).startswith('my_map.yaml: ')


def test_a_map_that_does_not_fit_the_vehicle_is_refused(tmp_path):
    nps = load_vehicle('nps_auv2')
    assert [ACTUATORS[i] for i in vehicle_actuators(nps)] == NPS_FINS + ['n_rpm']
    assert [ACTUATORS[i] for i in vehicle_actuators(load_vehicle('remus100'))] == [
        'delta_r', 'delta_s', 'n_rpm']
    assert [ACTUATORS[i] for i in vehicle_actuators(load_vehicle('kvlcc2_hsva'))] == [
        'delta_r', 'thrust']     # the measured thrust drives it, not the shaft speed
    no_stern = parse_input_map(_map(**_floats([a for a in ACTUATORS[:6] if a != 'delta_s'])),
                               'm.yaml')
    with pytest.raises(InputMapError, match=r"vehicle 'nps_auv2' is driven by delta_s "
                                            r'\(stern planes\), which no command input feeds'):
        no_stern.check_vehicle(nps)
    # remus100 has no bow planes in its model: a map without them fits it
    remus = parse_input_map(_map(**_floats(['delta_r', 'delta_s', 'n_rpm'])), 'm.yaml')
    remus.check_vehicle(load_vehicle('remus100'))
    with pytest.raises(InputMapError, match='delta_b'):
        remus.check_vehicle(nps)
    # raw sensors are parsed and checked, with their mounting; the live node refuses them
    doc = _map(**_floats())
    doc['inputs']['imu'] = {'topic': 'imu/data', 'type': 'sensor_msgs/msg/Imu',
                            'mounting': {'lever_arm': [0.5, 0.1, -0.2],
                                         'rotation': [0, 0, 90]}}
    path = tmp_path / 'raw.yaml'
    path.write_text(yaml.safe_dump(doc))
    m = load_input_map(str(path))
    (imu,) = m.sensors
    # given in FLU (REP-103, the default body_frame), held in FRD
    assert imu.mounting.lever_arm == (0.5, -0.1, 0.2)
    R = imu.mounting.matrix
    assert np.allclose(R @ [1, 0, 0], [0, -1, 0])    # sensor x = body left = FRD -y
    with pytest.raises(InputMapError, match="input 'imu' .*raw-sensor filter"):
        IdentSession(IdentifierSettings.from_values(input_map=str(path)))
    with pytest.raises(InputMapError, match="input map 'nope': no file"):
        IdentSession(IdentifierSettings.from_values(input_map='nope'))


def test_check_topics_names_the_missing_topic_and_the_wrong_type():
    m = parse_input_map(_map(**_floats()), 'm.yaml')
    present = {'/odom': 'nav_msgs/msg/Odometry', **{f'/cmd/{a}': 'std_msgs/msg/Float64'
                                                    for a in ACTUATORS[:5]}}
    with pytest.raises(InputMapError, match="bag: no actuator topic '/cmd/n_rpm' in the bag "
                                            r"\(input 'n_rpm' of m.yaml\)"):
        m.check_topics(present, 'bag')
    present['/cmd/n_rpm'] = 'std_msgs/msg/Int32'
    with pytest.raises(InputMapError, match='topic /cmd/n_rpm has type std_msgs/msg/Int32, '
                                            'expected std_msgs/msg/Float64'):
        m.check_topics(present, 'bag')


def test_every_command_form_converts_its_units():
    fin, shaft = 0.4, 1500.0
    doc = _map(
        js={'topic': 'js', 'type': 'sensor_msgs/JointState', 'channels': [
            {'joint': 'fin_a', 'actuator': 'delta_r', 'unit': 'deg', 'scale': -1},
            {'joint': 'shaft', 'field': 'velocity', 'actuator': 'n_rpm', 'unit': 'rps'}]},
        arr={'topic': 'arr', 'type': 'std_msgs/Float64MultiArray', 'channels': [
            {'index': 2, 'actuator': 'delta_s', 'unit': 'us'},
            {'index': 0, 'actuator': 'delta_b', 'unit': 'normalized'}]},
        f={'topic': 'f', 'type': 'std_msgs/Float64', 'actuator': 'delta_bp', 'unit': 'deg',
           'offset': 1.0},
        w={'topic': 'w', 'type': 'geometry_msgs/WrenchStamped', 'channels': [
            {'field': 'torque.y', 'actuator': 'delta_bs', 'unit': 'rad'},
            {'field': 'force.x', 'actuator': 'thrust', 'unit': 'kN'}]})
    m = parse_input_map(doc, 'm.yaml')
    e = {x.name: x for x in m.inputs}
    js = _joint_state(['shaft', 'fin_a'], [0.0, 10.0], [20.0, 0.0])
    assert read_channels(e['js'], js, fin, shaft) == [
        (Input.DELTA_R, pytest.approx(-math.radians(10.0))), (Input.N_RPM, 1200.0)]
    arr = SimpleNamespace(data=[0.5, 9.9, 1700.0])
    assert read_channels(e['arr'], arr, fin, shaft) == [
        (Input.DELTA_S, pytest.approx(0.5 * fin)), (Input.DELTA_B, pytest.approx(0.5 * fin))]
    assert read_channels(e['f'], SimpleNamespace(data=2.0), fin, shaft) == [
        (Input.DELTA_BP, pytest.approx(math.radians(3.0)))]
    wrench = SimpleNamespace(header=_header(0), wrench=SimpleNamespace(
        force=SimpleNamespace(x=0.25, y=0, z=0), torque=SimpleNamespace(x=0, y=0.1, z=0)))
    assert read_channels(e['w'], wrench, fin, shaft) == [(Input.DELTA_BS, 0.1),
                                                         (Input.THRUST, 250.0)]
    # what cannot be read names the culprit
    with pytest.raises(ConversionError, match="lacks joint 'fin_a'"):
        read_channels(e['js'], _joint_state(['shaft'], [0.0], [1.0]), fin, shaft)
    with pytest.raises(ConversionError, match='velocity has 1 entries for 2 names'):
        read_channels(e['js'], _joint_state(['shaft', 'fin_a'], [0, 0], [1.0]), fin, shaft)
    with pytest.raises(ConversionError, match='data has 2 entries; the delta_s is read from '
                                              'index 2'):
        read_channels(e['arr'], SimpleNamespace(data=[0.0, 0.0]), fin, shaft)
    # PWM with its own neutral and range, for the shaft: normalized x the shaft limit
    pwm = parse_input_map(_map(p={'topic': 'p', 'type': 'std_msgs/Float64', 'actuator': 'n_rpm',
                                  'unit': 'us', 'pwm': {'neutral': 1000, 'half_range': 500}}),
                          'm.yaml').commands[0]
    assert read_channels(pwm, SimpleNamespace(data=1250.0), fin, shaft) == [
        (Input.N_RPM, 750.0)]


def test_holding_waits_for_every_actuator_then_holds_each_last_value():
    nps = load_vehicle('nps_auv2')
    m = parse_input_map(_map(**_floats()), 'm.yaml')
    holder = CommandHolder.of(m, nps)
    e = {x.name: x for x in m.commands}
    assert holder.update(e['delta_r'], SimpleNamespace(data=0.1), 10) is None
    assert holder.missing() == ['delta_s', 'delta_b', 'delta_bp', 'delta_bs', 'n_rpm']
    for k, name in enumerate(ACTUATORS[1:5]):
        assert holder.update(e[name], SimpleNamespace(data=0.01 * k), 11) is None
    u = holder.update(e['n_rpm'], SimpleNamespace(data=1000.0), 12)
    assert u.tolist() == [0.1, 0.0, 0.01, 0.02, 0.03, 1000.0, 0.0]
    u = holder.update(e['delta_r'], SimpleNamespace(data=-0.2), 3 * 10**9)
    assert u.tolist() == [-0.2, 0.0, 0.01, 0.02, 0.03, 1000.0, 0.0]
    # staleness per actuator: every one but the rudder last heard at ~0 s
    assert holder.stale(3 * 10**9, 2.5) == ['delta_s', 'delta_b', 'delta_bp', 'delta_bs',
                                            'n_rpm']
    assert holder.stale(3 * 10**9, None) == []


def test_the_session_holds_commands_and_rejects_stale_ones(tmp_path):
    """Float64 per actuator: no command buffered until every actuator was heard; a message
    without a header is stamped with its receive time; with max_command_age an actuator
    topic that went silent makes the odometry 'stale command', naming it."""
    path = tmp_path / 'floats.yaml'
    path.write_text(yaml.safe_dump(_map(**_floats())))
    s = IdentSession(IdentifierSettings.from_values(input_map=str(path), max_command_age=0.5))
    t0 = 1_704_067_200 * 10**9
    ev = s.on_input('delta_r', SimpleNamespace(data=0.0), t0)
    assert ev.kind == 'command' and ev.code == 'holding' and 'n_rpm' in ev.reason
    assert s.counters.cmd_accepted == 0
    for name in ACTUATORS[1:6]:
        ev = s.on_input(name, SimpleNamespace(data=1000.0 if name == 'n_rpm' else 0.0), t0)
    assert ev.kind == 'command' and ev.code == '' and s.counters.cmd_accepted == 1
    ev = s.on_input('delta_r', SimpleNamespace(data=0.01), t0 + 10**9)
    assert ev.kind == 'command' and s.counters.cmd_accepted == 2
    odom = SimpleNamespace(header=_header(t0 + 10**9))
    ev = s.on_input('odom', odom)
    assert ev.kind == 'rejected' and ev.code == 'stale command'
    assert 'delta_s, delta_b, delta_bp, delta_bs, n_rpm' in ev.reason
    ev = s.on_input('delta_s', SimpleNamespace(data='x'), t0)
    assert ev.kind == 'rejected' and ev.reason.startswith('delta_s: ') and ev.code == 'conversion'
    assert s.counters.reasons['delta_s: conversion'] == 1


def test_the_documented_example_maps():
    """docs/examples/*.yaml: every input map parses; those of what the filter fuses today fit
    nps_auv2, the raw-sensor one is refused naming its first raw input."""
    from pathlib import Path
    examples = Path(__file__).resolve().parents[2] / 'docs' / 'examples'
    nps = load_vehicle('nps_auv2')
    maps = {p.stem: load_input_map(str(p)) for p in sorted(examples.glob('*.yaml'))
            if 'inputs' in yaml.safe_load(p.read_text())}
    assert set(maps) == {'joint_names', 'per_fin_topics', 'raw_sensors', 'stonefish_setpoints'}
    for name, m in maps.items():
        if name == 'raw_sensors':
            with pytest.raises(InputMapError, match="input 'imu' .*raw-sensor filter"):
                m.check_vehicle(nps)
            assert {e.type for e in m.sensors} == {
                'sensor_msgs/msg/Imu', 'geometry_msgs/msg/TwistWithCovarianceStamped',
                'sensor_msgs/msg/FluidPressure'}
        else:
            m.check_vehicle(nps)


# --- thruster channels (#29): a vehicle's thrusters fed by name ---

def test_bluerov2_map_reads_pwm_into_the_thruster_commands():
    v = load_vehicle('bluerov2_heavy')
    m = load_input_map('bluerov2_heavy')
    m.check_vehicle(v)
    holder = CommandHolder.of(m, v)
    # before any message: every thruster at its neutral 1500 us
    assert np.array_equal(holder.u[7:], [1500.0] * 8)
    entry = m.for_vehicle(v).commands[0]
    pwm = [1100.0, 1250.5, 1472.0, 1500.0, 1528.0, 1700.0, 1850.0, 1900.0]
    u = holder.update(entry, SimpleNamespace(data=pwm), 10)
    assert u is not None and u.shape == (15,)
    assert np.array_equal(u[7:], pwm) and np.array_equal(u[:7], np.zeros(7))


@pytest.mark.parametrize('channel, message', [
    ({'index': 0, 'actuator': 't9', 'unit': 'us'}, "has no thruster or actuator 't9'"),
    ({'index': 0, 'actuator': 't1', 'unit': 'N'},
     r'thruster t1 takes command pwm_us \(vehicle file\), the map gives unit N: use unit us'),
])
def test_thruster_channels_are_checked_against_the_vehicle(channel, message):
    m = parse_input_map(_map(a={'topic': 'thrusters', 'type': 'std_msgs/Float64MultiArray',
                                'channels': [channel]}))
    with pytest.raises(InputMapError, match=message):
        m.check_vehicle(load_vehicle('bluerov2_heavy'))


def test_a_thruster_no_channel_feeds_is_named():
    chans = [{'index': i, 'actuator': f't{i + 1}', 'unit': 'us'} for i in range(7)]
    m = parse_input_map(_map(a={'topic': 'thrusters', 'type': 'std_msgs/Float64MultiArray',
                                'channels': chans}))
    with pytest.raises(InputMapError, match='driven by t8 .thruster., which no command input '
                                            'feeds'):
        m.check_vehicle(load_vehicle('bluerov2_heavy'))
