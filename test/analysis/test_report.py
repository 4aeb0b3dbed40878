"""Tier 1: the report (figures, report.md, result.json) and the held-out validation."""
import json
import os

import matplotlib.image
import numpy as np
import pytest
import yaml

from auv_ident.analysis.experiments import load_source
from auv_ident.analysis.report import make_report, validate
from auv_ident.analysis.results import coefficient_list
from auv_ident.cli import main
from auv_ident.core.errors import ConfigError
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import STATE_NAMES
from auv_ident.core.simulation import maneuvers
from auv_ident.offline.independent_data import DataConfig, generate
from auv_ident.session.settings import IdentifierSettings
from auv_ident.vehicles import load_vehicle

FIGURES = ('convergence', 'measured_speeds', 'measured_pose', 'validation_positions',
           'validation_attitudes', 'validation_speeds', 'nis', 'adapted_noise',
           'innovation_autocorrelation')
TRUE_MODEL_FIGURES = ('validation_positions', 'validation_attitudes', 'validation_speeds')
PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'
SEED = 3


@pytest.fixture(scope='module')
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp('report')
    r = make_report(str(out), IdentifierSettings.from_values(vehicle='nps_auv2'),
                    simulate_maneuver='ident', seed=SEED, duration=60.0, validation_duration=40.0,
                    command='pytest', progress=False)
    with open(r['json'], encoding='utf-8') as fh:
        doc = json.load(fh)
    with open(r['report'], encoding='utf-8') as fh:
        md = fh.read()
    return r, doc, md


@pytest.fixture(scope='module')
def nps():
    v = load_vehicle('nps_auv2')
    names = coefficient_list(v, '')
    return v, names, Model(v, names).theta_true


def test_every_figure_is_a_readable_png_linked_from_the_report(report):
    r, _, md = report
    assert set(r['figures']) == set(FIGURES)
    for name in FIGURES:
        path = r['figures'][name]
        assert os.path.basename(path) == name + '.png'
        with open(path, 'rb') as fh:
            assert fh.read(8) == PNG_SIGNATURE
        assert os.path.getsize(path) > 20_000          # not an empty canvas
        img = matplotlib.image.imread(path)
        assert img.ndim == 3 and img.shape[0] >= 300 and img.shape[1] >= 600
        assert img.std() > 0.01                        # something is drawn
        assert f']({name}.png)' in md                  # embedded with a relative link


def _rows(md, first_header):
    """Cells of the Markdown table whose header row starts with first_header."""
    lines = md.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith(f'| {first_header} |'))
    header = [c.strip() for c in lines[start].strip('|').split('|')]
    rows = {}
    for ln in lines[start + 2:]:
        if not ln.startswith('|'):
            break
        cells = [c.strip() for c in ln.strip('|').split('|')]
        rows[cells[0]] = dict(zip(header, cells))
    return rows


def _same(cell, value):
    if value is None:
        return cell == '-'
    if isinstance(value, str):
        return cell == value
    return float(cell) == float(f'{value:.6g}')    # the table prints 6 significant digits


def test_report_tables_hold_the_result_json_numbers(report):
    r, doc, md = report
    assert doc == json.loads(json.dumps(r['result']))     # the file is the returned document
    co = doc['coefficients']
    main = _rows(md, 'coefficient')
    assert list(main) == list(co) == coefficient_list(load_vehicle('nps_auv2'), '')
    cols = {'truth': 'truth', 'estimate': 'estimate', '1-sigma': 'std', 'error %': 'error_pct',
            'paper estimate': 'paper_estimate', 'paper error %': 'paper_error_pct'}
    ekf_cols = {'initial': 'initial', 'EKF estimate': 'ekf_estimate', 'EKF 1-sigma': 'ekf_std',
                'EKF error %': 'ekf_error_pct', 'refined estimate': 'estimate',
                'refined error %': 'error_pct'}
    ekf = _rows(md[md.index('### EKF pass alone'):], 'coefficient')
    for n, c in co.items():
        for col, key in cols.items():
            assert _same(main[n][col], c[key]), (n, col, main[n][col], c[key])
        for col, key in ekf_cols.items():
            assert _same(ekf[n][col], c[key]), (n, col, ekf[n][col], c[key])
        assert c['truth'] is not None and abs(c['error_pct']) < 20
    rms = _rows(md[md.index('## Validation on a held-out manoeuvre'):], 'channel')
    assert list(rms) == list(STATE_NAMES)
    vd = doc['validation_true_model']
    for ch in STATE_NAMES:
        assert _same(rms[ch]['RMS difference'], vd['rms'][ch])
        assert rms[ch]['unit'] == vd['rms_units'][ch]
    assert f'{doc["mean_nis_per_dof"]:.3f}' in md and '`pytest`' in md


def test_the_diagnosis_comes_first_and_the_noise_model_is_reported(report):
    _, doc, md = report
    d = doc['diagnosis']
    lines = md.splitlines()
    assert lines[2] == f'**{d["messages"][0]}**'       # right under the title
    assert d['consistent'] is True                      # white noise at the configured level
    nm = _rows(md, 'measured channel')
    assert list(nm) == list(STATE_NAMES)
    for ch, row in nm.items():
        c = doc['noise_model']['channels'][ch]
        assert _same(row['level'], c['level']) and _same(row['AR(1)'], c['ar1'])
        assert 0.8 < c['level'] < 1.2 and len(c['acf']) == 21 and c['acf'][0] == 1.0
    ident = _rows(md, 'parameter')
    assert set(ident) == set(doc['identifiability'])
    for n, row in ident.items():
        assert row['verdict'] == doc['identifiability'][n]['verdict']


def test_validation_uses_a_held_out_manoeuvre_and_its_own_seed(report):
    _, doc, md = report
    vd = doc['validation_true_model']
    assert doc['maneuver'] == 'ident' and vd['maneuver'] == 'steps'
    assert vd['seed'] == SEED + 1000 and f'seed {SEED + 1000}' in md
    src = load_source(IdentifierSettings(), 'ident', seed=SEED, duration=40.0)
    held_out = maneuvers.commands('steps', src.t, rpm=src.U[0, 5], seed=SEED + 1000)
    assert not np.allclose(held_out[:, :5], src.U[:, :5])


def test_true_coefficients_reproduce_the_truth_exactly(nps):
    v, names, truth = nps
    val = validate(v, names, truth, maneuver='steps', duration=40.0, seed=1001)
    t, X_true, X_ident, rms = val
    assert val.maneuver == 'steps' and val.seed == 1001 and len(t) == len(X_true) == 801
    assert np.array_equal(X_true, X_ident)
    assert rms == dict.fromkeys(STATE_NAMES, 0.0)
    # the manoeuvre moves the vehicle: a zero RMS is not from a vehicle at rest
    assert np.ptp(X_true[:, 11]) > 0.1 and np.ptp(X_true[:, 8]) > 0.1


def test_perturbed_coefficients_give_a_positive_rms_on_every_channel(nps):
    v, names, truth = nps
    _, X_true, X_ident, rms = validate(v, names, 1.2 * truth, maneuver='steps', duration=40.0,
                                       seed=1001)
    assert np.array_equal(X_true[0], X_ident[0])      # same start: the trim of the true model
    assert all(rms[n] > 0 for n in STATE_NAMES), rms
    assert rms['w'] > 1e-4 and rms['theta'] > 1e-3     # m/s, deg: visibly different


def test_validating_on_the_identification_manoeuvre_is_refused(nps, tmp_path):
    v, names, truth = nps
    with pytest.raises(ConfigError, match='held-out'):
        validate(v, names, truth, maneuver='ident', identification_maneuver='ident')
    with pytest.raises(ValueError, match='held-out'):     # before the identification runs
        make_report(str(tmp_path), IdentifierSettings.from_values(vehicle='nps_auv2'),
                    simulate_maneuver='zigzag', duration=10.0, validation_maneuver='zigzag',
                    progress=False)
    assert not os.listdir(tmp_path)


def test_unknown_truth_validates_on_held_out_measurements_against_the_prior(tmp_path):
    """A bag whose metadata claims no simulated truth (the independent generator's: wall-clock
    stamps, no auv_ident custom_data) goes through the real bag path (bag_source: replay, exact
    hold), is identified on its first 75 % and validated on the measurements of the final 25 %,
    the identified model against the vehicle file's prior; no true-model validation."""
    data = generate(DataConfig(seed=5, duration=40.0, odom_rate=20.0), tmp_path / 'gen')
    meta = yaml.safe_load((data.bag / 'metadata.yaml').read_text())
    assert not meta['rosbag2_bagfile_information'].get('custom_data')
    r = make_report(str(tmp_path / 'report'), bag=str(data.bag), progress=False)
    doc = r['result']
    n = len(data.odom_stamp_ns)
    # every sample is used (but the first, when its command arrived after it)
    assert any(doc['source'].startswith(f'first 75 % of bag {data.bag} ({k} samples)')
               for k in (n - 1, n))
    assert doc['seed'] is None and doc['validation_true_model'] is None
    assert all(c['truth'] is None and c['error_pct'] is None
               for c in doc['coefficients'].values())
    vd = doc['validation']
    assert vd['models'] == ['identified', 'prior'] and vd['holdout_fraction'] == 0.25
    assert vd['source'].startswith('final 25 % (held out) of bag')
    # identification stopped where validation starts: 30 s of the 40
    assert doc['duration_s'] < 30.0 <= vd['t0_s'] and vd['duration_s'] > 9.0
    assert abs(vd['samples'] - n / 4) <= 2
    assert set(vd['channels']) == set(STATE_NAMES)
    # the bag's truth is the file: prior and identified model both follow the measurements
    assert vd['mean_fit_percent_nu']['prior'] > 30 and vd['mean_fit_percent_nu']['identified'] > 30
    assert set(r['figures']) == set(FIGURES) - set(TRUE_MODEL_FIGURES)
    truth = json.loads(data.truth_json.read_text())['coefficients']
    for name, c in doc['coefficients'].items():
        assert abs(c['estimate'] - truth[name]) < 0.2 * abs(truth[name]), (name, c, truth[name])
    with open(r['report'], encoding='utf-8') as fh:
        md = fh.read()
    assert '## Validation against measurements' in md and 'against the true model' not in md
    assert all(row['truth'] == '-' for row in _rows(md, 'coefficient').values())


def test_report_with_methods_side_by_side(tmp_path):
    """--methods: the standard methods on the same data and held-out run, in result.json and a
    report section before the figures."""
    r = make_report(str(tmp_path), IdentifierSettings.from_values(vehicle='nps_auv2'),
                    simulate_maneuver='ident', seed=SEED, duration=60.0, validation_duration=20.0,
                    progress=False, methods=['ekf', 'equation_error'])
    doc = r['result']
    assert list(doc['methods']) == ['ekf', 'equation_error']
    for m in doc['methods'].values():
        assert set(m['coefficients']) == set(doc['coefficients'])
        assert m['wall_s'] >= 0 and m['fit_percent']
    md = open(r['report'], encoding='utf-8').read()
    assert md.index('## Methods side by side') < md.index('## Figures')
    assert '| ekf |' in md and '| equation_error |' in md


def test_report_chooses_the_coefficients_from_a_bag_and_validates_the_chosen_set(tmp_path,
                                                                                  capsys):
    """`report --bag A --coefficients auto,NAME --validate B`: the set is chosen from A
    (core/identification/selection.py), identified, and the chosen set (not only NAME) flies in the
    validation
    on B; result.json has `selection`, report.md its section."""
    truth = generate(DataConfig(seed=7, duration=60.0, odom_rate=20.0, commands='periodic',
                                perturb=0.2), tmp_path / 'A')
    generate(DataConfig(vehicle=truth.truth_vehicle, seed=107, duration=30.0, odom_rate=20.0,
                        commands='periodic'), tmp_path / 'B')
    rc = main(['report', '--bag', str(tmp_path / 'A' / 'bag'), '--vehicle', 'nps_auv2',
               '--coefficients', 'auto,K_v', '--validate', str(tmp_path / 'B' / 'bag'),
               '--out', str(tmp_path / 'report')])
    assert rc == 0
    doc = json.loads((tmp_path / 'report' / 'result.json').read_text())
    # the first line printed is the verdict, as report.md's and identify's
    assert capsys.readouterr().out.splitlines()[0] == doc['diagnosis']['messages'][0]
    sel = doc['selection']
    assert sel['named'] == ['K_v'] and sel['chosen'][0] == 'K_v' and len(sel['chosen']) > 1
    assert list(doc['coefficients']) == sel['chosen']
    assert set(sel['chosen']) | set(sel['left_out']) == set(load_vehicle('nps_auv2').names)
    vd = doc['validation']
    assert vd['models'] == ['identified', 'prior'] and vd['holdout_fraction'] is None
    assert vd['source'].startswith(f'bag {tmp_path / "B" / "bag"}')
    # the identified model is the file with the chosen set's estimates: it flies differently
    # from the prior on B
    ch = vd['channels']
    assert any(abs(d['fit_percent'] - d['fit_percent_prior']) > 0.1 for d in ch.values())
    md = (tmp_path / 'report' / 'report.md').read_text()
    assert '## Automatic selection' in md and ', '.join(sel['chosen']) in md
    # the EKF histories are the chosen set's (the convergence figure)
    assert (tmp_path / 'report' / 'convergence.png').is_file()


def test_report_auto_needs_a_recorded_run(tmp_path, capsys):
    rc = main(['report', '--simulate', 'ident', '--duration', '10', '--coefficients', 'auto',
               '--out', str(tmp_path)])
    assert rc == 2 and 'report --bag' in capsys.readouterr().err


def test_report_mass_inverse_applies_to_every_model(tmp_path):
    """report --mass-inverse exact: an added-mass coefficient is identified, and the models
    flown in the validation form M^-1 the same way (result.json and report.md say it)."""
    data = generate(DataConfig(seed=5, duration=40.0, odom_rate=20.0), tmp_path / 'gen')
    r = make_report(str(tmp_path / 'report'), IdentifierSettings.from_values(
        coefficients='Z_w,Z_wdot', mass_inverse='exact'), bag=str(data.bag), progress=False)
    doc = r['result']
    assert doc['mass_inverse'] == 'exact' and list(doc['coefficients']) == ['Z_w', 'Z_wdot']
    assert doc['validation']['mean_fit_percent_nu']['identified'] > 30
    assert '- mass inverse: exact (every model of this report)' in open(
        r['report'], encoding='utf-8').read()
    with pytest.raises(ConfigError, match='mass-inverse exact'):
        make_report(str(tmp_path / 'literal'),
                    IdentifierSettings.from_values(coefficients='Z_w,Z_wdot'), bag=str(data.bag),
                    progress=False)
