"""The identifier node's odometry path: an input map of odometry and commands (the default,
odom_actuators) makes ros/identifier_node.py hand its work to :class:`OdomLive`, which drives a
session/session.py :class:`IdentSession` message by message, as ros/raw_live.py RawLive drives
the raw-sensor path.

What it subscribes to, publishes and serves (``~/estimate``, ``~/covariance``, ``~/current``,
``/diagnostics``, ``~/reset``, ``~/save``), its log lines and the estimate file: the module
docstring of ros/identifier_node.py (the node's ``--help``).
"""
from array import array
import copy
import math
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TwistWithCovarianceStamped
from nav_msgs.msg import Odometry
import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
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
from auv_ident.ros.intake import Intake
from auv_ident.ros.toolkit import (
    DIAGNOSTICS_QOS,
    identifier_status,
    LATCHED_QOS,
    message_class,
    STREAM_QOS,
)
from auv_ident.session.auto_choice import run_in_thread
from auv_ident.session.estimate_file import write_estimate_json
from auv_ident.session.messages import (
    current_indices,
    current_twist_fields,
    DEFAULT_FRAME_IDS,
    NS_PER_S,
    PublishGate,
)
from auv_ident.session.session import Event, IdentSession
from auv_ident.session.status import diagnostic_values
from auv_ident.session.warning_limiter import WarningLimiter

DIAGNOSTICS_PERIOD_S = 1.0
WARN_THROTTLE_S = 5.0
ERROR_THROTTLE_S = 1.0
AUTOSAVE_PERIOD_S = 10.0


class OdomLive:
    """The odometry side of ``node`` (an IntakeNode with a ``save_path``; ros/identifier_node.py
    module docstring); settings : IdentifierSettings."""

    def __init__(self, node, settings):
        self.node = node
        self.taken = 0      # messages the subscriptions' callbacks took (the stop's drain)
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
        self.pub_estimate = self.node.create_publisher(JointState, '~/estimate', LATCHED_QOS)
        self.pub_covariance = self.node.create_publisher(Float64MultiArray, '~/covariance',
                                                         LATCHED_QOS)
        self.pub_diagnostics = self.node.create_publisher(DiagnosticArray, '/diagnostics',
                                                          DIAGNOSTICS_QOS)
        # the water current, when estimated: ~/current (identifier_node.py, docs/current.md)
        self.pub_current = None
        if any(i >= 0 for i in self._current_index):
            self._current = TwistWithCovarianceStamped()
            # the world frame of the convention, set at each publication: with frame 'auto'
            # the first odometry decides it
            self.pub_current = self.node.create_publisher(TwistWithCovarianceStamped,
                                                          '~/current', LATCHED_QOS)
        self._subscribe_inputs()
        self.srv_reset = self.node.create_service(Trigger, '~/reset', self.on_reset)
        self.srv_save = self.node.create_service(Trigger, '~/save', self.on_save)
        self.diagnostics_timer = self.node.create_timer(
            DIAGNOSTICS_PERIOD_S, self.on_timer,
            clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.node.get_logger().info(
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
        self.intake = Intake.for_inputs(self.node, self.session.settings.intake_period_s,
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
        if not self.node.context.ok():   # shutting down
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
        logger = self.node.get_logger()
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
        if (ev.kind == 'error' or rerun) and self.node.context.ok():
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
        if not self.node.context.ok():   # shutting down
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
        """The DiagnosticStatus of the rule in ros/identifier_node.py's docstring: the session's
        health and values (session/status.py), with the node's own counts."""
        s = self.session
        h = s.health()
        values = diagnostic_values(s, h, [('actuator_publishers', str(self.actuator_publishers)),
                                          ('internal_errors', str(self.internal_errors)),
                                          ('odom_lost_event', str(self.odom_lost_event))])
        return identifier_status(h, s.vehicle.name, values)

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
        if (self.node.save_path and now - self._last_autosave >= AUTOSAVE_PERIOD_S
                and self.session.counters.odom_accepted != self._saved_steps):
            self._last_autosave = now
            ok, message = self.save()
            if not ok:
                line = self._error_limit(('save', 'autosave'), message)
                if line:
                    self._emit('error', line)

    def publish_diagnostics(self):
        arr = DiagnosticArray()
        arr.header.stamp = self.node.get_clock().now().to_msg()
        arr.status = [self.diagnostic_status()]
        self.pub_diagnostics.publish(arr)

    # -- services and files --

    def save(self):
        """Write the estimate file; returns (ok, message)."""
        if not self.node.save_path:
            return False, 'save_path parameter is empty: nothing written'
        doc = self.session.document()
        try:
            path = write_estimate_json(self.node.save_path, doc)
        except (OSError, ValueError) as err:
            return False, f'cannot write {self.node.save_path}: {err}'
        self._saved_steps = doc['steps']
        return True, f'wrote {path} ({doc["steps"]} updates)'

    def on_save(self, request, response):
        self.intake.take()      # what arrived before the request is in the file
        response.success, response.message = self.save()
        if response.success:
            self.node.get_logger().info(response.message)
        else:
            self.node.get_logger().warning(response.message)
        return response

    def on_reset(self, request, response):
        self.intake.take()      # what arrived before the request goes to the filter it had
        self.session.reset()
        response.success = True
        response.message = 'filter restarted from the start-up configuration'
        self.node.get_logger().info(response.message)
        return response

    def final_line(self):
        """The final estimate as one log line: the last good estimate (the start-up one before
        any), with the counts."""
        est, cov = self.session.best()
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        counters = self.session.counters
        return (f'{counters.odom_accepted} updates, {counters.odom_rejected} rejected, '
                f'{counters.errors} filter resets; last good estimate: ' + ', '.join(
                    f'{n} = {v:.6g} +- {s:.2g}' for n, v, s in zip(self.names, est, std)))


def _set_linear(msg, linear):
    """twist.twist.linear of a TwistWithCovarianceStamped from 3 values (m/s)."""
    lin = msg.twist.twist.linear
    lin.x, lin.y, lin.z = (float(v) for v in linear)
