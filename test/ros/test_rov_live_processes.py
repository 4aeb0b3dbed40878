"""The live identifier node on a thruster vehicle (#29 item 4, "the live node does the same on
the played bag"): a BlueROV2 Heavy bag of the independent generator (offline/independent_rov.py
--curve file: PWM on /thrusters as Float64MultiArray without a header, sent on change; ENU
odometry with coloured noise) played by our player with its /clock into `run identifier`
(vehicle bluerov2_heavy, input map bluerov2_heavy, noise_source parameter, use_sim_time). Its
final estimate (the estimate file written at SIGINT) is identify --bag's EKF pass with the same
map (replay_bag: the node's session fed the bag in log-time order) to 1e-9 relative: every
command stamped with its log time, and the noise learning's re-runs (a worker thread live)
ending where the replay's do."""
import json

from conftest import play_into_identifier
import numpy as np
import pytest

from auv_ident.offline.independent_rov import main as generate
from auv_ident.offline.replay import replay_bag
from auv_ident.ros.raw_loadtest import _cmd as _node_cmd
from auv_ident.session.settings import IdentifierSettings

# slow: the generator, two node processes and 25 s of bag at rate 2 over DDS, ~40 s on the
# 2-core machine
pytestmark = pytest.mark.slow

SETTINGS = {'vehicle': 'bluerov2_heavy', 'input_map': 'bluerov2_heavy',
            'noise_source': 'parameter'}


def test_player_fed_node_identifies_the_bluerov2_as_identify_bag(tmp_path, ros_env):
    # 25 s: 500 odometry samples, past the noise learning's first re-run (200 samples) and
    # its second (400), where a worker thread's takeover changed the estimates before
    out = tmp_path / 'rov'
    assert generate(['--out', str(out), '--seed', '3', '--duration', '25', '--curve',
                     'file']) == 0
    bag = str(out / 'bag')
    ref = replay_bag(bag, IdentifierSettings.from_values(**SETTINGS), warn=False)
    saved = tmp_path / 'live.json'
    err = play_into_identifier(
        _node_cmd('identifier', 'use_sim_time:=true', f'save_path:={saved}',
                  *(f'{k}:={v}' for k, v in SETTINGS.items())),
        _node_cmd('play', f'bag:={bag}', 'input_map:=bluerov2_heavy', 'publish_clock:=true',
                  'rate:=2.0', 'wait_for_subscribers:=[/odom,/thrusters,/clock]',
                  'wait_for_subscribers_s:=60.0', 'wait_for_all_acked_s:=30.0'), ros_env)
    assert 'Traceback' not in err, err[-3000:]
    live = json.loads(saved.read_text())
    assert live['coefficients'] == ref.names and len(ref.names) == 14   # 12 and the current
    # every odometry message fused as offline (the first one, before any command, rejected)
    assert live['steps'] == ref.accepted and ref.accepted == 499 and ref.rejected == 1
    assert 're-run 2, over 401 kept samples' in err, err[-3000:]
    np.testing.assert_allclose(live['estimate'], ref.estimate, rtol=1e-9, atol=0)
    np.testing.assert_allclose(live['covariance'], ref.cov, rtol=1e-6, atol=1e-18)
