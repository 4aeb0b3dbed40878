"""Added-mass coefficients identified end to end (simulate, EKF pass, batch refinement).

Identifying an added-mass coefficient changes the mass matrix M, so the model needs the exact
inverse of M (mass_inverse='exact'; NPS AUV II's file chooses MSS's fixed literal inverse,
which cannot follow M). The added-mass coefficients are those whose multiplier is an
acceleration (names ending in 'dot', config/nps_auv2.yaml).
"""
import json
import subprocess
import sys

from helpers import REPO
import numpy as np

from auv_ident.analysis.experiments import identify_simulated
from auv_ident.analysis.results import make_config
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.vehicles import load_vehicle

ADDED_MASS = ['Z_wdot', 'M_qdot']
MAX_ERROR_PCT = 3.0
MAX_SIGMAS = 3.0


def test_added_mass_with_pitch_damping_through_the_api():
    """Z_wdot and M_qdot together with the pitch-plane damping and fin terms, from +50 %."""
    names = ADDED_MASS + ['Z_w', 'Z_q', 'M_ds']
    v = load_vehicle('nps_auv2')
    # added mass: diagonal entries of M (Z_wdot: row/column w, M_qdot: q); Z_w is not
    assert [(v.coefficients[v.index(n)].equation, v.coefficients[v.index(n)].added_mass_col)
            for n in ADDED_MASS + ['Z_w']] == [(2, 2), (4, 4), (2, -1)]
    cfg = make_config(names, initial_offset=0.5)
    sim = identify_simulated('nps_auv2', names, cfg, maneuver='ident', seed=0, duration=300.0,
                             mass_inverse='exact')
    res = sim.result
    assert res.model.mass_inverse == 'exact' and sim.run.t[-1] == 300.0
    truth = Model(v, names, mass_inverse='exact').theta_true
    assert np.array_equal(res.truth, truth)                       # the vehicle file values
    assert np.allclose(res.initial, 1.5 * truth)                  # started 50 % off
    err = res.error_pct()
    z = (res.estimate - truth) / res.std
    assert np.all(np.abs(err) < MAX_ERROR_PCT), dict(zip(names, err))
    assert np.all(np.abs(z) < MAX_SIGMAS), dict(zip(names, z))
    assert np.all(np.abs(res.error_pct('ekf_estimate')) < MAX_ERROR_PCT)


def _identify_cli(tmp_path, *extra):
    return subprocess.run(
        [sys.executable, '-m', 'auv_ident', 'identify', '--vehicle', 'nps_auv2', '--simulate',
         'ident', '--duration', '200', '--seed', '1', '--coefficients', ','.join(ADDED_MASS),
         '--json', str(tmp_path / 'result.json'), *extra],
        cwd=REPO, capture_output=True, text=True, timeout=300)


def test_identify_cli_recovers_added_mass_with_the_exact_inverse(tmp_path):
    r = _identify_cli(tmp_path, '--mass-inverse', 'exact')
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / 'result.json').read_text())
    assert list(doc['coefficients']) == ADDED_MASS
    file_values = {'Z_wdot': -0.24, 'M_qdot': -0.017}             # config/nps_auv2.yaml
    for name, c in doc['coefficients'].items():
        assert c['truth'] == file_values[name]
        assert c['initial'] == 1.5 * c['truth']
        assert abs(c['error_pct']) < MAX_ERROR_PCT, (name, c)
        assert abs(c['estimate'] - c['truth']) < MAX_SIGMAS * c['std'], (name, c)


def test_identify_cli_refuses_added_mass_with_the_literal_inverse(tmp_path):
    r = _identify_cli(tmp_path)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert '--mass-inverse exact' in lines[0] and 'Traceback' not in r.stderr
    assert not (tmp_path / 'result.json').exists()
