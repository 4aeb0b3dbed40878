"""The messages of a simulated run as rclpy objects: what the simulator node publishes.

The same messages as a simulated bag holds them, built without ROS, are
:func:`auv_ident.bags.sim_bag.bag_sample_messages`; topics, types and the noise covariances
come from :mod:`auv_ident.bags.sim_bag`. Stamps here are simulation time t_k from 0 (the live
simulator's clock), not the bags' epoch.
"""
from auv_ident.bags.sim_bag import (ACTUATOR_TOPIC, noise_covariances, ODOM_TOPIC, TOPIC_TYPES,
                                    TRUTH_TOPIC)
from auv_ident.ros.conversions import actuators_to_joint_state, state_to_odometry
from auv_ident.session.messages import sec_to_ns

__all__ = ['ACTUATOR_TOPIC', 'ODOM_TOPIC', 'sample_messages', 'TOPIC_TYPES', 'TRUTH_TOPIC']


def sample_messages(run, k, frame='ned', with_truth=True):
    """The messages of sample k: list of (topic, t_ns, rclpy msg), stamped t_k (s from 0)."""
    t = float(run.t[k])
    pose_cov, twist_cov = noise_covariances(run.noise_std)
    joints = actuators_to_joint_state(t, run.u[k])
    if not len(joints.effort):
        # An empty float64 sequence at the end is what rclpy pads and rosbags rejects (see
        # bags.sim_bag.joint_state_msg); zeros keep these equal to the bag's messages.
        joints.effort = [0.0] * len(joints.name)
    # the command first: a replay in log-time order then pairs the first odometry with it
    out = [(ACTUATOR_TOPIC, sec_to_ns(t), joints),
           (ODOM_TOPIC, sec_to_ns(t), state_to_odometry(t, run.y[k], frame, pose_cov,
                                                        twist_cov))]
    if with_truth:
        out.append((TRUTH_TOPIC, sec_to_ns(t), state_to_odometry(t, run.x[k], frame)))
    return out
