"""The identifier node's raw-sensor branch: an input map with raw sensors (IMU, DVL, pressure,
pose; docs/raw_sensors.md) makes ros/identifier_node.py hand its work to :class:`RawLive`,
which drives a session/raw_session.py :class:`RawSession` message by message.

Subscriptions: one per input of the map, with its type (RELIABLE, KEEP_LAST 1000, as the
odometry path's), the commands first, taken as ``intake_period_s`` says (ros/intake.py: in
batches every 20 ms by default, in the order they were published); an IMU's raw, its bytes read
by ros/cdr.py ImuView.
Publications as the odometry path's: ``~/estimate``
(JointState: names, estimates, 1-sigma) and ``~/covariance`` (Float64MultiArray, p x p) after
every fused sensor message (with ``publish_rate_hz`` > 0: the first in each 1/rate interval of
stamps), latched; ``/diagnostics`` every 1 s and at once on a filter
restart (RawSession.health and diagnostic_values). The services ``~/reset`` (restart the
filter) and ``~/save`` (write ``save_path``: the estimate file with 'input_mode' 'raw sensors'
and the sensor errors; also at shutdown) as on the odometry path.
"""
from array import array

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from std_srvs.srv import Trigger

from auv_ident.ros.cdr import estimate_templates, ImuView, UndecodableMessage
from auv_ident.ros.intake import Intake
from auv_ident.ros.toolkit import (
    DIAGNOSTICS_QOS,
    identifier_status,
    LATCHED_QOS,
    message_class,
    STREAM_QOS,
)
from auv_ident.session.estimate_file import write_estimate_json
from auv_ident.session.input_map import IMU
from auv_ident.session.messages import NS_PER_S, PublishGate
from auv_ident.session.raw_session import RawSession


class RawLive:
    """The raw-sensor side of ``node`` (module docstring); settings : IdentifierSettings."""

    def __init__(self, node, settings):
        self.node = node
        self.session = RawSession(settings)
        self.session.warm_up()
        self.taken = 0      # messages the subscriptions' callbacks took (the stop's drain)
        self._publish_gate = PublishGate(settings.publish_rate_hz)
        names = self.session.names
        p = len(names)
        joined = ','.join(names)
        self._estimate = JointState(name=list(names))
        self._templates = None      # (estimate, covariance) PayloadTemplates, at the first update
        self._covariance = Float64MultiArray()
        self._covariance.layout.dim = [
            MultiArrayDimension(label='row:' + joined, size=p, stride=p * p),
            MultiArrayDimension(label='col:' + joined, size=p, stride=p)]
        self.pub_estimate = node.create_publisher(JointState, '~/estimate', LATCHED_QOS)
        self.pub_covariance = node.create_publisher(Float64MultiArray, '~/covariance',
                                                    LATCHED_QOS)
        self.pub_diagnostics = node.create_publisher(DiagnosticArray, '/diagnostics',
                                                     DIAGNOSTICS_QOS)
        imap = self.session.input_map
        inputs = imap.commands + imap.sensors
        self.intake = Intake.for_inputs(node, settings.intake_period_s, imap.inputs)
        self.subscriptions = []
        for entry in inputs:
            cls = message_class(entry.type, entry.topic)
            if entry.type == IMU:
                # the fast stream read from its CDR bytes (ros/cdr.py ImuView)
                callback, raw = self._imu_callback(entry.name, cls), True
            else:
                callback, raw = (lambda msg, receive_ns, name=entry.name:
                                 self.on_input(name, msg, receive_ns)), False
            self.subscriptions.append(self.intake.subscribe(cls, entry.topic, callback,
                                                            STREAM_QOS, raw=raw))
        self.srv_reset = node.create_service(Trigger, '~/reset', self.on_reset)
        self.srv_save = node.create_service(Trigger, '~/save', self.on_save)
        self.timer = node.create_timer(1.0, self.publish_diagnostics,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))
        node.get_logger().info(
            f'identifying {", ".join(names)} of {self.session.vehicle.name} from raw sensors ('
            + ', '.join(f'{e.name} on {e.topic}' for e in imap.sensors) + ')')

    def _imu_callback(self, name, cls):
        """The callback of IMU input `name`'s raw subscription: its bytes through one reused
        ImuView into :meth:`on_input`; bytes the view cannot read (not XCDR1) go through
        rclpy, and bytes neither reads are one rejected conversion."""
        view = ImuView()

        def on_payload(payload, receive_ns=None):
            if view.read(payload):
                return self.on_input(name, view, receive_ns)
            try:
                msg = deserialize_message(payload, cls)
            except Exception as err:             # noqa: BLE001 - undecodable bytes
                msg = UndecodableMessage(f'{type(err).__name__}: {err}')
            return self.on_input(name, msg, receive_ns)
        return on_payload

    def on_input(self, name, msg, receive_ns=None):
        """One message of the map's input `name`; returns the session's Event."""
        self.taken += 1
        s = self.session
        if receive_ns is None and not s.input_entry(name).stamped:
            receive_ns = self.intake.receive_ns()
        ev = s.on_input(name, msg, receive_ns)
        if ev.kind == 'update' and self._publish_gate.due(ev.stamp_ns):
            self.publish_estimate(ev)
        elif ev.kind == 'error':
            self.node.get_logger().error(ev.reason)
            self.publish_diagnostics()
        return ev

    def publish_estimate(self, ev):
        """~/estimate and ~/covariance of an update Event: as bytes, serialized templates
        refilled in place (ros/cdr.py PayloadTemplate: 36 -> ~10 us per update, the
        messages' conversion by rclpy avoided), or as messages where a template cannot be
        built."""
        if not self.node.context.ok():
            return
        if self._templates is None:
            self._templates = estimate_templates(self._estimate, self._covariance,
                                                 len(self.session.names), serialize_message)
        sec, nanosec = divmod(int(ev.stamp_ns), NS_PER_S)
        est_t, cov_t = self._templates
        if est_t is not None and cov_t is not None:
            self.pub_estimate.publish(est_t.fill(sec, nanosec, ev.estimate, ev.std))
            self.pub_covariance.publish(cov_t.fill(sec, nanosec, ev.cov))
            return
        est = self._estimate
        est.header.stamp.sec, est.header.stamp.nanosec = sec, nanosec
        est.position = array('d', np.ascontiguousarray(ev.estimate, dtype=float).tobytes())
        est.velocity = array('d', np.ascontiguousarray(ev.std, dtype=float).tobytes())
        self.pub_estimate.publish(est)
        self._covariance.data = array('d', np.ascontiguousarray(ev.cov, dtype=float).tobytes())
        self.pub_covariance.publish(self._covariance)

    def diagnostic_status(self):
        s = self.session
        h = s.health()
        return identifier_status(h, s.vehicle.name, s.diagnostic_values())

    def publish_diagnostics(self):
        if not self.node.context.ok():
            return
        arr = DiagnosticArray()
        arr.header.stamp = self.node.get_clock().now().to_msg()
        arr.status = [self.diagnostic_status()]
        self.pub_diagnostics.publish(arr)

    def on_reset(self, request, response):
        self.intake.take()      # what arrived before the request goes to the filter it had
        self.session.reset()
        response.success = True
        response.message = 'raw-sensor filter restarted from the start-up configuration'
        return response

    def save(self):
        """Write the node's save_path (session RawSession.document); returns (ok, message)."""
        path = self.node.save_path
        if not path:
            return False, 'save_path parameter is empty: nothing written'
        doc = self.session.document()
        try:
            out = write_estimate_json(path, doc)
        except (OSError, ValueError) as err:
            return False, f'cannot write {path}: {err}'
        return True, f'wrote {out} ({doc["steps"]} updates)'

    def on_save(self, request, response):
        self.intake.take()      # what arrived before the request is in the file
        response.success, response.message = self.save()
        return response

    def final_line(self):
        """The final estimate as one log line."""
        ev = self.session.last_good
        c = self.session.counters
        head = (f'raw sensors: fused {sum(c.fused.values())} messages, {c.commands} commands, '
                f'{c.errors} filter restarts; last estimate: ')
        if ev is None:
            return head + 'none'
        return head + ', '.join(f'{n} = {v:.6g} +- {s:.2g}'
                                for n, v, s in zip(self.session.names, ev.estimate, ev.std))
