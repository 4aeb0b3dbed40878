"""Sea water from a CTD: practical salinity from conductivity (PSS-78) and in-situ density
(the international equation of state EOS-80), so that a glider's raw logs (conductivity,
temperature, pressure) give the density its flight model reads.

Written here from the published algorithms: Fofonoff & Millard (1983), "Algorithms for
computation of fundamental properties of seawater", UNESCO Technical Papers in Marine Science
44 (PSS-78: Lewis & Perkin 1981; EOS-80: Millero et al. 1980, Millero & Poisson 1981), with
the check values printed there (test/core/test_seawater.py). Both take the temperature on the
IPTS-68 scale; CTDs report ITS-90, converted here as T68 = 1.00024 T90 (Saunders 1990).

Why EOS-80 and not TEOS-10: TEOS-10's density needs its Gibbs function (a 75-term polynomial
in absolute salinity) and, in the Baltic, the regional composition anomaly; EOS-80 is the
standard it replaced, within a few hundredths of a kg/m^3 of it in open-ocean water. On the
comet's Baltic record it differs from the processed file's TEOS-10 density by an offset the
glider's hull volume takes up (docs/glider.md, "Density from the raw logs"): what the flight
needs is the density's change over a dive, which both give alike.

Units: conductivity S/m, temperature degC (ITS-90), pressure Pa gauge (0 at the surface),
salinity on the practical scale (PSS-78, dimensionless), density kg/m^3.
"""
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

C_35_15_0 = 4.2914          # S/m: the conductivity of standard sea water, S = 35, 15 degC, p = 0
DBAR = 1e4                  # Pa
T68_PER_T90 = 1.00024

# PSS-78 (UNESCO 44, p. 6-9)
_A = (0.0080, -0.1692, 25.3851, 14.0941, -7.0261, 2.7081)
_B = (0.0005, -0.0056, -0.0066, -0.0375, 0.0636, -0.0144)
_K = 0.0162
_C = (0.6766097, 2.00564e-2, 1.104259e-4, -6.9698e-7, 1.0031e-9)     # r_t(t)
_D = (3.426e-2, 4.464e-4, 4.215e-1, -3.107e-3)                       # R_p's denominator
_E = (2.070e-5, -6.370e-10, 3.989e-15)                               # R_p's numerator, dbar
# EOS-80 (UNESCO 44, p. 15-19): one-atmosphere density and secant bulk modulus (bar)
_RHO_W = (999.842594, 6.793952e-2, -9.095290e-3, 1.001685e-4, -1.120083e-6, 6.536332e-9)
_RHO_S = (0.824493, -4.0899e-3, 7.6438e-5, -8.2467e-7, 5.3875e-9)
_RHO_S15 = (-5.72466e-3, 1.0227e-4, -1.6546e-6)
_RHO_S2 = 4.8314e-4
_K_W = (19652.21, 148.4206, -2.327105, 1.360477e-2, -5.155288e-5)
_K_S = (54.6746, -0.603459, 1.09987e-2, -6.1670e-5)
_K_S15 = (7.944e-2, 1.6483e-2, -5.3009e-4)
_A_W = (3.239908, 1.43713e-3, 1.16092e-4, -5.77905e-7)
_A_S = (2.2838e-3, -1.0981e-5, -1.6078e-6)
_A_S15 = 1.91075e-4
_B_W = (8.50935e-5, -6.12293e-6, 5.2787e-8)
_B_S = (-9.9348e-7, 2.0816e-8, 9.1697e-10)


def _poly(coefficients: Sequence[float], x: np.ndarray) -> np.ndarray:
    """sum_i c_i x^i."""
    total = np.zeros_like(x, dtype=float)
    for i, c in enumerate(coefficients):
        total = total + c * x ** i
    return total


def t68(temperature: ArrayLike) -> np.ndarray:
    """degC ITS-90 -> IPTS-68."""
    return T68_PER_T90 * np.asarray(temperature, dtype=float)


def practical_salinity(conductivity: ArrayLike, temperature: ArrayLike,
                       pressure: ArrayLike) -> np.ndarray:
    """PSS-78 salinity (N,) of conductivity S/m, temperature degC (ITS-90) and gauge
    pressure Pa (module docstring); valid for 2 < S < 42, -2 < t < 35 degC."""
    t = t68(temperature)
    p = np.asarray(pressure, dtype=float) / DBAR
    R = np.asarray(conductivity, dtype=float) / C_35_15_0
    Rp = 1.0 + p * _poly(_E, p) / (1.0 + _D[0] * t + _D[1] * t ** 2 + (_D[2] + _D[3] * t) * R)
    Rt = R / (Rp * _poly(_C, t))
    root = np.sqrt(np.clip(Rt, 0.0, None))
    dS = (t - 15.0) / (1.0 + _K * (t - 15.0)) * _poly(_B, root)
    return _poly(_A, root) + dS


def density(salinity: ArrayLike, temperature: ArrayLike, pressure: ArrayLike) -> np.ndarray:
    """In-situ density kg/m^3 (N,) of practical salinity, temperature degC (ITS-90) and
    gauge pressure Pa, EOS-80 (module docstring)."""
    S = np.asarray(salinity, dtype=float)
    t = t68(temperature)
    p = np.asarray(pressure, dtype=float) / 1e5          # bar
    S15 = S * np.sqrt(np.clip(S, 0.0, None))
    rho0 = (_poly(_RHO_W, t) + S * _poly(_RHO_S, t) + S15 * _poly(_RHO_S15, t)
            + _RHO_S2 * S ** 2)
    K0 = _poly(_K_W, t) + S * _poly(_K_S, t) + S15 * _poly(_K_S15, t)
    A = _poly(_A_W, t) + S * _poly(_A_S, t) + _A_S15 * S15
    B = _poly(_B_W, t) + S * _poly(_B_S, t)
    K = K0 + A * p + B * p ** 2
    return rho0 / (1.0 - p / K)


SALINITY_RANGE = (2.0, 42.0)     # PSS-78's range of validity


def ctd_density(conductivity: ArrayLike, temperature: ArrayLike,
                pressure: ArrayLike) -> np.ndarray:
    """In-situ density kg/m^3 (N,) from a CTD's conductivity S/m, temperature degC (ITS-90)
    and gauge pressure Pa: EOS-80 at the PSS-78 salinity; NaN where a value is missing or the
    salinity falls outside PSS-78's range (a CTD out of the water, a fouled cell)."""
    with np.errstate(invalid='ignore'):
        S = practical_salinity(conductivity, temperature, pressure)
        ok = np.isfinite(S) & (S >= SALINITY_RANGE[0]) & (S <= SALINITY_RANGE[1])
        return np.where(ok, density(np.where(ok, S, 0.0), temperature, pressure), np.nan)
