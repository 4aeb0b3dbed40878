"""Identification from a message stream without a ROS graph: the live node's logic and bag replay.

:class:`IdentSession` is everything the identifier node does per message, minus ROS: it turns
nav_msgs/Odometry and sensor_msgs/JointState (rclpy or rosbags objects) into arrays with
:mod:`auv_ident.conversions`, applies the rejection policy, feeds
:class:`auv_ident.core.stream.StreamIdentifier`, recovers from core errors and judges the
filter's health. The identifier node (``nodes/identifier_node.py``) and :func:`replay_bag` both
drive one IdentSession with the messages in arrival (log-time) order, so the same message
sequence gives identical estimates online and offline.

Rejection policy (the message is dropped, counted and reported; the filter is untouched):

- a ConversionError (wrong type, missing joint, zero quaternion, ...);
- an actuator command with a non-finite entry;
- odometry with a non-finite value in a *measured* channel (unmeasured channels are set to NaN
  and ignored);
- whatever StreamIdentifier rejects (stamp not after the previous one, no command yet).

Core errors (DomainError, DivergenceError, or a non-finite estimate after an update): the filter
restarts from its start-up configuration (initial guesses or warm start; the buffered commands
are kept), and the last good estimate stays available (:attr:`IdentSession.last_good`).

Estimate file (JSON, written by the node's ``~/save`` service and on shutdown, read by
``warm_start``)::

    {"vehicle": "nps_auv2",                 # vehicle name
     "coefficients": ["Z_ds", ...],         # p names, order of everything below
     "estimate": [..p floats..],            # vehicle file's units
     "std": [..p floats..],                 # 1-sigma, sqrt(diag(covariance))
     "covariance": [[..p..], ..p rows..],   # p x p, symmetric
     "stamp": 123.45,                       # s, odometry stamp of the last update (null: none)
     "stamp_ns": 123450000000,              # the same stamp in integer ns (null: none)
     "steps": 2400}                         # accepted odometry updates since start-up
"""
import bisect
from collections import Counter, deque
from dataclasses import dataclass, field
import json
import math
import os
from pathlib import Path

import numpy as np
import yaml

from .bag_io import bag_topics, BagError, read_bag
from .conversions import (ConversionError, FRAMES, joint_state_to_actuators, NS_PER_S,
                          odometry_to_state, stamp_to_ns)
from .core.ekf import MODES
from .core.errors import AuvIdentError, ConfigError, DivergenceError, DomainError
from .core.identify import DEFAULT_Q_STATE, FilterConfig
from .core.model import Model
from .core.simulate import DEFAULT_NOISE_STD
from .core.stream import StreamIdentifier
from .core.vehicle import load_vehicle, STATE_NAMES

MASS_INVERSES = ('default', 'exact', 'mss_literal')

# Health rule (see IdentSession.health)
NIS_WINDOW = 200          # updates in the running NIS window (10 s at 20 Hz)
NIS_BAND_PROB = 0.999     # two-sided chi-square band of the window's mean NIS per dof
CONVERGED_REL_STD = 0.05  # 'converged' needs every coefficient's 1-sigma below 5 % of |estimate|
GROSS_NIS_FACTOR = 10.0   # mean NIS/dof above 10x the band's upper edge: ERROR


class ParameterError(ConfigError):
    """A bad identifier setting; ``name`` is the node parameter (= keyword argument) at fault."""

    def __init__(self, name, message):
        self.name = name
        super().__init__(f'parameter {name!r}: {message}')


def _vector(name, values, n, default):
    """Return a float (n,) array; None or empty gives the default (ROS maps [] to 'not set')."""
    if values is None or len(values) == 0:
        return np.array(default, dtype=float)
    try:
        a = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(name, f'expected {n} numbers, got {values!r}') from None
    if a.shape != (n,):
        raise ParameterError(name, f'expected {n} numbers, got {a.size}')
    return a


def _positive(name, value, allow_zero=False):
    v = float(value)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        what = 'non-negative' if allow_zero else 'positive'
        raise ParameterError(name, f'{value!r} must be a {what} finite number')
    return v


def measured_mask(names):
    """(12,) bool from state channel names (u v w p q r x y z phi theta psi); empty: all."""
    if names is None or len(names) == 0:
        return np.ones(12, dtype=bool)
    if isinstance(names, np.ndarray) and names.dtype == bool:
        if names.shape != (12,):
            raise ParameterError('measured', f'a mask must have 12 entries, got {names.shape}')
        return names.copy()
    mask = np.zeros(12, dtype=bool)
    for n in names:
        if n not in STATE_NAMES:
            raise ParameterError('measured', f'unknown channel {n!r}; use names from '
                                             + ' '.join(STATE_NAMES))
        if mask[STATE_NAMES.index(n)]:
            raise ParameterError('measured', f'channel {n!r} listed twice')
        mask[STATE_NAMES.index(n)] = True
    return mask


# --- estimate files --------------------------------------------------------------------------


def estimate_document(vehicle, names, estimate, cov, stamp_ns, steps):
    """The JSON-ready dict of an estimate (schema in the module docstring)."""
    est = [float(v) for v in estimate]
    cov = np.asarray(cov, dtype=float)
    return {'vehicle': vehicle, 'coefficients': list(names), 'estimate': est,
            'std': [float(v) for v in np.sqrt(np.clip(np.diag(cov), 0.0, None))],
            'covariance': [[float(v) for v in row] for row in cov],
            'stamp': None if stamp_ns is None else stamp_ns / NS_PER_S,
            'stamp_ns': None if stamp_ns is None else int(stamp_ns),
            'steps': int(steps)}


def write_estimate_json(path, doc):
    """Write an estimate document atomically (temp file + rename); NaN/Inf refused."""
    path = Path(path)
    text = json.dumps(doc, indent=1, allow_nan=False) + '\n'
    # a plain open() (not mkstemp, which makes the file 0600) keeps the umask's permissions
    tmp = path.with_name(f'.{path.name}.{os.getpid()}.tmp')
    try:
        with open(tmp, 'w', encoding='utf-8') as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return path


def load_estimate_json(path):
    """Read an estimate file: (vehicle, names, estimate (p,), covariance (p, p)).

    Raises ParameterError('warm_start', ...) naming what is wrong."""
    try:
        with open(path, encoding='utf-8') as fh:
            doc = json.load(fh)
    except (OSError, ValueError) as err:
        raise ParameterError('warm_start', f'cannot read {path}: {err}') from None
    try:
        vehicle = str(doc['vehicle'])
        names = [str(n) for n in doc['coefficients']]
        est = np.asarray(doc['estimate'], dtype=float)
        cov = np.asarray(doc['covariance'], dtype=float)
    except (KeyError, TypeError, ValueError) as err:
        raise ParameterError('warm_start', f'{path}: not an estimate file ({err!r}); expected '
                                           'keys vehicle, coefficients, estimate, covariance') \
            from None
    p = len(names)
    if p == 0 or est.shape != (p,) or cov.shape != (p, p):
        raise ParameterError('warm_start', f'{path}: {p} coefficients but estimate shape '
                                           f'{est.shape} and covariance shape {cov.shape}')
    if not (np.all(np.isfinite(est)) and np.all(np.isfinite(cov))):
        raise ParameterError('warm_start', f'{path}: non-finite estimate or covariance')
    cov = 0.5 * (cov + cov.T)
    if np.any(np.linalg.eigvalsh(cov) <= 0):
        raise ParameterError('warm_start', f'{path}: covariance is not positive definite')
    return vehicle, names, est, cov


# --- the session -----------------------------------------------------------------------------


@dataclass
class Event:
    """What one message did.

    kind : 'update' (odometry fused), 'command' (actuators buffered), 'rejected' (dropped, see
        reason) or 'error' (a core error; the filter restarted, see reason)
    reason : why rejected / the error text / a note on an accepted update ('' if none)
    stamp_ns : header stamp of the message (None if it could not be read)
    estimate, std : (p,) after an update; cov : (p, p); nis, dof : of this update
    """

    kind: str
    reason: str = ''
    stamp_ns: object = None
    estimate: object = None
    std: object = None
    cov: object = None
    nis: float = math.nan
    dof: int = 0

    @property
    def accepted(self):
        return self.kind in ('update', 'command')


@dataclass
class LastGood:
    """The latest estimate that passed every check."""

    stamp_ns: int
    estimate: np.ndarray
    std: np.ndarray
    cov: np.ndarray


@dataclass
class Health:
    """Filter health by the rule of IdentSession.health: level 'OK'/'WARN'/'ERROR'."""

    level: str
    message: str
    mean_nis_per_dof: float
    band: tuple
    window: int


class IdentSession:
    """Online identification from ROS messages, ROS-graph-free (the node's per-message logic).

    Every keyword is named like the identifier node's parameter it comes from, and a bad value
    raises :class:`ParameterError` naming it.

    Parameters
    ----------
    vehicle : str, vehicle name or YAML path
    coefficients : sequence of str, coefficients to identify (empty: the vehicle's
        identify_default, or the warm-start file's list)
    initial : sequence of float, initial guesses (empty: truth * (1 + initial_offset))
    initial_offset : float, relative start offset when `initial` is empty
    noise_mode : 'fixed', 'paper', 'paper_q' or 'matching'
    tau : s, forgetting time constant; lam : the paper's lambda
    noise_std : (12,) measurement 1-sigma (state units); q_state : (12,) per-step process 1-sigma
    p0_rel, q_theta_rel : initial and per-step random-walk 1-sigma of theta, relative
    measured : channel names (empty: all 12)
    frame : 'ned' or 'enu', convention of the incoming Odometry
    sample_time : s, nominal sample time and longest single prediction step
    max_gap : s, a longer gap restarts the vehicle states (coefficients kept)
    mass_inverse : 'default', 'exact' or 'mss_literal'
    warm_start : '' or an estimate JSON path (start from its estimate and covariance)
    keep_arrays : keep every command and accepted measurement (for :func:`replay_bag`'s arrays)
    """

    def __init__(self, vehicle='nps_auv2', coefficients=(), initial=(), initial_offset=0.5,
                 noise_mode='fixed', tau=10.0, lam=2e-3, noise_std=None, q_state=None,
                 p0_rel=1.0, q_theta_rel=1e-5, measured=(), frame='ned', sample_time=0.05,
                 max_gap=5.0, mass_inverse='default', warm_start='', keep_arrays=False):
        try:
            self.vehicle = load_vehicle(vehicle)
        except ConfigError as err:
            raise ParameterError('vehicle', str(err)) from None
        if frame not in FRAMES:
            raise ParameterError('frame', f'{frame!r}; use one of {", ".join(FRAMES)}')
        self.frame = frame
        if mass_inverse not in MASS_INVERSES:
            raise ParameterError('mass_inverse', f'{mass_inverse!r}; use one of '
                                                 + ', '.join(MASS_INVERSES))
        if noise_mode not in MODES:
            raise ParameterError('noise_mode', f'{noise_mode!r}; use one of ' + ', '.join(MODES))
        T = _positive('sample_time', sample_time)
        max_gap = _positive('max_gap', max_gap)
        for name, v in (('tau', tau), ('lam', lam), ('p0_rel', p0_rel)):
            _positive(name, v)
        _positive('q_theta_rel', q_theta_rel, allow_zero=True)
        if not math.isfinite(initial_offset) or initial_offset == -1.0:
            raise ParameterError('initial_offset', f'{initial_offset!r} must be finite and not '
                                                   '-1 (that would start every guess at 0)')
        noise = _vector('noise_std', noise_std, 12, DEFAULT_NOISE_STD)
        qs = _vector('q_state', q_state, 12, DEFAULT_Q_STATE)
        for name, a in (('noise_std', noise), ('q_state', qs)):
            if not np.all(np.isfinite(a)) or np.any(a < 0):
                raise ParameterError(name, f'every 1-sigma must be finite and >= 0, got '
                                           f'{a.tolist()}')
        mask = measured_mask(measured)
        if np.any(noise[mask] <= 0):
            bad = [STATE_NAMES[i] for i in np.flatnonzero(mask & (noise <= 0))]
            raise ParameterError('noise_std', f'must be > 0 on every measured channel '
                                              f'(zero for {", ".join(bad)})')

        warm = None
        names = list(coefficients or ())
        if warm_start:
            w_vehicle, w_names, w_est, w_cov = load_estimate_json(warm_start)
            if w_vehicle != self.vehicle.name:
                raise ParameterError('warm_start', f'{warm_start} is for vehicle {w_vehicle!r}, '
                                                   f'not {self.vehicle.name!r}')
            if not names:
                names = w_names
            warm = (w_names, w_est, w_cov)
        if not names:
            names = list(self.vehicle.identify_default)
        for n in names:
            try:
                self.vehicle.index(n)
            except ConfigError as err:
                raise ParameterError('coefficients', str(err)) from None
        canon = [self.vehicle.names[self.vehicle.index(n)] for n in names]
        if len(set(canon)) != len(canon):
            raise ParameterError('coefficients', f'a coefficient is listed twice in {names}')
        try:
            self.model = Model(self.vehicle, canon, mass_inverse=mass_inverse)
        except ConfigError as err:
            raise ParameterError('mass_inverse', str(err)) from None
        p = self.model.p

        init = None
        if initial is not None and len(initial) > 0:
            init = _vector('initial', initial, p, None)
            if not np.all(np.isfinite(init)) or np.any(init == 0):
                raise ParameterError('initial', f'guesses must be finite and non-zero (0 gives '
                                                f'no scale for the covariance): {init.tolist()}')
        self.warm_cov = None
        if warm is not None:
            w_names, w_est, w_cov = warm
            w_canon = [self.vehicle.names[self.vehicle.index(n)] if n in self.vehicle.names
                       else n for n in w_names]
            if w_canon != canon:
                raise ParameterError('warm_start', f'{warm_start} holds {w_names}, but the '
                                                   f'coefficients to identify are {canon}')
            if init is not None:
                raise ParameterError('initial', 'give either initial guesses or warm_start, '
                                                'not both')
            if np.any(w_est == 0):
                raise ParameterError('warm_start', f'{warm_start}: an estimate of exactly 0')
            init = w_est
            self.warm_cov = w_cov

        self.cfg = FilterConfig(coefficients=canon, initial=init,
                                initial_offset=float(initial_offset), p0_rel=float(p0_rel),
                                q_theta_rel=float(q_theta_rel), q_state=qs, noise_std=noise,
                                measured=mask, mode=noise_mode, tau=float(tau), lam=float(lam))
        self.T = T
        self.max_gap = max_gap
        self.names = canon
        self.measured = mask
        self.keep_arrays = keep_arrays
        self.commands = []          # (t, u6) in arrival order, if keep_arrays
        self.measurements = []      # (t, y12) of accepted updates, if keep_arrays
        try:
            self.stream = self._new_stream()
        except ConfigError as err:  # what the checks above did not catch
            raise ParameterError('initial', str(err)) from None
        self.theta0 = self.stream.ekf.theta0.copy()
        self.odom_accepted = 0
        self.odom_rejected = 0
        self.cmd_accepted = 0
        self.cmd_rejected = 0
        self.errors = 0
        self.last_error = ''
        self.reasons = Counter()
        self.last_good = None
        self.last_nis = math.nan
        self.last_dof = 0
        self._since_error = None    # updates since the last core error (None: no error yet)
        self._nis = deque(maxlen=NIS_WINDOW)

    # -- filter lifecycle --

    def _new_stream(self, keep_commands_from=None):
        s = StreamIdentifier(self.model, self.cfg, self.T, self.max_gap)
        if self.warm_cov is not None:
            _warm_start_ekf(s.ekf, self.warm_cov)
        if keep_commands_from is not None:
            s.cmd_t = list(keep_commands_from.cmd_t)
            s.cmd_u = list(keep_commands_from.cmd_u)
        return s

    def reset(self):
        """Restart the filter from the start-up configuration (buffered commands are kept;
        counters and the last good estimate too)."""
        self.stream = self._new_stream(keep_commands_from=self.stream)
        self._nis.clear()

    def warm_up(self):
        """Run a throwaway copy of the filter over three synthetic trim samples, so numba
        loads (or, with a stale cache, compiles: ~15 s) the EKF before real data arrive."""
        from .core.simulate import initial_state
        try:
            s = StreamIdentifier(self.model, self.cfg, self.T, self.max_gap)
            rpm = float(self.vehicle.cruise_rpm)
            x0 = initial_state(self.model, rpm)
            s.add_command(0.0, np.array([0.0, 0.0, 0.0, 0.0, 0.0, rpm]))
            for k in range(3):
                s.add_measurement(k * self.T, np.where(self.measured, x0, np.nan))
        except AuvIdentError:
            pass    # only a warm-up: the real data decide

    @property
    def started(self):
        """True once the current filter has fused a measurement."""
        return self.stream.ekf.xa is not None

    def current(self):
        """(estimate, covariance) now: the filter's, the last good one, or the prior."""
        f = self.stream.ekf
        if f.xa is not None:
            return f.theta, f.theta_cov
        if self.last_good is not None:
            return self.last_good.estimate.copy(), self.last_good.cov.copy()
        if self.warm_cov is not None:
            return self.theta0.copy(), self.warm_cov.copy()
        return self.theta0.copy(), np.diag((self.cfg.p0_rel * np.abs(self.theta0)) ** 2)

    def document(self):
        """The estimate file's dict for the best estimate available now."""
        est, cov = self.current()
        stamp = self.last_good.stamp_ns if self.last_good is not None else None
        return estimate_document(self.vehicle.name, self.names, est, cov, stamp,
                                 self.odom_accepted)

    # -- messages --

    def _reject(self, what, reason, stamp_ns=None):
        if what == 'odom':
            self.odom_rejected += 1
        else:
            self.cmd_rejected += 1
        self.reasons[f'{what}: {reason.split(":")[0]}'] += 1
        return Event('rejected', f'{what}: {reason}', stamp_ns)

    def on_actuators(self, msg):
        """Buffer a sensor_msgs/JointState actuator command. Returns an Event."""
        stamp_ns = _stamp_ns(msg)
        try:
            t, u6 = joint_state_to_actuators(msg)
        except ConversionError as err:
            return self._reject('actuators', str(err), stamp_ns)
        if not np.all(np.isfinite(u6)):
            return self._reject('actuators', f'non-finite command {u6.tolist()} at {t:.9f} s',
                                stamp_ns)
        self.stream.add_command(t, u6)
        if self.keep_arrays:
            self.commands.append((t, u6))
        self.cmd_accepted += 1
        return Event('command', '', stamp_ns)

    def on_odom(self, msg):
        """Fuse a nav_msgs/Odometry measurement. Returns an Event."""
        stamp_ns = _stamp_ns(msg)
        try:
            t, x12, _, _ = odometry_to_state(msg, self.frame)
        except ConversionError as err:
            return self._reject('odom', str(err), stamp_ns)
        y = np.where(self.measured, x12, np.nan)
        bad = self.measured & ~np.isfinite(x12)
        if np.any(bad):
            return self._reject('odom', 'non-finite field(s) '
                                + ', '.join(STATE_NAMES[i] for i in np.flatnonzero(bad))
                                + f' at {t:.9f} s', stamp_ns)
        f = self.stream.ekf
        try:
            out = self.stream.add_measurement(t, y)
            if out.accepted:
                est, cov = self.stream.ekf.theta, self.stream.ekf.theta_cov
                d = np.diag(cov)
                if not (np.all(np.isfinite(est)) and np.all(np.isfinite(cov))
                        and np.all(d > 0)):
                    raise DivergenceError(f'non-finite or non-positive coefficient covariance '
                                          f'after the update at {t:.9f} s')
        except (DomainError, DivergenceError) as err:
            self.errors += 1
            self.last_error = f'{type(err).__name__}: {err}'
            self._since_error = 0
            self.reset()
            return Event('error', self.last_error + ' (filter restarted)', stamp_ns)
        if not out.accepted:
            return self._reject('odom', out.reason, stamp_ns)
        std = np.sqrt(d)
        self.odom_accepted += 1
        self.last_good = LastGood(stamp_ns, est, std, cov)
        self.last_nis, self.last_dof = float(f.nis), int(f.dof)
        if f.dof > 0 and math.isfinite(f.nis):
            self._nis.append((float(f.nis), int(f.dof)))
        if self._since_error is not None:
            self._since_error += 1
        if self.keep_arrays:
            self.measurements.append((t, y))
        return Event('update', out.reason, stamp_ns, est, std, cov, float(f.nis), int(f.dof))

    # -- health --

    def mean_nis_per_dof(self):
        if not self._nis:
            return math.nan
        a = np.array(self._nis)
        return float(a[:, 0].sum() / a[:, 1].sum())

    def health(self):
        """Judge the filter (the rule the /diagnostics status reports).

        Over the last NIS_WINDOW (200) updates, m = sum(NIS) / sum(dof) and the
        chi-square band [lo, hi] of m for D = sum(dof) degrees of freedom (two-sided 99.9 %:
        windows overlap, so a 99 % band would blip WARN now and then on a healthy filter):

        - no update since start or restart: WARN 'waiting for data';
        - a core error and fewer than NIS_WINDOW updates since, or m > 10 hi: ERROR 'diverging';
        - window full and m > hi (innovations larger than the filter expects): WARN 'diverging';
        - window full, m <= hi and every coefficient's 1-sigma < 5 % of |estimate|:
          OK 'converged';
        - otherwise OK 'converging'. (m < lo, a conservative filter, is not flagged.)
        """
        m = self.mean_nis_per_dof()
        n = len(self._nis)
        band = (math.nan, math.nan)
        if n:
            from scipy.stats import chi2
            D = float(sum(d for _, d in self._nis))
            a = 0.5 * (1.0 - NIS_BAND_PROB)
            band = (float(chi2.ppf(a, D) / D), float(chi2.ppf(1.0 - a, D) / D))
        if self._since_error is not None and self._since_error < NIS_WINDOW:
            return Health('ERROR', 'diverging', m, band, n)
        if not self.started:
            return Health('WARN', 'waiting for data', m, band, n)
        if n and m > GROSS_NIS_FACTOR * band[1]:
            return Health('ERROR', 'diverging', m, band, n)
        full = n >= NIS_WINDOW
        if full and m > band[1]:
            return Health('WARN', 'diverging', m, band, n)
        est, cov = self.current()
        rel = np.sqrt(np.diag(cov)) / np.abs(est)
        if full and np.all(rel < CONVERGED_REL_STD):
            return Health('OK', 'converged', m, band, n)
        return Health('OK', 'converging', m, band, n)


def _stamp_ns(msg):
    try:
        return stamp_to_ns(msg.header.stamp)
    except (AttributeError, TypeError, ValueError):
        return None


def _warm_start_ekf(ekf, theta_cov):
    """Make the EKF's start() use theta_cov for the coefficient block of P (not p0_rel).

    AugmentedEKF has no option for an initial coefficient covariance, so start() is wrapped:
    the original start builds the state and fuses y0 with the coefficient block diagonal; this
    version does the same with the full warm-start covariance (cross terms zero)."""
    def warm_start(y0, rpm):
        x0, sd0 = ekf.initial_state(y0, rpm)
        ekf.xa = np.concatenate([x0, ekf.theta0])
        P = np.zeros((ekf.n, ekf.n))
        P[:12, :12] = np.diag(sd0 ** 2)
        P[12:, 12:] = theta_cov
        ekf.P = P
        ekf.update(y0)
    ekf.start = warm_start


# --- bag replay ------------------------------------------------------------------------------


@dataclass
class ReplayResult:
    """Identification over a bag.

    names : coefficient names; vehicle, frame : what was used
    updates : list of (stamp_ns, estimate (p,), std (p,)), one per accepted odometry update
    estimate, std, cov : final (last good) estimate, 1-sigma, covariance (p,), (p,), (p, p)
    initial : the initial guesses; truth : the vehicle file's values (the truth of a simulated
        bag)
    accepted, rejected : odometry messages fused / dropped; commands : actuator messages
        buffered; errors : core errors (each restarted the filter); reasons : Counter of
        rejection reasons
    t, Y, U : (N,), (N, 12), (N, 6) of the accepted measurements (NaN: unmeasured channel) and
        U[k] = the command in force at t[k] (latest stamp <= t[k]), for identify.refine
    mean_nis_per_dof : over the last NIS window; health : the node's health verdict at the end
    """

    names: list
    vehicle: str
    frame: str
    updates: list
    estimate: np.ndarray
    std: np.ndarray
    cov: np.ndarray
    initial: np.ndarray
    truth: np.ndarray
    accepted: int
    rejected: int
    commands: int
    errors: int
    reasons: Counter
    t: np.ndarray
    Y: np.ndarray
    U: np.ndarray
    mean_nis_per_dof: float
    health: Health
    T: float = 0.05
    settings: dict = field(default_factory=dict)

    def document(self, stamp_ns=None):
        """The estimate file's dict of the final estimate."""
        if stamp_ns is None and self.updates:
            stamp_ns = self.updates[-1][0]
        return estimate_document(self.vehicle, self.names, self.estimate, self.cov, stamp_ns,
                                 self.accepted)


def bag_custom_data(path):
    """metadata.yaml's custom_data of a bag directory ({} if absent or unreadable)."""
    meta = Path(path) / 'metadata.yaml'
    if not meta.is_file():
        return {}
    try:
        doc = yaml.safe_load(meta.read_text(encoding='utf-8'))
        data = doc['rosbag2_bagfile_information'].get('custom_data') or {}
    except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError, AttributeError):
        return {}
    return {str(k): str(v) for k, v in data.items()} if isinstance(data, dict) else {}


def replay_messages(messages, session, odom_topic='/odom', actuator_topic='/actuators'):
    """Drive an IdentSession with (topic, t_ns, msg) in the given order; other topics ignored.

    Returns the list of (stamp_ns, estimate, std) of the accepted updates."""
    updates = []
    for topic, _, msg in messages:
        if topic == actuator_topic:
            session.on_actuators(msg)
        elif topic == odom_topic:
            ev = session.on_odom(msg)
            if ev.kind == 'update':
                updates.append((ev.stamp_ns, ev.estimate, ev.std))
    return updates


def session_result(session, updates, settings=None):
    """Pack a finished session into a ReplayResult (arrays aligned by the pairing rule)."""
    cmd = sorted(session.commands, key=lambda c: c[0])   # stable: later same-stamp one last
    cmd_t = [c[0] for c in cmd]
    t = np.array([m[0] for m in session.measurements], dtype=float)
    Y = (np.array([m[1] for m in session.measurements], dtype=float)
         if session.measurements else np.zeros((0, 12)))
    U = np.full((len(t), 6), np.nan)
    for k, tk in enumerate(t):
        i = bisect.bisect_right(cmd_t, tk)
        if i > 0:
            U[k] = cmd[i - 1][1]
    est, cov = session.current()
    if session.last_good is not None:
        est, cov = session.last_good.estimate, session.last_good.cov
    return ReplayResult(
        names=list(session.names), vehicle=session.vehicle.name, frame=session.frame,
        updates=updates, estimate=est, std=np.sqrt(np.diag(cov)), cov=cov,
        initial=session.theta0.copy(), truth=session.model.theta_true,
        accepted=session.odom_accepted, rejected=session.odom_rejected,
        commands=session.cmd_accepted, errors=session.errors, reasons=session.reasons,
        t=t, Y=Y, U=U, mean_nis_per_dof=session.mean_nis_per_dof(), health=session.health(),
        T=session.T, settings=dict(settings or {}))


def replay_bag(path, vehicle=None, coefficients=(), frame=None, odom_topic='/odom',
               actuator_topic='/actuators', **settings):
    """Identify from a bag exactly as the identifier node would have live.

    Odometry and actuator messages are read in log-time order (as recorded) and fed to an
    IdentSession in that order.

    Parameters
    ----------
    path : bag directory or .mcap file
    vehicle, frame : default from the bag's metadata custom_data ('auv_ident.vehicle',
        'auv_ident.frame', written for simulated runs), else 'nps_auv2' and 'ned'
    coefficients : names (empty: the vehicle's identify_default)
    odom_topic, actuator_topic : topics to read
    **settings : any other IdentSession keyword (initial, initial_offset, noise_mode, tau, lam,
        noise_std, q_state, p0_rel, q_theta_rel, measured, sample_time, max_gap, mass_inverse,
        warm_start); defaults are the node's parameter defaults

    Returns a ReplayResult. Raises BagError for an unreadable bag or a missing topic,
    ParameterError for a bad setting.
    """
    present = bag_topics(path)
    for what, topic in (('odometry', odom_topic), ('actuator', actuator_topic)):
        if topic not in present:
            listing = ', '.join(f'{t} ({present[t]})' for t in sorted(present)) or 'none'
            raise BagError(f'{path}: no {what} topic {topic!r} in the bag; topics present: '
                           f'{listing}')
    meta = bag_custom_data(path)
    vehicle = vehicle or meta.get('auv_ident.vehicle') or 'nps_auv2'
    frame = frame or meta.get('auv_ident.frame') or 'ned'
    settings.pop('keep_arrays', None)
    session = IdentSession(vehicle=vehicle, coefficients=coefficients, frame=frame,
                           keep_arrays=True, **settings)
    msgs = read_bag(path, {odom_topic: 'nav_msgs/msg/Odometry',
                           actuator_topic: 'sensor_msgs/msg/JointState'})
    updates = replay_messages(msgs, session, odom_topic, actuator_topic)
    return session_result(session, updates, dict(settings, vehicle=vehicle, frame=frame,
                                                 coefficients=list(coefficients)))



def _bag_truth_and_noise(path, model):
    """Truth (the vehicle file's values) only for bags our simulator wrote; the noise 1-sigma
    stored with them, else the default sensor suite."""
    meta = bag_custom_data(path)
    simulated = meta.get('auv_ident.simulated') == 'true'
    noise = DEFAULT_NOISE_STD.copy()
    if 'auv_ident.noise_std' in meta:
        try:
            vals = np.array([float(v) for v in meta['auv_ident.noise_std'].split()])
            if vals.shape == (12,) and np.all(vals > 0):
                noise = vals
        except ValueError:
            pass
    return (model.theta_true if simulated else None), noise, meta


def identify_bag(path, vehicle=None, coefficients='', noise_mode='fixed', initial_offset=0.5,
                 refine_pass=True, progress=None):
    """`identify --bag`: the live identifier's EKF pass over the bag (replay_bag), then the
    batch refinement on the paired arrays. Returns (JSON document, printable table)."""
    import time
    from . import experiments as ex
    from .core.identify import Result, refine
    t0 = time.perf_counter()
    names = [n.strip() for n in (coefficients or '').split(',') if n.strip()]
    rr = replay_bag(path, vehicle=vehicle, coefficients=names, noise_mode=noise_mode,
                    initial_offset=initial_offset)
    v = load_vehicle(rr.vehicle)
    model = Model(v, rr.names)
    truth, noise, meta = _bag_truth_and_noise(path, model)
    if rr.accepted < 2:
        raise BagError(f'{path}: only {rr.accepted} odometry samples could be used '
                       f'(rejected: {dict(rr.reasons)})')
    est, cov = rr.estimate, rr.cov
    if refine_pass:
        ok = np.all(np.isfinite(rr.U), axis=1)
        cfg = ex.make_config(rr.names, noise_mode='fixed', noise_std=noise)
        est, cov, _ = refine(model, cfg, rr.Y[ok], rr.U[ok], rr.T, rr.estimate,
                             progress=progress)
    res = Result(names=rr.names, estimate=est, std=np.sqrt(np.diag(cov)), cov=cov,
                 ekf_estimate=rr.estimate, ekf_std=rr.std, initial=rr.initial, truth=truth,
                 steps=rr.accepted, wall_s=time.perf_counter() - t0,
                 mean_nis_per_dof=rr.mean_nis_per_dof, refined=refine_pass)
    head = (f'{v.title}: identified {", ".join(rr.names)} from bag {path} '
            f'({rr.accepted} odometry samples used, {rr.rejected} rejected, {rr.commands} '
            f'actuator commands; frame {rr.frame})')
    if meta.get('auv_ident.simulated') == 'true':
        head += (f'\nsimulated by auv_ident: manoeuvre {meta.get("auv_ident.maneuver")!r}, seed '
                 f'{meta.get("auv_ident.seed")}; truth = the vehicle file values')
    head += (f'\ninitial guesses {100 * initial_offset:+.0f} % from the vehicle file; noise '
             f'adaptation: {noise_mode}; ' + ('EKF pass + batch refinement (filter-error ML)'
                                              if refine_pass else 'EKF pass only'))
    doc = ex.result_dict(v, res, {'bag': str(path), 'rejected': rr.rejected,
                                  'noise_mode': noise_mode,
                                  'rejection_reasons': dict(rr.reasons)})
    table = (head + '\n' + ex.result_table(v, res) + f'\n{res.steps} EKF steps, mean NIS/dof '
             f'{res.mean_nis_per_dof:.3f}, wall {res.wall_s:.2f} s')
    return doc, table


def bag_source(path, vehicle=None, coefficients=''):
    """experiments.Source of a bag: the paired arrays (U[k] = command in force at t_k)."""
    from .experiments import Source, coefficient_list
    names = [n.strip() for n in (coefficients or '').split(',') if n.strip()]
    rr = replay_bag(path, vehicle=vehicle, coefficients=names)
    v = load_vehicle(rr.vehicle)
    names = coefficient_list(v, ','.join(rr.names))
    truth, noise, meta = _bag_truth_and_noise(path, Model(v, names))
    ok = np.all(np.isfinite(rr.U), axis=1)
    return Source(vehicle=v, names=names, t=rr.t[ok], Y=rr.Y[ok], U=rr.U[ok], T=rr.T,
                  noise_std=noise, description=f'bag {path} ({int(ok.sum())} samples)',
                  truth=truth, seed=meta.get('auv_ident.seed'),
                  maneuver=meta.get('auv_ident.maneuver', ''))
