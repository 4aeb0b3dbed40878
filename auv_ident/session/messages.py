"""ROS-shaped messages read into numpy arrays, and the NED/FRD <-> ENU/FLU frame algebra.

The one place of the frame algebra: odometry read (:func:`odometry_to_state`) and written
(:func:`odometry_fields`), and the estimated water current published in the world frame of a
convention (:func:`current_twist_fields`).

Reading is duck-typed (attribute access only), so rclpy messages and rosbags-decoded ones are
read alike and this module imports no ROS package: the session layer and the bag layer both
use it. Building ROS messages (rclpy classes) is :mod:`auv_ident.ros.conversions`.

Conventions
-----------
State vector ``x12 = [u v w p q r x y z phi theta psi]``:

- ``u v w`` (m/s) and ``p q r`` (rad/s): body velocities in the body frame FRD
  (x forward, y starboard, z down).
- ``x y z`` (m): position in a world frame NED (x north, y east, z down).
- ``phi theta psi`` (rad): ZYX Euler angles (SNAME / Fossen): the rotation body FRD -> world
  NED is ``R = Rz(psi) Ry(theta) Rx(phi)``. Angles leaving this module are canonical:
  ``phi, psi`` in (-pi, pi], ``theta`` in [-pi/2, pi/2].

Actuator vector ``u7 = [delta_r, delta_s, delta_b, delta_bp, delta_bs, n_rpm, thrust]``
(core.model.state.Input): rudder, stern planes, bow planes, port bow plane, starboard bow
plane (rad), propeller speed (rpm) and measured propeller thrust (N).

nav_msgs/Odometry (REP-105 semantics):

- ``header.stamp`` is the sample time; ``header.frame_id`` the world frame,
  ``child_frame_id`` the body frame.
- ``pose.pose.position`` is the world position; ``pose.pose.orientation`` the quaternion of the
  rotation body -> world.
- ``twist.twist.linear`` / ``angular`` are body-frame velocities (twist is in the child frame).
- ``pose.covariance`` / ``twist.covariance`` are 6x6 row-major over
  ``(x, y, z, rotX, rotY, rotZ)``. The rotation block of the pose covariance is taken as the
  covariance of the fixed-axis roll/pitch/yaw angles, i.e. of ``(phi, theta, psi)`` in the NED
  convention (the reading used by robot_localization), so an EKF can put its Euler-angle
  covariance there unchanged.

Two frame conventions, selected by the string ``frame``:

- ``'ned'``: world NED, body FRD; default frame ids ``'odom_ned'`` / ``'base_link_frd'``.
- ``'enu'`` (REP-103): world ENU, body FLU; default frame ids ``'odom'`` / ``'base_link'``.

NED/FRD -> ENU/FLU: position and every world vector (the water current) ``(y, x, -z)``; body
vectors (linear and angular) ``(x, -y, -z)``; orientation
``q_enu_flu = q(NED->ENU) * q_ned_frd * q(FRD->FLU)``. In Euler angles this is exactly
``(phi, -theta, pi/2 - psi)``, so the pose covariance transforms with
``T_pose = blockdiag(P, E)``, ``P = [[0,1,0],[1,0,0],[0,0,-1]]``, ``E = diag(1,-1,-1)``, and the
twist covariance with ``T_twist = blockdiag(E, E)``: ``C' = T C T^T``. All T are signed
permutations, so the transforms are exact and their own inverses (T^-1 = T^T).

JointState layout for actuator commands: ``name = JOINT_NAMES``; ``position`` = fin angles (rad),
propeller entry 0.0 (meaningless); ``velocity = [0, 0, 0, 0, 0, shaft speed (rad/s)]``;
``effort = [0, 0, 0, 0, 0, measured thrust (N)]`` (never empty: an empty last float64 sequence
makes rclpy's padding unreadable for rosbags' strict reader; an AUV's commands carry thrust 0).
Readers match joints by name, in any order; a message without effort values reads as thrust 0
(bags recorded before the thrust existed). :func:`actuator_joint_fields` is the one place
both writers (ros/conversions.py, offline/sim_bag.py) take the layout from.

Non-finite values pass through unchanged: the caller decides (see :func:`is_finite_state`).
Bad input raises :class:`ConversionError` naming the field.
"""
from collections.abc import Sequence
import math
import operator
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.angles import wrap_angle
from auv_ident.core.errors import AuvIdentError
from auv_ident.core.model.state import CURRENT_NAMES, FINS, Input, N_INPUT

NS_PER_S = 1_000_000_000


class PublishGate:
    """Which good updates the live node publishes: all (``rate_hz`` 0), or the first in each
    interval of 1/rate_hz s of message stamps (the ``publish_rate_hz`` setting). Message time,
    not the wall clock, so a bag played at any speed publishes the same updates; a stamp in
    an earlier interval (a time jump back, a restart) is published and starts over."""
    __slots__ = ('period_ns', 'slot')

    def __init__(self, rate_hz: float) -> None:
        self.period_ns = round(NS_PER_S / rate_hz) if rate_hz > 0 else 0
        self.slot: int | None = None

    def due(self, stamp_ns: int) -> bool:
        """True if the update stamped ``stamp_ns`` is to be published (then it counts)."""
        if not self.period_ns:
            return True
        slot = int(stamp_ns) // self.period_ns
        if slot == self.slot:
            return False
        self.slot = slot
        return True
# A covariance diagonal entry at or above this (state units squared: a 1-sigma of 1000 m, m/s,
# rad or rad/s) says the message does not measure that channel (an imported log's unmeasured
# channel, a multi-rate log's sensor without a sample at that row): with noise_source
# 'message' the identifier then skips the channel for that message (session/session.py).
NOT_MEASURED_VARIANCE = 1e6

FRAMES = ('ned', 'enu')
DEFAULT_FRAME_IDS = {
    'ned': ('odom_ned', 'base_link_frd'),
    'enu': ('odom', 'base_link'),
}

# the joint of each core.model.state.Input channel, in that order
JOINT_NAMES = ('rudder', 'stern_planes', 'bow_planes', 'bow_plane_port',
               'bow_plane_starboard', 'propeller')
PROPELLER_JOINT = 'propeller'
RPM_TO_RAD_S = 2.0 * math.pi / 60.0

# q(NED->ENU): rotation by pi about (1, 1, 0)/sqrt(2); q(FRD->FLU): rotation by pi about x.
# Both are their own inverses as rotations. Quaternions are (x, y, z, w).
_S = math.sqrt(0.5)
_Q_NED_ENU = (_S, _S, 0.0, 0.0)
_Q_FRD_FLU = (1.0, 0.0, 0.0, 0.0)

# World position NED -> ENU and the Euler-angle / body-vector flip FRD -> FLU.
_P = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
_E = np.diag([1.0, -1.0, -1.0])
_Z3 = np.zeros((3, 3))
T_POSE_NED_TO_ENU = np.block([[_P, _Z3], [_Z3, _E]])
T_TWIST_FRD_TO_FLU = np.block([[_E, _Z3], [_Z3, _E]])
# The same maps as index permutations and signs: a matmul would turn a single inf into NaNs
# elsewhere (0 * inf), and non-finite values must pass through unchanged.
_POS_PERM, _POS_SIGN = np.array([1, 0, 2]), np.array([1.0, 1.0, -1.0])
_VEC_PERM, _VEC_SIGN = np.array([0, 1, 2]), np.array([1.0, -1.0, -1.0])
_POSE_PERM = np.array([1, 0, 2, 3, 4, 5])
_POSE_SIGN = np.array([1.0, 1.0, -1.0, 1.0, -1.0, -1.0])
_TWIST_PERM = np.arange(6)
_TWIST_SIGN = np.array([1.0, -1.0, -1.0, 1.0, -1.0, -1.0])
# the vector maps as tuples, for Python floats
_POS_PERM_T, _POS_SIGN_T = (1, 0, 2), (1.0, 1.0, -1.0)
_VEC_PERM_T, _VEC_SIGN_T = (0, 1, 2), (1.0, -1.0, -1.0)

# Below this cos(theta) the split of the rotation about the vertical into phi and psi is
# numerically meaningless (rounding error ~1e-16 / cos(theta)); phi is then set to 0.
_GIMBAL_COS = 1e-8


def _signed_perm(v: np.ndarray, perm: np.ndarray, sign: np.ndarray) -> np.ndarray:
    """Return T v for the signed permutation T with rows sign[i] * e_perm[i]."""
    return v[perm] * sign


def _signed_perm_cov(c: np.ndarray, perm: np.ndarray, sign: np.ndarray) -> np.ndarray:
    """Return T C T^T for the signed permutation T of :func:`_signed_perm`."""
    return c[np.ix_(perm, perm)] * np.outer(sign, sign)


class ConversionError(AuvIdentError, ValueError):
    """A ROS message or array could not be converted; the message names the culprit."""


# ---------------------------------------------------------------------------------------------
# time


def stamp_to_ns(stamp: Any) -> int:
    """Return a builtin_interfaces/Time as integer nanoseconds (exact); ConversionError for a
    nanosec outside [0, 10^9), which no valid Time has (it would alias another second)."""
    nanosec = int(stamp.nanosec)
    if not 0 <= nanosec < NS_PER_S:
        raise ConversionError(f'header.stamp.nanosec {nanosec} is outside [0, 10^9): not a '
                              'valid time')
    return int(stamp.sec) * NS_PER_S + nanosec


def stamp_to_sec(stamp: Any) -> float:
    """Return a builtin_interfaces/Time as float seconds (correctly rounded)."""
    # int / int true division is correctly rounded; sec + nanosec * 1e-9 is not.
    return stamp_to_ns(stamp) / NS_PER_S


def integer_stamp(stamp_ns: Any) -> int:
    """stamp_ns as an int (any integer type); ConversionError if it is not an integer."""
    try:
        return operator.index(stamp_ns)
    except TypeError:
        raise ConversionError(f'stamp_ns must be an integer number of ns, got '
                              f'{stamp_ns!r}') from None


def header_stamp_ns(msg: Any) -> int | None:
    """A message's header.stamp in integer ns, or None if the message has none that can be read;
    ConversionError naming the field for a stamp that is there but invalid."""
    try:
        return stamp_to_ns(msg.header.stamp)
    except ConversionError:
        raise
    except (AttributeError, TypeError, ValueError):
        return None


def sec_to_ns(t_sec: float) -> int:
    """Return float seconds as the nearest integer nanoseconds.

    Splitting off the integer part first keeps ns resolution at epoch-scale times, where
    ``t_sec * 1e9`` alone would lose ~100 ns.
    """
    t = float(t_sec)
    if not math.isfinite(t):
        raise ConversionError(f'time must be finite, got {t_sec!r}')
    whole = math.floor(t)
    frac_ns = round((t - whole) * NS_PER_S)  # t - floor(t) is exact in binary floating point
    return int(whole) * NS_PER_S + int(frac_ns)


# ---------------------------------------------------------------------------------------------
# rotations


def euler_to_quat(phi: float, theta: float, psi: float) -> tuple[float, float, float, float]:
    """Return the quaternion (x, y, z, w) of ZYX Euler angles (rad): Rz(psi) Ry(theta) Rx(phi)."""
    cr, sr = math.cos(0.5 * phi), math.sin(0.5 * phi)
    cp, sp = math.cos(0.5 * theta), math.sin(0.5 * theta)
    cy, sy = math.cos(0.5 * psi), math.sin(0.5 * psi)
    return (sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


def _unit_quat(x: float, y: float, z: float, w: float,
               name: str = 'quaternion') -> tuple[float, float, float, float]:
    x, y, z, w = float(x), float(y), float(z), float(w)
    isfinite = math.isfinite
    if not (isfinite(x) and isfinite(y) and isfinite(z) and isfinite(w)):
        raise ConversionError(f'{name} is not finite: {(x, y, z, w)}')
    n = math.sqrt(sum((x * x, y * y, z * z, w * w)))
    if n == 0.0:
        raise ConversionError(f'{name} has zero norm')
    return x / n, y / n, z / n, w / n


def quat_to_euler(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """Return ZYX Euler angles (phi, theta, psi) (rad) of a quaternion (x, y, z, w).

    The quaternion is normalised first; a zero-norm or non-finite one raises ConversionError.
    At gimbal lock (cos(theta) < 1e-8) phi is set to 0 and psi carries the whole rotation
    about the vertical.
    """
    x, y, z, w = _unit_quat(x, y, z, w)
    # Rotation-matrix entries in homogeneous form (no 1 - 2(..) cancellation).
    r11 = w * w + x * x - y * y - z * z
    r21 = 2.0 * (x * y + w * z)
    r31 = 2.0 * (x * z - w * y)
    r32 = 2.0 * (y * z + w * x)
    r33 = w * w - x * x - y * y + z * z
    cos_theta = math.hypot(r11, r21)
    # atan2 instead of asin(-r31): full precision near theta = +-pi/2.
    theta = math.atan2(-r31, cos_theta)
    if cos_theta < _GIMBAL_COS:
        r12 = 2.0 * (x * y - w * z)
        r22 = w * w - x * x + y * y - z * z
        phi = 0.0
        psi = math.atan2(-r12, r22)
    else:
        phi = math.atan2(r32, r33)
        psi = math.atan2(r21, r11)
    return wrap_angle(phi), theta, wrap_angle(psi)


def quat_multiply(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float, float]:
    """Return the Hamilton product a * b of quaternions given as (x, y, z, w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


def euler_to_rotation_matrix(phi: float, theta: float, psi: float) -> np.ndarray:
    """Return the 3x3 rotation body FRD -> world NED, Rz(psi) Ry(theta) Rx(phi)."""
    cr, sr = math.cos(phi), math.sin(phi)
    cp, sp = math.cos(theta), math.sin(theta)
    cy, sy = math.cos(psi), math.sin(psi)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr]])


# ---------------------------------------------------------------------------------------------
# Odometry


def is_finite_state(x12: ArrayLike) -> bool:
    """Return True if every entry of the state vector is finite."""
    return bool(np.all(np.isfinite(np.asarray(x12, dtype=float))))


def _check_frame(frame: str) -> None:
    if frame not in FRAMES:
        raise ConversionError(f'frame must be one of {FRAMES}, got {frame!r}')


def _as_vector(values: Any, n: int, name: str) -> Any:
    if type(values) is np.ndarray and values.dtype == np.float64 and values.shape == (n,):
        return values               # the common case, without asarray's overhead
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConversionError(f'{name} is not numeric: {exc}') from None
    if arr.shape != (n,):
        raise ConversionError(f'{name} must have shape ({n},), got {arr.shape}')
    return arr


def _as_cov6(values: ArrayLike | None, name: str) -> np.ndarray:
    """Return a 6x6 float array from None (zeros), a 6x6 or a flat 36 array."""
    if values is None:
        return np.zeros((6, 6))
    if type(values) is np.ndarray and values.dtype == np.float64 and values.shape == (36,):
        return values.reshape(6, 6)     # what a message holds, without asarray's overhead
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConversionError(f'{name} is not numeric: {exc}') from None
    if arr.shape == (36,):
        arr = arr.reshape(6, 6)
    if arr.shape != (6, 6):
        raise ConversionError(f'{name} must be 6x6 or 36 long, got shape {arr.shape}')
    return arr


def _swap_state(
        pos: Sequence[float], lin: Sequence[float], ang: Sequence[float], quat: Sequence[float],
) -> tuple[list[float], list[float], list[float], tuple[float, float, float, float]]:
    """NED/FRD <-> ENU/FLU for position, linear and angular velocity (sequences of 3 floats,
    returned as lists) and the orientation quaternion (x, y, z, w). An involution."""
    return ([pos[i] * s for i, s in zip(_POS_PERM_T, _POS_SIGN_T)],
            [lin[i] * s for i, s in zip(_VEC_PERM_T, _VEC_SIGN_T)],
            [ang[i] * s for i, s in zip(_VEC_PERM_T, _VEC_SIGN_T)],
            quat_multiply(quat_multiply(_Q_NED_ENU, quat), _Q_FRD_FLU))


def _swap_ned_enu(pos: np.ndarray, lin: np.ndarray, ang: np.ndarray, quat: Sequence[float],
                  pcov: np.ndarray, tcov: np.ndarray) -> tuple[Any, ...]:
    """NED/FRD <-> ENU/FLU for position, linear and angular velocity, orientation and the two
    6x6 covariances. Every transform is an involution, so the same call maps either way."""
    return (_signed_perm(pos, _POS_PERM, _POS_SIGN), _signed_perm(lin, _VEC_PERM, _VEC_SIGN),
            _signed_perm(ang, _VEC_PERM, _VEC_SIGN),
            quat_multiply(quat_multiply(_Q_NED_ENU, quat), _Q_FRD_FLU),
            _signed_perm_cov(pcov, _POSE_PERM, _POSE_SIGN),
            _signed_perm_cov(tcov, _TWIST_PERM, _TWIST_SIGN))


def odometry_fields(x12: ArrayLike, frame: str = 'ned', pose_cov: ArrayLike | None = None,
                    twist_cov: ArrayLike | None = None, frame_id: str | None = None,
                    child_frame_id: str | None = None) -> tuple[Any, ...]:
    """What a nav_msgs/Odometry of a NED/FRD state holds in convention ``frame``: the one
    computation behind both message builders (rclpy: ros/conversions.py, rosbags:
    offline/sim_bag.py).

    Returns ``(pos (3,), quat (x, y, z, w), lin (3,), ang (3,), pose_cov (6, 6),
    twist_cov (6, 6), frame_id, child_frame_id)``; covariances are zeros if omitted, the frame
    ids the convention's defaults unless given.
    """
    _check_frame(frame)
    x = _as_vector(x12, 12, 'x12')
    pcov = _as_cov6(pose_cov, 'pose_cov')
    tcov = _as_cov6(twist_cov, 'twist_cov')
    lin, ang, pos = x[0:3], x[3:6], x[6:9]
    quat = euler_to_quat(x[9], x[10], x[11])
    if frame == 'enu':
        pos, lin, ang, quat, pcov, tcov = _swap_ned_enu(pos, lin, ang, quat, pcov, tcov)
    default_world, default_body = DEFAULT_FRAME_IDS[frame]
    return (pos, quat, lin, ang, pcov, tcov,
            default_world if frame_id is None else frame_id,
            default_body if child_frame_id is None else child_frame_id)


def _field(msg: Any, path: str) -> Any:
    """Return a nested attribute of an Odometry, naming a missing one in a ConversionError."""
    obj = msg
    for part in path.split('.'):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise ConversionError(
                f'{type(msg).__name__} has no field {path!r}; expected a nav_msgs/Odometry'
            ) from None
    return obj


def _xyz(msg: Any, path: str) -> list[float]:
    return [float(_field(msg, f'{path}.{axis}')) for axis in 'xyz']


def _odometry_fields_named(msg: Any) -> tuple[Any, ...]:
    """The fields of an Odometry, path by path, naming a missing one in a ConversionError:
    (t_sec, pos, quat, lin, ang, pose_cov, twist_cov), as in the message."""
    t_sec = stamp_to_sec(_field(msg, 'header.stamp'))
    pos = _xyz(msg, 'pose.pose.position')
    quat = tuple(float(_field(msg, f'pose.pose.orientation.{c}')) for c in 'xyzw')
    lin = _xyz(msg, 'twist.twist.linear')
    ang = _xyz(msg, 'twist.twist.angular')
    pcov = _as_cov6(_field(msg, 'pose.covariance'), 'pose.covariance')
    tcov = _as_cov6(_field(msg, 'twist.covariance'), 'twist.covariance')
    return t_sec, pos, quat, lin, ang, pcov, tcov


def _odometry_fields(msg: Any) -> tuple[Any, ...]:
    """:func:`_odometry_fields_named` without the per-field bookkeeping (the per-message cost
    of the live identifier). Reads and converts in the same order, so the first failure is
    the same one; a missing field (AttributeError) is left to the named version."""
    try:
        t_sec = stamp_to_sec(msg.header.stamp)
        pose = msg.pose
        p = pose.pose.position
        pos = [float(p.x), float(p.y), float(p.z)]
        o = pose.pose.orientation
        quat = (float(o.x), float(o.y), float(o.z), float(o.w))
        twist = msg.twist
        v = twist.twist.linear
        lin = [float(v.x), float(v.y), float(v.z)]
        w = twist.twist.angular
        ang = [float(w.x), float(w.y), float(w.z)]
        pcov = _as_cov6(pose.covariance, 'pose.covariance')
        tcov = _as_cov6(twist.covariance, 'twist.covariance')
    except AttributeError:
        return _odometry_fields_named(msg)
    return t_sec, pos, quat, lin, ang, pcov, tcov


def _state(pos: Sequence[float], quat: Sequence[float], lin: Sequence[float],
           ang: Sequence[float]) -> np.ndarray:
    """x12 (NED/FRD) from the fields of an NED/FRD Odometry."""
    if all(map(math.isfinite, quat)):
        try:
            eul = quat_to_euler(*quat)
        except ConversionError:
            raise ConversionError('pose.pose.orientation is a zero quaternion') from None
    else:
        eul = (math.nan, math.nan, math.nan)
    return np.array([*lin, *ang, *pos, *eul])     # core.model.state.State order


def odometry_to_state(msg: Any,
                      frame: str = 'ned') -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(t_sec, x12, pose_cov, twist_cov)`` in NED/FRD from an Odometry in ``frame``.

    Accepts rclpy messages and rosbags-decoded ones alike (attribute access only). A non-finite
    orientation gives NaN Euler angles (the caller decides); a zero quaternion, which only an
    unset message has, raises ConversionError.

    Returns
    -------
    t_sec : float
        header.stamp (s).
    x12 : ndarray, shape (12,)
        ``[u v w p q r x y z phi theta psi]`` (m/s, rad/s, m, rad), NED/FRD.
    pose_cov, twist_cov : ndarray, shape (6, 6)
        Covariances over (x, y, z, phi, theta, psi) and (u, v, w, p, q, r), NED/FRD.
    """
    _check_frame(frame)
    t_sec, pos, quat, lin, ang, pcov, tcov = _odometry_fields(msg)
    if frame == 'enu':
        pos, lin, ang, quat = _swap_state(pos, lin, ang, quat)
        pcov = _signed_perm_cov(pcov, _POSE_PERM, _POSE_SIGN)
        tcov = _signed_perm_cov(tcov, _TWIST_PERM, _TWIST_SIGN)
    return t_sec, _state(pos, quat, lin, ang), pcov, tcov


def odometry_state(msg: Any, frame: str = 'ned') -> tuple[float, np.ndarray]:
    """Return ``(t_sec, x12)`` of :func:`odometry_to_state`, without transforming the
    covariances (they are checked all the same: a message that odometry_to_state refuses is
    refused here too). What the identifier reads per message."""
    _check_frame(frame)
    t_sec, pos, quat, lin, ang, _, _ = _odometry_fields(msg)
    if frame == 'enu':
        pos, lin, ang, quat = _swap_state(pos, lin, ang, quat)
    return t_sec, _state(pos, quat, lin, ang)


_POSE_DIAG = (0, 7, 14, 21, 28, 35)   # row-major 6x6 diagonal


def covariance_entry(channel: int, frame: str = 'ned') -> str:
    """The Odometry field holding the variance of state channel `channel` (0..11, NED/FRD
    order, as odometry_variances reads it), e.g. 'twist.covariance[0]' for u."""
    if channel < 6:
        return f'twist.covariance[{_POSE_DIAG[channel]}]'
    j = channel - 6
    if frame == 'enu' and j < 2:
        j = 1 - j
    return f'pose.covariance[{_POSE_DIAG[j]}]'


def odometry_variances(msg: Any, frame: str = 'ned') -> np.ndarray:
    """The 12 variances an Odometry states for ``[u v w p q r x y z phi theta psi]``.

    The diagonals of twist.covariance (u v w p q r) and pose.covariance (x y z, and the
    rotation block read as phi theta psi), in NED/FRD order: for 'enu' x and y swap (variances
    do not change sign). Entries are returned as found (0, -1 or NaN mean 'not stated'); a
    message without covariance arrays of 36 entries gives all NaN.
    """
    _check_frame(frame)
    out = np.full(12, np.nan)
    try:
        tcov = msg.twist.covariance
        pcov = msg.pose.covariance
        if len(tcov) == 36 and len(pcov) == 36:
            out[0:6] = [float(tcov[i]) for i in _POSE_DIAG]
            pose = [float(pcov[i]) for i in _POSE_DIAG]
            if frame == 'enu':
                pose[0], pose[1] = pose[1], pose[0]
            out[6:12] = pose
    except (AttributeError, TypeError, ValueError):
        pass
    return out


# ---------------------------------------------------------------------------------------------
# The water current


def current_indices(names: Sequence[str]) -> list[int]:
    """[i_north, i_east, i_down]: where each water-current component (core.model.state
    CURRENT_NAMES) is among the identified parameters' names, -1 for one not identified."""
    return [names.index(n) if n in names else -1 for n in CURRENT_NAMES]


def current_twist_fields(estimate: np.ndarray, cov: np.ndarray, indices: Sequence[int],
                         frame: str = 'ned') -> tuple[np.ndarray, np.ndarray]:
    """What a geometry_msgs/TwistWithCovariance of the estimated water current holds in
    convention ``frame``: ``(linear (3,), covariance (36,))``.

    estimate (p,), cov (p, p) : the identified parameters and their covariance; indices :
    :func:`current_indices` of their names. linear is the current where the water goes in the
    world frame (NED: north, east, down; ENU: east, north, up; m/s); covariance is the 6x6
    twist covariance, row-major, with the current's covariance in the linear block. A
    component not identified is 0 with variance 0 (it is given, not measured), and so is the
    angular part (the current model is irrotational, Fossen 2021 sec. 10.3).
    """
    _check_frame(frame)
    lin = np.zeros(3)       # NED
    C = np.zeros((3, 3))
    for a, i in enumerate(indices):
        if i < 0:
            continue
        lin[a] = estimate[i]
        for b, j in enumerate(indices):
            if j >= 0:
                C[a, b] = cov[i, j]
    if frame == 'enu':      # world NED -> ENU: (E, N, -D), the position's signed permutation
        lin = _signed_perm(lin, _POS_PERM, _POS_SIGN)
        C = _signed_perm_cov(C, _POS_PERM, _POS_SIGN)
    full = np.zeros((6, 6))
    full[:3, :3] = C
    return lin, full.ravel()


# ---------------------------------------------------------------------------------------------
# JointState




def joint_state_to_actuators(msg: Any) -> tuple[float, np.ndarray]:
    """Return ``(t_sec, u7)`` from a JointState in the layout of :data:`JOINT_NAMES`.

    Joints are matched by name in any order; other joints are ignored. Raises ConversionError
    for a missing or duplicated joint, or a position/velocity array whose length differs from
    name's.
    """
    try:
        names = list(msg.name)
        position = np.asarray(msg.position, dtype=float)
        velocity = np.asarray(msg.velocity, dtype=float)
        effort = np.asarray(getattr(msg, 'effort', ()), dtype=float)
        stamp = msg.header.stamp
    except AttributeError as exc:
        raise ConversionError(f'not a sensor_msgs/JointState: {exc}') from None
    if len(position) != len(names):
        raise ConversionError(
            f'JointState.position has {len(position)} entries for {len(names)} names')
    if len(velocity) != len(names):
        raise ConversionError(
            f'JointState.velocity has {len(velocity)} entries for {len(names)} names '
            f'(the {PROPELLER_JOINT!r} shaft speed is read from velocity)')
    if len(effort) not in (0, len(names)):
        raise ConversionError(
            f'JointState.effort has {len(effort)} entries for {len(names)} names '
            f'(the {PROPELLER_JOINT!r} thrust is read from effort)')
    index = {}
    for i, name in enumerate(names):
        if name in index:
            raise ConversionError(f'JointState.name lists joint {name!r} twice')
        index[name] = i
    missing = [n for n in JOINT_NAMES if n not in index]
    if missing:
        raise ConversionError(
            f'JointState lacks joint(s) {missing}; present: {names}')
    u7 = np.empty(N_INPUT)
    for k, name in enumerate(JOINT_NAMES[FINS]):
        u7[k] = position[index[name]]
    u7[Input.N_RPM] = velocity[index[PROPELLER_JOINT]] / RPM_TO_RAD_S
    u7[Input.THRUST] = effort[index[PROPELLER_JOINT]] if len(effort) else 0.0
    return stamp_to_sec(stamp), u7


def actuator_joint_fields(u7: ArrayLike) -> tuple[list[float], list[float], list[float]]:
    """(position, velocity, effort) lists of floats of the actuator JointState of u7 (7,)
    (module docstring: fins in position, shaft speed in rad/s in velocity, thrust in effort).
    Raises ConversionError for a vector of another length."""
    u = _as_vector(u7, N_INPUT, 'u7')
    n = len(JOINT_NAMES)
    position = [float(v) for v in u[FINS]] + [0.0]
    velocity = [0.0] * (n - 1) + [float(u[Input.N_RPM]) * RPM_TO_RAD_S]
    effort = [0.0] * (n - 1) + [float(u[Input.THRUST])]
    return position, velocity, effort
