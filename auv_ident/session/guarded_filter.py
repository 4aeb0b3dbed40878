"""One streaming filter under the session's per-message rules: :class:`GuardedFilter`.

Per odometry sample (:meth:`GuardedFilter.update`), the rule both the session's running
filter and the live 'auto' choice's chosen filter follow (session/session.py,
session/auto_choice.py), so that it exists once:

1. the measurement variances of the sample, if it states them, become the filter's R
   (core.filter.augmented.AugmentedEKF.use_measurement_variances, applied only when they
   change);
2. core.filter.stream.StreamIdentifier pairs it with the commands and fuses it (time rules,
   innovation gate, covariance repair: accepted or rejected with a code); a core error it
   cannot repair (:data:`FILTER_FAULTS`) goes to the caller, whose reset rule it is;
3. the estimate of an accepted update is checked (guard.checked_coefficients: finite,
   positive definite, no 1-sigma blown up), a failure raising DivergenceError;
4. the divergence guard's window takes every computed update (outliers included); a
   sustained inconsistency (guard.GuardWindow) is reported, the reset is the caller's;
5. an accepted update enters the health window, and becomes the last good estimate when the
   guard's window is consistent, the probation after a fault reset is over, the health
   window is not grossly inconsistent (guard.py's module docstring) and no sensor fault is
   active (the caller's ``trusted``: session/stuck.py).

The filter also keeps what the reset rule reads (the last good estimate, whether the last
reset started from it) and answers the estimate queries (:meth:`GuardedFilter.best`,
:meth:`GuardedFilter.estimate_now`).
"""
from dataclasses import dataclass
import math

import numpy as np

from auv_ident.core.errors import DivergenceError, DomainError
from auv_ident.session.guard import (
    checked_coefficients,
    COV_BLOWUP_FACTOR,
    FUSED_CODES,
    GROSS_NIS_FACTOR,
    GUARD_PROBATION,
    GUARD_WINDOW,
    GuardWindow,
    LastGood,
    NisWindow,
    reset_start,
)

# the core errors an update raises that the caller's reset rule handles
FILTER_FAULTS = (DomainError, DivergenceError)


@dataclass(slots=True)
class Update:
    """What one odometry sample did to a :class:`GuardedFilter`.

    accepted, reason, code : the stream's outcome (core.filter.stream.Outcome)
    nis, dof : of the update (NaN, 0 if none was computed)
    estimate, std, cov : the checked parameters after an accepted update (else None)
    sustained : the divergence guard's inconsistency has lasted GUARD_SECONDS: reset
    good : the update became the last good estimate
    """

    accepted: bool
    reason: str
    code: str
    nis: float
    dof: int
    estimate: object = None
    std: object = None
    cov: object = None
    sustained: bool = False
    good: bool = False


class GuardedFilter:
    """A StreamIdentifier with the per-message rules of the module docstring.

    stream : the StreamIdentifier (replaced by :meth:`restart`)
    guard_on : the divergence guard is on (not in noise mode 'paper')

    Attributes the caller reads: stream, names (the identified parameters), theta0 (the
    start-up prior), nis_window and guard_window (guard.NisWindow, guard.GuardWindow),
    last_good (a guard.LastGood or None), probation (a fault reset, and the guard window not
    yet full and consistent since).
    """

    def __init__(self, stream, guard_on):
        self.stream = stream
        f = stream.ekf
        self.names = list(f.names)
        self.theta0 = f.theta0.copy()
        # a 1-sigma above this is a divergence; fixed by the start-up prior (resets keep it)
        self.std_limits = (COV_BLOWUP_FACTOR * f.prior_scale).tolist()
        self.guard_on = guard_on
        self.nis_window = NisWindow()       # the health window
        self.guard_window = GuardWindow()   # the divergence guard's window
        self.last_good = None
        self.probation = False
        self.reset_from_good = False    # the last reset started from last_good, none good since
        self._variances_of = None       # (filter, r): the variances last applied, and where

    @property
    def started(self):
        """True once the current stream's filter has fused a measurement."""
        return self.stream.ekf.xa is not None

    @property
    def applied_variances(self):
        """(12,) the message variances the filter last took (use_variances), or None."""
        return None if self._variances_of is None else self._variances_of[1]

    def use_variances(self, r):
        """Make r (12,) the measurement variances (fixed mode: R; adaptive modes: R0, the
        reference the adaptation starts from and is bounded by) unless they already are."""
        f = self.stream.ekf
        last = self._variances_of
        if last is not None and last[0] is f and np.array_equal(r, last[1]):
            return
        f.use_measurement_variances(r)
        self._variances_of = (f, r)

    def update(self, t, stamp_ns, y, r=None, trusted=True):
        """Fuse odometry y (12,) stamped t (s; stamp_ns its int ns) with measurement variances
        r (12,) or None (the filter's own); returns an :class:`Update`. Raises FILTER_FAULTS
        (module docstring, steps 2 and 3). trusted False: a sensor fault is active (the
        session's stuck-sensor rule), so the update cannot become the last good estimate."""
        stream = self.stream
        f = stream.ekf
        if r is not None:
            self.use_variances(r)
        out = stream.add_measurement(t, y)
        step = Update(out.accepted, out.reason, out.code, float(f.nis), int(f.dof))
        if out.accepted:
            step.estimate, step.cov, step.std = checked_coefficients(f, t, self.names,
                                                                     self.std_limits)
        fused = out.code in FUSED_CODES      # an update was computed
        nis, dof = step.nis, step.dof
        window = self.guard_window
        if fused and self.guard_on and dof > 0 and window.add(t, nis, dof):
            step.sustained = True
            return step
        if not out.accepted:
            return step
        if fused and dof > 0 and math.isfinite(nis):
            self.nis_window.add(nis, dof)
        if (self.probation and len(window) >= GUARD_WINDOW
                and window.median() <= GUARD_PROBATION):
            self.probation = False
        if (trusted and window.since is None and not self.probation
                and not self.gross_inconsistency()):
            step.good = True
            self.reset_from_good = False
            self.last_good = LastGood(stamp_ns, step.estimate, step.std, step.cov)
        return step

    def why_not_good(self):
        """Why the last accepted update did not become the last good estimate (one clause)."""
        window = self.guard_window
        if window.since is not None:
            return (f'innovations inconsistent since {window.since:.3f} s (guard median '
                    f'NIS/dof {window.median():.4g})')
        if self.probation:
            return (f'probation after the filter reset ({len(window)} of {GUARD_WINDOW} '
                    f'updates, median NIS/dof {window.median():.4g}, needs <= '
                    f'{GUARD_PROBATION:g})')
        return (f'mean NIS/dof {self.mean_nis_per_dof():.4g} over the last '
                f'{len(self.nis_window)} updates is more than {GROSS_NIS_FACTOR:g}x its '
                'chi-square band')

    # -- resets --

    def fault_start(self, code):
        """What a reset after a fault (code: 'core error', 'guard', 'internal error') starts
        the coefficients from: the last good estimate (a LastGood) or None, the start-up
        configuration (guard.reset_start). Remembered for the next fault."""
        start = reset_start(self.last_good, code, self.reset_from_good)
        self.reset_from_good = start is not None
        return start

    def restart(self, stream, fault=False):
        """Go on with a new stream: the windows start empty, the last good estimate stays;
        after a fault (fault True) the updates are on probation while the guard is on."""
        self.stream = stream
        self.nis_window.clear()
        self.guard_window.clear()
        if fault:
            self.probation = self.guard_on

    # -- the windows --

    def guard_median(self):
        """Median NIS/dof over the divergence guard's window (outliers included); NaN if
        empty."""
        return self.guard_window.median()

    def guard_inconsistent(self):
        """True if the divergence guard is on and its window is full and inconsistent."""
        return self.guard_on and self.guard_window.inconsistent()

    def mean_nis_per_dof(self):
        """Mean NIS per dof over the health window (NaN if empty)."""
        return self.nis_window.mean()

    def gross_inconsistency(self):
        """True if the health window's mean NIS/dof is above GROSS_NIS_FACTOR x the upper edge
        of its band (what the health rule reports as ERROR 'diverging'); such updates are not
        good. Judged once the window holds GUARD_WINDOW updates, with the divergence guard
        on."""
        window = self.nis_window
        return self.guard_on and len(window) >= GUARD_WINDOW and window.gross()

    # -- the estimate --

    def estimate_now(self):
        """(estimate, covariance) now: the filter's, the last good one, or the prior."""
        f = self.stream.ekf
        if f.xa is not None:
            return f.theta, f.theta_cov
        if self.last_good is not None:
            return self.last_good.estimate.copy(), self.last_good.cov.copy()
        return self.theta0.copy(), f.theta_cov0.copy()

    def best(self):
        """(estimate, covariance) to report: the last good one, else :meth:`estimate_now`."""
        if self.last_good is not None:
            return self.last_good.estimate.copy(), self.last_good.cov.copy()
        return self.estimate_now()
