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
from auv_ident.session.messages import NS_PER_S
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


class _QueuedSubscription:
    """A subscription's handle as Intake.take reads it: messages queued by the test, each
    with the MessageInfo it says."""

    def __init__(self, msg_type, raw):
        self.msg_type, self.raw, self.handle, self.queue = msg_type, raw, self, []

    def __enter__(self):
        return self

    def __exit__(self, *_exc):
        return False

    def take_message(self, _msg_type, _raw):
        return self.queue.pop(0) if self.queue else None


class _QueuedNode:
    """What Intake needs of a node, with queued subscriptions and no timer (take is called
    by the test)."""

    def __init__(self):
        self.polled, self.subs = set(), {}

    def create_timer(self, *_args, **_kwargs):
        return None

    def create_subscription(self, msg_type, topic, _callback, _qos, raw=False):
        self.subs[topic] = _QueuedSubscription(msg_type, raw)
        return self.subs[topic]


def test_a_receive_clock_ahead_delays_a_message_by_one_take_at_most():
    """The rmw's received_timestamp 10 s ahead of the system clock: every message looks
    received after the take began, so each take defers what it reads; the next runs it all the
    same, in publication order with what it takes itself (a message received in time and
    published earlier goes first). Without that, nothing would be run for 10 s."""
    node = _QueuedNode()
    intake = Intake(node, 0.02)
    got = []
    for topic in ('/clock_like', '/command'):
        intake.subscribe(Float64, topic, lambda m, _ns, t=topic: got.append((t, m.data)),
                         STREAM_QOS)
    published = 0

    def queue(topic, value, ahead_s):
        nonlocal published
        published += 1
        node.subs[topic].queue.append((Float64(data=value), {
            'source_timestamp': published,
            'received_timestamp': time.time_ns() + int(ahead_s * NS_PER_S)}))

    sent = []
    for k in range(5):
        for topic in ('/clock_like', '/command'):
            queue(topic, float(k), 10.0)
            sent.append((topic, float(k)))
        intake.take()
        # every message queued before the previous take has reached its callback
        assert got == sent[:2 * k]
    assert intake.take() == 2 and got == sent
    assert intake.take() == 0
    # what the last take deferred goes with, and after, an earlier-published message received in
    # time
    queue('/command', 10.0, 10.0)
    assert intake.take() == 0
    node.subs['/clock_like'].queue.append((Float64(data=9.0), {
        'source_timestamp': 0, 'received_timestamp': time.time_ns()}))
    assert intake.take() == 2
    assert got[-2:] == [('/clock_like', 9.0), ('/command', 10.0)]


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
