"""A simulated run written as a rosbag2 MCAP bag, without ROS.

Topics (absolute names as they appear in the root namespace and in bags):

- ``/odom`` nav_msgs/Odometry: the MEASURED state y_k (sensor noise included), stamped t_k;
  covariances = the noise model (diagonal: pose x y z phi theta psi, twist u v w p q r).
- ``/actuators`` sensor_msgs/JointState: the command u_k applied over [t_k, t_k+1), stamped t_k;
  ``effort`` the thrust on the propeller joint, zeros elsewhere (see :func:`joint_state_msg`).
- ``/simulator/truth`` nav_msgs/Odometry: the true state x_k (zero covariance), for evaluation.

A thruster vehicle's run (an ROV: run.u wider than state.Input) has ``/thrusters``
std_msgs/Float64MultiArray instead of ``/actuators``: its thrusters' commands in the vehicle
file's order and their own units (PWM in us), written when they change (and at t = 0), as a
pilot's console sends them; its metadata names the input map that reads it
(``auv_ident.input_map``: config/inputs/<vehicle>.yaml, e.g. bluerov2_heavy).

Messages are built as rosbags message objects (rosbags' Jazzy types) with the frame algebra of
:mod:`auv_ident.session.messages`, and serialized by rosbags: the strict CDR form every reader
decodes. The same messages as rclpy objects (what the live simulator node publishes) are
:func:`auv_ident.ros.sim_messages.sample_messages`.

Time: a bag's stamps and log times are ``SIM_EPOCH_NS + t_k`` (t_k = k T from 0). The epoch is
a fixed date, 2024-01-01T00:00:00Z, not the time of writing, so that the same run gives the
same bag byte for byte (reproducible bags, stable regression data); it is realistic, so tools
(Foxglove, ``ros2 bag play`` without sim time) show a 2024 date instead of 1970-01-01. The
replay and identification use time differences only. metadata.yaml's custom_data records it
(``auv_ident.stamp_epoch_ns``, ``auv_ident.stamp_epoch``).
"""
import numpy as np
from rosbags.typesys import get_typestore, Stores

from auv_ident.bags.writer import BagWriter
from auv_ident.core.model.state import N_INPUT
from auv_ident.session.messages import (
    actuator_joint_fields,
    ConversionError,
    JOINT_NAMES,
    NS_PER_S,
    odometry_fields,
    sec_to_ns,
)

ODOM_TOPIC = '/odom'
ACTUATOR_TOPIC = '/actuators'
THRUSTER_TOPIC = '/thrusters'
TRUTH_TOPIC = '/simulator/truth'
TOPIC_TYPES = {ODOM_TOPIC: 'nav_msgs/msg/Odometry',
               ACTUATOR_TOPIC: 'sensor_msgs/msg/JointState',
               TRUTH_TOPIC: 'nav_msgs/msg/Odometry'}
THRUSTER_TOPIC_TYPES = {ODOM_TOPIC: 'nav_msgs/msg/Odometry',
                        THRUSTER_TOPIC: 'std_msgs/msg/Float64MultiArray',
                        TRUTH_TOPIC: 'nav_msgs/msg/Odometry'}


def has_thrusters(run):
    """Whether a run's inputs hold thruster commands (after state.Input's channels)."""
    return np.shape(run.u)[1] > N_INPUT


def run_topic_types(run):
    """{topic: type} of a run's bag: /actuators, or /thrusters for a thruster vehicle."""
    return THRUSTER_TOPIC_TYPES if has_thrusters(run) else TOPIC_TYPES

SIM_EPOCH = '2024-01-01T00:00:00Z'
SIM_EPOCH_NS = 1_704_067_200 * NS_PER_S
"""Stamp of t = 0 in simulated bags: 2024-01-01T00:00:00Z (see the module docstring)."""

_STORE = get_typestore(Stores.ROS2_JAZZY)
_T = _STORE.types


def noise_covariances(noise_std):
    """(pose_cov, twist_cov) 6x6 from the 12 measurement 1-sigmas (order of the state)."""
    s2 = np.asarray(noise_std, dtype=float) ** 2
    return np.diag(s2[6:12]), np.diag(s2[0:6])


def _stamp(t_ns):
    sec, nanosec = divmod(int(t_ns), NS_PER_S)
    if not -2**31 <= sec < 2**31:
        raise ConversionError(f'time {t_ns} ns does not fit builtin_interfaces/Time.sec (int32)')
    return _T['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec)


def _header(t_ns, frame_id):
    return _T['std_msgs/msg/Header'](stamp=_stamp(t_ns), frame_id=frame_id)


def _vector3(v):
    return _T['geometry_msgs/msg/Vector3'](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def odometry_msg(t_ns, x12, frame='ned', pose_cov=None, twist_cov=None, frame_id=None,
                 child_frame_id=None):
    """Return a rosbags nav_msgs/Odometry of a NED/FRD state, expressed in ``frame``.

    The fields equal those of :func:`auv_ident.ros.conversions.state_to_odometry` (same frame
    algebra, from :mod:`auv_ident.session.messages`); ``t_ns`` (int ns) is the stamp.
    """
    pos, quat, lin, ang, pcov, tcov, frame_id, child_frame_id = odometry_fields(
        x12, frame, pose_cov, twist_cov, frame_id, child_frame_id)
    pose = _T['geometry_msgs/msg/Pose'](
        position=_T['geometry_msgs/msg/Point'](x=float(pos[0]), y=float(pos[1]),
                                               z=float(pos[2])),
        orientation=_T['geometry_msgs/msg/Quaternion'](x=quat[0], y=quat[1], z=quat[2],
                                                       w=quat[3]))
    twist = _T['geometry_msgs/msg/Twist'](linear=_vector3(lin), angular=_vector3(ang))
    return _T['nav_msgs/msg/Odometry'](
        header=_header(t_ns, frame_id),
        child_frame_id=child_frame_id,
        pose=_T['geometry_msgs/msg/PoseWithCovariance'](
            pose=pose, covariance=np.array(pcov, dtype=np.float64).reshape(36)),
        twist=_T['geometry_msgs/msg/TwistWithCovariance'](
            twist=twist, covariance=np.array(tcov, dtype=np.float64).reshape(36)))


def joint_state_msg(t_ns, u7):
    """Return a rosbags sensor_msgs/JointState of actuator vector ``u7`` stamped ``t_ns``.

    ``u7 = [delta_r, delta_s, delta_b, delta_bp, delta_bs, n_rpm, thrust]`` (rad, rpm, N);
    layout of :mod:`auv_ident.session.messages` (actuator_joint_fields). ``effort`` (the
    thrust on the propeller joint, zeros elsewhere) is never empty:
    a message ending with an empty float64 sequence is exactly what rclpy (Fast-CDR) pads with
    up to 8 extra bytes and strict decoders (rosbags) reject, so no writer of these messages
    should produce one.
    """
    position, velocity, effort = actuator_joint_fields(u7)
    return _T['sensor_msgs/msg/JointState'](
        header=_header(t_ns, ''), name=list(JOINT_NAMES), position=np.array(position),
        velocity=np.array(velocity), effort=np.array(effort))


def command_message(msgtype, t_ns, raw):
    """A rosbags command message of type msgtype (sensor_msgs/msg/JointState,
    std_msgs/msg/Float64MultiArray or std_msgs/msg/Float64) stamped t_ns (headers only) holding
    raw: [(session.input_map.Channel, raw value)] (JointState: each channel's joint and field,
    the joints in channel order, other entries 0; Float64MultiArray: its index, others 0)."""
    if msgtype == 'std_msgs/msg/Float64':
        return _T[msgtype](data=float(raw[0][1]))
    if msgtype == 'std_msgs/msg/Float64MultiArray':
        data = np.zeros(max(c.index for c, _ in raw) + 1)
        for c, v in raw:
            data[c.index] = v
        return _T[msgtype](layout=_T['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0),
                           data=data)
    joints = list(dict.fromkeys(c.joint for c, _ in raw))
    arrays = {f: np.zeros(len(joints)) for f in ('position', 'velocity', 'effort')}
    for c, v in raw:
        arrays[c.field][joints.index(c.joint)] = v
    return _T['sensor_msgs/msg/JointState'](header=_header(t_ns, ''), name=joints, **arrays)


def thruster_msg(commands):
    """A rosbags std_msgs/Float64MultiArray of thruster commands (their units, file order)."""
    return _T['std_msgs/msg/Float64MultiArray'](
        layout=_T['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0),
        data=np.array(commands, dtype=np.float64))


def bag_sample_messages(run, k, frame='ned', with_truth=True, epoch_ns=SIM_EPOCH_NS):
    """The messages of sample k as a simulated bag holds them: list of (topic, t_ns, rosbags
    msg), stamp = log time = ``epoch_ns + t_k``; the command first (a replay in log-time order
    then pairs the first odometry with it). A thruster vehicle's commands only when they
    change (and at k = 0)."""
    t_ns = int(epoch_ns) + sec_to_ns(float(run.t[k]))
    pose_cov, twist_cov = noise_covariances(run.noise_std)
    if not has_thrusters(run):
        out = [(ACTUATOR_TOPIC, t_ns, joint_state_msg(t_ns, run.u[k]))]
    elif k == 0 or np.any(run.u[k] != run.u[k - 1]):
        out = [(THRUSTER_TOPIC, t_ns, thruster_msg(run.u[k, N_INPUT:]))]
    else:
        out = []
    out.append((ODOM_TOPIC, t_ns, odometry_msg(t_ns, run.y[k], frame, pose_cov, twist_cov)))
    if with_truth:
        out.append((TRUTH_TOPIC, t_ns, odometry_msg(t_ns, run.x[k], frame)))
    return out


def run_metadata(run, frame='ned', command='', epoch_ns=SIM_EPOCH_NS):
    """Provenance stored in the bag's metadata.yaml custom_data."""
    meta = {'auv_ident.vehicle': run.vehicle, 'auv_ident.maneuver': run.maneuver,
            'auv_ident.seed': str(run.seed), 'auv_ident.sample_time': repr(run.T),
            'auv_ident.frame': frame, 'auv_ident.simulated': 'true',
            'auv_ident.noise_std': ' '.join(repr(float(v)) for v in run.noise_std),
            'auv_ident.command': command,
            'auv_ident.stamp_epoch_ns': str(int(epoch_ns))}
    if getattr(run, 'current', None) is not None:
        # the truth of a run in a current: m/s NED, and what the DVL measured
        meta['auv_ident.current'] = ' '.join(repr(float(v)) for v in run.current)
        meta['auv_ident.velocity_reference'] = run.velocity_reference
    if int(epoch_ns) == SIM_EPOCH_NS:
        meta['auv_ident.stamp_epoch'] = SIM_EPOCH
    if has_thrusters(run):
        meta['auv_ident.input_map'] = run.vehicle    # config/inputs/<vehicle>.yaml
    return meta


def write_message_bag(path, topic_types, custom_data, messages, compression='zstd'):
    """Write rosbags messages as a rosbag2 MCAP bag directory at path (must not exist).

    topic_types : {topic: 'pkg/msg/Type'}, in the order the topics are registered
    custom_data : {str: str}, metadata.yaml's custom_data
    messages : iterable of (topic, t_ns, rosbags message); t_ns (int ns) is the log time
    The one writing path of simulated (:func:`write_run_bag`) and imported
    (:mod:`auv_ident.offline.import_bag`) runs; returns path.
    """
    with BagWriter(path, compression=compression) as w:
        for topic, typ in topic_types.items():
            w.add_topic(topic, typ)
        for key, val in custom_data.items():
            w.set_custom_data(key, val)
        for topic, t_ns, msg in messages:
            w.write(topic, t_ns, _STORE.serialize_cdr(msg, topic_types[topic]))
    return path


def write_run_bag(run, path, frame='ned', compression='zstd', command='',
                  epoch_ns=SIM_EPOCH_NS):
    """Write a simulated run as a rosbag2 MCAP bag directory at path (must not exist).

    Stamps and log times are ``epoch_ns + t_k`` (default 2024-01-01T00:00:00Z, see the module
    docstring); returns path.
    """
    messages = (m for k in range(len(run.t))
                for m in bag_sample_messages(run, k, frame, epoch_ns=epoch_ns))
    return write_message_bag(path, run_topic_types(run),
                             run_metadata(run, frame, command, epoch_ns), messages, compression)
