"""The identifier session's status: its counters, its health and the /diagnostics values.

:class:`Counters` counts what the messages did (accepted, rejected by reason, outliers,
repairs, resets, ...) and applies the health rule (guard.judge_health) to a filter;
:func:`diagnostic_values` is the list of (key, text) the identifier node publishes on
/diagnostics (the keys are documented in ros/identifier_node.py's module docstring), so that
the node only wraps them into a message.
"""
from collections import Counter
import math

import numpy as np

from auv_ident.core.model.state import STATE_NAMES
from auv_ident.session.guard import judge_health


class Counters:
    """What the session's messages did, as /diagnostics counts it.

    odom_accepted, odom_rejected, cmd_accepted, cmd_rejected : messages per topic
    reasons : Counter of the rejections by '<topic>: <code>'
    outliers, repairs, time_jumps : the stream's innovation-gate rejections, covariance
        repairs and confirmed backward time jumps
    errors, guard_resets, last_error : filter resets by the reset rule (of which by the
        divergence guard) and the reason of the last one
    last_nis, last_dof : of the last accepted update
    since_reset : accepted updates since the last fault reset (None: no reset yet; the health
        rule reports ERROR until NIS_WINDOW have passed)
    """

    def __init__(self):
        self.odom_accepted = 0
        self.odom_rejected = 0
        self.cmd_accepted = 0
        self.cmd_rejected = 0
        self.errors = 0
        self.last_error = ''
        self.reasons = Counter()
        self.outliers = 0
        self.repairs = 0
        self.guard_resets = 0
        self.time_jumps = 0
        self.last_nis = math.nan
        self.last_dof = 0
        self.since_reset = None

    def rejected(self, what, code):
        """A message of topic what ('odom' or 'actuators') rejected with code."""
        if what == 'odom':
            self.odom_rejected += 1
        else:
            self.cmd_rejected += 1
        self.reasons[f'{what}: {code}'] += 1

    def filtered(self, code):
        """The stream's code of an odometry sample it took or rejected."""
        if code == 'repaired':
            self.repairs += 1
        elif code == 'time jump':
            self.time_jumps += 1
        elif code == 'outlier':
            self.outliers += 1

    def updated(self, nis, dof):
        """An accepted odometry update with this NIS over dof channels."""
        self.odom_accepted += 1
        self.last_nis, self.last_dof = nis, dof
        if self.since_reset is not None:
            self.since_reset += 1

    def fault(self, reason):
        """A filter reset by the reset rule, for reason."""
        self.errors += 1
        self.last_error = reason
        self.since_reset = 0

    def new_filter(self, nis, dof):
        """Another filter takes over (the 'auto' switch): the resets were the previous one's;
        nis, dof of its last update."""
        self.since_reset = None
        self.last_nis, self.last_dof = nis, dof

    def health(self, filt):
        """The health of filt (a GuardedFilter) by the rule of guard.judge_health."""
        est, cov = filt.estimate_now()
        return judge_health(filt.nis_window, filt.guard_inconsistent(), self.since_reset,
                            filt.started, est, cov)


def _num(v):
    v = float(v)
    return repr(v) if np.isfinite(v) else 'n/a'


def diagnostic_values(session, health, own=()):
    """[(key, text)] of the /diagnostics status of an IdentSession with this health (its
    health()): the counters, then own (the caller's (key, text) counts, e.g. the node's
    internal_errors), last_error, the stuck-sensor rule's (session/stuck.py: 'repeated',
    channel-group samples not fed because they repeated exactly; 'stuck_sensor', the active
    fault or 'none'), the health window, the guard, the last update, the diagnosis, per
    parameter its last good value, 1-sigma and verdict, the 'auto' choice's values, the noise
    learner's (session/noise_learning.py; with learn_noise on in noise mode fixed), and the
    filter's R and Q diagonals. Floats are repr, 'n/a' if not finite."""
    s = session
    c = s.counters
    filt = s.filter
    f = filt.stream.ekf
    est, cov = s.best()
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    values = [('accepted', str(c.odom_accepted)), ('rejected', str(c.odom_rejected)),
              ('commands', str(c.cmd_accepted)), ('commands_rejected', str(c.cmd_rejected)),
              ('errors', str(c.errors)), ('guard_resets', str(c.guard_resets)),
              ('outliers', str(c.outliers)), ('repairs', str(c.repairs)),
              ('time_jumps', str(c.time_jumps))]
    values += list(own)
    values += [('last_error', c.last_error),
               ('repeated', str(s.stuck.repeats)),
               ('stuck_sensor', s.stuck.describe_active() or 'none'),
               ('mean_nis_per_dof', _num(health.mean_nis_per_dof)),
               ('nis_band', f'{_num(health.band[0])} {_num(health.band[1])}'),
               ('nis_window', str(health.window)),
               ('guard_median_nis_per_dof', _num(filt.guard_median())),
               ('last_nis', _num(c.last_nis)), ('last_dof', str(c.last_dof)),
               ('last_stamp', 'n/a' if filt.last_good is None
                else _num(filt.last_good.stamp_ns * 1e-9))]
    verdicts, diagnosis = s.diagnosis(health)
    values += [('consistent', {True: 'true', False: 'false', None: 'not judged'}[
        diagnosis['consistent']]), ('diagnosis', diagnosis['messages'][0])]
    values += [(f'diagnosis_{i}', m) for i, m in enumerate(diagnosis['messages'][1:], 1)]
    for name, v, sd in zip(s.names, est, std):
        values += [(name, _num(v)), (name + '_std', _num(sd)),
                   (name + '_verdict', verdicts[name]['verdict'])]
    if s.auto is not None:
        values += s.auto.diagnostic_values()
    if s.noise.enabled:
        values += s.noise.diagnostic_values()
    values += [('R_' + n, _num(v)) for n, v in zip(STATE_NAMES, np.diag(f.R))]
    values += [('Q_' + n, _num(v)) for n, v in zip(s.names, np.diag(f.Q)[12:])]
    return values
