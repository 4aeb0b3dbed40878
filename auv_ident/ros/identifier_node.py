"""Online identification of hydrodynamic coefficients: ``ros2 run auv_ident identifier``.

Thin layer over :class:`auv_ident.session.session.IdentSession` (message conversion, rejection
policy, the augmented EKF through core.filter.stream.StreamIdentifier, recovery, health rule):
the node builds the messages and publishes them; what they hold comes from the session layer
(the /diagnostics values: session/status.py; the frame algebra: session/messages.py).
Offline, :func:`auv_ident.offline.replay.replay_bag` drives the same class with a bag's
messages in log-time order, so a recorded run replays to the same estimates.

An input map with raw sensors (IMU, DVL, pressure, pose) hands the node to ros/raw_live.py
RawLive (session/raw_session.py: each message one step of the raw-sensor filter; its topics,
~/estimate, ~/covariance, /diagnostics, ~/reset, ~/save: docs/raw_sensors.md#live); what follows
is the odometry path.

Subscriptions (RELIABLE, KEEP_LAST depth 1000, VOLATILE: no loss at 200 Hz while the callback
is busy, see shared/ros_stack.md section 2; a BEST_EFFORT publisher cannot feed these): the
topics of the input map (parameter ``input_map``, session/input_map.py, docs/your_data.md), each
with the map's message type, taken as ``intake_period_s`` says (ros/intake.py: every 20 ms by
default, a batch at a time in the order they were published; 0: each as it arrives). The
default map, odom_actuators:
    ``actuators`` sensor_msgs/JointState: commands (conversions.py layout). The command inputs
        are created before the odometry, so when both are waiting the executor takes the
        command first. Commands of other forms (JointState with other joint names,
        Float64MultiArray by index, one Float64 per actuator, in other units) hold each
        actuator's last value (session/inputs.py); a message without a header is stamped
        with its receive time: when DDS received it, or with ``use_sim_time`` the last
        ``/clock`` taken before it (a played bag: the player's ``publish_clock`` gives each
        message's log time, so the node stamps it as replay_bag does).
    ``/clock`` rosgraph_msgs/Clock, with ``use_sim_time`` only: the node's own subscription
        (RELIABLE, depth 1000), taken with the inputs: batched, in the order they were
        published (each message's source_timestamp; a player publishes a message's /clock
        just before it); with ``intake_period_s`` 0, in the order the executor takes them as
        they arrive (ros/intake.py).
    ``odom`` nav_msgs/Odometry: measured state, in the convention of ``frame``; the message
        covariances are the measurement noise (``noise_source`` 'message', the default) or
        ignored (``noise_source`` 'parameter': ``noise_std`` is the noise model).

Publications
    ``~/estimate`` sensor_msgs/JointState, one per *good* odometry update (Event.good, the
        last good estimate rule of auv_ident/session/guard.py: fused, finite, positive
        definite, innovations consistent; during a divergence nothing is published, so the
        latched value stays the last good estimate; with ``publish_rate_hz`` > 0 only the first
        good update in each 1/rate interval of odometry stamps, session/messages.py
        PublishGate):
        header.stamp = the odometry stamp; name = coefficient names; position = estimates
        (vehicle file's units); velocity = 1-sigma; effort empty. The names and their number
        are fixed for the run, except once with ``coefficients`` [auto, ...] (below): at the
        switch to the chosen set, name, position, velocity and the covariance's layout get the
        new set and length; a subscriber must read the names of every message.
    ``~/covariance`` std_msgs/Float64MultiArray, with each estimate: layout.dim[0] = label
        'row:' + comma-joined names, size p, stride p*p; dim[1] = 'col:' + names, size p,
        stride p; data = the p x p covariance, row-major.
    ``~/current`` geometry_msgs/TwistWithCovarianceStamped, with each estimate when the water
        current is estimated (parameter ``current`` 'estimate'): header.frame_id = the world
        frame ('odom_ned' for frame ned, 'odom' for enu), twist.linear = the current where the
        water goes (NED: north, east, down; ENU: east, north, up; m/s), covariance row-major
        6x6 with the current's covariance in the linear block; a component not estimated
        (down, unless current_down) is 0 with variance 0; angular 0 (irrotational).
    All three RELIABLE + TRANSIENT_LOCAL, depth 1: a late subscriber gets the latest estimate at
    once. Depth 1 keeps only the latest: a slow reader can miss intermediate estimates (the
    count of updates is in /diagnostics; replay_bag gives every one).
    ``/diagnostics`` diagnostic_msgs/DiagnosticArray, every 1 s (steady clock) and at once on a
    filter error or a re-run with a learnt noise model: one DiagnosticStatus, name
    'auv_ident identifier', hardware_id = vehicle, level and message from
    IdentSession.health:
        ERROR 'diverging': a filter reset (a core error the covariance repair could not fix,
            or the divergence guard: innovations inconsistent for 1 s) within the last 200
            updates; the guard's window inconsistent now (median NIS/dof of the last 20
            updates > 100); or the mean NIS/dof over the last 200 updates > 10x its band
            (rules and reset in auv_ident/session/guard.py);
        ERROR 'stuck sensor: ...': a measured channel group repeats its values exactly for
            10 samples and 2 s or more (session/stuck.py: the repeats are not fed, no update
            is good until it changes);
        WARN 'waiting for data': no update since start-up or the last restart;
        WARN 'diverging': 200 updates in the window and mean NIS/dof above the two-sided
            99.9 % chi-square band of the window (sum of NIS over sum of dof);
        OK 'converged': window full, mean NIS/dof not above the band, and every coefficient's
            1-sigma < 5 % of |estimate|;
        OK 'converging': otherwise.
    values: accepted, rejected (odometry), commands, commands_rejected, errors (filter resets
    by the reset rule: core errors and divergence-guard resets), guard_resets, outliers
    (innovation gate), repairs (covariance repairs), time_jumps (confirmed backward jumps),
    actuator_publishers (on the actuator topic, checked at 1 Hz), internal_errors (unexpected
    exceptions caught in a callback; 0 unless there is a bug), odom_lost_event (odometry the
    middleware reports lost: rclpy's message-lost event, which Fast DDS does not raise for a
    queue overflow), odom_lost (odometry lost before the node read it, from the gaps in the
    stamps against the observed rate: session/status.py StampGaps; a warning at 1 Hz at most
    says how many and what to do), odom_rate_hz (the rate the stamps show), last_error,
    repeated (measured channel-group samples not fed because they repeated the previous
    sample exactly), stuck_sensor (the active stuck-sensor fault, or 'none'),
    mean_nis_per_dof, nis_band, nis_window, guard_median_nis_per_dof, last_nis, last_dof,
    last_stamp (of the last good estimate), consistent and diagnosis[_<i>] (the live diagnosis,
    session/live_diagnosis.py: 'false' also while the noise model the filter runs with is not
    confirmed by the innovations), then per coefficient <name>, <name>_std and <name>_verdict of
    the last good estimate (repr floats), R_<channel> (adapted measurement
    variance of u ... psi) and Q_<name> (coefficient random-walk variance). With
    ``coefficients`` [auto, ...] also auto_state ('choosing', 'chosen' or 'failed'),
    auto_window_s, auto_data_s (s of odometry kept, or the choice was made from),
    auto_named, auto_chosen (comma-joined), auto_left_out_count, auto_choice_wall_s,
    auto_error (why a choice failed) and auto_left_out_<name> (every left-out coefficient's
    reason); the diagnosis's first line says 'choosing coefficients from the data (X of Y
    s)' until the switch. With ``learn_noise`` (default) in noise mode fixed also
    noise_state ('learning': no fit yet, 'holds', 'relearnt': the last fit found the model off
    and none has confirmed it since), noise_reruns, and per measured channel noise_scale_<ch>
    (the learnt factor on its measurement variance, 1.0 as configured) and noise_factor_<ch>
    (the last fit's variance factor level^2 (1 + rho) / (1 - rho) of its whitened
    innovations; 'n/a' before a fit). What the learning finds is logged at info level; its
    re-runs run in a worker thread (as the 'auto' choice: the callbacks go on meanwhile) and
    the re-run filter takes over at the next odometry message or 1 Hz tick after it ends.

Services (std_srvs/srv/Trigger)
    ``~/reset``: restart the filter from the start-up configuration (initial guesses or warm
        start); buffered commands, counters and the last good estimate are kept.
    ``~/save``: write the estimate file to ``save_path`` (fails if save_path is empty).

Errors never stop the node: rejected messages (the rejection policy and plausibility rule of
auv_ident/session/screening.py: conversion errors, wrong frame, non-finite or implausible values,
zero, duplicate, out-of-order stamps, backward time jumps, no command yet, outliers) are warnings
naming the problem, rate-limited per topic and problem (WarningLimiter: at most one line per
kind every 5 s, with the count of those suppressed), so a flood of one problem never hides
another. A filter fault (core error or divergence guard) is logged as an error (at most one
per second), reported as ERROR on /diagnostics at once, and handled by the reset rule of
auv_ident/session/guard.py (vehicle states restart, coefficients from the last good estimate
with inflated covariance); the last good estimate stays available (latched ~/estimate, ~/save).
Nothing non-finite is published. An unexpected exception inside a callback (a bug) is caught,
logged as one line, counted in internal_errors and handled by the same reset rule, so the
node keeps running.

Estimate file (``save_path``, ``warm_start``): JSON ``{"vehicle", "coefficients": [names],
"estimate": [...], "std": [...], "covariance": [[...]], "stamp": s or null, "stamp_ns": int or
null, "steps": accepted updates, "diagnosis": {"consistent": true/false/null, "messages"},
"live_noise_model": {...}}`` (auv_ident/session/estimate_file.py) of the last good estimate; with
``coefficients`` [auto, ...] also ``"selection"`` (state, window; once chosen the offline
JSON's selection block: chosen, named, left_out with reasons, steps, criteria).
Written on ``~/save``, on shutdown (SIGINT/SIGTERM: after the messages DDS already received
are processed, for at most 2 s; a second signal skips that) and every AUTOSAVE_PERIOD_S (10 s,
steady clock) while new updates arrive, always atomically (temp file + rename: a kill leaves the
previous complete file). ``warm_start`` starts a later run from it.

Parameters (read once at start-up, declared read-only): every field of
:class:`auv_ident.session.settings.IdentifierSettings`, declared from the fields (name, default,
type, description with unit and choices; config/identifier.yaml and the docs/ros.md table are
made from the same fields), and ``save_path`` (''). An empty list means the default (ROS turns
``[]`` into "not set"). Bad values (or types) print one line naming the parameter and exit with
status 2 (ros/toolkit.py).

Coefficients chosen from the data (``coefficients`` [auto] or [auto, NAME, ...], as offline
``identify --bag --coefficients auto[,NAME,...]``; auv_ident/session/auto_choice.py): the node
identifies and publishes the named coefficients (none named: identify_default) while it keeps
the accepted odometry and commands of the first ``auto_window`` s; then
core/identification/selection.py's stepwise pass chooses the set from them in a worker thread (the
callbacks go on identifying and keeping messages), a filter of the chosen set is fed the kept
record, and the node switches to it at the next message or 1 Hz tick: logged (the set, every
left-out coefficient by reason), then published at once. A choice that fails is logged once as an
error and the running set stays. 'auto' with ``warm_start`` is a parameter error (the file fixes
the set). Cost and figures: docs/ros.md.

Executor and latency: rclpy's EventsExecutor (ros/toolkit.py spin); the estimate and
covariance messages are built once and refilled per update. docs/latency.md has the measured
path publish(odom) -> estimate received and the command that measures it.
"""
from array import array
import copy
import math
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TwistWithCovarianceStamped
from nav_msgs.msg import Odometry
import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from std_srvs.srv import Trigger

from auv_ident.ros.cdr import (
    estimate_templates,
    OdometryView,
    PayloadTemplate,
    UndecodableMessage,
)
from auv_ident.ros.intake import Intake, IntakeNode
from auv_ident.ros.raw_live import RawLive
from auv_ident.ros.toolkit import (
    declare_parameters,
    DIAGNOSTICS_QOS,
    LATCHED_QOS,
    message_class,
    optional_list,
    Param,
    run_node,
    spin,
    STREAM_QOS,
)
from auv_ident.session.auto_choice import run_in_thread
from auv_ident.session.estimate_file import check_save_path, write_estimate_json
from auv_ident.session.messages import (
    current_indices,
    current_twist_fields,
    DEFAULT_FRAME_IDS,
    NS_PER_S,
    PublishGate,
)
from auv_ident.session.raw_session import has_raw_sensors
from auv_ident.session.session import Event, IdentSession
from auv_ident.session.settings import help_text, IdentifierSettings, settings_fields
from auv_ident.session.settings_text import SAVE_PATH
from auv_ident.session.status import diagnostic_values
from auv_ident.session.warning_limiter import WarningLimiter

NODE_NAME = 'identifier'
STATUS_NAME = 'auv_ident identifier'
DIAGNOSTICS_PERIOD_S = 1.0
WARN_THROTTLE_S = 5.0
ERROR_THROTTLE_S = 1.0
AUTOSAVE_PERIOD_S = 10.0
LEVELS = {'OK': DiagnosticStatus.OK, 'WARN': DiagnosticStatus.WARN,
          'ERROR': DiagnosticStatus.ERROR}


def _parameter(f):
    """The node parameter of a setting (session/settings.py): its name, default (the
    Parameter.Type of an empty list: ROS cannot type one) and description."""
    kind = f.metadata['kind']
    if kind not in ('strings', 'floats'):
        return Param(f.name, f.default, help_text(f))
    return Param(f.name, list(f.default) if f.default else _LIST_TYPES[kind], help_text(f),
                 optional_list)


_LIST_TYPES = {'strings': Parameter.Type.STRING_ARRAY, 'floats': Parameter.Type.DOUBLE_ARRAY}
# every identifier setting, checked by IdentifierSettings (ParameterError naming the
# parameter; here only the type and "unset" are settled: ROS turns [] into "not set"), and the
# node's own save_path
_PARAMETERS = tuple(_parameter(f) for f in settings_fields()) + (Param(*SAVE_PATH),)


class IdentifierNode(IntakeNode):
    """Identify coefficients online from ``odom`` and ``actuators`` (module docstring)."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        values = declare_parameters(self, _PARAMETERS)
        self.save_path = values.pop('save_path')
        check_save_path(self.save_path)     # a bad folder: exit 2 now, not at shutdown
        settings = IdentifierSettings.from_values(**values)
        self.taken = 0      # messages the subscriptions' callbacks took (the stop's drain)
        # an input map with raw sensors: each message a step of the raw-sensor filter
        # (ros/raw_live.py, session/raw_session.py); the rest of this class is the odometry path
        self.raw = RawLive(self, settings) if has_raw_sensors(settings) else None
        if self.raw is not None:
            return
        # ParameterError names a bad parameter; an 'auto' choice and the noise learning's
        # re-runs run in worker threads, so that the callbacks go on taking (and keeping)
        # messages while they run
        self.session = IdentSession(settings, auto_runner=run_in_thread)
        self._reruns_seen = 0      # noise re-runs already announced (_noise_news)
        self._warn_limit = WarningLimiter(WARN_THROTTLE_S, time.monotonic)
        self._error_limit = WarningLimiter(ERROR_THROTTLE_S, time.monotonic)
        self.internal_errors = 0
        self.odom_lost_event = 0            # odometry the middleware reports lost
        self._lost_reported = 0             # lost odometry already in a warning
        self.actuator_publishers = 0        # publishers on the actuator topic (1 Hz check)
        self._odom_at_last_check = 0
        self._saved_steps = 0
        self._last_autosave = time.monotonic()
        self._publish_gate = PublishGate(settings.publish_rate_hz)
        self._estimate = JointState()
        self._covariance = Float64MultiArray()
        self._lay_out()
        # Load (or compile) the EKF now, before subscribing: a publisher that waits for our
        # subscriptions then never finds us busy with numba.
        self.session.warm_up()
        self.pub_estimate = self.create_publisher(JointState, '~/estimate', LATCHED_QOS)
        self.pub_covariance = self.create_publisher(Float64MultiArray, '~/covariance',
                                                    LATCHED_QOS)
        self.pub_diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics',
                                                     DIAGNOSTICS_QOS)
        # the water current, when estimated: ~/current (module docstring, docs/current.md)
        self.pub_current = None
        if any(i >= 0 for i in self._current_index):
            self._current = TwistWithCovarianceStamped()
            # the world frame of the convention, set at each publication: with frame 'auto'
            # the first odometry decides it
            self.pub_current = self.create_publisher(TwistWithCovarianceStamped, '~/current',
                                                     LATCHED_QOS)
        self._subscribe_inputs()
        self.srv_reset = self.create_service(Trigger, '~/reset', self.on_reset)
        self.srv_save = self.create_service(Trigger, '~/save', self.on_save)
        self.diagnostics_timer = self.create_timer(
            DIAGNOSTICS_PERIOD_S, self.on_timer,
            clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(
            f'identifying {", ".join(self.names)} of {self.session.vehicle.name} '
            f'(noise mode {self.session.settings.noise_mode}, frame {self.session.frame}, initial '
            f'{np.array2string(self.session.theta0, precision=5)})'
            + ('' if self.session.auto is None else
               f'; coefficients [auto]: the set is chosen from the first '
               f'{self.session.auto.window_s:g} s of data, then identified instead'))

    def _subscribe_inputs(self):
        """One subscription per input of the input map (session/input_map.py), with its
        type, taken as ``intake_period_s`` says (ros/intake.py): the commands first, so that
        when a command and an odometry message arrive together the command is taken first;
        the odometry read raw, from its CDR bytes into one reused view (ros/cdr.py)."""
        imap = self.session.input_map
        # with use_sim_time, a command without a header is stamped with the /clock value
        # taken last before it (ros/intake.py Intake.for_inputs)
        self.intake = Intake.for_inputs(self, self.session.settings.intake_period_s,
                                        imap.inputs)
        self.sub_commands = []
        for entry in imap.commands:
            cls = message_class(entry.type, entry.topic)
            self.sub_commands.append(self.intake.subscribe(
                cls, entry.topic,
                lambda msg, receive_ns, name=entry.name: self.on_input(name, msg, receive_ns),
                STREAM_QOS))
        self.sub_actuators = self.sub_commands[0]
        self._command_name = imap.commands[0].name
        self._odom_name = imap.odometry.name
        self._odom_view = OdometryView()
        # the middleware's message-lost event is counted too, but Fast DDS does not raise it
        # when the queue overflows (measured): the stamps' gaps are what tell (check_lost)
        self.sub_odom = self.intake.subscribe(
            Odometry, imap.odometry.topic, lambda payload, _: self.on_odom_payload(payload),
            STREAM_QOS, raw=True,
            event_callbacks=SubscriptionEventCallbacks(message_lost=self._on_message_lost))

    def _lay_out(self):
        """Names and layout of the published estimate and covariance, from the session's
        parameters. Built once and refilled per update: they change only when an 'auto' choice
        switches the set (once)."""
        self.names = self.session.names
        p = len(self.names)
        joined = ','.join(self.names)
        self._estimate.name = list(self.names)
        self._covariance.layout.dim = [
            MultiArrayDimension(label='row:' + joined, size=p, stride=p * p),
            MultiArrayDimension(label='col:' + joined, size=p, stride=p)]
        self._current_index = current_indices(self.names)
        self._templates = {}       # serialized estimate/covariance/current (_template)

    def _follow_choice(self, diagnostics=True):
        """After a session call: log what the 'auto' choice has to say (it started, switched
        or failed) and then publish the diagnostics at once (unless diagnostics is False: the
        caller does); once it switched the set, lay the messages out anew and publish the
        chosen set's last good estimate at once (its subscribers see the new length)."""
        auto = self.session.auto
        if not auto.news:
            return
        for level, text in auto.news:
            self._emit(level, text)
        auto.news.clear()
        switched = self.session.names is not self.names
        if switched:
            self._lay_out()
        if not self.context.ok():   # shutting down
            return
        good = self.session.last_good
        if switched and good is not None:
            self.publish_estimate(Event('update', '', good.stamp_ns, good.estimate, good.std,
                                        good.cov, good=True))
        if diagnostics:
            self.publish_diagnostics()

    # -- messages --

    def _noise_news(self):
        """Log what the noise learning found (session/noise_learning.py, info); returns True if
        a re-run's filter took over (the caller publishes /diagnostics at once)."""
        noise = self.session.noise
        rerun = noise.reruns != self._reruns_seen
        self._reruns_seen = noise.reruns
        for text in noise.news:
            self._emit('info', text)
        noise.news.clear()
        return rerun

    def _emit(self, level, text):
        """Write one log line (tests replace this to count what is logged)."""
        logger = self.get_logger()
        if level == 'error':
            logger.error(text)
        elif level == 'warning':
            logger.warning(text)
        else:
            logger.info(text)

    def _report(self, ev):
        """Log an Event's problem, rate-limited per topic and code (WarningLimiter)."""
        if not ev.reason and ev.kind != 'rejected' and ev.kind != 'error':
            return      # the common case: a plain update, nothing to say
        key = (ev.reason.split(':', 1)[0], ev.code)
        if ev.kind == 'rejected':
            line = self._warn_limit(key, f'rejected {ev.reason}')
            if line:
                self._emit('warning', line)
        elif ev.kind == 'error':
            line = self._error_limit(key, ev.reason)
            if line:
                self._emit('error', line)
        elif ev.reason:
            line = self._warn_limit(key, ev.reason)
            if line:
                self._emit('info', line)

    def _internal_error(self, what, err, stamp_ns=None):
        """Last resort for an unexpected exception in a callback: one line, a count, the
        reset rule; the node keeps running."""
        self.internal_errors += 1
        try:
            ev = self.session.recover(f'internal error on {what}: {type(err).__name__}: {err}',
                                      stamp_ns)
        except Exception:                        # noqa: BLE001 - keep the node alive
            ev = Event('error', f'{what}: internal error: {type(err).__name__}: {err}',
                       stamp_ns, code='internal error')
        self._report(ev)
        return ev

    def on_input(self, name, msg, receive_ns=None):
        """A command message of the input map's input `name`; returns the session's Event.
        receive_ns : the stamp of a message without a header (default: its receive time as
        ros/intake.py gives it, taken now)."""
        self.taken += 1
        try:
            if receive_ns is None and not self.session.input_map_entry(name).stamped:
                receive_ns = self.intake.receive_ns()
            ev = self.session.on_input(name, msg, receive_ns)
        except Exception as err:                 # noqa: BLE001 - a bug must not stop the node
            return self._internal_error(name, err)
        if self.session.auto is not None:
            self._follow_choice()
        self._report(ev)
        return ev

    def on_actuators(self, msg):
        """A message of the map's first command input (the default map: the JointState on
        actuators); returns the session's Event."""
        return self.on_input(self._command_name, msg)

    def on_odom(self, msg):
        """Fuse an odometry measurement and publish the estimate if good; returns the Event."""
        try:
            ev = self.session.on_input(self._odom_name, msg)
        except Exception as err:                 # noqa: BLE001 - a bug must not stop the node
            ev = self._internal_error('odom', err)
        if self.session.auto is not None:
            self._follow_choice()
        if ev.kind == 'update' and ev.good and self._publish_gate.due(ev.stamp_ns):
            self.publish_estimate(ev)
        self._report(ev)
        if self.session.notices:
            for text in self.session.notices:
                self._emit('warning', text)
            self.session.notices.clear()
        rerun = self._noise_news()
        if (ev.kind == 'error' or rerun) and self.context.ok():
            self.publish_diagnostics()
        return ev

    def on_odom_payload(self, payload):
        """The odom subscription's callback: serialized Odometry -> :meth:`on_odom`."""
        self.taken += 1
        if self._odom_view.read(payload):
            return self.on_odom(self._odom_view)
        try:    # not XCDR1 (another DDS, XCDR2): rclpy decodes it
            msg = deserialize_message(payload, Odometry)
        except Exception as err:                 # noqa: BLE001 - undecodable bytes
            msg = UndecodableMessage(f'{type(err).__name__}: {err}')
        return self.on_odom(msg)

    def publish_estimate(self, ev):
        """Publish ~/estimate and ~/covariance of an update Event (finite by construction:
        IdentSession turns a non-finite estimate into a filter error)."""
        estimate, cov = ev.estimate, ev.cov
        if not (np.isfinite(estimate).all() and np.isfinite(cov).all()):
            return
        if not self.context.ok():   # shutting down
            return
        sec, nanosec = divmod(int(ev.stamp_ns), NS_PER_S)
        est_t, cov_t = self._template('estimate'), self._template('covariance')
        # the templates hold len(self.names) values (_lay_out); another length would make
        # fill raise, so such an estimate goes out as messages
        if est_t is not None and cov_t is not None and len(estimate) == len(self.names):
            self.pub_estimate.publish(est_t.fill(sec, nanosec, estimate, ev.std))
            self.pub_covariance.publish(cov_t.fill(sec, nanosec, cov))
        else:
            self._publish_messages(sec, nanosec, estimate, ev.std, cov)
        if self.pub_current is not None:
            self.publish_current(sec, nanosec, estimate, cov)

    def _template(self, kind):
        """The PayloadTemplate (ros/cdr.py) of ~/estimate, ~/covariance or ~/current (kind;
        the current's per world frame id), built at the first publication after _lay_out;
        None where the bytes path is not available (the messages are published instead)."""
        if kind in self._templates:
            return self._templates[kind]
        if kind in ('estimate', 'covariance'):
            self._templates['estimate'], self._templates['covariance'] = estimate_templates(
                self._estimate, self._covariance, len(self.names), serialize_message)
            return self._templates[kind]
        msg = copy.deepcopy(self._current)
        msg.header.frame_id = kind
        arrays = [(_set_linear, 3), (lambda m, v: setattr(m.twist, 'covariance', v), 36)]
        template = PayloadTemplate.build(msg, arrays, serialize_message)
        self._templates[kind] = template
        return template

    def _publish_messages(self, sec, nanosec, estimate, std, cov):
        """~/estimate and ~/covariance as messages, refilled (the path without templates)."""
        est = self._estimate
        stamp = est.header.stamp
        stamp.sec, stamp.nanosec = sec, nanosec
        # array('d', bytes) is a plain copy; rclpy would convert a list or ndarray element by
        # element (measured 23 us for both messages built afresh, 3 us refilled this way)
        est.position = array('d', np.ascontiguousarray(estimate, dtype=float).tobytes())
        est.velocity = array('d', np.ascontiguousarray(std, dtype=float).tobytes())
        self.pub_estimate.publish(est)
        self._covariance.data = array('d', np.ascontiguousarray(cov, dtype=float).tobytes())
        self.pub_covariance.publish(self._covariance)

    def publish_current(self, sec, nanosec, estimate, cov):
        """~/current: the estimated water current in the world frame of ``frame``, with its
        covariance (session/messages.py current_twist_fields: the frame algebra)."""
        linear, covariance = current_twist_fields(estimate, cov, self._current_index,
                                                  self.session.frame)
        frame_id = DEFAULT_FRAME_IDS[self.session.frame][0]
        template = self._template(frame_id)
        if template is not None:
            self.pub_current.publish(template.fill(sec, nanosec, linear, covariance))
            return
        msg = self._current
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
        msg.header.frame_id = frame_id
        _set_linear(msg, linear)
        msg.twist.covariance = array('d', np.ascontiguousarray(covariance).tobytes())
        self.pub_current.publish(msg)

    # -- diagnostics --

    def diagnostic_status(self):
        """The DiagnosticStatus of the rule in the module docstring: the session's health and
        values (session/status.py), with the node's own counts."""
        s = self.session
        h = s.health()
        values = diagnostic_values(s, h, [('actuator_publishers', str(self.actuator_publishers)),
                                          ('internal_errors', str(self.internal_errors)),
                                          ('odom_lost_event', str(self.odom_lost_event))])
        return DiagnosticStatus(level=LEVELS[h.level], name=STATUS_NAME, message=h.message,
                                hardware_id=s.vehicle.name,
                                values=[KeyValue(key=k, value=v) for k, v in values])

    def check_actuator_publisher(self):
        """Live staleness rule: a held command is the norm (drivers publish on change), so
        odometry is not dropped for an old command (unless max_command_age is set); what tells
        that the actuator topic stopped is that no publisher is left. Then warn (rate-limited)
        while odometry still arrives. Returns the number of publishers."""
        # commands on several topics: the one with the fewest publishers tells
        count = min(sub.get_publisher_count() for sub in self.sub_commands)
        accepted = self.session.counters.odom_accepted
        if count == 0 and accepted > self._odom_at_last_check:
            line = self._warn_limit(('actuators', 'no publisher'),
                                    'actuators: no publisher left on the actuator topic while '
                                    'odometry arrives: the last command is held (set '
                                    'max_command_age to reject odometry instead)')
            if line:
                self._emit('warning', line)
        self._odom_at_last_check = accepted
        return count

    def _on_message_lost(self, info):
        """rclpy's message-lost event of the odom subscription (total_count: lost so far)."""
        self.odom_lost_event = int(info.total_count)

    def check_lost(self):
        """Warn (rate-limited) when odometry was lost before the node read it: counted from the
        gaps in the stamps (session/status.py StampGaps), or the middleware's event if that
        says more. Returns the count."""
        gaps = self.session.odom_gaps
        lost = max(gaps.lost, self.odom_lost_event)
        if lost > self._lost_reported:
            expected = max(gaps.expected, gaps.seen + lost)
            rate = 1.0 / gaps.interval_s if gaps.interval_s > 0 else math.nan
            line = self._warn_limit(
                ('odom', 'lost'),
                f'odom: {lost} messages lost before the identifier read them '
                f'({100.0 * lost / expected:.0f} % of the {expected} the stamps imply at '
                f'{rate:.0f} Hz; /diagnostics odom_lost): odometry arrives faster than the '
                f'identifier takes it and the subscription queue (KEEP_LAST, depth '
                f'{STREAM_QOS.depth}) drops the oldest. Publish odometry at a lower rate (200 '
                'Hz is measured to keep up, docs/speed.md) or give the node a core of its own; '
                'a deeper queue only absorbs bursts')
            if line:
                self._emit('warning', line)
                self._lost_reported = lost
        return lost

    def on_timer(self):
        """1 Hz: /diagnostics, the actuator topic's publisher check, the lost-odometry check
        and the autosave of the estimate file."""
        self.actuator_publishers = self.check_actuator_publisher()
        self.check_lost()
        if self.session.auto is not None:
            # a choice that finished while no message arrived switches now
            self.session.poll_choice()
            self._follow_choice(diagnostics=False)
        # so does a noise re-run
        self.session.poll_noise()
        self._noise_news()
        self.publish_diagnostics()
        now = time.monotonic()
        if (self.save_path and now - self._last_autosave >= AUTOSAVE_PERIOD_S
                and self.session.counters.odom_accepted != self._saved_steps):
            self._last_autosave = now
            ok, message = self.save()
            if not ok:
                line = self._error_limit(('save', 'autosave'), message)
                if line:
                    self._emit('error', line)

    def publish_diagnostics(self):
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [self.diagnostic_status()]
        self.pub_diagnostics.publish(arr)

    # -- services and files --

    def save(self):
        """Write the estimate file; returns (ok, message)."""
        if not self.save_path:
            return False, 'save_path parameter is empty: nothing written'
        doc = self.session.document()
        try:
            path = write_estimate_json(self.save_path, doc)
        except (OSError, ValueError) as err:
            return False, f'cannot write {self.save_path}: {err}'
        self._saved_steps = doc['steps']
        return True, f'wrote {path} ({doc["steps"]} updates)'

    def on_save(self, request, response):
        self.intake.take()      # what arrived before the request is in the file
        response.success, response.message = self.save()
        if response.success:
            self.get_logger().info(response.message)
        else:
            self.get_logger().warning(response.message)
        return response

    def on_reset(self, request, response):
        self.intake.take()      # what arrived before the request goes to the filter it had
        self.session.reset()
        response.success = True
        response.message = 'filter restarted from the start-up configuration'
        self.get_logger().info(response.message)
        return response

    def shutdown_save(self):
        """On shutdown: write save_path if set, and log the final estimate. False when the
        file could not be written (the process then exits 2: a mission's estimate lost is
        no success)."""
        if self.raw is not None:
            self._final_log('INFO', self.raw.final_line())
            if not self.save_path:
                return True
            ok, message = self.raw.save()
            self._final_log('INFO' if ok else 'ERROR', message)
            return ok
        est, cov = self.session.best()
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        counters = self.session.counters
        self._final_log('INFO', f'{counters.odom_accepted} updates, {counters.odom_rejected} '
                                f'rejected, {counters.errors} filter resets; last good '
                                'estimate: ' + ', '.join(
                                    f'{n} = {v:.6g} +- {s:.2g}'
                                    for n, v, s in zip(self.names, est, std)))
        if self.save_path:
            ok, message = self.save()
            self._final_log('INFO' if ok else 'ERROR', message)
            return ok
        return True

    def messages_taken(self):
        """How many messages the input subscriptions' callbacks have taken."""
        return self.taken if self.raw is None else self.raw.taken

    def _final_log(self, level, message):
        # After SIGINT/SIGTERM the context is already shut down and every log call would add
        # 'Failed to publish log message to rosout': write to the console directly then.
        if self.context.ok():
            if level == 'INFO':
                self.get_logger().info(message)
            else:
                self.get_logger().error(message)
        else:
            print(f'[{level}] [{self.get_name()}]: {message}', file=sys.stderr, flush=True)


def _set_linear(msg, linear):
    """twist.twist.linear of a TwistWithCovarianceStamped from 3 values (m/s)."""
    lin = msg.twist.twist.linear
    lin.x, lin.y, lin.z = (float(v) for v in linear)


def main(args=None):
    """Entry point: identify until SIGINT/SIGTERM (0), or exit 2 on a bad parameter (a
    save_path whose folder is missing or read-only included) or when the final save fails."""
    return run_node('identifier', args, __doc__, '-p vehicle:=nps_auv2', IdentifierNode,
                    _identify, finish=lambda node: node.shutdown_save())


def _identify(node, stop):
    # a stop drains what DDS already received (toolkit.drain): a bag's last messages, played
    # just before the SIGINT, are in the saved estimate
    spin(node, stop, taken=node.messages_taken)


if __name__ == '__main__':
    sys.exit(main())
