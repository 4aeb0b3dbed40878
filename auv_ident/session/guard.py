"""Divergence guard, reset rule and health rule of the identifier session, and its records.

Divergence guard (not in noise mode 'paper', whose adapted R makes the NIS meaningless):

- innovation gate (:func:`innovation_gate`): an update whose NIS exceeds OUTLIER_GATE_FACTOR
  (100) x the chi-square quantile 1 - 1e-9 for its m channels (6735 for m = 12, i.e. NIS/dof
  561) is not fused; the message is rejected as ``outlier``. Legitimate data stay far below:
  NIS/dof <= 4 on simulated runs, <= 56 with unmodelled process noise and the default (small)
  q_state, where a tighter gate was measured to reject good data and wreck the estimate;
- covariance: an update that finds or leaves the covariance non-positive-definite is repaired
  by symmetrising and flooring the eigenvalues (core.filter.augmented.repair_covariance) and
  counted in ``repairs``; the update stands;
- reset rule: a core error that the repair cannot fix (DomainError; DivergenceError:
  non-finite state or covariance, a second failure after the repair, a coefficient 1-sigma
  above COV_BLOWUP_FACTOR (100) x its prior p0_rel |initial guess|), or innovations
  inconsistent for GUARD_SECONDS (1 s of stamps: the median NIS/dof over the last
  GUARD_WINDOW (20) updates, outliers included, above GUARD_FACTOR (100); the median, so a
  burst shorter than half the window does not count; legitimate data with process noise
  reached 26; :class:`GuardWindow`), RESETS THE FILTER: the vehicle states restart from the
  next measurement, the coefficients from the last good estimate with its covariance times
  RESET_COV_INFLATION (4, i.e. 2x the 1-sigma). The start-up configuration (initial guesses
  or warm start) is used instead if there is no good estimate yet, if the inflated covariance
  is unusable, or for a core error when the previous reset also started from the last good
  estimate and no update since was good (the last good estimate itself may be the problem;
  :func:`reset_start`). Buffered commands are kept. /diagnostics reports ERROR 'diverging'
  until NIS_WINDOW (200) updates have passed; the reason is logged and in ``last_error``;
- last good estimate (``IdentSession.last_good``, a :class:`LastGood`): updated only by an
  update that was fused (not an outlier), has a finite estimate and a positive definite
  covariance, while the guard window is consistent and, after a reset, once GUARD_WINDOW
  updates have refilled it with a median NIS/dof <= GUARD_PROBATION (10), and while the
  health window (last 200 updates, :class:`NisWindow`) is not grossly inconsistent (mean
  NIS/dof above 10x its chi-square band: what /diagnostics reports as ERROR 'diverging';
  model mismatch of simulated runs with process noise stays at WARN) (Event.good). Only such
  updates are published by the node; the estimate file (~/save, shutdown, autosave) and
  ``IdentSession.best()`` give the last good estimate.

Health rule: :func:`judge_health`.
"""
from bisect import bisect_left, insort
from collections import deque
from dataclasses import dataclass
from functools import lru_cache
import math
import operator

import numpy as np

from auv_ident.core.errors import DivergenceError
from auv_ident.core.filter.augmented import is_positive_definite
from auv_ident.core.model.state import N_STATE

# Divergence guard
OUTLIER_P = 1e-9            # chi-square tail of the innovation gate ...
OUTLIER_GATE_FACTOR = 100.0  # ... times this
GUARD_WINDOW = 20           # updates in the guard's NIS window
GUARD_FACTOR = 100.0        # inconsistent: window median NIS/dof above this
GUARD_SECONDS = 1.0         # s of stamps the inconsistency must last before a reset
GUARD_PROBATION = 10.0      # after a reset: good only once the window median NIS/dof <= this
RESET_COV_INFLATION = 4.0   # coefficient covariance factor when a reset restarts from last good
COV_BLOWUP_FACTOR = 100.0   # a coefficient 1-sigma above this x p0_rel |theta0|: divergence
NIS_CAP = 1e300             # a non-finite NIS enters the guard window as this

# codes of StreamIdentifier outcomes for which an update was computed (fused or gated)
FUSED_CODES = frozenset(('', 'repaired', 'outlier'))

# Health rule (judge_health)
NIS_WINDOW = 200          # updates in the running NIS window (10 s at 20 Hz)
NIS_BAND_PROB = 0.999     # two-sided chi-square band of the window's mean NIS per dof
CONVERGED_REL_STD = 0.05  # 'converged' needs every coefficient's 1-sigma below 5 % of |estimate|
GROSS_NIS_FACTOR = 10.0   # mean NIS/dof above 10x the band's upper edge: ERROR


@dataclass(slots=True)
class Event:
    """What one message did.

    kind : 'update' (odometry fused), 'kept' (odometry kept unfiltered: IdentSession with
        filtering False), 'command' (actuators buffered), 'rejected' (dropped, see
        reason) or 'error' (a core error or a divergence-guard reset; the filter was reset by
        the reset rule, see reason)
    reason : why rejected / the error text / a note on an accepted update ('' if none),
        prefixed with the topic ('odom: ', 'actuators: ')
    stamp_ns : header stamp of the message, int ns (None if it could not be read)
    estimate, std : (p,) after an update; cov : (p, p); nis, dof : of this update
    code : short category of a rejection, error or note ('non-finite', 'outlier', 'gap',
        'repaired', 'guard', ...; '' for a plain update or command)
    good : an update that became the last good estimate (the node publishes only these)
    """

    kind: str
    reason: str = ''
    stamp_ns: object = None
    estimate: object = None
    std: object = None
    cov: object = None
    nis: float = math.nan
    dof: int = 0
    code: str = ''
    good: bool = False

    @property
    def accepted(self):
        return self.kind in ('update', 'kept', 'command')


@dataclass
class LastGood:
    """The latest estimate that passed every check: stamp (int ns), estimate and std (p,),
    covariance (p, p), in the vehicle file's units."""

    stamp_ns: int
    estimate: np.ndarray
    std: np.ndarray
    cov: np.ndarray


@dataclass
class Health:
    """Filter health by :func:`judge_health`: level 'OK'/'WARN'/'ERROR', a short message, the
    window's mean NIS per dof with its chi-square band (lo, hi) and the window length."""

    level: str
    message: str
    mean_nis_per_dof: float
    band: tuple
    window: int


@lru_cache(maxsize=1)
def innovation_gate():
    """(13,) largest NIS accepted from an update with m = 0..12 channels (m = 0: no limit)."""
    from scipy.stats import chi2
    gate = np.array([math.inf] + [OUTLIER_GATE_FACTOR * chi2.ppf(1.0 - OUTLIER_P, m)
                                  for m in range(1, N_STATE + 1)])
    gate.flags.writeable = False        # one array shared by every session's filter
    return gate


@lru_cache(maxsize=None)
def nis_band(dof):
    """(lo, hi): two-sided NIS_BAND_PROB chi-square band of a mean NIS per dof over `dof`
    (an int, the window's summed dof) degrees of freedom. Cached: a window of constant
    channels has one dof sum once full, and at most NIS_WINDOW x 12 exist."""
    from scipy.stats import chi2
    a = 0.5 * (1.0 - NIS_BAND_PROB)
    D = float(dof)
    return float(chi2.ppf(a, D) / D), float(chi2.ppf(1.0 - a, D) / D)


class GuardWindow:
    """The divergence guard's window: NIS/dof of the last GUARD_WINDOW updates (outliers
    included), kept sorted as well so that the median costs no sort per message, and the
    stamp since which the window has been inconsistent (``since``, s, None if it is not)."""

    def __init__(self):
        self._ratios = deque()
        self._sorted = []
        self.since = None

    def __len__(self):
        return len(self._ratios)

    def clear(self):
        self._ratios.clear()
        self._sorted.clear()
        self.since = None

    def median(self):
        """Median NIS/dof over the window; NaN if empty. The median: a burst of outliers
        shorter than half the window does not move it."""
        s = self._sorted
        n = len(s)
        if not n:
            return math.nan
        h = n // 2
        return s[h] if n % 2 else (s[h - 1] + s[h]) / 2

    def inconsistent(self):
        """True if the window is full and its median NIS/dof is above GUARD_FACTOR."""
        return len(self._ratios) >= GUARD_WINDOW and self.median() > GUARD_FACTOR

    def add(self, t, nis, dof):
        """Add an update's NIS (float) over dof (int > 0) channels at stamp t (s); returns
        True when the inconsistency has lasted GUARD_SECONDS."""
        ratio = (nis if math.isfinite(nis) else NIS_CAP) / dof
        ratios, ordered = self._ratios, self._sorted
        if len(ratios) == GUARD_WINDOW:
            del ordered[bisect_left(ordered, ratios.popleft())]
        ratios.append(ratio)
        insort(ordered, ratio)
        if not self.inconsistent():
            self.since = None
            return False
        if self.since is None or t < self.since:
            self.since = t
        return t - self.since >= GUARD_SECONDS


# NIS values enter NisWindow's sum as exact integers in units of 2^-1074 (the smallest
# subnormal), so the running sum is exact; int / int is correctly rounded, like math.fsum.
_UNIT_BITS = 1074
_UNIT = 1 << _UNIT_BITS


def _exact(x):
    num, den = x.as_integer_ratio()          # den = 2^k, k <= 1074
    return num << (_UNIT_BITS + 1 - den.bit_length())


class NisWindow:
    """The health window: NIS and dof of the last NIS_WINDOW fused updates (finite NIS only).

    The sums are kept exactly and updated per message: the mean NIS per dof is the correctly
    rounded sum over the window (= math.fsum) divided by the summed dof, without a pass over
    the window per message."""

    def __init__(self):
        self._items = deque()        # (exact nis, dof)
        self._sum = 0
        self._dof = 0

    def __len__(self):
        return len(self._items)

    def clear(self):
        self._items.clear()
        self._sum = 0
        self._dof = 0

    def add(self, nis, dof):
        """Add a fused update's NIS (finite float) over dof (int) channels."""
        items = self._items
        if len(items) == NIS_WINDOW:
            old, old_dof = items.popleft()
            self._sum -= old
            self._dof -= old_dof
        exact = _exact(nis)
        items.append((exact, dof))
        self._sum += exact
        self._dof += dof

    @property
    def dof(self):
        """Summed dof over the window."""
        return self._dof

    def total(self):
        """Sum of the window's NIS (correctly rounded)."""
        return self._sum / _UNIT

    def mean(self):
        """Mean NIS per dof over the window; NaN if empty."""
        if not self._items:
            return math.nan
        return float(self.total() / self._dof)

    def band(self):
        """(lo, hi) of :func:`nis_band` for the window; (NaN, NaN) if empty."""
        if not self._items:
            return math.nan, math.nan
        return nis_band(self._dof)

    def gross(self):
        """True if the mean NIS/dof is above GROSS_NIS_FACTOR x the upper edge of its band."""
        return bool(self._items) and self.mean() > GROSS_NIS_FACTOR * nis_band(self._dof)[1]


def reset_start(last_good, code, reset_from_good):
    """What a fault reset starts the coefficients from (reset rule): `last_good` (a LastGood,
    its covariance to be inflated by RESET_COV_INFLATION), or None for the start-up
    configuration.

    code : the reset's code ('core error', 'guard', 'internal error')
    reset_from_good : the previous reset started from last_good and no update since was good
    """
    if last_good is None:
        return None
    with np.errstate(all='ignore'):
        usable = is_positive_definite(RESET_COV_INFLATION * last_good.cov)
    if not usable or (code == 'core error' and reset_from_good):
        return None                 # the last good estimate may be the problem
    return last_good


def judge_health(nis_window, guard_inconsistent, since_reset, started, estimate, cov):
    """The filter's health (the rule the /diagnostics status reports).

    Over the last NIS_WINDOW (200) updates (`nis_window`, a NisWindow), m = sum(NIS) / sum(dof)
    and the chi-square band [lo, hi] of m for D = sum(dof) degrees of freedom (two-sided
    99.9 %: windows overlap, so a 99 % band would blip WARN now and then on a healthy filter):

    - a filter reset (core error or divergence guard) and fewer than NIS_WINDOW updates
      since (`since_reset`: updates since the last reset, None if none): ERROR 'diverging';
    - no update since start or restart (`started` False): WARN 'waiting for data';
    - the divergence guard's window inconsistent now (`guard_inconsistent`), or m > 10 hi:
      ERROR 'diverging';
    - window full and m > hi (innovations larger than the filter expects): WARN 'diverging';
    - window full, m <= hi and every coefficient's 1-sigma (from `cov`) < 5 % of |estimate|:
      OK 'converged';
    - otherwise OK 'converging'. (m < lo, a conservative filter, is not flagged.)
    """
    m = nis_window.mean()
    n = len(nis_window)
    band = nis_window.band()
    if since_reset is not None and since_reset < NIS_WINDOW:
        return Health('ERROR', 'diverging', m, band, n)
    if not started:
        return Health('WARN', 'waiting for data', m, band, n)
    if guard_inconsistent or (n and m > GROSS_NIS_FACTOR * band[1]):
        return Health('ERROR', 'diverging', m, band, n)
    full = n >= NIS_WINDOW
    if full and m > band[1]:
        return Health('WARN', 'diverging', m, band, n)
    with np.errstate(divide='ignore', invalid='ignore'):
        rel = np.sqrt(np.clip(np.diag(cov), 0.0, None)) / np.abs(estimate)
    if full and np.all(rel < CONVERGED_REL_STD):
        return Health('OK', 'converged', m, band, n)
    return Health('OK', 'converging', m, band, n)


def checked_coefficients(f, t, names, std_limits):
    """(estimate, covariance, std) of filter f's parameters after an accepted update at t (s);
    raises DivergenceError if they are unusable: non-finite, not positive definite, or a
    1-sigma above its limit (std_limits, a list of floats: COV_BLOWUP_FACTOR x the prior
    scale), naming the parameters (names).

    Per message, so on lists where numpy's per-call overhead would dominate; the decisions
    are those of the numpy forms (core.filter.augmented.is_positive_definite and so on)."""
    est, cov = f.theta, f.theta_cov
    var = cov.diagonal()
    isfinite = math.isfinite
    if not (all(map(isfinite, est.tolist())) and all(map(isfinite, cov.ravel().tolist()))
            and _has_cholesky(cov) and min(var.tolist()) > 0):
        raise DivergenceError(f'non-finite or non-positive-definite coefficient '
                              f'covariance after the update at {t:.9f} s')
    std = np.sqrt(var)
    if any(map(operator.gt, std.tolist(), std_limits)):
        blown = np.flatnonzero(std > np.array(std_limits))
        raise DivergenceError(
            'coefficient covariance blew up: 1-sigma of ' + ', '.join(
                f'{names[i]} = {math.sqrt(var[i]):.3g}'
                for i in blown) + f' above {COV_BLOWUP_FACTOR:g}x its '
            f'prior (p0_rel |initial guess|) at {t:.9f} s')
    return est, cov, std


def _has_cholesky(P):
    """True if the finite matrix P has a Cholesky factor (numpy's, as
    core.filter.augmented.is_positive_definite, whose finiteness check the caller did)."""
    try:
        np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        return False
    return True
