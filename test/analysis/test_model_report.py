"""report --model MODEL.json --validate BAG (analysis/model_report.py): a saved model judged on a
run it never saw. Simulated planar runs of kvlcc2_hsva: true zig-zags (the rudder reversed when
the heading passes the switch angle: a closed loop of the vehicle file's model through a known
steering gear, written as a manoeuvre CSV and simulated with sensor noise), one identified to a
model JSON, the other validated on; and the real HSVA runs (skipped without them, slow)."""
import csv
import json
import os
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from auv_ident.cli import EXIT_UNTRUSTED, main
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.sensors import DEFAULT_NOISE_STD
from auv_ident.core.model.state import Input, State
from auv_ident.core.model.trim import initial_state
from auv_ident.core.simulation.prediction import fit_percent
from auv_ident.core.simulation.simulate import simulate
from auv_ident.core.simulation.steering import SteeringGear
from auv_ident.core.simulation.zigzag_sim import simulate_zigzag
from auv_ident.offline.sim_bag import write_run_bag
from auv_ident.vehicles import load_vehicle

VEHICLE = 'kvlcc2_hsva'
GEAR = SteeringGear(delay=0.15, rate=np.deg2rad(15.0), time_constant=0.15)
# (a dead time short enough that the heading moves < 1 deg between order and onset: the
# switch angle is detected from the onsets, docs/zigzag.md)
CSV_HEADER = ['t'] + [f'{ch}_{m}' for ch in ('u', 'v', 'r', 'U', 'psi')
                      for m in ('measured', 'predicted', 'prior')]


def _thrust(x):
    """N: the thrust of the simulated runs rises as the ship slows (as at constant rev)."""
    return 41.0 + 60.0 * (1.178 - x[..., State.U])


def _zigzag_bag(out, first, seed, duration=62.0, rudder=20.0, switch=10.0, spoil=None):
    """A bag of a true zig-zag of the vehicle file's model: its closed loop through GEAR, the
    rudder and thrust written as a manoeuvre CSV, simulated with the sensor noise (then
    spoil(run), if given, changes its measurements run.y in place)."""
    v = load_vehicle(VEHICLE)
    m = Model(v)
    x0 = initial_state(m, v.cruise_rpm, depth=0.0)
    base = np.zeros(7)
    base[Input.N_RPM] = v.cruise_rpm
    sim = simulate_zigzag(lambda x, u: m.f(x, u), x0, rudder, switch, duration, GEAR,
                          thrust=_thrust, thrust_index=Input.THRUST, inputs=base, first=first,
                          execute_time=2.0)
    path = Path(str(out) + '.csv')
    with open(path, 'w', newline='') as fh:
        w = csv.writer(fh)
        w.writerow(['t', 'delta_r', 'delta_s', 'delta_b', 'delta_bp', 'delta_bs', 'n_rpm',
                    'thrust'])
        for t, d, T in zip(sim.t, sim.rudder, sim.thrust):
            w.writerow([repr(float(t)), repr(float(d)), 0, 0, 0, 0, v.cruise_rpm, repr(float(T))])
    # a ship's gyro: 1 mrad (0.06 deg; the default AUV heading noise, 0.3 deg, would move the
    # switch angle detected from the reversal headings by a degree)
    noise = DEFAULT_NOISE_STD.copy()
    noise[State.PSI] = 1e-3
    run = simulate(m, str(path), duration=duration - 0.5, seed=seed, noise_std=noise)
    if spoil is not None:
        spoil(run)
    write_run_bag(run, str(out))
    return str(out), sim


@pytest.fixture(scope='module')
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp('model_report')
    ident, _ = _zigzag_bag(d / 'zz_s', 'starboard', seed=1)
    val, sim = _zigzag_bag(d / 'zz_p', 'port', seed=2)
    model = str(d / 'model.json')
    assert main(['identify', '--bag', ident, '--coefficients', 'Y_v,N_r,N_dr,N_v',
                 '--json', model]) == 0
    return {'dir': d, 'ident': ident, 'val': val, 'model': model, 'sim': sim}


def test_report_model_on_an_unseen_zigzag(runs, capsys):
    out = runs['dir'] / 'rep'
    assert main(['report', '--model', runs['model'], '--vehicle', VEHICLE, '--validate',
                 runs['val'], '--out', str(out)]) == 0
    printed = capsys.readouterr().out
    assert 'closed-loop 20/10 zig-zag' in printed
    doc = json.loads((out / 'result.json').read_text())
    assert doc['identification_bags'] == [runs['ident']]
    assert doc['validation_bag'] == runs['val']
    assert set(doc['coefficients']) == {'Y_v', 'N_r', 'N_dr', 'N_v'}
    val = doc['validation']
    zz = val['zigzag']
    assert zz['detected'] and zz['test'] == '20/10' and zz['first'] == 'port'
    o = zz['overshoot_deg']
    assert set(o) >= {'measured', 'predicted', 'prior', 'predicted_ideal_helm'}
    assert len(o['measured']) >= 2 and len(o['predicted']) >= 2
    # the truth flew the measured run: the identified model's closed loop, through the gear
    # identified from the OTHER bag's rudder, gives its overshoots to the sensor noise
    assert abs(o['predicted'][0] - o['measured'][0]) < 0.5, o
    assert abs(o['predicted'][1] - o['measured'][1]) < 1.0, o
    g = zz['gear']
    assert g['identified_from'] == [runs['ident']]
    assert abs(g['delay_s'] - GEAR.delay) < 0.06 and abs(g['rate_deg_s'] - 15.0) < 0.5, g
    th = zz['thrust_model']
    assert th['fitted_on'] == [runs['ident']] and th['rms_N'] < 1.0
    # an ideal helm (no dead time) checks the turn earlier: a smaller first overshoot
    assert o['predicted_ideal_helm'][0] < o['predicted'][0]
    # the total speed is scored with the channels; the series are in validation.csv
    U = val['derived_channels']['U']
    assert U['fit_percent'] > 80.0
    with open(out / 'validation.csv', newline='') as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == CSV_HEADER
    a = np.array([[float(c) if c else np.nan for c in r] for r in rows[1:]])
    col = {name: a[:, i] for i, name in enumerate(rows[0])}
    assert fit_percent(col['r_measured'], col['r_predicted']) == pytest.approx(
        val['channels']['r']['fit_percent'], abs=1e-9)
    assert fit_percent(col['U_measured'], col['U_prior']) == pytest.approx(
        U['fit_percent_prior'], abs=1e-9)
    assert fit_percent(col['psi_measured'], col['psi_predicted']) == pytest.approx(
        val['channels']['psi']['fit_percent'], abs=1e-9)
    # the run has no rudder bias: the diagnosis finds none
    assert abs(val['rudder_bias_diagnosis']['bias_deg']) < 0.2, val['rudder_bias_diagnosis']
    md = (out / 'report.md').read_text()
    assert 'steering gear identified from the measured rudder' in md
    assert (out / 'report.html').is_file() and (out / 'zigzag.png').is_file()
    assert (out / 'free_run.png').is_file()


def test_refuses_the_identification_bag_and_foreign_models(runs, tmp_path, capsys):
    assert main(['report', '--model', runs['model'], '--validate', runs['ident'], '--out',
                 str(tmp_path / 'a')]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and "one of the model's identification bags" in err
    assert not (tmp_path / 'a').exists()
    assert main(['report', '--model', runs['model'], '--vehicle', 'nps_auv2', '--validate',
                 runs['val'], '--out', str(tmp_path / 'b')]) == 2
    assert "model of 'kvlcc2_hsva', not of --vehicle 'nps_auv2'" in capsys.readouterr().err
    bad = tmp_path / 'bad.json'
    bad.write_text(json.dumps({'vehicle': VEHICLE, 'coefficients': {'Y_v': {'std': 1.0}}}))
    assert main(['report', '--model', str(bad), '--validate', runs['val'], '--out',
                 str(tmp_path / 'c')]) == 2
    assert "coefficient 'Y_v' has no \"estimate\"" in capsys.readouterr().err
    assert main(['report', '--model', runs['model'], '--out', str(tmp_path / 'd')]) == 2
    assert 'needs --validate' in capsys.readouterr().err


def test_a_timed_rudder_sequence_is_not_a_zigzag(runs, tmp_path, capsys):
    """Our simulator's 'zigzag' reverses the rudder every 20 s, not at a heading: the report
    scores the free run and says why there is no closed-loop zig-zag."""
    bag = str(tmp_path / 'timed')
    assert main(['simulate', '--vehicle', VEHICLE, '--maneuver', 'zigzag', '--duration', '50',
                 '--seed', '3', '--out', bag]) == 0
    out = tmp_path / 'rep'
    assert main(['report', '--model', runs['model'], '--validate', bag, '--out', str(out)]) == 0
    doc = json.loads((out / 'result.json').read_text())
    zz = doc['validation']['zigzag']
    assert zz == {'detected': False, 'reason': zz['reason']} and 'not a zig-zag' in zz['reason']
    assert doc['validation']['channels']['r']['fit_percent'] > 80.0
    assert not (out / 'zigzag.png').exists()


def test_validation_reads_the_run_as_it_is_and_says_so_in_one_line(runs, tmp_path):
    """A validation run with wild yaw-rate samples (every 25th, 0.2 rad/s off: a gate judging
    them against the model drops them as outliers) and 3 malformed ones (u NaN): the wild
    samples are scored, not dropped, the malformed ones rejected, and the console says it in
    one line per bag read, with no per-sample lines (before: 'rejected odom: outlier ...',
    'filter reset: ...' from each bag's replay)."""
    def spoil(run):
        run.y[::25, State.R] += 0.2
        run.y[[100, 400, 700], State.U] = np.nan

    bag, _ = _zigzag_bag(tmp_path / 'wild', 'port', seed=4, spoil=spoil)
    out = tmp_path / 'rep'
    repo = Path(__file__).resolve().parents[2]
    env = dict(os.environ, PYTHONPATH=str(repo))
    done = subprocess.run([sys.executable, '-m', 'auv_ident', 'report', '--model',
                           runs['model'], '--validate', bag, '--out', str(out)],
                          capture_output=True, text=True, env=env, cwd=str(repo), timeout=600)
    assert done.returncode == 0, done.stderr
    console = (done.stdout + done.stderr).splitlines()
    # free-run fits, one screening line per bag (validation, gear and thrust), the zig-zag's
    # overshoots and reversal lags, the rudder diagnosis, the files
    assert len(console) == 7, console
    assert not any('outlier' in ln or 'filter reset' in ln for ln in console), console
    lines = [ln for ln in console if 'odometry messages' in ln]
    assert lines[0] == (f'{bag} (validation): 3 of 1231 odometry messages and 0 of 1231 '
                        'commands rejected (odom: non-finite 3)'), lines
    assert lines[1].startswith(f"{runs['ident']} (gear and thrust): 0 of ")
    doc = json.loads((out / 'result.json').read_text())
    val = doc['validation']
    assert val['samples'] == 1231 - 3 and val['zigzag']['detected']
    assert val['screening']['bags'][bag]['reasons'] == {'odom: non-finite': 3}
    # the wild samples are in the scored series
    with open(out / 'validation.csv', newline='') as fh:
        r = np.array([float(row['r_measured']) for row in csv.DictReader(fh)])
    assert np.sum(np.abs(np.diff(r)) > 0.15) >= 2 * 40


# --------------------------------------------------------------------- the real HSVA runs

GOALS = {'Z_20_10_P': (90.0, 90.0), 'Z_10_10_P': (75.0, 70.0)}    # issue #20: r / U fit %


@pytest.mark.slow
def test_kvlcc2_mirror_split_from_bags(tmp_path, capsys):
    """docs/kvlcc2.md 'A real ship from basin data': import the four HSVA runs, identify the
    two starboard ones to model.json, report --model on each port run. The goals of issue #20:
    free-run yaw rate and speed fit, and the closed-loop first / second overshoot within 1 / 3
    deg of the measured, far better than the captive-test prior (about 90 s)."""
    import sys
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from kvlcc2_data import require_runs, run_path, RUNS
    require_runs(RUNS)
    bags = {}
    for r in RUNS:
        bags[r] = str(tmp_path / r)
        assert main(['import', '--format', 'hsva', str(run_path(r)), '--out', bags[r]]) == 0
    model = str(tmp_path / 'model.json')
    # no hand-given noise: the noise model and the process noise come from the data
    # (analysis/bag_identify.py identify_bags)
    # the diagnosis calls this 3-DOF model of a real ship NOT consistent (model error the
    # residuals show; docs/kvlcc2.md): exit status 3, the model written all the same
    assert main(['identify', '--bag', bags['Z_10_10_S'], '--bag', bags['Z_20_10_S'],
                 '--vehicle', VEHICLE, '--json', model]) in (0, EXIT_UNTRUSTED)
    for r, (goal_r, goal_u) in GOALS.items():
        out = tmp_path / f'rep_{r}'
        assert main(['report', '--model', model, '--vehicle', VEHICLE, '--validate', bags[r],
                     '--out', str(out)]) == 0
        val = json.loads((out / 'result.json').read_text())['validation']
        fit_r, fit_u = val['channels']['r'], val['derived_channels']['U']
        assert fit_r['fit_percent'] >= goal_r and fit_u['fit_percent'] >= goal_u, (r, fit_r,
                                                                                  fit_u)
        assert fit_r['fit_percent'] > fit_r['fit_percent_prior'] + 15.0
        zz = val['zigzag']
        assert zz['detected'] and zz['first'] == 'port'
        o = zz['overshoot_deg']
        assert abs(o['predicted'][0] - o['measured'][0]) <= 1.0, (r, o)
        assert abs(o['predicted'][1] - o['measured'][1]) <= 3.0, (r, o)
        # the prior's first overshoot is further off (its second is 2.4x the measured, or
        # missing: the prior has not turned back by the end of the 10/10 run)
        assert (abs(o['prior'][0] - o['measured'][0])
                > abs(o['predicted'][0] - o['measured'][0]) + 1.0), (r, o)
        assert zz['gear']['identified_from'] == [bags['Z_10_10_S'], bags['Z_20_10_S']]
