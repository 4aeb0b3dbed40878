"""Tests of auv_ident.bags (schema, writer, reader, repair, info): rosbag2-layout MCAP writing,
reading, interop and bad input."""
from collections import Counter
import json
import logging
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import textwrap
import time

from helpers import assert_msg_equal, write_rclpy
from mcap.reader import make_reader, SeekingReader
from mcap_ros2.decoder import DecoderFactory
from nav_msgs.msg import Odometry
import numpy as np
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader as RosbagsReader
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
import yaml

from auv_ident.bags import reader as bag_reader, schema
from auv_ident.bags.reader import read_bag
from auv_ident.bags.repair import repair_bag
from auv_ident.bags.schema import BagError
from auv_ident.bags.writer import BagWriter
from auv_ident.ros import conversions as rc
from auv_ident.session import messages as sm

N = 120  # samples per topic
DT_NS = 5_000_000  # 200 Hz
T0_NS = 1_700_000_000 * 10**9  # epoch-scale stamps: ns must survive exactly
SHARE = Path(sys.prefix) / 'share'
SEP = '\n' + '=' * 80 + '\n'


def _expected_messages():
    """Return [(topic, t_ns, rclpy msg)] in time order: Odometry, JointState, Clock."""
    rng = np.random.default_rng(11)
    out = []
    for i in range(N):
        t_ns = T0_NS + i * DT_NS
        t = sm.stamp_to_sec(rc.ns_to_stamp(t_ns))
        x = rng.normal(size=12)
        cov = rng.normal(size=(6, 6))
        odom = rc.state_to_odometry(t, x, 'ned', pose_cov=cov @ cov.T, twist_cov=np.eye(6))
        odom.header.stamp = rc.ns_to_stamp(t_ns)
        joints = rc.actuators_to_joint_state(t, rng.normal(size=7))
        joints.effort = []      # what other writers send: the Fast-CDR padding pitfall
        joints.header.stamp = rc.ns_to_stamp(t_ns)
        clock = Clock(clock=rc.ns_to_stamp(t_ns))
        out += [('/odom', t_ns, odom), ('/actuators', t_ns + 1, joints),
                ('/clock', t_ns + 2, clock)]
    return out


EXPECTED = _expected_messages()


def _write_bag(path, compression=None, chunk_size=schema.DEFAULT_CHUNK_SIZE, messages=None):
    with BagWriter(path, compression=compression, chunk_size=chunk_size) as writer:
        writer.add_topic('/odom', 'nav_msgs/msg/Odometry')
        writer.add_topic('/actuators', 'sensor_msgs/JointState',
                         qos=QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT))
        writer.add_topic('/clock', 'rosgraph_msgs/msg/Clock', qos={'depth': 1})
        writer.set_custom_data('frame', 'ned')
        for topic, t_ns, msg in (EXPECTED if messages is None else messages):
            writer.write(topic, t_ns, serialize_message(msg))  # raw bytes, as a recorder
    return Path(path)


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    return _write_bag(tmp_path_factory.mktemp('bags') / 'run1')


def _mcap_file(bag_dir):
    return bag_dir / f'{bag_dir.name}_0.mcap'


# --- round trips and interop ------------------------------------------------------------------


def test_read_back_with_our_reader(bag):
    got = list(read_bag(bag))
    assert [(t, ns) for t, ns, _ in got] == [(t, ns) for t, ns, _ in EXPECTED]
    for (_, _, expected), (_, _, actual) in zip(EXPECTED, got):
        assert_msg_equal(expected, actual)
    # the EKF-facing view: conversions accept the decoded (rosbags) objects
    t, x12, pcov, _ = sm.odometry_to_state(got[0][2])
    assert sm.sec_to_ns(t) == T0_NS
    np.testing.assert_array_equal(pcov, np.asarray(EXPECTED[0][2].pose.covariance).reshape(6, 6))
    t, u7 = sm.joint_state_to_actuators(got[1][2])
    np.testing.assert_array_equal(u7, sm.joint_state_to_actuators(EXPECTED[1][2])[1])


def test_rclpy_joint_state_needs_the_fallback():
    """The pitfall is real: rosbags rejects rclpy's JointState with empty effort."""
    from rosbags.typesys import get_typestore, Stores
    payload = serialize_message(EXPECTED[1][2])
    with pytest.raises(Exception, match='size mismatch'):
        get_typestore(Stores.ROS2_JAZZY).deserialize_cdr(payload, 'sensor_msgs/msg/JointState')


def test_padding_is_tolerated_but_not_trailing_junk(tmp_path):
    """Up to 8 bytes of Fast-CDR padding pass; 16 bytes more are another payload: an error."""
    joints = EXPECTED[1][2]
    payload = serialize_message(joints)
    with BagWriter(tmp_path / 'junk') as writer:
        writer.add_topic('/actuators', 'sensor_msgs/msg/JointState')
        writer.write('/actuators', 1, payload)
        writer.write('/actuators', 2, payload + bytes(16))
    first = read_bag(tmp_path / 'junk', topics=['/actuators'])
    assert_msg_equal(joints, next(first)[2])
    with pytest.raises(BagError, match=r'junk: topic /actuators: undecodable sensor_msgs/msg/'
                                       r'JointState payload at 2 ns \(2[0-9] bytes left over'):
        next(first)


def test_an_undecodable_topic_is_skipped_with_one_warning(tmp_path, caplog):
    """Reading all topics: bad payloads of one topic are skipped (one warning naming it and
    why), every other message keeps coming; asked for by name, the topic is a BagError."""
    good = serialize_message(EXPECTED[1][2])
    with BagWriter(tmp_path / 'mixed') as writer:
        writer.add_topic('/odom', 'nav_msgs/msg/Odometry')
        writer.add_topic('/actuators', 'sensor_msgs/msg/JointState')
        for i, (topic, t_ns, msg) in enumerate(EXPECTED[:60]):
            if topic == '/odom':
                writer.write(topic, t_ns, serialize_message(msg))
                bad = good[:len(good) // 2] if i % 2 else good + bytes(32)
                writer.write('/actuators', t_ns + 1, bad)
                writer.write('/actuators', t_ns + 2, good)
    with caplog.at_level(logging.WARNING, logger='auv_ident.bags'):
        got = list(read_bag(tmp_path / 'mixed'))
    assert Counter(t for t, _, _ in got) == {'/odom': 20, '/actuators': 20}
    assert [ns for t, ns, _ in got if t == '/actuators'] == [
        ns + 2 for t, ns, _ in EXPECTED[:60] if t == '/odom']
    records = [r for r in caplog.records if r.name == 'auv_ident.bags']
    assert len(records) == 1
    text = records[0].getMessage()
    assert 'mixed: topic /actuators: undecodable sensor_msgs/msg/JointState payload' in text
    assert 'bytes left over' in text and 'skipping' in text
    with pytest.raises(BagError, match='topic /actuators: undecodable'):
        list(read_bag(tmp_path / 'mixed', topics=['/odom', '/actuators']))


def test_topic_selection_and_raw(bag):
    got = list(read_bag(bag, topics=['/actuators']))
    assert len(got) == N and {t for t, _, _ in got} == {'/actuators'}
    raw = list(read_bag(bag, topics={'/clock': 'rosgraph_msgs/Clock'}, raw=True))
    assert all(isinstance(m, bytes) for _, _, m in raw)
    assert_msg_equal(EXPECTED[2][2], deserialize_message(raw[0][2], Clock))


def test_log_time_order(tmp_path):
    shuffled = list(EXPECTED[:30])
    shuffled.reverse()  # written newest first
    path = _write_bag(tmp_path / 'rev', chunk_size=2048, messages=shuffled)
    times = [ns for _, ns, _ in read_bag(path)]
    assert times == sorted(times) and len(times) == 30


@pytest.mark.parametrize('pattern', ['in_order', 'ties', 'overlapping', 'shuffled'])
def test_log_time_order_is_mcaps_own_order(tmp_path, pattern):
    """read_bag reads chunks whose time ranges do not overlap one after another (each sorted
    in itself) and leaves the rest to mcap's merge: either way the order is exactly mcap's
    (log time, then the file's order), ties at chunk boundaries included."""
    rng = np.random.default_rng(3)
    msgs = list(EXPECTED[:60])
    if pattern == 'ties':       # runs of equal log times across chunk boundaries
        msgs = [(topic, T0_NS + (k // 7), m) for k, (topic, _, m) in enumerate(msgs)]
    elif pattern == 'overlapping':  # each chunk spans the whole run: mcap must merge
        msgs = [msgs[i] for i in np.argsort([(k % 5) * 1000 + k for k in range(60)])]
    elif pattern == 'shuffled':
        msgs = [msgs[i] for i in rng.permutation(60)]
    path = _write_bag(tmp_path / pattern, chunk_size=1024, messages=msgs)
    got = [(topic, ns, bytes(data)) for topic, ns, data in read_bag(path, raw=True)]
    with open(_mcap_file(path), 'rb') as fh:
        reader = SeekingReader(fh)
        want = [(ch.topic, m.log_time, bytes(m.data))
                for _, ch, m in reader.iter_messages(log_time_order=True)]
        chunks = reader.get_summary().chunk_indexes
    assert got == want and len(got) == 60 and len(chunks) > 3
    # the path taken: chunk by chunk unless chunks overlap in time
    merged = bag_reader._chunks_in_time_order(chunks) is None
    assert merged == (pattern in ('overlapping', 'shuffled'))


def test_rosbags_reader_and_anyreader(bag):
    with RosbagsReader(bag) as reader:
        conns = {c.topic: c for c in reader.connections}
        assert {t: c.msgtype for t, c in conns.items()} == {
            '/odom': 'nav_msgs/msg/Odometry', '/actuators': 'sensor_msgs/msg/JointState',
            '/clock': 'rosgraph_msgs/msg/Clock'}
        assert all(c.msgcount == N for c in conns.values())
        qos = conns['/actuators'].ext.offered_qos_profiles[0]
        assert qos.depth == 5 and qos.reliability.name == 'BEST_EFFORT'
        assert reader.message_count == 3 * N
    decoded = []
    with AnyReader([bag]) as reader:
        for conn, t_ns, raw in reader.messages():
            try:
                msg = reader.deserialize(raw, conn.msgtype)
            except Exception:  # only the documented JointState pitfall
                assert conn.msgtype == 'sensor_msgs/msg/JointState'
                msg = deserialize_message(bytes(raw), JointState)
            decoded.append((conn.topic, t_ns, msg))
    assert [(t, ns) for t, ns, _ in decoded] == [(t, ns) for t, ns, _ in EXPECTED]
    for (_, _, expected), (_, _, actual) in zip(EXPECTED, decoded):
        assert_msg_equal(expected, actual)


def test_mcap_ros2_decoder(bag):
    with open(_mcap_file(bag), 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        decoded = [(ch.topic, m.log_time, msg)
                   for _, ch, m, msg in reader.iter_decoded_messages(log_time_order=True)]
    assert len(decoded) == len(EXPECTED)
    for (topic, t_ns, expected), (topic2, t2, actual) in zip(EXPECTED, decoded):
        assert (topic, t_ns) == (topic2, t2)
        assert_msg_equal(expected, actual)


def test_bare_mcap_file_and_info(bag):
    got = list(read_bag(_mcap_file(bag), topics=['/odom']))
    assert len(got) == N
    assert_msg_equal(EXPECTED[0][2], got[0][2])
    topics = bag_reader.bag_topics(bag)
    assert topics == {'/odom': 'nav_msgs/msg/Odometry',
                      '/actuators': 'sensor_msgs/msg/JointState',
                      '/clock': 'rosgraph_msgs/msg/Clock'}
    assert bag_reader.message_counts(_mcap_file(bag)) == dict.fromkeys(topics, N)


def test_zstd_bag(tmp_path):
    path = _write_bag(tmp_path / 'z', compression='zstd', chunk_size=4096)
    with open(_mcap_file(path), 'rb') as f:
        summary = make_reader(f).get_summary()
    assert len(summary.chunk_indexes) > 1
    assert {c.compression for c in summary.chunk_indexes} == {'zstd'}
    got = list(read_bag(path))
    for (_, _, expected), (_, _, actual) in zip(EXPECTED, got):
        assert_msg_equal(expected, actual)
    with AnyReader([path]) as reader:
        assert sum(1 for _ in reader.messages()) == len(EXPECTED)


# --- rosbag2 layout ---------------------------------------------------------------------------


def test_metadata_yaml_v9(bag):
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['version'] == 9
    assert info['storage_identifier'] == 'mcap'
    assert info['relative_file_paths'] == ['run1_0.mcap']
    assert info['message_count'] == 3 * N
    assert info['starting_time'] == {'nanoseconds_since_epoch': T0_NS}
    last = EXPECTED[-1][1]
    assert info['duration'] == {'nanoseconds': last - T0_NS}
    assert info['files'] == [{'path': 'run1_0.mcap',
                              'starting_time': {'nanoseconds_since_epoch': T0_NS},
                              'duration': {'nanoseconds': last - T0_NS},
                              'message_count': 3 * N}]
    assert (info['compression_format'], info['compression_mode']) == ('', '')
    assert info['custom_data'] == {'frame': 'ned'}
    assert info['ros_distro'] == 'jazzy'
    topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    assert set(topics) == {'/odom', '/actuators', '/clock'}
    odom = topics['/odom']
    assert odom['message_count'] == N
    meta = odom['topic_metadata']
    assert meta['type'] == 'nav_msgs/msg/Odometry'
    assert meta['serialization_format'] == 'cdr'
    assert meta['type_description_hash'] == _share_hash('nav_msgs/msg/Odometry')
    assert meta['offered_qos_profiles'] == [schema.DEFAULT_QOS]
    qos = topics['/actuators']['topic_metadata']['offered_qos_profiles'][0]
    assert (qos['history'], qos['depth'], qos['reliability'], qos['durability'],
            qos['liveliness']) == ('keep_last', 5, 'best_effort', 'volatile', 'system_default')
    assert qos['deadline'] == {'sec': 0, 'nsec': 0}  # rclpy default: unspecified
    assert topics['/clock']['topic_metadata']['offered_qos_profiles'][0]['depth'] == 1
    assert schema.DEFAULT_QOS['lifespan'] == {'sec': 9223372036, 'nsec': 854775807}


def _share_hash(msgtype):
    pkg, ns, name = msgtype.split('/')
    doc = json.loads((SHARE / pkg / ns / f'{name}.json').read_text())
    return next(h['hash_string'] for h in doc['type_hashes'] if h['type_name'] == msgtype)


def test_mcap_records_follow_rosbag2(bag):
    with open(_mcap_file(bag), 'rb') as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        metadata = list(reader.iter_metadata())
    assert header.profile == 'ros2'
    schemas = {s.name: s for s in summary.schemas.values()}
    assert set(schemas) == {'nav_msgs/msg/Odometry', 'sensor_msgs/msg/JointState',
                            'rosgraph_msgs/msg/Clock'}
    assert {s.encoding for s in schemas.values()} == {'ros2msg'}
    for channel in summary.channels.values():
        assert channel.message_encoding == 'cdr'
        assert set(channel.metadata) == {'offered_qos_profiles', 'topic_type_hash'}
        msgtype = summary.schemas[channel.schema_id].name
        assert channel.metadata['topic_type_hash'] == _share_hash(msgtype)
        assert channel.metadata['topic_type_hash'].startswith('RIHS01_')
        profiles = yaml.safe_load(channel.metadata['offered_qos_profiles'])
        assert isinstance(profiles, list) and isinstance(profiles[0]['reliability'], str)
        assert not channel.metadata['offered_qos_profiles'].endswith('\n')  # as yaml-cpp
    stats = summary.statistics
    assert stats.message_count == 3 * N and stats.channel_count == 3
    assert sorted(stats.channel_message_counts.values()) == [N, N, N]
    rosbag2 = [m for m in metadata if m.name == 'rosbag2']
    assert len(rosbag2) == 1
    serialized = yaml.safe_load(rosbag2[0].metadata['serialized_metadata'])
    on_disk = yaml.safe_load((bag / 'metadata.yaml').read_text())
    assert serialized == on_disk['rosbag2_bagfile_information']


def test_schema_text_is_rosbag2_full_text(bag):
    with open(_mcap_file(bag), 'rb') as f:
        summary = make_reader(f).get_summary()
    text = next(s.data.decode() for s in summary.schemas.values()
                if s.name == 'nav_msgs/msg/Odometry')
    root = (SHARE / 'nav_msgs' / 'msg' / 'Odometry.msg').read_text()
    assert text.startswith(root + SEP + 'MSG: geometry_msgs/PoseWithCovariance\n')
    assert SEP + 'MSG: geometry_msgs/Pose\n' in text
    # each dependency once, sorted and depth first, as rosbag2's local definition source
    order = [line[5:] for line in text.split('\n') if line.startswith('MSG: ')]
    assert order == ['geometry_msgs/PoseWithCovariance', 'geometry_msgs/Pose',
                     'geometry_msgs/Point', 'geometry_msgs/Quaternion',
                     'geometry_msgs/TwistWithCovariance', 'geometry_msgs/Twist',
                     'geometry_msgs/Vector3', 'std_msgs/Header', 'builtin_interfaces/Time']
    for section in text.split(SEP)[1:]:
        name, body = section.split('\n', 1)
        pkg, typ = name[5:].split('/')
        assert body == (SHARE / pkg / 'msg' / f'{typ}.msg').read_text()
    clock = schema.message_definition('rosgraph_msgs/msg/Clock')
    assert clock == ((SHARE / 'rosgraph_msgs/msg/Clock.msg').read_text() + SEP
                     + 'MSG: builtin_interfaces/Time\n'
                     + (SHARE / 'builtin_interfaces/msg/Time.msg').read_text())


def test_qos_yaml_form():
    text = schema.qos_yaml([schema.qos_to_dict({'reliability': 'best_effort'})])
    assert text.startswith('- history: keep_last\n  depth: 10\n  reliability: best_effort\n')
    assert '  deadline:\n    sec: 9223372036\n    nsec: 854775807\n' in text
    assert text.endswith('avoid_ros_namespace_conventions: false')
    assert schema.qos_yaml([]) == '[]'
    with pytest.raises(BagError, match='reliability'):
        schema.qos_to_dict({'reliability': 'sometimes'})
    with pytest.raises(BagError, match='unknown QoS keys'):
        schema.qos_to_dict({'depht': 3})


# --- writer behaviour -------------------------------------------------------------------------


def test_writer_errors(tmp_path):
    existing = tmp_path / 'exists'
    existing.mkdir()
    with pytest.raises(BagError, match='exists'):
        BagWriter(existing)
    with pytest.raises(BagError, match='compression'):
        BagWriter(tmp_path / 'c', compression='lz4')
    writer = BagWriter(tmp_path / 'w')
    with pytest.raises(BagError, match='absolute'):
        writer.add_topic('odom', 'nav_msgs/msg/Odometry')
    with pytest.raises(BagError, match='invalid message type'):
        writer.add_topic('/odom', 'Odometry')
    with pytest.raises(BagError, match='no .msg definition'):
        writer.add_topic('/odom', 'nav_msgs/msg/Odometree')
    writer.add_topic('/odom', 'nav_msgs/msg/Odometry')
    writer.add_topic('/odom', 'nav_msgs/Odometry')  # same type again: fine
    with pytest.raises(BagError, match='already has type'):
        writer.add_topic('/odom', 'sensor_msgs/msg/JointState')
    with pytest.raises(BagError, match=r'/imu was not added.*/odom'):
        writer.write('/imu', 0, serialize_message(Odometry()))
    with pytest.raises(BagError, match='not CDR'):
        writer.write('/odom', 0, b'hello')
    with pytest.raises(BagError, match='nanoseconds'):
        writer.write('/odom', 0.5, serialize_message(Odometry()))
    with pytest.raises(BagError, match='nanoseconds'):
        writer.write('/odom', -1, serialize_message(Odometry()))
    assert not hasattr(writer, 'write_msg')  # bytes only: serializing is the ROS layer's job
    writer.write('/odom', 7, serialize_message(Odometry()))
    writer.close()
    writer.close()  # idempotent
    assert writer.closed
    with pytest.raises(BagError, match='closed'):
        writer.write('/odom', 8, serialize_message(Odometry()))
    writer.flush()  # no-op once closed
    assert bag_reader.message_counts(tmp_path / 'w') == {'/odom': 1}


def test_empty_bag_is_valid(tmp_path):
    with BagWriter(tmp_path / 'empty') as writer:
        writer.add_topic('/odom', 'nav_msgs/msg/Odometry')
    assert list(read_bag(tmp_path / 'empty')) == []
    assert bag_reader.message_counts(tmp_path / 'empty') == {'/odom': 0}
    with RosbagsReader(tmp_path / 'empty') as reader:
        assert reader.message_count == 0


def test_exception_in_with_block_still_finalises(tmp_path):
    with pytest.raises(RuntimeError):
        with BagWriter(tmp_path / 'x') as writer:
            write_rclpy(writer, '/clock', 5, Clock())
            raise RuntimeError('boom')
    assert (tmp_path / 'x' / 'metadata.yaml').is_file()
    assert [ns for _, ns, _ in read_bag(tmp_path / 'x')] == [5]


class _InterruptOnce:
    """A file whose n-th write raises KeyboardInterrupt after writing half its bytes: SIGINT
    arriving while mcap's Writer hands a chunk to the file."""

    def __init__(self, fh, at):
        self._fh, self._at, self.writes = fh, at, 0

    def write(self, data):
        self.writes += 1
        if self.writes == self._at:
            self._fh.write(bytes(data)[:len(data) // 2])
            raise KeyboardInterrupt
        return self._fh.write(data)

    def __getattr__(self, name):
        return getattr(self._fh, name)


@pytest.mark.parametrize('at', [4, 5, 6, 7, 8, 9])
def test_interrupted_write_still_closes_a_readable_bag(tmp_path, at):
    """An exception inside a write leaves mcap's Writer torn; close() keeps the complete
    chunks (as bag repair would), never a summary that points past the file's end."""
    payload = serialize_message(Clock())
    path = tmp_path / 'torn'
    writer = BagWriter(path, chunk_size=256)
    writer.add_topic('/clock', 'rosgraph_msgs/msg/Clock')
    writer.set_custom_data('vehicle', 'nps_auv2')
    stream = _InterruptOnce(writer._fh, at)
    writer._writer._Writer__stream = stream  # mcap's Writer writes through this
    written = 0
    with pytest.raises(KeyboardInterrupt):
        with writer:
            for i in range(10000):
                writer.write('/clock', i, payload)
                written += 1
    assert stream.writes >= at
    times = [ns for _, ns, _ in read_bag(path)]
    # the message being written when interrupted may have made it into a complete chunk
    assert 0 < len(times) <= written + 1 and times == list(range(len(times)))
    info = schema.read_metadata(path)
    assert info['message_count'] == len(times)
    assert schema.custom_data_of(info) == {'vehicle': 'nps_auv2'}
    assert not list(path.glob('*.rewriting'))
    with pytest.raises(BagError, match='closed'):
        writer.write('/clock', 10**6, payload)


_CHILD = textwrap.dedent("""
    import signal, sys, time
    # a process started in the background of a non-interactive shell inherits SIGINT ignored
    # (POSIX), and Python then leaves it ignored: this test is about the writer, so the child
    # takes SIGINT as an interactive program does
    signal.signal(signal.SIGINT, signal.default_int_handler)
    from rclpy.serialization import serialize_message
    from rosgraph_msgs.msg import Clock
    from auv_ident.bags.writer import BagWriter
    payload = serialize_message(Clock())
    with BagWriter(sys.argv[1], chunk_size=1024) as w:
        w.add_topic('/clock', 'rosgraph_msgs/msg/Clock')
        for i in range(100):
            w.write('/clock', i, payload)
        w.flush()
        print('ready', flush=True)
        i = 100
        while True:
            w.write('/clock', i, payload)
            i += 1
            time.sleep(0.0005)
""")


@pytest.fixture
def child():
    """Start a bag-writing process (no ROS node) that runs until signalled; reap it after."""
    procs = []

    def start(path):
        proc = subprocess.Popen([sys.executable, '-c', _CHILD, str(path)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        procs.append(proc)
        assert proc.stdout.readline().strip() == 'ready', proc.stderr.read()
        time.sleep(0.3)  # let it fill and hand over a few more chunks
        return proc

    yield start
    for proc in procs:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=20)
        proc.stdout.close()
        proc.stderr.close()


def test_sigint_finalises_bag(tmp_path, child):
    path = tmp_path / 'sigint'
    proc = child(path)
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail('the writer did not finish 20 s after SIGINT; its stderr: '
                    + proc.communicate()[1][-3000:])
    assert (path / 'metadata.yaml').is_file()
    times = [ns for _, ns, _ in read_bag(path)]
    assert times[:100] == list(range(100)) and times == list(range(len(times)))


def test_sigkill_loses_at_most_the_open_chunk(tmp_path, child):
    path = tmp_path / 'killed'
    proc = child(path)
    proc.kill()
    proc.wait(timeout=20)
    assert not (path / 'metadata.yaml').exists()
    with pytest.raises(BagError, match='truncated'):
        read_bag(path)
    with pytest.warns(UserWarning, match='recovered'):
        got = list(read_bag(path, allow_truncated=True))
    times = [ns for _, ns, _ in got]
    assert len(times) >= 100 and times == list(range(len(times)))
    # bag repair makes it a complete bag that index-based readers read in time order
    report = repair_bag(path, out=tmp_path / 'repaired')
    assert report.files[0].rewritten and report.files[0].messages == len(times)
    with open(tmp_path / 'repaired' / 'killed_0.mcap', 'rb') as f:
        reader = make_reader(f)
        assert isinstance(reader, SeekingReader)
        assert [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)] == times
    with RosbagsReader(tmp_path / 'repaired') as reader:
        assert [t for _, t, _ in reader.messages()] == times
    assert [ns for _, ns, _ in read_bag(tmp_path / 'repaired')] == times


# --- reader errors ----------------------------------------------------------------------------


def test_missing_empty_and_not_a_bag(tmp_path):
    with pytest.raises(BagError, match=r'nope.*does not exist'):
        read_bag(tmp_path / 'nope')
    (tmp_path / 'empty_dir').mkdir()
    with pytest.raises(BagError, match=r'empty_dir: empty directory'):
        read_bag(tmp_path / 'empty_dir')
    (tmp_path / 'zero.mcap').write_bytes(b'')
    with pytest.raises(BagError, match=r'zero.mcap: empty file'):
        read_bag(tmp_path / 'zero.mcap')
    with pytest.raises(BagError, match=r'zero.mcap: empty file'):
        bag_reader.bag_topics(tmp_path / 'zero.mcap')
    (tmp_path / 'text.mcap').write_text('definitely not an mcap file, but long enough ' * 3)
    with pytest.raises(BagError, match=r'text.mcap: not an MCAP file'):
        read_bag(tmp_path / 'text.mcap')
    with pytest.raises(BagError, match=r'text.mcap: not an MCAP file'):
        read_bag(tmp_path / 'text.mcap', allow_truncated=True)
    other = tmp_path / 'other'
    other.mkdir()
    (other / 'notes.txt').write_text('x')
    with pytest.raises(BagError, match='not a bag'):
        read_bag(other)


def test_bag_dir_without_metadata_yaml(tmp_path, bag):
    copy = tmp_path / 'no_meta'
    shutil.copytree(bag, copy)
    (copy / 'metadata.yaml').unlink()
    assert len(list(read_bag(copy, topics=['/clock']))) == N


def test_bad_metadata_yaml(tmp_path, bag):
    copy = tmp_path / 'copy'
    shutil.copytree(bag, copy)
    (copy / 'metadata.yaml').write_text('rosbag2_bagfile_information: [unclosed')
    with pytest.raises(BagError, match='metadata.yaml'):
        read_bag(copy)
    (copy / 'metadata.yaml').write_text(
        'rosbag2_bagfile_information:\n  storage_identifier: mcap\n'
        '  relative_file_paths: [gone_0.mcap]\n')
    with pytest.raises(BagError, match='gone_0.mcap'):
        read_bag(copy)


def test_absent_topic_lists_present_ones(bag):
    with pytest.raises(BagError, match=r'/imu.*present: /actuators \(sensor_msgs/msg/JointState'
                                       r'\), /clock .*, /odom \(nav_msgs/msg/Odometry\)'):
        read_bag(bag, topics=['/odom', '/imu'])
    with pytest.raises(BagError, match=r'/odom has type nav_msgs/msg/Odometry, expected '
                                       r'sensor_msgs/msg/JointState'):
        read_bag(bag, topics={'/odom': 'sensor_msgs/msg/JointState'})


@pytest.mark.parametrize('fraction', [0.05, 0.5, 0.97])
def test_truncated_file(tmp_path, fraction):
    path = _write_bag(tmp_path / 'cut', chunk_size=2048)
    data = _mcap_file(path).read_bytes()
    _mcap_file(path).write_bytes(data[:int(len(data) * fraction)])
    with pytest.raises(BagError, match=r'cut_0.mcap: truncated'):
        read_bag(path)
    with pytest.raises(BagError, match='truncated'):
        bag_reader.message_counts(path)
    with pytest.warns(UserWarning, match='recovered'):
        got = list(read_bag(path, allow_truncated=True))
    if fraction < 0.9:  # at 0.97 only the summary is cut: every chunk is still complete
        assert 0 < len(got) < len(EXPECTED) or fraction < 0.1
    assert [(t, ns) for t, ns, _ in got] == [(t, ns) for t, ns, _ in EXPECTED[:len(got)]]
    for (_, _, expected), (_, _, actual) in zip(EXPECTED, got):
        assert_msg_equal(expected, actual)


def test_truncated_by_one_byte(tmp_path, bag):
    cut = tmp_path / 'one.mcap'
    cut.write_bytes(_mcap_file(bag).read_bytes()[:-1])
    with pytest.raises(BagError, match='one.mcap: truncated'):
        read_bag(cut)


def _flipped(path, data, offset):
    corrupt = bytearray(data)
    corrupt[offset] ^= 0xFF
    path.write_bytes(bytes(corrupt))


def test_flipped_chunk_bytes_are_detected(tmp_path, bag):
    data = _mcap_file(bag).read_bytes()
    with open(_mcap_file(bag), 'rb') as f:
        chunk = make_reader(f).get_summary().chunk_indexes[0]
    target = tmp_path / 'flip.mcap'
    # a float inside a message: only the chunk CRC can tell
    _flipped(target, data, chunk.chunk_start_offset + chunk.chunk_length // 2)
    with pytest.raises(BagError, match=r'flip.mcap: corrupted MCAP chunk \(CRCValidationError'):
        list(read_bag(target))


@pytest.mark.parametrize('compression', [None, 'zstd'])
def test_any_flipped_byte_is_detected_or_harmless(tmp_path, compression):
    """A flip anywhere either raises BagError or leaves every message intact (index records)."""
    path = _write_bag(tmp_path / 'f', compression=compression, chunk_size=1500,
                      messages=EXPECTED[:60])
    data = _mcap_file(path).read_bytes()
    reference = list(read_bag(path, raw=True))
    target = tmp_path / 'flipped.mcap'
    offsets = sorted(set(np.linspace(0, len(data) - 1, 150).astype(int)) | {
        0, 9, len(data) - 1, len(data) - 9, len(data) - 12, len(data) - 25})
    detected = 0
    for offset in offsets:
        _flipped(target, data, int(offset))
        try:
            got = list(read_bag(target, raw=True))
        except BagError as exc:
            assert 'flipped.mcap' in str(exc)
            detected += 1
            continue
        assert got == reference, f'undetected corruption at byte {offset}'
    assert detected > len(offsets) // 2
