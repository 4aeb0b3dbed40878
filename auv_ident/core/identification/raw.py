"""Identification from raw sensor messages (issue 28 item 2): the asynchronous multi-rate pass of
core/filter/raw.py over one run's time-ordered records, and error bars that hold when the
sensors' noise is coloured. The entry point for a caller with records (a bag reader with an
input map, a CSV import, the independent generator): :func:`identify_raw`.

Error bars with coloured noise: the filter takes each message's noise as white. Real sensors
at 100 Hz are not (an AHRS attitude or a DVL averaged over pings shares most of its error with
the next sample), and a filter that fuses N correlated samples as independent reports error
bars about sqrt(N_eff / N) too small. Per channel group c (attitude, gyro, dvl, depth,
position) the whitened innovations' long-run variance over their count, over the run's second
half (Newey-West with
Bartlett weights, lag window by Andrews' rule: uncertainty.bandwidth, uncertainty.
long_run_variance; the largest over the group's channels) is the factor lambda_c by which that
group's information is overstated, its level included (noise larger than declared gives
lambda > 1). It is floored at 1: a declared noise is trusted as a lower bound. Per parameter i
the information the pass drew from each group, I_ci (the sum over the group's updates of
1/P_post - 1/P_prior of that parameter's variance), weighs them: the reported variance is the
filter's times f_i = sum_c I_ci / sum_c (I_ci / lambda_c) (the information-weighted harmonic
mean), the covariance D P D with D = diag(sqrt(f)).
"""
from collections.abc import Sequence
from dataclasses import dataclass, replace
import math
import time

import numpy as np

from auv_ident.core.errors import ConfigError, DataError
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.filter.raw import RawMeasurement, RawSensorConfig, RawSensorFilter
from auv_ident.core.identification.uncertainty import bandwidth, long_run_variance
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.sensors import DEFAULT_T
from auv_ident.core.model.state import COEFFICIENTS, N_STATE

MIN_INNOVATIONS = 50      # fewer whitened innovations in a group: no coloured-noise factor (1)
DEFAULT_PASSES = 2
MAX_EXTRA_PASSES = 2      # passes run beyond `passes` at most (identify_raw)
SETTLED_FACTOR = 2.0      # a pass's noise scales within this factor of those it used: settled


@dataclass
class RawIdentification:
    """What a raw-sensor pass found.

    names, estimate (p,), covariance (p, p): the model's parameters (coefficients, then current
    components) with the coloured-noise corrected covariance (module docstring);
    filter_covariance the filter's own; inflation (p,) the variance factors f_i;
    long_run : channel group -> lambda_c;
    errors : name -> (value, 1-sigma) of each estimated sensor error (raw_sensors.ERROR_UNITS;
        the 1-sigma times sqrt of the largest lambda_c: every group's innovations inform it);
    fused : kind -> messages fused (commands: taken); skipped : reason -> messages not fused;
    mean_nis : kind -> mean NIS per degree of freedom; restarts : vehicle-state restarts;
    state : (12,) the final vehicle state; noise_scale : channel group -> the factor on its
    declared covariance the last pass used; passes : how many; wall_s : s of all passes.
    """

    names: list[str]
    estimate: np.ndarray
    covariance: np.ndarray
    filter_covariance: np.ndarray
    inflation: np.ndarray
    long_run: dict[str, float]
    errors: dict[str, tuple[float, float]]
    fused: dict[str, int]
    skipped: dict[str, int]
    mean_nis: dict[str, float]
    restarts: int
    state: np.ndarray
    noise_scale: dict[str, float]
    passes: int = 1
    wall_s: float = math.nan

    @property
    def std(self) -> np.ndarray:
        """(p,) the parameters' corrected 1-sigma."""
        return np.sqrt(np.diag(self.covariance))


def long_run_factors(white: dict[str, list[np.ndarray]],
                     floor: float = 1.0) -> dict[str, float]:
    """Per channel group its coloured-noise factor lambda (module docstring), at least floor;
    white: group -> the whitened innovations of its updates in time order (each (m,))."""
    out = {}
    for group, ws in white.items():
        # the second half: the first holds the convergence from the prior, whose large and
        # slowly shrinking innovations are no property of the noise
        W = np.array(ws[len(ws) // 2:])
        lam = 1.0
        if W.shape[0] >= MIN_INNOVATIONS:
            lags = bandwidth(W)
            lam = max(long_run_variance(W[:, j], lags) / W.shape[0] for j in range(W.shape[1]))
        out[group] = max(floor, lam)
    return out


def raw_identification(f: RawSensorFilter, passes: int = 1,
                       wall_s: float = math.nan) -> RawIdentification:
    """The identification of a raw-sensor filter so far (DataError if it never started)."""
    if f.xf is None or f.P is None:
        raise DataError('no raw-sensor pass: no IMU orientation after a command '
                        f'(not fused: {f.skipped})')
    c = COEFFICIENTS.start
    p = f.p
    th = f.xf[c:c + p].copy()
    P_th = f.P[c:c + p, c:c + p].copy()
    lam = long_run_factors(f.white)
    num = np.zeros(p)
    den = np.zeros(p)
    for group, inf in f.info.items():
        inf = np.maximum(inf, 0.0)
        num += inf
        # a joint update (IMU attitude + rates) counts with its most coloured group
        den += inf / max(lam.get(g, 1.0) for g in group.split('+'))
    fac = np.where(den > 0, num / np.where(den > 0, den, 1.0), 1.0)
    D = np.sqrt(fac)
    f_err = max(lam.values(), default=1.0)
    errors = {e: (float(f.xf[i]), float(math.sqrt(f.P[i, i] * f_err)))
              for e, i in f.lay.errors.items()}
    mean_nis = {k: f.nis_sum[k] / f.dof_sum[k] for k in f.nis_sum if f.dof_sum[k] > 0}
    return RawIdentification(list(f.model.theta_names), th, P_th * np.outer(D, D), P_th, fac,
                             lam, errors, dict(f.fused), dict(f.skipped), mean_nis, f.restarts,
                             f.xf[:N_STATE].copy(), dict(f.noise_scale), passes, wall_s)


def _check_order(records: Sequence[RawMeasurement]) -> None:
    prev = -math.inf
    for i, m in enumerate(records):
        if m.t < prev:
            raise DataError(f'raw records not in time order: record {i} ({m.kind}) at '
                            f't = {m.t} s after t = {prev} s')
        prev = m.t


def identify_raw(model: Model, cfg: FilterConfig, records: Sequence[RawMeasurement],
                 sensors: RawSensorConfig | None = None, T: float = DEFAULT_T,
                 passes: int = DEFAULT_PASSES) -> RawIdentification:
    """The raw-sensor identification of one run: every record in turn through
    :class:`RawSensorFilter` (records in time order: one stamped before the previous is a
    DataError naming it), `passes` times (module docstring: each pass after the first starts
    from the previous one's parameters and sensor errors with the first pass's prior width (from
    the prior again when they are not plausible, _plausible), and weighs each channel group by
    the level and colour its innovations showed. After the `passes`-th, one more pass is run
    (at most MAX_EXTRA_PASSES more) while the last one was not plausible or the weights its
    innovations show differ from those it used by more than SETTLED_FACTOR).

    model : the Model whose theta_names are identified; cfg : FilterConfig (priors, process
    noise); records : RawMeasurement in time order (sensor messages and commands);
    sensors : RawSensorConfig (mountings, DVL reference, sensor errors to estimate, pressure
    constants); T : s, the nominal step cfg's per-step process noise refers to."""
    if passes < 1:
        raise ConfigError(f'passes = {passes!r} must be at least 1')
    t0 = time.perf_counter()
    _check_order(records)
    sensors = sensors or RawSensorConfig()
    f = RawSensorFilter(model, cfg, sensors, T)
    pc = model.p_coef
    th0 = f.base.theta0[:pc].copy()
    sd0 = np.sqrt(np.diag(f.base.theta_cov0)[:pc])
    target, done = passes, 0
    while True:
        f.process_many(records)
        done += 1
        if done >= MAX_EXTRA_PASSES + passes:
            break
        res = raw_identification(f)
        # the next pass weighs each group by what its innovations showed: its covariance times
        # the long-run factor (level and colour) measured with this pass's weights
        lam = long_run_factors(f.white, floor=0.0)
        scale = {g: max(1.0, f.noise_scale[g] * lam.get(g, 1.0)) for g in f.noise_scale}
        plausible = _plausible(res.estimate[:pc], th0, sd0)
        if done >= target and (passes < 2 or (plausible and _settled(f.noise_scale, scale))):
            break
        if done >= target:
            # weights measured on a pass that had them far off, or a pass gone wrong, overstate
            # or understate the noise: one pass more measures them again
            target += 1
        again, errors0 = cfg, None
        if plausible:
            again = replace(cfg, initial=res.estimate[:pc], theta_cov0=f.base.theta_cov0[:pc, :pc],
                            current_initial=_current_of(model, res.estimate))
            errors0 = np.array([res.errors[e][0] for e in f.err_names])
        f = RawSensorFilter(model, again, replace(sensors, noise_scale=scale), T,
                            errors0=errors0)
    return raw_identification(f, done, time.perf_counter() - t0)


def _settled(used: dict[str, float], measured: dict[str, float]) -> bool:
    """The weights a pass used agree with those its innovations show, within SETTLED_FACTOR."""
    return all(max(measured[g] / used[g], used[g] / measured[g]) <= SETTLED_FACTOR
               for g in used)


def _plausible(theta: np.ndarray, theta0: np.ndarray, sd0: np.ndarray) -> bool:
    """A pass's coefficients are a start for the next one when each keeps its prior's sign and
    lies within 3 prior 1-sigma of it (a pass whose sensors were weighted far too much can end
    10x off; starting the next pass there would keep it there)."""
    return bool(np.all(np.sign(theta) == np.sign(theta0))
                and np.all(np.abs(theta - theta0) <= 3.0 * sd0))


def _current_of(model: Model, theta: np.ndarray) -> np.ndarray | None:
    """The (3,) current of theta for the next pass's prior (None when none is identified)."""
    if not model.current_names:
        return None
    return model.current_with(theta)
