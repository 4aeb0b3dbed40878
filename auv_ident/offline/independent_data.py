"""Independent validation data: rosbag2 MCAP bags that look like a real AUV's logs, made by code
that shares nothing with the identifier except the vehicle model's derivative. A part of the
package, not of the tests: the campaigns of tools/ measure the identifier on these bags, and
``compare --truth`` reads the truth.json written beside them.

Why: the identifier is accurate on bags from its own simulator, which samples on a uniform grid,
publishes every command, adds white noise of the level the filter assumes and uses the very
coefficients the filter starts from. Real logs differ in all of these (see
/work/shared/real_data.md). This module makes bags with each difference switched on or off, so
that a test (or a person, with the command line) can measure what each one costs.

What is the package's and what is not
-------------------------------------
From ``auv_ident`` only :class:`auv_ident.core.model.hydrodynamics.Model` (its ``f(x, u)`` for
nu_dot; the kinematics returned with it are ignored), the vehicle loaders and ``trim_speed`` are
used. The manoeuvre, the servo rate limiter, the integrator (scipy DOP853 between command changes,
or fixed-step RK4), the kinematics, the current, the sampling and stamping, the noise, the ROS
messages (rosbags' typestore, Jazzy) and the bag writer (rosbags) are all here.

Conventions (the package's documented message contract)
-------------------------------------------------------
State ``x = [u v w p q r x y z phi theta psi]``: body FRD velocities, NED position, ZYX Euler
angles (body -> world ``R = Rz(psi) Ry(theta) Rx(phi)``). Inputs
``[delta_r delta_s delta_b delta_bp delta_bs n_rpm]`` (rad, rpm).

- ``/odom`` nav_msgs/msg/Odometry: frame ids 'odom_ned' / 'base_link_frd'; pose = NED position
  and the quaternion (x y z w) of R; twist = body u v w (over ground, or through the water with
  ``dvl='water'``) and p q r; covariances 6x6 row-major, zero or the true noise variances.
- ``/actuators`` sensor_msgs/msg/JointState: names JOINT_NAMES, position = 5 fin angles + 0.0,
  velocity = [0]*5 + [shaft speed rad/s], effort = 6 zeros.

Time: ``header.stamp`` is the sample (or command) time on the vehicle's clock, starting at a
real date; the bag's log time is the stamp plus a random transport delay, and messages are
written in log-time order, so a command can arrive after an odometry stamped later.

Truth: the fins the model sees are the zero-order hold of the PUBLISHED command sequence,
switching at the command stamps, so the bag's commands are exactly the truth input. The truth
coefficients, the configuration, the current and the noise levels go to ``truth.json`` next to
the bag directory (never inside it: the identifier must not see them).

Water current (Fossen 2021, ch. 10, irrotational and constant in NED): the model's dynamics act
on the relative velocity ``nu_r = nu - [R^T v_c; 0]``; integrated here are ``nu_r`` (with
``nu_r_dot = Model.f([nu_r, eta], u)[:6]``, exact for a constant irrotational current since the
rigid-body terms satisfy M_RB nu_dot + C_RB(nu) nu = M_RB nu_r_dot + C_RB(nu_r) nu_r) and
``eta_dot = J(eta) (nu_r + [R^T v_c; 0])`` with this module's own J.

Usage::

    from auv_ident.offline.independent_data import DataConfig, generate
    data = generate(DataConfig(duration=60, odom_rate=10, odom_jitter=0.1), 'out/run1')
    # out/run1/bag (the rosbag2 directory), out/run1/truth.json [, truth_vehicle.yaml]

    python -m auv_ident.offline.independent_data --out out/run1 --duration 600 --odom-rate 10 \
        --odom-jitter 0.1 --dropout 0.05 --commands on_change --noise ar1 --noise-tau 1 \
        --noise-level 2 --current-ned=-0.0707,-0.0707,0 --perturb 0.2 \
        --perturb-keep Z_ds,Z_q,Z_w,M_ds,K_v
"""
import argparse
import dataclasses
from dataclasses import dataclass, field
import json
import math
from pathlib import Path
import sys

import numpy as np
from scipy.integrate import solve_ivp
import yaml

from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.trim import trim_speed
from auv_ident.core.model.vehicle import vehicle_from_file
from auv_ident.offline.generator_common import (
    epoch_ns,
    jsonable,
    prepare_out_dir,
    qos,
    quat_of,
)
from auv_ident.session.messages import JOINT_NAMES
from auv_ident.vehicles import load_vehicle, resolve_vehicle_path

GENERATOR = 'auv_ident.offline.independent_data v1'
NS = 1_000_000_000
RPM_TO_RAD_S = 2.0 * math.pi / 60.0

# The package's documented sensor 1-sigma (README "Sensor noise"), written out again here so that
# a change in the package cannot silently change these data.
DOCUMENTED_SIGMA = (0.01, 0.01, 0.01, 0.001, 0.001, 0.001, 0.5, 0.5, 0.05, 0.002, 0.002, 0.005)
CHANNELS = ('u', 'v', 'w', 'p', 'q', 'r', 'x', 'y', 'z', 'phi', 'theta', 'psi')
ODOM_FRAME, BODY_FRAME = 'odom_ned', 'base_link_frd'
ODOM_TOPIC, ACTUATOR_TOPIC = '/odom', '/actuators'


@dataclass
class DataConfig:
    """Everything that defines one generated bag (all times in s, angles in deg unless noted).

    Random choices come from independent streams of ``seed`` (manoeuvre, odometry stamps,
    dropouts, delays, command stamps, noise, vehicle perturbation), so switching one feature
    on or off leaves the others' draws unchanged: bags differing in one option share the rest.
    """

    # --- vehicle and run
    vehicle: str = 'nps_auv2'          # name (config/) or path of a vehicle YAML
    duration: float = 600.0
    seed: int = 0
    rpm: float = 500.0                 # constant shaft speed
    depth0: float = 10.0               # m, initial depth (z, NED)
    u0: object = None                  # m/s, initial surge through the water (None: trim)
    heading0_deg: float = 0.0          # initial heading psi
    start_time: str = '2025-06-03T09:00:00Z'   # stamp of t = 0 (UTC)

    # --- manoeuvre (open loop): rudder legs, plane steps, servo rate limit
    lead_in: float = 2.0               # straight run before the first fin moves
    rudder_deg: float = 20.0           # rudder legs alternate +-rudder_deg (clipped to the limit)
    rudder_hold: tuple = (20.0, 40.0)  # each leg lasts U(a, b)
    plane_levels_deg: tuple = (10.0, 15.0, 20.0)   # plane steps: +-one of these, at random
    plane_hold: tuple = (5.0, 6.0)     # each plane step lasts U(a, b)
    bow_planes: bool = True            # step delta_b as well as delta_s (independently)
    fin_rate_deg: float = 10.0         # servo rate limit, deg/s
    fin_quantum_deg: float = 0.0       # command quantisation (0: none)

    # --- integration (the truth)
    integrator: str = 'dop853'         # 'dop853' (solve_ivp between command changes) or 'rk4'
    rtol: float = 1e-9                 # DOP853 relative tolerance (atol = rtol * 1e-2)
    rk4_dt: float = 0.002              # RK4 maximum step

    # --- odometry sampling
    odom_rate: float = 10.0            # Hz, nominal
    odom_jitter: float = 0.0           # stamp jitter, +- this fraction of the period (uniform)
    dropout: float = 0.0               # fraction of samples missing (independent)
    gaps: tuple = ()                   # ((start, length), ...): no odometry in these windows
    odom_delay: tuple = (0.002, 0.020)  # log time - stamp ~ U(a, b)

    # --- actuator commands
    commands: str = 'on_change'        # 'on_change' or 'periodic'
    command_rate: float = 20.0         # Hz: the driver's clock (on_change: while a fin moves)
    command_phase: float = 0.0         # offset of the command clock from t = 0 (< 1/rate)
    command_jitter: float = 0.0        # +- fraction of the command period (uniform)
    command_delay: tuple = (0.001, 0.010)  # log time - stamp ~ U(a, b)

    # --- sensor noise
    noise: str = 'white'               # 'white', 'ar1' (first-order coloured) or 'none'
    noise_level: float = 1.0           # factor on the documented sigmas
    noise_tau: object = 1.0            # AR(1) correlation time: a number or 12 numbers
    noise_std: object = None           # 12 1-sigma values replacing the documented ones
    covariance: str = 'zero'           # odometry covariance fields: 'zero' or 'true'
    covariance_scale: float = 1.0      # 'true' variances times this (optimistic < 1)

    # --- truth vehicle
    perturb: float = 0.0               # coefficients scaled by U(1 - perturb, 1 + perturb)...
    perturb_keep: tuple = ()           # ...except these (e.g. the ones to identify)
    perturb_added_mass: bool = True    # scale added-mass terms too (pairs by one factor)

    # --- water current
    current_ned: tuple = (0.0, 0.0, 0.0)   # m/s, constant, NED (where the water goes)
    dvl: str = 'ground'                # twist.linear: 'ground' (nu) or 'water' (nu_r)

    # --- bag
    compress: bool = False             # zstd chunks in the MCAP file
    write_states: bool = False         # also write truth_states.npz (truth at the stamps)

    def validate(self):
        """ValueError naming the first bad field."""
        if self.duration <= 0:
            raise ValueError('duration must be > 0')
        if not 0 < self.odom_rate <= 1000:
            raise ValueError('odom_rate must be in (0, 1000] Hz')
        if not 0 <= self.odom_jitter < 0.5:
            raise ValueError('odom_jitter must be in [0, 0.5) (stamps stay ordered)')
        if not 0 <= self.command_jitter < 0.5:
            raise ValueError('command_jitter must be in [0, 0.5)')
        if not 0 <= self.dropout < 1:
            raise ValueError('dropout must be in [0, 1)')
        _one_of('commands', self.commands, ('on_change', 'periodic'))
        if not 0 <= self.command_phase < 1.0 / self.command_rate:
            raise ValueError('command_phase must be in [0, 1/command_rate)')
        for name, options in (('noise', ('white', 'ar1', 'none')),
                              ('covariance', ('zero', 'true')), ('dvl', ('ground', 'water')),
                              ('integrator', ('dop853', 'rk4'))):
            _one_of(name, getattr(self, name), options)
        if not 0 <= self.perturb < 1:
            raise ValueError('perturb must be in [0, 1)')
        if len(self.current_ned) != 3:
            raise ValueError('current_ned needs 3 components (N, E, D)')
        for a, b in (self.odom_delay, self.command_delay, self.rudder_hold, self.plane_hold):
            if not 0 <= a <= b:
                raise ValueError(f'bad interval ({a}, {b})')
        for g in self.gaps:
            if len(g) != 2 or g[1] < 0:
                raise ValueError(f'gap {g!r} must be (start, length >= 0)')

    def sigma(self):
        """The 12 noise 1-sigma values actually applied (0 for noise='none')."""
        base = np.array(DOCUMENTED_SIGMA if self.noise_std is None else self.noise_std, float)
        if base.shape != (12,):
            raise ValueError('noise_std needs 12 values (u v w p q r x y z phi theta psi)')
        return np.zeros(12) if self.noise == 'none' else base * float(self.noise_level)

    def tau(self):
        t = np.broadcast_to(np.asarray(self.noise_tau, dtype=float), (12,)).copy()
        if np.any(t <= 0):
            raise ValueError('noise_tau must be > 0')
        return t


def _one_of(name, value, options):
    """ValueError unless value is one of options: "name must be 'a', 'b' or 'c'"."""
    if value not in options:
        raise ValueError(f'{name} must be ' + ', '.join(map(repr, options[:-1]))
                         + f' or {options[-1]!r}')


@dataclass
class GeneratedData:
    """What :func:`generate` made. Times ``t*`` are s from the start (``t0_ns``)."""

    bag: Path                 # the rosbag2 directory
    truth_json: Path
    truth_vehicle: str        # path of the vehicle file the truth used
    t0_ns: int
    odom_stamp_ns: np.ndarray     # (N,) stamps of the odometry written
    odom_log_ns: np.ndarray       # (N,) their log times
    t_odom: np.ndarray            # (N,) the same stamps in s (what the truth was sampled at)
    x_true: np.ndarray            # (N, 12) truth: nu over ground, eta
    nu_r: np.ndarray              # (N, 6) truth velocity relative to the water
    y: np.ndarray                 # (N, 12) measured (twist linear per dvl option, noisy)
    noise: np.ndarray             # (N, 12) the noise added
    u_true: np.ndarray            # (N, 7) input in force at each odometry stamp
    cmd_stamp_ns: np.ndarray      # (M,) stamps of the commands written
    cmd_log_ns: np.ndarray        # (M,)
    cmd_values: np.ndarray        # (M, 7) rad, rad, rad, rad, rad, rpm, N
    tick_t: np.ndarray            # (K,) every tick of the command clock (s)
    tick_values: np.ndarray       # (K, 7) the driver's command at each tick
    nominal_odom: int             # samples on the nominal grid (before dropouts and gaps)
    coefficients: dict            # truth coefficient values (all), by name
    factors: dict                 # truth / file value per coefficient (1.0 if kept)
    truth: dict = field(default_factory=dict)   # the truth.json document


# ---------------------------------------------------------------------------------------------
# kinematics (own; ZYX Euler, body FRD -> world NED)


def rotation(phi, theta, psi):
    """R = Rz(psi) Ry(theta) Rx(phi): body FRD -> world NED."""
    cf, sf = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    return np.array([[cp * ct, -sp * cf + cp * st * sf, sp * sf + cp * cf * st],
                     [sp * ct, cp * cf + sf * st * sp, -cp * sf + st * sp * cf],
                     [-st, ct * sf, ct * cf]])


def euler_rate(phi, theta, p, q, r):
    """(phi_dot, theta_dot, psi_dot) = T(phi, theta) [p q r]."""
    cf, sf = math.cos(phi), math.sin(phi)
    ct, tt = math.cos(theta), math.tan(theta)
    return (p + sf * tt * q + cf * tt * r, cf * q - sf * r, (sf * q + cf * r) / ct)


def quaternion(phi, theta, psi):
    """Quaternion (x, y, z, w) of Rz(psi) Ry(theta) Rx(phi) (product of axis rotations)."""
    # q = qz(psi) * qy(theta) * qx(phi), Hamilton product written out
    cx, sx = math.cos(phi / 2), math.sin(phi / 2)
    cy, sy = math.cos(theta / 2), math.sin(theta / 2)
    cz, sz = math.cos(psi / 2), math.sin(psi / 2)
    w = cz * cy * cx + sz * sy * sx
    x = cz * cy * sx - sz * sy * cx
    y = cz * sy * cx + sz * cy * sx
    z = sz * cy * cx - cz * sy * sx
    return x, y, z, w


def wrap(a):
    """Wrap angles to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


class Dynamics:
    """The right-hand side in y = [nu_r (6), eta (6)] with a constant NED current."""

    def __init__(self, model, current_ned):
        self.model = model
        self.vc = np.asarray(current_ned, dtype=float)
        self.x = np.empty(12)
        self.u = np.zeros(7)

    def nu_over_ground(self, y):
        nu = np.array(y[:6], dtype=float)
        if self.vc.any():
            nu[:3] += rotation(*y[9:12]).T @ self.vc
        return nu

    def __call__(self, t, y):
        self.x[:] = y
        xd = self.model.f(self.x, self.u)          # only nu_dot (the first 6) is used
        nu = self.nu_over_ground(y)
        R = rotation(y[9], y[10], y[11])
        out = np.empty(12)
        out[:6] = xd[:6]
        out[6:9] = R @ nu[:3]
        out[9:12] = euler_rate(y[9], y[10], nu[3], nu[4], nu[5])
        return out


def integrate(dyn, y0, switch_t, switch_u, t_out, t_end, cfg):
    """Integrate from t = 0 with input switch_u[i] held on [switch_t[i], switch_t[i+1]);
    return y at the times t_out (sorted, within [0, t_end]), shape (len(t_out), 12)."""
    switch_t = np.asarray(switch_t, float)
    t_out = np.asarray(t_out, float)
    out = np.empty((len(t_out), 12))
    bounds = np.append(switch_t, max(t_end, t_out[-1] if len(t_out) else t_end))
    y = np.array(y0, dtype=float)
    j = 0
    for i in range(len(switch_t)):
        a, b = bounds[i], bounds[i + 1]
        dyn.u[:] = switch_u[i]
        k = j
        while k < len(t_out) and t_out[k] < b:
            k += 1
        if b <= a:
            out[j:k] = y
            j = k
            continue
        if cfg.integrator == 'dop853':
            sol = solve_ivp(dyn, (a, b), y, method='DOP853', rtol=cfg.rtol,
                            atol=cfg.rtol * 1e-2, t_eval=np.append(t_out[j:k], b))
            if not sol.success:
                raise RuntimeError(f'integration failed on [{a}, {b}]: {sol.message}')
            out[j:k] = sol.y[:, :-1].T
            y = sol.y[:, -1].copy()
        else:
            y = _rk4_span(dyn, y, a, b, t_out[j:k], out[j:k], cfg.rk4_dt)
        j = k
    if j < len(t_out):  # stamps exactly at t_end
        out[j:] = y
    return out


def _rk4_span(dyn, y, a, b, t_out, out, h_max):
    """Classic RK4 over [a, b] in equal steps <= h_max between the output times; fills out."""
    marks = list(t_out) + [b]
    t = a
    for m_i, m in enumerate(marks):
        span = m - t
        if span > 0:
            n = max(1, math.ceil(span / h_max - 1e-9))
            h = span / n
            for _ in range(n):
                k1 = dyn(t, y)
                k2 = dyn(t + h / 2, y + h / 2 * k1)
                k3 = dyn(t + h / 2, y + h / 2 * k2)
                k4 = dyn(t + h, y + h * k3)
                y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
                t += h
            t = m
        if m_i < len(t_out):
            out[m_i] = y
    return y


# ---------------------------------------------------------------------------------------------
# manoeuvre and commands


def _targets(cfg, rng, fin_limit, t_end):
    """Piecewise-constant fin targets (rad): list per fin channel of (start times, values)."""
    lim_deg = math.degrees(fin_limit)
    rud = math.radians(min(cfg.rudder_deg, lim_deg))
    out = []
    # rudder legs alternating in sign, first sign random
    t, sign = cfg.lead_in, rng.choice([-1.0, 1.0])
    times, vals = [0.0], [0.0]
    while t < t_end:
        times.append(t)
        vals.append(sign * rud)
        t += rng.uniform(*cfg.rudder_hold)
        sign = -sign
    out.append((np.array(times), np.array(vals)))
    levels = np.radians([min(a, lim_deg) for a in cfg.plane_levels_deg])
    for ch in (1, 2):
        times, vals = [0.0], [0.0]
        if ch == 1 or cfg.bow_planes:
            t = cfg.lead_in
            while t < t_end:
                times.append(t)
                vals.append(rng.choice([-1.0, 1.0]) * rng.choice(levels))
                t += rng.uniform(*cfg.plane_hold)
        out.append((np.array(times), np.array(vals)))
    return out


def command_ticks(cfg, rng):
    """Tick times (s) of the driver's command clock: 0, then phase + j / rate (+ jitter)."""
    period = 1.0 / cfg.command_rate
    j = np.arange(1, int(math.floor((cfg.duration - cfg.command_phase) / period)) + 1)
    t = cfg.command_phase + j * period
    if cfg.command_jitter:
        t = t + rng.uniform(-1, 1, len(t)) * cfg.command_jitter * period
    t = t[(t > 0) & (t <= cfg.duration)]
    return np.concatenate([[0.0], t])


def command_values(cfg, targets, ticks, rpm):
    """The driver's command at each tick: fins rate-limited towards the targets (and
    quantised), shaft constant, thrust 0. Returns (K, 7)."""
    vals = np.zeros((len(ticks), 7))
    vals[:, 5] = rpm
    rate = math.radians(cfg.fin_rate_deg)
    q = math.radians(cfg.fin_quantum_deg)
    for ch, (tt, tv) in enumerate(targets):
        idx = np.searchsorted(tt, ticks, side='right') - 1
        target = tv[idx]
        pos = 0.0
        prev_t = 0.0
        for k, t in enumerate(ticks):
            step = rate * (t - prev_t)
            gap = target[k] - pos
            # (1 + 1e-9): a tick period that rounds a hair short must not leave a 1e-17 rest
            pos = target[k] if abs(gap) <= step * (1 + 1e-9) else pos + math.copysign(step, gap)
            prev_t = t
            vals[k, ch] = pos
    if q > 0:
        vals[:, :5] = np.round(vals[:, :5] / q) * q
    return vals


def published_commands(cfg, ticks, vals):
    """Indices of the ticks whose command is published."""
    if cfg.commands == 'periodic':
        return np.arange(len(ticks))
    changed = np.any(np.diff(vals, axis=0) != 0.0, axis=1)
    return np.concatenate([[0], 1 + np.flatnonzero(changed)])


# ---------------------------------------------------------------------------------------------
# sampling and noise


def odom_stamps(cfg, rng_jitter, rng_drop):
    """Nominal grid k / rate, jittered; minus dropouts and gaps. Returns (t kept, nominal n)."""
    period = 1.0 / cfg.odom_rate
    n = int(math.floor(cfg.duration * cfg.odom_rate + 1e-9)) + 1
    nominal = np.arange(n) * period
    jit = rng_jitter.uniform(-1, 1, n) * cfg.odom_jitter * period
    t = np.clip(nominal + jit, 0.0, cfg.duration)
    keep = rng_drop.random(n) >= cfg.dropout
    for start, length in cfg.gaps:
        keep &= ~((nominal >= start) & (nominal < start + length))
    return t[keep], n


def colored_noise(t, sigma, tau, rng, kind):
    """Noise at times t (s): white N(0, sigma^2), or a stationary Ornstein-Uhlenbeck process
    sampled exactly at t (AR(1) with a_k = exp(-dt_k / tau), variance sigma^2)."""
    n = len(t)
    w = rng.standard_normal((n, 12))
    if kind == 'white' or n == 0:
        return w * sigma
    e = np.empty((n, 12))
    e[0] = w[0]
    dt = np.diff(t)
    for k in range(1, n):
        a = np.exp(-dt[k - 1] / tau)
        e[k] = a * e[k - 1] + np.sqrt(1.0 - a * a) * w[k]
    return e * sigma


# ---------------------------------------------------------------------------------------------
# truth vehicle


def perturbed_vehicle(cfg, rng, out_dir):
    """Write the truth vehicle (a perturbed copy of the file) to out_dir/truth_vehicle.yaml.

    Every coefficient not in ``perturb_keep`` is scaled by U(1 - perturb, 1 + perturb), drawn
    in file order for all coefficients (so the keep list does not change the others' factors).
    Added-mass pairs M[i, j] / M[j, i] share one factor (M stays symmetric); if an added-mass
    coefficient changes and the file uses MSS's literal inverse, the copy uses the exact one
    (otherwise the change would have no effect). Returns (path, factors, notes)."""
    src = resolve_vehicle_path(cfg.vehicle)
    with open(src, encoding='utf-8') as fh:
        raw = yaml.safe_load(fh)
    coefs = raw['coefficients']
    names = list(coefs)
    draws = dict(zip(names, rng.uniform(1 - cfg.perturb, 1 + cfg.perturb, len(names))))
    eq_index = {e: i for i, e in enumerate('XYZKMN')}
    col_index = {f'{a}dot': i for i, a in enumerate('uvwpqr')}
    pair_factor = {}
    keep = set(cfg.perturb_keep)
    unknown = keep - set(names)
    if unknown:
        raise ValueError(f'perturb_keep names unknown coefficients {sorted(unknown)}')
    factors, am_changed = {}, False
    for name in names:
        value, eq, k, mult = coefs[name]
        is_am = isinstance(mult, str) and mult.strip() in col_index
        if name in keep or (is_am and not cfg.perturb_added_mass):
            factors[name] = 1.0
            continue
        if is_am:
            key = frozenset((eq_index[eq], col_index[mult.strip()]))
            f = pair_factor.setdefault(key, draws[name])
            am_changed = am_changed or float(value) != 0.0
        else:
            f = draws[name]
        factors[name] = float(f)
        coefs[name] = [float(value) * float(f), eq, k, mult]
    notes = []
    if am_changed and raw.get('mass_inverse') == 'mss_literal':
        raw['mass_inverse'] = 'exact'
        notes.append('added-mass terms perturbed: mass_inverse mss_literal -> exact')
    raw['name'] = f"{raw.get('name', 'vehicle')}_truth"
    raw['title'] = f"{raw.get('title', '')} (perturbed truth, seed {cfg.seed}, " \
                   f"+-{cfg.perturb:g})"
    path = Path(out_dir) / 'truth_vehicle.yaml'
    with open(path, 'w', encoding='utf-8') as fh:
        fh.write(f'# truth vehicle made by {GENERATOR} from {src}\n')
        yaml.safe_dump(raw, fh, sort_keys=False)
    return str(path), factors, notes


# ---------------------------------------------------------------------------------------------
# messages and bag


class MessageBuilder:
    """nav_msgs/Odometry and sensor_msgs/JointState from the rosbags Jazzy typestore."""

    ODOM = 'nav_msgs/msg/Odometry'
    JOINTS = 'sensor_msgs/msg/JointState'

    def __init__(self):
        from rosbags.typesys import get_typestore, Stores
        self.store = get_typestore(Stores.ROS2_JAZZY)
        T = self.store.types
        self.Time = T['builtin_interfaces/msg/Time']
        self.Header = T['std_msgs/msg/Header']
        self.Odometry = T[self.ODOM]
        self.PoseWithCovariance = T['geometry_msgs/msg/PoseWithCovariance']
        self.Pose = T['geometry_msgs/msg/Pose']
        self.Point = T['geometry_msgs/msg/Point']
        self.Quaternion = T['geometry_msgs/msg/Quaternion']
        self.TwistWithCovariance = T['geometry_msgs/msg/TwistWithCovariance']
        self.Twist = T['geometry_msgs/msg/Twist']
        self.Vector3 = T['geometry_msgs/msg/Vector3']
        self.JointState = T[self.JOINTS]

    def header(self, stamp_ns, frame_id):
        return self.Header(stamp=self.Time(sec=int(stamp_ns // NS), nanosec=int(stamp_ns % NS)),
                           frame_id=frame_id)

    def odometry(self, stamp_ns, y12, pose_cov, twist_cov):
        """y12 = [u v w p q r x y z phi theta psi] as measured (NED/FRD)."""
        qx, qy, qz, qw = quaternion(y12[9], y12[10], y12[11])
        pose = self.PoseWithCovariance(
            pose=self.Pose(position=self.Point(x=float(y12[6]), y=float(y12[7]),
                                               z=float(y12[8])),
                           orientation=self.Quaternion(x=qx, y=qy, z=qz, w=qw)),
            covariance=np.asarray(pose_cov, dtype=np.float64).reshape(36))
        twist = self.TwistWithCovariance(
            twist=self.Twist(linear=self.Vector3(x=float(y12[0]), y=float(y12[1]),
                                                 z=float(y12[2])),
                             angular=self.Vector3(x=float(y12[3]), y=float(y12[4]),
                                                  z=float(y12[5]))),
            covariance=np.asarray(twist_cov, dtype=np.float64).reshape(36))
        msg = self.Odometry(header=self.header(stamp_ns, ODOM_FRAME), child_frame_id=BODY_FRAME,
                            pose=pose, twist=twist)
        return self.store.serialize_cdr(msg, self.ODOM)

    def joints(self, stamp_ns, u6):
        position = np.zeros(6)
        position[:5] = u6[:5]
        velocity = np.zeros(6)
        velocity[5] = u6[5] * RPM_TO_RAD_S
        msg = self.JointState(header=self.header(stamp_ns, ''), name=list(JOINT_NAMES),
                              position=position, velocity=velocity, effort=np.zeros(6))
        return self.store.serialize_cdr(msg, self.JOINTS)


def write_bag(path, records, builder, compress=False):
    """records: iterable of (log_ns, topic, payload) in log-time order."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    w = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    if compress:
        from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
        w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    profiles = [qos()]
    with w:
        conns = {
            ODOM_TOPIC: w.add_connection(ODOM_TOPIC, builder.ODOM, typestore=builder.store,
                                         offered_qos_profiles=profiles),
            ACTUATOR_TOPIC: w.add_connection(ACTUATOR_TOPIC, builder.JOINTS,
                                             typestore=builder.store,
                                             offered_qos_profiles=profiles),
        }
        for log_ns, topic, payload in records:
            w.write(conns[topic], int(log_ns), payload)


# ---------------------------------------------------------------------------------------------
# the generator


def _streams(seed):
    names = ('maneuver', 'odom_jitter', 'dropout', 'odom_delay', 'cmd_jitter', 'cmd_delay',
             'noise', 'perturb')
    seqs = np.random.SeedSequence(seed).spawn(len(names))
    return {n: np.random.default_rng(s) for n, s in zip(names, seqs)}


def generate(cfg, out_dir, overwrite=False):
    """Make one bag: ``out_dir/bag`` (rosbag2 MCAP directory), ``out_dir/truth.json`` and, for a
    perturbed truth, ``out_dir/truth_vehicle.yaml``. Returns a :class:`GeneratedData`."""
    cfg.validate()
    out_dir = prepare_out_dir(out_dir, overwrite,
                              ('bag', 'truth.json', 'truth_vehicle.yaml', 'truth_states.npz'))
    bag = out_dir / 'bag'
    rng = _streams(cfg.seed)

    # truth vehicle
    file_vehicle = load_vehicle(cfg.vehicle)
    notes = []
    if cfg.perturb > 0:
        vpath, factors, notes = perturbed_vehicle(cfg, rng['perturb'], out_dir)
        vehicle = vehicle_from_file(vpath)
    else:
        vpath, vehicle = file_vehicle.path, file_vehicle
        factors = dict.fromkeys(vehicle.names, 1.0)
    model = Model(vehicle)
    fin_limit = float(vehicle.raw['limits']['fin_rad'])

    # commands: the driver's clock, the rate-limited servo commands, the published subset
    targets = _targets(cfg, rng['maneuver'], fin_limit, cfg.duration)
    ticks = command_ticks(cfg, rng['cmd_jitter'])
    t0_ns = epoch_ns(cfg.start_time)
    tick_ns = t0_ns + np.round(ticks * NS).astype(np.int64)
    ticks = (tick_ns - t0_ns) / NS           # the truth switches at the stamps as written
    tick_vals = command_values(cfg, targets, ticks, cfg.rpm)
    pub = published_commands(cfg, ticks, tick_vals)
    cmd_ns, cmd_vals = tick_ns[pub], tick_vals[pub]
    cmd_t = ticks[pub]

    # odometry stamps
    t_odom, nominal = odom_stamps(cfg, rng['odom_jitter'], rng['dropout'])
    odom_ns = t0_ns + np.round(t_odom * NS).astype(np.int64)
    t_odom = (odom_ns - t0_ns) / NS

    # truth: start in the steady straight run through the water
    u_trim = trim_speed(model, cfg.rpm)
    y0 = np.zeros(12)
    y0[0] = u_trim if cfg.u0 is None else float(cfg.u0)
    y0[8] = cfg.depth0
    y0[11] = math.radians(cfg.heading0_deg)
    dyn = Dynamics(model, cfg.current_ned)
    Yt = integrate(dyn, y0, cmd_t, cmd_vals, t_odom, cfg.duration, cfg)
    nu_r = Yt[:, :6].copy()
    x_true = Yt.copy()
    for k in range(len(x_true)):
        x_true[k, :6] = dyn.nu_over_ground(Yt[k])
    u_true = cmd_vals[np.searchsorted(cmd_t, t_odom, side='right') - 1]

    # measurements
    sigma, tau = cfg.sigma(), cfg.tau()
    noise = colored_noise(t_odom, sigma, tau, rng['noise'], cfg.noise)
    meas = x_true.copy()
    if cfg.dvl == 'water':
        meas[:, :3] = nu_r[:, :3]
    y = meas + noise
    y[:, 9:12] = wrap(y[:, 9:12])
    if cfg.covariance == 'true':
        var = sigma ** 2 * cfg.covariance_scale
        pose_cov = np.diag(var[6:12])
        twist_cov = np.diag(var[0:6])
    else:
        pose_cov = twist_cov = np.zeros((6, 6))

    # messages, in log-time order (ties: odometry first, then by stamp)
    builder = MessageBuilder()
    odom_log = odom_ns + np.round(rng['odom_delay'].uniform(*cfg.odom_delay, len(odom_ns))
                                  * NS).astype(np.int64)
    cmd_log = cmd_ns + np.round(rng['cmd_delay'].uniform(*cfg.command_delay, len(cmd_ns))
                                * NS).astype(np.int64)
    order = sorted([(int(odom_log[k]), 0, int(odom_ns[k]), k) for k in range(len(odom_ns))]
                   + [(int(cmd_log[k]), 1, int(cmd_ns[k]), k) for k in range(len(cmd_ns))])

    def records():
        for log_ns, kind, stamp_ns, k in order:
            if kind == 0:
                yield log_ns, ODOM_TOPIC, builder.odometry(stamp_ns, y[k], pose_cov, twist_cov)
            else:
                yield log_ns, ACTUATOR_TOPIC, builder.joints(stamp_ns, cmd_vals[k])

    write_bag(bag, records(), builder, compress=cfg.compress)

    # the sidecar (never inside the bag)
    coefficients = dict(zip(vehicle.names, map(float, vehicle.values)))
    truth = {
        'generator': GENERATOR,
        'bag': str(bag),
        'vehicle_file': file_vehicle.path,
        'truth_vehicle': vpath,
        'coefficients': coefficients,
        'file_coefficients': dict(zip(file_vehicle.names, map(float, file_vehicle.values))),
        'factors': factors,
        'perturbed': [n for n, f in factors.items() if f != 1.0],
        'notes': notes,
        'config': jsonable(dataclasses.asdict(cfg)),
        'start_ns': t0_ns,
        'current_ned': list(map(float, cfg.current_ned)),
        'current_body_t0': (rotation(*y0[9:12]).T @ np.asarray(cfg.current_ned, float)).tolist(),
        'dvl': cfg.dvl,
        'noise': {'kind': cfg.noise, 'sigma': dict(zip(CHANNELS, sigma.tolist())),
                  'tau_s': dict(zip(CHANNELS, tau.tolist())) if cfg.noise == 'ar1' else None,
                  'covariance_fields': cfg.covariance},
        'trim_speed_water': float(u_trim),
        'counts': {'odom_nominal': int(nominal), 'odom_written': int(len(odom_ns)),
                   'command_ticks': int(len(ticks)), 'commands_written': int(len(cmd_ns))},
        'channels': list(CHANNELS),
    }
    truth_json = out_dir / 'truth.json'
    truth_json.write_text(json.dumps(truth, indent=1) + '\n', encoding='utf-8')
    if cfg.write_states:
        np.savez_compressed(out_dir / 'truth_states.npz', t=t_odom, stamp_ns=odom_ns,
                            x_true=x_true, nu_r=nu_r, y=y, u=u_true, cmd_stamp_ns=cmd_ns,
                            cmd_values=cmd_vals)
    return GeneratedData(
        bag=bag, truth_json=truth_json, truth_vehicle=vpath, t0_ns=t0_ns,
        odom_stamp_ns=odom_ns, odom_log_ns=odom_log, t_odom=t_odom, x_true=x_true, nu_r=nu_r,
        y=y, noise=noise, u_true=u_true, cmd_stamp_ns=cmd_ns, cmd_log_ns=cmd_log,
        cmd_values=cmd_vals, tick_t=ticks, tick_values=tick_vals, nominal_odom=nominal,
        coefficients=coefficients, factors=factors, truth=truth)


# ---------------------------------------------------------------------------------------------
# raw sensors (issue 28): IMU, DVL and pressure at their own rates, with sensor errors


@dataclass
class RawConfig:
    """A raw-sensor run: the vehicle, manoeuvre, commands and current of ``data`` (its odometry
    options unused), sensed by an IMU, a DVL and a pressure sensor at their own rates and
    phases, each with a noise whose level factor and AR(1) correlation time are drawn per run
    from ``noise_level`` and ``noise_tau`` (s) and disclosed only in the truth; the messages
    declare the documented 1-sigma (DOCUMENTED_SIGMA). Sensor errors drawn per run: a constant
    gyro bias N(0, gyro_bias_sd) per axis (rad/s), a DVL heading misalignment of U(a, b) deg
    with a random sign (about body z, on top of the nominal mounting dvl_yaw_deg), a DVL scale
    error U(a, b), a surface pressure off the standard atmosphere by U(a, b) Pa. Lever arms m,
    body FRD."""

    data: DataConfig = field(default_factory=DataConfig)
    imu_rate: float = 100.0
    dvl_rate: float = 5.0
    dvl_dropout: float = 0.05
    depth_rate: float = 10.0
    gyro_bias_sd: float = 0.002
    dvl_misalignment_deg: tuple = (1.0, 2.0)
    dvl_scale: tuple = (-0.005, 0.005)
    dvl_yaw_deg: float = 45.0
    dvl_lever_arm: tuple = (-0.5, 0.0, 0.15)
    pressure_lever_arm: tuple = (-1.0, 0.0, -0.1)
    surface_pressure_pa: tuple = (-300.0, 300.0)
    noise_level: tuple = (0.5, 2.0)
    noise_tau: tuple = (0.0, 1.0)

    def validate(self):
        """ValueError naming the first bad field."""
        self.data.validate()
        for name in ('imu_rate', 'dvl_rate', 'depth_rate'):
            if not 0 < getattr(self, name) <= 1000:
                raise ValueError(f'{name} must be in (0, 1000] Hz')
        if not 0 <= self.dvl_dropout < 1:
            raise ValueError('dvl_dropout must be in [0, 1)')
        for name in ('dvl_misalignment_deg', 'dvl_scale', 'surface_pressure_pa', 'noise_level',
                     'noise_tau'):
            a, b = getattr(self, name)
            if not a <= b:
                raise ValueError(f'{name}: bad interval ({a}, {b})')


@dataclass
class RawRun:
    """What :func:`generate_raw` made: ``records`` (core.filter.raw.RawMeasurement, in time
    order, commands included), ``truth`` (coefficients, sensor errors, noise: what the
    identifier is not told), ``t`` (N,) s and ``x_true`` (N, 12) the truth at every sensor
    stamp, ``commands`` ((M,) s, (M, 7)) the published commands."""

    records: list
    truth: dict
    t: np.ndarray
    x_true: np.ndarray
    cmd_t: np.ndarray
    cmd_values: np.ndarray


# sensor frames of the generator: the IMU aligned with the body, the DVL turned by dvl_yaw_deg
SG = 1025.0 * 9.80665     # rho g (Pa/m) of the generated pressure (seawater, standard gravity)
P_ATM = 101325.0


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _exp_rot(v):
    """Rotation matrix of the rotation vector v (Rodrigues)."""
    a = float(np.linalg.norm(v))
    if a < 1e-12:
        return np.eye(3)
    k = v / a
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(a) * K + (1.0 - math.cos(a)) * K @ K


def _ou(t, sigma, tau, rng):
    """Stationary Ornstein-Uhlenbeck noise (len(t), len(sigma)) sampled at t (s); white for
    tau = 0."""
    sigma = np.asarray(sigma, dtype=float)
    w = rng.standard_normal((len(t), len(sigma)))
    if tau <= 0:
        return w * sigma
    e = np.empty_like(w)
    e[0] = w[0]
    a = np.exp(-np.diff(t) / tau)
    b = np.sqrt(1.0 - a * a)
    for k in range(1, len(t)):
        e[k] = a[k - 1] * e[k - 1] + b[k - 1] * w[k]
    return e * sigma


def _sensor_stamps(rate, duration, rng, dropout=0.0):
    """k / rate + a random phase within the period, minus independent dropouts."""
    t = rng.uniform(0.0, 1.0 / rate) + np.arange(int(duration * rate)) / rate
    t = np.round(t[t <= duration] * NS) / NS
    return t[rng.random(len(t)) >= dropout]


def _raw_errors(cfg, rng):
    """The run's sensor errors and noise (drawn): the truth the identifier is not told."""
    a, b = cfg.dvl_misalignment_deg
    noise = {s: {'level': float(rng.uniform(*cfg.noise_level)),
                 'tau_s': float(rng.uniform(*cfg.noise_tau))}
             for s in ('attitude', 'gyro', 'dvl', 'depth')}
    return {'gyro_bias': rng.normal(0.0, cfg.gyro_bias_sd, 3).tolist(),
            'dvl_misalignment': math.radians(rng.choice([-1.0, 1.0]) * rng.uniform(a, b)),
            'dvl_scale': float(rng.uniform(*cfg.dvl_scale)),
            'surface_pressure_offset_pa': float(rng.uniform(*cfg.surface_pressure_pa)),
            'noise': noise}


def generate_raw(cfg):
    """Make one raw-sensor run in memory (no bag: the input map's reader turns bags into the same
    records). Returns a :class:`RawRun`."""
    from auv_ident.core.filter.raw import RawMeasurement
    cfg.validate()
    d = cfg.data
    seqs = np.random.SeedSequence([d.seed, 28]).spawn(6)
    r_man, r_stamp, r_err, r_noise, _, _ = (np.random.default_rng(s) for s in seqs)
    vehicle = load_vehicle(d.vehicle)
    model = Model(vehicle)
    fin_limit = float(vehicle.raw['limits']['fin_rad'])
    targets = _targets(d, r_man, fin_limit, d.duration)
    ticks = np.round(command_ticks(d, r_man) * NS) / NS    # stamps at 1 ns, as a bag has
    vals = command_values(d, targets, ticks, d.rpm)
    pub = published_commands(d, ticks, vals)
    cmd_t, cmd_vals = ticks[pub], vals[pub]
    stamps = {'imu': _sensor_stamps(cfg.imu_rate, d.duration, r_stamp),
              'dvl': _sensor_stamps(cfg.dvl_rate, d.duration, r_stamp, cfg.dvl_dropout),
              'pressure': _sensor_stamps(cfg.depth_rate, d.duration, r_stamp)}
    t_all = np.unique(np.concatenate(list(stamps.values())))
    y0 = np.zeros(12)
    y0[0] = trim_speed(model, d.rpm) if d.u0 is None else float(d.u0)
    y0[8] = d.depth0
    y0[11] = math.radians(d.heading0_deg)
    dyn = Dynamics(model, d.current_ned)
    Y = integrate(dyn, y0, cmd_t, cmd_vals, t_all, d.duration, d)
    x_true = Y.copy()
    for k in range(len(Y)):
        x_true[k, :6] = dyn.nu_over_ground(Y[k])
    at = {name: np.searchsorted(t_all, ts) for name, ts in stamps.items()}
    err = _raw_errors(cfg, r_err)
    sig = np.asarray(DOCUMENTED_SIGMA, dtype=float)

    def noise(name, t, sigma):
        n = err['noise'][name]
        return _ou(t, np.asarray(sigma) * n['level'], n['tau_s'], r_noise)

    recs = []
    # IMU: the body attitude turned by a small world-axes rotation, rates plus bias
    k_imu = at['imu']
    e_att = noise('attitude', stamps['imu'], sig[9:12])
    e_gyr = noise('gyro', stamps['imu'], sig[3:6])
    imu_cov = np.diag(np.concatenate([sig[9:12], sig[3:6]]) ** 2)
    for j, k in enumerate(k_imu):
        R = _exp_rot(e_att[j]) @ rotation(*x_true[k, 9:12])
        w = x_true[k, 3:6] + np.asarray(err['gyro_bias']) + e_gyr[j]
        recs.append(RawMeasurement('imu', float(t_all[k]), np.concatenate([quat_of(R), w]),
                                   imu_cov))
    # DVL: bottom (or water) velocity at its lever arm, in its turned and misaligned frame
    r_d = np.asarray(cfg.dvl_lever_arm, dtype=float)
    R_mount = _rz(err['dvl_misalignment']) @ _rz(math.radians(cfg.dvl_yaw_deg))
    e_dvl = noise('dvl', stamps['dvl'], sig[0:3])
    dvl_cov = np.diag(sig[0:3] ** 2)
    for j, k in enumerate(at['dvl']):
        v = (Y[k, 0:3] if d.dvl == 'water' else x_true[k, 0:3])
        v_s = v + np.cross(x_true[k, 3:6], r_d)
        meas = (1.0 + err['dvl_scale']) * (R_mount.T @ v_s) + e_dvl[j]
        recs.append(RawMeasurement('dvl', float(t_all[k]), meas, dvl_cov))
    # pressure: the sensor's depth under the real surface pressure
    r_p = np.asarray(cfg.pressure_lever_arm, dtype=float)
    e_p = noise('depth', stamps['pressure'], sig[8:9])
    p_cov = np.array([[(sig[8] * SG) ** 2]])
    for j, k in enumerate(at['pressure']):
        z_s = x_true[k, 8] + rotation(*x_true[k, 9:12])[2] @ r_p + e_p[j, 0]
        recs.append(RawMeasurement('pressure', float(t_all[k]),
                                   np.array([P_ATM + err['surface_pressure_offset_pa']
                                             + SG * z_s]), p_cov))
    for t, u in zip(cmd_t, cmd_vals):
        recs.append(RawMeasurement('command', float(t), np.asarray(u, dtype=float)))
    # time order; a command stamped with a sensor message goes first (it acts from its stamp)
    recs.sort(key=lambda m: (m.t, m.kind != 'command'))
    truth = {'generator': GENERATOR + ' raw', 'config': jsonable(dataclasses.asdict(cfg)),
             'coefficients': dict(zip(vehicle.names, map(float, vehicle.values))),
             'sensor_errors': err, 'dvl_mounting_nominal_yaw_deg': cfg.dvl_yaw_deg,
             'counts': {k: int(len(v)) for k, v in stamps.items()}}
    return RawRun(recs, truth, t_all, x_true, cmd_t, cmd_vals)


class NavigationFilter:
    """A plain navigation EKF, the kind that makes a vehicle's fused odometry: state [x y z (NED),
    u v w (body), phi theta psi, gyro bias (3)], constant body velocity (white acceleration
    q_acc m/s^2/sqrt(Hz)), attitude driven by the gyro minus its bias; updated by the IMU
    attitude, the DVL (its nominal mounting and lever arm, no misalignment or scale: what such a
    filter is told) and the depth from pressure (standard atmosphere). Its odometry is
    [u v w, gyro - bias, x y z, phi theta psi] at odom_rate, the latest estimate at each tick:
    smoothed and lagged by its own constant-velocity model, as real fused odometry is. Shares
    nothing with the identifier."""

    def __init__(self, dvl_yaw_deg, dvl_lever_arm, pressure_lever_arm, q_acc=0.05,
                 q_bias=1e-5):
        self.Rd = _rz(math.radians(dvl_yaw_deg))
        self.rd = np.asarray(dvl_lever_arm, float)
        self.rp = np.asarray(pressure_lever_arm, float)
        self.q_acc, self.q_bias = q_acc, q_bias
        self.x = None
        self.P = None
        self.w = np.zeros(3)
        self.t = None
        self.seen = set()     # the kinds fused: the solution is valid once every one has been

    def _predict(self, t):
        dt = t - self.t
        if dt <= 0:
            return
        x = self.x
        phi, th, psi = x[6:9]
        R = rotation(phi, th, psi)
        om = self.w - x[9:12]
        F = np.eye(12)
        F[0:3, 3:6] = R * dt
        ct, tt = math.cos(th), math.tan(th)
        Tm = np.array([[1, math.sin(phi) * tt, math.cos(phi) * tt],
                       [0, math.cos(phi), -math.sin(phi)],
                       [0, math.sin(phi) / ct, math.cos(phi) / ct]])
        F[6:9, 9:12] = -Tm * dt
        x[0:3] += R @ x[3:6] * dt
        x[6:9] += Tm @ om * dt
        Q = np.zeros((12, 12))
        Q[3:6, 3:6] = np.eye(3) * self.q_acc ** 2 * dt
        Q[6:9, 6:9] = np.eye(3) * 1e-6 * dt
        Q[9:12, 9:12] = np.eye(3) * self.q_bias ** 2 * dt
        Q[0:3, 0:3] = np.eye(3) * 1e-4 * dt
        self.P = F @ self.P @ F.T + Q
        self.t = t

    def _update(self, nu, H, Rm):
        S = H @ self.P @ H.T + Rm
        K = self.P @ H.T @ np.linalg.inv(S)
        self.x += K @ nu
        A = np.eye(12) - K @ H
        self.P = A @ self.P @ A.T + K @ Rm @ K.T

    def feed(self, m):
        """Take one raw record (commands ignored)."""
        if m.kind == 'command':
            return
        if self.x is None:
            if m.kind != 'imu':
                return
            R = rotation_of_q(m.values[:4])
            self.x = np.zeros(12)
            self.x[6:9] = (math.atan2(R[2, 1], R[2, 2]), -math.asin(R[2, 0]),
                           math.atan2(R[1, 0], R[0, 0]))
            self.P = np.diag([100.0, 100.0, 100.0, 1.0, 1.0, 1.0, 1e-4, 1e-4, 1e-4,
                              1e-4, 1e-4, 1e-4])
            self.t = m.t
        self._predict(m.t)
        self.seen.add(m.kind)
        x = self.x
        if m.kind == 'imu':
            self.w = m.values[4:7].copy()
            R_m = rotation_of_q(m.values[:4])
            meas = np.array([math.atan2(R_m[2, 1], R_m[2, 2]), -math.asin(R_m[2, 0]),
                             math.atan2(R_m[1, 0], R_m[0, 0])])
            H = np.zeros((3, 12))
            H[:, 6:9] = np.eye(3)
            self._update(wrap(meas - x[6:9]), H, np.diag(np.diag(m.covariance)[:3]))
            x[6:9] = wrap(x[6:9])
        elif m.kind == 'dvl':
            om = self.w - x[9:12]
            v_b = self.Rd @ m.values - np.cross(om, self.rd)
            H = np.zeros((3, 12))
            H[:, 3:6] = np.eye(3)
            self._update(v_b - x[3:6], H, self.Rd @ m.covariance @ self.Rd.T)
        elif m.kind == 'pressure':
            R = rotation(*x[6:9])
            z = (m.values[0] - P_ATM) / SG - R[2] @ self.rp
            H = np.zeros((1, 12))
            H[0, 2] = 1.0
            self._update(np.array([z - x[2]]), H, m.covariance / SG ** 2)

    def odometry(self):
        """(12,) the current estimate as an odometry sample (u v w p q r x y z phi theta psi)."""
        x = self.x
        return np.concatenate([x[3:6], self.w - x[9:12], x[0:3], x[6:9]])


def rotation_of_q(q):
    """Rotation matrix of the quaternion q = (x, y, z, w)."""
    x, y, z, w = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def fused_odometry(run, cfg, rate=20.0):
    """(t (K,), Y (K, 12)): the plain navigation filter's odometry of a raw run at `rate` Hz
    (every 1/rate s, the latest estimate after the messages up to that tick)."""
    nav = NavigationFilter(cfg.dvl_yaw_deg, cfg.dvl_lever_arm, cfg.pressure_lever_arm)
    ticks = np.round(np.arange(1, int(run.records[-1].t * rate) + 1) / rate * NS) / NS
    t_out, Y = [], []
    j = 0
    for m in run.records:
        while j < len(ticks) and ticks[j] < m.t:
            if nav.seen >= {'imu', 'dvl', 'pressure'}:
                t_out.append(ticks[j])
                Y.append(nav.odometry())
            j += 1
        nav.feed(m)
    return np.array(t_out), np.array(Y)


# ---------------------------------------------------------------------------------------------
# command line


def _parse_tuple(text):
    return tuple(float(v) for v in text.split(',') if v.strip())


def _parse_gaps(text):
    out = []
    for part in text.split(','):
        if part.strip():
            a, b = part.split(':')
            out.append((float(a), float(b)))
    return tuple(out)


def config_parser():
    p = argparse.ArgumentParser(
        description="Make a rosbag2 MCAP bag of an AUV run independently of auv_ident's own "
                    'simulator (truth.json next to it). Tuples: comma-separated; gaps: '
                    'start:length,start:length; names: comma-separated. A value that starts '
                    'with "-" needs "=": --current-ned=-0.07,-0.07,0.')
    p.add_argument('--out', required=True, help='output directory (bag/ and truth.json)')
    p.add_argument('--overwrite', action='store_true')
    for f in dataclasses.fields(DataConfig):
        opt = '--' + f.name.replace('_', '-')
        default = f.default
        if f.name == 'gaps':
            p.add_argument(opt, type=_parse_gaps, default=default, help='start:length,...')
        elif f.name == 'perturb_keep':
            p.add_argument(opt, type=lambda s: tuple(n.strip() for n in s.split(',')
                                                     if n.strip()), default=default)
        elif f.name == 'u0':
            p.add_argument(opt, type=float, default=None, help='default: trim speed')
        elif f.name in ('noise_tau', 'noise_std'):
            p.add_argument(opt, type=lambda s: (_parse_tuple(s) if ',' in s else float(s)),
                           default=default)
        elif isinstance(default, bool):
            p.add_argument(opt, type=lambda s: s.lower() in ('1', 'true', 'yes', 'on'),
                           default=default, help=f'true/false (default {default})')
        elif isinstance(default, tuple):
            p.add_argument(opt, type=_parse_tuple, default=default,
                           help=f'default {",".join(map(str, default))}')
        else:
            p.add_argument(opt, type=type(default), default=default,
                           help=f'default {default}')
    return p


def main(argv=None):
    args = config_parser().parse_args(argv)
    kw = {f.name: getattr(args, f.name) for f in dataclasses.fields(DataConfig)}
    cfg = DataConfig(**kw)
    data = generate(cfg, args.out, overwrite=args.overwrite)
    c = data.truth['counts']
    print(f"wrote {data.bag}: {c['odom_written']} odometry ({c['odom_nominal']} nominal), "
          f"{c['commands_written']} commands ({cfg.commands}); truth in {data.truth_json}")
    return 0


if __name__ == '__main__':
    sys.exit(main())
