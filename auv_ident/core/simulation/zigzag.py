"""Zig-zag manoeuvre measures (IMO MSC.137(76), MSC/Circ.1053; ITTC 7.5-04-02-01) from a
heading and a rudder time series, measured or simulated.

``measures = zigzag_measures(t, psi, delta)`` with t (N,) s, psi (N,) rad, delta (N,) rad.
Signs are ours (NED/FRD, SNAME): psi positive to starboard (clockwise seen from above), delta_r
positive to port (trailing edge to port, which turns the ship to port). A starboard-first run
(``_S``) therefore opens with delta < 0 and psi growing.

The manoeuvre: at the first execute the rudder is ordered to ``rudder_deg`` to one side; when
the heading deviation from the initial heading reaches ``switch_deg`` towards that side the
rudder is reversed to the same angle on the other side (the second execute), and so on. The
definitions, all angles in deg and from the initial heading psi_0 (the heading at the first
execute), times in s:

- *rudder angle* (``rudder_deg``): the held rudder amplitude, the median |delta| over the
  samples where the rudder is held (moving slower than 0.5 deg/s over 0.5 s) beyond half its
  largest deflection, rounded to a whole degree in ``nominal`` (the ordered angle); a
  *reversal* is the rudder passing from beyond half that amplitude on one side to beyond it
  on the other (noise about zero makes none);
- *switch angle* (``switch_deg``): the heading deviation at which the rudder leaves its held
  angle at each reversal (median over the reversals). It exceeds the ordered switch angle by
  the heading change over the helm's and the gear's delay (0.26-0.47 deg in the HSVA runs), so
  ``nominal`` takes the largest whole degree not above the smallest of them plus one sample's
  heading change (the order precedes the onset, and a helm never reverses before the heading
  reaches the angle; this assumes the heading moves less than 1 deg from order to onset at
  the quickest reversal, else give switch_deg); every time measure below uses the nominal
  (ordered) angle;
- *reversal lag* k (``reversal_lag_deg[k]``, ``reversal_lag_s[k]``): how far past the nominal
  switch angle the k-th reversal came, the heading deviation at the rudder onset minus the
  nominal (deg), and the time from the heading passing the nominal angle in that leg to the
  onset (s; NaN when the heading did not pass it in the leg). A helm's delay at a high yaw
  rate moves the reversal by degrees; the lag says so, it does not make the run less of a
  zig-zag (:func:`zigzag_problem`);
- *check times* (``check_times``): the instants the heading deviation passes +-nominal switch
  angle, one per reversal: the reversal orders (the second, third, ... executes);
- *overshoot angle* k (``overshoots_deg[k]``): the heading's excursion beyond the switch
  heading after the k-th reversal, ``max(s_k (psi - psi_0)) - switch`` over the interval from
  the k-th check time to the next (s_k = +1 if the k-th reversal came at a deviation to
  starboard); the first and second overshoot angles are the IMO ones. Only complete overshoots
  are listed: the heading must have turned back by ``return_deg`` inside the run;
- *time to overshoot* k (``times_to_overshoot[k]``, "time to check yaw"): from the k-th check
  time to the heading extreme;
- *initial turning time* (``initial_turning_time``): from the first execute to the first check
  time;
- *period* (``period``): the mean time between the check times k and k + 2 (a full cycle of the
  heading), NaN with fewer than 3 reversals.

The first execute is ``execute_time`` when the caller knows the order time (a simulation, or a
measured run with the gear's onset delay subtracted); else the instant the measured rudder
first leaves its initial angle by more than ``rudder_tol_deg`` (the order precedes it by the
gear's onset delay, :mod:`auv_ident.core.simulation.steering`).

References: IMO Resolution MSC.137(76) (2002), Standards for ship manoeuvrability; IMO
MSC/Circ.1053 (2002), Explanatory notes to the standards for ship manoeuvrability; ITTC
Recommended Procedure 7.5-04-02-01, Full Scale Manoeuvring Trials.
"""
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.errors import DataError

RAD2DEG = 180.0 / np.pi
HOLD_RATE_DEG_S = 0.5     # deg/s: slower than this the rudder counts as held
RUDDER_TOL_DEG = 0.02     # deg: the least rudder motion that counts as a move, when the held
#                           rudder is noise-free (the HSVA files: held angles constant to the
#                           last digit, 0.0122 deg quantisation); else 4 noise sigmas
RATE_SPAN_S = 0.5         # s: the rudder rate that decides 'held' is a difference over this span,
#                           so sensor noise (0.05 deg at 20 Hz: 1.4 deg/s sample to sample) does
#                           not hide a hold (0.14 deg/s over 0.5 s)
RETURN_DEG = 0.1          # deg: how far the heading must turn back for an extreme to count
MAX_REVERSAL_LAG_S = 3.0  # s: a helm reverses the rudder within this long of the heading passing
#                           the switch angle (the basin's 0.09-0.17 s onset, a person's reaction
#                           of 1-2 s); a reversal later than this, or before the heading got
#                           there, was timed by something else (zigzag_problem)


@dataclass
class ZigzagMeasures:
    """The measures of one zig-zag run (module docstring for the definitions).

    rudder_deg, switch_deg : deg, detected from the data (or given)
    nominal : (rudder, switch) whole degrees, the ordered angles; ``label`` e.g. '20/10'
    first : 'starboard' or 'port', the side of the first rudder order
    execute_time : s; initial_heading_deg : deg, psi_0
    rudder_onsets : s, per reversal, when the rudder leaves its held angle
    onset_deviation_deg : deg, per reversal, s_k (psi - psi_0) at the rudder onset
    reversal_lag_deg, reversal_lag_s : deg, s, per reversal: onset deviation minus the nominal
        switch angle, and time from the heading passing the nominal angle in that leg to the
        onset (NaN: it did not pass it)
    check_times : s, per reversal, the heading passing the nominal switch angle
    overshoots_deg, overshoot_times, times_to_overshoot : deg, s (absolute), s (from the check
        time), per complete overshoot
    initial_turning_time, period : s (NaN if undefined)
    """

    rudder_deg: float
    switch_deg: float
    nominal: tuple
    first: str
    execute_time: float
    initial_heading_deg: float
    rudder_onsets: list = field(default_factory=list)
    onset_deviation_deg: list = field(default_factory=list)
    reversal_lag_deg: list = field(default_factory=list)
    reversal_lag_s: list = field(default_factory=list)
    check_times: list = field(default_factory=list)
    overshoots_deg: list = field(default_factory=list)
    overshoot_times: list = field(default_factory=list)
    times_to_overshoot: list = field(default_factory=list)
    initial_turning_time: float = float('nan')
    period: float = float('nan')

    @property
    def label(self) -> str:
        """The run's name in the usual form 'rudder/switch', e.g. '10/10'."""
        return f'{self.nominal[0]:g}/{self.nominal[1]:g}'

    @property
    def first_overshoot_deg(self) -> float:
        return self.overshoots_deg[0] if self.overshoots_deg else float('nan')

    @property
    def second_overshoot_deg(self) -> float:
        return self.overshoots_deg[1] if len(self.overshoots_deg) > 1 else float('nan')

    def as_dict(self) -> dict[str, Any]:
        """Plain numbers and lists (JSON-ready)."""
        out = {k: getattr(self, k) for k in self.__dataclass_fields__}
        out['nominal'] = list(self.nominal)
        out['label'] = self.label
        return out


def check_series(t: ArrayLike, *signals: ArrayLike,
                 names: Sequence[str] = ('psi', 'delta')) -> list[np.ndarray]:
    """(N,) float arrays of t and the signals; DataError naming the culprit if the stamps do
    not increase, lengths differ or a value is not finite."""
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or len(t) < 3:
        raise DataError(f'a zig-zag time series needs at least 3 samples, got t of shape '
                        f'{t.shape}')
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise DataError('zig-zag time stamps t must be finite and strictly increasing')
    out = [t]
    for name, s in zip(names, signals):
        s = np.asarray(s, dtype=float)
        if s.shape != t.shape:
            raise DataError(f'{name} has shape {s.shape}, the time stamps {t.shape}')
        bad = np.flatnonzero(~np.isfinite(s))
        if len(bad):
            raise DataError(f'{name} holds NaN/Inf at sample {int(bad[0])}')
        out.append(s)
    return out


def rudder_rate(t: np.ndarray, delta_deg: np.ndarray) -> np.ndarray:
    """(N,) deg/s, |d(delta)/dt| as the central difference over RATE_SPAN_S (one-sided at
    the ends)."""
    lo = np.searchsorted(t, t - 0.5 * RATE_SPAN_S)
    hi = np.minimum(np.searchsorted(t, t + 0.5 * RATE_SPAN_S, side='right') - 1, len(t) - 1)
    span = t[hi] - t[lo]
    out = np.zeros(len(t))
    ok = span > 0
    out[ok] = np.abs(delta_deg[hi[ok]] - delta_deg[lo[ok]]) / span[ok]
    return out


def rudder_tolerance(t: np.ndarray, delta_deg: np.ndarray) -> float:
    """deg: the least rudder motion that counts as a move: 4 sigmas of the white noise on the
    held samples (1.4826 MAD of their second differences / sqrt 6), at least RUDDER_TOL_DEG."""
    rate = rudder_rate(t, delta_deg)
    held = rate < HOLD_RATE_DEG_S
    d2 = np.diff(delta_deg, 2)[held[1:-1]]
    if len(d2) < 5:
        return RUDDER_TOL_DEG
    sigma = 1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0)
    return float(max(RUDDER_TOL_DEG, 4.0 * sigma))


def rudder_onset(t: np.ndarray, delta_deg: np.ndarray, start: int, tol_deg: float) -> int | None:
    """Index of the first sample at or after ``start`` where the rudder differs from its
    value at ``start`` by more than tol_deg (None if it never does)."""
    moved = np.flatnonzero(np.abs(delta_deg[start:] - delta_deg[start]) > tol_deg)
    return int(start + moved[0]) if len(moved) else None


def _crossing_time(t: np.ndarray, y: np.ndarray, level: float, i0: int,
                   i1: int) -> tuple[float, int] | None:
    """(time, index) of the first rise of y through level between samples i0 and i1: the
    first j in (i0, i1] with y[j - 1] < level <= y[j], the time interpolated linearly; None
    if there is none. The first crossing, not a smoothed one: the helm reverses when the
    heading it reads first passes the switch angle, noise and all (smoothing over a span would
    also blur the kink an instant rudder puts into the heading at a reversal)."""
    seg = y[i0:i1 + 1]
    rise = np.flatnonzero((seg[:-1] < level) & (seg[1:] >= level))
    if not len(rise):
        return None
    j = i0 + int(rise[0]) + 1
    a = (level - y[j - 1]) / (y[j] - y[j - 1])
    return float(t[j - 1] + a * (t[j] - t[j - 1])), j


def _peak(t: np.ndarray, y: np.ndarray, i: int) -> tuple[float, float]:
    """Time and value of the parabola through samples i-1, i, i+1 (the sampled extreme
    refined between the samples; the sample itself at the ends)."""
    if i == 0 or i == len(y) - 1:
        return float(t[i]), float(y[i])
    t0, t1, t2 = t[i - 1:i + 2]
    y0, y1, y2 = y[i - 1:i + 2]
    # vertex of the interpolating parabola (non-uniform stamps allowed)
    d1 = (y1 - y0) / (t1 - t0)
    d2 = (y2 - y1) / (t2 - t1)
    c = (d2 - d1) / (t2 - t0)
    if c >= 0.0:
        return float(t1), float(y1)
    b = d1 - c * (t0 + t1)
    tv = float(np.clip(-b / (2.0 * c), t0, t2))
    yv = y0 + d1 * (tv - t0) + c * (tv - t0) * (tv - t1)
    return tv, float(max(yv, y1))


def held_amplitude(t: np.ndarray, delta_deg: np.ndarray) -> float:
    """deg: median |delta| over the samples held (rate below HOLD_RATE_DEG_S) beyond half the
    largest deflection; DataError if the rudder never holds a deflection."""
    rate = rudder_rate(t, delta_deg)
    big = np.abs(delta_deg) > 0.5 * np.max(np.abs(delta_deg))
    held = (rate < HOLD_RATE_DEG_S) & big
    if not held.any() or np.max(np.abs(delta_deg)) < 1.0:
        raise DataError('the rudder never holds a deflection of 1 deg or more: not a zig-zag '
                        f'(largest |delta| {np.max(np.abs(delta_deg)):.3g} deg)')
    return float(np.median(np.abs(delta_deg[held])))


def reversal_onsets(t: np.ndarray, delta_deg: np.ndarray, start: int, tol_deg: float,
                    amp_deg: float) -> list[int]:
    """Indices of the last sample at the held angle before each reversal of the rudder after
    sample ``start`` (the first execute). A reversal: the rudder passes from beyond half the
    amplitude amp_deg on one side to beyond it on the other (so noise about zero is none); the
    held angle is the median of the samples held (rate below HOLD_RATE_DEG_S) since the
    previous reversal, and the onset is the last sample before the move within tol_deg of
    it."""
    rate = rudder_rate(t, delta_deg)
    big = np.flatnonzero(np.abs(delta_deg) > 0.5 * amp_deg)
    big = big[big >= start]
    sides = np.sign(delta_deg[big])
    out = []
    last = start
    for i in np.flatnonzero(sides[1:] != sides[:-1]) + 1:
        p, q = int(big[i - 1]), int(big[i])     # the last sample before, first after
        held = rate[last:p + 1] < HOLD_RATE_DEG_S
        if held.any():
            level = float(np.median(delta_deg[last:p + 1][held]))
            k = p
            while k > last and abs(delta_deg[k] - level) > tol_deg:
                k -= 1
            out.append(k)
        last = q
    return out


def reversal_lags(t: np.ndarray, dev: np.ndarray, s0: float, switch: float, start: int,
                  onsets: Sequence[int]) -> list[float]:
    """s, per reversal: from the heading deviation dev (deg, from psi_0) passing the switch
    angle (deg) towards the leg's side (s0 (-1)^k) for the last time in the leg (from the
    previous onset, or sample ``start`` for the first) to the rudder onset (sample index);
    NaN when it did not pass it there (reversed before the heading got there)."""
    out = []
    leg = start
    for k, i in enumerate(onsets):
        # to the sample after the onset: the order precedes the onset, so the heading may pass
        # the angle within the onset's sample (a lag of less than one sample below 0)
        end = min(i + 1, len(dev) - 1)
        y = s0 * (-1) ** k * dev[leg:end + 1]
        rise = np.flatnonzero((y[:-1] < switch) & (y[1:] >= switch))
        if not len(rise):
            out.append(float('nan'))
        else:
            j = int(rise[-1]) + 1
            a = (switch - y[j - 1]) / (y[j] - y[j - 1])
            tj = leg + j
            out.append(float(t[i] - (t[tj - 1] + a * (t[tj] - t[tj - 1]))))
        leg = i
    return out


def zigzag_problem(m: ZigzagMeasures, max_lag_s: float = MAX_REVERSAL_LAG_S) -> str | None:
    """Why a run whose measures are m is not a zig-zag, or None if it is one: the rudder
    switches sign between +-rudder_deg (zigzag_measures finds a held angle and reversals), each
    reversal comes after the heading deviation passed +-the nominal switch angle in its leg and
    within max_lag_s (s) of it, and at least one overshoot is complete. A helm's lag is
    reported (m.reversal_lag_deg, m.reversal_lag_s), not refused, up to max_lag_s: a rudder
    sequence timed otherwise (legs of fixed length, reversals independent of the heading)
    reverses at lags of many seconds, or before the heading reaches the angle."""
    if not m.rudder_onsets:
        return 'the rudder is never reversed'
    if m.nominal[1] <= 0:
        k = int(np.argmin(m.onset_deviation_deg))
        return (f'reversal {k + 1} of the rudder came at a heading deviation of '
                f'{m.onset_deviation_deg[k]:.1f} deg towards the side it had turned to, short '
                'of any switch angle of 1 deg or more: a timed rudder sequence, not a zig-zag')
    if not m.check_times or not m.overshoots_deg:
        return 'the heading never passes the switch angle and turns back'
    lags = np.array(m.reversal_lag_s, dtype=float)
    early = np.flatnonzero(~np.isfinite(lags))
    late = np.flatnonzero(np.isfinite(lags) & (lags > max_lag_s))
    if len(early) or len(late):
        k = int(early[0] if len(early) else late[np.argmax(lags[late])])
        what = ('before the heading deviation passed' if len(early) else
                f'{lags[k]:.1f} s after the heading deviation passed')
        return (f'reversal {k + 1} of the rudder came {what} the switch angle '
                f'{m.nominal[1]:g} deg (a helm reverses within {max_lag_s:g} s of it): a timed '
                'rudder sequence, not a zig-zag')
    return None


def zigzag_measures(t: ArrayLike, psi: ArrayLike, delta: ArrayLike,
                    execute_time: float | None = None, rudder_deg: float | None = None,
                    switch_deg: float | None = None, rudder_tol_deg: float | None = None,
                    return_deg: float = RETURN_DEG) -> ZigzagMeasures:
    """The IMO zig-zag measures of a run (module docstring).

    Parameters
    ----------
    t : (N,) s, strictly increasing
    psi : (N,) rad, heading (positive to starboard; unwrapped here)
    delta : (N,) rad, rudder angle delta_r (positive to port)
    execute_time : s, the first rudder order if known; None: the rudder's first motion
    rudder_deg, switch_deg : deg, the ordered angles if known (a simulation); None: detected
        and rounded to whole degrees for ``nominal``
    rudder_tol_deg : deg, the least rudder motion that counts as a move; None: from the data
        (:func:`rudder_tolerance`)
    return_deg : deg, how far the heading must turn back for an overshoot to be complete

    Returns
    -------
    ZigzagMeasures (overshoots in deg, times in s)
    """
    t, psi, delta = check_series(t, psi, delta)
    psi_deg = np.unwrap(psi) * RAD2DEG
    d_deg = delta * RAD2DEG
    if rudder_tol_deg is None:
        rudder_tol_deg = rudder_tolerance(t, d_deg)
    first_move = rudder_onset(t, d_deg, 0, rudder_tol_deg)
    if first_move is None:
        raise DataError('the rudder never moves: not a zig-zag run')
    amp = held_amplitude(t, d_deg)
    # the side of the first order: the rudder's first held deflection beyond half amplitude
    j = first_move + int(np.argmax(np.abs(d_deg[first_move:]) > 0.5 * amp))
    sgn = -1.0 if d_deg[j] < 0.0 else 1.0    # delta < 0 (to starboard) turns to starboard
    first = 'starboard' if sgn < 0.0 else 'port'
    s0 = -sgn                                # sign of the heading deviation of the first leg
    if execute_time is None:
        # the sample before the first moved one: the rudder was still at rest there
        execute_time = float(t[max(first_move - 1, 0)])
    execute_time = float(execute_time)
    psi0 = float(np.interp(execute_time, t, psi_deg))
    dev = psi_deg - psi0
    onsets = reversal_onsets(t, d_deg, first_move, rudder_tol_deg, amp)
    onset_dev = [float(s0 * (-1) ** k * dev[i]) for k, i in enumerate(onsets)]
    if switch_deg is None:
        if not onsets:
            raise DataError('the rudder is never reversed: cannot detect the switch angle; '
                            'give switch_deg')
        switch_meas = float(np.median(onset_dev))
        # the order comes before the onset, so the ordered angle is at most the onset
        # deviation plus the heading change over one sample (the onset's resolution); a helm
        # may reverse late (its delay at a high yaw rate is degrees), never early: the
        # quickest reversal bounds the ordered angle
        psi_step = [abs(dev[i + 1] - dev[i]) if i + 1 < len(dev) else 0.0 for i in onsets]
        switch_nom = float(np.floor(np.min(np.array(onset_dev) + np.array(psi_step)) + 1e-9))
    else:
        switch_meas = switch_nom = float(switch_deg)
    rudder_nom = float(round(amp)) if rudder_deg is None else float(rudder_deg)
    rudder_meas = amp if rudder_deg is None else float(rudder_deg)
    i_exec = int(np.searchsorted(t, execute_time))
    checks = []
    i_from = i_exec
    side = s0
    while True:
        hit = _crossing_time(t, side * dev, switch_nom, i_from, len(t) - 1)
        if hit is None:
            break
        checks.append(hit[0])
        i_from = hit[1]     # strictly later each time: the loop ends
        side = -side
    m = ZigzagMeasures(rudder_deg=rudder_meas, switch_deg=switch_meas,
                       nominal=(rudder_nom, switch_nom), first=first,
                       execute_time=execute_time, initial_heading_deg=psi0,
                       rudder_onsets=[float(t[i]) for i in onsets],
                       onset_deviation_deg=onset_dev,
                       reversal_lag_deg=[d - switch_nom for d in onset_dev],
                       reversal_lag_s=reversal_lags(t, dev, s0, switch_nom, first_move, onsets),
                       check_times=checks)
    if checks:
        m.initial_turning_time = checks[0] - execute_time
    if len(checks) >= 3:
        m.period = float(np.mean(np.array(checks[2:]) - np.array(checks[:-2])))
    for k, tc in enumerate(checks):
        side = s0 * (-1) ** k
        i0 = int(np.searchsorted(t, tc))
        i1 = int(np.searchsorted(t, checks[k + 1])) if k + 1 < len(checks) else len(t) - 1
        y = side * dev
        i_ext = i0 + int(np.argmax(y[i0:i1 + 1]))
        # complete only if the heading has turned back by return_deg before the window ends
        if i_ext >= i1 or y[i_ext] - np.min(y[i_ext:i1 + 1]) < return_deg:
            break
        te, ye = _peak(t, y, i_ext)
        m.overshoots_deg.append(ye - switch_nom)
        m.overshoot_times.append(te)
        m.times_to_overshoot.append(te - tc)
    return m
