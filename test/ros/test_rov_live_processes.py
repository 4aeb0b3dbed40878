"""The live identifier node on a thruster vehicle (#29 item 4, "the live node does the same on
the played bag"): a BlueROV2 Heavy bag of the independent generator (offline/independent_rov.py
--curve file: PWM on /thrusters as Float64MultiArray without a header, sent on change; ENU
odometry with coloured noise) played by our player with its /clock into `run identifier`
(vehicle bluerov2_heavy, input map bluerov2_heavy, noise_source parameter, use_sim_time). Its
final estimate (the estimate file written at SIGINT) is identify --bag's EKF pass with the same
map (replay_bag: the node's session fed the bag in log-time order) to 1e-9 relative: every
command stamped with its log time, and the noise learning's re-runs (a worker thread live)
ending where the replay's do. The second test plays the whole 600 s session (the issue's
10-minute tank session) and holds the node's final estimate to the truth as identify --bag's
is held: every coefficient within 5 %, the truth within 3 sigma for >= 90 % of them."""
import json

from conftest import play_into_identifier
import numpy as np
import pytest

from auv_ident.offline.independent_rov import main as generate
from auv_ident.offline.replay import replay_bag
from auv_ident.ros.raw_loadtest import _cmd as _node_cmd
from auv_ident.session.settings import IdentifierSettings

# slow: the generator, two node processes and the bag played over DDS: 25 s at rate 2, ~40 s
# on the 2-core machine; 600 s at rate 4 and its replay, ~5 min
pytestmark = pytest.mark.slow

SETTINGS = {'vehicle': 'bluerov2_heavy', 'input_map': 'bluerov2_heavy',
            'noise_source': 'parameter'}


def _play_session(tmp_path, ros_env, duration_s, rate, timeout_s):
    """Generate the independent BlueROV2 bag (seed 3, --curve file, duration_s), play it with
    its /clock at `rate` into the identifier process (SIGINT at the end); returns (the bag,
    its truth's coefficients, the node's estimate file as a dict, the node's stderr)."""
    out = tmp_path / 'rov'
    assert generate(['--out', str(out), '--seed', '3', '--duration', str(duration_s),
                     '--curve', 'file']) == 0
    bag = str(out / 'bag')
    saved = tmp_path / 'live.json'
    err = play_into_identifier(
        _node_cmd('identifier', 'use_sim_time:=true', f'save_path:={saved}',
                  *(f'{k}:={v}' for k, v in SETTINGS.items())),
        _node_cmd('play', f'bag:={bag}', 'input_map:=bluerov2_heavy', 'publish_clock:=true',
                  f'rate:={rate}', 'wait_for_subscribers:=[/odom,/thrusters,/clock]',
                  'wait_for_subscribers_s:=60.0', 'wait_for_all_acked_s:=30.0'), ros_env,
        timeout=timeout_s)
    assert 'Traceback' not in err, err[-3000:]
    truth = json.loads((out / 'truth.json').read_text())['coefficients']
    return bag, truth, json.loads(saved.read_text()), err


def test_player_fed_node_identifies_the_bluerov2_as_identify_bag(tmp_path, ros_env):
    # 25 s: 500 odometry samples, past the noise learning's first re-run (200 samples) and
    # its second (400), where a worker thread's takeover changed the estimates before
    bag, _, live, err = _play_session(tmp_path, ros_env, 25, 2.0, 120.0)
    ref = replay_bag(bag, IdentifierSettings.from_values(**SETTINGS), warn=False)
    assert live['coefficients'] == ref.names and len(ref.names) == 14   # 12 and the current
    # every odometry message fused as offline (the first one, before any command, rejected)
    assert live['steps'] == ref.accepted and ref.accepted == 499 and ref.rejected == 1
    assert 're-run 2, over 401 kept samples' in err, err[-3000:]
    np.testing.assert_allclose(live['estimate'], ref.estimate, rtol=1e-9, atol=0)
    np.testing.assert_allclose(live['covariance'], ref.cov, rtol=1e-6, atol=1e-18)


def test_node_on_the_played_10_minute_session_recovers_the_coefficients(tmp_path, ros_env):
    # the "the live node does the same on the played bag": the whole 600 s session
    # (12000 odometry, 4305 commands) played at 4x (~160 s), the node's final estimate (its
    # EKF pass: the node runs no batch refinement) is the replay's and within the issue's
    # bounds of the truth (measured: all 12 within 3.4 %, the truth within 1.6 sigma)
    bag, truth, live, err = _play_session(tmp_path, ros_env, 600, 4.0, 600.0)
    assert live['steps'] == 11999, err[-3000:]          # the first odometry precedes a command
    ref = replay_bag(bag, IdentifierSettings.from_values(**SETTINGS), warn=False)
    np.testing.assert_allclose(live['estimate'], ref.estimate, rtol=1e-9, atol=0)
    est, std = dict(zip(live['coefficients'], live['estimate'])), dict(
        zip(live['coefficients'], live['std']))
    names = [n for n in live['coefficients'] if not n.startswith('current_')]
    assert len(names) == 12
    error = {n: abs(est[n] - truth[n]) / abs(truth[n]) for n in names}
    assert max(error.values()) < 0.05, error
    within = [n for n in names if abs(est[n] - truth[n]) <= 3.0 * std[n]]
    assert len(within) >= 0.9 * len(names), (within, error)
