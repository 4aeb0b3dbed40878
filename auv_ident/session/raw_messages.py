"""Raw-sensor messages of an input map (session/input_map.py) read into
core.filter.raw.RawMeasurement records, in NED/FRD.

The frame: an entry's ``frame`` 'ned' (world NED, sensor axes FRD-like) or 'enu' (REP-103:
world ENU, sensor axes FLU-like); 'auto' reads the message's header frame_id: one that is or
ends in 'ned' or 'frd' is NED/FRD, any other ENU/FLU (REP-103 is the ROS default). A sensor's
vector (IMU rate, DVL velocity) stays in the sensor's own axes, flipped FLU -> FRD where the
map says ENU, because the mounting (lever arm, rotation sensor -> body) is held in FRD.

A NavSatFix (a GNSS fix at the surface) is a horizontal position fix: latitude and longitude
turned into north and east metres about the origin (the map's ``datum``, else the run's first
fix) on the flat earth (navsat_ned: the WGS-84 meridian and prime-vertical radii at the
origin; within 1e-4 relative over 10 km, more than any GNSS fix needs), altitude not used (a
submerged vehicle has no fix; depth comes from its own sensor). A message without a fix
(status < 0) or with a NaN coordinate becomes a position record of NaN values, which the filter
counts as non-finite and does not fuse. Its ``position_covariance`` (ENU, m^2) is read when
its type is not 0 (unknown).

Covariances: a ROS covariance whose first entry is -1 ("not provided") or that is all zero is
passed as None, so the filter uses its default noise for that channel group.
"""
from dataclasses import replace
import math
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
    NAVSAT,
    POSE,
    PRESSURE,
)
from auv_ident.session.messages import _Q_FRD_FLU, _Q_NED_ENU, quat_multiply

RAW_TYPES = (IMU, DVL, PRESSURE, POSE, NAVSAT)
WGS84_A = 6378137.0                 # m, the WGS-84 semi-major axis
WGS84_E2 = 6.69437999014e-3         # its first eccentricity squared
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


def navsat_ned(lat: float, lon: float, lat0: float, lon0: float) -> np.ndarray:
    """(2,) north, east (m) of latitude, longitude (deg) about the origin (lat0, lon0) deg on
    the flat earth (module docstring): the WGS-84 meridian radius M and prime-vertical radius N
    at lat0, north = M dlat, east = N cos(lat0) dlon (dlat, dlon in rad; dlon wrapped to
    [-180, 180) deg)."""
    phi0 = np.radians(lat0)
    s2 = np.sin(phi0) ** 2
    n_radius = WGS84_A / np.sqrt(1.0 - WGS84_E2 * s2)
    m_radius = n_radius * (1.0 - WGS84_E2) / (1.0 - WGS84_E2 * s2)
    dlon = (lon - lon0 + 180.0) % 360.0 - 180.0
    return np.array([m_radius * np.radians(lat - lat0),
                     n_radius * np.cos(phi0) * np.radians(dlon)])


def navsat_origin(entry: InputEntry, msg: Any) -> tuple[float, float] | None:
    """The (lat, lon) deg origin a NavSatFix of ``entry`` is measured from: the map's datum,
    else this message's own fix if it has one (the caller keeps the first), else None."""
    datum = entry.option('datum')
    if datum is not None:
        return (float(datum[0]), float(datum[1]))
    if _has_fix(msg):
        return (float(msg.latitude), float(msg.longitude))
    return None


def _has_fix(msg: Any) -> bool:
    return (int(msg.status.status) >= 0 and math.isfinite(float(msg.latitude))
            and math.isfinite(float(msg.longitude)))


def _navsat(entry: InputEntry, msg: Any, t: float,
            origin: tuple[float, float] | None) -> RawMeasurement:
    """A NavSatFix as a horizontal position record (module docstring)."""
    origin = navsat_origin(entry, msg) if entry.option('datum') is not None else origin
    if origin is None or not _has_fix(msg):
        return RawMeasurement('position', t, np.full(2, np.nan), None, entry.name)
    ne = navsat_ned(float(msg.latitude), float(msg.longitude), *origin)
    cov = None
    if int(msg.position_covariance_type) != 0:
        c = np.asarray(msg.position_covariance, dtype=float).reshape(3, 3)
        # ENU (east, north, up) -> (north, east)
        cov = _cov(c[np.ix_([1, 0], [1, 0])], 2)
    return RawMeasurement('position', t, ne, cov, entry.name)


def imu_vectors(msg: Any, ned: bool) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(orientation x y z w sensor -> NED, rates p q r rad/s FRD) of a sensor_msgs/Imu in NED/FRD
    (ned) or ENU/FLU."""
    o, w = msg.orientation, msg.angular_velocity
    q = (o.x, o.y, o.z, o.w)
    rate = (float(w.x), float(w.y), float(w.z))
    if ned:
        return q, rate
    # q_ned_frd = q(ENU->NED) q_enu_flu q(FLU->FRD): both fixed rotations self-inverse
    return (quat_multiply(quat_multiply(_Q_NED_ENU, q), _Q_FRD_FLU),
            (rate[0], -rate[1], -rate[2]))


def imu_covariance(msg: Any, ned: bool) -> np.ndarray | None:
    """(6, 6) attitude then rate covariance of a sensor_msgs/Imu (NED/FRD; None unless it
    gives both)."""
    c_att = _cov(msg.orientation_covariance, 3, None if ned else _FLIP)
    c_rate = _cov(msg.angular_velocity_covariance, 3, None if ned else _FLIP)
    if c_att is None or c_rate is None:
        return None
    # filled in place: np.block costs ~20 us per message at 400 Hz
    cov = np.zeros((6, 6))
    cov[:3, :3] = c_att
    cov[3:, 3:] = c_rate
    return cov


def raw_record(entry: InputEntry, msg: Any, t: float,
               origin: tuple[float, float] | None = None) -> RawMeasurement:
    """One raw-sensor message of ``entry`` at ``t`` s as a RawMeasurement (sensor: the entry's
    name). origin: a NavSatFix entry's (lat, lon) deg origin where the map gives no datum (the
    caller's first fix: navsat_origin); unused by the other types. InputMapError for a type
    this reader does not convert."""
    if entry.type == NAVSAT:
        return _navsat(entry, msg, t, origin)
    ned = is_ned(entry, msg)
    if entry.type == IMU:
        q, rate = imu_vectors(msg, ned)
        return RawMeasurement('imu', t, np.array([*q, *rate], dtype=float),
                              imu_covariance(msg, ned), entry.name)
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


def raw_sensor_config(input_map: InputMap,
                      mountings: dict[str, Any] | None = None) -> RawSensorConfig:
    """RawSensorConfig of the map's sensors: each one's mounting (by input name; the map's own,
    or ``mountings``, input name -> the map's Mounting type, where a bag's /tf_static was merged
    in by offline/tf_static.py), the DVL's reference, the pressure sensor's density (kg/m^3),
    gravity (m/s^2) and surface pressure (Pa)."""
    given = mountings if mountings is not None else {e.name: e.mounting for e in input_map.sensors}
    cfg = RawSensorConfig(mountings={
        name: rs.Mounting(np.array(m.lever_arm, dtype=float), m.matrix)
        for name, m in given.items()})
    for e in input_map.sensors:
        if e.type == DVL:
            cfg = replace(cfg, dvl_reference=e.option('reference'))
        elif e.type == PRESSURE:
            cfg = replace(cfg, rho=float(e.option('density')), g=float(e.option('gravity')),
                          p_surface=float(e.option('surface_pressure')))
    return cfg
