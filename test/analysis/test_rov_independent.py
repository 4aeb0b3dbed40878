"""A BlueROV2 Heavy identified from the independent generator's bags (#29), end to end through
the commands a user types: offline/independent_rov.py (its own model, scipy RK45, AR(1) noise
of undisclosed level, ENU odometry, PWM commands on change, covariance fields wrong on purpose)
with its thrust curve the vehicle file's perturbed +10 % (`--curve file`) or its own copy of the
T200 table +10 % (`--curve table`, the default), identified with
`identify --bag --input-map bluerov2_heavy --noise-source parameter` and validated on another
seed with `report --model --validate --input-map`."""
import json

import pytest

from auv_ident.cli import main as cli_main
from auv_ident.offline.independent_rov import main as generate


def _bag(tmp_path, seed, duration, curve='file'):
    out = tmp_path / f'rov{seed}{curve}'
    assert generate(['--out', str(out), '--seed', str(seed), '--duration', str(duration),
                     '--curve', curve]) == 0
    return out / 'bag', json.loads((out / 'truth.json').read_text())['coefficients']


def _fits(report_dir):
    """channel -> fit % of the identified model: the report's first table (the fit table)."""
    rows = {}
    for line in (report_dir / 'report.md').read_text().splitlines():
        if line.startswith('| ') and line.count('|') > 3:
            rows.setdefault(line.split('|')[1].strip(), line.split('|')[2].strip())
    return rows


def test_report_model_validates_a_thruster_bag_through_its_input_map(tmp_path, capsys):
    """The model file records the input map its bags were read through, and export reads them
    with it for its fit envelope; --input-map reaches report --model's validation bag (both
    named the default map before: exit 2); a vehicle without a rudder gets no rudder-bias
    diagnosis (it reported its search bound)."""
    ident, _ = _bag(tmp_path, 3, 40.0)
    held, _ = _bag(tmp_path, 4, 30.0)
    model = tmp_path / 'm.json'
    cli_main(['identify', '--vehicle', 'bluerov2_heavy', '--bag', str(ident), '--input-map',
              'bluerov2_heavy', '--noise-source', 'parameter', '--coefficients',
              'thrust_gain_fwd,X_uu,N_rr', '--json', str(model)])
    assert json.loads(model.read_text())['input_map'] == 'bluerov2_heavy'
    # export fits its damping over the bags the model records, through the recorded map
    assert cli_main(['export', str(model), '--vehicle', 'bluerov2_heavy', '--format', 'uuv',
                     '--out', str(tmp_path / 'rov.xacro')]) in (0, None)
    assert "identification's bags" in capsys.readouterr().out
    out = tmp_path / 'report'
    assert cli_main(['report', '--vehicle', 'bluerov2_heavy', '--model', str(model),
                     '--validate', str(held), '--input-map', 'bluerov2_heavy',
                     '--out', str(out)]) in (0, None)
    text = (out / 'report.md').read_text()
    assert '| u |' in text and '| r |' in text
    assert 'rudder bias' not in text


@pytest.mark.slow
def test_independent_tank_session_within_5_percent_and_validated(tmp_path, capsys):
    """The issue's done-when on the independent generator: a consistent verdict (exit 0), the
    file's set within 5 % and the truth within 3 sigma; a run it never saw (another seed)
    predicted with fit >= 90 % in u, v, w, r."""
    ident, truth = _bag(tmp_path, 1, 600.0)
    held, _ = _bag(tmp_path, 2, 600.0)
    model = tmp_path / 'm.json'
    # the verdict: consistent, exit 0 (it was NOT consistent on a lag-1 correlation of 1.13 the
    # unbounded estimator read off the gappy u innovations, and on the position drift)
    assert cli_main(['identify', '--vehicle', 'bluerov2_heavy', '--bag', str(ident),
                     '--input-map', 'bluerov2_heavy', '--noise-source', 'parameter',
                     '--json', str(model)]) == 0
    doc = json.loads(model.read_text())
    assert doc['diagnosis']['consistent'] is True, doc['diagnosis']['messages']
    coefficients = doc['coefficients']
    assert len(coefficients) == 12
    for name, c in coefficients.items():
        t = truth[name]
        assert abs(c['estimate'] - t) <= 0.05 * abs(t), (name, c['estimate'], t)
        assert abs(c['estimate'] - t) <= 3 * c['std'], (name, c['estimate'], t, c['std'])
    out = tmp_path / 'report'
    cli_main(['report', '--vehicle', 'bluerov2_heavy', '--model', str(model), '--validate',
              str(held), '--input-map', 'bluerov2_heavy', '--out', str(out)])
    rows = _fits(out)
    for ch in ('u', 'v', 'w', 'r'):
        assert float(rows[ch]) >= 90.0, (ch, rows[ch])


@pytest.mark.slow
def test_table_truth_is_plausible_within_3_sigma_and_flies_as_the_truth(tmp_path):
    """The generator's default truth, its own linear interpolation of the T200 table +10 %,
    which the file's polynomial could not follow (exit 3, NOT plausible, gains 0.72 and 0.67
    against 1.1): with the table in the file the verdict is plausible, every coefficient's
    truth within 3 sigma and the gains within 2 %, and the held-out run (seed 4) is
    predicted as the true model predicts it. Not asserted: the issue's 5 % (X_u comes back
    +6.9 % at 1.4 sigma on seed 3, docs/vehicles.md) and the fit >= 90 % (seed 4's noise puts
    even the true model at 81, 70, 88 % in u, v, w); nor the consistency verdict, whose
    lag-1 estimator gives correlations above 1 here."""
    ident, truth = _bag(tmp_path, 3, 600.0, 'table')
    held, _ = _bag(tmp_path, 4, 600.0, 'table')
    model = tmp_path / 'm.json'
    cli_main(['identify', '--vehicle', 'bluerov2_heavy', '--bag', str(ident), '--input-map',
              'bluerov2_heavy', '--noise-source', 'parameter', '--json', str(model)])
    doc = json.loads(model.read_text())
    assert doc['diagnosis']['plausible'], doc['diagnosis']
    for name, c in doc['coefficients'].items():
        t = truth[name]
        assert abs(c['estimate'] - t) <= 3 * c['std'], (name, c['estimate'], t, c['std'])
    for gain in ('thrust_gain_fwd', 'thrust_gain_rev'):
        assert abs(doc['coefficients'][gain]['estimate'] / truth[gain] - 1) <= 0.02
    # the true model in the same model file: the ceiling the noise of seed 4 sets
    for name, c in doc['coefficients'].items():
        c['estimate'] = truth[name]
    true_model = tmp_path / 'truth.json'
    true_model.write_text(json.dumps(doc))
    fits = {}
    for name, path in (('identified', model), ('truth', true_model)):
        out = tmp_path / f'report_{name}'
        cli_main(['report', '--vehicle', 'bluerov2_heavy', '--model', str(path), '--validate',
                  str(held), '--input-map', 'bluerov2_heavy', '--out', str(out)])
        fits[name] = _fits(out)
    for ch in ('u', 'v', 'w', 'r'):
        assert float(fits['identified'][ch]) >= float(fits['truth'][ch]) - 1.0, (ch, fits)


@pytest.mark.slow
def test_independent_tank_session_with_a_motor_lag_identifies_its_time_constant(tmp_path):
    """The independent generator with a 0.15 s motor lag (`--motor-lag 0.15`: the lag as states
    of its own ODE, scipy RK45) and the file's curve +10 %: the file with a `thruster_lag`
    coefficient of 0.2 s (the start 50 % above it, 0.3 s, twice the truth) identified with the
    time constant: consistent, every coefficient within 5 % and 3 sigma of the truth."""
    import yaml

    from auv_ident.core.vehicle_files import read_yaml_file
    from auv_ident.vehicles import resolve_vehicle_path
    out = tmp_path / 'lag'
    assert generate(['--out', str(out), '--seed', '1', '--duration', '600', '--curve', 'file',
                     '--motor-lag', '0.15']) == 0
    truth = json.loads((out / 'truth.json').read_text())['coefficients']
    raw = read_yaml_file(resolve_vehicle_path('bluerov2_heavy'))
    raw['coefficients']['thrust_time_constant'] = [0.2, 'XYZKMN', 0, 'thruster_lag']
    vehicle = tmp_path / 'rov_lag.yaml'
    vehicle.write_text(yaml.safe_dump(raw))
    names = raw['identify_default'] + ['thrust_time_constant']
    model = tmp_path / 'm.json'
    assert cli_main(['identify', '--vehicle', str(vehicle), '--bag', str(out / 'bag'),
                     '--input-map', 'bluerov2_heavy', '--noise-source', 'parameter',
                     '--coefficients', ','.join(names), '--json', str(model)]) == 0
    doc = json.loads(model.read_text())
    assert doc['diagnosis']['consistent'] is True, doc['diagnosis']['messages']
    for name, c in doc['coefficients'].items():
        t = truth[name]
        assert abs(c['estimate'] - t) <= 0.05 * abs(t), (name, c['estimate'], t)
        assert abs(c['estimate'] - t) <= 3 * c['std'], (name, c['estimate'], t, c['std'])


@pytest.mark.slow
def test_an_unmodelled_motor_lag_under_loud_coloured_noise_is_not_called_consistent(tmp_path):
    """The confidently wrong case of tools/rov_trust_grid.py (cell 10_0.1_0.3_file_std10):
    a 0.3 s motor lag the shipped file does not model, AR(1) noise at 10x the generator's
    level (5-20 x its base, correlation 2-5 s), identified with the noise_std raised 10x (the
    configured pass diverges otherwise, exit 2). Before the cross-correlation with the
    commands' changes the first line said consistent (exit 0) with X_u +1.05 against -13.7 at
    5.4 sigma: the residuals' cross-correlation with the held PWM levels was 4.3 sd (limit
    4.5), with their changes it is 10.6 sd at a lag of 0.3 s, the motor lag."""
    from auv_ident.core.model.sensors import DEFAULT_NOISE_STD
    out = tmp_path / 'lag_loud'
    assert generate(['--out', str(out), '--seed', '3', '--duration', '600', '--curve', 'file',
                     '--motor-lag', '0.3', '--noise-level', '5,20', '--noise-tau', '2,5']) == 0
    model = tmp_path / 'm.json'
    assert cli_main(['identify', '--vehicle', 'bluerov2_heavy', '--bag', str(out / 'bag'),
                     '--input-map', 'bluerov2_heavy', '--noise-source', 'parameter',
                     '--noise-std', ','.join(f'{10 * v:g}' for v in DEFAULT_NOISE_STD),
                     '--json', str(model)]) == 3
    doc = json.loads(model.read_text())
    assert doc['diagnosis']['consistent'] is False
    check = doc['diagnosis']['checks']['residual_input_correlation']
    assert check['input'].startswith('the changes of t') and abs(check['z']) > 4.5, check
