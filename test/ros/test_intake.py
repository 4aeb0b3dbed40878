"""ros/intake.py: the identifier's inputs taken in batches (the default) or as they arrive.

Messages tier, in-process: a publisher and an IntakeNode in one context over loopback DDS."""
import time

import pytest
import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import Float64

from auv_ident.ros.intake import Intake, IntakeNode
from auv_ident.ros.toolkit import STREAM_QOS
from auv_ident.session.input_map import FLOAT64, InputEntry, JOINT_STATE, ODOMETRY
from auv_ident.session.settings import IdentifierSettings, ParameterError


@pytest.fixture
def ctx(ros_env):
    context = rclpy.Context()
    rclpy.init(context=context)
    yield context
    rclpy.shutdown(context=context)


def _wait_matched(pub, n=1, timeout_s=5.0):
    end = time.monotonic() + timeout_s
    while pub.get_subscription_count() < n:
        assert time.monotonic() < end, 'subscription not matched'
        time.sleep(0.01)


def test_a_batch_is_taken_in_the_order_it_was_published_across_topics(ctx):
    """Two topics published in turn come out of one take() in that order (not topic by
    topic), each with its DDS receive time; the executor is never given them."""
    node = IntakeNode('intake_test', context=ctx)
    try:
        got = []
        intake = Intake(node, 0.02)
        for topic in ('/intake_a', '/intake_b'):
            intake.subscribe(Float64, topic, lambda m, ns, t=topic: got.append((t, m.data, ns)),
                             STREAM_QOS)
        assert list(node.subscriptions) == []       # what an executor would be given
        pubs = {t: node.create_publisher(Float64, t, STREAM_QOS)
                for t in ('/intake_a', '/intake_b')}
        for p in pubs.values():
            _wait_matched(p)
        sent = [('/intake_a', 1.0), ('/intake_b', 2.0), ('/intake_a', 3.0),
                ('/intake_b', 4.0), ('/intake_a', 5.0)]
        before = time.time_ns()
        for topic, value in sent:
            pubs[topic].publish(Float64(data=value))
            time.sleep(0.002)
        time.sleep(0.2)
        after = time.time_ns()
        assert got == []                 # nothing taken until the intake takes
        assert intake.take() == len(sent)
        assert [(t, v) for t, v, _ in got] == sent
        stamps = [ns for _, _, ns in got]
        assert stamps == sorted(stamps) and before <= stamps[0] and stamps[-1] <= after
        assert intake.take() == 0
        # the timer takes them while an executor spins
        ex = EventsExecutor(context=ctx)
        ex.add_node(node)
        pubs['/intake_b'].publish(Float64(data=6.0))
        end = time.monotonic() + 2.0
        while len(got) < 6 and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        ex.remove_node(node)
        assert got[-1][:2] == ('/intake_b', 6.0)
    finally:
        node.destroy_node()


def test_period_zero_takes_each_message_as_it_arrives(ctx):
    node = IntakeNode('intake_now', context=ctx)
    try:
        got = []
        intake = Intake(node, 0.0)
        sub = intake.subscribe(Float64, '/intake_now', lambda m, ns: got.append((m.data, ns)),
                               STREAM_QOS)
        assert intake.timer is None and list(node.subscriptions) == [sub]
        pub = node.create_publisher(Float64, '/intake_now', STREAM_QOS)
        _wait_matched(pub)
        ex = EventsExecutor(context=ctx)
        ex.add_node(node)
        before = time.time_ns()
        pub.publish(Float64(data=7.0))
        end = time.monotonic() + 2.0
        while not got and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        ex.remove_node(node)
        assert got and got[0][0] == 7.0 and before <= got[0][1] <= time.time_ns()
    finally:
        node.destroy_node()


def test_an_intake_for_inputs_follows_the_clock_only_on_sim_time_with_a_headerless_input(ctx):
    """Intake.for_inputs (both node paths' constructor): a /clock subscription exactly when
    the node has use_sim_time and an input has no header to stamp its messages."""
    odom = InputEntry('odom', 'odom', ODOMETRY, 'odometry')
    stamped = InputEntry('actuators', 'actuators', JOINT_STATE, 'command')
    headerless = InputEntry('thrust', 'thrust', FLOAT64, 'command')
    cases = [(True, (headerless, odom), True), (True, (stamped, odom), False),
             (False, (headerless, odom), False)]
    for i, (sim_time, entries, follows) in enumerate(cases):
        node = IntakeNode(f'intake_clock_{i}', context=ctx, parameter_overrides=[
            Parameter('use_sim_time', Parameter.Type.BOOL, sim_time)])
        try:
            intake = Intake.for_inputs(node, 0.02, entries)
            assert (intake.sub_clock is not None) is follows, (sim_time, entries)
            assert ('/clock' in intake.callbacks) is follows
            assert intake.period_s == 0.02
        finally:
            node.destroy_node()


def test_the_intake_period_is_checked_where_it_enters():
    assert IdentifierSettings().intake_period_s == 0.02
    assert IdentifierSettings.from_values(intake_period_s=0.0).intake_period_s == 0.0
    for bad in (-0.01, 0.6, float('nan')):
        with pytest.raises(ParameterError, match='intake_period_s'):
            IdentifierSettings.from_values(intake_period_s=bad)
