"""Test helper (not collected): publish a short simulated run as a node process would.

``python test/ros_pub_helper.py --count N --rate HZ`` publishes N samples of a simulated NPS
AUV II run: per sample ``/odom`` (nav_msgs/Odometry), ``/actuators`` (sensor_msgs/JointState
with an EMPTY effort array: the Fast-CDR padding pitfall of shared/ros_stack.md section 3) and
``/clock`` (rosgraph_msgs/Clock), built with :func:`auv_ident.ros.sim_messages.sample_messages`. It
waits (<= --timeout s) until every publisher has a subscriber, lets the subscriber's side of
the match settle, publishes at --rate, prints ``done N`` and exits 0 (3 on a match timeout).
With --hold it then keeps its publishers alive until its stdin closes: a publisher that exits
right after its last publish can lose that sample (the subscriber drops it when the writer
disappears; seen in about 1 of 6 runs), so the tests stop the recorder first.

Tests import :func:`build_samples` to get the very same messages for comparison.
"""
import argparse
import sys
import time

TOPICS = ('/odom', '/actuators', '/clock')
SEED = 7
SAMPLE_TIME = 0.05


def build_samples(count, seed=SEED):
    """Return [[(topic, rclpy msg) in TOPICS order] per sample] of a simulated run."""
    from auv_ident.core.model.hydrodynamics import Model
    from auv_ident.core.simulation.simulate import simulate
    from auv_ident.ros.conversions import clock_msg
    from auv_ident.ros.sim_messages import sample_messages
    from auv_ident.vehicles import load_vehicle
    run = simulate(Model(load_vehicle('nps_auv2'), ()), 'zigzag',
                   duration=(count - 1) * SAMPLE_TIME, T=SAMPLE_TIME, seed=seed)
    assert len(run.t) == count
    samples = []
    for k in range(count):
        by_topic = {topic: msg for topic, _, msg in sample_messages(run, k, with_truth=False)}
        by_topic['/clock'] = clock_msg(float(run.t[k]))
        by_topic['/actuators'].effort = []  # the padding pitfall is exercised in recordings
        samples.append([(topic, by_topic[topic]) for topic in TOPICS])
    return samples


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--count', type=int, default=100)
    parser.add_argument('--rate', type=float, default=100.0, help='samples per second')
    parser.add_argument('--timeout', type=float, default=20.0, help='wait for subscribers, s')
    parser.add_argument('--hold', action='store_true', help='after publishing, wait for EOF')
    args = parser.parse_args(argv)

    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    samples = build_samples(args.count)
    rclpy.init()
    node = rclpy.create_node('test_pub_helper')
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    pubs = {topic: node.create_publisher(type(msg), topic, qos)
            for topic, msg in samples[0]}
    try:
        deadline = time.monotonic() + args.timeout
        while any(p.get_subscription_count() == 0 for p in pubs.values()):
            if time.monotonic() > deadline:
                print('no subscriber on ' + ', '.join(
                    t for t, p in pubs.items() if p.get_subscription_count() == 0),
                    file=sys.stderr)
                return 3
            time.sleep(0.01)
        time.sleep(0.25)  # the subscriber's side of the match may lag the publisher's
        start = time.monotonic()
        for k, sample in enumerate(samples):
            delay = start + k / args.rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            for topic, msg in sample:
                pubs[topic].publish(msg)
        print(f'done {len(samples)}', flush=True)
        if args.hold:
            sys.stdin.read()
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    sys.exit(main())
