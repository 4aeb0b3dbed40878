"""Streaming identification: pair odometry samples with actuator commands by stamp and step
the augmented EKF. The live identifier node and the offline bag replay both use this class,
so the same message sequence always gives the same estimates.

Pairing rule (deterministic: the same message sequence always gives the same result, and the
arrival order between the two topics does not matter as long as the command stamped t_{k-1}
arrives before the odometry stamped t_k, which a simulator or vehicle publishing both at each
sample guarantees):
the measurement stamped t_k is fused after a time update from t_{k-1} to t_k with the latest
actuator command whose stamp is <= t_{k-1} (zero-order hold: the command in force over the
interval). A gap longer than `max_substep` is bridged by several time updates of at most
`max_substep` each with the same command. A measurement whose stamp is not after the previous
one (duplicate, out of order, a looped bag) is rejected; so is one with no command at or before
t_{k-1}.
"""
import bisect
from dataclasses import dataclass

import numpy as np

from .identify import AugmentedEKF


@dataclass
class Outcome:
    """What happened to one measurement: accepted (stepped the filter) or why not."""

    accepted: bool
    reason: str = ''


class StreamIdentifier:
    """Online identification from time-stamped samples (t in seconds, float).

    Parameters
    ----------
    model, cfg : as AugmentedEKF
    T : nominal sample time (s), also the longest single time-update step
    max_gap : s; a gap longer than this restarts the vehicle states from the new measurement
        (the coefficient estimates and their covariance are kept)
    """

    def __init__(self, model, cfg, T, max_gap=5.0):
        self.ekf = AugmentedEKF(model, cfg, T)
        self.T = float(T)
        self.max_gap = float(max_gap)
        self.cmd_t = []
        self.cmd_u = []
        self.t_prev = None
        self.accepted = 0
        self.rejected = 0

    def add_command(self, t, u6):
        """Buffer an actuator command (fins rad, shaft rpm) stamped t."""
        u6 = np.asarray(u6, dtype=float)
        i = bisect.bisect_right(self.cmd_t, t)
        if i > 0 and self.cmd_t[i - 1] == t:
            self.cmd_u[i - 1] = u6          # same stamp: the later message wins
            return
        self.cmd_t.insert(i, t)
        self.cmd_u.insert(i, u6)
        # keep a short history: only commands at or after t_prev can still be used
        if self.t_prev is not None and len(self.cmd_t) > 64:
            j = bisect.bisect_right(self.cmd_t, self.t_prev) - 1
            if j > 0:
                del self.cmd_t[:j]
                del self.cmd_u[:j]

    def command_at(self, t):
        """The command in force at t (latest stamp <= t), or None."""
        i = bisect.bisect_right(self.cmd_t, t)
        return self.cmd_u[i - 1] if i > 0 else None

    def add_measurement(self, t, y12):
        """Fuse a measurement stamped t (NaN entries: channel missing). Returns an Outcome."""
        f = self.ekf
        if self.t_prev is None or f.xa is None:
            u = self.command_at(t)
            if u is None:
                self.rejected += 1
                return Outcome(False, 'no actuator command at or before the first odometry')
            f.start(y12, u[5])
            self.t_prev = t
            self.accepted += 1
            return Outcome(True)
        dt = t - self.t_prev
        if not dt > 0.0:
            self.rejected += 1
            return Outcome(False, f'stamp {t:.9f} s is not after the previous one '
                                  f'({self.t_prev:.9f} s): duplicate or out of order')
        u = self.command_at(self.t_prev)
        if u is None:
            self.rejected += 1
            return Outcome(False, f'no actuator command at or before {self.t_prev:.9f} s')
        if dt > self.max_gap:
            keep_theta, keep_cov = f.xa[12:].copy(), f.P[12:, 12:].copy()
            f.start(y12, u[5])
            f.xa[12:] = keep_theta
            f.P[12:, 12:] = keep_cov
            f.P[:12, 12:] = 0.0
            f.P[12:, :12] = 0.0
            self.t_prev = t
            self.accepted += 1
            return Outcome(True, f'gap of {dt:.3f} s: vehicle states restarted')
        n_sub = max(1, int(np.ceil(dt / self.T - 1e-9)))
        h = dt / n_sub
        for _ in range(n_sub):
            f.predict(u, h)
        f.update(y12)
        self.t_prev = t
        self.accepted += 1
        return Outcome(True)
