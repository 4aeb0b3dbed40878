"""Test-run isolation for every test that may start a ROS node, and the shared helpers' path.

The tests live in folders that mirror the package (core/, session/, ros/, bags/, analysis/;
test_layering.py, which checks the whole package, at the top). The shared helpers stay here in
test/ (conftest.py, helpers.py, ros_pub_helper.py, kvlcc2_data.py, method_runs.py) and are
imported by plain name (`from helpers import ...`): pytest's default prepend import mode puts
each test file's own folder on sys.path, so this file puts test/ there too, for every folder. The
folders have no __init__.py (test/ as a package would be named `test`, the standard library's
test package), so every test file's basename must be unique across the folders.

DDS stays on loopback: each pytest run gets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, its own
ROS_DOMAIN_ID (1-101) and its own ROS_LOG_DIR, set here before any test imports rclpy, and
inherited by every node process a test spawns. Fast DDS shared-memory files that killed
processes leave behind are removed at the end of the run (`fastdds shm clean`).
"""
import os
import random
import shutil
import subprocess
import sys
import tempfile

import pytest

TEST_DIR = os.path.dirname(os.path.abspath(__file__))
if TEST_DIR not in sys.path:
    sys.path.insert(0, TEST_DIR)

_LOG_DIR = tempfile.mkdtemp(prefix='auv_ident_roslog_')
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.pop('ROS_LOCALHOST_ONLY', None)  # deprecated; RANGE supersedes it
if 'AUV_IDENT_TEST_DOMAIN_ID' in os.environ:
    os.environ['ROS_DOMAIN_ID'] = os.environ['AUV_IDENT_TEST_DOMAIN_ID']
else:
    os.environ['ROS_DOMAIN_ID'] = str(random.SystemRandom().randint(1, 101))
os.environ['ROS_LOG_DIR'] = _LOG_DIR


def require_loopback_dds():
    """Fail loudly (never skip) if DDS discovery could leave this machine."""
    if os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE') != 'LOCALHOST':
        raise RuntimeError(
            'refusing to start a ROS node: ROS_AUTOMATIC_DISCOVERY_RANGE is not LOCALHOST '
            '(DDS discovery must stay on loopback)')
    dom = int(os.environ.get('ROS_DOMAIN_ID', '-1'))
    if not 1 <= dom <= 101:
        raise RuntimeError(f'refusing to start a ROS node: ROS_DOMAIN_ID={dom} not in 1..101')


@pytest.fixture
def ctx():
    """An rclpy context of the test's own (loopback DDS checked), shut down afterwards."""
    require_loopback_dds()
    import rclpy
    context = rclpy.context.Context()
    rclpy.init(context=context)
    yield context
    rclpy.try_shutdown(context=context)


@pytest.fixture
def ros_env():
    """Environment for a node process a test spawns (loopback DDS, this run's domain)."""
    require_loopback_dds()
    return dict(os.environ)


def spawn_node(cmd, env):
    """A node process of a test (loopback DDS only), its stdout and stderr piped."""
    require_loopback_dds()
    assert env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    return subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def play_into_identifier(ident_cmd, player_cmd, env, timeout=120.0):
    """Start the identifier, play a bag into it with the player (both exit 0), then SIGINT
    the identifier (it writes its estimate file); returns the identifier's stderr. Every
    process is killed on the way out."""
    import signal
    ident, player = spawn_node(ident_cmd, env), None
    try:
        player = spawn_node(player_cmd, env)
        _, perr = player.communicate(timeout=timeout)
        assert player.returncode == 0, perr[-2000:]
        ident.send_signal(signal.SIGINT)
        _, err = ident.communicate(timeout=30.0)
        assert ident.returncode == 0, err[-3000:]
    finally:
        for p in (ident, player):
            if p is not None and p.poll() is None:
                p.kill()
                p.communicate()
    return err


def pytest_sessionfinish(session, exitstatus):
    fastdds = os.path.join(os.path.dirname(sys.executable), 'fastdds')
    if os.path.exists(fastdds):
        subprocess.run([fastdds, 'shm', 'clean'], capture_output=True, check=False)
    shutil.rmtree(_LOG_DIR, ignore_errors=True)
