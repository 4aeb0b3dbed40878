"""The live identifier's noise model, learnt from its own innovations as it runs.

Offline, ``identify`` reads the measurement noise's level and colour off the whitened
innovations of a first EKF pass and runs the pass again with it
(core/identification/noise_fit.py). Live there is one pass, under way; :class:`NoiseLearner`
does the same from the running filter:

1. it keeps every accepted command and odometry sample (as the 'auto' choice keeps its window,
   session/auto_choice.py) and the whitened innovations of the last LEARN_WINDOW fused updates;
2. every LEARN_EVERY accepted updates, once LEARN_MIN_UPDATES have been fused, it fits per
   measured channel the level (RMS) and the lag-1 autocorrelation rho of those innovations
   (core.identification.uncertainty.noise_model) and the variance factor
   ``level^2 (1 + rho) / (1 - rho)``: the variance a white noise would need to carry the
   information the channel really carries about slowly varying quantities such as the
   coefficients (the long-run variance of an AR(1) process; noise_fit.effective_std);
3. the noise model holds when every channel's factor is within NOISE_MODEL_CHANGE of 1 either way
   (noise_fit's rule) or within FIT_SIGMAS standard errors of its logarithm (a fit of strongly
   correlated noise is uncertain: with rho 0.9, 600 innovations carry the information of ~30
   independent ones, and the factor scatters by ~30 %; the standard error :func:`log_factor_sd`).
   Measured with the plain 1.5x rule alone: runs with the model learnt flipped to NOT consistent
   and back on that scatter. Otherwise the learnt variance scale of every fitted channel is
   multiplied by its factor and a filter from the start-up configuration is fed the whole kept
   record with the measurement variances times that scale (the offline second pass, online); it
   replaces the running filter (its estimate, covariance, windows and last good estimate). The
   re-run runs in the session's runner (the node's: a worker thread, as the 'auto' choice; the
   running filter takes and keeps the messages meanwhile, and the re-run filter is fed them before
   it takes over at the next message after it ends: IdentSession.poll_noise; the fits due among
   those messages are made then, as if it had taken over at once, so that the live node ends
   where replay_bag does: NoiseLearner.rerun_done). Its innovations are
   whitened by the new variances, so the next fit of a learnt model gives factors near 1: a fixed
   point. A re-run costs one filter pass over the record (~0.6 ms per sample), so one is made only
   once the record holds RERUN_GROWTH times the samples of the last one (at 200, 400, 800, ...
   samples): all re-runs together cost at most about twice one pass over the final record, however
   long the run. A fit that is off meanwhile leaves the estimate NOT consistent until the next
   re-run and a fit after it. The record is kept up to KEEP_LIMIT odometry samples; after that no
   more re-runs.

Until a fit has found the model holding, the estimate is NOT consistent (live_diagnosis.py):
the error bars of a filter whose noise model is wrong do not hold. Before the first fit nothing
is judged. White noise of the configured level gives factors near 1: nothing changes (the same
estimates as without learning). Only in noise mode 'fixed' (the adaptive modes adapt R
themselves).
"""
from concurrent.futures import Future
from dataclasses import dataclass
import math

import numpy as np

from auv_ident.core.identification.noise_fit import MAX_RHO, NOISE_MODEL_CHANGE
from auv_ident.core.identification.uncertainty import noise_model
from auv_ident.core.model.state import N_INPUT, N_STATE, STATE_NAMES
from auv_ident.session.auto_choice import ChosenFilter, COMMAND, COMMAND_REJECTED, ODOMETRY
from auv_ident.session.record import Rows

LEARN_MIN_UPDATES = 200     # fused updates before the first fit (the health window's length)
LEARN_EVERY = 100           # then a fit every this many accepted updates
LEARN_WINDOW = 6000         # the fit reads the whitened innovations of the last this many
FIT_SIGMAS = 3.5            # a factor this many standard errors of its log from 1 is off
RERUN_GROWTH = 2.0          # a re-run once the record is this many times the last one's
KEEP_LIMIT = 36000          # odometry samples kept at most (1 h at 10 Hz; ~11 MB: KeptRecord)
LEARNING, HOLDS, RELEARNT, OFF = 'learning', 'holds', 'relearnt', 'off'
FUSED_OK = ('', 'repaired')     # stream codes of an accepted, fused update


class KeptRecord:
    """The learner's record of accepted commands, rejected command stamps and odometry
    samples, in arrival order, in compact arrays (session/record.py Rows): at 200 Hz the
    record of entry tuples took about 0.9 KB a sample and the live node's memory grew by 21 MB
    in the 120 s load test; these rows take about 0.3 KB. :meth:`entries` gives back the
    tuples auto_choice's ChosenFilter.feed takes."""

    _ODOM_WIDTH = 1 + N_STATE + N_STATE + 2    # t, y, r, r given (1/0), trusted (1/0)

    def __init__(self, n_inputs=N_INPUT):
        self.n_inputs = n_inputs                           # the vehicle's input vector length
        self.order = Rows(1, dtype=np.int8)                # COMMAND, COMMAND_REJECTED, ODOMETRY
        self.commands = Rows(1 + n_inputs)                 # t, u (NaN for a rejected one)
        self.odometry = Rows(self._ODOM_WIDTH)
        self.stamps = Rows(1, dtype=np.int64)              # stamp_ns of each odometry row

    def __len__(self):
        return len(self.order)

    def add_command(self, t, u):
        self.order.append(KIND_CODE[COMMAND])
        self.commands.append(t, u)

    def add_rejected(self, t):
        self.order.append(KIND_CODE[COMMAND_REJECTED])
        self.commands.append(t, np.full(self.n_inputs, np.nan))

    def add_odometry(self, t, stamp_ns, y, r, trusted):
        self.order.append(KIND_CODE[ODOMETRY])
        given = r is not None
        self.odometry.append(t, y, r if given else np.zeros(N_STATE), float(given),
                             float(trusted))
        self.stamps.append(stamp_ns)

    def restart_at(self, t):
        """A new time line from t (s) on: the odometry is dropped, the commands stamped up
        to t are kept (they may be the new line's, as auto_choice keeps them)."""
        kinds = self.order.array[:, 0]
        command_kinds = kinds[kinds != KIND_CODE[ODOMETRY]]
        commands = self.commands.array
        keep = commands[:, 0] <= t
        kept_kinds, kept_rows = command_kinds[keep].copy(), commands[keep].copy()
        self.__init__()
        for kind, row in zip(kept_kinds, kept_rows):
            self.order.append(kind)
            self.commands.append(row)

    def entries(self, default_variances, scale, start=0):
        """The entries from start on as tuples, each odometry sample's variances (the
        default_variances (12,) where it stated none) times scale (12,)."""
        kinds = self.order.array[:, 0]
        is_odometry = kinds == KIND_CODE[ODOMETRY]
        i_odom = int(np.count_nonzero(is_odometry[:start]))
        i_cmd = start - i_odom
        commands, odometry = self.commands.array, self.odometry.array
        stamps = self.stamps.array[:, 0]
        out = []
        n = N_STATE
        for kind in kinds[start:]:
            if kind == KIND_CODE[ODOMETRY]:
                row = odometry[i_odom]
                r = row[1 + n:1 + 2 * n] if row[1 + 2 * n] else default_variances
                out.append((ODOMETRY, float(row[0]), int(stamps[i_odom]),
                            row[1:1 + n].copy(), r * scale, bool(row[2 + 2 * n])))
                i_odom += 1
            else:
                row = commands[i_cmd]
                out.append((COMMAND, float(row[0]), row[1:].copy()) if kind == KIND_CODE[COMMAND]
                           else (COMMAND_REJECTED, float(row[0])))
                i_cmd += 1
        return out


KIND_CODE = {COMMAND: 0, COMMAND_REJECTED: 1, ODOMETRY: 2}


class InnovationWindow:
    """The last `size` whitened innovations (12,) in arrival order, for the fits.

    Rows go into a preallocated (2 size, 12) array; :meth:`rows` is a view of the last `size`
    of them, oldest first. When the array is full its last size - 1 rows move to the front
    (once every size + 1 appends). The array (1.2 MB for 6000 rows) is made at the first
    append: a session that does not learn never has it. Measured: the deque of (12,) arrays
    it replaces cost a new array per update and 1.2 ms to turn into one array at each fit
    (6000 rows); an append here is one row copy and a fit's rows cost nothing."""

    def __init__(self, size, width=N_STATE):
        self.size = int(size)
        self.width = int(width)
        self.buffer = None
        self.end = 0            # rows [start, end) of buffer hold the window
        self.start = 0

    def __len__(self):
        return self.end - self.start

    def append(self, row):
        """Add one innovation (width,), dropping the oldest beyond size."""
        if self.buffer is None:
            self.buffer = np.empty((2 * self.size, self.width))
        if self.end == self.buffer.shape[0]:
            keep = self.size - 1
            self.buffer[:keep] = self.buffer[self.end - keep:self.end]
            self.start, self.end = 0, keep
        self.buffer[self.end] = row
        self.end += 1
        if self.end - self.start > self.size:
            self.start += 1

    def clear(self):
        self.start = self.end = 0

    def rows(self):
        """(len, width) view of the window, oldest first (valid until the next append)."""
        if self.buffer is None:
            return np.empty((0, self.width))
        return self.buffer[self.start:self.end]


@dataclass
class Rerun:
    """A re-run under way: its Future (of :func:`rerun`'s result), the scale (12,) it runs
    with, and the kept entries it took."""

    future: Future
    scale: np.ndarray
    taken: int


def rerun(stream, guard_on, entries, fed=None):
    """Feed entries (the kept record with the learnt variances, NoiseLearner.entries) to a
    GuardedFilter of stream (fed None: a new ChosenFilter of it; else fed goes on); returns
    (fed, the whitened innovations (12,) of its fused updates). Raises
    auto_choice.ChoiceFailed where the session would reset the filter."""
    fed = ChosenFilter(stream, guard_on) if fed is None else fed
    whites = []

    def keep(filt, step):
        if step.code in FUSED_OK:
            whites.append(np.array(filt.stream.ekf.white, dtype=float))
    fed.feed(entries, 'the learnt noise model', keep)
    return fed, whites


def variance_factors(white, T, measured):
    """(factors (12,), model): per measured channel level^2 (1 + rho) / (1 - rho) of the
    whitened innovations white (N, 12) (NaN: not fused), rho clipped to [0, MAX_RHO]; NaN where
    there is no fit (unmeasured, too few samples). model: noise_model's dict by channel name."""
    nm = noise_model(white, T, STATE_NAMES)
    factors = np.full(N_STATE, np.nan)
    for j, name in enumerate(STATE_NAMES):
        d = nm.get(name)
        if d is None or not measured[j]:
            continue
        rho = min(max(d['ar1'], 0.0), MAX_RHO)
        factors[j] = d['level'] ** 2 * (1.0 + rho) / (1.0 - rho)
    return factors, nm


def log_factor_sd(rho, n):
    """Standard error of log(level^2 (1 + rho) / (1 - rho)) fitted to n samples of an AR(1)
    process with lag-1 correlation rho (large-sample): the sample variance's relative variance
    2 (1 + rho^2) / ((1 - rho^2) n) (Bartlett) plus the colour term's, (2 / (1 - rho^2))^2
    times rho's variance (1 - rho^2) / n."""
    rho = min(max(rho, 0.0), MAX_RHO)
    return math.sqrt((2.0 * (1.0 + rho ** 2) + 4.0) / ((1.0 - rho ** 2) * n))


def off_model(factors, model):
    """(12,) bool: the channels whose variance factor (variance_factors) is off: by more than
    NOISE_MODEL_CHANGE and by more than FIT_SIGMAS standard errors (module docstring)."""
    off = np.zeros(N_STATE, dtype=bool)
    for j, name in enumerate(STATE_NAMES):
        d = model.get(name)
        if d is None or not math.isfinite(factors[j]):
            continue
        dev = abs(math.log(factors[j])) if factors[j] > 0 else math.inf
        off[j] = (dev > math.log(NOISE_MODEL_CHANGE)
                  and dev > FIT_SIGMAS * log_factor_sd(d['ar1'], d['samples']))
    return off


class NoiseLearner:
    """The learnt noise model of one session (module docstring).

    measured : (12,) bool, the channels fused; T : s, the nominal sample time
    enabled : learn (noise mode 'fixed' and the learn_noise setting); else state 'off' and
        nothing is kept

    Attributes the caller reads: scale (12,), the factor on the measurement variances learnt
    so far (1: as configured); state (LEARNING: no fit yet, HOLDS: the last fit found the model
    holding, RELEARNT: the last fit changed it and no fit has confirmed it since, OFF); reruns;
    factors (12,) and model of the last fit; news, lines for the caller to log (then clear).
    """

    def __init__(self, measured, T, enabled=True, n_inputs=N_INPUT):
        self.measured = np.asarray(measured, dtype=bool)
        self.T = float(T)
        self.enabled = bool(enabled)
        self.state = LEARNING if enabled else OFF
        self.scale = np.ones(N_STATE)
        self.kept = KeptRecord(n_inputs)        # the record (entries() as auto_choice's)
        self.kept_odometry = 0                  # odometry entries in it
        self.rerun_at = LEARN_MIN_UPDATES       # kept odometry samples the next re-run needs
        self.white = InnovationWindow(LEARN_WINDOW)
        self.fused = 0                          # fused updates of the running filter
        self.since_fit = 0
        self.reruns = 0
        self.factors = np.full(N_STATE, np.nan)
        self.model = {}
        self.news = []
        self.pending = None                     # the Rerun under way, if any

    # -- what the session keeps --

    @property
    def keeping(self):
        """True while the record is kept (learning on, KEEP_LIMIT not reached)."""
        return self.enabled and self.kept_odometry < KEEP_LIMIT

    def keep_command(self, t, u):
        """Keep an accepted command u (7,) stamped t (s)."""
        if self.keeping:
            self.kept.add_command(t, u)

    def keep_command_rejected(self, t):
        """Keep the stamp t (s) of a rejected command (the stream's command_rejected)."""
        if self.keeping:
            self.kept.add_rejected(t)

    def keep_odometry(self, t, stamp_ns, y, r, code, trusted=True):
        """Keep an accepted odometry sample (r: its variances before the learnt scale, None:
        the configured ones); code 'time jump': a new time line, the record restarts on it
        (commands stamped up to t may be the new line's, as auto_choice keeps them); trusted
        False: a sensor fault was active (session/stuck.py), the re-run takes it as no good
        estimate either."""
        if not self.keeping:
            return
        if code == 'time jump':
            self.kept.restart_at(t)
            self.kept_odometry = 0
        self.kept.add_odometry(t, stamp_ns, y, r, trusted)
        self.kept_odometry += 1

    def innovations(self, white):
        """The whitened innovations (12,) of a fused, accepted update of the running filter;
        returns True when a fit is due (module docstring, step 2)."""
        if not self.enabled:
            return False
        self.white.append(white)
        self.fused += 1
        self.since_fit += 1
        return self.fused >= LEARN_MIN_UPDATES and self.since_fit >= LEARN_EVERY

    def restarted(self):
        """The running filter was replaced by a reset or the 'auto' switch: its innovations
        start anew, and a re-run under way (of the replaced set or start) is dropped."""
        self.white.clear()
        self.fused = 0
        self.since_fit = 0
        self.pending = None

    # -- the fit --

    def fit(self):
        """Fit the window (step 2); returns the new scale (12,) if the model must change and a
        re-run is due (module docstring, step 3), else None (the state says whether the model
        holds)."""
        self.since_fit = 0
        factors, self.model = variance_factors(self.white.rows(), self.T, self.measured)
        self.factors = factors
        off = off_model(factors, self.model)
        if not off.any():
            if self.state != HOLDS:
                self.news.append('noise model holds: ' + self.describe())
            self.state = HOLDS
            return None
        if not self.rerun_due:
            if self.state != RELEARNT:
                self.news.append('noise model off (' + self.next_rerun() + '): '
                                 + self.describe())
            self.state = RELEARNT
            return None
        self.state = RELEARNT
        # every fitted channel to its fixed point, not only the ones off: the re-run costs the
        # same, and a channel left near the limit would cross it on more data
        return self.scale * np.where(np.isfinite(factors), factors, 1.0)

    @property
    def rerun_due(self):
        """True if the record is long enough for a re-run (and still kept whole)."""
        return self.keeping and self.kept_odometry >= self.rerun_at

    def next_rerun(self):
        """When the next re-run can come, as a clause."""
        if not self.keeping:
            return f'no more re-runs: the record reached {KEEP_LIMIT} samples'
        return f'the next re-run once {self.rerun_at:.0f} samples are kept'

    def start_rerun(self, future, scale):
        """A re-run with scale (12,) over the whole record so far has started (future: its
        :func:`rerun` result)."""
        self.pending = Rerun(future, scale, len(self.kept))

    def rerun_done(self, scale, samples, whites, later=()):
        """A re-run with scale (12,) over samples kept odometry samples has replaced the
        running filter; whites: its innovations, the window from now on (so the next fit
        judges the re-run model at once); later: the innovations of the samples kept while it
        ran (a worker thread's re-run: fed to it before it took over).

        The later ones go through the window one by one with the fits that fall due among
        them, as if the re-run had taken over at once (a synchronous runner: replay_bag):
        the fits, the state and the next re-run's size then do not depend on how long the
        worker took, and the live node's estimates are the replay's (measured before: a
        played 60 s BlueROV2 bag's re-runs took over at 271 and 740 samples live instead of
        200 and 401, and the estimates ended 0.5-4 % apart). A fit among them that finds the
        model off cannot start a re-run (that needs twice the record; a worker that took that
        long leaves it to the next fit)."""
        self.restarted()
        for w in whites:
            self.innovations(w)
        self.scale = scale
        self.reruns += 1
        self.rerun_at = RERUN_GROWTH * samples
        self.news.append(f'noise model learnt from the innovations (re-run {self.reruns}, '
                         f'over {samples} kept samples): ' + self.describe())
        for w in later:
            if self.innovations(w):
                self.fit()

    def rerun_failed(self, reason, samples):
        """A re-run over samples kept odometry samples failed: the running filter stays; the
        next try once the record has grown as after a re-run."""
        self.rerun_at = RERUN_GROWTH * samples
        self.news.append(f'the re-run with the learnt noise model failed ({reason}): the '
                         f'running filter stays ({self.next_rerun()})')

    def entries(self, default_variances, scale, start=0):
        """The kept record from entry start on, each odometry sample's variances times scale
        (12,) (default_variances (12,): those of a sample that states none)."""
        return self.kept.entries(default_variances, scale, start)

    # -- what the caller shows --

    def describe(self):
        """One clause: per channel fitted, its variance factor of the last fit, level and
        lag-1 correlation, and the learnt scale where it is not 1."""
        parts = []
        for j, name in enumerate(STATE_NAMES):
            d = self.model.get(name)
            if d is None or not self.measured[j]:
                continue
            text = f'{name} x{self.factors[j]:.2g} (level {d["level"]:.2g}, rho {d["ar1"]:.2f})'
            if self.scale[j] != 1.0:
                text += f' scale {self.scale[j]:.3g}'
            parts.append(text)
        return ('variance factor of the innovations per channel: ' + ', '.join(parts)
                if parts else 'no channel fitted')

    def worst(self):
        """(name, factor) of the channel whose last factor is furthest from 1, or None."""
        f = np.where(self.measured & np.isfinite(self.factors), self.factors, np.nan)
        if not np.isfinite(f).any():
            return None
        j = int(np.nanargmax(np.abs(np.log(f))))
        return STATE_NAMES[j], float(f[j])

    def diagnostic_values(self):
        """[(key, text)] for /diagnostics: noise_state, noise_reruns, then per measured
        channel noise_scale_<ch> (the learnt factor on its variance) and noise_factor_<ch>
        (the last fit's variance factor, 'n/a' before)."""
        values = [('noise_state', self.state), ('noise_reruns', str(self.reruns))]
        for j, name in enumerate(STATE_NAMES):
            if self.measured[j]:
                f = self.factors[j]
                values += [(f'noise_scale_{name}', repr(float(self.scale[j]))),
                           (f'noise_factor_{name}', repr(float(f)) if math.isfinite(f)
                            else 'n/a')]
        return values

    def document(self):
        """The estimate file's ``noise_model`` block."""
        return {'state': self.state, 'reruns': self.reruns,
                'scale': {n: float(self.scale[j]) for j, n in enumerate(STATE_NAMES)
                          if self.measured[j]},
                'factor': {n: float(self.factors[j]) for j, n in enumerate(STATE_NAMES)
                           if self.measured[j] and math.isfinite(self.factors[j])}}
