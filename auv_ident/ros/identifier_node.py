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
is the odometry path, ros/odom_live.py OdomLive.

Subscriptions (RELIABLE, KEEP_LAST depth 1000, VOLATILE: no loss at 200 Hz while the callback
is busy, see shared/ros_stack.md section 2; a BEST_EFFORT publisher cannot feed these): the
topics of the input map (parameter ``input_map``, session/input_map.py, docs/your_data.md), each
with the map's message type, taken as ``intake_period_s`` says (ros/intake.py: every 20 ms by
default, a batch at a time in the order they were published; 0: each as it arrives). The
default map, odom_actuators:
    ``actuators`` sensor_msgs/JointState: commands (conversions.py layout). The command inputs
        are created before the odometry, so when both are waiting and published at the same
        instant the command is taken first (batched: a tie of publication times; with
        ``intake_period_s`` 0: the executor's order). Commands of other forms (JointState with
        other joint names, Float64MultiArray by index, one Float64 per actuator, in other
        units) hold each actuator's last value (session/inputs.py); a message without a header
        is stamped with its receive time: when DDS received it, or with ``use_sim_time`` the
        last ``/clock`` taken before it (a played bag: the player's ``publish_clock`` gives
        each message's log time, so the node stamps it as replay_bag does).
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
import sys

from rclpy.parameter import Parameter

from auv_ident.ros.intake import IntakeNode
from auv_ident.ros.odom_live import OdomLive
from auv_ident.ros.raw_live import RawLive
from auv_ident.ros.toolkit import declare_parameters, optional_list, Param, run_node, spin
from auv_ident.session.estimate_file import check_save_path
from auv_ident.session.raw_session import has_raw_sensors
from auv_ident.session.settings import help_text, IdentifierSettings, settings_fields
from auv_ident.session.settings_text import SAVE_PATH

NODE_NAME = 'identifier'


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
    """Identify coefficients online from the input map's topics (module docstring): the
    parameters, then the work handed to the odometry path (:attr:`odom`, ros/odom_live.py) or,
    with raw sensors in the map, the raw-sensor path (:attr:`raw`, ros/raw_live.py); the other
    is None."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        values = declare_parameters(self, _PARAMETERS)
        self.save_path = values.pop('save_path')
        check_save_path(self.save_path)     # a bad folder: exit 2 now, not at shutdown
        settings = IdentifierSettings.from_values(**values)
        # an input map with raw sensors: each message a step of the raw-sensor filter
        # (ros/raw_live.py, session/raw_session.py); else the odometry path (ros/odom_live.py)
        self.raw = RawLive(self, settings) if has_raw_sensors(settings) else None
        self.odom = OdomLive(self, settings) if self.raw is None else None

    def _live(self):
        return self.raw if self.raw is not None else self.odom

    def shutdown_save(self):
        """On shutdown: write save_path if set, and log the final estimate. False when the
        file could not be written (the process then exits 2: a mission's estimate lost is
        no success)."""
        live = self._live()
        self._final_log('INFO', live.final_line())
        if not self.save_path:
            return True
        ok, message = live.save()
        self._final_log('INFO' if ok else 'ERROR', message)
        return ok

    def messages_taken(self):
        """How many messages the input subscriptions' callbacks have taken."""
        return self._live().taken

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
