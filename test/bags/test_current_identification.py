"""Identification in a water current, on bags made independently of the identifier
(offline/independent_data.py: its own integrator, kinematics, noise and rosbags writer), through
``identify --bag`` (analysis.bag_identify.identify_bag) and the command line.

The slow tests fly 600 s bags in steady currents from several directions, DVL over ground and
through the water, on NPS AUV II and REMUS 100: the goals of the issue (coefficients within
2 %, the current within 0.01 m/s, both within 3 sigma). tools/current_campaign.py measures the
same over many seeds, directions and speeds.
"""
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from auv_ident.analysis.bag_identify import identify_bag
from auv_ident.offline.independent_data import DataConfig, generate
from auv_ident.session.settings import IdentifierSettings

GOAL_PCT = 2.0          # every coefficient within this of the truth (%)
GOAL_CURRENT = 0.01     # m/s


def _current(speed, towards_deg):
    a = math.radians(towards_deg)
    return (speed * math.cos(a), speed * math.sin(a), 0.0)


def _check(doc, truth, sigmas=3.0):
    """The goal on one bag: coefficients and current against truth.json."""
    for name, c in doc['coefficients'].items():
        tv = truth['coefficients'][name]
        err = c['estimate'] - tv
        # the median goal (< 2 %) per bag, except for a coefficient the run determines only to
        # more than a third of it (K_v at 500 rpm: 1-sigma ~1.2 %): honest bars only
        if c['std'] < GOAL_PCT / 300 * abs(tv):
            assert abs(err) < GOAL_PCT / 100 * abs(tv), (name, c['estimate'], tv)
        assert abs(err) < sigmas * c['std'], (name, err / c['std'])
    cur = doc['current']
    est = np.array([cur['north'], cur['east'], cur['down']])
    err = est - np.array(truth['current_ned'])
    for i, name in enumerate(('current_n', 'current_e')):
        assert name in cur['estimated']
        assert abs(err[i]) < GOAL_CURRENT, (name, est, truth['current_ned'])
        assert abs(err[i]) < sigmas * cur['std'][i], (name, err[i] / cur['std'][i])
    assert doc['warnings'] == [] and cur['identifiability']['separable']


@pytest.mark.slow
@pytest.mark.parametrize('vehicle,speed,towards,dvl,seed', [
    ('nps_auv2', 0.3, 45.0, 'ground', 1),
    ('nps_auv2', 0.1, 200.0, 'ground', 2),
    ('nps_auv2', 0.2, 300.0, 'water', 3),
    ('remus100', 0.2, 135.0, 'ground', 1),
])
def test_coefficients_and_current_from_an_independent_bag(tmp_path, vehicle, speed, towards,
                                                           dvl, seed):
    cfg = DataConfig(vehicle=vehicle, duration=600.0, seed=seed, odom_rate=20.0,
                     commands='periodic', command_rate=20.0,
                     current_ned=_current(speed, towards), dvl=dvl)
    data = generate(cfg, tmp_path / 'run')
    doc, table = identify_bag(data.bag, IdentifierSettings.from_values(vehicle=vehicle,
                                                                       velocity_reference=dvl))
    _check(doc, data.truth)
    assert doc['current']['velocity_reference'] == dvl
    assert abs(doc['current']['speed'] - speed) < GOAL_CURRENT
    assert 'current (m/s)' in table and 'north' in table
    json.dumps(doc)


@pytest.mark.slow
def test_left_out_the_current_wrecks_the_coefficients_estimated_it_does_not(tmp_path):
    """The baseline's case e (0.1 m/s from the north-east, DVL over ground): with --current
    none the paper's five come out wrong (tens of % before the noise model, a few % now) and
    the diagnosis says the model is inadequate; with the default they meet the goal."""
    cfg = DataConfig(duration=600.0, seed=1, odom_rate=20.0, commands='periodic',
                     command_rate=20.0, current_ned=_current(0.1, 225.0))
    data = generate(cfg, tmp_path / 'run')
    still, _ = identify_bag(data.bag, IdentifierSettings.from_values(current='none'))
    worst = max(abs(c['estimate'] - data.truth['coefficients'][n])
                / abs(data.truth['coefficients'][n]) for n, c in still['coefficients'].items())
    assert worst > 0.02 and still['current'] is None
    assert still['diagnosis']['consistent'] is False
    doc, _ = identify_bag(data.bag)
    _check(doc, data.truth)


def test_straight_run_warns_that_the_current_is_not_separable(tmp_path):
    """No rudder: the heading stays put, the output says so and what to fly instead (JSON
    field and a warning line)."""
    cfg = DataConfig(duration=60.0, seed=5, odom_rate=10.0, commands='periodic',
                     command_rate=10.0, rudder_deg=0.0, current_ned=_current(0.2, 30.0))
    data = generate(cfg, tmp_path / 'run')
    doc, table = identify_bag(data.bag, IdentifierSettings.from_values(coefficients='Z_w,M_ds'))
    ident = doc['current']['identifiability']
    assert not ident['separable'] and ident['heading_span_deg'] < 5.0
    assert any('straight run' in r for r in ident['reasons'])
    assert ident['advice'].startswith('turns: the current is separable from the coefficients '
                                      'only through heading changes')
    assert len(doc['warnings']) == 1 and doc['warnings'][0] in table
    assert 'warning: the water current is not separable' in table


def _cli(*args):
    return subprocess.run([sys.executable, '-m', 'auv_ident', *args], capture_output=True,
                          text=True)


def test_identify_command_line_current_options(tmp_path):
    """--current estimate (default) | none | N,E[,D], --current-down, --velocity-reference; the
    JSON `current` and the table; a bad value is one line naming the option."""
    cfg = DataConfig(duration=40.0, seed=6, odom_rate=10.0, commands='periodic',
                     command_rate=10.0, current_ned=_current(0.15, 100.0))
    data = generate(cfg, tmp_path / 'run')
    out = tmp_path / 'est.json'
    p = _cli('identify', '--bag', str(data.bag), '--coefficients', 'Z_w,M_ds', '--no-refine',
             '--json', str(out))
    assert p.returncode == 0, p.stderr
    doc = json.loads(out.read_text())
    cur = doc['current']
    assert set(cur) >= {'north', 'east', 'down', 'std', 'estimated', 'velocity_reference',
                        'speed', 'direction_deg', 'ekf', 'identifiability'}
    assert cur['estimated'] == ['current_n', 'current_e'] and len(cur['std']) == 3
    assert cur['down'] == 0.0 and cur['std'][2] == 0.0
    assert 'water current: estimated (north, east; down 0)' in p.stdout
    assert 'current (m/s)' in p.stdout
    # with the down component
    p = _cli('identify', '--bag', str(data.bag), '--coefficients', 'Z_w,M_ds', '--no-refine',
             '--current-down', '--json', str(out), '--force')
    assert p.returncode == 0, p.stderr
    cur = json.loads(out.read_text())['current']
    assert cur['estimated'] == ['current_n', 'current_e', 'current_d'] and cur['std'][2] > 0
    # still water: no current in the result
    p = _cli('identify', '--bag', str(data.bag), '--coefficients', 'Z_w,M_ds', '--no-refine',
             '--current', 'none', '--json', str(out), '--force')
    assert p.returncode == 0, p.stderr
    assert json.loads(out.read_text())['current'] is None and 'current (m/s)' not in p.stdout
    # a known current: held, reported as given
    p = _cli('identify', '--bag', str(data.bag), '--coefficients', 'Z_w,M_ds', '--no-refine',
             '--current=-0.026,0.148', '--json', str(out), '--force')
    assert p.returncode == 0, p.stderr
    cur = json.loads(out.read_text())['current']
    assert cur['estimated'] == [] and cur['north'] == -0.026 and cur['std'] == [0.0] * 3
    for bad, needle in ((['--current', 'fast'], "current = 'fast'"),
                        (['--current', 'none', '--current-down'], 'current-down needs'),
                        (['--velocity-reference', 'bottom'], 'invalid choice')):
        p = _cli('identify', '--bag', str(data.bag), '--no-refine', *bad)
        assert p.returncode == 2 and needle in p.stderr and 'Traceback' not in p.stderr, \
            p.stderr
