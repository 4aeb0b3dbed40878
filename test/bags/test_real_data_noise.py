"""Real data, part 2: coloured noise of an unknown level, a wrong prior, and error bars that
tell the truth. Bags made by offline/independent_data.py (its own integrator, noise and writer)."""
import json
from pathlib import Path

import numpy as np
import pytest

from auv_ident.analysis.bag_identify import identify_bag
from auv_ident.core.identification.diagnosis import diagnose, XCORR_Z
from auv_ident.offline.independent_data import DataConfig, generate
from auv_ident.session.settings import IdentifierSettings

PAPER_SET = 'Z_ds,Z_q,Z_w,M_ds,K_v'


def _z_and_err(doc, truth_json, which='estimate', std='std'):
    truth = json.loads(Path(truth_json).read_text())['coefficients']
    z, err = [], []
    for name, c in doc['coefficients'].items():
        e = c[which] - truth[name]
        z.append(abs(e) / c[std])
        err.append(100.0 * abs(e) / abs(truth[name]))
    return np.array(z), np.array(err)


@pytest.mark.slow
def test_coloured_noise_of_unknown_level_gives_honest_error_bars(tmp_path):
    """AR(1) noise, correlation 0.1-3 s, 0.5-3x the documented level, not told: the refined
    result and the EKF pass are honest (truth within 3 sigma in >= 90 % of cases, median
    |error|/sigma >= 0.25), and the diagnosis names the noise."""
    zs, ze = [], []
    for seed, level, tau in ((1, 2.0, 1.0), (2, 3.0, 0.3), (3, 0.5, 3.0), (4, 1.5, 0.1)):
        cfg = DataConfig(seed=seed, odom_rate=20.0, noise='ar1', noise_level=level,
                         noise_tau=tau)
        data = generate(cfg, tmp_path / f's{seed}')
        doc, table = identify_bag(data.bag, IdentifierSettings.from_values(vehicle='nps_auv2',
                                                                           coefficients=PAPER_SET))
        assert 'noise_model' in doc and doc['diagnosis']['messages']
        z, _ = _z_and_err(doc, data.truth_json)
        zs.append(z)
        z, _ = _z_and_err(doc, data.truth_json, 'ekf_estimate', 'ekf_std')
        ze.append(z)
    for z in (np.concatenate(zs), np.concatenate(ze)):
        assert np.mean(z < 3.0) >= 0.9, z
        assert np.median(z) >= 0.25, z


@pytest.mark.slow
def test_a_wrong_prior_is_diagnosed_on_the_first_line(tmp_path):
    """Every other coefficient 0.8-1.2x the file's: the paper's five alone cannot be right,
    and the result says so first, naming the reason; white noise of the documented level with
    the right prior is consistent."""
    wrong = generate(DataConfig(seed=1, odom_rate=20.0, commands='periodic', perturb=0.2,
                                perturb_keep=tuple(PAPER_SET.split(','))), tmp_path / 'wrong')
    doc, table = identify_bag(wrong.bag, IdentifierSettings.from_values(vehicle='nps_auv2',
                                                                        coefficients=PAPER_SET))
    assert doc['diagnosis']['consistent'] is False
    assert table.splitlines()[0].startswith('NOT consistent: the model is inadequate')
    assert '--coefficients auto' in doc['diagnosis']['messages'][0]
    right = generate(DataConfig(seed=1, odom_rate=20.0, commands='periodic'), tmp_path / 'ok')
    doc, table = identify_bag(right.bag, IdentifierSettings.from_values(vehicle='nps_auv2',
                                                                        coefficients=PAPER_SET))
    assert doc['diagnosis']['consistent'] is True
    assert table.splitlines()[0].startswith('consistent')
    z, err = _z_and_err(doc, right.truth_json)
    # K_v (the last) is information-limited at 500 rpm: its 1-sigma is ~1.2 % (docs/method.md)
    assert np.all(err[:4] < 1.5) and np.all(z < 3.0), (err, z)


def test_diagnosis_rules():
    fine = diagnose(xcorr=[(2.0, 'u', 'delta_r', 3)], dt=0.05, mean_nis_per_dof=1.0)
    assert fine['consistent'] and fine['messages'][0].startswith('consistent')
    bad = diagnose(xcorr=[(-(XCORR_Z + 0.1), 'v', 'delta_r', 40)], dt=0.05)
    assert not bad['consistent']
    assert bad['messages'][0].startswith('NOT consistent: the model is inadequate: the v '
                                         'residuals follow delta_r')
    assert bad['checks']['residual_input_correlation']['lag_s'] == pytest.approx(2.0)


@pytest.mark.slow
@pytest.mark.parametrize('vehicle,seed,level,tau', [('remus100', 1, 2.0, 1.0),
                                                     ('isimi', 3, 2.0, 1.0)])
def test_the_other_vehicles_get_honest_bars_on_coloured_noise(tmp_path, vehicle, seed, level,
                                                               tau):
    """REMUS 100 and the ISIMI reconstruction, their default sets, 1500 rpm, fins within their
    +-13.6 deg: coloured noise of an unstated level gives honest bars, consistent."""
    cfg = DataConfig(vehicle=vehicle, seed=seed, odom_rate=20.0, rpm=1500.0, noise='ar1',
                     noise_level=level, noise_tau=tau, rudder_deg=13.0)
    data = generate(cfg, tmp_path / vehicle)
    doc, _ = identify_bag(data.bag, IdentifierSettings.from_values(vehicle=vehicle))
    assert doc['diagnosis']['consistent'] is True
    for which, std in (('estimate', 'std'), ('ekf_estimate', 'ekf_std')):
        z, err = _z_and_err(doc, data.truth_json, which, std)
        assert np.all(z < 3.0) and np.all(err < 3.0), (which, z, err)


def test_noise_far_above_the_configured_level_does_not_stop_the_identification(tmp_path):
    """3x the documented level, AR(1) 1 s, not told: the EKF with the configured noise leaves
    the model's domain 3.5 s in (an over-confident filter chases the noise into a negative
    surge speed); the noise model is read off a pass with more noise instead, and the result
    says so rather than ending in an error."""
    cfg = DataConfig(seed=1, duration=10.0, odom_rate=20.0, commands='periodic',
                     command_rate=20.0, noise='ar1', noise_level=3.0, noise_tau=1.0)
    data = generate(cfg, tmp_path / 'loud')
    doc, table = identify_bag(data.bag, IdentifierSettings.from_values(vehicle='nps_auv2',
                                                                       coefficients=PAPER_SET))
    notes = doc['noise_model']['notes']
    assert doc['noise_model']['used']
    assert notes[0].startswith('the EKF with the configured noise failed (EKF stopped at')
    assert 'a pass with 3x the configured noise' in notes[0]
    assert notes[0] in table
    assert all(np.isfinite(c['estimate']) and c['std'] > 0
               for c in doc['coefficients'].values())
