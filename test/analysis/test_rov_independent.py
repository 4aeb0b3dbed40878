"""A BlueROV2 Heavy identified from the independent generator's bags (#29), end to end through
the commands a user types: offline/independent_rov.py (its own model, scipy RK45, AR(1) noise
of undisclosed level, ENU odometry, PWM commands on change, covariance fields wrong on purpose)
with its thrust curve the vehicle file's perturbed +10 % (`--curve file`), identified with
`identify --bag --input-map bluerov2_heavy --noise-source parameter` and validated on another
seed with `report --model --validate --input-map`."""
import json

import pytest

from auv_ident.cli import main as cli_main
from auv_ident.offline.independent_rov import main as generate


def _bag(tmp_path, seed, duration):
    out = tmp_path / f'rov{seed}'
    assert generate(['--out', str(out), '--seed', str(seed), '--duration', str(duration),
                     '--curve', 'file']) == 0
    return out / 'bag', json.loads((out / 'truth.json').read_text())['coefficients']


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
    rows = {}               # channel -> fit % identified: the first table (the fit table)
    for line in (out / 'report.md').read_text().splitlines():
        if line.startswith('| ') and line.count('|') > 3:
            rows.setdefault(line.split('|')[1].strip(), line.split('|')[2].strip())
    for ch in ('u', 'v', 'w', 'r'):
        assert float(rows[ch]) >= 90.0, (ch, rows[ch])
