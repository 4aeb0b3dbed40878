"""A raw-sensor example bag, made again by one command: a run of the independent generator
(offline/independent_data.py generate_raw: 100 Hz IMU, 5 Hz DVL with 5 % dropouts, 10 Hz
pressure, commands on change, a gyro bias, a DVL misalignment of 1-2 deg, coloured noise) written
as a rosbag2 MCAP bag of sensor_msgs/Imu, TwistWithCovarianceStamped (the DVL),
sensor_msgs/FluidPressure and the sensor_msgs/JointState commands, with the NED input map that
reads it (the DVL's and pressure sensor's nominal mountings in body FRD)::

    python -m auv_ident.offline.raw_example OUT_DIR [--duration 60] [--seed 5] [--imu-rate 100]

writes OUT_DIR/bag and OUT_DIR/map.yaml (OUT_DIR/bag must not exist). The same seed gives the
same bag. Each message is logged at its header stamp (a 1.7e9 s epoch).
"""
import argparse
from pathlib import Path
import sys

import numpy as np
import yaml

from auv_ident.offline.independent_data import DataConfig, generate_raw, RawConfig
from auv_ident.offline.sim_bag import _header, _STORE, joint_state_msg, write_message_bag
from auv_ident.session.input_map import DEFAULT_MAP, DVL, IMU, PRESSURE, resolve_input_map

_T = _STORE.types
EPOCH_NS = 1_700_000_000 * 10**9
TOPICS = {'/imu': IMU, '/dvl': DVL, '/pressure': PRESSURE,
          '/actuators': 'sensor_msgs/msg/JointState'}


def _v3(v):
    return _T['geometry_msgs/msg/Vector3'](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _cov(c, n, m):
    """(m*m,) row-major covariance with c (n, n) in its first block (zeros: none given)."""
    full = np.zeros((m, m))
    if c is not None:
        full[:n, :n] = np.asarray(c, dtype=float).reshape(n, n)
    return full.ravel()


def record_message(r):
    """(topic, log ns = stamp ns, rosbags message) of one RawMeasurement (NED/FRD)."""
    ns = EPOCH_NS + int(round(r.t * 1e9))
    h = _header(ns, '')
    if r.kind == 'command':
        return '/actuators', ns, joint_state_msg(ns, r.values)
    if r.kind == 'imu':
        c = np.zeros((6, 6)) if r.covariance is None else r.covariance
        q = r.values[:4]
        return '/imu', ns, _T[IMU](
            header=h, orientation=_T['geometry_msgs/msg/Quaternion'](
                x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
            orientation_covariance=c[:3, :3].ravel().copy(), angular_velocity=_v3(r.values[4:]),
            angular_velocity_covariance=c[3:, 3:].ravel().copy(),
            linear_acceleration=_v3([0, 0, 0]), linear_acceleration_covariance=np.zeros(9))
    if r.kind == 'dvl':
        return '/dvl', ns, _T[DVL](
            header=h, twist=_T['geometry_msgs/msg/TwistWithCovariance'](
                twist=_T['geometry_msgs/msg/Twist'](linear=_v3(r.values), angular=_v3([0] * 3)),
                covariance=_cov(r.covariance, 3, 6)))
    if r.kind == 'pressure':
        return '/pressure', ns, _T[PRESSURE](
            header=h, fluid_pressure=float(r.values[0]),
            variance=0.0 if r.covariance is None else float(r.covariance[0, 0]))
    raise ValueError(f'record kind {r.kind!r} is not written by the raw example')


def load_input_map_yaml(name):
    """The YAML document of a shipped input map (the commands' layout is the default map's)."""
    with open(resolve_input_map(name), encoding='utf-8') as f:
        return yaml.safe_load(f)


def input_map(cfg):
    """The NED input map of a RawConfig's sensors (mountings as generated, nominal)."""
    return {'version': 1, 'body_frame': 'frd', 'inputs': {
        'imu': {'topic': '/imu', 'type': IMU, 'frame': 'ned',
                'fields': ['orientation', 'angular_velocity']},
        'dvl': {'topic': '/dvl', 'type': DVL, 'frame': 'ned', 'reference': 'ground',
                'mounting': {'lever_arm': list(cfg.dvl_lever_arm),
                             'rotation': [0, 0, cfg.dvl_yaw_deg], 'unit': 'deg'}},
        'pressure': {'topic': '/pressure', 'type': PRESSURE,
                     'mounting': {'lever_arm': list(cfg.pressure_lever_arm)}},
        'actuators': dict(load_input_map_yaml(DEFAULT_MAP)['inputs']['actuators'],
                          topic='/actuators')}}


def write_raw_example(out_dir, duration=60.0, seed=5, imu_rate=100.0):
    """Write out_dir/bag and out_dir/map.yaml (module docstring); returns (bag, map path)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cfg = RawConfig(data=DataConfig(duration=float(duration), seed=int(seed), integrator='rk4',
                                    rk4_dt=0.005), imu_rate=float(imu_rate))
    cfg.validate()
    run = generate_raw(cfg)
    bag = write_message_bag(out / 'bag', TOPICS, {}, (record_message(r) for r in run.records),
                            None)
    map_path = out / 'map.yaml'
    map_path.write_text(yaml.safe_dump(input_map(cfg), sort_keys=False), encoding='utf-8')
    return bag, map_path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('out_dir')
    ap.add_argument('--duration', type=float, default=60.0, help='s (default 60)')
    ap.add_argument('--seed', type=int, default=5)
    ap.add_argument('--imu-rate', type=float, default=100.0, help='Hz (default 100)')
    a = ap.parse_args(argv)
    if (Path(a.out_dir) / 'bag').exists():
        print(f'error: {Path(a.out_dir) / "bag"} exists', file=sys.stderr)
        return 2
    try:
        bag, map_path = write_raw_example(a.out_dir, a.duration, a.seed, a.imu_rate)
    except ValueError as err:
        print(f'error: {err}', file=sys.stderr)
        return 2
    print(f'wrote {bag} and {map_path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
