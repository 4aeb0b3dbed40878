"""The node toolkit (auv_ident/ros/toolkit.py): parameter declaration and checks, the wait for
subscribers, the stop flag, and the one entry harness as every node executable meets it (a bad
parameter or type: one line naming it, exit 2; --help; stray arguments).
"""
import os
import signal
import subprocess
import sys
import time

from conftest import require_loopback_dds
from helpers import REPO  # noqa: E402 - the repository root (conftest puts test/ on the path)
import pytest
from rcl_interfaces.msg import ParameterType
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import String

from auv_ident.ros import toolkit
from auv_ident.ros.toolkit import (
    choice,
    declare_parameters,
    number,
    Param,
    required_string,
    StopFlag,
    strings,
    SubscriberWait,
)
from auv_ident.session.settings import ParameterError

TABLE = (
    Param('rate', 1.0, 'a rate [Hz]', number(above=0.0)),
    Param('count', 3, 'a count [-]', number(minimum=0)),
    Param('mode', 'a', 'a mode', choice(('a', 'b'))),
    Param('names', Parameter.Type.STRING_ARRAY, 'names', strings()),
    Param('path', '', 'a path (required)', required_string('x.bag')),
    Param('flag', False, 'a flag'),
)


def _node(ctx, **overrides):
    return rclpy.create_node('toolkit_test', context=ctx, parameter_overrides=[
        Parameter(k, value=v) for k, v in overrides.items()])


def test_declare_parameters_reads_checks_and_declares_read_only(ctx):
    node = _node(ctx, rate=2.5, names=[' /a ', '/b'], path=' x.bag ')
    try:
        values = declare_parameters(node, TABLE)
        assert values == {'rate': 2.5, 'count': 3, 'mode': 'a', 'names': ['/a', '/b'],
                          'path': 'x.bag', 'flag': False}
        described = node.describe_parameters(['rate', 'names'])
        assert all(d.read_only for d in described)
        assert described[0].description == 'a rate [Hz]'
        assert described[0].type == ParameterType.PARAMETER_DOUBLE
        assert described[1].type == ParameterType.PARAMETER_STRING_ARRAY
    finally:
        node.destroy_node()


@pytest.mark.parametrize('name, value, words', [
    ('rate', 0.0, 'must be > 0'),
    ('rate', float('nan'), 'finite'),
    ('count', -1, 'must be >= 0'),
    ('mode', 'c', 'use one of a, b'),
    ('names', ['/a', ' '], 'empty entry'),
    ('path', '  ', 'required'),
    ('rate', 2, "expected a floating-point number (write 5.0, not 5), got '2' (integer)"),
    ('names', '/a', "expected a list of strings, e.g. [a, b], got '/a' (string)"),
    ('flag', 1, 'expected true or false'),
])
def test_a_bad_value_or_type_names_the_parameter(ctx, name, value, words):
    overrides = {'path': 'x.bag', name: value}
    node = _node(ctx, **overrides)
    try:
        with pytest.raises(ParameterError) as info:
            declare_parameters(node, TABLE)
        assert str(info.value).startswith(f"parameter '{name}': ")
        assert words in str(info.value)
        assert info.value.name == name
    finally:
        node.destroy_node()


def test_unset_parameters_read_as_none_or_empty(ctx):
    node = _node(ctx, path='x')
    try:
        values = declare_parameters(node, TABLE + (
            Param('unset', Parameter.Type.DOUBLE_ARRAY, 'unset', toolkit.optional_list),))
        assert values['names'] == [] and values['unset'] is None
        with pytest.raises(ParameterError, match="parameter 'names': required"):
            declare_parameters(_node(ctx, path='x'), (
                Param('names', Parameter.Type.STRING_ARRAY, '', strings(required=True)),))
    finally:
        node.destroy_node()


def test_subscriber_wait_by_node_and_by_topic(ctx):
    pub_node = rclpy.create_node('talker', context=ctx)
    sub_node = rclpy.create_node('listener', namespace='/ns', context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    try:
        pub = pub_node.create_publisher(String, '/chatter', toolkit.STREAM_QOS)
        other = pub_node.create_publisher(String, '/other', toolkit.STREAM_QOS)
        wait = SubscriberWait(pub_node, [pub, other], nodes=['/ns/listener'],
                              topics=['/chatter'], timeout=0.3, settle=0.0)
        assert wait.wait() is False
        assert wait.missing == ['/chatter', '/ns/listener']
        sub_node.create_subscription(String, '/chatter', lambda msg: None, toolkit.STREAM_QOS)
        ex.add_node(sub_node)
        by_node = SubscriberWait(pub_node, [pub, other], nodes=['listener'], timeout=10.0,
                                 settle=0.1)
        t0 = time.monotonic()
        assert by_node.wait() is True
        assert time.monotonic() - t0 >= 0.1 and pub.get_subscription_count() == 1
        by_topic = SubscriberWait(pub_node, [pub], topics=['/chatter'], timeout=10.0)
        assert by_topic.wait() is True
        flag = StopFlag()
        try:
            flag.event.set()
            never = SubscriberWait(pub_node, [other], topics=['/other'], timeout=10.0)
            assert never.wait(flag.event) is None      # a stop request ends the wait
        finally:
            flag.restore()
    finally:
        ex.shutdown()
        sub_node.destroy_node()
        pub_node.destroy_node()


def test_a_stop_drains_what_dds_already_received(ctx):
    """A stop requested while acknowledged messages wait in the subscription's queue: spin
    with ``taken`` runs their callbacks before it returns; without, they are lost (what a
    bag's last messages were when the identifier got its SIGINT right after the player)."""
    pub_node = rclpy.create_node('drain_talker', context=ctx)
    sub_node = rclpy.create_node('drain_listener', context=ctx)
    got = []
    try:
        pub = pub_node.create_publisher(String, '/drained', toolkit.STREAM_QOS)
        sub_node.create_subscription(String, '/drained', got.append, toolkit.STREAM_QOS)
        assert SubscriberWait(pub_node, [pub], topics=['/drained'], timeout=10.0).wait()
        flag = StopFlag()
        try:
            flag.event.set()            # stopped before the messages are taken
            for i in range(50):
                pub.publish(String(data=str(i)))
            assert pub.wait_for_all_acked(rclpy.duration.Duration(seconds=10.0))
            toolkit.spin(sub_node, flag)
            assert got == []
            toolkit.spin(sub_node, flag, taken=lambda: len(got))
        finally:
            flag.restore()
        assert [m.data for m in got] == [str(i) for i in range(50)]
    finally:
        sub_node.destroy_node()
        pub_node.destroy_node()


def test_stop_flag_first_signal_requests_second_interrupts():
    before = signal.getsignal(signal.SIGTERM)
    flag = StopFlag()
    try:
        with pytest.raises(KeyboardInterrupt):  # not armed yet: the node is being built
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1.0)
        assert not flag.is_set()
        flag.armed = True
        os.kill(os.getpid(), signal.SIGTERM)
        assert flag.wait(2.0) and flag.signum == signal.SIGTERM
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)                     # the handler runs between bytecodes
        flag.hold()
        os.kill(os.getpid(), signal.SIGINT)     # ignored while finishing
        time.sleep(0.05)
    finally:
        flag.restore()
    assert signal.getsignal(signal.SIGTERM) is before


# --- the entry harness, as every node executable meets it -------------------------------------

BAD_PARAMETERS = {
    # node: (parameters, name in the message, words in the message)
    'simulator': (['rate_hz:=50'], 'rate_hz', 'floating-point'),
    'simulator2': (['maneuver:=loop_the_loop'], 'maneuver', 'loop_the_loop'),
    'identifier': (['frame:=nwu'], 'frame', 'nwu'),
    'identifier2': (['tau:=10'], 'tau', 'floating-point'),
    'record': (['topics:=/odom', 'output:=/tmp/never_written'], 'topics', 'list of strings'),
    'play': (['bag:=/nonexistent', 'rate:=-1.0'], 'rate', 'must be > 0'),
}


def _run(node, *args, env):
    require_loopback_dds()
    assert env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    return subprocess.Popen([sys.executable, '-m', 'auv_ident', 'run', node, *args], env=env,
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_every_node_exits_2_with_one_line_naming_a_bad_parameter(ros_env):
    procs = {}
    try:
        for key, (params, _, _) in BAD_PARAMETERS.items():   # all at once: start-up dominates
            node = key.rstrip('2')
            args = ['--ros-args'] + [a for p in params for a in ('-p', p)]
            procs[key] = (node, _run(node, *args, env=ros_env))
        procs['help'] = ('play', _run('play', '--help', env=ros_env))
        procs['stray'] = ('record', _run('record', 'topics:=[/odom]', env=ros_env))
        results = {}
        for key, (node, proc) in procs.items():
            out, err = proc.communicate(timeout=120.0)
            results[key] = (node, proc.returncode, out, err)
    finally:
        for _, proc in procs.values():
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    for key, (params, name, words) in BAD_PARAMETERS.items():
        node, rc, out, err = results[key]
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert rc == 2 and len(lines) == 1, (key, rc, err)
        assert lines[0].startswith(f"[{node}] error: parameter '{name}': "), (key, lines[0])
        assert words in lines[0], (key, lines[0])
    _, rc, out, err = results['help']
    assert rc == 0 and 'Play a rosbag2' in out and not err.strip()
    _, rc, out, err = results['stray']
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1 and 'unexpected argument' in lines[0], err
    assert not os.path.exists('/tmp/never_written')
