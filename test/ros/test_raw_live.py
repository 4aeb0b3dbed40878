"""The live identifier node with a raw-sensor input map (ros/raw_live.py, session/raw_session.py):
fed a raw bag's messages in the bag's order, it publishes the estimates of identify --bag's
first EKF pass (identify_raw with passes=1 over offline/raw_bag.py's records of that bag)."""
import time

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import FluidPressure, Imu, JointState
from std_msgs.msg import Float64MultiArray

from auv_ident.bags.reader import read_bag
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.identification.raw import identify_raw
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.offline.raw_bag import raw_bag_records, raw_sensor_config
from auv_ident.offline.raw_example import write_raw_example
from auv_ident.ros.identifier_node import IdentifierNode
from auv_ident.session.input_map import load_input_map
from auv_ident.session.raw_session import RawSession
from auv_ident.session.settings import IdentifierSettings, ParameterError
from auv_ident.vehicles import load_vehicle

NAMES = ['Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v']
LATCHED = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


@pytest.fixture(scope='module')
def raw_example(tmp_path_factory):
    d = tmp_path_factory.mktemp('rawlive')
    return write_raw_example(d, duration=10.0, seed=5)


def _offline_first_pass(bag, map_path):
    imap = load_input_map(str(map_path))
    v = load_vehicle('nps_auv2')
    records, _ = raw_bag_records(bag, imap, v)
    return identify_raw(Model(v, NAMES), FilterConfig(), records, raw_sensor_config(imap),
                        passes=1), records


def _feed(on_input, bag, map_path):
    imap = load_input_map(str(map_path))
    by_topic = {e.bag_topic: e.name for e in imap.inputs}
    events = []
    for topic, log_ns, msg in read_bag(bag, imap.topic_types):
        events.append(on_input(by_topic[topic], msg, log_ns))
    return events


def test_raw_session_is_the_offline_first_pass(raw_example):
    bag, map_path = raw_example
    ref, records = _offline_first_pass(bag, map_path)
    s = RawSession(IdentifierSettings.from_values(input_map=str(map_path), coefficients=NAMES))
    events = _feed(s.on_input, bag, map_path)
    updates = [e for e in events if e.kind == 'update']
    assert updates and not [e for e in events if e.kind in ('rejected', 'error')]
    assert len(updates) == sum(n for k, n in ref.fused.items() if k != 'command')
    np.testing.assert_allclose(updates[-1].estimate, ref.estimate, rtol=1e-12, atol=0)
    np.testing.assert_allclose(updates[-1].cov, ref.filter_covariance, rtol=1e-7, atol=1e-18)
    assert s.health().level == 'OK'
    keys = dict(s.diagnostic_values())
    assert int(keys['fused_imu']) == ref.fused['imu'] and 'dvl_misalignment' in keys


def test_raw_session_refuses_a_setting_it_does_not_use(raw_example):
    _, map_path = raw_example
    with pytest.raises(ParameterError) as err:
        RawSession(IdentifierSettings.from_values(input_map=str(map_path), coefficients=NAMES,
                                                  frame='enu', tau=5.0))
    assert err.value.name == 'frame' and 'also given: tau' in err.value.message


def test_node_with_a_raw_map_subscribes_and_publishes_the_offline_pass(ctx, raw_example):
    bag, map_path = raw_example
    ref, _ = _offline_first_pass(bag, map_path)
    node = IdentifierNode(context=ctx, parameter_overrides=[
        Parameter('input_map', value=str(map_path)), Parameter('coefficients', value=NAMES)])
    probe = rclpy.create_node('probe', context=ctx)
    try:
        subs = {s.topic_name: s.msg_type for s in node.raw.subscriptions}
        assert subs['/imu'] is Imu and subs['/pressure'] is FluidPressure
        assert subs['/actuators'] is JointState and len(subs) == 4
        estimates, diags, covariances = [], [], []
        probe.create_subscription(JointState, '/identifier/estimate', estimates.append, LATCHED)
        probe.create_subscription(Float64MultiArray, '/identifier/covariance',
                                  covariances.append, LATCHED)
        probe.create_subscription(DiagnosticArray, '/diagnostics', diags.append, 10)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(probe)
        events = _feed(node.raw.on_input, bag, map_path)
        last = [e for e in events if e.kind == 'update'][-1]
        np.testing.assert_allclose(last.estimate, ref.estimate, rtol=1e-12, atol=0)
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and not (
                estimates and list(estimates[-1].position) == list(last.estimate) and diags
                and covariances and list(covariances[-1].data) == list(last.cov.ravel())):
            ex.spin_once(timeout_sec=0.05)
        assert list(estimates[-1].name) == NAMES
        assert list(estimates[-1].position) == list(last.estimate)
        assert list(estimates[-1].velocity) == list(last.std)
        assert (estimates[-1].header.stamp.sec * 10**9 + estimates[-1].header.stamp.nanosec
                == last.stamp_ns)
        assert list(covariances[-1].data) == list(last.cov.ravel())
        assert [d.label for d in covariances[-1].layout.dim] == ['row:' + ','.join(NAMES),
                                                                 'col:' + ','.join(NAMES)]
        st = diags[-1].status[0]
        assert st.name == 'auv_ident identifier' and st.message in ('converging', 'converged')
        assert node.shutdown_save()
    finally:
        probe.destroy_node()
        node.destroy_node()


def test_raw_node_takes_its_inputs_as_the_intake_period_says(ctx, raw_example):
    """intake_period_s is a setting of the raw path too: 0 gives the executor the input
    subscriptions (each message as it arrives); the default takes them in batches."""
    _, map_path = raw_example
    nodes = []
    try:
        for period in (0.0, None):
            params = [Parameter('input_map', value=str(map_path)),
                      Parameter('coefficients', value=NAMES)]
            if period is not None:
                params.append(Parameter('intake_period_s', value=period))
            node = IdentifierNode(context=ctx, parameter_overrides=params)
            nodes.append(node)
            given = {s.topic_name for s in node.subscriptions}
            inputs = {s.topic_name for s in node.raw.subscriptions}
            if period == 0.0:
                assert node.raw.intake.timer is None and inputs <= given
            else:
                assert node.raw.intake.period_s == 0.02 and not inputs & given
    finally:
        for node in nodes:
            node.destroy_node()


def test_raw_node_publishes_at_the_publish_rate(ctx, raw_example):
    """publish_rate_hz 5: the same estimates as the session's, published for the first update
    of each 0.2 s of stamps."""
    bag, map_path = raw_example
    node = IdentifierNode(context=ctx, parameter_overrides=[
        Parameter('input_map', value=str(map_path)), Parameter('coefficients', value=NAMES),
        Parameter('publish_rate_hz', value=5.0)])
    try:
        published = []
        node.raw.publish_estimate = published.append
        events = _feed(node.raw.on_input, bag, map_path)
        s = RawSession(IdentifierSettings.from_values(input_map=str(map_path),
                                                      coefficients=NAMES))
        expected = _feed(s.on_input, bag, map_path)
        updates = [e for e in events if e.kind == 'update']
        assert [e.stamp_ns for e in updates] == [e.stamp_ns for e in expected
                                                 if e.kind == 'update']
        np.testing.assert_array_equal(updates[-1].estimate,
                                      [e for e in expected if e.kind == 'update'][-1].estimate)
        firsts = {}
        for e in updates:
            firsts.setdefault(e.stamp_ns // 200_000_000, e)
        assert len(updates) > 500 and 45 <= len(published) <= 55
        assert published == list(firsts.values())
    finally:
        node.destroy_node()


def test_node_reads_imu_bytes_as_the_messages(ctx, raw_example):
    """The IMU subscription is raw (ros/cdr.py ImuView): its callback gives the events the
    same messages give RawSession; bytes nobody can decode are one rejected message."""
    from rclpy.serialization import deserialize_message
    bag, map_path = raw_example
    node = IdentifierNode(context=ctx, parameter_overrides=[
        Parameter('input_map', value=str(map_path)), Parameter('coefficients', value=NAMES)])
    try:
        sub = next(s for s in node.raw.subscriptions if s.topic_name == '/imu')
        assert sub.raw
        s = RawSession(IdentifierSettings.from_values(input_map=str(map_path),
                                                      coefficients=NAMES))
        imap = load_input_map(str(map_path))
        by_topic = {e.bag_topic: e.name for e in imap.inputs}
        imu = 0
        for (topic, log_ns, msg), (_, _, payload) in zip(
                read_bag(bag, imap.topic_types), read_bag(bag, imap.topic_types, raw=True)):
            name = by_topic[topic]
            if name == 'imu':
                msg = deserialize_message(payload, Imu)
                got, expected = node.raw.intake.callbacks['/imu'](payload), s.on_input(name, msg)
                imu += 1
            else:
                got, expected = node.raw.on_input(name, msg, log_ns), s.on_input(name, msg,
                                                                                  log_ns)
            assert (got.kind, got.stamp_ns, got.reason) == (expected.kind, expected.stamp_ns,
                                                            expected.reason)
            assert np.array_equal(got.estimate, expected.estimate)
            if imu == 300:
                break
        assert node.raw.session.counters.fused['imu'] > 250
        ev = node.raw.intake.callbacks['/imu'](b'\x00\x01\x00\x00' + b'\xff' * 40)
        # no header to read a stamp from: RawSession rejects it as any message without one
        assert ev.kind == 'rejected' and node.raw.session.counters.rejected == 1
    finally:
        node.destroy_node()


def test_raw_session_document_before_and_after_data(raw_example, tmp_path):
    bag, map_path = raw_example
    s = RawSession(IdentifierSettings.from_values(input_map=str(map_path), coefficients=NAMES))
    doc = s.document()
    assert doc['steps'] == 0 and doc['stamp_ns'] is None and doc['coefficients'] == NAMES
    assert s.health().message == 'waiting for data'
    _feed(s.on_input, bag, map_path)
    doc = s.document()
    assert doc['input_mode'] == 'raw sensors' and doc['estimate'] == list(s.last_good.estimate)
    assert set(doc['sensor_errors']) >= {'gyro_bias_p', 'dvl_misalignment'}
