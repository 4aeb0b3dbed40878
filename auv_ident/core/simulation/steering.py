"""The steering gear of a zig-zag run, identified from its measured rudder.

``ident = identify_steering_gear(runs)``: ``runs`` are measured zig-zag runs, each a
:class:`~auv_ident.offline.importers.MeasuredRun` (anything with ``t`` (N,) s, ``x`` (N, 12) and
``inputs['rudder']`` (N,) rad) or a tuple ``(t, psi, delta)`` (s, rad, rad). ``ident.gear`` is
the :class:`SteeringGear` fitted to every rudder reversal of every run together;
``ident.reversals`` the same figures fitted per reversal, ``ident.summary`` their mean and
spread.

The gear model: the helm orders the new angle delta_c at the instant the heading passes the
switch angle (the check time of :mod:`auv_ident.core.simulation.zigzag`); after a dead time
``delay`` the rudder follows a proportional servo with a rate limit,

    d(delta)/dt = sat((delta_c - delta) / T_s, R)          (rad/s)

(``time_constant`` T_s in s, ``rate`` R in rad/s; T_s = 0 is a pure rate limit, the classic
steering-gear model: a servo with magnitude and rate saturation), and the ordered angle is
clipped to +-``limit``. For a step of the order the
response is closed-form (:meth:`SteeringGear.response`): a ramp at R until the error is R T_s,
then an exponential approach with T_s. The measured rudder of the HSVA runs starts slowly
(~0.3 s to reach full rate) and slows down near the new angle (~0.5 s): the fitted dead time
absorbs the start, T_s the end, and R is the rate of the ramp in between; the mean rate over
the whole swing (``mean_rate``) is slower than R and is reported beside it.

Per reversal, besides the fit: ``onset_delay`` (s), from the check time to the last sample the
rudder still holds its angle (the first visible motion), and ``mean_rate`` (deg/s), the swing
divided by the time from that onset until the rudder is within tolerance of its new angle.

The first execute of a run has no check time (the order time is not recorded), so it is left
out of the fit; a simulation of a measured run orders it at the measured onset minus the mean
``onset_delay`` (:meth:`GearIdentification.execute_order_time`).
"""
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from auv_ident.core.errors import ConfigError, DataError
from auv_ident.core.model.state import State
from auv_ident.core.simulation.zigzag import (
    check_series,
    HOLD_RATE_DEG_S,
    RAD2DEG,
    rudder_rate,
    rudder_tolerance,
    zigzag_measures,
    ZigzagMeasures,
)

DEG = np.pi / 180.0
DEFAULT_LIMIT_DEG = 35.0    # deg: the rudder stops of a conventional ship (SOLAS II-1/29)
SETTLE_S = 1.5              # s: the fit window runs this long past the rudder's arrival
HOLD_WINDOW_S = 2.0         # s: the held angle before a reversal is read over this long


@dataclass(frozen=True)
class SteeringGear:
    """Dead time + rate-limited first-order rudder servo (module docstring).

    delay : s, from the order to the servo's start
    rate : rad/s, rate limit R (inf: no limit)
    time_constant : s, T_s (0: pure rate limit)
    limit : rad, the largest ordered angle
    """

    delay: float
    rate: float
    time_constant: float = 0.0
    limit: float = DEFAULT_LIMIT_DEG * DEG

    def __post_init__(self) -> None:
        for name in ('delay', 'time_constant'):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0.0):
                raise ConfigError(f'steering gear {name} must be finite and >= 0 s, got {v}')
        if not (self.rate > 0.0):
            raise ConfigError(f'steering gear rate must be > 0 rad/s (inf: no limit), got '
                              f'{self.rate}')
        if not (np.isfinite(self.limit) and self.limit > 0.0):
            raise ConfigError(f'steering gear limit must be finite and > 0 rad, got {self.limit}')

    @classmethod
    def ideal(cls, rate_deg_s: float, limit_deg: float = DEFAULT_LIMIT_DEG) -> 'SteeringGear':
        """The ideal helm: no dead time, no lag, the nominal rate (deg/s; inf: instant)."""
        return cls(delay=0.0, rate=rate_deg_s * DEG, time_constant=0.0, limit=limit_deg * DEG)

    @property
    def rate_deg_s(self) -> float:
        return self.rate * RAD2DEG

    def response(self, s: Any, start: float, target: float) -> Any:
        """Rudder angle(s) (rad) s seconds after the servo started (s < 0: before) from the
        angle ``start`` towards ``target`` (rad, already clipped to the limit)."""
        s = np.asarray(s, dtype=float)
        span = target - start
        size = abs(span)
        sign = 1.0 if span >= 0.0 else -1.0
        out = np.full(s.shape, float(start))
        # an instant rudder (R = inf, T_s = 0) is at its target from s = 0 on (right-continuous)
        go = s >= 0.0 if not np.isfinite(self.rate) and self.time_constant == 0.0 else s > 0.0
        if size == 0.0 or not go.any():
            return out if out.ndim else float(out)
        sg = s[go]
        R, T = self.rate, self.time_constant
        if T == 0.0:
            moved = np.minimum(R * sg, size) if np.isfinite(R) else np.full(sg.shape, size)
        else:
            t_ramp = max(size - R * T, 0.0) / R if np.isfinite(R) else 0.0
            e0 = min(size, R * T)     # the error when the exponential phase starts
            moved = np.where(sg <= t_ramp, R * sg if np.isfinite(R) else 0.0,
                             size - e0 * np.exp(-np.maximum(sg - t_ramp, 0.0) / T))
        out[go] = start + sign * moved
        return out if out.ndim else float(out)

    def as_dict(self) -> dict[str, float]:
        return {'delay_s': self.delay, 'rate_deg_s': self.rate_deg_s,
                'time_constant_s': self.time_constant, 'limit_deg': self.limit * RAD2DEG}


@dataclass
class GearIdentification:
    """The result of :func:`identify_steering_gear`.

    gear : SteeringGear fitted to all reversals together; rms_deg : its rms residual (deg)
    reversals : list of dicts, one per reversal: run, k (reversal index in the run),
        check_time (s), swing_deg, onset_delay (s), mean_rate (deg/s), delay (s),
        rate (deg/s), time_constant (s), rms_deg (the per-reversal fit)
    summary : {figure: (mean, standard deviation)} over the reversals
    onset_delay : s, the mean onset delay
    """

    gear: SteeringGear
    rms_deg: float
    reversals: list = field(default_factory=list)
    summary: dict = field(default_factory=dict)
    onset_delay: float = 0.0

    def execute_order_time(self, measures: ZigzagMeasures) -> float:
        """s: the estimated order time of a measured run's first execute (its rudder onset,
        ``measures.execute_time`` when detected from the rudder, minus the mean onset
        delay)."""
        return measures.execute_time - self.onset_delay


def run_series(run: Any) -> list[np.ndarray]:
    """(t, psi, delta) of a run (module docstring): s, rad, rad."""
    if isinstance(run, tuple) and len(run) == 3:
        return check_series(*run)
    try:
        return check_series(run.t, run.x[:, State.PSI], run.inputs['rudder'])
    except (AttributeError, KeyError, IndexError, TypeError) as err:
        raise DataError(f'{run!r:.80} is neither a (t, psi, delta) tuple nor a measured run '
                        'with t, x and inputs["rudder"]') from err


def _held_level(t: np.ndarray, d: np.ndarray, i0: int, i1: int) -> float | None:
    """deg: the median of the held samples of d in [i0, i1) (None if none is held)."""
    held = rudder_rate(t, d)[i0:i1] < HOLD_RATE_DEG_S
    return float(np.median(d[i0:i1][held])) if held.any() else None


def reversal_windows(t: np.ndarray, psi: np.ndarray, delta: np.ndarray) -> list[dict[str, Any]]:
    """The reversals of one run: dicts with the sample window of the move (from the check time
    to SETTLE_S after the rudder reached its new angle, or the next order), the check time,
    the held angles before and after (deg), the onset and arrival times (s)."""
    m = zigzag_measures(t, psi, delta)
    d = delta * RAD2DEG
    tol = rudder_tolerance(t, d)
    out = []
    for k, (tc, t_on) in enumerate(zip(m.check_times, m.rudder_onsets)):
        if t_on < tc:
            raise DataError(f'reversal {k + 1}: the rudder moved at {t_on:.3f} s, before the '
                            f'heading passed the switch angle at {tc:.3f} s: the switch angle '
                            f'{m.nominal[1]:g} deg detected is wrong')
        i_on = int(np.searchsorted(t, t_on))
        i_next = (int(np.searchsorted(t, m.check_times[k + 1])) if k + 1 < len(m.check_times)
                  else len(t))
        # the held angle: over the HOLD_WINDOW_S before the onset
        before = _held_level(t, d, int(np.searchsorted(t, t_on - HOLD_WINDOW_S)), i_on + 1)
        after = _held_level(t, d, i_on + 1, i_next)
        if before is None or after is None:
            continue
        near = np.flatnonzero(np.abs(d[i_on:i_next] - after) <= tol)
        if not len(near):
            continue
        i_arr = i_on + int(near[0])
        i_end = min(i_next, int(np.searchsorted(t, t[i_arr] + SETTLE_S)))
        i_start = int(np.searchsorted(t, tc))
        out.append({'k': k + 1, 'check_time': tc, 'before': before, 'after': after,
                    'onset': t_on, 'arrival': float(t[i_arr]), 'window': (i_start, i_end)})
    return out


def _residuals(p: np.ndarray, pieces: Sequence[Any]) -> np.ndarray:
    gear = SteeringGear(delay=p[0], rate=p[1] * DEG, time_constant=p[2])
    return np.concatenate([
        gear.response(tw - (tc + p[0]), a * DEG, b * DEG) * RAD2DEG - dw
        for tw, dw, tc, a, b in pieces])


def _fit(pieces: Sequence[Any],
         x0: tuple[float, float, float] = (0.2, 15.0, 0.2)) -> tuple[np.ndarray, float]:
    """(delay s, rate deg/s, T_s s), rms deg: least squares over the pieces from x0."""
    x0 = np.clip(np.asarray(x0, dtype=float), [0.0, 0.5, 0.0], [3.0, 200.0, 3.0])
    res = least_squares(_residuals, x0, args=(pieces,),
                        bounds=([0.0, 0.5, 0.0], [3.0, 200.0, 3.0]), x_scale=[0.1, 5.0, 0.1])
    rms = float(np.sqrt(np.mean(res.fun ** 2)))
    return res.x, rms


def identify_steering_gear(runs: Sequence[Any],
                           limit_deg: float = DEFAULT_LIMIT_DEG) -> GearIdentification:
    """Fit the steering gear (module docstring) to the rudder reversals of measured zig-zag
    runs.

    Parameters
    ----------
    runs : sequence of measured runs or (t (N,) s, psi (N,) rad, delta (N,) rad) tuples
    limit_deg : deg, the rudder limit of the resulting gear (not identifiable from a
        zig-zag, whose rudder stays inside it)

    Returns
    -------
    GearIdentification
    """
    runs = list(runs)
    if not runs:
        raise DataError('identify_steering_gear needs at least one zig-zag run')
    pieces, rows = [], []
    for j, run in enumerate(runs):
        t, psi, delta = run_series(run)
        d = delta * RAD2DEG
        for w in reversal_windows(t, psi, delta):
            i0, i1 = w['window']
            piece = (t[i0:i1], d[i0:i1], w['check_time'], w['before'], w['after'])
            pieces.append(piece)
            p, rms = _fit([piece])
            swing = abs(w['after'] - w['before'])
            rows.append({'run': j, 'k': w['k'], 'check_time': w['check_time'],
                         'swing_deg': swing, 'onset_delay': w['onset'] - w['check_time'],
                         'mean_rate': swing / (w['arrival'] - w['onset']),
                         'delay': float(p[0]), 'rate': float(p[1]),
                         'time_constant': float(p[2]), 'rms_deg': rms})
    if not pieces:
        raise DataError('no complete rudder reversal in the runs: nothing to identify the '
                        'steering gear from')
    # the joint fit starts from the median of the per-reversal fits: the residual is not
    # smooth in the dead time (sampled ramps), and a common start can stall far from it
    p, rms = _fit(pieces, np.median([[r['delay'], r['rate'], r['time_constant']]
                                     for r in rows], axis=0))
    gear = SteeringGear(delay=float(p[0]), rate=float(p[1]) * DEG, time_constant=float(p[2]),
                        limit=limit_deg * DEG)
    keys = ('onset_delay', 'mean_rate', 'delay', 'rate', 'time_constant', 'rms_deg')
    summary = {k: (float(np.mean([r[k] for r in rows])),
                   float(np.std([r[k] for r in rows], ddof=1)) if len(rows) > 1 else 0.0)
               for k in keys}
    return GearIdentification(gear=gear, rms_deg=rms, reversals=rows, summary=summary,
                              onset_delay=summary['onset_delay'][0])
