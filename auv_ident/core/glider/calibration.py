"""Calibration of the glider flight model over several dives: least squares on the depth rate,
error bars from the sandwich covariance, and what the dives can identify.

The fit: the free parameters theta minimise ``sum_k (dz/dt_model,k(theta) - dz/dt_k)^2`` over
the samples of the fit window (depth between ``depth_window`` m, the glider not at the
surface): the depth rate from the pressure is the only measurement the model is fitted to. The
speed through water (a DVL's) is never used here: it judges the model afterwards
(:mod:`.validation`).

Error bars: the depth-rate residuals are far from white (a wrong buoyancy or drag gives an
error that lasts a whole dive, internal waves a few minutes), so the least-squares covariance
``s^2 (J^T J)^-1`` would be far too narrow. The covariance is the sandwich ``A^-1 B A^-1``
with B the long-run covariance of the per-sample scores (Newey-West, Bartlett weights, the lag
window from the residuals' correlation: :func:`auv_ident.core.identification.uncertainty.
sandwich_covariance`), samples outside the window counting zero but keeping their place in
time, so lags span the real time between samples.

What the dives cannot identify: the mass and the hull volume enter the steady flight only
as ``rho V_g - m`` (the density changes by 0.25 % over these dives: the split between them is
weak), so the mass is fixed and V_g identified. The lift slope and the induced drag change
only the angle of attack, which at the near-constant pitch of these dives is a constant
factor on the speed that C_D0 takes up as well: :func:`identifiability` reports their
correlation with C_D0 from the same sandwich with them added, at the solution.
"""
from collections.abc import Callable, Sequence
from dataclasses import dataclass
import time
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from auv_ident.core.errors import ConfigError, DataError
from auv_ident.core.glider.flight import FLIGHT_MODELS, GliderParameters
from auv_ident.core.glider.record import GliderRecord
from auv_ident.core.identification.uncertainty import (
    sandwich_covariance,
    verdicts_from_covariance,
)

# the parameters the depth rate identifies on these dives, and their scales (a typical
# uncertainty: the fit's variables are (value - start) / scale, of order 1)
IDENTIFIED = ('hull_volume', 'drag_zero_lift', 'compressibility')
SCALES = {'mass': 0.1, 'hull_volume': 1e-4, 'drag_zero_lift': 0.01, 'compressibility': 1e-10,
          'induced_drag': 1.0, 'lift_slope': 0.5, 'thermal_expansion': 1e-5}
DEPTH_WINDOW = (10.0, 35.0)     # m: deeper than the surface layer, above the inflections
DIFF_STEP = 1e-4                # finite-difference step, in units of the scales
MIN_SAMPLES = 50
OUT_OF_DOMAIN = 10.0            # m/s: the residual of parameters no glider has


@dataclass
class Calibration:
    """A calibrated flight model.

    model : 'steady' or 'dynamic'; params : the GliderParameters at the solution
    free : names of the identified parameters; std : their 1-sigma (sandwich), cov : (p, p)
    verdicts : name -> identifiability verdict dict (uncertainty.verdicts_from_covariance)
    rms : m/s, depth-rate residual RMS over the fit window; samples : in the window
    lags : the sandwich's lag window (samples); inflation : (p,) its bars over the white-noise
    ones; seconds : the fit's wall time; window : the depth window (m);
    depth_rate_density : None (the depth rate with the local density) or the constant one
    """

    model: str
    params: GliderParameters
    free: tuple[str, ...]
    std: np.ndarray
    cov: np.ndarray
    verdicts: dict[str, dict[str, Any]]
    rms: float
    samples: int
    lags: int
    inflation: np.ndarray
    seconds: float
    window: tuple[float, float] = DEPTH_WINDOW
    depth_rate_density: float | None = None

    def value(self, name: str) -> float:
        return float(getattr(self.params, name))

    def estimates(self) -> dict[str, tuple[float, float]]:
        """name -> (value, 1-sigma) of the identified parameters."""
        return {n: (self.value(n), float(s)) for n, s in zip(self.free, self.std)}


def fit_window(record: GliderRecord,
               window: tuple[float, float] = DEPTH_WINDOW) -> np.ndarray:
    """(N,) bool: the samples the fit uses (depth inside the window)."""
    lo, hi = window
    depth = record.depth
    return (depth > lo) & (depth < hi) & ~record.at_surface()


def measured_depth_rate(record: GliderRecord, density: float | None = None) -> np.ndarray:
    """(N,) m/s: the record's depth rate, with its local density, or with one constant density
    (kg/m^3; gliderflight's convention: -dP/dt / (rho_0 g))."""
    if density is None:
        return record.depth_rate()
    return record.depth_rate() * record.density / float(density)


def _check_names(names: Sequence[str]) -> None:
    known = set(GliderParameters.__dataclass_fields__)
    for n in names:
        if n not in known or n not in SCALES:
            raise ConfigError(f'glider parameter {n!r} cannot be calibrated; one of '
                              f'{", ".join(sorted(SCALES))}')


Residuals = Callable[[np.ndarray], np.ndarray]


def residual_function(record: GliderRecord, start: GliderParameters, names: Sequence[str],
                      model: str, window: tuple[float, float], density: float | None = None
                      ) -> tuple[Residuals, np.ndarray, np.ndarray, np.ndarray]:
    """(f, mask, x0, scale): f(x) -> (N,) model minus measured depth rate (NaN outside the
    window, mask) at the parameters ``start`` with names[i] = x0[i] + x[i] * scale[i] (x0 the
    start's values, scale from SCALES)."""
    flight = FLIGHT_MODELS[model]
    mask = fit_window(record, window)
    measured = measured_depth_rate(record, density)
    x0 = np.array([getattr(start, n) for n in names])
    scale = np.array([SCALES[n] for n in names])

    def f(x: np.ndarray) -> np.ndarray:
        try:
            params = start.with_values(names, x0 + np.asarray(x) * scale)
        except ConfigError:
            # a trial step beyond the physical values (a negative C_D0: Levenberg-Marquardt's
            # first step may be 100 scale units long): a residual far above any flight's, so
            # the step is refused and the trust region shrinks
            return np.where(mask, OUT_OF_DOMAIN, np.nan)
        r = flight(params, record).depth_rate - measured
        return np.where(mask, r, np.nan)

    return f, mask, x0, scale


def _jacobian(f: Residuals, x: np.ndarray, step: float = DIFF_STEP) -> np.ndarray:
    """(N, p) central differences of f at x (NaN rows where f is NaN)."""
    cols = []
    for i in range(len(x)):
        dx = np.zeros(len(x))
        dx[i] = step
        cols.append((f(x + dx) - f(x - dx)) / (2.0 * step))
    return np.column_stack(cols)


def calibrate(record: GliderRecord, start: GliderParameters, model: str = 'dynamic',
              free: Sequence[str] = IDENTIFIED, window: tuple[float, float] = DEPTH_WINDOW,
              depth_rate_density: float | None = None) -> 'Calibration':
    """Calibrate the flight model on a record's dives (module docstring).

    record : GliderRecord; start : GliderParameters, the prior (a glider file's,
    core/glider/vehicle.py), which the parameters not freed keep; model : 'steady' or
    'dynamic'; free : the parameters to identify (names of GliderParameters with a scale in
    SCALES); window : depth range (m) of the fit;
    depth_rate_density : None (the depth rate from the local density) or a constant (kg/m^3)
    Returns a :class:`Calibration`.
    """
    if model not in FLIGHT_MODELS:
        raise ConfigError(f'glider model {model!r}: one of {", ".join(FLIGHT_MODELS)}')
    free = tuple(free)
    if not free:
        raise ConfigError('glider calibration: no parameter to calibrate (free is empty)')
    _check_names(free)
    t0 = time.perf_counter()
    f, mask, x0, scale = residual_function(record, start, free, model, window,
                                           depth_rate_density)
    n_fit = int(mask.sum())
    if n_fit < MIN_SAMPLES:
        raise DataError(f'glider calibration: {n_fit} samples in the depth window {window} m; '
                        f'at least {MIN_SAMPLES} needed')
    sol = least_squares(lambda x: f(x)[mask], np.zeros(len(free)), method='lm',
                        diff_step=DIFF_STEP, x_scale=1.0)
    x = sol.x
    r = f(x)
    J = np.nan_to_num(_jacobian(f, x))
    blind = [n for n, col in zip(free, J.T) if not np.any(col)]
    if blind:
        raise DataError(f'glider calibration: the record says nothing on {", ".join(blind)} '
                        '(thermal_expansion needs the temperature)')
    cov_x, info = sandwich_covariance(J, r[:, None])
    values = x0 + x * scale
    cov = cov_x * np.outer(scale, scale)
    params = start.with_values(free, values)
    std = np.sqrt(np.diag(cov))
    verdicts = verdicts_from_covariance(cov, values, list(free))
    return Calibration(model=model, params=params, free=free, std=std, cov=cov,
                       verdicts=verdicts, rms=float(np.sqrt(np.nanmean(r ** 2))),
                       samples=n_fit, lags=int(info['lags']), inflation=info['inflation'],
                       seconds=time.perf_counter() - t0,
                       window=(float(window[0]), float(window[1])),
                       depth_rate_density=depth_rate_density)


def identifiability(record: GliderRecord, calibration: Calibration,
                    extra: Sequence[str] = ('lift_slope', 'induced_drag')
                    ) -> dict[str, dict[str, Any]]:
    """name -> verdict dict (uncertainty.verdicts_from_covariance) of the calibration's free
    parameters together with ``extra`` ones, from the sandwich at the solution: what the
    dives could say about the extra parameters had they been freed (module docstring). A
    parameter the record holds no information on (thermal expansion without a temperature)
    is 'not excited' with an infinite 1-sigma."""
    names = tuple(calibration.free) + tuple(n for n in extra if n not in calibration.free)
    _check_names(names)
    f, _, x0, scale = residual_function(record, calibration.params, names, calibration.model,
                                        calibration.window, calibration.depth_rate_density)
    x = np.zeros(len(names))
    J = np.nan_to_num(_jacobian(f, x))
    informed = np.array([np.any(col) for col in J.T])
    cov = np.full((len(names), len(names)), np.nan)
    keep = np.flatnonzero(informed)
    cov_x, _ = sandwich_covariance(J[:, keep], f(x)[:, None])
    cov[np.ix_(keep, keep)] = cov_x * np.outer(scale[keep], scale[keep])
    cov[~informed, ~informed] = np.inf      # no information: 'not excited'
    return verdicts_from_covariance(np.nan_to_num(cov, nan=0.0, posinf=np.inf), x0,
                                    list(names), informed=informed)
