"""Per-message CPU of the identifier node's callbacks in one process, part by part.

    PYTHONPATH=. ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST .venv/bin/python tools/node_cost.py \
        [--rate 200] [--seconds 60] [--profile]

One simulated NPS AUV II run ('ident' manoeuvre) at --rate Hz is serialized as the load test
publishes it (auv_ident/ros/loadtest.py). An IdentifierNode (sample_time = 1/rate) gets, sample
by sample, what its subscriptions hand it: the command's bytes turned into a JointState by
rclpy (deserialize_message, what a typed subscription does) and passed to its callback, then
the odometry's bytes passed to the raw odometry callback (on_odom_payload). No DDS and no
executor: this is the node's own work per message (the load test's identifier CPU adds the
executor's take and the middleware). Figures are us per sample (command + odometry), the
mean over the samples after the first 10 % (warm-up), with process CPU time (thread_time).

Parts, each timed alone: rclpy's JointState deserialization; the command callback; the
odometry callback; of that, the session's on_input (IdentSession, commands and odometry) and
publish_estimate; of the session, IdentSession.on_odom (per odometry message, the noise
learner's periodic fits included).
``--profile`` prints a cProfile of the whole loop (cumulative, top 35).

``--raw`` measures the raw-sensor path instead (ros/raw_live.py): the example raw bag
(offline/raw_example.py: IMU at --imu-rate Hz, 5 Hz DVL, 10 Hz pressure, commands on change,
--seconds long), each IMU message handed to the node's raw IMU callback as its CDR bytes from
the bag (what its raw subscription gives), the others as the bag's decoded messages to
RawLive.on_input; us per message, of which RawSession.on_input and publishing, and of the
session the IMU messages' filter step (RawSensorFilter.process_imu, the compiled step with its
Python around it; per message of all kinds).
``--publish-rate`` sets the node's publish_rate_hz (both paths).
"""
import argparse
import cProfile
import os
import pstats
import sys
import time

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--rate', type=float, default=200.0, help='Hz (default 200)')
    ap.add_argument('--seconds', type=float, default=60.0, help='simulated s (default 60)')
    ap.add_argument('--profile', action='store_true')
    ap.add_argument('--raw', action='store_true', help='the raw-sensor path (docstring)')
    ap.add_argument('--imu-rate', type=float, default=400.0, help='Hz, with --raw')
    ap.add_argument('--publish-rate', type=float, default=0.0, help='publish_rate_hz')
    a = ap.parse_args(argv)
    if a.raw:
        return raw_cost(a)

    import rclpy
    from rclpy.parameter import Parameter
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import JointState

    from auv_ident.core.model.hydrodynamics import Model
    from auv_ident.core.simulation.simulate import simulate
    from auv_ident.ros.identifier_node import IdentifierNode
    from auv_ident.ros.sim_messages import sample_messages
    from auv_ident.vehicles import load_vehicle

    T = 1.0 / a.rate
    run = simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=a.seconds, T=T, seed=0)
    payloads = []
    for k in range(len(run.t)):
        msgs = {tp: m for tp, _, m in sample_messages(run, k, with_truth=False)}
        payloads.append((serialize_message(msgs['/actuators']),
                         serialize_message(msgs['/odom'])))
    n = len(payloads)
    warm = n // 10

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = IdentifierNode(context=ctx, parameter_overrides=[
        Parameter('sample_time', value=T), Parameter('publish_rate_hz', value=a.publish_rate)])
    parts = {'deserialize': 0.0, 'session': 0.0, 'on_odom': 0.0, 'publish': 0.0}
    clock = time.thread_time
    node.odom.session.on_input = _timed(node.odom.session.on_input, parts, 'session')
    node.odom.session.on_odom = _timed(node.odom.session.on_odom, parts, 'on_odom')
    node.odom.publish_estimate = _timed(node.odom.publish_estimate, parts, 'publish')
    cmd_t = odom_t = 0.0
    prof = cProfile.Profile() if a.profile else None
    for k, (cmd, odom) in enumerate(payloads):
        if k == warm:
            cmd_t = odom_t = 0.0
            parts.update(dict.fromkeys(parts, 0.0))    # in place: _timed holds it
            if prof is not None:
                prof.enable()
        t0 = clock()
        msg = deserialize_message(cmd, JointState)
        t1 = clock()
        node.odom.on_actuators(msg)
        t2 = clock()
        node.odom.on_odom_payload(odom)
        t3 = clock()
        parts['deserialize'] += t1 - t0
        cmd_t += t2 - t1
        odom_t += t3 - t2
    if prof is not None:
        prof.disable()
    m = n - warm
    us = 1e6 / m
    total = (parts['deserialize'] + cmd_t + odom_t) * us
    print(f'{n} samples at {a.rate:g} Hz, {m} timed; us per sample (command + odometry), CPU:')
    print(f'  total                            {total:7.1f}')
    print(f'  command: rclpy deserialize       {parts["deserialize"] * us:7.1f}')
    print(f'  command: callback                {cmd_t * us:7.1f}')
    print(f'  odometry: raw callback           {odom_t * us:7.1f}')
    print(f'  of the callbacks: session        {parts["session"] * us:7.1f}')
    print(f'  of the callbacks: publish        {parts["publish"] * us:7.1f}')
    print(f'  of the session: on_odom          {parts["on_odom"] * us:7.1f}')
    if prof is not None:
        pstats.Stats(prof).sort_stats('cumulative').print_stats(35)
    node.destroy_node()
    rclpy.shutdown(context=ctx)


def _timed(fn, parts, key):
    """``fn`` adding its thread CPU time to ``parts[key]`` (s)."""
    def timed(*args, **kwargs):
        t0 = time.thread_time()
        try:
            return fn(*args, **kwargs)
        finally:
            parts[key] += time.thread_time() - t0
    return timed


def raw_cost(a):
    """The --raw measurement (module docstring)."""
    import tempfile

    import rclpy
    from rclpy.parameter import Parameter

    from auv_ident.bags.reader import read_bag
    from auv_ident.core.filter.raw import RawSensorFilter
    from auv_ident.offline.raw_example import write_raw_example
    from auv_ident.ros.identifier_node import IdentifierNode
    from auv_ident.session.input_map import IMU, load_input_map

    bag, map_path = write_raw_example(tempfile.mkdtemp(prefix='node_cost_'),
                                      duration=a.seconds, seed=5, imu_rate=a.imu_rate)
    imap = load_input_map(str(map_path))
    by_topic = {e.bag_topic: e for e in imap.inputs}
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = IdentifierNode(context=ctx, parameter_overrides=[
        Parameter('input_map', value=str(map_path)),
        Parameter('coefficients', value=['Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v']),
        Parameter('publish_rate_hz', value=a.publish_rate)])
    raw = node.raw
    imu_callback = {s.topic_name: raw.intake.callbacks[s.topic_name]
                    for s in raw.subscriptions if s.raw}
    feed = []
    for (topic, ns, m), (_, _, payload) in zip(read_bag(bag, imap.topic_types),
                                               read_bag(bag, imap.topic_types, raw=True)):
        e = by_topic[topic]
        if e.type == IMU:
            feed.append((imu_callback[e.topic], (payload,)))
        else:
            feed.append((raw.on_input, (e.name, m, ns)))
    clock = time.thread_time
    parts = {'session': 0.0, 'publish': 0.0, 'filter': 0.0}
    raw.session.on_input = _timed(raw.session.on_input, parts, 'session')
    raw.publish_estimate = _timed(raw.publish_estimate, parts, 'publish')
    # the IMU's filter step (on the class: a filter restart makes a new filter)
    if hasattr(RawSensorFilter, 'process_imu'):
        RawSensorFilter.process_imu = _timed(RawSensorFilter.process_imu, parts, 'filter')
    n, warm = len(feed), len(feed) // 10
    total = 0.0
    prof = cProfile.Profile() if a.profile else None
    for k, (callback, args) in enumerate(feed):
        if k == warm:
            total = 0.0
            parts.update(dict.fromkeys(parts, 0.0))
            if prof is not None:
                prof.enable()
        t0 = clock()
        callback(*args)
        total += clock() - t0
    if prof is not None:
        prof.disable()
    us = 1e6 / (n - warm)
    print(f'{n} raw messages (IMU {a.imu_rate:g} Hz), {n - warm} timed; us per message, CPU:')
    print(f'  total (callback)                 {total * us:7.1f}')
    print(f'  of it: RawSession.on_input       {parts["session"] * us:7.1f}')
    print(f'  of it: publish                   {parts["publish"] * us:7.1f}')
    print(f'  of the session: IMU filter step  {parts["filter"] * us:7.1f}')
    if prof is not None:
        pstats.Stats(prof).sort_stats('tottime').print_stats(35)
    node.destroy_node()
    rclpy.shutdown(context=ctx)


if __name__ == '__main__':
    main()
