"""Measurement models of the raw sensors an AUV carries, each seeing only the states it measures
(issue 28 item 2): what the filter of core/filter/raw.py fuses one message at a time.

Frames and units: body FRD, world NED, ZYX Euler angles, R = Rz(psi) Ry(theta) Rx(phi) body ->
world; m, m/s, rad, rad/s, Pa. A sensor's mounting is its lever arm r (m, body FRD, from the
body origin to the sensor) and the rotation R_s that takes a vector from the sensor's frame to
the body frame (v_body = R_s v_sensor).

Every model h(x) returns the predicted measurement and its Jacobian with respect to the whole
filter state x_f = [x (12 vehicle states), theta (model parameters: coefficients, then the
identified water-current components), e (the sensor errors the filter estimates, SensorErrors)]:

=========== ================================================ ============================
sensor      h                                                states it sees
=========== ================================================ ============================
attitude    R_meas R(eta)^T = Exp(nu), nu ~ N(0, C) (3, rad)  phi theta psi
            (the small rotation between the measured and
            predicted attitude, world axes: the frame of
            sensor_msgs/Imu's orientation covariance)
gyro        R_s^T (omega + b_g)                               p q r, gyro bias b_g
DVL         (1 + k) R_s^T Rz(a)^T (v + omega x r + c)         u v w, p q r, misalignment a,
            c = -R^T v_c (water track, state over ground),    scale k (and phi theta psi,
            +R^T v_c (bottom track, state through water),     current: when c != 0)
            else 0
depth       z + (R r)_3 + d (m, down)                          z, phi theta psi (r != 0),
                                                              depth offset d
pressure    p_surface + rho g (z + (R r)_3 + d) (Pa)          as depth
position    (x y z) + R r, the first 2 or 3                    x y z (phi theta psi, r != 0)
=========== ================================================ ============================

The Jacobians are analytic; test/core/test_raw_sensors.py checks each against central finite
differences.
"""
from dataclasses import dataclass, field
import math

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.compiled_cache import cached_njit
from auv_ident.core.errors import ConfigError
from auv_ident.core.model.state import ANGULAR, CURRENT_NAMES, EULER, LINEAR, N_STATE, State

# the sensor errors a filter may estimate, in this order (those switched on), with their units
ERROR_NAMES = ('gyro_bias_p', 'gyro_bias_q', 'gyro_bias_r', 'dvl_misalignment', 'dvl_scale',
               'depth_offset')
ERROR_UNITS = ('rad/s', 'rad/s', 'rad/s', 'rad', '1', 'm')
GRAVITY = 9.80665          # m/s^2, standard gravity
SEAWATER_DENSITY = 1025.0  # kg/m^3
STANDARD_ATMOSPHERE = 101325.0  # Pa, the surface pressure when none is given


@dataclass(frozen=True)
class Mounting:
    """Where a sensor sits: lever_arm (3,) m body FRD from the body origin, rotation (3, 3)
    sensor frame -> body frame (orthonormal, det +1)."""

    lever_arm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    def __post_init__(self) -> None:
        r = np.asarray(self.lever_arm, dtype=float)
        R = np.asarray(self.rotation, dtype=float)
        if r.shape != (3,) or not np.all(np.isfinite(r)):
            raise ConfigError(f'mounting lever_arm must be 3 finite numbers (m), got {r}')
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6) \
                or np.linalg.det(R) < 0:
            raise ConfigError(f'mounting rotation must be a 3x3 rotation matrix, got {R}')
        object.__setattr__(self, 'lever_arm', r)
        object.__setattr__(self, 'rotation', R)


def rotation_and_derivatives(phi: float, theta: float,
                             psi: float) -> tuple[np.ndarray, np.ndarray]:
    """(R (3, 3), dR (3, 3, 3)) with R = Rz(psi) Ry(theta) Rx(phi) (body -> NED) and dR[i] its
    derivative with respect to the i-th Euler angle (phi, theta, psi)."""
    cf, sf = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cf, -sf], [0.0, sf, cf]])
    Ry = np.array([[ct, 0.0, st], [0.0, 1.0, 0.0], [-st, 0.0, ct]])
    Rz = np.array([[cp, -sp, 0.0], [sp, cp, 0.0], [0.0, 0.0, 1.0]])
    dRx = np.array([[0.0, 0.0, 0.0], [0.0, -sf, -cf], [0.0, cf, -sf]])
    dRy = np.array([[-st, 0.0, ct], [0.0, 0.0, 0.0], [-ct, 0.0, -st]])
    dRz = np.array([[-sp, -cp, 0.0], [cp, -sp, 0.0], [0.0, 0.0, 0.0]])
    R = Rz @ Ry @ Rx
    dR = np.stack([Rz @ Ry @ dRx, Rz @ dRy @ Rx, dRz @ Ry @ Rx])
    return R, dR


@cached_njit()
def rotation(phi: float, theta: float, psi: float) -> np.ndarray:
    """R = Rz(psi) Ry(theta) Rx(phi) (body -> NED). Compiled: the IMU update of
    core/filter/raw_update.py calls it too."""
    cf, sf = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    return np.array([[cp * ct, -sp * cf + cp * st * sf, sp * sf + cp * cf * st],
                     [sp * ct, cp * cf + sf * st * sp, -cp * sf + st * sp * cf],
                     [-st, ct * sf, ct * cf]])


@cached_njit()
def rotation_of_quaternion(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of the quaternion q (4,) = (x, y, z, w) (normalised here)."""
    s = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    x, y, z, w = q[0] * s, q[1] * s, q[2] * s, q[3] * s
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def euler_of_rotation(R: np.ndarray) -> np.ndarray:
    """(phi, theta, psi) rad of R = Rz(psi) Ry(theta) Rx(phi)."""
    return np.array([math.atan2(R[2, 1], R[2, 2]),
                     -math.asin(max(-1.0, min(1.0, R[2, 0]))),
                     math.atan2(R[1, 0], R[0, 0])])


def rotation_log(R: np.ndarray) -> np.ndarray:
    """The rotation vector (3,) rad of R (axis times angle, angle in [0, pi])."""
    c = max(-1.0, min(1.0, 0.5 * (np.trace(R) - 1.0)))
    angle = math.acos(c)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-8:
        return 0.5 * v
    if math.pi - angle < 1e-6:
        # near pi the antisymmetric part vanishes: the axis from the symmetric part
        axis = np.sqrt(np.maximum(0.0, (np.diag(R) + 1.0) / 2.0))
        k = int(np.argmax(axis))
        axis[:k] = np.copysign(axis[:k], R[k, :k] + R[:k, k])
        axis[k + 1:] = np.copysign(axis[k + 1:], R[k, k + 1:] + R[k + 1:, k])
        return angle * axis / np.linalg.norm(axis)
    return angle / (2.0 * math.sin(angle)) * v


def euler_to_world_rate(phi: float, theta: float, psi: float) -> np.ndarray:
    """E (3, 3): the world-frame small rotation d(rotvec) = E d(phi, theta, psi) of a change of
    the Euler angles (columns: the axes the three angles turn about, in NED)."""
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    return np.array([[cp * ct, -sp, 0.0], [sp * ct, cp, 0.0], [-st, 0.0, 1.0]])


def _skew(a: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


@dataclass(frozen=True)
class Layout:
    """Where things sit in the filter state x_f (n,): the vehicle states first (state.State),
    then the model's p parameters (`current` holds, per NED component, its index in x_f or -1
    when the component is the model's fixed value), then the sensor errors (`errors`: name ->
    index in x_f, ERROR_NAMES order)."""

    n: int
    current: tuple[int, int, int]
    errors: dict[str, int]

    @staticmethod
    def of(theta_names: list[str], error_names: list[str]) -> 'Layout':
        p = len(theta_names)
        cur = tuple(N_STATE + theta_names.index(c) if c in theta_names else -1
                    for c in CURRENT_NAMES)
        errors = {e: N_STATE + p + i for i, e in enumerate(error_names)}
        return Layout(N_STATE + p + len(error_names), cur, errors)  # type: ignore[arg-type]

    def error(self, xf: np.ndarray, name: str, default: float = 0.0) -> float:
        """The value of sensor error `name` in xf (default when not estimated)."""
        i = self.errors.get(name)
        return default if i is None else float(xf[i])


def attitude_innovation(xf: np.ndarray, q_sensor: ArrayLike, mount: Mounting,
                        n: int) -> tuple[np.ndarray, np.ndarray]:
    """(nu (3,), H (3, n)): the attitude innovation Log(R_meas R(eta)^T) (rad, world axes) of an
    IMU orientation q_sensor (x, y, z, w; sensor frame -> NED) and its Jacobian with respect to
    xf (d nu / d xf = -H: nu = H (x_true - x) to first order)."""
    R_meas = rotation_of_quaternion(np.asarray(q_sensor, dtype=float)) @ mount.rotation.T
    nu = rotation_log(R_meas @ rotation(*xf[EULER]).T)
    H = np.zeros((3, n))
    H[:, EULER] = euler_to_world_rate(*xf[EULER])
    return nu, H


def gyro(xf: np.ndarray, mount: Mounting, lay: Layout) -> tuple[np.ndarray, np.ndarray]:
    """(h (3,) rad/s in the sensor frame, H (3, n)) of a gyro: R_s^T (omega + b_g)."""
    b = np.array([lay.error(xf, e) for e in ERROR_NAMES[:3]])
    Rt = mount.rotation.T
    h = Rt @ (xf[ANGULAR] + b)
    H = np.zeros((3, lay.n))
    H[:, ANGULAR] = Rt
    for j, e in enumerate(ERROR_NAMES[:3]):
        if e in lay.errors:
            H[:, lay.errors[e]] = Rt[:, j]
    return h, H


def _current_term(xf: np.ndarray, model_current: np.ndarray, sign: float, lay: Layout,
                  H_w: np.ndarray) -> np.ndarray:
    """sign R^T v_c (3,) (body frame) and its Jacobian added to H_w (3, n)."""
    vc = np.array([xf[i] if i >= 0 else model_current[c] for c, i in enumerate(lay.current)])
    R, dR = rotation_and_derivatives(*xf[EULER])
    for a in range(3):
        H_w[:, State.PHI + a] += sign * dR[a].T @ vc
    for c, i in enumerate(lay.current):
        if i >= 0:
            H_w[:, i] += sign * R.T[:, c]
    return sign * (R.T @ vc)


def dvl(xf: np.ndarray, mount: Mounting, lay: Layout, reference: str, state_reference: str,
        model_current: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(h (3,) m/s in the DVL frame, H (3, n)): (1 + k) R_s^T Rz(a)^T (v + omega x r + c).

    reference : 'ground' (bottom track) or 'water' (water track), what the DVL measures;
    state_reference : what the filter's u v w are (the model's velocity_reference); c the
    current's body-frame velocity when the two differ (module docstring); model_current (3,)
    m/s NED, the model's current for components the filter does not estimate.
    a (rad): the misalignment of the DVL's heading on the body (about body z); k: its scale
    error (1 + k times the true speed)."""
    n = lay.n
    r = mount.lever_arm
    omega = xf[ANGULAR]
    H_w = np.zeros((3, n))      # Jacobian of w = v + omega x r + c
    H_w[:, LINEAR] = np.eye(3)
    H_w[:, ANGULAR] = -_skew(r)
    w = xf[LINEAR] + np.cross(omega, r)
    if reference != state_reference:
        w = w + _current_term(xf, model_current, -1.0 if reference == 'water' else 1.0, lay,
                              H_w)
    a = lay.error(xf, 'dvl_misalignment')
    k = lay.error(xf, 'dvl_scale')
    ca, sa = math.cos(a), math.sin(a)
    RzT = np.array([[ca, sa, 0.0], [-sa, ca, 0.0], [0.0, 0.0, 1.0]])
    dRzT = np.array([[-sa, ca, 0.0], [-ca, -sa, 0.0], [0.0, 0.0, 0.0]])
    A = mount.rotation.T @ RzT
    h0 = A @ w
    H = (1.0 + k) * (A @ H_w)
    if 'dvl_misalignment' in lay.errors:
        H[:, lay.errors['dvl_misalignment']] = (1.0 + k) * (mount.rotation.T @ dRzT @ w)
    if 'dvl_scale' in lay.errors:
        H[:, lay.errors['dvl_scale']] = h0
    return (1.0 + k) * h0, H


def depth(xf: np.ndarray, mount: Mounting, lay: Layout) -> tuple[np.ndarray, np.ndarray]:
    """(h (1,) m, H (1, n)) of a depth sensor: z + (R r)_3 + d (d: the depth offset)."""
    R, dR = rotation_and_derivatives(*xf[EULER])
    r = mount.lever_arm
    H = np.zeros((1, lay.n))
    H[0, State.Z] = 1.0
    for a in range(3):
        H[0, State.PHI + a] = dR[a][2] @ r
    if 'depth_offset' in lay.errors:
        H[0, lay.errors['depth_offset']] = 1.0
    return np.array([xf[State.Z] + R[2] @ r + lay.error(xf, 'depth_offset')]), H


def pressure(xf: np.ndarray, mount: Mounting, lay: Layout, rho: float, g: float,
             p_surface: float) -> tuple[np.ndarray, np.ndarray]:
    """(h (1,) Pa, H (1, n)) of a pressure sensor: p_surface + rho g (depth of the sensor),
    rho kg/m^3, g m/s^2, p_surface Pa."""
    h, H = depth(xf, mount, lay)
    return p_surface + rho * g * h, rho * g * H


def position(xf: np.ndarray, mount: Mounting, lay: Layout,
             m: int) -> tuple[np.ndarray, np.ndarray]:
    """(h (m,) m NED, H (m, n)) of a position fix of the antenna/transponder at the lever arm:
    (x y z) + R r, its first m = 2 (horizontal) or 3 entries."""
    R, dR = rotation_and_derivatives(*xf[EULER])
    r = mount.lever_arm
    H = np.zeros((3, lay.n))
    H[:, 6:9] = np.eye(3)
    for a in range(3):
        H[:, State.PHI + a] = dR[a] @ r
    return (xf[6:9] + R @ r)[:m], H[:m]
