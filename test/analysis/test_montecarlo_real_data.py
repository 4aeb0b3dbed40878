"""montecarlo on data that contradict the filter's assumptions (issue #14): coloured noise of
another level and a truth vehicle whose other coefficients differ from the file's, neither
told to the identifier."""
import numpy as np

from auv_ident.analysis.experiments import identify_simulated, montecarlo
from auv_ident.analysis.results import make_config

FIVE = ['Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v']


def test_coloured_noise_is_found_and_the_bars_cover_it():
    st = montecarlo('nps_auv2', FIVE, seeds=2, offsets=(0.5,), duration=120.0, jobs=1,
                    noise_level=2.0, noise_tau=1.0)
    assert st['noise_level'] == 2.0 and st['noise_tau_s'] == 1.0 and st['diverged'] == 0
    assert all(r['noise_model_used'] for r in st['runs'])
    assert st['within_3sigma_all'] >= 0.9 and st['median_abs_z'] >= 0.25


def test_a_perturbed_truth_is_flagged_by_the_diagnosis():
    cfg = make_config(FIVE)
    """600 s: shorter runs do not always carry enough evidence (300 s, seed 1: the residual-
    input cross-correlation reached 4.5 sd, just at its limit)."""
    perturbed = identify_simulated('nps_auv2', FIVE, cfg, duration=600.0, seed=1,
                                   perturb=0.2)
    file = identify_simulated('nps_auv2', FIVE, cfg, duration=600.0, seed=1)
    res, exact = perturbed.result, file.result
    assert np.array_equal(res.truth, exact.truth)       # the identified ones are kept
    assert not np.allclose(perturbed.run.x, file.run.x)   # but the vehicle flies differently
    assert exact.diagnosis.consistent
    assert not res.diagnosis.consistent
    assert 'inadequate' in res.diagnosis.messages[0]
