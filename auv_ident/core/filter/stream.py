"""Streaming identification: pair odometry samples with actuator commands by stamp and step
the augmented EKF. The live identifier node and the offline bag replay both use this class,
so the same message sequence always gives the same estimates.

Pairing rule (deterministic: the same message sequence always gives the same result, and the
arrival order between the two topics does not matter as long as the command stamped t_{k-1}
arrives before the odometry stamped t_k; a command published after the odometry of its own
stamp t_k is still paired by its stamp, it is first used for the interval after t_k):
the measurement stamped t_k is fused after a time update from t_{k-1} to t_k with the
commands in force over the interval (zero-order hold): the latest command stamped <= t_{k-1},
and every command stamped inside (t_{k-1}, t_k) from its stamp on (the interval is crossed in
pieces; commands that arrived before the odometry t_k), by the rules of
:mod:`auv_ident.core.filter.timing`, which the batch methods follow too:
the interval at 1 ns resolution, RK4 steps of at most T with the command held, and a restart
of the vehicle states (below) after an interval longer than `max_bridge` (s).
Holding the last command is the norm whatever its age: a driver that publishes commands only
when they change sends nothing while a fin is held. With `max_command_age` (s) set, a
measurement whose command in force is stamped more than that before t_{k-1} is rejected
('stale command': for a vehicle that repeats its commands, a silent actuator topic means it
stopped, and holding its last command would feed the filter a wrong input).
A measurement whose stamp is not after the previous one (duplicate, out of order) is
rejected; so is one with no command at or before t_{k-1}. A restart after a gap (below) takes
only the shaft speed of the latest command at or before t_k, whatever its age (no time update
uses it). If a command stamped after the one in force and before t_k was rejected by
the caller
(:meth:`StreamIdentifier.command_rejected`), the command over the interval is unknown and the
measurement is rejected too ('command unknown'): holding the older command would feed the
filter the wrong input.

Time rules (t_prev: stamp of the last fused measurement; every rejection has a short `code`):

- stamp 0 after a non-zero stamp: rejected, code 'zero stamp' (an unset header.stamp; a
  stream may legitimately *start* at 0, simulation time does);
- t == t_prev: 'duplicate stamp'; t_prev - max_gap <= t < t_prev: 'out of order';
- t > t_prev + max_bridge (a forward jump, e.g. a link drop-out, or a run of rejected
  messages): the vehicle states restart from this measurement, coefficients and their
  covariance kept (accepted, code 'gap'; AugmentedEKF.restart);
- t < t_prev - max_gap (a backward jump: a bag looped, a clock reset): rejected, code
  'time jump backwards', until JUMP_CONFIRM (5) such messages in a row agree among
  themselves (each after the previous one by at most max_gap); the fifth restarts the
  vehicle states as for a forward jump (code 'time jump') and the command buffer is replaced
  by the commands that arrived stamped before t_prev - max_gap (the new time line's). A
  single stale or bogus stamp therefore never moves the time line.

Commands: a command stamped like a buffered one replaces it (the later message wins); one
stamped more than max_gap before t_prev is held apart for a backward jump (at most
CMD_BUFFER_MAX, the oldest dropped); the buffer in use is pruned to the commands from the one
in force at t_prev on, and never holds more than CMD_BUFFER_MAX (a missing odometry topic
cannot grow it).

Filter faults (see :meth:`StreamIdentifier._fuse`): a measurement update that fails because
the covariance is not positive definite is retried once after
:func:`auv_ident.core.filter.augmented.repair_covariance` (symmetrise, floor the scaled
eigenvalues); an update that leaves a covariance without a Cholesky factor is repaired the same
way. Both are counted in `repairs` and noted in the Outcome (code 'repaired'). What cannot be
repaired (non-finite state or covariance, a second failure, a state outside the model's domain)
raises DivergenceError / DomainError for the caller's reset rule. With an innovation gate
(`gate`), an update whose NIS exceeds it is not fused (code 'outlier'); the time update to its
stamp stands.
"""
import bisect
from collections import deque
from dataclasses import dataclass
import math

import numpy as np

from auv_ident.core.errors import ConfigError, DivergenceError
from auv_ident.core.filter.augmented import (
    AugmentedEKF,
    FilterConfig,
    is_positive_definite,
    repair_covariance,
)
from auv_ident.core.filter.timing import DEFAULT_MAX_BRIDGE, interval, time_step
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import Input

JUMP_CONFIRM = 5          # messages in a row that confirm a backward time jump
CMD_BUFFER_MAX = 4096     # most commands held (each buffer)
_PRUNE_AT = 64


@dataclass
class Outcome:
    """What happened to one message: accepted (stepped the filter / buffered) or why not.

    code : short category ('' for a plain accepted update), the key rejections are counted by
    """

    accepted: bool
    reason: str = ''
    code: str = ''


class StreamIdentifier:
    """Online identification from time-stamped samples (t in seconds, float).

    Parameters
    ----------
    model, cfg : as AugmentedEKF
    T : nominal sample time (s), also the longest single time-update step
    max_gap : s; a gap longer than this restarts the vehicle states from the new measurement
        (the coefficient estimates and their covariance are kept)
    gate : None, or (13,) largest NIS accepted from an update with m = 0..12 channels
    max_bridge : s, longest gap bridged by time updates (None: timing.DEFAULT_MAX_BRIDGE,
        0.25 s; at most max_gap); a longer one restarts the vehicle states
    max_command_age : s, or None (no limit, the default): a measurement whose command in force
        is older than this is rejected as 'stale command'
    """

    def __init__(self, model: Model, cfg: FilterConfig, T: float, max_gap: float = 5.0,
                 gate: np.ndarray | None = None, max_bridge: float | None = None,
                 max_command_age: float | None = None) -> None:
        self.ekf = AugmentedEKF(model, cfg, T)
        self.ekf.gate = gate
        self.T = float(T)
        self.max_gap = float(max_gap)
        self.max_bridge = min(DEFAULT_MAX_BRIDGE if max_bridge is None else float(max_bridge),
                              self.max_gap)
        if max_command_age is not None and not float(max_command_age) >= 0.0:
            raise ConfigError(f'max_command_age = {max_command_age!r} s must be >= 0 or None')
        self.max_command_age = None if max_command_age is None else float(max_command_age)
        self.cmd_t: list[float] = []
        self.cmd_u: list[np.ndarray] = []
        self.cmd_latest: float | None = None      # largest command stamp seen
        # (t, u7) held for a backward jump
        self.cmd_jump: deque[tuple[float, np.ndarray]] = deque(maxlen=CMD_BUFFER_MAX)
        self.cmd_bad: list[float] = []           # sorted stamps of recently rejected commands
        self.t_prev: float | None = None
        self.accepted = 0
        self.rejected = 0
        self.repairs = 0
        self.outliers = 0
        self.jumps = 0
        self._jump: list[float] = []   # stamps of the messages of a pending backward jump

    # -- commands --

    def add_command(self, t: float, u7: np.ndarray) -> Outcome:
        """Buffer an actuator command u7 (7,: fins rad, shaft rpm, thrust N) stamped t.
        Returns an Outcome."""
        u7 = np.asarray(u7, dtype=float)
        if t == 0.0 and self.cmd_latest is not None and self.cmd_latest > 0.0:
            return Outcome(False, f'zero stamp after {self.cmd_latest:.9f} s (header.stamp not '
                                  'set?)', 'zero stamp')
        self.cmd_latest = t if self.cmd_latest is None else max(self.cmd_latest, t)
        if self.t_prev is not None and t < self.t_prev - self.max_gap:
            self.cmd_jump.append((t, u7))
            return Outcome(True, f'stamp {t:.9f} s more than max_gap before the odometry '
                                 f'({self.t_prev:.9f} s): held for a time jump', 'held')
        i = bisect.bisect_right(self.cmd_t, t)
        if i > 0 and self.cmd_t[i - 1] == t:
            self.cmd_u[i - 1] = u7          # same stamp: the later message wins
            return Outcome(True)
        self.cmd_t.insert(i, t)
        self.cmd_u.insert(i, u7)
        # keep a short history: only commands at or after t_prev can still be used
        if self.t_prev is not None and len(self.cmd_t) > _PRUNE_AT:
            j = bisect.bisect_right(self.cmd_t, self.t_prev) - 1
            if j > 0:
                del self.cmd_t[:j]
                del self.cmd_u[:j]
        if len(self.cmd_t) > CMD_BUFFER_MAX:
            k = len(self.cmd_t) - CMD_BUFFER_MAX
            del self.cmd_t[:k]
            del self.cmd_u[:k]
        return Outcome(True)

    def command_rejected(self, t: float) -> None:
        """Note that the caller rejected a command stamped t (see the module docstring)."""
        if t is None or not np.isfinite(t):
            return
        bisect.insort(self.cmd_bad, t)
        if self.t_prev is not None and self.cmd_bad[0] < self.t_prev - self.max_gap:
            k = bisect.bisect_left(self.cmd_bad, self.t_prev - self.max_gap)
            del self.cmd_bad[:k]
        if len(self.cmd_bad) > CMD_BUFFER_MAX:
            del self.cmd_bad[:len(self.cmd_bad) - CMD_BUFFER_MAX]

    def command_at(self, t: float) -> np.ndarray | None:
        """The command in force at t (latest stamp <= t), or None."""
        i = bisect.bisect_right(self.cmd_t, t)
        return self.cmd_u[i - 1] if i > 0 else None

    def copy_commands_from(self, other: 'StreamIdentifier') -> None:
        """Take over another stream's buffered commands (after a filter restart)."""
        self.cmd_t = list(other.cmd_t)
        self.cmd_u = list(other.cmd_u)
        self.cmd_latest = other.cmd_latest
        self.cmd_jump = deque(other.cmd_jump, maxlen=CMD_BUFFER_MAX)
        self.cmd_bad = list(other.cmd_bad)

    # -- measurements --

    def _reject(self, reason: str, code: str) -> Outcome:
        self.rejected += 1
        return Outcome(False, reason, code)

    def add_measurement(self, t: float, y12: np.ndarray) -> Outcome:
        """Fuse a measurement stamped t (NaN entries: channel missing). Returns an Outcome."""
        f = self.ekf
        if self.t_prev is None or f.xa is None:
            u = self.command_at(t)
            if u is None:
                return self._reject('no actuator command at or before the first odometry '
                                    f'({t:.9f} s)', 'no command')
            f.start(y12, u[Input.N_RPM])
            self.t_prev = t
            self._jump = []
            self.accepted += 1
            return Outcome(True)
        if t == 0.0 and self.t_prev > 0.0:
            return self._reject(f'zero stamp after {self.t_prev:.9f} s (header.stamp not '
                                'set?)', 'zero stamp')
        dt = interval(self.t_prev, t)
        if dt < -self.max_gap:
            return self._backward_jump(t, y12)
        if not dt > 0.0:
            return self._reject(f'stamp {t:.9f} s is not after the previous one '
                                f'({self.t_prev:.9f} s): duplicate or out of order',
                                'duplicate stamp' if dt == 0.0 else 'out of order')
        n_sub, h = time_step(dt, self.T, self.max_bridge)
        restart = n_sub == 0
        # the command in force: at t_prev over the interval, or at t for a restart after a gap
        t_cmd = t if restart else self.t_prev
        i = bisect.bisect_right(self.cmd_t, t_cmd)
        if i == 0:
            return self._reject(f'no actuator command at or before {t_cmd:.9f} s',
                                'no command')
        u = self.cmd_u[i - 1]
        age = t_cmd - self.cmd_t[i - 1]
        limit = self.max_command_age
        if limit is not None and age > limit and not restart:     # a restart uses only its rpm
            return self._reject(f'stale command: the latest actuator command in force at '
                                f'{t_cmd:.9f} s is {age:.3f} s old (more than {limit:g} s); '
                                'is the actuator topic still published?', 'stale command')
        if not restart and self.cmd_bad:
            # a rejected command stamped while the interval is crossed (after the one in force,
            # before t) leaves the input of part of the interval unknown
            j = bisect.bisect_right(self.cmd_bad, self.cmd_t[i - 1])
            if j < len(self.cmd_bad) and self.cmd_bad[j] < t:
                return self._reject(f'command unknown: the actuator command stamped '
                                    f'{self.cmd_bad[j]:.9f} s (after the one in force, '
                                    f'{self.cmd_t[i - 1]:.9f} s) was rejected',
                                    'command unknown')
        self._jump = []
        if restart:
            f.restart(y12, u[Input.N_RPM])
            if dt > self.max_gap:
                self.cmd_jump.clear()
            self.t_prev = t
            self.accepted += 1
            return Outcome(True, f'gap of {dt:.3f} s: vehicle states restarted', 'gap')
        # zero-order hold: a command stamped inside (t_prev, t) takes over at its stamp, so the
        # interval is crossed in pieces, each with the command in force over it
        k = bisect.bisect_right(self.cmd_t, self.t_prev)
        if k < len(self.cmd_t) and self.cmd_t[k] < t:
            a = self.t_prev
            while k < len(self.cmd_t) and self.cmd_t[k] < t:
                self._cross(a, self.cmd_t[k], u)
                a, u = self.cmd_t[k], self.cmd_u[k]
                k += 1
            self._cross(a, t, u)
        else:
            for _ in range(n_sub):
                f.predict(u, h)
        return self._fuse(t, y12)

    def _cross(self, a: float, b: float, u: np.ndarray) -> None:
        """Time update from a to b (s) with the command u held, in steps of at most T."""
        dt = interval(a, b)
        if dt > 0.0:
            n, h = time_step(dt, self.T, math.inf)
            for _ in range(n):
                self.ekf.predict(u, h)

    def _backward_jump(self, t: float, y12: np.ndarray) -> Outcome:
        assert self.t_prev is not None       # a jump is back from a previous measurement
        gap = self.t_prev - t
        if self._jump and 0.0 < t - self._jump[-1] <= self.max_gap:
            self._jump.append(t)
        else:
            self._jump = [t]
        n = len(self._jump)
        what = (f'time jump backwards of {gap:.3f} s (stamp {t:.9f} s after '
                f'{self.t_prev:.9f} s)')
        if n < JUMP_CONFIRM:
            return self._reject(f'{what}: {n} of {JUMP_CONFIRM} consistent messages to '
                                'restart the time line', 'time jump backwards')
        # confirmed: the commands held for the new time line replace the buffer
        held = {}
        for tc, uc in self.cmd_jump:        # arrival order: a later same-stamp one wins
            held[tc] = uc
        cmd_t = sorted(held)
        u = None
        i = bisect.bisect_right(cmd_t, t)
        if i > 0:
            u = held[cmd_t[i - 1]]
        if u is None:
            return self._reject(f'{what}: confirmed, but no actuator command of the new time '
                                'line at or before it', 'no command')
        self.cmd_t = cmd_t
        self.cmd_u = [held[tc] for tc in cmd_t]
        self.cmd_jump.clear()
        f = self.ekf
        f.restart(y12, u[Input.N_RPM])
        self.t_prev = t
        self._jump = []
        self.jumps += 1
        self.accepted += 1
        return Outcome(True, f'{what}: confirmed by {n} messages, vehicle states restarted',
                       'time jump')

    def _fuse(self, t: float, y12: np.ndarray) -> Outcome:
        """Measurement update after the time update to t, with the repair rule (docstring)."""
        f = self.ekf
        note = ''
        try:
            f.update(y12)
        except DivergenceError:
            if not np.all(np.isfinite(f.xa)):
                raise
            f.P, lam = repair_covariance(f.P, f.reference_std())
            self.repairs += 1
            f.update(y12)                   # a second failure goes to the caller
            note = (f'covariance not positive definite before the update (smallest scaled '
                    f'eigenvalue {lam:.3g}): repaired')
        self.t_prev = t
        if f.gated and f.gate is not None:      # only a gate gates
            self.outliers += 1
            return self._reject(f'outlier: NIS {f.nis:.4g} over {f.dof} channel(s) above the '
                                f'gate {f.gate[f.dof]:.4g}', 'outlier')
        if not is_positive_definite(f.P):
            f.P, lam = repair_covariance(f.P, f.reference_std())
            self.repairs += 1
            note = (f'covariance not positive definite after the update (smallest scaled '
                    f'eigenvalue {lam:.3g}): repaired')
        self.accepted += 1
        return Outcome(True, note, 'repaired' if note else '')
