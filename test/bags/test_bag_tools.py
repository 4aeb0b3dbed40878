"""Bags beyond our own writer: foreign rosbag2 MCAP bags, `bag info`, `bag repair`, strictly
decodable simulated bags and their epoch, and the bags layer staying ROS-free.

The foreign bags are read from shared/foreign_bags (see its SOURCES.txt; AUV_IDENT_FOREIGN_BAGS
overrides the path); those tests skip, saying so, where it is absent. Expected figures come
from independent readers (mcap's own reader, mcap_ros2, rosbags) or from the metadata.yaml
that rosbag2 wrote, never from our reader.
"""
from collections import Counter
import datetime
import logging
import os
from pathlib import Path
import shutil
import subprocess
import sys

import helpers
from helpers import assert_msg_equal
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import get_typestore, Stores
import yaml

from auv_ident.bags.info import bag_info, format_bag_info
from auv_ident.bags.reader import bag_topics, message_counts, read_bag
from auv_ident.bags.repair import repair_bag
from auv_ident.bags.schema import BagError, normalize_msgtype
from auv_ident.bags.writer import BagWriter
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.simulation.simulate import simulate
from auv_ident.offline.sim_bag import (
    bag_sample_messages,
    SIM_EPOCH,
    SIM_EPOCH_NS,
    TOPIC_TYPES,
    write_run_bag,
)
from auv_ident.ros.sim_messages import sample_messages
from auv_ident.session.messages import sec_to_ns
from auv_ident.vehicles import load_vehicle

REPO = Path(helpers.REPO)
FOREIGN = Path(os.environ.get('AUV_IDENT_FOREIGN_BAGS', '/work/shared/foreign_bags'))
FOREIGN_BAGS = ('bag_with_topics_and_service_events', 'cdr_test', 'rewriter_b', 'talker',
                'test_bag_for_seek', 'test_bag_mcap', 'wbag')
# rosbag2 (Jazzy) writes service-event schemas as the .srv text, which neither rosbags nor
# mcap_ros2 parses: these topics are the real-world case of an undecodable topic.
SERVICE_EVENTS = ('/test_service1/_service_event', '/test_service2/_service_event')
JAZZY = get_typestore(Stores.ROS2_JAZZY)


def foreign(name):
    path = FOREIGN / name
    if not path.is_dir():
        pytest.skip(f'foreign bag {path} absent (shared/foreign_bags is not on this machine; '
                    'set AUV_IDENT_FOREIGN_BAGS to its path)')
    return path


def _cli(*args):
    return subprocess.run([sys.executable, '-m', 'auv_ident', *args], cwd=REPO,
                          capture_output=True, text=True, timeout=300)


def _independent(path):
    """Per topic (type, count) and the log-time span, read with mcap's own reader."""
    files = [path] if path.is_file() else sorted(path.glob('*.mcap'))
    topics, times = {}, []
    for f in files:
        with open(f, 'rb') as fh:
            reader = make_reader(fh)
            summary = reader.get_summary()
            for channel in summary.channels.values():
                schema = summary.schemas[channel.schema_id]
                topics.setdefault(channel.topic, (normalize_msgtype(schema.name), 0))
            for _, channel, message in reader.iter_messages():
                msgtype, n = topics[channel.topic]
                topics[channel.topic] = (msgtype, n + 1)
                times.append(message.log_time)
    return topics, (min(times), max(times))


@pytest.fixture(scope='module')
def run():
    return simulate(Model(load_vehicle('nps_auv2'), ()), 'zigzag', duration=20.0, T=0.05,
                    seed=5)


@pytest.fixture(scope='module')
def sim_bag(run, tmp_path_factory):
    return write_run_bag(run, tmp_path_factory.mktemp('sim') / 'run')


# --- foreign bags: info, counts, decoding -----------------------------------------------------


@pytest.mark.parametrize('name', FOREIGN_BAGS)
def test_info_of_foreign_bags(name):
    path = foreign(name)
    topics, (first, last) = _independent(path)
    info = bag_info(path)
    assert {t.name: (t.msgtype, t.count) for t in info.topics} == topics
    assert {t.serialization_format for t in info.topics} == {'cdr'}
    assert (info.start_ns, info.end_ns) == (first, last)
    assert info.message_count == sum(n for _, n in topics.values()) and not info.incomplete
    # what rosbag2 itself wrote about the bag
    meta = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info.message_count == meta['message_count']
    assert {t['topic_metadata']['name']: (normalize_msgtype(t['topic_metadata']['type']),
                                          t['message_count'])
            for t in meta['topics_with_message_count']} == topics
    if name != 'wbag':  # a hand-made test resource whose times do not match its files
        assert info.start_ns == meta['starting_time']['nanoseconds_since_epoch']
        assert info.duration_ns == meta['duration']['nanoseconds']
    assert message_counts(path) == {t: n for t, (_, n) in topics.items()}


@pytest.mark.parametrize('name', FOREIGN_BAGS)
def test_bag_info_cli_on_foreign_bags(name):
    path = foreign(name)
    topics, _ = _independent(path)
    r = _cli('bag', 'info', str(path))
    assert r.returncode == 0 and not r.stderr, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].startswith('Files:') and 'Storage id:        mcap' in r.stdout
    assert f'Messages:          {sum(n for _, n in topics.values())}' in lines
    for topic, (msgtype, n) in topics.items():
        assert (f'Topic: {topic} | Type: {msgtype} | Count: {n} | Serialization Format: cdr'
                in r.stdout)
    assert 'Duration:' in r.stdout and 'Start:' in r.stdout and 'End:' in r.stdout


def test_bag_info_cli_on_the_shipped_bag():
    path = REPO / 'bags' / 'nps_auv2_ident'
    topics, (first, last) = _independent(path)
    r = _cli('bag', 'info', str(path))
    assert r.returncode == 0 and not r.stderr, r.stderr
    assert topics == {'/odom': ('nav_msgs/msg/Odometry', 12001),
                      '/actuators': ('sensor_msgs/msg/JointState', 12001),
                      '/simulator/truth': ('nav_msgs/msg/Odometry', 12001)}
    lines = r.stdout.splitlines()
    assert 'Messages:          36003' in lines and 'ROS Distro:        jazzy' in lines
    # stamped on the documented simulated-bag epoch, 2024-01-01T00:00:00Z (docs/bags.md)
    epoch = 1704067200 * 10**9
    assert 'Duration:          600.000000000s' in lines
    assert (first, last) == (epoch, epoch + 600 * 10**9)
    assert 'Start:             Jan  1 2024 00:00:00.000000000 UTC (1704067200.000000000)' in lines
    assert ('Topic information: Topic: /actuators | Type: sensor_msgs/msg/JointState | '
            'Count: 12001 | Serialization Format: cdr') in lines
    assert 'Custom data:       auv_ident.vehicle: nps_auv2' in lines


@pytest.mark.parametrize('name', FOREIGN_BAGS)
def test_reading_all_topics_of_foreign_bags(name, caplog):
    """Every message of every decodable topic; an undecodable topic: one warning, skipped."""
    path = foreign(name)
    topics, _ = _independent(path)
    with caplog.at_level(logging.WARNING, logger='auv_ident.bags'):
        got = Counter(topic for topic, _, _ in read_bag(path))
    skipped = [t for t in SERVICE_EVENTS if t in topics]
    assert got == Counter({t: n for t, (_, n) in topics.items() if n and t not in skipped})
    warnings = [r for r in caplog.records if r.name == 'auv_ident.bags']
    assert len(warnings) == len(skipped)
    for topic, record in zip(sorted(skipped), sorted(warnings, key=lambda r: r.getMessage())):
        text = record.getMessage()
        assert topic in text and 'cannot decode' in text and 'definition not parsed' in text


def test_requested_undecodable_topic_is_a_bag_error():
    path = foreign('bag_with_topics_and_service_events')
    with pytest.raises(BagError, match=r'topic /test_service1/_service_event: cannot decode '
                                       r"'test_msgs/srv/BasicTypes_Event' at all"):
        read_bag(path, topics=['/test_topic1', '/test_service1/_service_event'])
    assert len(list(read_bag(path, topics=['/test_service1/_service_event'], raw=True))) == 4


def _mcap_ros2_messages(path, topic):
    with open(path, 'rb') as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        return [msg for _, ch, _, msg in reader.iter_decoded_messages(log_time_order=True)
                if ch.topic == topic]


def test_schema_named_pkg_type_is_found():
    """test_bag_for_seek names its schema 'test_msgs/BasicTypes' (no /msg/)."""
    path = foreign('test_bag_for_seek')
    with open(path / 'test_bag_for_seek_0.mcap', 'rb') as fh:
        names = {s.name for s in make_reader(fh).get_summary().schemas.values()}
    assert names == {'test_msgs/BasicTypes'}
    assert bag_topics(path) == {'topic1': 'test_msgs/msg/BasicTypes'}
    got = [m for _, _, m in read_bag(path, topics={'topic1': 'test_msgs/BasicTypes'})]
    expected = _mcap_ros2_messages(path / 'test_bag_for_seek_0.mcap', 'topic1')
    assert len(got) == len(expected) == 5
    for a, b in zip(got, expected):
        for field in ('bool_value', 'float32_value', 'float64_value', 'int8_value',
                      'int32_value', 'uint64_value'):
            assert getattr(a, field) == getattr(b, field), field


def test_file_without_statistics_is_read():
    """test_bag_mcap (rosbags 0.10) has no Statistics record, optional in MCAP."""
    path = foreign('test_bag_mcap')
    mcap_file = path / 'test_bag_mcap.mcap'
    with open(mcap_file, 'rb') as fh:
        assert make_reader(fh).get_summary().statistics is None
    topic = '/test/nav_msgs/odometry'
    got = [m for _, _, m in read_bag(path, topics={topic: 'nav_msgs/msg/Odometry'})]
    expected = _mcap_ros2_messages(mcap_file, topic)
    assert len(got) == len(expected) == 2
    for a, b in zip(got, expected):
        assert a.header.stamp.sec == b.header.stamp.sec and a.child_frame_id == b.child_frame_id
        assert a.pose.pose.position.x == b.pose.pose.position.x
        np.testing.assert_array_equal(a.twist.covariance, b.twist.covariance)


# --- our own bags: strictly decodable, epoch ---------------------------------------------------


def test_simulated_bag_decodes_strictly_on_every_topic(sim_bag, run):
    """rosbags' deserialize_cdr itself, no fallback: every message of every topic."""
    counts = Counter()
    with open(sim_bag / 'run_0.mcap', 'rb') as fh:
        for _, channel, message in make_reader(fh).iter_messages(log_time_order=True):
            JAZZY.deserialize_cdr(message.data, TOPIC_TYPES[channel.topic])
            counts[channel.topic] += 1
    assert counts == {t: len(run.t) for t in TOPIC_TYPES}


def test_rclpy_sample_messages_serialize_strictly_decodable(run):
    """The live simulator's JointState (effort zeros) is strictly decodable once serialized
    by rclpy, unlike one with an empty effort (the Fast-CDR padding)."""
    msgs = {t: m for t, _, m in sample_messages(run, 3)}
    joints = msgs['/actuators']
    assert list(joints.effort) == [0.0] * 6
    JAZZY.deserialize_cdr(serialize_message(joints), 'sensor_msgs/msg/JointState')
    joints.effort = []
    with pytest.raises(Exception, match='size mismatch'):
        JAZZY.deserialize_cdr(serialize_message(joints), 'sensor_msgs/msg/JointState')


def test_bag_builder_equals_the_rclpy_builder(run):
    """The bag's (rosbags) and the node's (rclpy) messages agree field by field; stamps differ
    by the epoch only."""
    for frame in ('ned', 'enu'):
        for k in (0, 17, len(run.t) - 1):
            live = sample_messages(run, k, frame)
            # one message per topic from each builder (so the zips below compare them all)
            assert sorted(t for t, _, _ in live) == sorted(TOPIC_TYPES)
            assert len(list(bag_sample_messages(run, k, frame))) == len(TOPIC_TYPES)
            for (topic, t_ns, expected), (topic2, t2, actual) in zip(
                    live, bag_sample_messages(run, k, frame, epoch_ns=0)):
                assert (topic, t_ns) == (topic2, t2)
                assert_msg_equal(expected, actual, f'{frame} {topic}[{k}]')
            for (_, t_ns, _), (_, t2, msg) in zip(live, bag_sample_messages(run, k, frame)):
                assert t2 == t_ns + SIM_EPOCH_NS
                assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == t2
            for (_, t_ns, expected), (_, t2, actual) in zip(
                    sample_messages(run, k, frame, epoch_ns=SIM_EPOCH_NS),
                    bag_sample_messages(run, k, frame)):
                assert t_ns == t2
                assert_msg_equal(expected, actual, f'{frame} epoch[{k}]')


def test_simulated_bag_starts_at_the_epoch_and_is_reproducible(sim_bag, run, tmp_path):
    # the two spellings of the epoch agree (the metadata stores both)
    epoch = datetime.datetime.fromisoformat(SIM_EPOCH.replace('Z', '+00:00'))
    assert epoch.utcoffset() == datetime.timedelta(0)
    assert int(epoch.timestamp()) * 10**9 == SIM_EPOCH_NS
    meta = yaml.safe_load((sim_bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert meta['starting_time'] == {'nanoseconds_since_epoch': SIM_EPOCH_NS}
    assert meta['custom_data']['auv_ident.stamp_epoch_ns'] == str(SIM_EPOCH_NS)
    assert meta['custom_data']['auv_ident.stamp_epoch'] == SIM_EPOCH
    times = [t for _, t, _ in read_bag(sim_bag, topics=['/odom'])]
    assert times[0] == SIM_EPOCH_NS and times[-1] == SIM_EPOCH_NS + sec_to_ns(run.t[-1])
    r = _cli('bag', 'info', str(sim_bag))
    assert r.returncode == 0, r.stderr
    assert ('Start:             Jan  1 2024 00:00:00.000000000 UTC (1704067200.000000000)'
            in r.stdout.splitlines())
    # fixed, not "now": the same run gives the same bytes
    again = write_run_bag(run, tmp_path / 'run')
    for name in ('run_0.mcap', 'metadata.yaml'):
        assert (again / name).read_bytes() == (sim_bag / name).read_bytes(), name


def test_replay_does_not_depend_on_the_epoch(run, tmp_path):
    """The same run stamped from 0 and from 2024 identifies bit for bit: the replay's time line
    starts at a time origin (0 for stamps near 0, the first stamp's whole second for wall-clock
    stamps), so its float seconds are the same small numbers for both."""
    from auv_ident.offline.replay import replay_bag
    at_zero = replay_bag(write_run_bag(run, tmp_path / 'zero', epoch_ns=0), warn=False)
    at_epoch = replay_bag(write_run_bag(run, tmp_path / 'epoch'), warn=False)
    assert at_zero.accepted == at_epoch.accepted == len(run.t) and at_epoch.rejected == 0
    assert [u[0] - SIM_EPOCH_NS for u in at_epoch.updates] == [u[0] for u in at_zero.updates]
    assert at_zero.time_origin_ns == 0 and at_epoch.time_origin_ns == SIM_EPOCH_NS
    assert np.array_equal(at_epoch.t, at_zero.t) and np.array_equal(at_epoch.t_cmd, at_zero.t_cmd)
    np.testing.assert_allclose(at_zero.t, run.t, rtol=0, atol=1e-9)
    assert np.array_equal(at_epoch.estimate, at_zero.estimate)
    assert np.array_equal(at_epoch.cov, at_zero.cov)


# --- repair ------------------------------------------------------------------------------------


def _cut(bag, dst, fraction=None, offset=None):
    """Copy a bag's data file, cut at fraction of its length or at offset, into a new directory
    (no metadata.yaml: as a killed recorder leaves it)."""
    dst.mkdir()
    data = next(bag.glob('*.mcap')).read_bytes()
    target = dst / f'{dst.name}_0.mcap'
    target.write_bytes(data[:offset if offset is not None else int(len(data) * fraction)])
    return target


def _read_back_indexed(path):
    """(topic, log time, payload) read through the index by mcap's SeekingReader in log-time
    order and by rosbags' Reader, no truncation option anywhere; both must agree."""
    with open(next(path.glob('*.mcap')), 'rb') as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.chunk_indexes
        seeking = [(ch.topic, m.log_time, m.data)
                   for _, ch, m in reader.iter_messages(log_time_order=True)]
    with RosbagsReader(path) as reader:
        by_rosbags = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
        assert reader.message_count == len(seeking)
    assert [t for _, t, _ in seeking] == sorted(t for _, t, _ in seeking)
    assert sorted(by_rosbags, key=lambda r: (r[1], r[0])) == sorted(
        seeking, key=lambda r: (r[1], r[0]))
    return seeking


@pytest.mark.parametrize('compression', [None, 'zstd'])
def test_repair_torn_recording(run, tmp_path, compression):
    """A file cut inside a chunk (as a writer killed while the OS wrote it): every message of
    the complete chunks comes back, readable through the index; only the torn chunk is lost."""
    source = tmp_path / 'source'
    with BagWriter(source, compression=compression, chunk_size=4096) as w:
        for topic, msgtype in TOPIC_TYPES.items():
            w.add_topic(topic, msgtype)
        for k in range(len(run.t)):
            for topic, t_ns, msg in bag_sample_messages(run, k):
                w.write(topic, t_ns, JAZZY.serialize_cdr(msg, TOPIC_TYPES[topic]))
    with open(next(source.glob('*.mcap')), 'rb') as fh:
        torn = make_reader(fh).get_summary().chunk_indexes[40]
    cut = _cut(source, tmp_path / 'killed', offset=torn.chunk_start_offset
               + torn.chunk_length // 2)
    with pytest.raises(BagError, match='truncated'):
        read_bag(cut.parent)
    with pytest.warns(UserWarning, match='recovered'):
        complete_chunks = list(read_bag(cut.parent, raw=True, allow_truncated=True))

    r = _cli('bag', 'repair', str(cut.parent), '--out', str(tmp_path / 'fixed'))
    assert r.returncode == 0, r.stderr
    assert 'rewritten (no summary: its writer did not finish)' in r.stdout
    assert f'{len(complete_chunks)} messages from 40 complete chunks' in r.stdout
    lost = [ln.strip() for ln in r.stdout.splitlines() if 'lost:' in ln]
    start, end = (f'{t // 10**9}.{t % 10**9:09d}' for t in (torn.message_start_time,
                                                              torn.message_end_time))
    assert lost == [f'lost: {cut.stat().st_size - torn.chunk_start_offset} bytes from byte '
                    f'{torn.chunk_start_offset} (chunk: record of {torn.chunk_length - 9} '
                    f'bytes, only {cut.stat().st_size - torn.chunk_start_offset - 9} present); '
                    f'that chunk held the messages logged {start} .. {end} s'
                    + ('' if compression else lost[0][lost[0].rindex(', at least'):])], lost

    fixed = _read_back_indexed(tmp_path / 'fixed')
    assert fixed == complete_chunks
    # nothing before the torn chunk is lost; the first message missing is that chunk's first
    everything = list(read_bag(source, raw=True))
    assert everything[:len(fixed)] == fixed
    assert everything[len(fixed)][1] == torn.message_start_time
    info = yaml.safe_load((tmp_path / 'fixed' / 'metadata.yaml').read_text())
    info = info['rosbag2_bagfile_information']
    assert info['version'] == 9 and info['message_count'] == len(fixed)
    assert info['starting_time'] == {'nanoseconds_since_epoch': SIM_EPOCH_NS}
    assert sum(t['message_count'] for t in info['topics_with_message_count']) == len(fixed)
    assert all(t['topic_metadata']['offered_qos_profiles'][0]['reliability'] == 'reliable'
               for t in info['topics_with_message_count'])
    # a second repair has nothing to do
    again = repair_bag(tmp_path / 'fixed')
    assert not again.changed and 'nothing to repair' in again.lines()[0]


def test_repair_in_place_keeps_custom_data_and_the_original(sim_bag, tmp_path):
    """A bag with metadata.yaml whose data file was cut: in place, original kept as .orig."""
    bag = tmp_path / 'bag'
    shutil.copytree(sim_bag, bag)
    data = (bag / 'run_0.mcap').read_bytes()
    (bag / 'run_0.mcap').write_bytes(data[:len(data) // 2])
    report = repair_bag(bag)
    assert report.changed and report.in_place and report.files[0].rewritten
    assert (bag / 'run_0.mcap.orig').read_bytes() == data[:len(data) // 2]
    assert 'the original is kept as run_0.mcap.orig' in '\n'.join(report.lines())
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    old = yaml.safe_load((sim_bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['custom_data'] == old['custom_data']
    assert info['relative_file_paths'] == ['run_0.mcap']
    got = _read_back_indexed(bag)
    assert 0 < len(got) < old['message_count'] and info['message_count'] == len(got)
    assert message_counts(bag) == {t['topic_metadata']['name']: t['message_count']
                                   for t in info['topics_with_message_count']}
    # the repaired bag replays like any bag
    from auv_ident.offline.replay import replay_bag
    assert replay_bag(bag, warn=False).accepted == message_counts(bag)['/odom']


def test_repair_adds_statistics_to_a_foreign_file(tmp_path):
    path = foreign('test_bag_mcap')
    report = repair_bag(path, out=tmp_path / 'with_stats')
    assert report.files[0].rewritten and report.files[0].why == 'no Statistics record'
    assert report.files[0].lost is None
    got = _read_back_indexed(tmp_path / 'with_stats')
    with open(path / 'test_bag_mcap.mcap', 'rb') as fh:
        original = [(ch.topic, m.log_time, m.data)
                    for _, ch, m in make_reader(fh).iter_messages(log_time_order=True)]
    assert sorted(got) == sorted(original)
    assert bag_topics(tmp_path / 'with_stats') == bag_topics(path)


def test_repair_keeps_complete_bags_as_they_are(tmp_path):
    path = foreign('talker')
    report = repair_bag(path, out=tmp_path / 'copy')
    assert [f.rewritten for f in report.files] == [False]
    assert (tmp_path / 'copy' / 'talker.mcap').read_bytes() == (path / 'talker.mcap').read_bytes()
    assert message_counts(tmp_path / 'copy') == message_counts(path)


def test_repair_bad_input_is_one_clear_line(tmp_path, sim_bag):
    (tmp_path / 'text.mcap').write_text('not an mcap file at all, but long enough ' * 3)
    cases = [((str(tmp_path / 'text.mcap'),), 'text.mcap: not an MCAP file'),
             ((str(tmp_path / 'nope'),), 'no such bag'),
             ((str(sim_bag), '--out', str(sim_bag)), 'output path exists already')]
    for args, needle in cases:
        r = _cli('bag', 'repair', *args)
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert r.returncode == 2 and len(lines) == 1 and needle in lines[0], r.stderr
    r = _cli('bag', 'info', str(tmp_path / 'text.mcap'))
    assert r.returncode == 2 and 'not an MCAP file' in r.stderr and 'Traceback' not in r.stderr


def test_info_flags_an_unfinished_file(sim_bag, tmp_path):
    cut = _cut(sim_bag, tmp_path / 'cut', fraction=0.5)
    info = bag_info(cut.parent)
    assert len(info.incomplete) == 1 and 'did not finish' in info.incomplete[0]
    with pytest.warns(UserWarning):
        assert info.message_count == len(list(read_bag(cut.parent, allow_truncated=True)))
    text = '\n'.join(format_bag_info(info))
    assert 'INCOMPLETE:' in text and 'bag repair' in text


# --- layering ----------------------------------------------------------------------------------


def test_bags_layer_imports_no_ros():
    code = ('import sys\n'
            'import auv_ident.bags.reader, auv_ident.bags.writer, auv_ident.offline.sim_bag\n'
            'import auv_ident.bags.repair, auv_ident.bags.info, auv_ident.offline.replay\n'
            'bad = sorted(m for m in sys.modules if m.split(".")[0] == "rclpy"\n'
            '             or m.split(".")[0].endswith("_msgs") or m.startswith("auv_ident.ros"))\n'
            'print(bad)\n')
    r = subprocess.run([sys.executable, '-c', code], cwd=REPO, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == '[]', (r.stdout, r.stderr)
