"""The messages of a simulated run as rclpy objects: what the simulator node publishes.

The same messages as a simulated bag holds them, built without ROS, are
:func:`auv_ident.offline.sim_bag.bag_sample_messages`; topics, types and the noise covariances
come from :mod:`auv_ident.offline.sim_bag`. Stamps are simulation time t_k from 0 (the live
simulator's clock) unless an epoch is given.
"""
from auv_ident.offline.sim_bag import (
    ACTUATOR_TOPIC,
    noise_covariances,
    ODOM_TOPIC,
    SIM_EPOCH_NS,
    TOPIC_TYPES,
    TRUTH_TOPIC,
)
from auv_ident.ros.conversions import actuators_to_joint_state, ns_to_stamp, state_to_odometry
from auv_ident.session.messages import sec_to_ns

__all__ = ['ACTUATOR_TOPIC', 'ODOM_TOPIC', 'sample_messages', 'SIM_EPOCH_NS', 'TOPIC_TYPES',
           'TRUTH_TOPIC']


def sample_messages(run, k, frame='ned', with_truth=True, epoch_ns=0):
    """The messages of sample k: list of (topic, t_ns, rclpy msg), stamped ``epoch_ns + t_k``.

    ``epoch_ns`` 0 (default): simulation time from 0, as the simulator node publishes today;
    :data:`auv_ident.offline.sim_bag.SIM_EPOCH_NS` gives exactly the stamps of a simulated bag.
    """
    t = float(run.t[k])
    t_ns = int(epoch_ns) + sec_to_ns(t)
    pose_cov, twist_cov = noise_covariances(run.noise_std)
    joints = actuators_to_joint_state(t, run.u[k])     # effort: the thrust, as in the bags
    # the command first: a replay in log-time order then pairs the first odometry with it
    out = [(ACTUATOR_TOPIC, t_ns, joints),
           (ODOM_TOPIC, t_ns, state_to_odometry(t, run.y[k], frame, pose_cov, twist_cov))]
    if with_truth:
        out.append((TRUTH_TOPIC, t_ns, state_to_odometry(t, run.x[k], frame)))
    if epoch_ns:
        for _, _, msg in out:
            msg.header.stamp = ns_to_stamp(t_ns)
    return out
