"""Short simulated runs shared by the tests of the identification methods (UKF, output error,
equation error): NPS AUV II, the paper's `ident` manoeuvre at 500 rpm, the paper's five
coefficients; "noise-light" = a fifth of the documented sensor noise (core/model/sensors.py)."""
from functools import lru_cache

import numpy as np

from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.sensors import DEFAULT_NOISE_STD
from auv_ident.core.simulation.simulate import simulate
from auv_ident.vehicles import load_vehicle

PAPER_FIVE = ['Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v']
LIGHT_NOISE_STD = 0.2 * DEFAULT_NOISE_STD


@lru_cache(maxsize=None)
def light_run(duration=90.0, seed=3):
    """(model with PAPER_FIVE, run): a noise-light simulated run of `duration` s."""
    v = load_vehicle('nps_auv2')
    run = simulate(Model(v), 'ident', duration=duration, seed=seed,
                   noise_std=LIGHT_NOISE_STD.copy())
    return Model(v, PAPER_FIVE), run


def relative_error(estimate, truth):
    return np.abs((np.asarray(estimate) - truth) / truth)
