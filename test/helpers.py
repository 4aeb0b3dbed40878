"""Helpers shared by the test modules: node processes and message comparison."""
import array
from contextlib import contextmanager
import dataclasses
import importlib.util
import os
import signal
import subprocess
import sys
import time

from conftest import require_loopback_dds
import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))



def load_tool(name):
    """The module of tools/NAME.py, loaded from its file (the tools are scripts, not a
    package; one that inserts the package root into sys.path does so here too)."""
    spec = importlib.util.spec_from_file_location(name, os.path.join(REPO, 'tools',
                                                                     f'{name}.py'))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod

def spawn_node(node, ros_args, env, log_dir, name=None):
    """Start `python -m auv_ident run NODE --ros-args ...` with stdout/stderr in log_dir.

    The spawning environment must keep DDS on loopback (checked here as well as in the
    ros_env fixture that builds env)."""
    require_loopback_dds()
    if env.get('ROS_AUTOMATIC_DISCOVERY_RANGE') != 'LOCALHOST':
        raise RuntimeError('refusing to spawn a node whose environment lets DDS leave loopback')
    name = name or node
    out = open(os.path.join(log_dir, f'{name}.out'), 'w')
    err = open(os.path.join(log_dir, f'{name}.err'), 'w')
    proc = subprocess.Popen([sys.executable, '-m', 'auv_ident', 'run', node, '--ros-args',
                             *ros_args], env=env, cwd=REPO, stdout=out, stderr=err)
    proc.logs = (out, err)
    return proc


def stop_process(proc, sig=signal.SIGINT, timeout=10.0):
    """Stop a spawned process (sig, then SIGKILL after timeout s); returns its exit status."""
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    for fh in proc.logs:
        fh.close()
    return proc.returncode


def read_text(path):
    """The text of a (log) file."""
    with open(path, encoding='utf-8') as fh:
        return fh.read()


@contextmanager
def probe_node(name):
    """(node, executor): a node of the test process in a context of its own, for probing the
    graph of spawned node processes; shut down on leaving."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node(name, context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        yield node, ex
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


def spin_until(ex, cond, timeout):
    """Spin the executor ex until cond() or timeout s; returns cond()."""
    deadline = time.monotonic() + timeout
    while not cond() and time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.05)
    return cond()


def spawn_identifier(probe, ros_args, env, log_dir):
    """Spawn the identifier process (as spawn_node) and wait, spinning the probe (node,
    executor), until it subscribes to /odom: up to 40 s, since a stale numba cache makes it
    compile its EKF first (~15 s). Returns the process, running (its log in the assertion
    message otherwise)."""
    node, ex = probe
    ident = spawn_node('identifier', ros_args, env, log_dir)

    def subscribed():
        return any(i.node_name == 'identifier'
                   for i in node.get_subscriptions_info_by_topic('/odom'))
    spin_until(ex, lambda: subscribed() or ident.poll() is not None, 40.0)
    assert ident.poll() is None and subscribed(), read_text(
        os.path.join(log_dir, 'identifier.err'))
    return ident


def assert_msg_equal(expected, actual, where='msg'):
    """Compare an rclpy or rosbags message with a decoded one (rosbags, rclpy or mcap_ros2)
    by field."""
    if hasattr(expected, 'get_fields_and_field_types'):
        for name in expected.get_fields_and_field_types():
            assert_msg_equal(getattr(expected, name), getattr(actual, name), f'{where}.{name}')
    elif dataclasses.is_dataclass(expected) and hasattr(expected, '__msgtype__'):  # rosbags
        for f in dataclasses.fields(expected):
            if f.name.startswith('__'):  # __msgtype__: rosbags' type name, not a ROS field
                continue
            assert_msg_equal(getattr(expected, f.name), getattr(actual, f.name),
                             f'{where}.{f.name}')
    elif isinstance(expected, (list, tuple, array.array, np.ndarray)):
        assert len(expected) == len(actual), where
        for i, (e, a) in enumerate(zip(expected, actual)):
            assert_msg_equal(e, a, f'{where}[{i}]')
    else:
        assert expected == actual, f'{where}: {expected!r} != {actual!r}'


def write_rclpy(writer, topic, t_ns, msg):
    """Serialize an rclpy message and write it to a BagWriter (which takes bytes only); the
    topic is added with the default QoS if new (a no-op if known with the same type)."""
    from rclpy.serialization import serialize_message
    pkg = type(msg).__module__.split('.')[0]
    writer.add_topic(topic, f'{pkg}/msg/{type(msg).__name__}')
    writer.write(topic, t_ns, serialize_message(msg))
