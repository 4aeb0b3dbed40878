"""core.model.sensors: the coloured-noise generator and the perturbed truth vehicle."""
import numpy as np

from auv_ident.core.model.sensors import ar1_noise, perturbed_values
from auv_ident.vehicles import load_vehicle


def test_ar1_noise_has_its_level_and_correlation():
    e = ar1_noise(np.random.default_rng(0), 200_000, [2.0, 0.5], tau=1.0, T=0.05)
    assert np.allclose(e.std(axis=0), [2.0, 0.5], rtol=0.05)
    lag1 = [np.corrcoef(e[:-1, j], e[1:, j])[0, 1] for j in range(2)]
    assert np.allclose(lag1, np.exp(-0.05), atol=0.01)
    white = ar1_noise(np.random.default_rng(0), 50_000, [1.0], tau=0.0, T=0.05)
    assert abs(np.corrcoef(white[:-1, 0], white[1:, 0])[0, 1]) < 0.02


def test_perturbed_values_keep_the_named_and_the_added_mass():
    v = load_vehicle('nps_auv2')
    vals = perturbed_values(v, 0.2, np.random.default_rng(1), keep=('Z_w', 'K_v'))
    ratio = vals / np.where(v.values == 0, 1.0, v.values)
    for i, c in enumerate(v.coefficients):
        name = v.names[i]
        if name in ('Z_w', 'K_v') or c.is_added_mass or v.values[i] == 0:
            assert vals[i] == v.values[i]
        else:
            assert 0.8 <= ratio[i] <= 1.2
    assert np.sum(vals != v.values) > 20
