"""Live error bars that hold (issue 26, item 4), over DDS with real processes: our player
(``play``) feeds the identifier (``identifier``) a bag made by the independent generator
(offline/independent_data.py, its own integrator and writer) at 10x real time.

- AR(1) sensor noise, twice the documented level, correlated over 1 s, the level not told
  (the identifier runs with its default noise_std): the identifier learns the noise model from
  its innovations (session/noise_learning.py) and ends with the truth within 3 sigma for at
  least 4 of the paper's five, or says NOT consistent on /diagnostics for the whole run (the
  issue's done-when). Measured (seed 1, 120 s): every one within 1.9 sigma, consistent.
- White noise of the documented level: never NOT consistent (no false alarm), nothing
  re-run, the truth within 3 sigma.
"""
import json
import os
import signal
import subprocess
import sys

from diagnostic_msgs.msg import DiagnosticArray
from helpers import (
    probe_node,
    read_text,
    spawn_identifier,
    spawn_node,
    spin_until,
    stop_process,
)
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from auv_ident.offline.independent_data import DataConfig, generate

pytestmark = pytest.mark.slow     # a 120 s bag played at 10x into an identifier process

PAPER = ('Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v')
DURATION = 120.0
ODOM_RATE = 10.0                  # the generator's default
N_ODOM = int(DURATION * ODOM_RATE) + 1
RATE = 10.0                       # playback speed
LATCHED = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


@pytest.fixture
def probe(ros_env):
    with probe_node('noise_probe') as probe:
        yield probe


def _values(diag):
    return {v.key: v.value for v in diag.status[0].values}


def _play_into_identifier(probe, ros_env, tmp_path, bag):
    """Start the identifier, play bag into it at RATE, stop it with SIGINT (it saves its
    estimate file); returns (estimate file document, [/diagnostics values dicts], log)."""
    node, ex = probe
    diags, estimates = [], []
    node.create_subscription(DiagnosticArray, '/diagnostics',
                             lambda m: diags.append(_values(m)), 100)
    node.create_subscription(JointState, '/identifier/estimate', estimates.append, LATCHED)
    save = tmp_path / 'estimate.json'
    procs = []
    try:
        ident = spawn_identifier(probe, ['-p', f'save_path:={save}'], ros_env, str(tmp_path))
        procs.append(ident)
        player = spawn_node('play', ['-p', f'bag:={bag}', '-p', f'rate:={RATE}',
                                     '-p', "wait_for_subscribers:=['/odom', '/actuators']"],
                            ros_env, str(tmp_path))
        procs.append(player)
        assert spin_until(ex, lambda: player.poll() is not None, DURATION / RATE + 40.0), \
            'the player did not finish'
        assert stop_process(player) == 0, read_text(tmp_path / 'play.err')

        def drained():
            return diags and int(diags[-1]['accepted']) + int(diags[-1]['rejected']) >= N_ODOM
        spin_until(ex, drained, 20.0)
        spin_until(ex, lambda: False, 1.5)    # one more /diagnostics after the last message
        assert stop_process(ident, signal.SIGINT) == 0, read_text(tmp_path / 'identifier.err')
        log = read_text(tmp_path / 'identifier.err')
        assert 'Traceback' not in log, log
    finally:
        for p in procs:
            stop_process(p, signal.SIGKILL if p.poll() is None else signal.SIGINT)
        subprocess.run([os.path.join(os.path.dirname(sys.executable), 'fastdds'), 'shm',
                        'clean'], capture_output=True, check=False)
    assert estimates, 'no estimate published'
    return json.loads(save.read_text()), diags, log


def _errors_in_sigma(doc, truth):
    names = doc['coefficients']
    return {n: abs(doc['estimate'][names.index(n)] - truth[n]) / doc['std'][names.index(n)]
            for n in PAPER}


@pytest.mark.parametrize('noise,level', [('ar1', 2.0), ('white', 1.0)])
def test_live_error_bars_hold_on_the_played_bag(ros_env, probe, tmp_path, noise, level):
    data = generate(DataConfig(seed=1, noise=noise, noise_level=level, noise_tau=1.0,
                               duration=DURATION), tmp_path / 'data')
    truth = json.loads(data.truth_json.read_text())['coefficients']
    doc, diags, log = _play_into_identifier(probe, ros_env, tmp_path, str(data.bag))
    assert int(diags[-1]['accepted']) >= 0.99 * N_ODOM, diags[-1]['accepted']
    z = _errors_in_sigma(doc, truth)
    within = sum(v < 3.0 for v in z.values())
    said = [d['consistent'] for d in diags]
    last = diags[-1]
    # the figures docs/accuracy.md quotes (pytest -s shows them)
    print(f'\n{noise} x{level:g}: |error|/sigma ' + ', '.join(f'{n} {v:.2f}' for n, v in z.items())
          + f'; consistent {last["consistent"]}, noise re-runs {last["noise_reruns"]}, '
          f'first "true" at /diagnostics message {said.index("true") if "true" in said else None}'
          f' of {len(said)}; ' + ', '.join(f'{k} {last[k]}' for k in last
                                           if k.startswith('noise_scale_')))
    # the estimate file says what /diagnostics says at the end
    assert doc['diagnosis']['consistent'] == {'true': True, 'false': False,
                                              'not judged': None}[last['consistent']]
    if noise == 'ar1':
        # the done-when: truth within 3 sigma for >= 4 of 5, or NOT consistent all along
        assert within >= 4 or all(c != 'true' for c in said), (z, said)
        # and the learning did it: the noise model was learnt and holds at the end
        assert int(last['noise_reruns']) >= 1 and last['noise_state'] == 'holds', last
        assert last['consistent'] == 'true' and within >= 4, (z, last['diagnosis'])
        assert 'noise model learnt from the innovations' in log
        # never consistent on the configured (wrong) noise model: only once a learnt one holds
        assert all(d['noise_reruns'] != '0' and d['noise_state'] == 'holds'
                   for d in diags if d['consistent'] == 'true'), diags
    else:
        # no false alarm: never NOT consistent, nothing re-run
        assert 'false' not in said, [d['diagnosis'] for d in diags if d['consistent'] ==
                                     'false'][:1]
        assert last['consistent'] == 'true' and last['noise_reruns'] == '0', last
        assert within == len(PAPER), z
