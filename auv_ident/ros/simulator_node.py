"""Simulated AUV: ``ros2 run auv_ident simulator`` (or ``python -m auv_ident run simulator``).

The whole run is computed at start-up with :func:`auv_ident.core.simulation.simulate.simulate`
(deterministic: same parameters, same messages), then a timer publishes sample k's messages,
built by :func:`auv_ident.ros.sim_messages.sample_messages` (the messages a simulated bag holds).
When the run is over the node logs a summary and exits with status 0.

Publications (relative names: ``-r __ns:=/auv1`` moves them)
    ``actuators`` sensor_msgs/JointState: command u_k held over [t_k, t_k+1), stamped t_k
        (layout in conversions.py). Published first in each sample, so a subscriber has the
        command before the odometry of the same stamp.
    ``odom`` nav_msgs/Odometry: MEASURED state y_k (sensor noise added), stamped t_k; the
        covariances carry the noise model.
    ``~/truth`` nav_msgs/Odometry: the true state x_k (``/simulator/truth`` in the root
        namespace), for evaluation.
    ``/clock`` rosgraph_msgs/Clock: t_k, published before sample k's messages, when
        ``publish_clock`` is true.

Stamps are simulation time t_k = k / rate_hz from 0 (not wall time). Run consumers with
``use_sim_time:=true`` when ``/clock`` is published.

QoS
    actuators/odom/truth: RELIABLE, KEEP_LAST depth 1000, VOLATILE. KEEP_LAST with RELIABLE
    gives no back-pressure: a reader that falls behind loses the oldest samples once its queue
    is full. Measured on this stack (shared/ros_stack.md section 2): depth 1 lost 1-3 % at
    200 Hz and depth 10 lost the first samples after matching, depth 100+ lost nothing. Depth
    1000 absorbs 5 s of a 200 Hz stream (10x real time at 20 Hz) while a subscriber is busy,
    e.g. loading its compiled EKF. /clock: RELIABLE depth 100 (rclpy's time source subscribes
    BEST_EFFORT depth 1, which a RELIABLE writer serves). Profiles: ros/toolkit.py.

Parameters (``config/simulator.yaml``; read once at start-up, declared read-only)
    ``vehicle`` (str, 'nps_auv2')  vehicle name or YAML path.
    ``maneuver`` (str, 'ident')  ident, zigzag, steps, prbs, roll, or a CSV path.
    ``duration`` (float, 600.0 s)  length of the run.
    ``rate_hz`` (float, 20.0 Hz)  sample rate (sample time 1/rate_hz).
    ``seed`` (int, 0)  seed of the manoeuvre and of the noise.
    ``rpm`` (float, 0.0 rpm)  shaft speed; 0 = the vehicle's cruise rpm.
    ``frame`` ('ned' | 'enu', 'ned')  convention of the published Odometry.
    ``noise_std`` (12 floats)  measurement 1-sigma of u v w (m/s), p q r (rad/s), x y z (m),
        phi theta psi (rad); default core.simulation.simulate.DEFAULT_NOISE_STD.
    ``process_noise`` (bool, false)  add white accelerations
    (core.simulation.simulate.DEFAULT_PROCESS_STD). ``current`` (2 or 3 floats, [0, 0, 0] m/s)  a
    constant water current, NED (north, east[,
        down]; where the water goes); zeros = still water (docs/current.md).
    ``velocity_reference`` ('ground' | 'water', 'ground')  what the published twist.linear is:
        over ground (DVL in bottom lock) or through the water (water-track DVL).
    ``real_time_factor`` (float, 1.0)  >1 publishes faster than real time; 0 = as fast as
        possible (may outrun a subscriber, see QoS).
    ``publish_clock`` (bool, unset)  publish /clock; unset = true when real_time_factor != 1.
    ``wait_for_subscribers`` (string array, empty)  node names (``identifier``, or fully
        qualified ``/auv1/identifier``) to wait for before sample 0: each must subscribe to at
        least one of the topics above (/clock included) and every subscription the graph
        shows on them must be matched by our publishers; then 0.25 s more for the readers to
        match us.
    ``wait_timeout`` (float, 5.0 s)  give up waiting after this long (a warning) and start.

Bad parameter values (or types) print one line naming the parameter and exit with status 2;
SIGINT/SIGTERM stop publishing, exit 0 (ros/toolkit.py run_node).
"""
import math
import os
import sys
import time

from nav_msgs.msg import Odometry
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from auv_ident.core.errors import AuvIdentError, ConfigError
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.sensors import DEFAULT_NOISE_STD, DEFAULT_PROCESS_STD
from auv_ident.core.simulation.maneuvers import MANEUVERS, THRUSTER_MANEUVERS
from auv_ident.core.simulation.simulate import simulate
from auv_ident.offline.sim_bag import has_thrusters, SIM_EPOCH_NS
from auv_ident.ros.conversions import ns_to_stamp
from auv_ident.ros.sim_messages import (
    ACTUATOR_TOPIC,
    ODOM_TOPIC,
    sample_messages,
    THRUSTER_TOPIC,
    TRUTH_TOPIC,
)
from auv_ident.ros.toolkit import (
    choice,
    CLOCK_QOS,
    declare_parameters,
    number,
    Param,
    run_node,
    spin,
    STREAM_QOS,
    strings,
    SubscriberWait,
)
from auv_ident.session.messages import FRAMES, sec_to_ns
from auv_ident.session.settings import ParameterError
from auv_ident.vehicles import load_vehicle

NODE_NAME = 'simulator'
MIN_PERIOD_S = 1e-3       # timer period floor; faster rates publish several samples per tick
BURST = 10                # samples per tick when real_time_factor = 0
ACK_TIMEOUT_S = 2.0       # at the end: wait this long for reliable readers to acknowledge
MAX_SAMPLES = 10_000_000


def _vehicle(name, value):
    try:
        return load_vehicle(value)
    except ConfigError as err:
        raise ParameterError(name, str(err)) from None


def _maneuver(name, value):
    # the vehicle decides which of them fly (a thruster vehicle: THRUSTER_MANEUVERS); simulate
    # names the choices when the other kind is asked for
    if value not in MANEUVERS + THRUSTER_MANEUVERS and not os.path.isfile(value):
        raise ParameterError(name, f'{value!r} is neither one of '
                                   f'{", ".join(MANEUVERS + THRUSTER_MANEUVERS)} nor an '
                                   'existing CSV file')
    return value


def _noise_std(name, value):
    noise = [float(v) for v in (DEFAULT_NOISE_STD if value is None else value)]
    if len(noise) != 12 or not all(math.isfinite(v) and v >= 0 for v in noise):
        raise ParameterError(name, f'expected 12 finite non-negative 1-sigmas, got {noise}')
    return noise


def _current(name, value):
    current = [float(v) for v in (value or [])]
    if len(current) not in (0, 2, 3) or not all(math.isfinite(v) for v in current):
        raise ParameterError(name, f'expected north, east[, down] in m/s, got {current}')
    current = (current + [0.0] * 3)[:3] if current else None
    return current if current and any(current) else None


_PARAMETERS = (
    Param('vehicle', 'nps_auv2', 'vehicle name (config/<name>.yaml) or vehicle YAML path',
          _vehicle),
    Param('maneuver', 'ident', 'manoeuvre: ' + ', '.join(MANEUVERS) + ', or a CSV path; a '
          'thruster vehicle (ROV): ' + ', '.join(THRUSTER_MANEUVERS) + ' (ident: tank)',
          _maneuver),
    Param('duration', 600.0, 'length of the run [s]', number(above=0.0)),
    Param('rate_hz', 20.0, 'sample rate [Hz]; sample time = 1/rate_hz', number(above=0.0)),
    Param('seed', 0, 'seed of the manoeuvre and the noise [-]', number(minimum=0)),
    Param('rpm', 0.0, "shaft speed [rpm]; 0 = the vehicle's cruise rpm", number(minimum=0.0)),
    Param('frame', 'ned', "convention of the published Odometry: 'ned' (NED/FRD) or 'enu' "
                          '(REP-103)', choice(FRAMES)),
    Param('noise_std', [float(v) for v in DEFAULT_NOISE_STD],
          'measurement noise 1-sigma of u v w [m/s], p q r [rad/s], x y z [m], phi theta psi '
          '[rad]', _noise_std),
    Param('current', [0.0, 0.0, 0.0], 'constant water current north, east[, down], where the '
                                      'water goes (NED); zeros = still water [m/s]', _current),
    Param('velocity_reference', 'ground', "published twist.linear: 'ground' (DVL bottom lock) "
                                          "or 'water' (water-track DVL)",
          choice(('ground', 'water'))),
    Param('process_noise', False, 'add white acceleration noise (unmodelled forces) [-]'),
    Param('real_time_factor', 1.0, 'simulated s per wall s; >1 faster than real time, 0 = as '
                                   'fast as possible [-]', number(minimum=0.0)),
    Param('publish_clock', Parameter.Type.BOOL,
          'publish /clock; unset = true when real_time_factor != 1 [-]'),
    Param('wait_for_subscribers', Parameter.Type.STRING_ARRAY,
          'node names to wait for (subscribed and matched) before sample 0; empty = none',
          strings()),
    Param('wait_timeout', 5.0, 'longest wait for wait_for_subscribers [s]', number(minimum=0.0)),
)


class SimulatorNode(Node):
    """Publish a precomputed simulated run (see the module docstring)."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self._read_parameters()
        model = Model(self.vehicle)
        try:
            self.run = simulate(model, self.maneuver, duration=self.duration, T=self.T,
                                seed=self.seed, rpm=self.rpm, noise_std=self.noise_std,
                                process_std=DEFAULT_PROCESS_STD if self.process_noise else None,
                                current=self.current,
                                velocity_reference=self.velocity_reference)
        except AuvIdentError as err:
            name = 'rpm' if 'surge' in str(err) else 'maneuver'
            raise ParameterError(name, str(err)) from None
        self.n = len(self.run.t)
        self.k = 0
        self.finished = Future()
        self.exit_code = None
        # a thruster vehicle's PWM commands on 'thrusters' (config/inputs/<vehicle>.yaml),
        # the fin and propeller commands of the others on 'actuators'
        self.pub_actuators = (self.create_publisher(Float64MultiArray, 'thrusters', STREAM_QOS)
                              if has_thrusters(self.run)
                              else self.create_publisher(JointState, 'actuators', STREAM_QOS))
        self.pub_odom = self.create_publisher(Odometry, 'odom', STREAM_QOS)
        self.pub_truth = self.create_publisher(Odometry, '~/truth', STREAM_QOS)
        self.pub_clock = (self.create_publisher(ClockMsg, '/clock', CLOCK_QOS)
                          if self.publish_clock else None)
        self._routes = {ACTUATOR_TOPIC: self.pub_actuators, THRUSTER_TOPIC: self.pub_actuators,
                        ODOM_TOPIC: self.pub_odom, TRUTH_TOPIC: self.pub_truth}
        self._stream_pubs = (self.pub_actuators, self.pub_odom, self.pub_truth)
        # every subscription on our topics (/clock included) must be matched before sample 0
        self._wait = (SubscriberWait(self, self._stream_pubs + ((self.pub_clock,)
                                                                if self.pub_clock else ()),
                                     nodes=self.wait_for, timeout=self.wait_timeout)
                      if self.wait_for else None)
        self._t0 = None if self._wait else time.monotonic()
        rtf = self.real_time_factor
        period = MIN_PERIOD_S if rtf == 0 else max(MIN_PERIOD_S, self.T / rtf)
        # Steady clock: the publishing pace is wall time even if use_sim_time is set.
        self.timer = self.create_timer(period, self.step,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(
            f'{self.vehicle.title}: manoeuvre {self.maneuver}, {self.run.t[-1]:.1f} s at '
            f'{self.rate_hz:g} Hz ({self.n} samples), seed {self.seed}, frame {self.frame}, '
            f'real-time factor {rtf:g}' + (', publishing /clock' if self.pub_clock else '')
            + (f'; waiting for {", ".join(self.wait_for)}' if self._wait else ''))

    # -- parameters --

    def _read_parameters(self):
        """Declare, read and check every parameter once (ParameterError names a bad one)."""
        p = declare_parameters(self, _PARAMETERS)
        self.vehicle, self.maneuver, self.frame = p['vehicle'], p['maneuver'], p['frame']
        self.duration, self.rate_hz, self.seed = p['duration'], p['rate_hz'], p['seed']
        self.T = 1.0 / self.rate_hz
        if self.duration * self.rate_hz > MAX_SAMPLES:
            raise ParameterError('duration', f'{self.duration} s at {self.rate_hz} Hz is more '
                                              f'than {MAX_SAMPLES} samples')
        self.rpm = None if p['rpm'] == 0 else p['rpm']
        self.noise_std, self.process_noise = p['noise_std'], p['process_noise']
        self.real_time_factor = p['real_time_factor']
        clk = p['publish_clock']
        self.publish_clock = (self.real_time_factor != 1.0) if clk is None else clk
        self.wait_for = p['wait_for_subscribers']
        self.wait_timeout = p['wait_timeout']
        self.current = p['current']
        self.velocity_reference = p['velocity_reference']

    # -- publishing --

    def publish_sample(self, k):
        """Publish sample k: /clock (if enabled), then actuators, odom, truth."""
        if not self.context.ok():   # shutting down (SIGINT during the timer callback)
            return
        if self.pub_clock is not None:
            # simulated time is a date, as in a simulated bag (offline/sim_bag.py SIM_EPOCH)
            self.pub_clock.publish(ClockMsg(clock=ns_to_stamp(
                SIM_EPOCH_NS + sec_to_ns(float(self.run.t[k])))))
        msgs = sample_messages(self.run, k, self.frame, epoch_ns=SIM_EPOCH_NS)
        # the command first: a subscriber then has u_k before y_k of the same stamp
        msgs.sort(key=lambda m: m[0] not in (ACTUATOR_TOPIC, THRUSTER_TOPIC))
        for topic, _, msg in msgs:
            self._routes[topic].publish(msg)

    def _start(self):
        self._wait = None
        self._t0 = time.monotonic()
        self.get_logger().info(f'publishing {self.n} samples')

    def step(self):
        """Timer callback: wait for subscribers, then publish the samples that are due."""
        if self.finished.done():
            return
        if self._wait is not None:
            ready = self._wait.poll()
            if ready is None:
                return
            if not ready:
                self.get_logger().warning(
                    f'still no subscription from {", ".join(self._wait.missing)} after '
                    f'{self.wait_timeout:g} s: starting anyway')
            self._start()
        if self.real_time_factor == 0:
            due = min(self.n, self.k + BURST)
        else:
            elapsed = (time.monotonic() - self._t0) * self.real_time_factor
            due = min(self.n, int(math.floor(elapsed / self.T + 1e-9)) + 1)
        while self.k < due:
            self.publish_sample(self.k)
            self.k += 1
        if self.k >= self.n:
            self._finish()

    def _finish(self):
        self.timer.cancel()
        wall = time.monotonic() - self._t0
        acked = all(p.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
                    for p in self._stream_pubs)
        s = self.run.summary()
        fs = s['final_state']
        self.get_logger().info(
            f'run over: {self.n} samples ({s["duration_s"]:.1f} s simulated) in {wall:.2f} s '
            f'wall ({s["duration_s"] / max(wall, 1e-9):.1f}x real time)'
            + ('' if acked else '; some subscribers did not acknowledge every sample')
            + f'. Speed mean {s["speed_m_s"]["mean"]:.3f} m/s (min {s["speed_m_s"]["min"]:.3f},'
            f' max {s["speed_m_s"]["max"]:.3f}); depth {s["depth_m"]["min"]:.2f} .. '
            f'{s["depth_m"]["max"]:.2f} m; max |roll| {s["roll_deg_max"]:.2f} deg; final '
            f'x {fs["x"]:.1f} m, y {fs["y"]:.1f} m, psi {fs["psi"]:.3f} rad')
        self.exit_code = 0
        self.finished.set_result(0)


def main(args=None):
    """Entry point: run the simulation, exit 0 when it is over (2 on a bad parameter)."""
    return run_node('simulator', args, __doc__, '-p duration:=60.0', SimulatorNode,
                    lambda node, stop: spin(node, stop, done=node.finished.done))


if __name__ == '__main__':
    sys.exit(main())
