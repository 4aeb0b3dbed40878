"""The chi-square distribution's tail and quantile, as scipy.stats.chi2 computes them
(scipy.special: chi2.sf is chdtrc, chi2.ppf is 2 gammaincinv(df / 2, p)), without importing
scipy.stats: that import loads integrate, interpolate, spatial and ndimage as well, about
35 MB of resident memory that ``identify --bag`` and the live node never use otherwise
(docs/reliability.md, bounded memory).
"""
import math

from scipy import special


def sf(x: float, df: float) -> float:
    """P(X > x) for X chi-square with df > 0 degrees of freedom (1 for x <= 0)."""
    if not math.isfinite(x):
        return 0.0 if x > 0 else 1.0
    return 1.0 if x <= 0 else float(special.chdtrc(df, x))


def ppf(p: float, df: float) -> float:
    """The p quantile (0 < p < 1) of the chi-square distribution with df > 0 degrees of
    freedom."""
    if not 0.0 < p < 1.0:
        raise ValueError(f'chi-square quantile of p = {p}: 0 < p < 1')
    return float(2.0 * special.gammaincinv(df / 2.0, p))
