"""The identifier's per-message logic, without a ROS graph: :class:`IdentSession`.

:class:`IdentSession` is everything the identifier node does per message, minus ROS. Its
array API takes what a message says as plain arrays and stamps:

- :meth:`IdentSession.add_command` ``(stamp_ns, u6)``: an actuator command, fins (rad) and
  shaft speed (rpm) in the layout of core/model/state.py's ``Input``;
- :meth:`IdentSession.add_odometry` ``(stamp_ns, x12, frame_id, child_frame_id)``: a
  measured state ``[u v w p q r x y z phi theta psi]`` in NED/FRD (as
  :func:`auv_ident.session.messages.odometry_to_state` returns it) with the message's frame
  ids;

and :meth:`IdentSession.on_actuators` / :meth:`IdentSession.on_odom` are thin adapters that
read sensor_msgs/JointState and nav_msgs/Odometry objects (rclpy or rosbags, duck-typed, with
:mod:`auv_ident.session.messages`) and call the same code, a message that cannot be read being
rejected as ``conversion``. Each call returns an :class:`~auv_ident.session.guard.Event`.

Per message the session screens (rejection policy, frame-id and plausibility rules:
session/screening.py), feeds :class:`auv_ident.core.filter.stream.StreamIdentifier` (pairing with
commands, time rules), checks the estimate, runs the divergence guard and reset rule, keeps
the last good estimate and the health windows (session/guard.py). The identifier node
(``ros/identifier_node.py``) and :func:`auv_ident.offline.replay.replay_bag` both drive one
IdentSession with the messages in arrival (log-time) order, so the same message sequence
gives identical events and estimates online and offline. The estimate file (``~/save``,
``warm_start``) is session/estimate_file.py. With ``coefficients`` ['auto', ...] the session
also keeps the accepted messages of the first ``auto_window`` s and switches, once, to the set
chosen from them (session/auto_choice.py; :meth:`IdentSession.poll_choice`).
"""
from collections import Counter
import math

import numpy as np

from auv_ident.core.errors import AuvIdentError, ConfigError, DivergenceError, DomainError
from auv_ident.core.filter.augmented import DEFAULT_Q_STATE, FilterConfig
from auv_ident.core.filter.stream import StreamIdentifier
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.sensors import DEFAULT_NOISE_STD
from auv_ident.core.model.state import Input, N_INPUT, N_STATE, STATE_NAMES
from auv_ident.core.model.vehicle import P_FIN, P_NMAX
from auv_ident.session.auto_choice import AutoChoice, ChoiceJob
from auv_ident.session.estimate_file import estimate_document, load_estimate_json
from auv_ident.session.guard import (
    checked_coefficients,
    COV_BLOWUP_FACTOR,
    Event,
    FUSED_CODES,
    GROSS_NIS_FACTOR,
    GUARD_FACTOR,
    GUARD_PROBATION,
    GUARD_SECONDS,
    GUARD_WINDOW,
    GuardWindow,
    Health,
    innovation_gate,
    judge_health,
    LastGood,
    NisWindow,
    RESET_COV_INFLATION,
    reset_start,
)
from auv_ident.session.live_diagnosis import live_diagnosis, live_verdicts
from auv_ident.session.messages import (
    _as_vector,
    ConversionError,
    header_stamp_ns,
    integer_stamp,
    joint_state_to_actuators,
    NS_PER_S,
    odometry_state,
    odometry_variances,
)
from auv_ident.session.screening import (
    command_problem,
    frame_problem,
    implausible_states,
    nonfinite_states,
)
from auv_ident.session.settings import (
    coefficient_list,
    coefficient_request,
    IdentifierSettings,
    noise_model,
    ParameterError,
    vehicle_named,
)

# The records and the guard constants callers use come with the session.
__all__ = ['Event', 'GUARD_SECONDS', 'Health', 'IdentSession', 'LastGood']

# stamps from this on (~11.6 days after 1970) are wall-clock times: the session then counts
# time from the whole second of the first stamp (IdentSession docstring)
TIME_ORIGIN_MIN_NS = 10 ** 15


class IdentSession:
    """Online identification from arrays or ROS messages, ROS-graph-free (the node's
    per-message logic; module docstring).

    Parameters
    ----------
    settings : :class:`~auv_ident.session.settings.IdentifierSettings`, every identification
        setting, checked (its fields say each one's meaning, unit and default; build one from
        keywords with ``IdentifierSettings.from_values(vehicle='remus100', ...)``); None: the
        defaults. What needs the vehicle file (coefficient names, the warm-start file, the
        initial guesses) is checked here, a bad value raising :class:`ParameterError` naming it.
    keep_arrays : keep every command and accepted measurement (for :func:`replay_bag`'s arrays)
    auto_runner : work -> concurrent.futures.Future that runs the coefficients ['auto', ...]
        choice (auto_choice.py: run_inline, the default, or run_in_thread, the node's)

    The identified parameters (``names``) are the coefficients, then the estimated current
    components ('current_n', 'current_e'[, 'current_d']).

    Time: stamps are integer ns; the session works in seconds since a time origin, the whole
    second of the first stamp when stamps are wall-clock times (>= TIME_ORIGIN_MIN_NS), else 0,
    so that float seconds keep the stamps' ns resolution (an epoch-scale float second resolves
    only ~0.2 us). A zero stamp after stamps on a wall-clock origin is rejected as
    'zero stamp' (an unset header.stamp).
    """

    def __init__(self, settings=None, keep_arrays=False, auto_runner=None):
        settings = IdentifierSettings() if settings is None else settings
        self.settings = settings
        self.vehicle = vehicle_named(settings.vehicle)
        self.frame = settings.frame
        T, max_gap, self.max_bridge = settings.timing
        self.max_command_age = settings.command_age_limit
        self.noise_source = settings.noise_source
        noise, qs, mask = noise_model(settings.noise_std, settings.q_state, settings.measured,
                                      DEFAULT_NOISE_STD, DEFAULT_Q_STATE)
        # a planar vehicle's held states are not measurements (core/model/planar.py): their fields
        # are neither read nor screened, whatever an odometry message holds there
        mask = mask & self.vehicle.free_states
        auto, coefficients = coefficient_request(self.vehicle, settings.coefficients)
        warm_start = settings.warm_start
        if auto and warm_start:
            raise ParameterError('warm_start', "coefficients ['auto', ...] chooses the set from "
                                 'the data; a warm-start file fixes it: give one or the other')
        warm = load_estimate_json(warm_start) if warm_start else None
        canon, init, self.warm_cov = coefficient_list(self.vehicle, coefficients,
                                                      settings.initial, warm_start, warm)
        self.current_option = settings.current_option
        self.velocity_reference = settings.velocity_reference
        self._mass_inverse = settings.mass_inverse
        try:
            self.model = self._model_of(canon)
        except ConfigError as err:
            raise ParameterError('mass_inverse', str(err)) from None

        self.cfg = FilterConfig(coefficients=canon, initial=init,
                                initial_offset=settings.initial_offset, p0_rel=settings.p0_rel,
                                q_theta_rel=settings.q_theta_rel, q_state=qs, noise_std=noise,
                                measured=mask, mode=settings.noise_mode, tau=settings.tau,
                                lam=settings.lam, theta_cov0=self.warm_cov,
                                current_sd0=settings.current_sd0,
                                current_walk=settings.current_walk)
        self.T = T
        self.max_gap = max_gap
        self.names = list(self.model.theta_names)
        self.coefficient_names = canon
        self.measured = mask
        self._measured_states = tuple(int(i) for i in np.flatnonzero(mask))
        self._all_measured = bool(mask.all())
        self.keep_arrays = keep_arrays
        self.commands = []          # (t, u6) in arrival order, if keep_arrays
        self.measurements = []      # (t, y12) of accepted updates, if keep_arrays
        self.variances = []         # (12,) R diagonal used by each accepted update, if kept
        self.time_origin_ns = None  # stamps are taken relative to this (class docstring)
        self.notices = []           # one-time notes for the caller to log (then clear)
        self._fallback_noted = set()
        self.noise_default = np.asarray(noise, dtype=float) ** 2    # R diagonal of noise_std
        self._R_now = self.noise_default.copy()
        self.guard_on = settings.noise_mode != 'paper'   # the divergence guard (session/guard.py)
        self.gate = innovation_gate() if self.guard_on else None
        try:
            self.stream = self._new_stream()
        except ConfigError as err:  # what the checks above did not catch
            raise ParameterError('initial', str(err)) from None
        self.theta0 = self.stream.ekf.theta0.copy()
        self.blowup_std = COV_BLOWUP_FACTOR * self.stream.ekf.prior_scale
        self._blowup_std = self.blowup_std.tolist()
        v = self.vehicle.par
        self.fin_limit = float(v[P_FIN])        # rad
        self.shaft_limit = float(v[P_NMAX])     # rpm
        # counters (the node's /diagnostics)
        self.odom_accepted = 0
        self.odom_rejected = 0
        self.cmd_accepted = 0
        self.cmd_rejected = 0
        self.errors = 0
        self.last_error = ''
        self.reasons = Counter()
        self.outliers = 0
        self.repairs = 0
        self.guard_resets = 0
        self.time_jumps = 0
        self.last_good = None
        self.last_nis = math.nan
        self.last_dof = 0
        self._since_error = None    # updates since the last reset (None: no reset yet)
        self._nis_window = NisWindow()      # the health window
        self._guard_window = GuardWindow()  # the divergence guard's window
        self._after_reset = False   # a fault reset, and the guard window not yet full since
        self._reset_from_good = False   # the last reset started from last_good, none good since
        self._frame_ids = None      # (frame_id, child_frame_id) of the first accepted odometry
        # coefficients ['auto', ...]: the live choice (None: the set is fixed)
        self.auto = (AutoChoice(coefficients, settings.auto_window, auto_runner) if auto
                     else None)

    def _model_of(self, coefficients):
        """The Model identifying these coefficients with the session's current settings."""
        return Model(self.vehicle, list(coefficients) + self.current_option.names,
                     mass_inverse=self._mass_inverse, current=self.current_option.fixed,
                     velocity_reference=self.velocity_reference)

    # -- filter lifecycle --

    def _new_stream(self, keep_commands_from=None, start_from=None):
        """A fresh StreamIdentifier: from the start-up configuration, or (start_from, a
        LastGood) from that estimate with its covariance times RESET_COV_INFLATION."""
        s = StreamIdentifier(self.model, self.cfg, self.T, self.max_gap, gate=self.gate,
                             max_bridge=self.max_bridge, max_command_age=self.max_command_age)
        if start_from is not None:
            s.ekf.set_prior(start_from.estimate,
                            RESET_COV_INFLATION * np.asarray(start_from.cov, float))
        if keep_commands_from is not None:
            s.copy_commands_from(keep_commands_from)
        return s

    def _clear_windows(self):
        self._nis_window.clear()
        self._guard_window.clear()

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
        """The reset rule (session/guard.py): vehicle states from the next measurement,
        coefficients from the last good estimate with inflated covariance."""
        self.errors += 1
        self.last_error = reason
        self._since_error = 0
        start_from = reset_start(self.last_good, code, self._reset_from_good)
        self._reset_from_good = start_from is not None
        self.stream = self._new_stream(keep_commands_from=self.stream, start_from=start_from)
        self._clear_windows()
        self._after_reset = self.guard_on
        start = ('the last good estimate (covariance x '
                 f'{RESET_COV_INFLATION:g})' if start_from is not None
                 else 'the start-up configuration')
        return Event('error', f'odom: {reason} (filter reset: vehicle states from the next '
                              f'measurement, coefficients from {start})', stamp_ns, code=code)

    def warm_up(self):
        """Run a throwaway copy of the filter over three synthetic trim samples, so numba
        loads (or, with a stale cache, compiles: ~15 s) the EKF before real data arrive."""
        from auv_ident.core.model.trim import initial_state
        try:
            s = StreamIdentifier(self.model, self.cfg, self.T, self.max_gap)
            rpm = float(self.vehicle.cruise_rpm)
            x0 = initial_state(self.model, rpm)
            u0 = np.zeros(N_INPUT)
            u0[Input.N_RPM] = rpm
            u0[Input.THRUST] = self.vehicle.cruise_thrust     # the trim's (0 for an AUV)
            s.add_command(0.0, u0)
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
        doc = estimate_document(self.vehicle.name, self.names, est, cov, stamp,
                                self.odom_accepted)
        if self.auto is not None:
            doc['selection'] = self.auto.document()
        return doc

    # -- coefficients ['auto', ...] (session/auto_choice.py) --

    def _start_choice(self):
        """The window is full: hand the choice to the runner, with a snapshot of what it
        needs (it may run in another thread; it reads nothing the session changes)."""
        running = {}
        if self.last_good is not None:
            running = dict(zip(self.coefficient_names, self.last_good.estimate.tolist()))
        auto = self.auto
        auto.start(ChoiceJob(
            make_model=self._model_of, cfg=self.cfg, named=auto.named, running=running,
            entries=list(auto.kept), noise_variances=self.noise_default, T=self.T,
            max_gap=self.max_gap, gate=self.gate, max_bridge=self.max_bridge,
            max_command_age=self.max_command_age, guard_on=self.guard_on))
        # not switched here even if the runner has finished (inline): the message being
        # handled is the running filter's to the end; the next one (or poll_choice) switches

    def poll_choice(self):
        """Switch to the chosen set if the choice has finished (auto_choice.py, step 3), or
        record its failure. Called before every message; the node also calls it from its
        timer. Returns True if the state changed (chosen or failed)."""
        auto = self.auto
        if auto is None or not auto.running:
            return False
        try:
            result = auto.finished()
        except Exception as err:                 # noqa: BLE001 - the running set stays
            auto.fail(err)
            return True
        if result is None:
            return False
        f = result.chosen_filter
        self.model, self.cfg, self.stream = result.model, result.cfg, f.stream
        self.names = list(self.model.theta_names)
        self.coefficient_names = list(result.selection.chosen)
        self.theta0 = self.stream.ekf.theta0.copy()
        self.blowup_std = COV_BLOWUP_FACTOR * self.stream.ekf.prior_scale
        self._blowup_std = self.blowup_std.tolist()
        self._nis_window, self._guard_window = f.nis_window, f.guard_window
        self.last_good, self.warm_cov = f.last_good, None
        # the resets and probation were the running filter's; the chosen one had none
        self._since_error, self._after_reset, self._reset_from_good = None, False, False
        self.last_nis, self.last_dof = float(self.stream.ekf.nis), int(self.stream.ekf.dof)
        auto.chose(result, None if f.last_good is None else f.last_good.stamp_ns)
        return True

    # -- the array API --

    def add_command(self, stamp_ns, u6):
        """Buffer an actuator command. Returns an Event.

        stamp_ns : int, header stamp (ns)
        u6 : (7,) fins (rad), shaft speed (rpm) and thrust (N), core/model/state.py ``Input``
            order; copied
        """
        try:
            stamp_ns = integer_stamp(stamp_ns)
        except ConversionError as err:
            return self._reject('actuators', 'conversion', str(err))
        try:
            u6 = _as_vector(u6, N_INPUT, 'u6').copy()
        except ConversionError as err:
            return self._reject('actuators', 'conversion', str(err), stamp_ns)
        return self._command(stamp_ns, u6)

    def add_odometry(self, stamp_ns, x12, frame_id='', child_frame_id='', variances=None):
        """Fuse an odometry sample. Returns an Event.

        stamp_ns : int, header stamp (ns)
        x12 : (12,) ``[u v w p q r x y z phi theta psi]`` (m/s, rad/s, m, rad) in NED/FRD,
            as :func:`auv_ident.session.messages.odometry_to_state` returns it; only the
            measured channels are read (the rest may be NaN); copied
        frame_id, child_frame_id : the message's frame ids, for the frame-id rule ('': none)
        variances : (12,) the variances the message states for x12's channels (state units
            squared; :func:`auv_ident.session.messages.odometry_variances`), or None; used with
            noise_source 'message' where finite and positive
        """
        try:
            stamp_ns = integer_stamp(stamp_ns)
        except ConversionError as err:
            return self._reject('odom', 'conversion', str(err))
        try:
            x12 = _as_vector(x12, N_STATE, 'x12').copy()
        except ConversionError as err:
            return self._reject('odom', 'conversion', str(err), stamp_ns)
        if variances is not None:
            try:
                variances = _as_vector(variances, N_STATE, 'variances')
            except ConversionError as err:
                return self._reject('odom', 'conversion', str(err), stamp_ns)
        return self._odometry(stamp_ns, x12, str(frame_id), str(child_frame_id), variances)

    # -- the message adapters --

    def on_actuators(self, msg):
        """Buffer a sensor_msgs/JointState actuator command. Returns an Event."""
        stamp_ns = None
        try:
            stamp_ns = header_stamp_ns(msg)
            _, u6 = joint_state_to_actuators(msg)
        except ConversionError as err:
            return self._reject('actuators', 'conversion', str(err), stamp_ns)
        return self._command(stamp_ns, u6)

    def on_odom(self, msg):
        """Fuse a nav_msgs/Odometry measurement (in the `frame` convention). Returns an Event."""
        stamp_ns = None
        try:
            stamp_ns = header_stamp_ns(msg)
            _, x12 = odometry_state(msg, self.frame)
        except ConversionError as err:
            return self._reject('odom', 'conversion', str(err), stamp_ns)
        variances = (odometry_variances(msg, self.frame) if self.noise_source == 'message'
                     else None)
        return self._odometry(stamp_ns, x12, str(getattr(msg.header, 'frame_id', '')),
                              str(getattr(msg, 'child_frame_id', '')), variances)

    # -- what one message does --

    def _reject(self, what, code, reason, stamp_ns=None):
        if what == 'odom':
            self.odom_rejected += 1
        else:
            self.cmd_rejected += 1
            if stamp_ns is not None and code != 'zero stamp':
                t = self._time(stamp_ns)
                self.stream.command_rejected(t)
                if self.auto is not None and self.auto.kept is not None:
                    self.auto.keep_command_rejected(t)
        self.reasons[f'{what}: {code}'] += 1
        return Event('rejected', f'{what}: {reason}', stamp_ns, code=code)

    def _time(self, stamp_ns):
        """A stamp (int ns) in seconds on the session's time line (class docstring)."""
        origin = self.time_origin_ns
        if origin is None:
            origin = (stamp_ns // NS_PER_S) * NS_PER_S if stamp_ns >= TIME_ORIGIN_MIN_NS else 0
            self.time_origin_ns = origin
        return (stamp_ns - origin) / NS_PER_S

    def _zero_stamp(self, what, stamp_ns):
        """The rejection of an unset stamp on a wall-clock time line, else None."""
        if stamp_ns == 0 and self.time_origin_ns:
            return self._reject(what, 'zero stamp', f'zero stamp after stamps from '
                                f'{self.time_origin_ns / NS_PER_S:.0f} s on (header.stamp '
                                'not set?)', stamp_ns)
        return None

    def _measurement_variances(self, variances):
        """The R diagonal for this message (noise_source 'message'): the message's variances
        where finite and positive, noise_std's elsewhere (noted once per channel)."""
        ok = np.isfinite(variances) & (variances > 0.0)
        missing = [STATE_NAMES[i] for i in self._measured_states
                   if not ok[i] and i not in self._fallback_noted]
        if missing:
            self._fallback_noted.update(STATE_NAMES.index(n) for n in missing)
            self.notices.append('odom: the message states no usable covariance (zero, -1 or '
                                f'not finite) for {", ".join(missing)}: noise_std used for '
                                'them (noise_source message)')
        return np.where(ok, variances, self.noise_default)

    def _use_variances(self, f, r):
        """Make r the measurement noise of filter f (fixed mode: R; adaptive modes: R0, the
        reference the adaptation starts from and is bounded by), and of its start-up
        covariance."""
        if f is getattr(self, '_R_filter', None) and np.array_equal(r, self._R_now):
            return
        f.use_measurement_variances(r)
        self._R_filter, self._R_now = f, r

    def _command(self, stamp_ns, u6):
        """add_command after reading: stamp_ns int, u6 a (7,) float array of our own."""
        if self.auto is not None and self.auto.running:
            self.poll_choice()
        zero = self._zero_stamp('actuators', stamp_ns)
        if zero is not None:
            return zero
        t = self._time(stamp_ns)
        problem = command_problem(u6.tolist(), t, self.fin_limit, self.shaft_limit)
        if problem is not None:
            return self._reject('actuators', problem[0], problem[1], stamp_ns)
        out = self.stream.add_command(t, u6)
        if not out.accepted:
            return self._reject('actuators', out.code, out.reason, stamp_ns)
        if self.keep_arrays:
            self.commands.append((t, u6))
        if self.auto is not None and self.auto.kept is not None:
            self.auto.keep_command(t, u6)
        self.cmd_accepted += 1
        return Event('command', '', stamp_ns)

    def _odometry(self, stamp_ns, x12, frame_id, child_frame_id, variances=None):
        """add_odometry after reading: stamp_ns int, x12 a (12,) float array of our own."""
        if self.auto is not None and self.auto.running:
            self.poll_choice()
        zero = self._zero_stamp('odom', stamp_ns)
        if zero is not None:
            return zero
        t = self._time(stamp_ns)
        problem = frame_problem(frame_id, child_frame_id, self.frame, self._frame_ids)
        if problem is not None:
            return self._reject('odom', problem[0], f'{problem[1]} at {t:.9f} s', stamp_ns)
        values = x12.tolist()
        bad = nonfinite_states(values, self._measured_states)
        if bad:
            return self._reject('odom', 'non-finite', f'non-finite field(s) {", ".join(bad)} '
                                                      f'at {t:.9f} s', stamp_ns)
        text = implausible_states(values, self._measured_states)
        if text:
            return self._reject('odom', 'implausible', f'{text} at {t:.9f} s', stamp_ns)
        y = x12 if self._all_measured else np.where(self.measured, x12, np.nan)
        stream = self.stream
        f = stream.ekf
        r = None
        if variances is not None:
            r = self._measurement_variances(variances)
            self._use_variances(f, r)
        try:
            out = stream.add_measurement(t, y)
            if out.accepted:
                est, cov, std = checked_coefficients(f, t, self.names, self._blowup_std)
        except (DomainError, DivergenceError) as err:
            return self._fault_reset('core error', f'{type(err).__name__}: {err}', stamp_ns)
        code = out.code
        fused = code in FUSED_CODES      # an update was computed
        if code == 'repaired':
            self.repairs += 1
        elif code == 'time jump':
            self.time_jumps += 1
        nis, dof = float(f.nis), int(f.dof)
        window = self._guard_window
        sustained = fused and self.guard_on and dof > 0 and window.add(t, nis, dof)
        if not out.accepted:
            if code == 'outlier':
                self.outliers += 1
            ev = self._reject('odom', code, out.reason, stamp_ns)
            if sustained:
                return self._guard_reset(t, stamp_ns)
            return ev
        self.odom_accepted += 1
        self.last_nis, self.last_dof = nis, dof
        if fused and dof > 0 and math.isfinite(nis):
            self._nis_window.add(nis, dof)
        if self._since_error is not None:
            self._since_error += 1
        if self.keep_arrays:
            self.measurements.append((t, y))
            self.variances.append(self.noise_default if r is None else r)
        auto = self.auto
        if (auto is not None and auto.kept is not None
                and auto.keep_odometry(t, stamp_ns, y, r, code)):
            self._start_choice()
        if sustained:
            return self._guard_reset(t, stamp_ns)
        if (self._after_reset and len(window) >= GUARD_WINDOW
                and window.median() <= GUARD_PROBATION):
            self._after_reset = False
        good = (window.since is None and not self._after_reset
                and not self.gross_inconsistency())
        if good:
            self._reset_from_good = False
            self.last_good = LastGood(stamp_ns, est, std, cov)
            if self._frame_ids is None:
                self._frame_ids = (frame_id, child_frame_id)
            return Event('update', f'odom: {out.reason}' if out.reason else '', stamp_ns, est,
                         std, cov, nis, dof, code, True)
        if window.since is not None:
            why = (f'innovations inconsistent since {window.since:.3f} s (guard median NIS/dof '
                   f'{window.median():.4g})')
        elif self._after_reset:
            why = (f'probation after the filter reset ({len(window)} of {GUARD_WINDOW} '
                   f'updates, median NIS/dof {window.median():.4g}, needs <= '
                   f'{GUARD_PROBATION:g})')
        else:
            why = (f'mean NIS/dof {self.mean_nis_per_dof():.4g} over the last '
                   f'{len(self._nis_window)} updates is more than {GROSS_NIS_FACTOR:g}x its '
                   'chi-square band')
        reason = 'odom: ' + (out.reason + '; ' if out.reason else '') + why + ': not taken as good'
        return Event('update', reason, stamp_ns, est, std, cov, nis, dof, 'guard', False)

    def _guard_reset(self, t, stamp_ns):
        self.guard_resets += 1
        window = self._guard_window
        return self._fault_reset('guard', f'innovations inconsistent for '
                                          f'{t - window.since:.3f} s (median NIS/dof '
                                          f'{window.median():.4g} over the last {len(window)} '
                                          f'updates, above {GUARD_FACTOR:g})', stamp_ns)

    # -- guard and health --

    def guard_median(self):
        """Median NIS/dof over the divergence guard's window (outliers included); NaN if
        empty."""
        return self._guard_window.median()

    def guard_inconsistent(self):
        """True if the divergence guard is on and its window is full and inconsistent."""
        return self.guard_on and self._guard_window.inconsistent()

    def mean_nis_per_dof(self):
        """Mean NIS per dof over the health window (NaN if empty)."""
        return self._nis_window.mean()

    def gross_inconsistency(self):
        """True if the health window's mean NIS/dof is above GROSS_NIS_FACTOR x the upper edge
        of its band (what health() reports as ERROR 'diverging'); such updates are not good.
        Judged once the window holds GUARD_WINDOW updates, with the divergence guard on."""
        window = self._nis_window
        return self.guard_on and len(window) >= GUARD_WINDOW and window.gross()

    def health(self):
        """The filter's health (session/guard.py judge_health: the /diagnostics status)."""
        est, cov = self.current()
        return judge_health(self._nis_window, self.guard_inconsistent(), self._since_error,
                            self.started, est, cov)

    def diagnosis(self, health=None):
        """(verdicts, diagnosis) of the running filter (session/live_diagnosis.py): per
        identified parameter its verdict from the best estimate's covariance against the
        prior, and {'consistent': True | False | None, 'messages': [...]}."""
        est, cov = self.best()
        prior_std = np.sqrt(np.diag(self.stream.ekf.theta_cov0))
        verdicts = live_verdicts(self.vehicle, self.names, est, cov, prior_std)
        diagnosis = live_diagnosis(self.health() if health is None else health, verdicts)
        if self.auto is not None:
            # while choosing or after a failure the set is provisional: that comes first
            line = self.auto.diagnosis_line(self.coefficient_names)
            diagnosis['messages'].insert(0 if self.auto.state != 'chosen' else 1, line)
        return verdicts, diagnosis

