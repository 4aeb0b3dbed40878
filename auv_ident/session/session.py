"""The identifier's per-message logic, without a ROS graph: :class:`IdentSession`.

:class:`IdentSession` is everything the identifier node does per message, minus ROS. Its
array API takes what a message says as plain arrays and stamps:

- :meth:`IdentSession.add_command` ``(stamp_ns, u7)``: an actuator command, fins (rad),
  shaft speed (rpm) and thrust (N) in the layout of core/model/state.py's ``Input``;
- :meth:`IdentSession.add_odometry` ``(stamp_ns, x12, frame_id, child_frame_id)``: a
  measured state ``[u v w p q r x y z phi theta psi]`` in NED/FRD (as
  :func:`auv_ident.session.messages.odometry_to_state` returns it) with the message's frame
  ids;

and :meth:`IdentSession.on_input` takes a message of an input of the input map (the
``input_map`` setting, session/input_map.py: by default the nav_msgs/Odometry ``odom`` and the
sensor_msgs/JointState ``actuators``; commands of any form through session/inputs.py, held on
change), :meth:`IdentSession.on_actuators` / :meth:`IdentSession.on_odom` the default layout's
two messages. They read the messages (rclpy or rosbags, duck-typed, with
:mod:`auv_ident.session.messages`) and call the same code, a message that cannot be read being
rejected as ``conversion``. Each call returns an :class:`~auv_ident.session.guard.Event`.
With noise_source 'message', a channel whose stated variance is at least
NOT_MEASURED_VARIANCE (1e6) is not measured by that message and is skipped.

Per message the session screens (rejection policy, frame-id and plausibility rules:
session/screening.py), then hands the odometry to its running filter,
:class:`~auv_ident.session.guarded_filter.GuardedFilter` (``IdentSession.filter``: the
measurement variances, :class:`auv_ident.core.filter.stream.StreamIdentifier`'s pairing with
commands and time rules, the estimate check, the divergence guard, the health window and the
last good estimate; the rules are session/guard.py's), applies the reset rule when the filter
reports a fault, and counts what happened (``IdentSession.counters``, session/status.py: the
/diagnostics counters and the health rule). The identifier node (``ros/identifier_node.py``)
and :func:`auv_ident.offline.replay.replay_bag` both drive one IdentSession with the messages
in arrival (log-time) order, so the same message sequence gives identical events and
estimates online and offline. The estimate file (``~/save``, ``warm_start``) is
session/estimate_file.py. With ``coefficients`` ['auto', ...] the session also keeps the
accepted messages of the first ``auto_window`` s and switches, once, to the set chosen from
them (session/auto_choice.py, whose chosen filter is a GuardedFilter too; the switch:
:meth:`IdentSession.poll_choice`).
"""
from dataclasses import replace

import numpy as np

from auv_ident.core.errors import AuvIdentError, ConfigError
from auv_ident.core.filter.augmented import DEFAULT_Q_STATE, FilterConfig
from auv_ident.core.filter.stream import StreamIdentifier
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.sensors import DEFAULT_NOISE_STD
from auv_ident.core.model.state import Input, N_STATE, STATE_NAMES
from auv_ident.core.model.vehicle import P_FIN, P_NMAX
from auv_ident.session.auto_choice import AutoChoice, ChoiceJob, failure_text, run_inline
from auv_ident.session.estimate_file import estimate_document, load_estimate_json
from auv_ident.session.guard import (
    Event,
    GUARD_FACTOR,
    GUARD_SECONDS,
    Health,
    innovation_gate,
    LastGood,
    RESET_COV_INFLATION,
)
from auv_ident.session.guarded_filter import FILTER_FAULTS, GuardedFilter
from auv_ident.session.input_map import InputMapError, load_input_map
from auv_ident.session.inputs import CommandHolder
from auv_ident.session.live_diagnosis import live_diagnosis, live_verdicts
from auv_ident.session.messages import (
    _as_vector,
    ConversionError,
    covariance_entry,
    header_stamp_ns,
    integer_stamp,
    joint_state_to_actuators,
    NOT_MEASURED_VARIANCE,
    NS_PER_S,
    odometry_state,
    odometry_variances,
)
from auv_ident.session.noise_learning import FUSED_OK, NoiseLearner, rerun
from auv_ident.session.record import Rows
from auv_ident.session.screening import (
    command_problem,
    frame_of_ids,
    implausible_variances,
    named_conventions,
    odometry_problem,
    PLAUSIBLE_VARIANCE_RATIO,
)
from auv_ident.session.settings import (
    coefficient_list,
    coefficient_request,
    IdentifierSettings,
    noise_model,
    ParameterError,
    vehicle_named,
)
from auv_ident.session.status import Counters, StampGaps
from auv_ident.session.stuck import describe_spans, StuckDetector

# The records and the guard constants callers use come with the session.
__all__ = ['Event', 'GUARD_SECONDS', 'Health', 'IdentSession', 'LastGood']

class InputMapSettingError(ParameterError, InputMapError):
    """The input_map setting names a map that is wrong or does not fit the vehicle."""


# stamps from this on (~11.6 days after 1970) are wall-clock times: the session then counts
# time from the whole second of the first stamp (IdentSession docstring)
TIME_ORIGIN_MIN_NS = 10 ** 15


# message variances below this fraction of noise_std's, while the guard resets: named as a
# likely cause (a DVL's or an INS's real 1-sigma is rarely 10x better than the documented level)
UNDERSTATED_VARIANCE = 1e-2


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
    filtering : False: screen the messages (the rules of session/screening.py, a repeated
        odometry stamp rejected as 'duplicate stamp') and keep them (keep_arrays implied) without
        filtering: no innovation gate, no guard, no resets, no 'auto' choice, no noise
        learning. A validation's measured run is read so (offline/replay.py read_bag_run): its
        samples are what the data are, none dropped because the model under test disagrees
        with them. Odometry then gives Events of kind 'kept'.
    auto_runner : work -> concurrent.futures.Future that runs the coefficients ['auto', ...]
        choice and the noise learning's re-runs (auto_choice.py: run_inline, the default, or
        run_in_thread, the node's)

    The identified parameters (``names``) are the coefficients, then the estimated current
    components ('current_n', 'current_e'[, 'current_d']).

    Time: stamps are integer ns; the session works in seconds since a time origin, the whole
    second of the first stamp when stamps are wall-clock times (>= TIME_ORIGIN_MIN_NS), else 0,
    so that float seconds keep the stamps' ns resolution (an epoch-scale float second resolves
    only ~0.2 us). A zero stamp after stamps on a wall-clock origin is rejected as
    'zero stamp' (an unset header.stamp).

    Parts: ``filter``, the running GuardedFilter (``stream``, ``last_good`` and ``theta0`` are
    its); ``counters``, the /diagnostics Counters (session/status.py); ``auto``, the
    AutoChoice of coefficients ['auto', ...] (None: the set is fixed).
    """

    def __init__(self, settings=None, keep_arrays=False, auto_runner=None, filtering=True):
        settings = IdentifierSettings() if settings is None else settings
        self.filtering = bool(filtering)
        keep_arrays = keep_arrays or not self.filtering
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
        # the input map (session/input_map.py): the topics, and the odometry's channels used
        try:
            self.input_map = load_input_map(settings.input_map)
            self.input_map.check_vehicle(self.vehicle)
            # thruster channels read into the vehicle's input vector (InputMap.for_vehicle)
            self.input_map = self.input_map.for_vehicle(self.vehicle)
            odom = self.input_map.odometry
            self.frame = self._map_frame(odom.frame)
        except InputMapError as err:
            raise InputMapSettingError('input_map', str(err)) from None
        mask = mask & np.isin(STATE_NAMES, odom.fields)
        self.holder = CommandHolder.of(self.input_map, self.vehicle)
        self._inputs = {e.name: e for e in self.input_map.inputs}
        self._multi_command = len(self.input_map.commands) > 1
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
        # if keep_arrays (record.Rows, compact: a replay keeps every message of a bag):
        self.commands = Rows(1 + self.vehicle.n_inputs)   # [t, u] in arrival order
        self.measurements = Rows(1 + N_STATE)       # [t, y12] of accepted updates
        self.variances = Rows(N_STATE)              # R diagonal used by each accepted update
        self.time_origin_ns = None  # stamps are taken relative to this (class docstring)
        self.notices = []           # one-time notes for the caller to log (then clear)
        self._fallback_noted = set()
        self._variances_seen = (b'', None)   # the last message variances' bytes and R (below)
        self.noise_default = np.asarray(noise, dtype=float) ** 2    # R diagonal of noise_std
        self.guard_on = settings.noise_mode != 'paper'   # the divergence guard (session/guard.py)
        self.gate = innovation_gate() if self.guard_on else None
        try:
            # the running filter under the per-message rule (session/guarded_filter.py)
            self.filter = GuardedFilter(self._new_stream(), self.guard_on)
        except ConfigError as err:  # what the checks above did not catch
            raise ParameterError('initial', str(err)) from None
        v = self.vehicle.par
        self.fin_limit = float(v[P_FIN])        # rad
        self.shaft_limit = float(v[P_NMAX])     # rpm
        self.counters = Counters()  # the node's /diagnostics counters (session/status.py)
        # odometry lost before it reached us, from the gaps in its stamps (status.StampGaps)
        self.odom_gaps = StampGaps(max_gap)
        # exact repeats of a measured channel group: not fed; a stuck sensor (session/stuck.py)
        self.stuck = StuckDetector(self._measured_states)
        self._frame_ids = None      # (frame_id, child_frame_id) of the first accepted odometry
        # coefficients ['auto', ...]: the live choice (None: the set is fixed)
        self.auto = (AutoChoice(coefficients, settings.auto_window, auto_runner)
                     if auto and self.filtering else None)
        self._kept_stamps = set()   # odometry stamps kept unfiltered (filtering False)
        # the noise model learnt from the innovations (session/noise_learning.py); not
        # without filtering (no filter, no innovations)
        self.noise = NoiseLearner(mask, T, settings.learn_noise and self.filtering
                                  and settings.noise_mode == 'fixed',
                                  n_inputs=self.vehicle.n_inputs)
        self._runner = run_inline if auto_runner is None else auto_runner

    def _map_frame(self, map_frame):
        """The odometry convention: the `frame` setting, or the map's where that is 'auto';
        InputMapError when both name one and they differ."""
        if map_frame == 'auto' or map_frame == self.frame:
            return self.frame
        if self.frame == 'auto':
            return map_frame
        raise InputMapError(f'{self.input_map.where}: the odometry input says frame '
                            f'{map_frame}, the frame setting {self.frame}: give one of them')

    def _model_of(self, coefficients):
        """The Model identifying these coefficients with the session's current settings."""
        return Model(self.vehicle, list(coefficients) + self.current_option.names,
                     mass_inverse=self._mass_inverse, current=self.current_option.fixed,
                     velocity_reference=self.velocity_reference)

    # -- the running filter (session/guarded_filter.py) and its life cycle --

    @property
    def stream(self):
        """The running filter's core.filter.stream.StreamIdentifier."""
        return self.filter.stream

    @property
    def last_good(self):
        """The last good estimate (a guard.LastGood), None before the first."""
        return self.filter.last_good

    @property
    def theta0(self):
        """(p,) the running filter's start-up prior of the identified parameters."""
        return self.filter.theta0

    @property
    def started(self):
        """True once the current filter has fused a measurement."""
        return self.filter.started

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

    def reset(self):
        """Restart the filter from the start-up configuration (the ~/reset service): buffered
        commands, counters and the last good estimate are kept; the frame ids are forgotten."""
        self.filter.restart(self._new_stream(keep_commands_from=self.filter.stream))
        self.noise.restarted()
        self._frame_ids = None

    def recover(self, reason, stamp_ns=None):
        """Apply the reset rule after an unexpected error outside the core (the node's last
        resort); returns the 'error' Event."""
        return self._fault_reset('internal error', reason, stamp_ns)

    def _fault_reset(self, code, reason, stamp_ns):
        """The reset rule (session/guard.py): vehicle states from the next measurement,
        coefficients from the last good estimate with inflated covariance."""
        self.counters.fault(reason)
        filt = self.filter
        start_from = filt.fault_start(code)
        filt.restart(self._new_stream(keep_commands_from=filt.stream, start_from=start_from),
                     fault=True)
        self.noise.restarted()
        start = ('the last good estimate (covariance x '
                 f'{RESET_COV_INFLATION:g})' if start_from is not None
                 else 'the start-up configuration')
        return Event('error', f'odom: {reason} (filter reset: vehicle states from the next '
                              f'measurement, coefficients from {start})', stamp_ns, code=code)

    def _guard_reset(self, t, stamp_ns):
        self.counters.guard_resets += 1
        window = self.filter.guard_window
        return self._fault_reset('guard', f'innovations inconsistent for '
                                          f'{t - window.since:.3f} s (median NIS/dof '
                                          f'{window.median():.4g} over the last {len(window)} '
                                          f'updates, above {GUARD_FACTOR:g})'
                                          + self._understated_noise(), stamp_ns)

    def _understated_noise(self):
        """A clause for a divergence under message covariances far below noise_std's (the
        data scatter far more than the messages say: a driver's covariance in other units, or
        its own filter's confidence rather than the sensor's noise), else ''."""
        r = self.filter.applied_variances
        if self.noise_source != 'message' or r is None:
            return ''
        measured = list(self._measured_states)
        ratio = r[measured] / self.noise_default[measured]
        low = float(np.min(ratio))
        if not low < UNDERSTATED_VARIANCE:
            return ''
        i = measured[int(np.argmin(ratio))]
        return (f'; the odometry covariance states far less noise than noise_std (e.g. '
                f'{covariance_entry(i, self.frame)} ({STATE_NAMES[i]}) = {r[i]:.3g}, '
                f'{low:.2g} x): if the data scatter more, set noise_source parameter')

    def warm_up(self):
        """Run a throwaway copy of the filter over three synthetic trim samples, so numba
        loads (or, with a stale cache, compiles: ~15 s) the EKF before real data arrive."""
        from auv_ident.core.model.trim import initial_state, rest_inputs
        try:
            s = StreamIdentifier(self.model, self.cfg, self.T, self.max_gap)
            rpm = float(self.vehicle.cruise_rpm)
            x0 = initial_state(self.model, rpm)
            u0 = rest_inputs(self.model)     # thrusters at neutral
            u0[Input.N_RPM] = rpm
            u0[Input.THRUST] = self.vehicle.cruise_thrust     # the trim's (0 for an AUV)
            s.add_command(0.0, u0)
            for k in range(3):
                s.add_measurement(k * self.T, np.where(self.measured, x0, np.nan))
        except AuvIdentError:
            pass    # only a warm-up: the real data decide

    # -- the estimate, its file, health and diagnosis --

    def best(self):
        """(estimate, covariance) to report: the last good one, else estimate_now(); with no
        good estimate yet while a sensor is stuck (session/stuck.py), the start-up prior, not
        what the filter formed during the fault."""
        if self.last_good is None and self.stuck.active():
            return self.theta0.copy(), self.stream.ekf.theta_cov0.copy()
        return self.filter.best()

    def estimate_now(self):
        """(estimate, covariance) now: the filter's, the last good one, or the prior."""
        return self.filter.estimate_now()

    def document(self):
        """The estimate file's dict of the best estimate (the last good one, else the prior;
        session/estimate_file.py), with the live diagnosis's verdict on its error bars and the
        learnt noise model."""
        est, cov = self.best()
        good = self.last_good
        doc = estimate_document(self.vehicle.name, self.names, est, cov,
                                None if good is None else good.stamp_ns,
                                self.counters.odom_accepted,
                                None if self.auto is None else self.auto.document())
        # the offline result's layout ({'consistent', 'messages'}), so that what reads one
        # reads the other; the learnt noise model under a key of its own (the offline
        # 'noise_model' is another document)
        _, doc['diagnosis'] = self.diagnosis()
        if self.noise.enabled:
            doc['live_noise_model'] = self.noise.document()
        return doc

    def health(self):
        """The filter's health (session/guard.py judge_health: the /diagnostics status); ERROR
        'stuck sensor: ...' while a measured channel group is stuck (session/stuck.py)."""
        health = self.counters.health(self.filter)
        stuck = self.stuck.describe_active()
        if stuck:
            return replace(health, level='ERROR', message=f'stuck sensor: {stuck}')
        return health

    def diagnosis(self, health=None):
        """(verdicts, diagnosis) of the running filter (session/live_diagnosis.py): per
        identified parameter its verdict from the best estimate's covariance against the
        prior, and {'consistent': True | False | None, 'messages': [...]}."""
        est, cov = self.best()
        prior_std = np.sqrt(np.diag(self.stream.ekf.theta_cov0))
        verdicts = live_verdicts(self.vehicle, self.names, est, cov, prior_std)
        diagnosis = live_diagnosis(self.health() if health is None else health, verdicts,
                                   self.noise)
        if self.auto is not None:
            # while choosing or after a failure the set is provisional: that comes first
            line = self.auto.diagnosis_line(self.coefficient_names)
            diagnosis['messages'].insert(0 if self.auto.state != 'chosen' else 1, line)
        return verdicts, diagnosis

    # -- coefficients ['auto', ...] (session/auto_choice.py) --

    def _start_choice(self, running_from):
        """The window is full: hand the choice to the runner, with a snapshot of what it
        needs (it may run in another thread; it reads nothing the session changes).
        running_from : the LastGood (or None) the running filter's coefficients start from,
        the last good estimate before the message that filled the window."""
        running = {}
        if running_from is not None:
            running = dict(zip(self.coefficient_names, running_from.estimate.tolist()))
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
        result = auto.poll()
        if result is not None:
            self._switch(result)
        return not auto.running

    def _switch(self, result):
        """Identify the chosen set from now on: its model, configuration and fed filter (a
        GuardedFilter, with its estimate, covariance, windows and last good estimate)
        replace the running ones; the resets and probation were the running filter's."""
        self.model, self.cfg, self.filter = result.model, result.cfg, result.chosen_filter.filter
        self.names = list(self.model.theta_names)
        self.coefficient_names = list(result.selection.chosen)
        self.warm_cov = None
        ekf = self.filter.stream.ekf
        self.counters.new_filter(float(ekf.nis), int(ekf.dof))
        self.noise.restarted()
        good = self.filter.last_good
        self.auto.chose(result, None if good is None else good.stamp_ns)

    # -- the array API --

    def add_command(self, stamp_ns, u7):
        """Buffer an actuator command. Returns an Event.

        stamp_ns : int, header stamp (ns)
        u7 : (7,) fins (rad), shaft speed (rpm) and thrust (N), core/model/state.py ``Input``
            order, then a thruster vehicle's thruster commands (vehicle.n_inputs in all);
            copied
        """
        try:
            stamp_ns = integer_stamp(stamp_ns)
        except ConversionError as err:
            return self._reject('actuators', 'conversion', str(err))
        try:
            u7 = _as_vector(u7, self.vehicle.n_inputs, 'u7').copy()
        except ConversionError as err:
            return self._reject('actuators', 'conversion', str(err), stamp_ns)
        return self._command(stamp_ns, u7)

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
        if self.frame == 'auto':    # x12 is NED/FRD by contract: the ids only for the rule
            self.frame = 'ned'
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

    def _decide_frame(self, frame_id, child_frame_id):
        """frame 'auto': the convention of the first odometry's frame ids (screening
        frame_of_ids); a guess (ids without a convention's token) is said once in the
        notices."""
        frame = frame_of_ids(frame_id, child_frame_id)
        if named_conventions(frame_id, child_frame_id):
            self.frame = frame
            return
        why = (f'its frame ids {frame_id!r} / {child_frame_id!r} carry no _ned/_frd token: '
               'REP-103 names, ENU/FLU' if frame == 'enu'
               else 'it has no frame ids: NED/FRD, our own convention')
        self._set_frame(frame, f'the first odometry: {why}; set frame explicitly if wrong')

    def _set_frame(self, frame, why):
        self.frame = frame
        self.notices.append(f'frame auto -> {frame} ({why})')

    def on_input(self, name, msg, receive_ns=None):
        """A message of the input map's input `name` (session/input_map.py). Returns an
        Event.

        receive_ns : the receive time (int ns: the node's clock live, the log time of a bag),
            the stamp of a message without a header (Float64, Float64MultiArray)
        Commands update the held actuators (session/inputs.py CommandHolder); once every fed
        actuator has been heard the whole input vector is buffered at the message's stamp.
        """
        entry = self._inputs[name]
        if entry.role == 'odometry':
            if self._multi_command and self.max_command_age is not None:
                stale = self._stale_commands(msg)
                if stale is not None:
                    return stale
            return self.on_odom(msg)
        stamp_ns = None
        try:
            stamp_ns = header_stamp_ns(msg) if entry.stamped else integer_stamp(receive_ns)
            if stamp_ns is None:
                raise ConversionError(f'{entry.type} without a readable header.stamp')
            u7 = self.holder.update(entry, msg, stamp_ns)
        except ConversionError as err:
            return self._reject(name, 'conversion', str(err), stamp_ns)
        if u7 is None:
            return Event('command', f'{name}: holding: no value yet for '
                                    + ', '.join(self.holder.missing()), stamp_ns,
                         code='holding')
        return self._command(stamp_ns, u7, name)

    def input_map_entry(self, name):
        """The input map's InputEntry called name."""
        return self._inputs[name]

    def _stale_commands(self, msg):
        """With commands on several topics: the 'stale command' rejection of an odometry
        message at whose stamp some actuator's last value is older than max_command_age (each
        topic is held on its own), else None."""
        try:
            stamp_ns = header_stamp_ns(msg)
        except ConversionError:
            return None     # on_odom says what is wrong with it
        if stamp_ns is None:
            return None
        stale = self.holder.stale(stamp_ns, self.max_command_age)
        if not stale:
            return None
        return self._reject('odom', 'stale command', 'the last command of '
                            + ', '.join(stale) + f' is older than max_command_age '
                            f'({self.max_command_age:g} s)', stamp_ns)

    def on_actuators(self, msg):
        """Buffer a sensor_msgs/JointState actuator command in the default layout
        (session/messages.py JOINT_NAMES). Returns an Event."""
        stamp_ns = None
        try:
            stamp_ns = header_stamp_ns(msg)
            _, u7 = joint_state_to_actuators(msg)
        except ConversionError as err:
            return self._reject('actuators', 'conversion', str(err), stamp_ns)
        return self._command(stamp_ns, u7)

    def on_odom(self, msg):
        """Fuse a nav_msgs/Odometry measurement (in the `frame` convention). Returns an Event."""
        stamp_ns = None
        if self.frame == 'auto':
            self._decide_frame(str(getattr(msg.header, 'frame_id', '') if hasattr(msg, 'header')
                                   else ''), str(getattr(msg, 'child_frame_id', '')))
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
        self.counters.rejected(what, code)
        if what != 'odom' and stamp_ns is not None and code != 'zero stamp':
            t = self._time(stamp_ns)
            self.stream.command_rejected(t)
            if self.auto is not None:
                self.auto.keep_command_rejected(t)
            self.noise.keep_command_rejected(t)
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
        where finite, positive and plausible (screening.implausible_variances: within a
        factor of the documented level, noise_std), noise_std's elsewhere; each channel
        noted once, naming the covariance entry and the setting that ignores them.

        A driver states the same covariance in every message: the same variances as the last
        message's give its R again (a copy) without the checks, whose notices were made then
        (noise_default and the measured channels do not change; ~30 us a message).
        """
        key = variances.tobytes()
        if key == self._variances_seen[0]:
            return self._variances_seen[1].copy()
        r = self._checked_variances(variances)
        self._variances_seen = (key, r.copy())
        return r

    def _checked_variances(self, variances):
        """_measurement_variances' R of variances (12,), the notices noted."""
        ok = np.isfinite(variances) & (variances > 0.0)
        # a variance this large is the ROS way of saying 'not measured' (robot_localization's
        # drivers, our importer): _sample skips the channel rather than judging the value
        unmeasured = ok & (variances >= NOT_MEASURED_VARIANCE)
        absurd = implausible_variances(variances, self.noise_default) & ok & ~unmeasured
        skipped = [i for i in self._measured_states
                   if unmeasured[i] and ('unmeasured', i) not in self._fallback_noted]
        if skipped:
            self._fallback_noted.update(('unmeasured', i) for i in skipped)
            self.notices.append(
                'odom: ' + ', '.join(f'{covariance_entry(i, self.frame)} ({STATE_NAMES[i]}) = '
                                     f'{variances[i]:.3g}' for i in skipped)
                + f' (>= {NOT_MEASURED_VARIANCE:.0e}): the message says it does not measure '
                f'{", ".join(STATE_NAMES[i] for i in skipped)}, so those channels are skipped '
                'in it; set noise_source parameter to fuse them with noise_std instead')
        missing = [i for i in self._measured_states
                   if not ok[i] and ('unstated', i) not in self._fallback_noted]
        if missing:
            self._fallback_noted.update(('unstated', i) for i in missing)
            self.notices.append('odom: the message states no usable covariance (zero, -1 or '
                                f'not finite) for {", ".join(STATE_NAMES[i] for i in missing)}'
                                ': noise_std used for them (noise_source message)')
        wild = [i for i in self._measured_states
                if absurd[i] and ('absurd', i) not in self._fallback_noted]
        if wild:
            self._fallback_noted.update(('absurd', i) for i in wild)
            ratios = variances[wild] / self.noise_default[wild]
            self.notices.append(
                'odom: implausible message covariance ' + ', '.join(
                    f'{covariance_entry(i, self.frame)} ({STATE_NAMES[i]}) = {variances[i]:.3g}'
                    for i in wild)
                + f': {ratios.min():.2g}' + ('' if ratios.min() == ratios.max() else
                                              f' to {ratios.max():.2g}')
                + " x the variance of noise_std (a sensor's is within "
                f'{PLAUSIBLE_VARIANCE_RATIO:.0e}x either way); noise_std used instead. Set '
                "noise_source parameter to ignore the messages' covariances, or fix the driver")
        return np.where(ok & ~absurd, variances, self.noise_default)

    def _command(self, stamp_ns, u7, what='actuators'):
        """add_command after reading: stamp_ns int, u7 a (7,) float array of our own; what:
        the input it came from (the rejections' topic)."""
        if self.auto is not None and self.auto.running:
            self.poll_choice()
        zero = self._zero_stamp(what, stamp_ns)
        if zero is not None:
            return zero
        t = self._time(stamp_ns)
        problem = command_problem(u7.tolist(), t, self.fin_limit, self.shaft_limit)
        if problem is not None:
            return self._reject(what, problem[0], problem[1], stamp_ns)
        out = self.stream.add_command(t, u7)
        if not out.accepted:
            return self._reject(what, out.code, out.reason, stamp_ns)
        if self.keep_arrays:
            self.commands.append(t, u7)
        if self.auto is not None:
            self.auto.keep_command(t, u7)
        self.noise.keep_command(t, u7)
        self.counters.cmd_accepted += 1
        return Event('command', '', stamp_ns)

    def _odometry(self, stamp_ns, x12, frame_id, child_frame_id, variances=None):
        """add_odometry after reading: stamp_ns int, x12 a (12,) float array of our own."""
        if self.auto is not None and self.auto.running:
            self.poll_choice()
        if self.noise.pending is not None:
            self.poll_noise()
        zero = self._zero_stamp('odom', stamp_ns)
        if zero is not None:
            return zero
        self.odom_gaps.see(stamp_ns)
        t = self._time(stamp_ns)
        problem = odometry_problem(x12.tolist(), t, frame_id, child_frame_id, self.frame,
                                   self._frame_ids, self._measured_states)
        if problem is not None:
            return self._reject('odom', problem[0], problem[1], stamp_ns)
        y, r = self._sample(x12, variances)
        # the stuck-sensor rule decides what the filter takes; unfiltered, samples are kept.
        # It judges what the message measures: a channel it says it does not (NaN in y) never
        # repeats, so its group is not held
        fresh = y.tolist()
        held = self._repeats(t, fresh) if self.filtering else []
        if held and self.stuck.all_held(held):
            return self._reject('odom', 'repeated', 'every measured channel group ('
                                + ', '.join(g.name for g in held) + ') repeats the previous '
                                f'sample exactly at {t:.9f} s: not fed (a stuck sensor?)',
                                stamp_ns)
        if held:
            y = y.copy()
            y[self.stuck.channels(held)] = np.nan
        if not self.filtering:
            return self._kept(t, stamp_ns, y, r, frame_id, child_frame_id)
        filt = self.filter
        before = filt.last_good
        # the faults that go on with this sample (a stuck group that changes now ends its own)
        stuck = describe_spans(self.stuck.faults_among(held))
        try:
            step = filt.update(t, stamp_ns, y, self._learnt_variances(r),
                               trusted=not stuck)
        except FILTER_FAULTS as err:
            return self._fault_reset('core error', f'{type(err).__name__}: {err}', stamp_ns)
        self.counters.filtered(step.code)
        if step.accepted:
            self.stuck.renew(t, fresh, held)
            self._stuck_notices()
        if not step.accepted:
            ev = self._reject('odom', step.code, step.reason, stamp_ns)
            return self._guard_reset(t, stamp_ns) if step.sustained else ev
        self._taken(t, stamp_ns, y, r, step, before, not stuck)
        if step.sustained:
            return self._guard_reset(t, stamp_ns)
        if self._learn(step):
            return self._relearnt_event(stamp_ns)
        if step.good:
            if self._frame_ids is None:
                self._frame_ids = (frame_id, child_frame_id)
            return Event('update', f'odom: {step.reason}' if step.reason else '', stamp_ns,
                         step.estimate, step.std, step.cov, step.nis, step.dof, step.code, True)
        why = f'stuck sensor: {stuck}' if stuck else filt.why_not_good()
        reason = ('odom: ' + (step.reason + '; ' if step.reason else '') + why
                  + ': not taken as good')
        return Event('update', reason, stamp_ns, step.estimate, step.std, step.cov, step.nis,
                     step.dof, 'guard', False)

    def _kept(self, t, stamp_ns, y, r, frame_id, child_frame_id):
        """filtering False: keep a screened odometry sample as it is (the first of a stamp;
        a repeated stamp is not a second measurement of that instant)."""
        if stamp_ns in self._kept_stamps:
            return self._reject('odom', 'duplicate stamp', f'duplicate stamp {t:.9f} s (the '
                                'first message with it kept)', stamp_ns)
        self._kept_stamps.add(stamp_ns)
        self.counters.odom_accepted += 1
        self.measurements.append(t, y)
        self.variances.append(self.noise_default if r is None
                              else np.where(np.isnan(y) & self.measured, np.nan, r))
        if self._frame_ids is None:
            self._frame_ids = (frame_id, child_frame_id)
        return Event('kept', '', stamp_ns)

    def _sample(self, x12, variances):
        """(y (12,), r (12,) or None): the measured channels of x12 (NaN elsewhere, and where
        the message's variance says it does not measure them, >= NOT_MEASURED_VARIANCE) and
        the measurement variances of the message (noise_source 'message'), else None."""
        y = x12 if self._all_measured else np.where(self.measured, x12, np.nan)
        r = None
        if variances is not None:
            r = self._measurement_variances(variances)
            unmeasured = variances >= NOT_MEASURED_VARIANCE
            if unmeasured.any():    # the message says it does not measure these: skipped
                y = np.where(unmeasured, np.nan, y)
        return y, r

    def _repeats(self, t, x12):
        """The stuck-sensor rule (session/stuck.py) on a screened odometry sample at t (s),
        x12 a list of 12 floats (NaN where not measured):
        the measured channel groups that repeat the last sample the filter took exactly
        ([] for a stamp not after it, which the stream's time rules take), their repeats
        counted and a fault started, said once in the notices."""
        prev = self.stream.t_prev
        if prev is not None and t <= prev:
            return []
        held = self.stuck.held(x12)
        if held:
            self.stuck.repeat(t, held)
            self._stuck_notices()
        return held

    def _stuck_notices(self):
        stuck = self.stuck
        if stuck.notices:
            self.notices.extend(stuck.notices)
            stuck.notices.clear()

    def _taken(self, t, stamp_ns, y, r, step, before, trusted):
        """Count and keep an accepted odometry sample (y, its variances r or None; trusted:
        no sensor fault active); start the 'auto' choice, from the last good estimate before
        it, when its window fills."""
        self.counters.updated(step.nis, step.dof)
        if self.keep_arrays:
            self.measurements.append(t, y)
            # a channel the message did not measure (NaN in y) is no sample of its noise
            self.variances.append(self.noise_default if r is None
                                  else np.where(np.isnan(y) & self.measured, np.nan, r))
        self.noise.keep_odometry(t, stamp_ns, y, r, step.code, trusted)
        if self.auto is not None and self.auto.keep_odometry(t, stamp_ns, y, r, step.code,
                                                            trusted):
            self._start_choice(before)

    # -- the noise model learnt from the innovations (session/noise_learning.py) --

    def _learnt_variances(self, r):
        """The variances to fuse a sample with: r (or, None, the configured ones) times the
        learnt scale; None (the filter's own) while nothing has been learnt."""
        scale = self.noise.scale
        if self.noise.reruns == 0:
            return r
        return (self.noise_default if r is None else r) * scale

    def _learn(self, step):
        """Hand a fused update's whitened innovations to the learner; when its fit says the
        noise model must change, start the re-run of a filter from the start-up configuration
        over the kept record with the learnt variances, in the runner (the node's: a worker
        thread; the messages go on meanwhile, the running filter takes them and they are
        kept). Returns True if a re-run's filter has replaced the running one now (an inline
        runner)."""
        noise = self.noise
        if (noise.pending is not None or step.code not in FUSED_OK
                or not noise.innovations(self.stream.ekf.white)):
            return False
        scale = noise.fit()
        if scale is None:
            return False
        # what the worker reads, taken here: a fresh stream and a snapshot of the record
        stream, entries, guard_on = self._new_stream(), noise.entries(self.noise_default,
                                                                      scale), self.guard_on
        noise.start_rerun(self._runner(lambda: rerun(stream, guard_on, entries)), scale)
        return self.poll_noise()

    def poll_noise(self):
        """Switch to the re-run filter if its job has finished: it is fed what was kept
        meanwhile and replaces the running filter (its estimate, covariance, windows and last
        good estimate); a failed re-run is recorded and the running filter stays. Called before
        every odometry message; the node also calls it from its timer. Returns True if the
        filter was replaced."""
        noise = self.noise
        job = noise.pending
        if job is None or not job.future.done():
            return False
        noise.pending = None
        try:
            fed, whites = job.future.result()
            samples = fed.samples       # the record the re-run was started on
            later = rerun(None, self.guard_on, noise.entries(self.noise_default, job.scale,
                                                             job.taken), fed)[1]
        except Exception as err:                 # noqa: BLE001 - the running filter stays
            noise.rerun_failed(failure_text(err), noise.kept_odometry)
            return False
        self.filter = fed.filter
        noise.rerun_done(job.scale, samples, whites, later)
        ekf = self.filter.stream.ekf
        self.counters.new_filter(float(ekf.nis), int(ekf.dof))
        return True

    def _relearnt_event(self, stamp_ns):
        """The update Event after a re-run with the learnt noise model: the re-run filter's
        estimate, not good (the model is not yet confirmed, so the node does not publish it);
        the reason is the learner's line (also in its news, for the caller to log)."""
        text = self.noise.news[-1]
        est, cov = self.estimate_now()
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        ekf = self.stream.ekf
        return Event('update', 'odom: ' + text, stamp_ns, est, std, cov,
                     float(ekf.nis), int(ekf.dof), 'noise model', False)
