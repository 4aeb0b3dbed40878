"""Online identification of hydrodynamic coefficients: ``ros2 run auv_ident identifier``.

Thin layer over :class:`auv_ident.replay.IdentSession` (message conversion, rejection policy,
the augmented EKF through core.stream.StreamIdentifier, recovery, health rule). Offline,
:func:`auv_ident.replay.replay_bag` drives the same class with a bag's messages in log-time
order, so a recorded run replays to the same estimates.

Subscriptions (RELIABLE, KEEP_LAST depth 1000, VOLATILE: no loss at 200 Hz while the callback
is busy, see shared/ros_stack.md section 2; a BEST_EFFORT publisher cannot feed these)
    ``actuators`` sensor_msgs/JointState: commands (conversions.py layout). Created before
        ``odom``, so when both are waiting the executor takes the command first.
    ``odom`` nav_msgs/Odometry: measured state, in the convention of ``frame``; the message
        covariances are ignored (``noise_std`` is the noise model).

Publications
    ``~/estimate`` sensor_msgs/JointState, one per accepted odometry update: header.stamp = the
        odometry stamp; name = coefficient names; position = estimates (vehicle file's units);
        velocity = 1-sigma; effort empty.
    ``~/covariance`` std_msgs/Float64MultiArray, with each estimate: layout.dim[0] = label
        'row:' + comma-joined names, size p, stride p*p; dim[1] = 'col:' + names, size p,
        stride p; data = the p x p covariance, row-major.
    Both RELIABLE + TRANSIENT_LOCAL, depth 1: a late subscriber gets the latest estimate at
    once. Depth 1 keeps only the latest: a slow reader can miss intermediate estimates (the
    count of updates is in /diagnostics; replay_bag gives every one).
    ``/diagnostics`` diagnostic_msgs/DiagnosticArray, every 1 s (steady clock) and at once on a
    filter error: one DiagnosticStatus, name 'auv_ident identifier', hardware_id = vehicle,
    level and message from IdentSession.health:
        WARN 'waiting for data': no update since start-up or the last restart;
        ERROR 'diverging': a core error (DomainError/DivergenceError) within the last 200
            updates, or the mean NIS/dof over the last 200 updates > 10x its band;
        WARN 'diverging': 200 updates in the window and mean NIS/dof above the two-sided
            99.9 % chi-square band of the window (sum of NIS over sum of dof);
        OK 'converged': window full, mean NIS/dof not above the band, and every coefficient's
            1-sigma < 5 % of |estimate|;
        OK 'converging': otherwise.
    values: accepted, rejected (odometry), commands, commands_rejected, errors, last_error,
    mean_nis_per_dof, nis_band, nis_window, last_nis, last_dof, last_stamp, then per
    coefficient <name> and <name>_std (repr floats), R_<channel> (adapted measurement variance
    of u ... psi) and Q_<name> (coefficient random-walk variance).

Services (std_srvs/srv/Trigger)
    ``~/reset``: restart the filter from the start-up configuration (initial guesses or warm
        start); buffered commands, counters and the last good estimate are kept.
    ``~/save``: write the estimate file to ``save_path`` (fails if save_path is empty).

Errors never stop the node: rejected messages (conversion errors, non-finite fields, stamps not
after the previous one, no command yet) are rate-limited warnings naming the problem. A core
error is logged as an error and reported as ERROR on /diagnostics; the filter restarts from its
start-up configuration and the last good estimate stays available (it is what ~/save writes
until the restarted filter has an estimate). Nothing non-finite is published.

Estimate file (``save_path``, ``warm_start``): JSON ``{"vehicle", "coefficients": [names],
"estimate": [...], "std": [...], "covariance": [[...]], "stamp": s or null, "stamp_ns": int or
null, "steps": accepted updates}`` (auv_ident/replay.py). Written on ``~/save`` and on shutdown
(SIGINT/SIGTERM), atomically.

Parameters (``config/identifier.yaml`` documents each with units and default; read once at
start-up, declared read-only)
    ``vehicle`` ('nps_auv2'), ``coefficients`` (empty = the vehicle's identify_default),
    ``initial`` (empty = file value * (1 + initial_offset)), ``initial_offset`` (0.5),
    ``noise_mode`` ('fixed' | 'paper' | 'paper_q' | 'matching'), ``tau`` (10.0 s), ``lam``
    (the paper's lambda, 2e-3; ``lambda`` would shadow a Python keyword in code),
    ``noise_std`` (12, DEFAULT_NOISE_STD), ``q_state`` (12, DEFAULT_Q_STATE), ``p0_rel``
    (1.0), ``q_theta_rel`` (1e-5), ``measured`` (channel names, default all 12), ``frame``
    ('ned' | 'enu'), ``sample_time`` (0.05 s), ``max_gap`` (5.0 s), ``mass_inverse``
    ('default'), ``save_path`` (''), ``warm_start`` (''). An empty list means the default
    (ROS turns ``[]`` into "not set"). Bad values print one line naming the parameter and exit
    with status 2.
"""
import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import Odometry
import numpy as np
from rcl_interfaces.msg import ParameterDescriptor
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import (InvalidParameterTypeException, ParameterException,
                               ParameterUninitializedException)
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from std_srvs.srv import Trigger

from auv_ident.conversions import ns_to_stamp
from auv_ident.core.ekf import MODES
from auv_ident.core.errors import AuvIdentError
from auv_ident.core.identify import DEFAULT_Q_STATE
from auv_ident.core.simulate import DEFAULT_NOISE_STD
from auv_ident.core.vehicle import STATE_NAMES
from auv_ident.replay import IdentSession, write_estimate_json

RCLError = _rclpy.RCLError
NODE_NAME = 'identifier'
STATUS_NAME = 'auv_ident identifier'
DIAGNOSTICS_PERIOD_S = 1.0
WARN_THROTTLE_S = 5.0
ERROR_THROTTLE_S = 1.0
LEVELS = {'OK': DiagnosticStatus.OK, 'WARN': DiagnosticStatus.WARN,
          'ERROR': DiagnosticStatus.ERROR}

INPUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
DIAGNOSTICS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                             reliability=ReliabilityPolicy.RELIABLE)

_PARAMETERS = (
    # name, default (or type when empty by default), description
    ('vehicle', 'nps_auv2', 'vehicle name (config/<name>.yaml) or vehicle YAML path'),
    ('coefficients', Parameter.Type.STRING_ARRAY,
     "coefficients to identify; empty = the vehicle file's identify_default"),
    ('initial', Parameter.Type.DOUBLE_ARRAY,
     "initial guesses, same order [vehicle file's units]; empty = truth * (1 + "
     'initial_offset)'),
    ('initial_offset', 0.5, 'relative offset of the initial guesses from the file values when '
                            'initial is empty [-]'),
    ('noise_mode', 'fixed', 'noise adaptation: ' + ', '.join(MODES)),
    ('tau', 10.0, 'time constant of the forgetting factor of the adaptation [s]'),
    ('lam', 2e-3, "the paper's lambda of the adaptation [-]"),
    ('noise_std', [float(v) for v in DEFAULT_NOISE_STD],
     'measurement noise 1-sigma of u v w [m/s], p q r [rad/s], x y z [m], phi theta psi [rad]'),
    ('q_state', [float(v) for v in DEFAULT_Q_STATE],
     'per-step process noise 1-sigma of the 12 states (units as noise_std)'),
    ('p0_rel', 1.0, 'initial 1-sigma of each coefficient, fraction of |initial guess| [-]'),
    ('q_theta_rel', 1e-5, 'per-step random-walk 1-sigma of each coefficient, fraction of '
                          '|initial guess| [-]'),
    ('measured', list(STATE_NAMES), 'measured channels among ' + ' '.join(STATE_NAMES)),
    ('frame', 'ned', "convention of the incoming Odometry: 'ned' or 'enu'"),
    ('sample_time', 0.05, 'nominal sample time and longest single prediction step [s]'),
    ('max_gap', 5.0, 'a longer gap between odometry stamps restarts the vehicle states '
                     '(coefficients kept) [s]'),
    ('mass_inverse', 'default', "M^-1: 'default' (vehicle file's choice), 'exact' or "
                                "'mss_literal'"),
    ('save_path', '', 'estimate JSON written on ~/save and on shutdown; empty = none'),
    ('warm_start', '', 'estimate JSON to start from (estimate and covariance); empty = none'),
)


class IdentifierNode(Node):
    """Identify coefficients online from ``odom`` and ``actuators`` (module docstring)."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self._declare_parameters()
        settings = self._read_parameters()
        self.save_path = settings.pop('save_path')
        self.session = IdentSession(**settings)      # ParameterError names a bad parameter
        self.names = list(self.session.names)
        p = len(self.names)
        joined = ','.join(self.names)
        self._layout = [MultiArrayDimension(label='row:' + joined, size=p, stride=p * p),
                        MultiArrayDimension(label='col:' + joined, size=p, stride=p)]
        # Load (or compile) the EKF now, before subscribing: a publisher that waits for our
        # subscriptions then never finds us busy with numba.
        self.session.warm_up()
        self.pub_estimate = self.create_publisher(JointState, '~/estimate', LATCHED_QOS)
        self.pub_covariance = self.create_publisher(Float64MultiArray, '~/covariance',
                                                    LATCHED_QOS)
        self.pub_diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics',
                                                     DIAGNOSTICS_QOS)
        self.sub_actuators = self.create_subscription(JointState, 'actuators',
                                                      self.on_actuators, INPUT_QOS)
        self.sub_odom = self.create_subscription(Odometry, 'odom', self.on_odom, INPUT_QOS)
        self.srv_reset = self.create_service(Trigger, '~/reset', self.on_reset)
        self.srv_save = self.create_service(Trigger, '~/save', self.on_save)
        self.diagnostics_timer = self.create_timer(
            DIAGNOSTICS_PERIOD_S, self.publish_diagnostics,
            clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(
            f'identifying {", ".join(self.names)} of {self.session.vehicle.name} '
            f'(noise mode {settings["noise_mode"]}, frame {self.session.frame}, initial '
            f'{np.array2string(self.session.theta0, precision=5)})')

    # -- parameters --

    def _declare_parameters(self):
        # read_only: they are read once at start-up; `ros2 param set` is refused, not ignored
        for name, default, text in _PARAMETERS:
            self.declare_parameter(name, default,
                                   ParameterDescriptor(description=text, read_only=True))

    def _param(self, name):
        """A parameter's value, or None if it is not set (ROS maps '[]' to not set)."""
        try:
            return self.get_parameter(name).value
        except ParameterUninitializedException:
            return None

    def _read_parameters(self):
        """Parameters as IdentSession keywords (it validates them, naming the parameter)."""
        out = {name: self._param(name) for name, _, _ in _PARAMETERS}
        for name in ('coefficients', 'initial', 'measured'):
            out[name] = list(out[name] or [])
        for name in ('noise_std', 'q_state'):
            out[name] = None if not out[name] else list(out[name])
        return out

    # -- messages --

    def on_actuators(self, msg):
        """Buffer an actuator command; returns the session's Event."""
        ev = self.session.on_actuators(msg)
        if ev.kind == 'rejected':
            self.get_logger().warning(f'rejected {ev.reason}',
                                      throttle_duration_sec=WARN_THROTTLE_S)
        return ev

    def on_odom(self, msg):
        """Fuse an odometry measurement and publish the estimate; returns the Event."""
        ev = self.session.on_odom(msg)
        if ev.kind == 'update':
            self.publish_estimate(ev)
            if ev.reason:
                self.get_logger().info(ev.reason, throttle_duration_sec=WARN_THROTTLE_S)
        elif ev.kind == 'rejected':
            self.get_logger().warning(f'rejected {ev.reason}',
                                      throttle_duration_sec=WARN_THROTTLE_S)
        elif ev.kind == 'error':
            self.get_logger().error(ev.reason, throttle_duration_sec=ERROR_THROTTLE_S)
            self.publish_diagnostics()
        return ev

    def publish_estimate(self, ev):
        """Publish ~/estimate and ~/covariance of an update Event (finite by construction:
        IdentSession turns a non-finite estimate into a filter error)."""
        if not (np.all(np.isfinite(ev.estimate)) and np.all(np.isfinite(ev.cov))):
            return
        if not self.context.ok():   # shutting down (SIGINT during a callback)
            return
        est = JointState()
        est.header.stamp = ns_to_stamp(ev.stamp_ns)
        est.name = list(self.names)
        est.position = [float(v) for v in ev.estimate]
        est.velocity = [float(v) for v in ev.std]
        est.effort = []
        cov = Float64MultiArray()
        cov.layout.dim = list(self._layout)
        cov.layout.data_offset = 0
        cov.data = [float(v) for v in np.asarray(ev.cov).ravel()]
        self.pub_estimate.publish(est)
        self.pub_covariance.publish(cov)

    # -- diagnostics --

    def diagnostic_status(self):
        """The DiagnosticStatus of the rule in the module docstring."""
        s = self.session
        h = s.health()
        f = s.stream.ekf
        est, cov = s.current()
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))

        def num(v):
            v = float(v)
            return repr(v) if np.isfinite(v) else 'n/a'

        values = [('accepted', str(s.odom_accepted)), ('rejected', str(s.odom_rejected)),
                  ('commands', str(s.cmd_accepted)),
                  ('commands_rejected', str(s.cmd_rejected)),
                  ('errors', str(s.errors)), ('last_error', s.last_error),
                  ('mean_nis_per_dof', num(h.mean_nis_per_dof)),
                  ('nis_band', f'{num(h.band[0])} {num(h.band[1])}'),
                  ('nis_window', str(h.window)),
                  ('last_nis', num(s.last_nis)), ('last_dof', str(s.last_dof)),
                  ('last_stamp', 'n/a' if s.last_good is None
                   else num(s.last_good.stamp_ns * 1e-9))]
        for name, v, sd in zip(self.names, est, std):
            values += [(name, num(v)), (name + '_std', num(sd))]
        values += [('R_' + n, num(v)) for n, v in zip(STATE_NAMES, np.diag(f.R))]
        values += [('Q_' + n, num(v)) for n, v in zip(self.names, np.diag(f.Q)[12:])]
        return DiagnosticStatus(level=LEVELS[h.level], name=STATUS_NAME, message=h.message,
                                hardware_id=s.vehicle.name,
                                values=[KeyValue(key=k, value=v) for k, v in values])

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
        try:
            path = write_estimate_json(self.save_path, self.session.document())
        except (OSError, ValueError) as err:
            return False, f'cannot write {self.save_path}: {err}'
        return True, f'wrote {path} ({self.session.odom_accepted} updates)'

    def on_save(self, request, response):
        response.success, response.message = self.save()
        if response.success:
            self.get_logger().info(response.message)
        else:
            self.get_logger().warning(response.message)
        return response

    def on_reset(self, request, response):
        self.session.reset()
        response.success = True
        response.message = 'filter restarted from the start-up configuration'
        self.get_logger().info(response.message)
        return response

    def shutdown_save(self):
        """On shutdown: write save_path if set, and log the final estimate."""
        est, cov = self.session.current()
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        self._final_log('INFO', f'{self.session.odom_accepted} updates, '
                                f'{self.session.odom_rejected} rejected, {self.session.errors} '
                                'errors; estimate: ' + ', '.join(
                                    f'{n} = {v:.6g} +- {s:.2g}'
                                    for n, v, s in zip(self.names, est, std)))
        if self.save_path:
            ok, message = self.save()
            self._final_log('INFO' if ok else 'ERROR', message)

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


def _type_hint(err):
    if isinstance(err, InvalidParameterTypeException) and "'DOUBLE'" in str(err):
        return ' (write floats with a decimal point, e.g. 5.0)'
    return ''


def main(args=None):
    """Entry point: identify until SIGINT/SIGTERM (0), or exit 2 on a bad parameter."""
    try:
        rclpy.init(args=args)
    except RCLError as err:     # unparsable --ros-args (rcl has logged the details)
        print(f'identifier: error: {err}', file=sys.stderr)
        return 2
    try:
        node = IdentifierNode()
    except (AuvIdentError, ParameterException) as err:
        print(f'identifier: error: {err}' + _type_hint(err), file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    except KeyboardInterrupt:
        rclpy.try_shutdown()
        return 0
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RCLError:
        if rclpy.ok():      # a real error, not a signal that invalidated the context
            raise
    finally:
        node.shutdown_save()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
