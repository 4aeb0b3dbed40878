"""The identifier session's status: its counters, its health and the /diagnostics values.

:class:`Counters` counts what the messages did (accepted, rejected by reason, outliers,
repairs, resets, ...) and applies the health rule (guard.judge_health) to a filter;
:func:`diagnostic_values` is the list of (key, text) the identifier node publishes on
/diagnostics (the keys are documented in ros/identifier_node.py's module docstring), so that
the node only wraps them into a message.
"""
from collections import Counter, deque
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


class StampGaps:
    """Messages lost before the session saw them, judged from the gaps in their stamps against
    the rate they are observed at.

    A subscription queue that overflows (KEEP_LAST drops the oldest when the callback falls
    behind) drops messages silently: rclpy's message-lost event is not raised for it with
    Fast DDS (measured: a 2 kHz stream into a depth-10 queue, RELIABLE or BEST_EFFORT, lost 85
    to 95 % and the event never came; docs/reliability.md). What shows is the stamps: a stream
    sampled every dt that arrives with an interval of k dt lost k - 1 messages.

    The nominal interval is the median of the last WINDOW intervals that were not gaps (the
    first estimate, from MIN_INTERVALS intervals, holds while fewer than half of them are gaps:
    37 % of a stream lost in runs of one to three makes about a fifth of them; a lower
    quantile would take the jitter of the stamps for gaps); an interval longer than GAP_FACTOR
    times it counts round(dt / nominal) - 1 lost, up to max_gap_s (longer: a pause of the
    source, not a queue; the stream's own gap rule handles it). Nothing is judged before
    MIN_INTERVALS intervals; a stamp equal to the last is skipped, one before it (out of
    order, a time jump) too, except that one inside the last gap counted is taken off it (it
    came late, not never).

    lost : messages lost so far; seen : stamps seen; interval_s : the nominal interval (s,
    NaN until known)."""

    WINDOW = 200
    MIN_INTERVALS = 20
    GAP_FACTOR = 1.5
    REFRESH = 50        # intervals between two estimates of the nominal one

    def __init__(self, max_gap_s):
        self.max_gap_ns = float(max_gap_s) * 1e9
        self.lost = 0
        self.seen = 0
        self.interval_s = math.nan
        self._last = None
        self._intervals = deque(maxlen=self.WINDOW)
        self._since = 0
        self._gap = (0, 0, 0)       # (from, to, lost) of the last gap counted

    @property
    def expected(self):
        """Messages the stamps imply were sent (seen + lost)."""
        return self.seen + self.lost

    def see(self, stamp_ns):
        """One message's stamp (int ns); returns how many it shows lost before it (-1: it
        arrived late into the last gap, which had counted it lost)."""
        self.seen += 1
        last = self._last
        if last is None or stamp_ns > last:
            self._last = stamp_ns
        if last is None or stamp_ns == last:
            return 0
        if stamp_ns < last:
            start, end, missed = self._gap
            if start < stamp_ns < end and missed > 0:
                self._gap = (start, end, missed - 1)
                self.lost -= 1
                return -1
            return 0
        dt = float(stamp_ns - last)
        nominal = self.interval_s * 1e9
        if math.isfinite(nominal) and dt > self.GAP_FACTOR * nominal:
            if dt > self.max_gap_ns:
                return 0
            missed = int(round(dt / nominal)) - 1
            self.lost += missed
            self._gap = (last, stamp_ns, missed)
            return missed
        self._intervals.append(dt)
        self._since += 1
        if len(self._intervals) >= self.MIN_INTERVALS and (
                self._since >= self.REFRESH or not math.isfinite(nominal)):
            self._since = 0
            self.interval_s = float(np.median(self._intervals)) * 1e-9
        return 0


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
    values += [('odom_lost', str(s.odom_gaps.lost)),
               ('odom_rate_hz', _num(1.0 / s.odom_gaps.interval_s))]
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
