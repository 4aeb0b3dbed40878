"""offline/raw_bag.py: a bag with raw-sensor topics read through an input map into the
records identify_raw takes."""
import numpy as np
import pytest

from auv_ident.offline.raw_bag import raw_bag_records, raw_sensor_config
from auv_ident.offline.sim_bag import _STORE, write_message_bag
from auv_ident.session.input_map import InputMapError, parse_input_map
from auv_ident.vehicles import load_vehicle

T = _STORE.types
EPOCH = 1_700_000_000 * 10**9
MAP = {'version': 1, 'inputs': {
    'imu': {'topic': '/imu', 'type': 'sensor_msgs/msg/Imu', 'frame': 'enu',
            'fields': ['orientation', 'angular_velocity']},
    'dvl': {'topic': '/dvl', 'type': 'geometry_msgs/msg/TwistWithCovarianceStamped',
            'frame': 'ned', 'reference': 'water',
            'mounting': {'lever_arm': [-0.5, 0.0, 0.15], 'rotation': [0, 0, 45], 'unit': 'deg'}},
    'depth': {'topic': '/pressure', 'type': 'sensor_msgs/msg/FluidPressure',
              'surface_pressure': 101000.0},
    'fins': {'topic': '/fins', 'type': 'sensor_msgs/msg/JointState',
             'channels': [{'joint': 'rudder', 'actuator': 'delta_r'}]}}}


def _header(ns, fid=''):
    return T['std_msgs/msg/Header'](
        stamp=T['builtin_interfaces/msg/Time'](sec=ns // 10**9, nanosec=ns % 10**9),
        frame_id=fid)


def _v3(x, y, z):
    return T['geometry_msgs/msg/Vector3'](x=x, y=y, z=z)


def _messages():
    z9 = np.zeros(9)
    imu = T['sensor_msgs/msg/Imu'](
        header=_header(EPOCH + 10**8), orientation=T['geometry_msgs/msg/Quaternion'](
            x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=z9.copy(),
        angular_velocity=_v3(0.1, 0.2, 0.3), angular_velocity_covariance=z9.copy(),
        linear_acceleration=_v3(0.0, 0.0, 0.0), linear_acceleration_covariance=z9.copy())
    dvl = T['geometry_msgs/msg/TwistWithCovarianceStamped'](
        header=_header(EPOCH + 3 * 10**8), twist=T['geometry_msgs/msg/TwistWithCovariance'](
            twist=T['geometry_msgs/msg/Twist'](linear=_v3(1.5, 0.1, -0.2),
                                               angular=_v3(0.0, 0.0, 0.0)),
            covariance=np.zeros(36)))
    pres = T['sensor_msgs/msg/FluidPressure'](header=_header(EPOCH + 2 * 10**8),
                                              fluid_pressure=151000.0, variance=25.0)
    fins = T['sensor_msgs/msg/JointState'](header=_header(EPOCH), name=['rudder'],
                                           position=np.array([0.05]), velocity=np.zeros(0),
                                           effort=np.zeros(0))
    # log times out of stamp order: the records follow the stamps
    return [('/fins', EPOCH + 10, fins), ('/dvl', EPOCH + 20, dvl),
            ('/imu', EPOCH + 4 * 10**8, imu), ('/pressure', EPOCH + 5 * 10**8, pres)]


def _bag(tmp_path, drop=()):
    types = {'/imu': 'sensor_msgs/msg/Imu', '/dvl': 'geometry_msgs/msg/TwistWithCovarianceStamped',
             '/pressure': 'sensor_msgs/msg/FluidPressure', '/fins': 'sensor_msgs/msg/JointState'}
    types = {k: v for k, v in types.items() if k not in drop}
    return write_message_bag(tmp_path / 'bag', types, {},
                             [m for m in _messages() if m[0] in types], None)


def test_records_in_stamp_order_ned_frd(tmp_path):
    imap = parse_input_map(MAP)
    records, t0 = raw_bag_records(_bag(tmp_path), imap, load_vehicle('nps_auv2'))
    assert t0 == EPOCH
    assert [(r.kind, round(r.t, 9)) for r in records] == [
        ('command', 0.0), ('imu', 0.1), ('pressure', 0.2), ('dvl', 0.3)]
    assert records[0].values[0] == 0.05                          # delta_r
    np.testing.assert_allclose(records[1].values[4:], [0.1, -0.2, -0.3])   # FLU -> FRD
    np.testing.assert_allclose(records[3].values, [1.5, 0.1, -0.2])        # already FRD
    assert records[3].sensor == 'dvl' and records[2].covariance[0, 0] == 25.0
    cfg = raw_sensor_config(imap)
    assert cfg.dvl_reference == 'water' and cfg.p_surface == 101000.0
    # the map's body_frame is REP-103 FLU by default: held in FRD
    np.testing.assert_allclose(cfg.mountings['dvl'].lever_arm, [-0.5, 0.0, -0.15])


def test_a_topic_the_bag_lacks_is_named(tmp_path):
    with pytest.raises(InputMapError, match='/dvl'):
        raw_bag_records(_bag(tmp_path, drop=('/dvl',)), parse_input_map(MAP),
                        load_vehicle('nps_auv2'))
