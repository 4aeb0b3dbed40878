"""Messages of a simulated run, as the simulator node publishes them, and a run written as a bag.

Topics (absolute names as they appear in the root namespace and in bags):

- ``/odom`` nav_msgs/Odometry: the MEASURED state y_k (sensor noise included), stamped t_k;
  covariances = the noise model (diagonal: pose x y z phi theta psi, twist u v w p q r).
- ``/actuators`` sensor_msgs/JointState: the command u_k applied over [t_k, t_k+1), stamped t_k.
- ``/simulator/truth`` nav_msgs/Odometry: the true state x_k (zero covariance), for evaluation.
"""
import numpy as np

from auv_ident.ros.conversions import actuators_to_joint_state, state_to_odometry
from auv_ident.session.messages import sec_to_ns

ODOM_TOPIC = '/odom'
ACTUATOR_TOPIC = '/actuators'
TRUTH_TOPIC = '/simulator/truth'
TOPIC_TYPES = {ODOM_TOPIC: 'nav_msgs/msg/Odometry',
               ACTUATOR_TOPIC: 'sensor_msgs/msg/JointState',
               TRUTH_TOPIC: 'nav_msgs/msg/Odometry'}


def noise_covariances(noise_std):
    """(pose_cov, twist_cov) 6x6 from the 12 measurement 1-sigmas (order of the state)."""
    s2 = np.asarray(noise_std, dtype=float) ** 2
    return np.diag(s2[6:12]), np.diag(s2[0:6])


def sample_messages(run, k, frame='ned', with_truth=True):
    """The messages of sample k: list of (topic, t_ns, msg)."""
    t = float(run.t[k])
    pose_cov, twist_cov = noise_covariances(run.noise_std)
    # the command first: a replay in log-time order then pairs the first odometry with it
    out = [(ACTUATOR_TOPIC, sec_to_ns(t), actuators_to_joint_state(t, run.u[k])),
           (ODOM_TOPIC, sec_to_ns(t), state_to_odometry(t, run.y[k], frame, pose_cov,
                                                        twist_cov))]
    if with_truth:
        out.append((TRUTH_TOPIC, sec_to_ns(t), state_to_odometry(t, run.x[k], frame)))
    return out


def run_metadata(run, frame='ned', command=''):
    """Provenance stored in the bag's metadata.yaml custom_data."""
    return {'auv_ident.vehicle': run.vehicle, 'auv_ident.maneuver': run.maneuver,
            'auv_ident.seed': str(run.seed), 'auv_ident.sample_time': repr(run.T),
            'auv_ident.frame': frame, 'auv_ident.simulated': 'true',
            'auv_ident.noise_std': ' '.join(repr(float(v)) for v in run.noise_std),
            'auv_ident.command': command}


def write_run_bag(run, path, frame='ned', compression='zstd', command=''):
    """Write a simulated run as a rosbag2 MCAP bag directory at path (must not exist)."""
    from auv_ident.bags.writer import BagWriter
    with BagWriter(path, compression=compression) as w:
        for topic, typ in TOPIC_TYPES.items():
            w.add_topic(topic, typ)
        for key, val in run_metadata(run, frame, command).items():
            w.set_custom_data(key, val)
        for k in range(len(run.t)):
            for topic, t_ns, msg in sample_messages(run, k, frame):
                w.write_msg(topic, t_ns, msg)
    return path
