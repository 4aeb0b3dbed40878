"""The noise model read off the data (core/identification/noise_fit.py) on records that carry
no innovation information (#27 item 6: 'ValueError: math domain error' when a level is 0)."""
import numpy as np

from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.identification.noise_fit import fit_noise
from auv_ident.core.identification.results import Record
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.simulation.simulate import simulate
from auv_ident.vehicles import load_vehicle


def test_a_record_of_restarts_only_keeps_the_configured_noise():
    """Every sample 0.5 s after the last (> max_bridge 0.25 s): each restarts the vehicle
    states from its measurement, so every innovation is 0 by construction. That is no noise
    level (the level 0 made log(0) raise); the configured noise stands and no channel has a
    model."""
    v = load_vehicle('nps_auv2')
    model = Model(v, v.identify_default)
    run = simulate(Model(v), 'ident', duration=30.0, T=0.05, seed=3)
    keep = slice(None, None, 10)
    rec = Record(run.t[keep], run.y[keep], run.u[keep])
    cfg = FilterConfig(coefficients=list(v.identify_default),
                       noise_std=np.asarray(run.noise_std, float), mode='fixed')
    fit = fit_noise(model, cfg, [rec], T=0.05)
    assert fit.model == {}
    np.testing.assert_array_equal(fit.effective_std, fit.configured_std)
    assert np.all(fit.effective_std > 0)
