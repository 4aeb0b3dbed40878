"""Building ROS messages (rclpy classes) from numpy arrays: Odometry, JointState, Clock, Time.

The conventions (frames, state and actuator layouts, covariance transforms) are in
:mod:`auv_ident.session.messages`, which reads the same messages back without ROS.
"""
from builtin_interfaces.msg import Time
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from auv_ident.session.messages import (
    actuator_joint_fields,
    ConversionError,
    JOINT_NAMES,
    NS_PER_S,
    odometry_fields,
    sec_to_ns,
)


def ns_to_stamp(t_ns):
    """Return integer nanoseconds as a builtin_interfaces/Time (nanosec in [0, 1e9))."""
    sec, nanosec = divmod(int(t_ns), NS_PER_S)
    if not -2**31 <= sec < 2**31:
        raise ConversionError(f'time {t_ns} ns does not fit builtin_interfaces/Time.sec (int32)')
    return Time(sec=sec, nanosec=nanosec)


def sec_to_stamp(t_sec):
    """Return float seconds as a builtin_interfaces/Time, rounded to the nearest ns."""
    return ns_to_stamp(sec_to_ns(t_sec))


def clock_msg(t_sec):
    """Return a rosgraph_msgs/Clock for simulation time ``t_sec`` (s)."""
    return Clock(clock=sec_to_stamp(t_sec))


def state_to_odometry(t_sec, x12, frame='ned', pose_cov=None, twist_cov=None,
                      frame_id=None, child_frame_id=None):
    """Return a nav_msgs/Odometry for a NED/FRD state, expressed in convention ``frame``.

    Parameters
    ----------
    t_sec : float
        Sample time (s), goes to header.stamp (rounded to ns).
    x12 : array_like, shape (12,)
        ``[u v w p q r x y z phi theta psi]`` (m/s, rad/s, m, rad), always NED/FRD.
    frame : {'ned', 'enu'}
        Convention of the message.
    pose_cov, twist_cov : array_like, shape (6, 6) or (36,), optional
        NED/FRD covariances over (x, y, z, phi, theta, psi) and (u, v, w, p, q, r); zeros if
        omitted. Transformed with ``T C T^T`` for 'enu'.
    frame_id, child_frame_id : str, optional
        Override the convention's default frame ids.
    """
    pos, quat, lin, ang, pcov, tcov, frame_id, child_frame_id = odometry_fields(
        x12, frame, pose_cov, twist_cov, frame_id, child_frame_id)

    msg = Odometry()
    msg.header.stamp = sec_to_stamp(t_sec)
    msg.header.frame_id = frame_id
    msg.child_frame_id = child_frame_id
    p = msg.pose.pose.position
    p.x, p.y, p.z = (float(v) for v in pos)
    o = msg.pose.pose.orientation
    o.x, o.y, o.z, o.w = quat
    tl, ta = msg.twist.twist.linear, msg.twist.twist.angular
    tl.x, tl.y, tl.z = (float(v) for v in lin)
    ta.x, ta.y, ta.z = (float(v) for v in ang)
    msg.pose.covariance = pcov.reshape(36)
    msg.twist.covariance = tcov.reshape(36)
    return msg


def actuators_to_joint_state(t_sec, u7):
    """Return a sensor_msgs/JointState for actuator vector ``u7`` at time ``t_sec`` (s).

    ``u7 = [delta_r, delta_s, delta_b, delta_bp, delta_bs, n_rpm, thrust]`` (rad, rpm, N).
    """
    msg = JointState()
    msg.header.stamp = sec_to_stamp(t_sec)
    msg.name = list(JOINT_NAMES)
    # effort holds the thrust and zeros, never []: rclpy/Fast-CDR pads a message that ends
    # with an empty float64 sequence and rosbags' strict reader then refuses every recorded
    # command (ros_stack.md section 3)
    msg.position, msg.velocity, msg.effort = actuator_joint_fields(u7)
    return msg

