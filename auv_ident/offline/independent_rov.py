"""Independent data for a thruster vehicle: a BlueROV2 Heavy tank session as a rosbag2 MCAP bag,
made by a 6-DOF model of its own (plain numpy/scipy) so that it can judge the package's
thruster model (issue 29). Nothing of ``auv_ident.core.model``, the simulator or
``offline.independent_data`` (which imports the model) is used: the kinematics and quaternions
below are written out again on purpose; only model-free bag helpers are shared
(offline/generator_common.py).

Truth model (Fossen 2021, ch. 6-8, in body FRD / world NED)::

    (M_RB + M_A) nu_dot + C_RB(nu) nu + C_A(nu) nu + D(nu) nu + g(eta) = tau_thrusters

with the parameters of M. von Benzon et al., "An Open-Source Benchmark Simulator: Control of a
BlueROV2 Underwater Robot", J. Mar. Sci. Eng. 10(12):1898, 2022 (Table 3): m 13.5 kg,
V 0.0134 m^3 (rho 1000 kg/m^3, g 9.81 m/s^2), I = diag(0.26, 0.23, 0.37) kg m^2, r_G = 0,
r_B = (0, 0, -0.01) m; added mass magnitudes 6.3567, 7.1206, 18.6863, 0.1858, 0.1348, 0.2215
(its full Coriolis C_A(nu), Fossen eq. 6.43, and the rigid-body C_RB(nu), eq. 3.57 with
r_G = 0); linear damping 13.7, 0, 33.0, 0, 0.8, 0; quadratic damping 141, 217, 190, 1.192,
0.470, 1.500; restoring forces from W = m g and B = rho g V at r_G and r_B.

Thrusters: eight T200s, thrust interpolated linearly in Blue Robotics' published 16 V table
("T200 Public Performance Data 10-20V, September 2019", sheet 16 V, the PWM and force columns
as vortexntnu/vortex-auv motion/thruster_interface_auv/resources/T200-Thrusters-16V.csv
carries them; kgf * 9.80665 N), the TABLE itself and not a fit, so a fitted curve is judged;
its dead band 1472-1528 us gives 0 N. Truth thrust = (1 + thrust_perturb) * table (default
+10 %), optionally through a first-order motor lag. ``curve: file`` replaces the table by the
curve config/bluerov2_heavy.yaml states (the same published points through the file's
interpolation, a monotone piecewise cubic, here scipy's PchipInterpolator, not our loader or
kernel): the issue's "thrust curve perturbed 10 % from the file". The two differ only in
how they interpolate the same points: by at most 0.12 N, between the table's 4 us steps.
Positions (FRD, m) from clydemcqueen/bluerov2_ignition models/bluerov2_heavy/configs.yaml
(Gazebo FLU, y and z negated here); directions from ArduSub's VECTORED_6DOF frame (ardupilot
libraries/AP_Motors/AP_Motors6DOF.cpp): a PWM above 1500 us pushes along ``d``.

Thruster order (the order of ``/thrusters`` data and of config/bluerov2_heavy.yaml)::

    t1 horizontal front-right  r ( 0.140,  0.092,  0.000)  d (-0.7071,  0.7071, 0)
    t2 horizontal front-left   r ( 0.140, -0.092,  0.000)  d (-0.7071, -0.7071, 0)
    t3 horizontal rear-right   r (-0.150,  0.092,  0.000)  d ( 0.7071,  0.7071, 0)
    t4 horizontal rear-left    r (-0.150, -0.092,  0.000)  d ( 0.7071, -0.7071, 0)
    t5 vertical   front-right  r ( 0.118,  0.215, -0.064)  d (0, 0, 1)
    t6 vertical   front-left   r ( 0.118, -0.215, -0.064)  d (0, 0, 1)
    t7 vertical   rear-right   r (-0.118,  0.215, -0.064)  d (0, 0, 1)
    t8 vertical   rear-left    r (-0.118, -0.215, -0.064)  d (0, 0, 1)

Bag layout (``OUT/bag``, rosbag2 MCAP, rosbags Jazzy typestore):

- ``/thrusters`` std_msgs/msg/Float64MultiArray, 8 entries t1..t8, PWM in us (integers as
  floats, 1100..1900), layout.dim = [{label 'thrusters', size 8, stride 8}]. No header: the
  bag's log time is when it was received, and the truth switches at that log time. Published
  when a PWM changes on the pilot's 20 Hz clock, plus a repeat after ``repeat_period`` s of
  silence (a driver's keep-alive).
- ``/odom`` nav_msgs/msg/Odometry at ~``odom_rate`` Hz with jittered stamps, log time = stamp
  + a transport delay. ``frame='enu'`` (default, REP-103/105 as a ROS driver publishes):
  header.frame_id 'odom' (ENU), child_frame_id 'base_link' (FLU); ``frame='ned'``: 'odom_ned'
  and 'base_link_frd'. Pose = position and orientation of the body in the world frame; twist =
  body linear and angular velocity in the child frame. Covariances 6x6 row-major, diagonal,
  per ``covariance`` ('wrong' by default: the true variances times ``covariance_scale``).

Noise: AR(1) per channel on [u v w p q r x y z phi theta psi] (NED/FRD), each channel's 1-sigma
= base * U(noise_level) and correlation time U(noise_tau) s drawn from the seed; disclosed only
in ``OUT/truth.json`` (beside the bag, never inside), with the truth coefficients under the
names of config/bluerov2_heavy.yaml, the perturbation and the configuration.

Usage::

    python -m auv_ident.offline.independent_rov --out out/rov1 --seed 1 --duration 600
"""
import argparse
import dataclasses
from dataclasses import dataclass
import json
import math
from pathlib import Path
import sys

import numpy as np
from scipy.integrate import solve_ivp
from scipy.interpolate import PchipInterpolator

from auv_ident.offline.generator_common import (
    epoch_ns,
    jsonable,
    prepare_out_dir,
    qos,
    quat_of,
)

GENERATOR = 'auv_ident.offline.independent_rov v1'
NS = 1_000_000_000
KGF = 9.80665
THRUSTER_TOPIC, ODOM_TOPIC = '/thrusters', '/odom'
FRAMES = {'enu': ('odom', 'base_link'), 'ned': ('odom_ned', 'base_link_frd')}
CHANNELS = ('u', 'v', 'w', 'p', 'q', 'r', 'x', 'y', 'z', 'phi', 'theta', 'psi')
# base 1-sigma of a tank navigation solution (DVL/USBL-free: acoustic positioning and a
# doppler at tank scale), scaled per channel by a factor drawn from noise_level
BASE_SIGMA = (0.01, 0.01, 0.01, 0.002, 0.002, 0.002, 0.03, 0.03, 0.01, 0.003, 0.003, 0.005)

# --- T200 16 V table: PWM 1100..1900 us in 4 us steps, force kgf (Blue Robotics 2019)
T200_PWM = np.arange(1100, 1901, 4, dtype=float)
T200_KGF = np.array([
    -4.07, -4.05, -4.02, -3.96, -3.90, -3.87, -3.82, -3.80, -3.75, -3.71,
    -3.66, -3.59, -3.52, -3.45, -3.40, -3.31, -3.25, -3.20, -3.11, -3.04,
    -2.99, -2.94, -2.86, -2.82, -2.77, -2.71, -2.66, -2.58, -2.55, -2.51,
    -2.45, -2.38, -2.35, -2.28, -2.24, -2.20, -2.12, -2.08, -2.02, -1.98,
    -1.94, -1.86, -1.81, -1.76, -1.70, -1.67, -1.61, -1.56, -1.51, -1.49,
    -1.44, -1.40, -1.35, -1.30, -1.26, -1.20, -1.16, -1.12, -1.10, -1.05,
    -1.02, -0.98, -0.94, -0.90, -0.87, -0.82, -0.78, -0.74, -0.72, -0.68,
    -0.65, -0.62, -0.58, -0.54, -0.51, -0.48, -0.44, -0.42, -0.39, -0.35,
    -0.32, -0.29, -0.26, -0.24, -0.21, -0.18, -0.15, -0.13, -0.10, -0.09,
    -0.07, -0.05, -0.04, 0.00, 0.00, 0.00, 0.00, 0.00, 0.00, 0.00,
    0.00, 0.00, 0.00, 0.00, 0.00, 0.00, 0.00, 0.00, 0.04, 0.05,
    0.08, 0.10, 0.13, 0.15, 0.18, 0.22, 0.25, 0.29, 0.32, 0.36,
    0.40, 0.44, 0.47, 0.51, 0.56, 0.60, 0.64, 0.68, 0.72, 0.78,
    0.82, 0.87, 0.91, 0.95, 0.99, 1.03, 1.10, 1.14, 1.18, 1.24,
    1.28, 1.33, 1.39, 1.44, 1.48, 1.54, 1.59, 1.65, 1.69, 1.76,
    1.82, 1.88, 1.93, 1.99, 2.05, 2.12, 2.18, 2.22, 2.28, 2.38,
    2.43, 2.52, 2.58, 2.65, 2.73, 2.76, 2.84, 2.89, 2.98, 3.05,
    3.11, 3.17, 3.22, 3.30, 3.37, 3.42, 3.51, 3.61, 3.68, 3.74,
    3.82, 3.89, 3.96, 4.06, 4.15, 4.25, 4.30, 4.38, 4.51, 4.53,
    4.65, 4.71, 4.79, 4.84, 4.93, 5.01, 5.08, 5.14, 5.18, 5.22,
    5.25])
DEAD_BAND = (1472.0, 1528.0)

_S = 0.70710678118654752
THRUSTER_R = np.array([[0.140, 0.092, 0.0], [0.140, -0.092, 0.0], [-0.150, 0.092, 0.0],
                       [-0.150, -0.092, 0.0], [0.118, 0.215, -0.064], [0.118, -0.215, -0.064],
                       [-0.118, 0.215, -0.064], [-0.118, -0.215, -0.064]])
THRUSTER_D = np.array([[-_S, _S, 0.0], [-_S, -_S, 0.0], [_S, _S, 0.0], [_S, -_S, 0.0],
                       [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
THRUSTER_NAMES = ('t1', 't2', 't3', 't4', 't5', 't6', 't7', 't8')


@dataclass(frozen=True)
class RovTruth:
    """The truth vehicle (SI, FRD). Damping and added mass as positive magnitudes."""

    mass: float = 13.5
    volume: float = 0.0134
    rho: float = 1000.0
    g: float = 9.81
    inertia: tuple = (0.26, 0.23, 0.37)
    r_g: tuple = (0.0, 0.0, 0.0)
    r_b: tuple = (0.0, 0.0, -0.01)
    added_mass: tuple = (6.3567, 7.1206, 18.6863, 0.1858, 0.1348, 0.2215)
    linear_damping: tuple = (13.7, 0.0, 33.0, 0.0, 0.8, 0.0)
    quadratic_damping: tuple = (141.0, 217.0, 190.0, 1.192, 0.470, 1.500)

    @property
    def W(self):
        return self.mass * self.g

    @property
    def B(self):
        return self.rho * self.g * self.volume

    def coefficients(self, thrust_gain, motor_lag=0.0):
        """The truth under the names of config/bluerov2_heavy.yaml (its sign convention), and
        with a motor lag (s) its time constant under the name docs/vehicles.md gives the
        file's `thruster_lag` coefficient, thrust_time_constant."""
        out = {'thrust_gain_fwd': thrust_gain, 'thrust_gain_rev': thrust_gain}
        if motor_lag > 0:
            out['thrust_time_constant'] = float(motor_lag)
        for names, values in ((('X_udot', 'Y_vdot', 'Z_wdot', 'K_pdot', 'M_qdot', 'N_rdot'),
                               self.added_mass),
                              (('X_u', 'Y_v', 'Z_w', 'K_p', 'M_q', 'N_r'), self.linear_damping),
                              (('X_uu', 'Y_vv', 'Z_ww', 'K_pp', 'M_qq', 'N_rr'),
                               self.quadratic_damping)):
            out.update({n: -float(v) for n, v in zip(names, values)})
        return out


def skew(a):
    """S(a) with S(a) b = a x b."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def rotation(phi, theta, psi):
    """R = Rz(psi) Ry(theta) Rx(phi): body FRD -> world NED."""
    cf, sf, ct, st = math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    rz = np.array([[cp, -sp, 0.0], [sp, cp, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[ct, 0.0, st], [0.0, 1.0, 0.0], [-st, 0.0, ct]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cf, -sf], [0.0, sf, cf]])
    return rz @ ry @ rx


def t200_thrust(pwm, gain=1.0):
    """Thrust (N) of a T200 at 16 V: the published table interpolated linearly, times gain.
    Outside 1100..1900 us the table's end values (the ESC saturates)."""
    return gain * KGF * np.interp(np.asarray(pwm, float), T200_PWM, T200_KGF)


# the curve config/bluerov2_heavy.yaml states (its `thrusters:` entries; the same for all
# eight): the same published table (the file copies its 201 points, in kgf, as T200_KGF here)
# through the interpolation the file names, the monotone piecewise cubic (PCHIP), here scipy's
# own; the command saturated at 1100..1900 us (neutral 1500 +- command_max 400, the table's ends)
FILE_CURVE = {'pwm': T200_PWM, 'kgf': T200_KGF, 'interpolation': 'pchip',
              'command_range': (1100.0, 1900.0)}
_FILE_PCHIP = PchipInterpolator(FILE_CURVE['pwm'], KGF * FILE_CURVE['kgf'])


def file_curve_thrust(pwm, gain=1.0):
    """Thrust (N) of the vehicle file's curve (FILE_CURVE), times gain."""
    return gain * _FILE_PCHIP(np.clip(np.asarray(pwm, float), *FILE_CURVE['command_range']))


THRUST_CURVES = {'table': t200_thrust, 'file': file_curve_thrust}


def thruster_wrench(forces):
    """tau (6,) = sum_i [d_i F_i; r_i x d_i F_i] for the eight forces (N), FRD."""
    f = THRUSTER_D * np.asarray(forces, float)[:, None]
    return np.concatenate([f.sum(0), np.cross(THRUSTER_R, f).sum(0)])


class RovModel:
    """The right-hand side of the truth: state [nu (6), eta (6), thrust (8)] (thrust only with
    a motor lag); nu body FRD, eta = NED position and ZYX Euler angles."""

    def __init__(self, truth, lag=0.0):
        self.truth = truth
        self.lag = float(lag)
        self.A11 = np.diag(truth.added_mass[:3])
        self.A22 = np.diag(truth.added_mass[3:])
        self.Ib = np.diag(truth.inertia)
        m = truth.mass
        M_rb = np.zeros((6, 6))
        M_rb[:3, :3] = m * np.eye(3)
        M_rb[:3, 3:] = -m * skew(truth.r_g)
        M_rb[3:, :3] = m * skew(truth.r_g)
        M_rb[3:, 3:] = self.Ib - m * skew(truth.r_g) @ skew(truth.r_g)
        self.M = M_rb + np.diag(truth.added_mass)
        self.M_inv = np.linalg.inv(self.M)
        self.Dl = np.asarray(truth.linear_damping, float)
        self.Dq = np.asarray(truth.quadratic_damping, float)
        self.rg = np.asarray(truth.r_g, float)
        self.rb = np.asarray(truth.r_b, float)
        self.thrust_cmd = np.zeros(8)

    def coriolis(self, nu):
        """C_RB(nu) + C_A(nu) (Fossen 2021, Lagrangian forms of ch. 3 and 6): skew-symmetric."""
        m = self.truth.mass
        n1, n2 = nu[:3], nu[3:]
        C = np.zeros((6, 6))
        C[:3, 3:] = -m * skew(n1) - m * skew(skew(n2) @ self.rg)
        C[3:, :3] = C[:3, 3:]
        C[3:, 3:] = (m * skew(skew(n1) @ self.rg)
                     - skew((self.Ib - m * skew(self.rg) @ skew(self.rg)) @ n2))
        a1, a2 = self.A11 @ n1, self.A22 @ n2
        C[:3, 3:] += -skew(a1)
        C[3:, :3] += -skew(a1)
        C[3:, 3:] += -skew(a2)
        return C

    def restoring(self, eta):
        """g(eta): minus the weight and buoyancy wrench in the body frame."""
        R = rotation(*eta[3:6])
        fg = R.T @ np.array([0.0, 0.0, self.truth.W])
        fb = -(R.T @ np.array([0.0, 0.0, self.truth.B]))
        return -np.concatenate([fg + fb, np.cross(self.rg, fg) + np.cross(self.rb, fb)])

    def nu_dot(self, nu, eta, tau):
        damp = self.Dl * nu + self.Dq * np.abs(nu) * nu
        return self.M_inv @ (tau - self.coriolis(nu) @ nu - damp - self.restoring(eta))

    def __call__(self, t, y):
        nu, eta = y[:6], y[6:12]
        thrust = y[12:20] if self.lag > 0 else self.thrust_cmd
        phi, theta = eta[3], eta[4]
        cf, sf, ct, tt = math.cos(phi), math.sin(phi), math.cos(theta), math.tan(theta)
        p, q, r = nu[3:]
        out = np.empty(len(y))
        out[:6] = self.nu_dot(nu, eta, thruster_wrench(thrust))
        out[6:9] = rotation(*eta[3:6]) @ nu[:3]
        out[9:12] = (p + sf * tt * q + cf * tt * r, cf * q - sf * r, (sf * q + cf * r) / ct)
        if self.lag > 0:
            out[12:20] = (self.thrust_cmd - thrust) / self.lag
        return out

    def energy(self, nu):
        """Kinetic energy 0.5 nu^T M nu (J)."""
        return 0.5 * float(nu @ self.M @ nu)


@dataclass
class RovConfig:
    """One tank session (s, Hz, us unless noted). Random draws come from independent streams of
    ``seed`` so that changing one option keeps the others' draws."""

    duration: float = 600.0
    seed: int = 0
    depth0: float = 1.5                 # m, initial depth (NED z)
    start_time: str = '2025-09-16T14:00:00Z'
    thrust_perturb: float = 0.10        # truth thrust = (1 + this) * table
    curve: str = 'table'                # 'table' (T200 table) or 'file' (the file's curve)
    motor_lag: float = 0.0              # s, first-order thrust lag (0: none)
    pilot_rate: float = 20.0            # Hz, the stick's clock
    repeat_period: float = 2.0          # s of silence before a command is repeated
    command_delay: tuple = (0.001, 0.010)   # the published command's trip to the recorder
    stick_levels: tuple = (0.2, 0.6)    # |stick| of a step, U(a, b)
    depth_band: float = 1.0             # m: the pilot steers back beyond depth0 +- this
    odom_rate: float = 20.0
    odom_jitter: float = 0.2            # stamp jitter, +- this fraction of the period
    odom_delay: tuple = (0.002, 0.020)
    frame: str = 'enu'                  # 'enu' (REP-103/105) or 'ned'
    noise: str = 'ar1'                  # 'ar1' or 'none'
    noise_level: tuple = (0.5, 2.0)     # per-channel factor on BASE_SIGMA, U(a, b)
    noise_tau: tuple = (0.2, 3.0)       # s, per-channel AR(1) correlation time, U(a, b)
    covariance: str = 'wrong'           # 'wrong', 'true' or 'zero'
    covariance_scale: float = 0.1       # 'wrong': the true variances times this
    rtol: float = 1e-9                  # RK45 relative tolerance (atol = rtol * 1e-3)

    def validate(self):
        """ValueError naming the first bad field."""
        if self.duration <= 0:
            raise ValueError('duration must be > 0 s')
        if not 0 < self.odom_rate <= 1000 or not 0 < self.pilot_rate <= 1000:
            raise ValueError('odom_rate and pilot_rate must be in (0, 1000] Hz')
        if not 0 <= self.odom_jitter < 0.5:
            raise ValueError('odom_jitter must be in [0, 0.5) (stamps stay ordered)')
        if not -0.5 < self.thrust_perturb < 1:
            raise ValueError('thrust_perturb must be in (-0.5, 1)')
        if self.motor_lag < 0 or self.repeat_period <= 0 or self.depth_band <= 0:
            raise ValueError('motor_lag must be >= 0, repeat_period and depth_band > 0')
        for name, options in (('frame', ('enu', 'ned')), ('noise', ('ar1', 'none')),
                              ('curve', tuple(THRUST_CURVES)),
                              ('covariance', ('wrong', 'true', 'zero'))):
            if getattr(self, name) not in options:
                raise ValueError(f'{name} must be one of {options}')
        for name in ('command_delay', 'stick_levels', 'odom_delay', 'noise_level', 'noise_tau'):
            a, b = getattr(self, name)
            if not 0 <= a <= b:
                raise ValueError(f'{name} must be (a, b) with 0 <= a <= b')
        if self.noise_tau[0] <= 0:
            raise ValueError('noise_tau must be > 0')


# ---------------------------------------------------------------------------------------------
# the pilot


# the pilot's gain per stick (surge, sway, heave, yaw). With BG = 1 cm the truth is statically
# unstable in pitch above u ~ 0.33 m/s and in roll above v ~ 0.34 m/s (the Munk moments
# (Z_wdot - X_udot) u w and (Y_vdot - Z_wdot) v w outgrow B * BG = 1.3 N m/rad), so a pilot
# keeps surge and sway (and heave, in a shallow tank) near 0.3 m/s; full yaw stick would spin
# the vehicle at over 4 rad/s (von Benzon's yaw damping is quadratic only)
STICK_GAIN = (0.5, 0.5, 0.5, 0.25)


def mix(stick):
    """Motor outputs in [-1, 1] for the sticks (surge, sway, heave, yaw) in [-1, 1], FRD
    (heave > 0 down, yaw > 0 to starboard): each horizontal thruster takes the sign of its own
    surge, sway and yaw effect, scaled down together when a sum exceeds 1 (ArduSub's way)."""
    surge, sway, heave, yaw = stick
    yaw_arm = np.cross(THRUSTER_R, THRUSTER_D)[:, 2]
    out = np.zeros(8)
    out[:4] = (surge * np.sign(THRUSTER_D[:4, 0]) + sway * np.sign(THRUSTER_D[:4, 1])
               + yaw * np.sign(yaw_arm[:4]))
    out[4:] = heave
    peak = np.max(np.abs(out[:4]))
    if peak > 1:
        out[:4] /= peak
    return np.clip(out, -1, 1)


def pwm_of(out):
    """PWM (us), quantised to 1 us: 1500 + 400 * output."""
    return np.round(1500.0 + 400.0 * np.asarray(out, float))


def pilot_block(cfg, rng, t, stick, t_now, depth):
    """Fill the pilot's stick (K, 4) at the ticks t (K,) for one block starting at t_now; the
    time the block ends (s). Blocks: a step of one stick or of two (hold 3-8 s, then centred
    4-8 s: a free decay) or a sweep of one stick (chirp 0.05 -> 0.6 Hz over 20-35 s). The pilot
    looks at the depth (m, NED) before each block: more than depth_band off depth0, the block
    is a heave step back towards depth0 (the vehicle is 0.98 N heavy and a tank is shallow)."""
    kind = ('step', 'step', 'pair', 'chirp')[int(rng.integers(4))]
    off = depth - cfg.depth0
    if kind == 'chirp' and abs(off) <= cfg.depth_band:
        axis = int(rng.integers(4))
        length = rng.uniform(20.0, 35.0)
        amp = rng.uniform(*cfg.stick_levels)
        sel = (t >= t_now) & (t < t_now + length)
        tau = t[sel] - t_now
        f0, f1 = 0.05, 0.6
        phase = 2 * np.pi * (f0 * tau + 0.5 * (f1 - f0) / length * tau ** 2)
        stick[sel, axis] = amp * STICK_GAIN[axis] * np.sin(phase)
        return t_now + length + rng.uniform(2.0, 5.0)
    if abs(off) > cfg.depth_band:
        # a gentle climb or dive (stick 0.2: about 0.2 m/s) held for about the distance
        hold = float(np.clip(abs(off) / 0.2, 1.0, 10.0))
        sel = (t >= t_now) & (t < t_now + hold)
        stick[sel, 2] = -np.sign(off) * 0.2
        return t_now + hold + rng.uniform(4.0, 8.0)
    hold = rng.uniform(3.0, 8.0)
    sel = (t >= t_now) & (t < t_now + hold)
    # pairs only among surge, sway and yaw: with heave, the Munk moments (Z_wdot - X_udot)
    # u w and (Y_vdot - Z_wdot) v w exceed the 1 cm BG's restoring and would roll the
    # vehicle over, which a pilot avoids
    axes = (rng.choice((0, 1, 3), size=2, replace=False) if kind == 'pair'
            else [int(rng.integers(4))])
    for ax in axes:
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        if ax == 2:     # heave: towards depth0 (down when level with it)
            sign = -1.0 if off > 0 else 1.0
        stick[sel, ax] = sign * rng.uniform(*cfg.stick_levels) * STICK_GAIN[ax]
    return t_now + hold + rng.uniform(4.0, 8.0)


def published(t, pwm, repeat_period, keep=None, start=0):
    """Indices of the ticks published: the first, each one whose PWM differs from the last
    published, and a repeat after repeat_period s without a message. ``keep`` (a list, extended
    in place) and ``start`` continue an earlier call from tick ``start`` on."""
    keep = [] if keep is None else keep
    for k in range(start, len(t)):
        if (not keep or np.any(pwm[k] != pwm[keep[-1]])
                or t[k] - t[keep[-1]] >= repeat_period - 1e-9):
            keep.append(k)
    return keep


# ---------------------------------------------------------------------------------------------
# integration, sensing


def integrate(model, y0, switch_t, switch_pwm, gain, t_out, t_end, rtol, final=None,
              curve='table'):
    """solve_ivp RK45 between command switches (the thrust is piecewise constant, or its lag
    target is); the states at t_out (sorted) from each span's dense output. ``final`` (a list)
    receives the state at t_end."""
    out = np.empty((len(t_out), len(y0)))
    y = np.array(y0, float)
    edges = np.concatenate([switch_t, [t_end]])
    k0 = int(np.searchsorted(t_out, edges[0], side='left'))
    out[:k0] = y                    # before the first command: at rest as given
    for i in range(len(switch_t)):
        a, b = edges[i], edges[i + 1]
        if b <= a:
            continue
        model.thrust_cmd = THRUST_CURVES[curve](switch_pwm[i], gain)
        sol = solve_ivp(model, (a, b), y, method='RK45', rtol=rtol, atol=rtol * 1e-3,
                        dense_output=True)
        if not sol.success:
            raise RuntimeError(f'integration failed at t = {a:.3f} s: {sol.message}')
        k1 = int(np.searchsorted(t_out, b, side='left'))
        if k1 > k0:
            out[k0:k1] = sol.sol(t_out[k0:k1]).T
        k0 = k1
        y = sol.y[:, -1]
    if k0 < len(t_out):
        out[k0:] = y
    if final is not None:
        final.append(y)
    return out


def ar1_noise(t, sigma, tau, rng):
    """Stationary first-order coloured noise at irregular t: x_k = a x_{k-1} + sqrt(1-a^2) s e."""
    n = np.zeros((len(t), len(sigma)))
    n[0] = sigma * rng.standard_normal(len(sigma))
    for k in range(1, len(t)):
        a = np.exp(-(t[k] - t[k - 1]) / tau)
        n[k] = a * n[k - 1] + np.sqrt(1 - a * a) * sigma * rng.standard_normal(len(sigma))
    return n


# NED -> ENU (world) and FRD -> FLU (body): both their own inverses
P_WORLD = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
P_BODY = np.diag([1.0, -1.0, -1.0])


def to_frame(y12, frame):
    """Position (3,), quaternion (x y z w), body linear and angular velocity in ``frame``."""
    R = rotation(*y12[9:12])
    pos, lin, ang = y12[6:9], y12[0:3], y12[3:6]
    if frame == 'enu':
        R, pos = P_WORLD @ R @ P_BODY, P_WORLD @ pos
        lin, ang = P_BODY @ lin, P_BODY @ ang
    q = np.array(quat_of(R))
    return pos, (q if q[3] >= 0 else -q), lin, ang   # w >= 0, as drivers publish


def _streams(seed):
    names = ('pilot', 'odom_jitter', 'odom_delay', 'cmd_delay', 'noise_draw', 'noise')
    return {n: np.random.default_rng(s)
            for n, s in zip(names, np.random.SeedSequence(seed).spawn(len(names)))}


# ---------------------------------------------------------------------------------------------
# bag


class _Messages:
    """Float64MultiArray and Odometry from the rosbags Jazzy typestore."""

    ARRAY, ODOM = 'std_msgs/msg/Float64MultiArray', 'nav_msgs/msg/Odometry'

    def __init__(self, frame):
        from rosbags.typesys import get_typestore, Stores
        self.store = get_typestore(Stores.ROS2_JAZZY)
        self.T = self.store.types
        self.frame_ids = FRAMES[frame]
        self.frame = frame

    def thrusters(self, pwm):
        T = self.T
        layout = T['std_msgs/msg/MultiArrayLayout'](
            dim=[T['std_msgs/msg/MultiArrayDimension'](label='thrusters', size=8, stride=8)],
            data_offset=0)
        msg = T[self.ARRAY](layout=layout, data=np.asarray(pwm, dtype=np.float64))
        return self.store.serialize_cdr(msg, self.ARRAY)

    def odometry(self, stamp_ns, y12, pose_cov, twist_cov):
        T = self.T
        pos, q, lin, ang = to_frame(y12, self.frame)
        v3, hdr = T['geometry_msgs/msg/Vector3'], T['std_msgs/msg/Header']
        header = hdr(stamp=T['builtin_interfaces/msg/Time'](sec=int(stamp_ns // NS),
                                                            nanosec=int(stamp_ns % NS)),
                     frame_id=self.frame_ids[0])
        pose = T['geometry_msgs/msg/PoseWithCovariance'](
            pose=T['geometry_msgs/msg/Pose'](
                position=T['geometry_msgs/msg/Point'](x=pos[0], y=pos[1], z=pos[2]),
                orientation=T['geometry_msgs/msg/Quaternion'](x=q[0], y=q[1], z=q[2], w=q[3])),
            covariance=pose_cov)
        twist = T['geometry_msgs/msg/TwistWithCovariance'](
            twist=T['geometry_msgs/msg/Twist'](linear=v3(x=lin[0], y=lin[1], z=lin[2]),
                                               angular=v3(x=ang[0], y=ang[1], z=ang[2])),
            covariance=twist_cov)
        msg = T[self.ODOM](header=header, child_frame_id=self.frame_ids[1], pose=pose,
                           twist=twist)
        return self.store.serialize_cdr(msg, self.ODOM)


def _write_bag(path, records, msgs):
    from rosbags.rosbag2 import StoragePlugin, Writer
    w = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    with w:
        conns = {topic: w.add_connection(topic, kind, typestore=msgs.store,
                                         offered_qos_profiles=[qos()])
                 for topic, kind in ((ODOM_TOPIC, msgs.ODOM), (THRUSTER_TOPIC, msgs.ARRAY))}
        for log_ns, topic, payload in records:
            w.write(conns[topic], int(log_ns), payload)


def _covariances(cfg, sigma):
    """Diagonal 6x6 pose and twist covariances (row-major 36) in the message's frame."""
    if cfg.covariance == 'zero':
        var = np.zeros(12)
    else:
        var = sigma ** 2 * (cfg.covariance_scale if cfg.covariance == 'wrong' else 1.0)
    pose, twist = var[6:12].copy(), var[0:6].copy()
    if cfg.frame == 'enu':
        pose[[0, 1]] = pose[[1, 0]]     # ENU x is north's partner: east
    return np.diag(pose).reshape(36), np.diag(twist).reshape(36)


def generate(cfg, out_dir, overwrite=False, truth=None):
    """Write ``out_dir/bag``, ``out_dir/truth.json`` and ``out_dir/truth_states.npz`` (truth at
    the odometry stamps). Returns the truth.json document."""
    cfg.validate()
    truth = truth or RovTruth()
    out_dir = prepare_out_dir(out_dir, overwrite, ('bag', 'truth.json', 'truth_states.npz'))
    rng = _streams(cfg.seed)
    t0_ns = epoch_ns(cfg.start_time)
    gain = 1.0 + cfg.thrust_perturb

    # odometry stamps
    period = 1.0 / cfg.odom_rate
    nominal = np.arange(0.0, cfg.duration, period)
    jit = rng['odom_jitter'].uniform(-cfg.odom_jitter, cfg.odom_jitter, len(nominal)) * period
    odom_ns = t0_ns + np.round((nominal + jit).clip(0.0) * NS).astype(np.int64)
    t_odom = (odom_ns - t0_ns) / NS

    # the session, block by block: the pilot plans a block from the depth at its start, its
    # commands are published on change and arrive at the recorder (where the truth switches),
    # and the truth is integrated up to the block's end
    model = RovModel(truth, cfg.motor_lag)
    y = np.zeros(20 if cfg.motor_lag > 0 else 12)
    y[8] = cfg.depth0               # at rest, level, heading north
    t_tick = np.arange(0.0, cfg.duration, 1.0 / cfg.pilot_rate)
    stick = np.zeros((len(t_tick), 4))
    pwm = np.full((len(t_tick), 8), 1500.0)
    Y = np.empty((len(t_odom), len(y)))
    pub, arrive = [], []
    t_int, t_now, k_tick, k_odom = 0.0, 3.0, 0, 0   # 3 s at rest first
    pwm_in_force = np.full(8, 1500.0)
    t_last = max(cfg.duration, float(t_odom[-1]) + 1e-6)
    while t_int < t_last:
        t_next = (pilot_block(cfg, rng['pilot'], t_tick, stick, t_now, y[8])
                  if t_now < cfg.duration else t_last)
        k_end = int(np.searchsorted(t_tick, t_next, side='left'))
        pwm[k_tick:k_end] = [pwm_of(mix(sk)) for sk in stick[k_tick:k_end]]
        n_pub = len(pub)
        published(t_tick[:k_end], pwm, cfg.repeat_period, pub, k_tick)
        arrive += [t_tick[k] + rng['cmd_delay'].uniform(*cfg.command_delay) for k in pub[n_pub:]]
        t_end = min(t_next, t_last)
        sw = [(t_int, pwm_in_force)] + [(arrive[i], pwm[pub[i]]) for i in range(len(pub))
                                        if t_int <= arrive[i] < t_end]
        k_out = int(np.searchsorted(t_odom, t_end, side='left'))
        Y[k_odom:k_out] = integrate(model, y, np.array([a for a, _ in sw]),
                                    np.array([p for _, p in sw]), gain, t_odom[k_odom:k_out],
                                    t_end, cfg.rtol, final=(y_end := []),
                                    curve=cfg.curve)
        y, pwm_in_force = y_end[0], sw[-1][1]
        t_int, t_now, k_tick, k_odom = t_end, t_next, k_end, k_out
    pub = np.array(pub)
    cmd_log_ns = t0_ns + np.round(np.array(arrive) * NS).astype(np.int64)
    cmd_pwm = pwm[pub]
    x_true = Y[:, :12]

    # noise: levels and colours drawn per run, disclosed only in truth.json
    nd = rng['noise_draw']
    sigma = np.asarray(BASE_SIGMA) * nd.uniform(*cfg.noise_level, 12)
    tau = nd.uniform(*cfg.noise_tau, 12)
    if cfg.noise == 'none':
        sigma = np.zeros(12)
    noise = ar1_noise(t_odom, sigma, tau, rng['noise'])
    y = x_true + noise
    y[:, 9:12] = (y[:, 9:12] + np.pi) % (2 * np.pi) - np.pi
    pose_cov, twist_cov = _covariances(cfg, sigma)

    msgs = _Messages(cfg.frame)
    odom_log = odom_ns + np.round(rng['odom_delay'].uniform(*cfg.odom_delay, len(odom_ns))
                                  * NS).astype(np.int64)
    order = sorted([(int(odom_log[k]), 0, k) for k in range(len(odom_ns))]
                   + [(int(cmd_log_ns[k]), 1, k) for k in range(len(cmd_log_ns))])

    def records():
        for log_ns, kind, k in order:
            if kind == 0:
                yield log_ns, ODOM_TOPIC, msgs.odometry(int(odom_ns[k]), y[k], pose_cov,
                                                        twist_cov)
            else:
                yield log_ns, THRUSTER_TOPIC, msgs.thrusters(cmd_pwm[k])

    _write_bag(out_dir / 'bag', records(), msgs)
    np.savez_compressed(out_dir / 'truth_states.npz', t=t_odom, stamp_ns=odom_ns,
                        x_true=Y, y=y, noise=noise, cmd_log_ns=cmd_log_ns, cmd_pwm=cmd_pwm,
                        tick_t=t_tick, tick_pwm=pwm)
    doc = {
        'generator': GENERATOR,
        'bag': str(out_dir / 'bag'),
        'vehicle': 'bluerov2_heavy',
        'source': 'von Benzon et al. 2022, J. Mar. Sci. Eng. 10(12):1898, Table 3',
        'coefficients': truth.coefficients(gain, cfg.motor_lag),
        'truth_model': jsonable(dataclasses.asdict(truth)),
        'W': truth.W, 'B': truth.B,
        'thrusters': {'names': list(THRUSTER_NAMES), 'r_frd': THRUSTER_R.tolist(),
                      'd_frd': THRUSTER_D.tolist(),
                      'curve': ('T200 16 V table, linear interpolation, times thrust_gain'
                                if cfg.curve == 'table' else
                                "the vehicle file's curve (FILE_CURVE: the table, PCHIP), "
                                'times thrust_gain'),
                      'dead_band_us': list(DEAD_BAND)},
        'perturbed': {'thrust_gain_fwd': gain, 'thrust_gain_rev': gain,
                      'note': ('truth thrust = gain * the published table (the vehicle file '
                               'uses the table as 1.0)' if cfg.curve == 'table' else
                               "truth thrust = gain * the vehicle file's curve")},
        'frame': cfg.frame, 'frame_ids': list(FRAMES[cfg.frame]),
        'noise': {'kind': cfg.noise, 'sigma': dict(zip(CHANNELS, sigma.tolist())),
                  'tau_s': dict(zip(CHANNELS, tau.tolist())),
                  'channels_frame': 'NED/FRD state before conversion',
                  'covariance_fields': cfg.covariance},
        'start_ns': t0_ns,
        'counts': {'odom': int(len(odom_ns)), 'ticks': int(len(t_tick)),
                   'commands': int(len(pub))},
        'manoeuvres': 'pilot blocks: steps of surge, sway, heave, yaw; pairs of surge, sway, '
                      'yaw; chirps 0.05-0.6 Hz; heave steps back to depth0 beyond depth_band',
        'config': jsonable(dataclasses.asdict(cfg)),
        'integrator': f'scipy solve_ivp RK45 between command switches, rtol {cfg.rtol}',
    }
    (out_dir / 'truth.json').write_text(json.dumps(doc, indent=1) + '\n', encoding='utf-8')
    return doc


def main(argv=None):
    p = argparse.ArgumentParser(description='Write an independent BlueROV2 Heavy tank session '
                                            '(OUT/bag, OUT/truth.json).')
    p.add_argument('--out', required=True, help='output directory')
    p.add_argument('--overwrite', action='store_true')
    for f in dataclasses.fields(RovConfig):
        opt = '--' + f.name.replace('_', '-')
        if isinstance(f.default, tuple):
            p.add_argument(opt, type=lambda s: tuple(float(v) for v in s.split(',')),
                           default=f.default, help=f'a,b (default {f.default})')
        else:
            p.add_argument(opt, type=type(f.default), default=f.default,
                           help=f'default {f.default}')
    args = p.parse_args(argv)
    cfg = RovConfig(**{f.name: getattr(args, f.name) for f in dataclasses.fields(RovConfig)})
    try:
        doc = generate(cfg, args.out, overwrite=args.overwrite)
    except (ValueError, FileExistsError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 2
    c = doc['counts']
    print(f"wrote {doc['bag']}: {c['odom']} odometry, {c['commands']} thruster commands "
          f"({c['ticks']} pilot ticks); truth in {Path(args.out) / 'truth.json'}")
    return 0


if __name__ == '__main__':
    sys.exit(main())
