"""Offline, a stuck or missing sensor is named and the result untrusted (session/stuck.py,
analysis/bag_identify.py): `identify --bag` on a bag whose odometry repeats exactly for 5 s,
and on one whose orientation is left at the identity quaternion, exits 3 with the span named
on the first line; the clean bag is consistent."""
from dataclasses import replace
import json

import numpy as np
import pytest

from auv_ident.cli import EXIT_UNTRUSTED, main
from auv_ident.core.identification.diagnosis import diagnose, not_noise_channels
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import State
from auv_ident.core.simulation.simulate import simulate
from auv_ident.offline.replay import replay_bag
from auv_ident.offline.sim_bag import write_run_bag
from auv_ident.vehicles import load_vehicle

STUCK = (200, 300)      # 5 s at 20 Hz from t = 10 s: the odometry of t = 9.95 s repeated


@pytest.fixture(scope='module')
def run():
    return simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=30.0, T=0.05, seed=3)


def _bag(run, tmp_path, name, change):
    y = run.y.copy()
    change(y)
    return write_run_bag(replace(run, y=y), tmp_path / name)


def _identify(bag, tmp_path, capsys):
    out = tmp_path / 'result.json'
    status = main(['identify', '--bag', str(bag), '--no-refine', '--json', str(out)])
    return status, json.loads(out.read_text()), capsys.readouterr().out


def test_repeated_odometry_in_a_bag_is_named_and_untrusted(run, tmp_path, capsys):
    def freeze(y):
        y[STUCK[0]:STUCK[1]] = y[STUCK[0] - 1]
    bag = _bag(run, tmp_path, 'stuck', freeze)
    rr = replay_bag(bag, warn=False)
    assert dict(rr.reasons) == {'odom: repeated': 100}
    assert [(s.group, round(s.since, 3), round(s.seconds, 3), s.repeats, s.active)
            for s in rr.stuck] == [(g, 9.95, 5.0, 100, False) for g in
                                   ('position', 'attitude', 'linear velocity',
                                    'angular velocity')]
    status, doc, printed = _identify(bag, tmp_path, capsys)
    assert status == EXIT_UNTRUSTED
    head = ('NOT consistent: odometry position, attitude, linear velocity, angular velocity '
            'repeated exactly for 5.0 s from t = 9.950 s (100 samples not fed): a stuck '
            'sensor')
    assert doc['diagnosis']['messages'][0].startswith(head)
    assert printed.startswith(head)
    assert doc['diagnosis']['checks']['stuck_sensor'] == [doc['diagnosis']['messages'][0][
        len('NOT consistent: '):]]
    # the repeats are not outliers: no replay with a noise model for them
    assert doc['replayed_with_noise_model'] is None
    assert doc['rejection_reasons'] == {'odom: repeated': 100}


def test_orientation_never_filled_is_named_and_untrusted(run, tmp_path, capsys):
    """The identity quaternion throughout (a driver that fills only the twist): NOT
    consistent naming the attitude, never 'consistent ... the error bars hold'."""
    def identity(y):
        y[:, State.PHI:] = 0.0
    status, doc, printed = _identify(_bag(run, tmp_path, 'identity', identity), tmp_path,
                                     capsys)
    assert status == EXIT_UNTRUSTED
    assert doc['diagnosis']['messages'][0].startswith(
        'NOT consistent: odometry attitude repeated exactly for 30.0 s from t = 0.000 s '
        '(600 samples not fed): a stuck sensor, or a field the driver never fills')
    assert 'leave the channels out (--measured)' in printed.splitlines()[0]


def test_no_estimate_file_is_formed_while_a_sensor_is_stuck(run, tmp_path, capsys):
    """identify --bag --estimate-out writes the identifier node's warm start: a bag whose
    sensor is still stuck at its end (the orientation never filled) gives an estimate formed
    while the fault was active, which the node never saves as its last good one: not written,
    said on stderr, exit 3. A fault that ended (the 5 s repeat) gives the file: its repeats
    were never fed."""
    def identity(y):
        y[:, State.PHI:] = 0.0

    def freeze(y):
        y[STUCK[0]:STUCK[1]] = y[STUCK[0] - 1]
    out = tmp_path / 'e.json'
    bag = _bag(run, tmp_path, 'identity', identity)
    assert main(['identify', '--bag', str(bag), '--no-refine', '--estimate-out',
                 str(out)]) == EXIT_UNTRUSTED
    err = capsys.readouterr().err
    assert not out.exists()
    assert (f'--estimate-out {out}: not written: the odometry attitude repeated exactly for '
            '30.0 s from t = 0.000 s (600 samples not fed) is still stuck at the end of the '
            'bag') in err
    assert main(['identify', '--bag', str(_bag(run, tmp_path, 'stuck', freeze)), '--no-refine',
                 '--estimate-out', str(out)]) == EXIT_UNTRUSTED
    assert json.loads(out.read_text())['steps'] == 501      # the 100 repeats not fed


def test_the_clean_bag_is_consistent(run, tmp_path, capsys):
    status, doc, _ = _identify(_bag(run, tmp_path, 'clean', lambda y: None), tmp_path, capsys)
    assert status == 0 and doc['diagnosis']['consistent']
    assert 'stuck_sensor' not in doc['diagnosis']['checks']


def _channel(ar1, samples=1200):
    return {'level': 1.0, 'ar1': ar1, 'tau_s': -0.05 / np.log(ar1) if ar1 < 1 else np.inf,
            'samples': samples, 'white': False, 'p_white': 0.0, 'ljung_box': 1e4}


def test_a_channel_correlated_beyond_the_run_is_not_noise():
    """A bias or a constant channel (lag-1 correlation 1, 'time constant inf s') is no noise
    that averages out: NOT consistent naming the channel. Strong but shorter correlation
    (AR(1), tau 1 s at 20 Hz: 0.95) is noise the noise model handles."""
    model = {'u': _channel(0.95), 'phi': _channel(1.0), 'theta': _channel(0.9995)}
    assert [n for n, _ in not_noise_channels(model)] == ['phi', 'theta']
    assert not not_noise_channels({'u': _channel(0.95), 'theta': _channel(0.999)})

    class Fit:
        used, covariance, notes, refine_converged = True, 'white', [], True
    Fit.model = model
    d = diagnose(Fit(), refined=False)
    assert not d['consistent'] and d['checks']['not_noise_channels'] == ['phi', 'theta']
    assert d['messages'][0].startswith('NOT consistent: the phi innovations are not noise: '
                                       'lag-1 correlation 1.0000 (time constant inf s), '
                                       'longer than the run (1200 samples): a bias or a '
                                       'missing sensor')


def test_position_and_heading_drift_is_noted_not_called_a_missing_sensor():
    """Position and heading innovations of an EKF are the model error integrated (no restoring
    force): correlated beyond the run on a good BlueROV2 bag (x 0.99995 of 11999 samples). A
    note, not NOT consistent; an attitude channel correlated so is still not noise."""
    from auv_ident.core.identification.diagnosis import drifting_channels

    model = {'u': _channel(0.95, 11999), 'x': _channel(0.99995, 11999),
             'psi': _channel(0.99995, 11999)}
    assert not not_noise_channels(model)
    assert [n for n, _ in drifting_channels(model)] == ['x', 'psi']

    class Fit:
        used, covariance, notes, refine_converged = True, 'white', [], True
    Fit.model = model
    d = diagnose(Fit(), refined=False)
    assert d['consistent'] and d['checks']['not_noise_channels'] == []
    assert any(m.startswith('the x innovations drift (lag-1 correlation 0.99995')
               for m in d['messages'])
    Fit.model = {**model, 'theta': _channel(0.99995, 11999)}
    d = diagnose(Fit(), refined=False)
    assert not d['consistent'] and d['checks']['not_noise_channels'] == ['theta']
