"""Sea water from a CTD (core/glider/seawater.py): PSS-78 salinity and EOS-80 density against
the check values of Fofonoff & Millard (1983), UNESCO Technical Papers in Marine Science 44
(given there on the IPTS-68 scale, hence the temperatures / 1.00024 here), and a CTD's bad
samples left without a density."""
import numpy as np
import pytest

from auv_ident.core.glider.seawater import (
    C_35_15_0,
    ctd_density,
    density,
    practical_salinity,
    T68_PER_T90,
)

DBAR = 1e4      # Pa


@pytest.mark.parametrize('S, t68, p_dbar, rho', [
    (0, 5, 0, 999.96675), (0, 5, 10000, 1044.12802), (0, 25, 0, 997.04796),
    (0, 25, 10000, 1037.90204), (35, 5, 0, 1027.67547), (35, 5, 10000, 1069.48914),
    (35, 25, 0, 1023.34306), (35, 25, 10000, 1062.53817)])
def test_eos80_density_check_values(S, t68, p_dbar, rho):
    assert density(S, t68 / T68_PER_T90, p_dbar * DBAR) == pytest.approx(rho, abs=1e-5)


def test_pss78_check_values():
    # standard sea water at 15 degC and the surface is S = 35 by definition
    assert practical_salinity(C_35_15_0, 15 / T68_PER_T90, 0.0) == pytest.approx(35, abs=1e-6)
    # UNESCO 44's check value: R = 1.888091 at 40 degC and 10000 dbar is S = 40
    assert practical_salinity(1.888091 * C_35_15_0, 40 / T68_PER_T90,
                              10000 * DBAR) == pytest.approx(40, abs=1e-5)


def test_a_ctd_sample_without_a_valid_salinity_has_no_density():
    c = np.array([1.0, 0.0, np.nan, 1.0, 9.0])          # S/m: Baltic water, out of water, lost
    t = np.array([10.0, 10.0, 10.0, np.nan, 10.0])
    rho = ctd_density(c, t, np.full(5, 20 * DBAR))
    assert 1004.0 < rho[0] < 1008.0 and np.all(np.isnan(rho[1:]))
