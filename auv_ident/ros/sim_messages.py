"""The messages of a simulated run as rclpy objects: what the simulator node publishes.

The same messages as a simulated bag holds them, built without ROS, are
:func:`auv_ident.offline.sim_bag.bag_sample_messages`; topics, types and the noise covariances
come from :mod:`auv_ident.offline.sim_bag`. Stamps are simulation time t_k from 0 (the live
simulator's clock) unless an epoch is given.
"""
from auv_ident.core.model.state import N_INPUT
from auv_ident.offline.sim_bag import (
    ACTUATOR_TOPIC,
    has_thrusters,
    noise_covariances,
    ODOM_TOPIC,
    SIM_EPOCH_NS,
    THRUSTER_TOPIC,
    TOPIC_TYPES,
    TRUTH_TOPIC,
)
from auv_ident.ros.conversions import actuators_to_joint_state, ns_to_stamp, state_to_odometry
from auv_ident.session.messages import sec_to_ns

__all__ = ['ACTUATOR_TOPIC', 'ODOM_TOPIC', 'sample_messages', 'SIM_EPOCH_NS', 'THRUSTER_TOPIC',
           'TOPIC_TYPES', 'TRUTH_TOPIC']


def sample_messages(run, k, frame='ned', with_truth=True, epoch_ns=0):
    """The messages of sample k: list of (topic, t_ns, rclpy msg), stamped ``epoch_ns + t_k``
    (a thruster vehicle's std_msgs/Float64MultiArray of PWM commands has no header, and comes
    only when the commands change, as in its bags).

    ``epoch_ns`` 0 (default): simulation time from 0, as the simulator node publishes today;
    :data:`auv_ident.offline.sim_bag.SIM_EPOCH_NS` gives exactly the stamps of a simulated bag.
    """
    t = float(run.t[k])
    t_ns = int(epoch_ns) + sec_to_ns(t)
    pose_cov, twist_cov = noise_covariances(run.noise_std)
    # the command first: a replay in log-time order then pairs the first odometry with it
    if not has_thrusters(run):
        # effort: the thrust, as in the bags
        out = [(ACTUATOR_TOPIC, t_ns, actuators_to_joint_state(t, run.u[k]))]
    elif k == 0 or (run.u[k] != run.u[k - 1]).any():
        from std_msgs.msg import Float64MultiArray
        out = [(THRUSTER_TOPIC, t_ns,
                Float64MultiArray(data=[float(c) for c in run.u[k, N_INPUT:]]))]
    else:
        out = []
    out.append((ODOM_TOPIC, t_ns, state_to_odometry(t, run.y[k], frame, pose_cov, twist_cov)))
    if with_truth:
        out.append((TRUTH_TOPIC, t_ns, state_to_odometry(t, run.x[k], frame)))
    if epoch_ns:
        for _, _, msg in out:
            if hasattr(msg, 'header'):
                msg.header.stamp = ns_to_stamp(t_ns)
    return out
