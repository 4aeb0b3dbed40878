"""The identifier's per-message logic, without a ROS graph: :class:`IdentSession`.

:class:`IdentSession` is everything the identifier node does per message, minus ROS: it turns
nav_msgs/Odometry and sensor_msgs/JointState (rclpy or rosbags objects) into arrays with
:mod:`auv_ident.session.messages`, applies the rejection policy, feeds
:class:`auv_ident.core.stream.StreamIdentifier`, guards against divergence and judges the
filter's health. The identifier node (``ros/identifier_node.py``) and :func:`replay_bag` both
drive one IdentSession with the messages in arrival (log-time) order, so the same message
sequence gives identical estimates online and offline.

Rejection policy (the message is dropped, counted under ``'<topic>: <code>'`` in
``IdentSession.reasons`` and reported with a reason naming the problem; the filter is
untouched). Codes, in the order they are checked:

- ``conversion``: a ConversionError (wrong message type, missing or duplicated joint, zero
  quaternion, array lengths that do not match the joint names, ...);
- ``wrong frame`` (odometry): header.frame_id / child_frame_id name the other convention
  (a token ``ned`` or ``frd`` with frame 'enu', ``enu`` or ``flu`` with frame 'ned'; ids
  without such a token, e.g. 'odom'/'base_link', are not judged);
- ``frame changed`` (odometry): frame ids that differ from those of the first accepted
  odometry (the ~/reset service forgets them);
- ``non-finite``: NaN or Inf in a command, or in a *measured* odometry channel (unmeasured
  channels are set to NaN and ignored; the message covariances are not used);
- ``implausible``: a value no vehicle produces, i.e. wrong units or a wrong frame (the
  plausibility rule below);
- from StreamIdentifier (core/stream.py, its docstring has the time rules): ``no command``,
  ``stale command`` (the command in force is older than 1 s), ``command unknown`` (a
  newer command in the interval was rejected: the input is unknown), ``zero stamp``,
  ``duplicate stamp``, ``out of order``, ``time jump backwards`` (until five consistent
  messages confirm it), ``outlier`` (innovation gate, below). Accepted with a note: ``gap``
  (more than max_bridge, 0.25 s, without odometry: vehicle states restarted), ``time jump``,
  ``repaired``.

Plausibility rule (wrong units or frames detectable by range; only measured channels):
|u|, |v|, |w| <= MAX_BODY_SPEED (10 m/s: cm/s or mm/s are caught); |p|, |q|, |r| <=
MAX_BODY_RATE (5 rad/s: deg/s are caught once a rate exceeds 5 deg/s); |phi|, |theta| <=
MAX_TILT (1.2 rad = 69 deg: a sensor frame mounted 90 deg off, e.g. an optical frame);
|z| <= MAX_DEPTH (11000 m: depth in cm/mm); |x|, |y| <= MAX_HORIZONTAL (2e7 m: position in
mm); commands: |fin| <= FIN_LIMIT_FACTOR (2) x the vehicle's fin limit (degrees given as
radians: caught once a deflection exceeds 2x the limit *in degrees*, i.e. 0.7 deg for +-20 deg
fins), |n| <= SHAFT_LIMIT_FACTOR (2) x the vehicle's shaft limit (rpm written into the rad/s
velocity field is caught above 2 x 1500 / 9.55 = 314 rpm). NOT detectable by range: rates in
deg/s below 5 deg/s, speeds in knots, shaft speed in rev/s, positions in km, an ENU/FLU stream
read as NED/FRD (every value stays in range: (phi, -theta, pi/2 - psi), flipped v, w, q, r);
these make the innovations inconsistent with the model instead, which the divergence guard
below catches (outliers, then a reset, ERROR 'diverging' on /diagnostics). Simulated runs of
every vehicle and manoeuvre and the shipped bag are far inside the bounds (|u| < 0.7 m/s,
rates < 0.16 rad/s, tilt < 0.4 rad).

Divergence guard (not in noise mode 'paper', whose adapted R makes the NIS meaningless):

- innovation gate: an update whose NIS exceeds OUTLIER_GATE_FACTOR (100) x the chi-square
  quantile 1 - 1e-9 for its m channels (6735 for m = 12, i.e. NIS/dof 561) is not fused; the
  message is rejected as ``outlier``. Legitimate data stay far below: NIS/dof <= 4 on
  simulated runs, <= 56 with unmodelled process noise and the default (small) q_state, where
  a tighter gate was measured to reject good data and wreck the estimate;
- covariance: an update that finds or leaves the covariance non-positive-definite is repaired
  by symmetrising and flooring the eigenvalues (core.filter.repair_covariance) and counted
  in ``repairs``; the update stands;
- reset rule: a core error that the repair cannot fix (DomainError; DivergenceError:
  non-finite state or covariance, a second failure after the repair, a coefficient 1-sigma
  above COV_BLOWUP_FACTOR (100) x its prior p0_rel |initial guess|), or innovations
  inconsistent for GUARD_SECONDS (1 s of stamps: the median NIS/dof over the last
  GUARD_WINDOW (20) updates, outliers included, above GUARD_FACTOR (100); the median, so a
  burst shorter than half the window does not count; legitimate data with process noise
  reached 26), RESETS THE FILTER: the vehicle states restart from the next measurement,
  the coefficients from the last good estimate with its covariance times RESET_COV_INFLATION
  (4, i.e. 2x the 1-sigma). The start-up configuration (initial guesses or warm start) is
  used instead if there is no good estimate yet, if the inflated covariance is unusable, or
  for a core error when the previous reset also started from the last good estimate and no
  update since was good (the last good estimate itself may be the problem). Buffered
  commands are kept. /diagnostics reports ERROR 'diverging' until NIS_WINDOW (200) updates
  have passed; the reason is logged and in ``last_error``;
- last good estimate (:attr:`IdentSession.last_good`): updated only by an update that was
  fused (not an outlier), has a finite estimate and a positive definite covariance, while the
  guard window is consistent and, after a reset, once GUARD_WINDOW updates have refilled it
  with a median NIS/dof <= GUARD_PROBATION (10), and while the health window (last 200
  updates) is not grossly inconsistent (mean NIS/dof above 10x its chi-square band: what
  /diagnostics reports as ERROR 'diverging'; model mismatch of simulated runs with process
  noise stays at WARN) (Event.good). Only such updates are published by the node; the
  estimate file (~/save, shutdown, autosave) and :meth:`IdentSession.best` give the last
  good estimate.

Estimate file (JSON, written by the node's ``~/save`` service, on shutdown and every 10 s
while updates arrive; read by ``warm_start``; always the last good estimate)::

    {"vehicle": "nps_auv2",                 # vehicle name
     "coefficients": ["Z_ds", ...],         # p names, order of everything below
     "estimate": [..p floats..],            # vehicle file's units
     "std": [..p floats..],                 # 1-sigma, sqrt(diag(covariance))
     "covariance": [[..p..], ..p rows..],   # p x p, symmetric
     "stamp": 123.45,                       # s, odometry stamp of the last update (null: none)
     "stamp_ns": 123450000000,              # the same stamp in integer ns (null: none)
     "steps": 2400}                         # accepted odometry updates since start-up
"""
from collections import Counter, deque
from dataclasses import dataclass
import math
import re

import numpy as np

from auv_ident.core.ekf import MODES
from auv_ident.core.errors import AuvIdentError, ConfigError, DivergenceError, DomainError
from auv_ident.core.filter import DEFAULT_Q_STATE, FilterConfig, is_positive_definite
from auv_ident.core.model import Model
from auv_ident.core.sensors import DEFAULT_NOISE_STD
from auv_ident.core.stream import StreamIdentifier
from auv_ident.core.state import STATE_NAMES
from auv_ident.core.vehicle import P_FIN, P_NMAX
from auv_ident.session.estimate_file import estimate_document, load_estimate_json
from auv_ident.session.messages import (ConversionError, FRAMES, JOINT_NAMES,
                                        joint_state_to_actuators, NS_PER_S, odometry_to_state,
                                        stamp_to_ns)
from auv_ident.session.settings import (_positive, _vector, MASS_INVERSES, measured_mask,
                                        ParameterError)
from auv_ident.vehicles import load_vehicle

# Plausibility rule (module docstring)
MAX_BODY_SPEED = 10.0       # m/s, |u| |v| |w|
MAX_BODY_RATE = 5.0         # rad/s, |p| |q| |r|
MAX_TILT = 1.2              # rad, |phi| |theta|
MAX_DEPTH = 11000.0         # m, |z|
MAX_HORIZONTAL = 2.0e7      # m, |x| |y|
FIN_LIMIT_FACTOR = 2.0      # x the vehicle's fin limit
SHAFT_LIMIT_FACTOR = 2.0    # x the vehicle's shaft-speed limit
_STATE_BOUNDS = np.array([MAX_BODY_SPEED] * 3 + [MAX_BODY_RATE] * 3
                         + [MAX_HORIZONTAL, MAX_HORIZONTAL, MAX_DEPTH]
                         + [MAX_TILT, MAX_TILT, np.inf])
_STATE_UNITS = ['m/s'] * 3 + ['rad/s'] * 3 + ['m'] * 3 + ['rad'] * 3

# Divergence guard (module docstring)
OUTLIER_P = 1e-9            # chi-square tail of the innovation gate ...
OUTLIER_GATE_FACTOR = 100.0  # ... times this
GUARD_WINDOW = 20           # updates in the guard's NIS window
GUARD_FACTOR = 100.0        # inconsistent: window median NIS/dof above this
GUARD_SECONDS = 1.0         # s of stamps the inconsistency must last before a reset
GUARD_PROBATION = 10.0      # after a reset: good only once the window median NIS/dof <= this
RESET_COV_INFLATION = 4.0   # coefficient covariance factor when a reset restarts from last good
COV_BLOWUP_FACTOR = 100.0   # a coefficient 1-sigma above this x p0_rel |theta0|: divergence
MAX_SUBSTEPS = 20000        # max_gap / sample_time: the longest bridge of one gap
MAX_BRIDGE_S = 0.25         # default max_bridge: longest gap bridged by time updates (s)
MAX_COMMAND_AGE_S = 1.0     # s, a command in force older than this (at most max_gap) is stale

# frame-id tokens that name a convention
_FRAME_TOKENS = {'ned': 'ned', 'frd': 'ned', 'enu': 'enu', 'flu': 'enu'}

# Health rule (see IdentSession.health)
NIS_WINDOW = 200          # updates in the running NIS window (10 s at 20 Hz)
NIS_BAND_PROB = 0.999     # two-sided chi-square band of the window's mean NIS per dof
CONVERGED_REL_STD = 0.05  # 'converged' needs every coefficient's 1-sigma below 5 % of |estimate|
GROSS_NIS_FACTOR = 10.0   # mean NIS/dof above 10x the band's upper edge: ERROR

@dataclass
class Event:
    """What one message did.

    kind : 'update' (odometry fused), 'command' (actuators buffered), 'rejected' (dropped, see
        reason) or 'error' (a core error or a divergence-guard reset; the filter was reset by
        the rule of the module docstring, see reason)
    reason : why rejected / the error text / a note on an accepted update ('' if none),
        prefixed with the topic ('odom: ', 'actuators: ')
    stamp_ns : header stamp of the message (None if it could not be read)
    estimate, std : (p,) after an update; cov : (p, p); nis, dof : of this update
    code : short category of a rejection, error or note ('non-finite', 'outlier', 'gap',
        'repaired', 'guard', ...; '' for a plain update or command)
    good : an update that became the last good estimate (the node publishes only these)
    """

    kind: str
    reason: str = ''
    stamp_ns: object = None
    estimate: object = None
    std: object = None
    cov: object = None
    nis: float = math.nan
    dof: int = 0
    code: str = ''
    good: bool = False

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
    max_gap : s, a longer gap restarts the vehicle states (coefficients kept); also the
        horizon of backward time jumps and stale commands (core/stream.py)
    max_bridge : s, longest gap between odometry stamps bridged by time updates; a longer one
        restarts the vehicle states too (0 or None: MAX_BRIDGE_S = 0.25 s, at least one
        sample time, at most max_gap; see core/stream.py for why)
    mass_inverse : 'default', 'exact' or 'mss_literal'
    warm_start : '' or an estimate JSON path (start from its estimate and covariance)
    keep_arrays : keep every command and accepted measurement (for :func:`replay_bag`'s arrays)
    """

    def __init__(self, vehicle='nps_auv2', coefficients=(), initial=(), initial_offset=0.5,
                 noise_mode='fixed', tau=10.0, lam=2e-3, noise_std=None, q_state=None,
                 p0_rel=1.0, q_theta_rel=1e-5, measured=(), frame='ned', sample_time=0.05,
                 max_gap=5.0, mass_inverse='default', warm_start='', keep_arrays=False,
                 max_bridge=None):
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
        if T > 1.0:
            raise ParameterError('sample_time', f'{sample_time!r} s is longer than 1 s: one RK4 '
                                                'step of the model over it is not a faithful '
                                                'integration (use the sensor sample time)')
        max_gap = _positive('max_gap', max_gap)
        if max_gap < T:
            raise ParameterError('max_gap', f'{max_gap!r} s is shorter than sample_time '
                                            f'({T!r} s): every sample would restart the states')
        if max_bridge is None or max_bridge == 0:
            max_bridge = MAX_BRIDGE_S
        max_bridge = _positive('max_bridge', max_bridge)
        self.max_bridge = min(max(max_bridge, T), max_gap)
        if max_gap / T > MAX_SUBSTEPS:
            raise ParameterError('max_gap', f'{max_gap!r} s is more than {MAX_SUBSTEPS} '
                                            f'sample times ({T!r} s): one gap would take '
                                            'that many time updates')
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
                                measured=mask, mode=noise_mode, tau=float(tau), lam=float(lam),
                                theta_cov0=self.warm_cov)
        self.T = T
        self.max_gap = max_gap
        self.names = canon
        self.measured = mask
        self.keep_arrays = keep_arrays
        self.commands = []          # (t, u6) in arrival order, if keep_arrays
        self.measurements = []      # (t, y12) of accepted updates, if keep_arrays
        self.gate = None
        if noise_mode != 'paper':
            from scipy.stats import chi2
            self.gate = np.array([math.inf] + [OUTLIER_GATE_FACTOR
                                               * chi2.ppf(1.0 - OUTLIER_P, m)
                                               for m in range(1, 13)])
        try:
            self.stream = self._new_stream()
        except ConfigError as err:  # what the checks above did not catch
            raise ParameterError('initial', str(err)) from None
        self.theta0 = self.stream.ekf.theta0.copy()
        self.blowup_std = COV_BLOWUP_FACTOR * self.cfg.p0_rel * np.abs(self.theta0)
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
        self._since_error = None    # updates since the last reset (None: no reset yet)
        self._nis = deque(maxlen=NIS_WINDOW)
        self._nis_sum = None        # cached (sum NIS, sum dof) of _nis
        # divergence guard
        self.guard = noise_mode != 'paper'
        self.outliers = 0
        self.repairs = 0
        self.guard_resets = 0
        self.time_jumps = 0
        self._guard = deque(maxlen=GUARD_WINDOW)
        self._guard_since = None    # stamp (s) since which the guard window is inconsistent
        self._after_reset = False   # a fault reset, and the guard window not yet full since
        self._reset_from_good = False   # the last reset started from last_good, none good since
        self._band_cache = {}
        self._frame_ids = None      # (frame_id, child_frame_id) of the first accepted odometry
        v = self.vehicle.par
        self.fin_bound = FIN_LIMIT_FACTOR * float(v[P_FIN])
        self.shaft_bound = SHAFT_LIMIT_FACTOR * float(v[P_NMAX])

    # -- filter lifecycle --

    def _new_stream(self, keep_commands_from=None, start_from=None):
        """A fresh StreamIdentifier: from the start-up configuration, or (start_from, a
        LastGood) from that estimate with its covariance times RESET_COV_INFLATION."""
        s = StreamIdentifier(self.model, self.cfg, self.T, self.max_gap, gate=self.gate,
                             max_bridge=self.max_bridge,
                             max_command_age=min(MAX_COMMAND_AGE_S, self.max_gap))
        if start_from is not None:
            s.ekf.set_prior(start_from.estimate,
                            RESET_COV_INFLATION * np.asarray(start_from.cov, float))
        if keep_commands_from is not None:
            s.copy_commands_from(keep_commands_from)
        return s

    def _clear_windows(self):
        self._nis.clear()
        self._nis_sum = None
        self._guard.clear()
        self._guard_since = None

    def reset(self):
        """Restart the filter from the start-up configuration (the ~/reset service): buffered
        commands, counters and the last good estimate are kept; the frame ids are forgotten."""
        self.stream = self._new_stream(keep_commands_from=self.stream)
        self._frame_ids = None
        self._clear_windows()

    def recover(self, reason, stamp_ns=None):
        """Apply the reset rule after an unexpected error outside the core (the node's last
        resort); returns the 'error' Event."""
        return self._fault_reset('internal error', reason, stamp_ns)

    def _fault_reset(self, code, reason, stamp_ns):
        """The reset rule (module docstring): vehicle states from the next measurement,
        coefficients from the last good estimate with inflated covariance."""
        self.errors += 1
        self.last_error = reason
        self._since_error = 0
        start_from = self.last_good
        if start_from is not None:
            with np.errstate(all='ignore'):
                usable = is_positive_definite(RESET_COV_INFLATION * start_from.cov)
            if not usable or (code == 'core error' and self._reset_from_good):
                start_from = None       # the last good estimate may be the problem
        self._reset_from_good = start_from is not None
        self.stream = self._new_stream(keep_commands_from=self.stream, start_from=start_from)
        self._clear_windows()
        self._after_reset = self.guard
        start = ('the last good estimate (covariance x '
                 f'{RESET_COV_INFLATION:g})' if start_from is not None
                 else 'the start-up configuration')
        return Event('error', f'odom: {reason} (filter reset: vehicle states from the next '
                              f'measurement, coefficients from {start})', stamp_ns, code=code)

    def warm_up(self):
        """Run a throwaway copy of the filter over three synthetic trim samples, so numba
        loads (or, with a stale cache, compiles: ~15 s) the EKF before real data arrive."""
        from auv_ident.core.trim import initial_state
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

    def best(self):
        """(estimate, covariance) to report: the last good one, else current()."""
        if self.last_good is not None:
            return self.last_good.estimate.copy(), self.last_good.cov.copy()
        return self.current()

    def current(self):
        """(estimate, covariance) now: the filter's, the last good one, or the prior."""
        f = self.stream.ekf
        if f.xa is not None:
            return f.theta, f.theta_cov
        if self.last_good is not None:
            return self.last_good.estimate.copy(), self.last_good.cov.copy()
        return self.theta0.copy(), self.stream.ekf.theta_cov0.copy()

    def document(self):
        """The estimate file's dict of the best estimate (the last good one, else the prior)."""
        est, cov = self.best()
        stamp = self.last_good.stamp_ns if self.last_good is not None else None
        return estimate_document(self.vehicle.name, self.names, est, cov, stamp,
                                 self.odom_accepted)

    # -- messages --

    def _reject(self, what, code, reason, stamp_ns=None):
        if what == 'odom':
            self.odom_rejected += 1
        else:
            self.cmd_rejected += 1
            if stamp_ns is not None and code != 'zero stamp':
                self.stream.command_rejected(stamp_ns / NS_PER_S)
        self.reasons[f'{what}: {code}'] += 1
        return Event('rejected', f'{what}: {reason}', stamp_ns, code=code)

    def on_actuators(self, msg):
        """Buffer a sensor_msgs/JointState actuator command. Returns an Event."""
        stamp_ns = _stamp_ns(msg)
        try:
            t, u6 = joint_state_to_actuators(msg)
        except ConversionError as err:
            return self._reject('actuators', 'conversion', str(err), stamp_ns)
        if not np.all(np.isfinite(u6)):
            return self._reject('actuators', 'non-finite',
                                f'non-finite command {u6.tolist()} at {t:.9f} s', stamp_ns)
        fins = np.abs(u6[:5]) > self.fin_bound
        if np.any(fins):
            bad = ', '.join(f'{n} = {u6[i]:.6g} rad' for i, n in enumerate(JOINT_NAMES[:5])
                            if fins[i])
            return self._reject('actuators', 'implausible',
                                f'implausible fin angle(s) {bad} at {t:.9f} s: beyond '
                                f'{FIN_LIMIT_FACTOR:g}x the '
                                f'{self.fin_bound / FIN_LIMIT_FACTOR:.4g} rad limit (degrees '
                                'given as radians?)', stamp_ns)
        if abs(u6[5]) > self.shaft_bound:
            return self._reject('actuators', 'implausible',
                                f'implausible shaft speed {u6[5]:.6g} rpm at {t:.9f} s: beyond '
                                f'{SHAFT_LIMIT_FACTOR:g}x the '
                                f'{self.shaft_bound / SHAFT_LIMIT_FACTOR:.6g} rpm limit (rpm '
                                'written into the rad/s velocity field?)', stamp_ns)
        out = self.stream.add_command(t, u6)
        if not out.accepted:
            return self._reject('actuators', out.code, out.reason, stamp_ns)
        if self.keep_arrays:
            self.commands.append((t, u6))
        self.cmd_accepted += 1
        return Event('command', '', stamp_ns)

    def _frame_problem(self, msg):
        """(code, text) if the odometry's frame ids contradict the frame parameter or the
        stream's first frame ids, else None."""
        fid = str(getattr(msg.header, 'frame_id', ''))
        cid = str(getattr(msg, 'child_frame_id', ''))
        named = set()
        for text in (fid, cid):
            for token in re.split(r'[^a-z0-9]+', text.lower()):
                if token in _FRAME_TOKENS:
                    named.add(_FRAME_TOKENS[token])
        if named and named != {self.frame}:
            return 'wrong frame', (f'frame ids {fid!r} / {cid!r} name the '
                                   f'{"/".join(sorted(n.upper() for n in named))} convention, '
                                   f'but the frame parameter is {self.frame!r}')
        if self._frame_ids is not None and (fid, cid) != self._frame_ids:
            return 'frame changed', (f'frame ids {fid!r} / {cid!r} differ from '
                                     f'{self._frame_ids[0]!r} / {self._frame_ids[1]!r} of the '
                                     'first accepted odometry')
        return None

    def _implausible(self, y):
        """Text naming the measured channels beyond the plausibility bounds, or ''."""
        bad = np.abs(np.nan_to_num(y, nan=0.0)) > _STATE_BOUNDS
        if not np.any(bad):
            return ''
        return 'implausible ' + ', '.join(
            f'{STATE_NAMES[i]} = {y[i]:.6g} {_STATE_UNITS[i]} (|{STATE_NAMES[i]}| <= '
            f'{_STATE_BOUNDS[i]:g})' for i in np.flatnonzero(bad)) + ' (wrong units or frame?)'

    def _band_hi(self, D):
        hi = self._band_cache.get(D)
        if hi is None:
            from scipy.stats import chi2
            hi = float(chi2.ppf(0.5 * (1.0 + NIS_BAND_PROB), D) / D)
            self._band_cache[D] = hi
        return hi

    def guard_median(self):
        """Median NIS/dof over the guard window (outliers included); NaN if empty. The median:
        a burst of outliers shorter than half the window does not move it."""
        if not self._guard:
            return math.nan
        return float(np.median([n / d for n, d in self._guard]))

    def guard_inconsistent(self):
        """True if the guard window is full and its median NIS/dof is above GUARD_FACTOR."""
        if not self.guard or len(self._guard) < GUARD_WINDOW:
            return False
        return self.guard_median() > GUARD_FACTOR

    def _guard_step(self, t, nis, dof):
        """Feed the guard; returns True when the inconsistency has lasted GUARD_SECONDS."""
        if not self.guard or dof <= 0:
            return False
        self._guard.append((float(nis) if math.isfinite(nis) else 1e300, int(dof)))
        if not self.guard_inconsistent():
            self._guard_since = None
            return False
        if self._guard_since is None or t < self._guard_since:
            self._guard_since = t
        return t - self._guard_since >= GUARD_SECONDS

    def on_odom(self, msg):
        """Fuse a nav_msgs/Odometry measurement. Returns an Event."""
        stamp_ns = _stamp_ns(msg)
        try:
            t, x12, _, _ = odometry_to_state(msg, self.frame)
        except ConversionError as err:
            return self._reject('odom', 'conversion', str(err), stamp_ns)
        problem = self._frame_problem(msg)
        if problem is not None:
            return self._reject('odom', problem[0], f'{problem[1]} at {t:.9f} s', stamp_ns)
        y = np.where(self.measured, x12, np.nan)
        bad = self.measured & ~np.isfinite(x12)
        if np.any(bad):
            return self._reject('odom', 'non-finite', 'non-finite field(s) '
                                + ', '.join(STATE_NAMES[i] for i in np.flatnonzero(bad))
                                + f' at {t:.9f} s', stamp_ns)
        text = self._implausible(y)
        if text:
            return self._reject('odom', 'implausible', f'{text} at {t:.9f} s', stamp_ns)
        f = self.stream.ekf
        try:
            out = self.stream.add_measurement(t, y)
            if out.accepted:
                f = self.stream.ekf
                est, cov = f.theta, f.theta_cov
                d = np.diag(cov)
                if not (np.all(np.isfinite(est)) and is_positive_definite(cov)
                        and np.all(d > 0)):
                    raise DivergenceError(f'non-finite or non-positive-definite coefficient '
                                          f'covariance after the update at {t:.9f} s')
                blown = np.sqrt(d) > self.blowup_std
                if np.any(blown):
                    raise DivergenceError(
                        'coefficient covariance blew up: 1-sigma of ' + ', '.join(
                            f'{self.names[i]} = {math.sqrt(d[i]):.3g}'
                            for i in np.flatnonzero(blown)) + f' above {COV_BLOWUP_FACTOR:g}x '
                        f'its prior (p0_rel |initial guess|) at {t:.9f} s')
        except (DomainError, DivergenceError) as err:
            return self._fault_reset('core error', f'{type(err).__name__}: {err}', stamp_ns)
        fused = out.code in ('', 'repaired', 'outlier')     # an update was computed
        if out.code == 'repaired':
            self.repairs += 1
        elif out.code == 'time jump':
            self.time_jumps += 1
        sustained = fused and self._guard_step(t, f.nis, f.dof)
        if not out.accepted:
            if out.code == 'outlier':
                self.outliers += 1
            ev = self._reject('odom', out.code, out.reason, stamp_ns)
            if sustained:
                return self._guard_reset(t, stamp_ns)
            return ev
        self.odom_accepted += 1
        self.last_nis, self.last_dof = float(f.nis), int(f.dof)
        if fused and f.dof > 0 and math.isfinite(f.nis):
            self._nis.append((float(f.nis), int(f.dof)))
            self._nis_sum = None
        if self._since_error is not None:
            self._since_error += 1
        if self.keep_arrays:
            self.measurements.append((t, y))
        if sustained:
            return self._guard_reset(t, stamp_ns)
        std = np.sqrt(d)
        if (self._after_reset and len(self._guard) >= GUARD_WINDOW
                and self.guard_median() <= GUARD_PROBATION):
            self._after_reset = False
        gross = self.gross_inconsistency()
        good = self._guard_since is None and not self._after_reset and not gross
        if good:
            self._reset_from_good = False
            self.last_good = LastGood(stamp_ns, est, std, cov)
            if self._frame_ids is None:
                self._frame_ids = (str(getattr(msg.header, 'frame_id', '')),
                                   str(getattr(msg, 'child_frame_id', '')))
        reason = f'odom: {out.reason}' if out.reason else ''
        if not good:
            if self._guard_since is not None:
                why = (f'innovations inconsistent since {self._guard_since:.3f} s (guard '
                       f'median NIS/dof {self.guard_median():.4g})')
            elif self._after_reset:
                why = (f'probation after the filter reset ({len(self._guard)} of '
                       f'{GUARD_WINDOW} updates, median NIS/dof {self.guard_median():.4g}, '
                       f'needs <= {GUARD_PROBATION:g})')
            else:
                why = (f'mean NIS/dof {self.mean_nis_per_dof():.4g} over the last '
                       f'{len(self._nis)} updates is more than {GROSS_NIS_FACTOR:g}x its '
                       'chi-square band')
            reason = ('odom: ' + (out.reason + '; ' if out.reason else '') + why
                      + ': not taken as good')
        return Event('update', reason, stamp_ns, est, std, cov, float(f.nis), int(f.dof),
                     code='guard' if not good else out.code, good=good)

    def _guard_reset(self, t, stamp_ns):
        self.guard_resets += 1
        m = self.guard_median()
        return self._fault_reset('guard', f'innovations inconsistent for '
                                          f'{t - self._guard_since:.3f} s (median NIS/dof '
                                          f'{m:.4g} over the last {len(self._guard)} updates, '
                                          f'above {GUARD_FACTOR:g})', stamp_ns)

    # -- health --

    def _nis_sums(self):
        if self._nis_sum is None:
            self._nis_sum = (math.fsum(n for n, _ in self._nis), sum(d for _, d in self._nis))
        return self._nis_sum

    def mean_nis_per_dof(self):
        if not self._nis:
            return math.nan
        total, dof = self._nis_sums()
        return float(total / dof)

    def gross_inconsistency(self):
        """True if the health window's mean NIS/dof is above GROSS_NIS_FACTOR x the upper edge
        of its band (what health() reports as ERROR 'diverging'); such updates are not good."""
        if not self.guard or len(self._nis) < GUARD_WINDOW:
            return False
        total, dof = self._nis_sums()
        return total / dof > GROSS_NIS_FACTOR * self._band_hi(int(dof))

    def health(self):
        """Judge the filter (the rule the /diagnostics status reports).

        Over the last NIS_WINDOW (200) updates, m = sum(NIS) / sum(dof) and the
        chi-square band [lo, hi] of m for D = sum(dof) degrees of freedom (two-sided 99.9 %:
        windows overlap, so a 99 % band would blip WARN now and then on a healthy filter):

        - a filter reset (core error or divergence guard) and fewer than NIS_WINDOW updates
          since: ERROR 'diverging';
        - no update since start or restart: WARN 'waiting for data';
        - the divergence guard's window inconsistent now (see the module docstring), or
          m > 10 hi: ERROR 'diverging';
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
        if self.guard_inconsistent() or (n and m > GROSS_NIS_FACTOR * band[1]):
            return Health('ERROR', 'diverging', m, band, n)
        full = n >= NIS_WINDOW
        if full and m > band[1]:
            return Health('WARN', 'diverging', m, band, n)
        est, cov = self.current()
        with np.errstate(divide='ignore', invalid='ignore'):
            rel = np.sqrt(np.clip(np.diag(cov), 0.0, None)) / np.abs(est)
        if full and np.all(rel < CONVERGED_REL_STD):
            return Health('OK', 'converged', m, band, n)
        return Health('OK', 'converging', m, band, n)

def _stamp_ns(msg):
    try:
        return stamp_to_ns(msg.header.stamp)
    except (AttributeError, TypeError, ValueError):
        return None
