"""record and play nodes as real processes: bags they write and messages they publish.

Every node process gets the ros_env environment (loopback DDS, this run's ROS_DOMAIN_ID, see
conftest.py). Messages are compared decoded, field by field, never as payload bytes (rclpy
payloads contain uninitialized padding).
"""
import os
from pathlib import Path
import select
import signal
import subprocess
import sys
import time
import warnings

from conftest import require_loopback_dds
from helpers import assert_msg_equal
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from nav_msgs.msg import Odometry
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
import ros_pub_helper
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader as RosbagsReader
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
import yaml

from auv_ident.bags.reader import message_counts, read_bag
from auv_ident.bags.repair import repair_bag
from auv_ident.bags.schema import BagError
from auv_ident.offline.sim_bag import bag_sample_messages, SIM_EPOCH_NS, TOPIC_TYPES, write_run_bag
from auv_ident.ros.raw_loadtest import _cmd as _node_cmd
from auv_ident.session.messages import sec_to_ns, stamp_to_ns

pytestmark = pytest.mark.slow     # record, play and publisher processes over DDS

HELPER = Path(ros_pub_helper.__file__)
N = 60            # samples the helper publishes (x 3 topics)
PUB_RATE = 100.0  # samples per second
TOPICS = ('/odom', '/actuators', '/clock')
TYPES = {'/odom': Odometry, '/actuators': JointState, '/clock': Clock}
PLAY_RATE = 5.0


@pytest.fixture(scope='module')
def samples():
    return ros_pub_helper.build_samples(N)


@pytest.fixture(scope='module')
def sim_run():
    from auv_ident.core.model.hydrodynamics import Model
    from auv_ident.core.simulation.simulate import simulate
    from auv_ident.vehicles import load_vehicle
    return simulate(Model(load_vehicle('nps_auv2'), ()), 'zigzag', duration=2.0, T=0.05,
                    seed=3)


def _spawn(cmd, env, **kw):
    require_loopback_dds()
    assert env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    return subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, **kw)


def _finish(proc, timeout=15.0, sig=None):
    """Send sig (if any), wait, return (rc, stdout, stderr); kill on a timeout."""
    if sig is not None:
        proc.send_signal(sig)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f'{proc.args[:5]} did not finish in {timeout} s:\n{err[-2000:]}')
    return proc.returncode, out, err


def _reap(*procs):
    for proc in procs:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def _readline(proc, timeout):
    """Return the next stdout line of proc ('' on EOF or timeout)."""
    ready, _, _ = select.select([proc.stdout], [], [], timeout)
    return proc.stdout.readline() if ready else ''


def _record_helper_run(tmp_path, env, sig):
    """Run the helper publisher and a recorder; stop the recorder with sig; return the bag."""
    bag = tmp_path / 'rec'
    helper = _spawn([sys.executable, str(HELPER), '--count', str(N), '--rate', str(PUB_RATE),
                     '--hold'], env, stdin=subprocess.PIPE)
    recorder = _spawn(_node_cmd('record', f'topics:=[{",".join(TOPICS)}]', f'output:={bag}',
                                'wait_for_topics_s:=20.0'), env)
    try:
        t_start = time.time_ns()
        line = _readline(helper, timeout=40.0)
        if line.strip() != f'done {N}':
            helper.kill()
            pytest.fail(f'helper: {line!r} {helper.communicate()[1][-2000:]}')
        assert recorder.poll() is None, recorder.communicate()[1]
        # the helper's publishers stay alive until the recorder has stopped
        time.sleep(0.3 if sig != signal.SIGKILL else 1.5)  # SIGKILL: > 2 flush periods
        t_end = time.time_ns()  # every message must have been received by now
        rc, _, err = _finish(recorder, sig=sig)
        helper.communicate(input='', timeout=15.0)  # EOF: the helper exits
        assert helper.returncode == 0
    finally:
        _reap(helper, recorder)
    return bag, rc, err, (t_start, t_end)


def _check_recorded(bag, samples, window, allow_truncated=False):
    per_topic = {t: [] for t in TOPICS}
    for topic, t_ns, msg in read_bag(bag, allow_truncated=allow_truncated):
        per_topic[topic].append((t_ns, msg))
    assert {t: len(v) for t, v in per_topic.items()} == dict.fromkeys(TOPICS, N)
    for j, topic in enumerate(TOPICS):
        times = [t for t, _ in per_topic[topic]]
        # log time = receive time (system clock), not the header stamp (sim time from 0 s)
        assert window[0] <= times[0] and times[-1] <= window[1], topic
        assert times == sorted(times)
        for k, (_, msg) in enumerate(per_topic[topic]):
            assert_msg_equal(samples[k][j][1], msg, f'{topic}[{k}]')


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_record_until_signal(tmp_path, ros_env, samples, sig):
    bag, rc, err, window = _record_helper_run(tmp_path, ros_env, sig)
    assert rc == 0, err
    assert 'Traceback' not in err
    assert (bag / 'metadata.yaml').is_file()
    assert message_counts(bag) == dict.fromkeys(TOPICS, N)
    _check_recorded(bag, samples, window)

    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['message_count'] == 3 * N
    meta = {t['topic_metadata']['name']: t['topic_metadata']
            for t in info['topics_with_message_count']}
    assert meta['/actuators']['type'] == 'sensor_msgs/msg/JointState'
    # the publisher's offered QoS, as get_publishers_info_by_topic reports it
    assert [q['reliability'] for q in meta['/odom']['offered_qos_profiles']] == ['reliable']

    if sig == signal.SIGTERM:
        return  # the readers below are exercised once
    # rosbags AnyReader (JointState with empty effort needs rclpy: the padding pitfall)
    got = {t: [] for t in TOPICS}
    with AnyReader([bag]) as reader:
        assert {c.topic: c.msgcount for c in reader.connections} == dict.fromkeys(TOPICS, N)
        for conn, _, raw in reader.messages():
            try:
                msg = reader.deserialize(raw, conn.msgtype)
            except Exception:
                assert conn.msgtype == 'sensor_msgs/msg/JointState'
                msg = deserialize_message(bytes(raw), JointState)
            got[conn.topic].append(msg)
    assert {t: len(v) for t, v in got.items()} == dict.fromkeys(TOPICS, N)
    for j, topic in enumerate(TOPICS):
        for k, msg in enumerate(got[topic]):
            assert_msg_equal(samples[k][j][1], msg, f'AnyReader {topic}[{k}]')
    # mcap + mcap_ros2
    got = {t: [] for t in TOPICS}
    with open(bag / f'{bag.name}_0.mcap', 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages(log_time_order=True):
            got[channel.topic].append(msg)
    assert {t: len(v) for t, v in got.items()} == dict.fromkeys(TOPICS, N)
    for j, topic in enumerate(TOPICS):
        for k, msg in enumerate(got[topic]):
            assert_msg_equal(samples[k][j][1], msg, f'mcap_ros2 {topic}[{k}]')


def test_record_sigkill_keeps_flushed_chunks(tmp_path, ros_env, samples):
    """SIGKILL: no metadata.yaml, but everything older than a flush period is recoverable."""
    bag, rc, _, window = _record_helper_run(tmp_path, ros_env, signal.SIGKILL)
    assert rc == -signal.SIGKILL
    assert not (bag / 'metadata.yaml').exists()
    with pytest.raises(BagError, match='truncated'):
        read_bag(bag)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')  # 'recovered ... from complete chunks'
        _check_recorded(bag, samples, window, allow_truncated=True)
    # `bag repair` turns it into a complete bag: read without allow_truncated
    report = repair_bag(bag, out=tmp_path / 'repaired')
    assert [f.rewritten for f in report.files] == [True]
    _check_recorded(tmp_path / 'repaired', samples, window)
    with RosbagsReader(tmp_path / 'repaired') as reader:
        assert {c.topic: c.msgcount for c in reader.connections} == dict.fromkeys(TOPICS, N)


def _probe(ctx, topics):
    """A subscriber node (own context) collecting (monotonic time, msg) per topic."""
    node = rclpy.create_node('test_probe', context=ctx)
    got = {t: [] for t in topics}
    for topic, cls in topics.items():
        node.create_subscription(
            cls, topic, lambda m, t=topic: got[t].append((time.monotonic(), m)),
            QoSProfile(depth=1000))
    return node, got


def test_play_publishes_every_message_in_order(tmp_path, ros_env, ctx, sim_run):
    bag = write_run_bag(sim_run, tmp_path / 'run')
    topics = {t: (Odometry if 'Odometry' in ty else JointState) for t, ty in TOPIC_TYPES.items()}
    topics['/clock'] = Clock
    node, got = _probe(ctx, topics)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    player = _spawn(_node_cmd('play', f'bag:={bag}', f'rate:={PLAY_RATE}',
                              'publish_clock:=true', 'wait_for_subscribers_s:=20.0',
                              f'wait_for_subscribers:=[{",".join(topics)}]'), ros_env)
    n = len(sim_run.t)
    try:
        deadline = time.monotonic() + 40.0
        while time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.02)
            if all(len(v) >= n for v in got.values()):
                break
            if player.poll() is not None:  # exited: what is still to come arrives at once
                deadline = min(deadline, time.monotonic() + 2.0)
        for _ in range(10):  # anything still queued
            executor.spin_once(timeout_sec=0.01)
        rc, out, err = _finish(player)
    finally:
        _reap(player)
        executor.shutdown()
        node.destroy_node()
    assert rc == 0, err
    assert 'Traceback' not in err
    assert {t: len(v) for t, v in got.items()} == dict.fromkeys(topics, n), (
        err, [stamp_to_ns(m.clock) for _, m in got['/clock']])
    for k in range(n):
        for topic, _, expected in bag_sample_messages(sim_run, k):
            assert_msg_equal(expected, got[topic][k][1], f'{topic}[{k}]')
    # /clock = the log times (here the sample times from the simulated bags' epoch), ascending
    clock_ns = [stamp_to_ns(m.clock) for _, m in got['/clock']]
    assert clock_ns == [SIM_EPOCH_NS + sec_to_ns(t) for t in sim_run.t]
    # the recorded spacing divided by rate: 2.0 s of log time in about 0.4 s
    arrival = [t for t, _ in got['/odom']]
    span = arrival[-1] - arrival[0]
    expected_span = (sim_run.t[-1] - sim_run.t[0]) / PLAY_RATE
    assert 0.8 * expected_span <= span <= expected_span + 1.0, span


def test_record_play_round_trip(tmp_path, ros_env, sim_run):
    source = write_run_bag(sim_run, tmp_path / 'source')
    copy = tmp_path / 'copy'
    topics = list(TOPIC_TYPES)
    # the odometry and actuator topics through the default input map (odom_actuators), the
    # truth by name
    player = _spawn(_node_cmd('play', f'bag:={source}', f'rate:={PLAY_RATE}',
                              'input_map:=odom_actuators', 'topics:=[/simulator/truth]',
                              f'wait_for_subscribers:=[{",".join(topics)}]',
                              'wait_for_subscribers_s:=20.0'), ros_env)
    recorder = _spawn(_node_cmd('record', 'topics:=[/simulator/truth]',
                                'input_map:=odom_actuators', f'output:={copy}',
                                'compression:=none', 'wait_for_topics_s:=20.0'), ros_env)
    try:
        rc, _, err = _finish(player, timeout=40.0)
        assert rc == 0, err
        time.sleep(0.3)
        rc, _, err = _finish(recorder, sig=signal.SIGINT)
        assert rc == 0, err
    finally:
        _reap(player, recorder)
    original = list(read_bag(source))
    recorded = list(read_bag(copy))
    assert message_counts(copy) == message_counts(source)
    for topic in topics:
        a = [m for t, _, m in original if t == topic]
        b = [m for t, _, m in recorded if t == topic]
        assert len(a) == len(b) == len(sim_run.t)
        for k in range(len(a)):
            # rebuild the bag's messages: the reference for field-by-field comparison
            expected = {t: m for t, _, m in bag_sample_messages(sim_run, k)}[topic]
            assert_msg_equal(expected, a[k], f'source {topic}[{k}]')
            assert_msg_equal(expected, b[k], f'copy {topic}[{k}]')
    times = [t_ns for t, t_ns, _ in recorded if t == '/odom']
    span = (times[-1] - times[0]) * 1e-9
    expected_span = (sim_run.t[-1] - sim_run.t[0]) / PLAY_RATE
    assert 0.8 * expected_span <= span <= expected_span + 1.0, span


def _corrupt_bag(tmp_path):
    bag = tmp_path / 'corrupt'
    bag.mkdir()
    (bag / 'corrupt_0.mcap').write_bytes(b'\x89MCAP0\r\n' + os.urandom(300))
    return bag


BAD_CASES = {
    'record_no_output': (('record', 'topics:=[/odom]'), "parameter 'output'"),
    'record_output_exists': (('record', 'topics:=[/odom]', 'output:={tmp}'), 'exists'),
    'record_no_topics': (('record', 'output:={tmp}/new'), "parameter 'topics'"),
    'record_bad_compression': (('record', 'topics:=[/odom]', 'output:={tmp}/new',
                                'compression:=lz4'), "parameter 'compression'"),
    'record_undiscovered': (('record', 'topics:=[/nobody_publishes_this]', 'output:={tmp}/x',
                             'wait_for_topics_s:=0.2'), '/nobody_publishes_this'),
    'record_bad_types': (('record', 'topics:=[/odom]', 'output:={tmp}/y',
                          'types:=[/odom=nav_msgs/msg/NoSuchType]'), 'NoSuchType'),
    'play_missing_bag': (('play', 'bag:={tmp}/nonexistent'), '{tmp}/nonexistent'),
    'play_corrupt_bag': (('play', 'bag:={corrupt}'), 'corrupt_0.mcap'),
    'play_bad_rate': (('play', 'bag:={corrupt}', 'rate:=0.0'), "parameter 'rate'"),
    'play_no_bag': (('play',), "parameter 'bag'"),
    'play_bad_ros_args': (('play', 'bag:=['), 'bad --ros-args'),
    'record_bad_input_map': (('record', 'input_map:=nope', 'output:={tmp}/z'),
                             "parameter 'input_map': input map 'nope': no file"),
    'play_bad_input_map': (('play', 'bag:={corrupt}', 'input_map:=nope'),
                           "parameter 'input_map': input map 'nope': no file"),
}


def test_bad_parameters_one_clear_line(tmp_path, ros_env):
    corrupt = _corrupt_bag(tmp_path)
    procs = {}
    try:
        for name, (args, _) in BAD_CASES.items():  # all at once: startup dominates
            node, *params = [a.format(tmp=tmp_path, corrupt=corrupt) for a in args]
            procs[name] = _spawn(_node_cmd(node, *params), ros_env)
        for name, (args, expected) in BAD_CASES.items():
            rc, out, err = _finish(procs[name], timeout=30.0)
            lines = [ln for ln in err.splitlines() if ln.strip()]
            assert rc == 2, (name, err)
            assert 'Traceback' not in err, (name, err)
            assert len(lines) == 1, (name, err)
            assert expected.format(tmp=tmp_path) in lines[0], (name, lines[0])
            assert lines[0].startswith(f'[{args[0]}] error: '), (name, lines[0])
    finally:
        _reap(*procs.values())
    assert not (tmp_path / 'new').exists() and not (tmp_path / 'x').exists()
    assert not (tmp_path / 'y').exists() and not (tmp_path / 'z').exists()
