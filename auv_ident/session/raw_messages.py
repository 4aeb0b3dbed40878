"""Raw-sensor messages of an input map (session/input_map.py) read into
core.filter.raw.RawMeasurement records, in NED/FRD.

The frame: an entry's ``frame`` 'ned' (world NED, sensor axes FRD-like) or 'enu' (REP-103:
world ENU, sensor axes FLU-like); 'auto' reads the message's header frame_id: one that is or
ends in 'ned' or 'frd' is NED/FRD, any other ENU/FLU (REP-103 is the ROS default). A sensor's
vector (IMU rate, DVL velocity) stays in the sensor's own axes, flipped FLU -> FRD where the
map says ENU, because the mounting (lever arm, rotation sensor -> body) is held in FRD.

Covariances: a ROS covariance whose first entry is -1 ("not provided") or that is all zero is
passed as None, so the filter uses its default noise for that channel group.
"""
from dataclasses import replace
from typing import Any

import numpy as np

from auv_ident.core.filter.raw import RawMeasurement, RawSensorConfig
from auv_ident.core.model import raw_sensors as rs
from auv_ident.session.input_map import (
    DVL,
    IMU,
    InputEntry,
    InputMap,
    InputMapError,
    POSE,
    PRESSURE,
)
from auv_ident.session.messages import _Q_FRD_FLU, _Q_NED_ENU, quat_multiply

RAW_TYPES = (IMU, DVL, PRESSURE, POSE)
# FLU <-> FRD on a body/sensor vector, ENU <-> NED on a world position (their own inverses)
_FLIP = np.array([1.0, -1.0, -1.0])
_POS_PERM, _POS_SIGN = [1, 0, 2], np.array([1.0, 1.0, -1.0])


def is_ned(entry: InputEntry, msg: Any) -> bool:
    """True if the entry's message is in NED/FRD (module docstring)."""
    if entry.frame != 'auto':
        return entry.frame == 'ned'
    fid = str(getattr(getattr(msg, 'header', None), 'frame_id', '')).lower().lstrip('/')
    return fid in ('ned', 'frd') or fid.endswith(('_ned', '_frd'))


def _cov(values: Any, n: int, sign: np.ndarray | None = None) -> np.ndarray | None:
    """(n, n) covariance of a ROS row-major array, sign-flipped as S C S; None if absent."""
    c = np.asarray(values, dtype=float).reshape(n, n)
    if c[0, 0] == -1.0 or not np.any(c):
        return None
    return c if sign is None else c * np.outer(sign, sign)


def raw_record(entry: InputEntry, msg: Any, t: float) -> RawMeasurement:
    """One raw-sensor message of ``entry`` at ``t`` s as a RawMeasurement (sensor: the entry's
    name). InputMapError for a type this reader does not convert."""
    ned = is_ned(entry, msg)
    if entry.type == IMU:
        o, w = msg.orientation, msg.angular_velocity
        q = (o.x, o.y, o.z, o.w)
        rate = np.array([w.x, w.y, w.z], dtype=float)
        if not ned:
            # q_ned_frd = q(ENU->NED) q_enu_flu q(FLU->FRD): both fixed rotations self-inverse
            q = quat_multiply(quat_multiply(_Q_NED_ENU, q), _Q_FRD_FLU)
            rate = rate * _FLIP
        c_att = _cov(msg.orientation_covariance, 3, None if ned else _FLIP)
        c_rate = _cov(msg.angular_velocity_covariance, 3, None if ned else _FLIP)
        cov = None
        if c_att is not None and c_rate is not None:
            cov = np.block([[c_att, np.zeros((3, 3))], [np.zeros((3, 3)), c_rate]])
        return RawMeasurement('imu', t, np.concatenate([q, rate]), cov, entry.name)
    if entry.type == DVL:
        v = msg.twist.twist.linear
        vel = np.array([v.x, v.y, v.z], dtype=float) * (1.0 if ned else _FLIP)
        cov = _cov(np.asarray(msg.twist.covariance, dtype=float).reshape(6, 6)[:3, :3], 3,
                   None if ned else _FLIP)
        return RawMeasurement('dvl', t, vel, cov, entry.name)
    if entry.type == PRESSURE:
        var = float(msg.variance)
        return RawMeasurement('pressure', t, np.array([float(msg.fluid_pressure)]),
                              np.array([[var]]) if var > 0 else None, entry.name)
    if entry.type == POSE:
        p = msg.pose.pose.position
        pos = np.array([p.x, p.y, p.z], dtype=float)
        c = np.asarray(msg.pose.covariance, dtype=float).reshape(6, 6)[:3, :3]
        if not ned:
            pos, c = (pos[_POS_PERM] * _POS_SIGN,
                      c[np.ix_(_POS_PERM, _POS_PERM)] * np.outer(_POS_SIGN, _POS_SIGN))
        if entry.option('measures') == 'depth':
            return RawMeasurement('depth', t, pos[2:], _cov(c[2:, 2:], 1), entry.name)
        return RawMeasurement('position', t, pos, _cov(c, 3), entry.name)
    raise InputMapError(f'input {entry.name!r} ({entry.type}): not a raw-sensor type this '
                        'reader converts (' + ', '.join(RAW_TYPES) + ')')


def raw_sensor_config(input_map: InputMap) -> RawSensorConfig:
    """RawSensorConfig of the map's sensors: each one's mounting (by input name), the DVL's
    reference, the pressure sensor's density (kg/m^3), gravity (m/s^2) and surface pressure
    (Pa)."""
    cfg = RawSensorConfig(mountings={
        e.name: rs.Mounting(np.array(e.mounting.lever_arm, dtype=float), e.mounting.matrix)
        for e in input_map.sensors})
    for e in input_map.sensors:
        if e.type == DVL:
            cfg = replace(cfg, dvl_reference=e.option('reference'))
        elif e.type == PRESSURE:
            cfg = replace(cfg, rho=float(e.option('density')), g=float(e.option('gravity')),
                          p_surface=float(e.option('surface_pressure')))
    return cfg
