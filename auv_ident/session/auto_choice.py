"""The identifier's ``coefficients: [auto]`` / ``[auto, NAME, ...]``: the coefficients chosen
live from the first ``auto_window`` seconds of data.

Offline, ``identify --bag BAG --coefficients auto[,NAME,...]`` chooses the coefficients from a
recorded run (core/identification/selection.py). Live, the session does the same from the run under
way, in these steps (:attr:`AutoChoice.state` in brackets):

1. (``choosing``) The session identifies the named coefficients (none named: the vehicle's
   identify_default) exactly as it would without 'auto', so the node publishes from the first
   second. It also keeps every command and odometry sample it accepts (after the same
   screening, pairing and innovation gate), in arrival order, until the accepted odometry
   spans ``auto_window`` s.
2. (``choosing``) The choice, :func:`choose_and_feed`, runs in the caller's runner: a worker
   thread in the node (:func:`run_in_thread`), inline by default (:func:`run_inline`, so that
   a bag replay is deterministic). It runs core.identification.selection.choose_coefficients on
   that record: pass 1 of the offline selection (stepwise regression on the filter-error residuals
   at the vehicle file's values), with the running filter's measurement noise (the median of the
   accepted updates' R), q_state and channels. Then it builds a filter of the chosen set and
   feeds it the record. The coefficients the running filter identified start at its last good
   estimate, the others at the vehicle file's values, each with the prior 1-sigma p0_rel of
   its start, and the water current starts from its prior. Messages keep arriving meanwhile:
   the running filter takes them, and they are kept too.
3. (``chosen``) The switch happens at the first message or :meth:`IdentSession.poll_choice`
   after the job finished, in the caller's thread, so never concurrently with a message. The
   chosen filter is fed what was kept meanwhile, then replaces the running one: its estimate,
   covariance, health windows and last good estimate. No accepted sample is lost: each one
   reaches the chosen filter once. The estimate's names and length change, once.
4. (``failed``) The choice or the feeding raised: the model left its domain, the chosen
   filter diverged on the record (a core error, or its divergence guard fired), or anything
   else; or the data chose no coefficient at all ('auto' alone). The running set stays. The
   reason is kept for the caller to log once and for /diagnostics.

Why pass 1 only: pass 2 identifies the set twice with the batch refinement (tens of s of CPU,
docs/accuracy.md) to drop the members that identification finds weak or correlated. Live, the
filter's own covariance judges them (the live diagnosis's verdicts). The live error bars are the
filter's: unlike the offline result, they do not add the consider covariance of the
coefficients left at the file's values.
"""
from collections import Counter
from concurrent.futures import Future
from dataclasses import dataclass, replace
import math
import threading
import time

import numpy as np

from auv_ident.core.errors import AuvIdentError
from auv_ident.core.filter.stream import StreamIdentifier
from auv_ident.core.identification.selection import choose_coefficients
from auv_ident.session.guarded_filter import FILTER_FAULTS, GuardedFilter
from auv_ident.session.record import exact_hold, median_noise_std, paired

AUTO_WINDOW_S = 120.0   # s of accepted odometry the choice is made from (docs/ros.md: why)
CHOOSING, CHOSEN, FAILED = 'choosing', 'chosen', 'failed'

# kinds of the kept entries: (COMMAND, t, u7), (COMMAND_REJECTED, t),
# (ODOMETRY, t, stamp_ns, y12, R diagonal or None, trusted: no sensor fault was active)
COMMAND, COMMAND_REJECTED, ODOMETRY = range(3)


class ChoiceFailed(AuvIdentError):
    """The choice cannot be taken; the message says why. selection: the Selection if the
    choice itself was made (its left-out reasons stay visible)."""

    def __init__(self, message, selection=None):
        super().__init__(message)
        self.selection = selection


def run_inline(work):
    """Run work() now; return its concurrent.futures.Future (done: result or exception)."""
    future = Future()
    try:
        future.set_result(work())
    except Exception as err:                     # noqa: BLE001 - handed to the caller
        future.set_exception(err)
    return future


def run_in_thread(work):
    """Run work() in a daemon thread; return its Future at once. Daemon: a node shut down
    while a choice runs exits without waiting for it."""
    future = Future()

    def target():
        try:
            future.set_result(work())
        except Exception as err:                 # noqa: BLE001 - handed to the caller
            future.set_exception(err)

    threading.Thread(target=target, name='auto_choice', daemon=True).start()
    return future


@dataclass(frozen=True)
class ChoiceJob:
    """Everything the choice needs, taken in the caller's thread when the window is full,
    so that the worker reads nothing the session changes.

    make_model : names -> Model (the session's vehicle, current and mass inverse)
    cfg : the running FilterConfig (noise mode, p0_rel, q_state, channels, current prior)
    named : coefficients always chosen; running : {name: last good estimate} of the running
        filter's coefficients (empty if it has none)
    entries : the kept record (module docstring); noise_variances : (12,) noise_std squared
    T, max_gap, gate, max_bridge, max_command_age, guard_on : the session's filter settings
    """

    make_model: object
    cfg: object
    named: tuple
    running: dict
    entries: list
    noise_variances: np.ndarray
    T: float
    max_gap: float
    gate: object
    max_bridge: float
    max_command_age: object
    guard_on: bool


@dataclass
class ChoiceResult:
    """What the job made: the Selection, the chosen set's model, FilterConfig and fed filter
    (:class:`ChosenFilter`), and the wall time of the choice alone and of the whole job (s)."""

    selection: object
    model: object
    cfg: object
    chosen_filter: object
    choice_wall_s: float
    job_wall_s: float


class ChosenFilter:
    """The chosen set's streaming filter, fed the kept record with the session's per-message
    rule: a :class:`~auv_ident.session.guarded_filter.GuardedFilter`, as the session's own
    (the same pairing, gate, covariance repair, estimate check, health and guard windows and
    last good estimate). Where the session would reset the filter (a core error, a sustained
    guard), this raises ChoiceFailed instead: a set whose filter fails on the data it was
    chosen from is not taken. At the switch its filter becomes the session's."""

    def __init__(self, stream, guard_on):
        self.filter = GuardedFilter(stream, guard_on)
        self.names = self.filter.names
        self.samples = 0        # odometry entries fed
        self.updates = 0        # of which accepted
        self.rejected = Counter()

    def feed(self, entries, what='the chosen set', on_update=None):
        """Feed kept entries in order; raises ChoiceFailed where the session would reset.
        what : whose filter, for the messages; on_update : called with the GuardedFilter
        and the Update after each accepted odometry update (the noise learner reads its
        innovations)."""
        filt = self.filter
        stream = filt.stream
        for entry in entries:
            kind = entry[0]
            if kind == COMMAND:
                stream.add_command(entry[1], entry[2])
                continue
            if kind == COMMAND_REJECTED:
                stream.command_rejected(entry[1])
                continue
            _, t, stamp_ns, y, r, trusted = entry
            self.samples += 1
            try:
                step = filt.update(t, stamp_ns, y, r, trusted)
            except FILTER_FAULTS as err:
                raise ChoiceFailed(f'the filter of {what} failed on the kept data at '
                                   f'{t:.3f} s: {type(err).__name__}: {err}') from None
            if step.sustained:
                window = filt.guard_window
                raise ChoiceFailed(f'the filter of {what} diverged on the kept data: '
                                   f'innovations inconsistent since {window.since:.3f} s '
                                   f'(guard median NIS/dof {window.median():.4g})')
            if not step.accepted:
                self.rejected[step.code] += 1
                continue
            self.updates += 1
            if on_update is not None:
                on_update(filt, step)


def choose_and_feed(job):
    """The worker's job (module docstring, step 2): choose the set from job.entries and feed a
    filter of it the same entries. Returns a ChoiceResult; raises what the choice raises."""
    start = time.perf_counter()
    commands, measurements, variances = [], [], []
    for entry in job.entries:
        if entry[0] == COMMAND:
            commands.append((entry[1], entry[2]))
        elif entry[0] == ODOMETRY:
            measurements.append((entry[1], entry[3]))
            variances.append(job.noise_variances if entry[4] is None else entry[4])
    if len(measurements) < 2:
        raise ChoiceFailed(f'{len(measurements)} odometry sample(s) kept: nothing to choose '
                           'from')
    record = exact_hold(*paired(commands, measurements))
    # the noise the running filter used; the selection's filter runs with it fixed
    cfg = replace(job.cfg, noise_std=median_noise_std(variances, job.noise_variances),
                  mode='fixed')
    # one thread: the choice runs beside the live identifier, which keeps the other core for
    # the messages (offline, the same sensitivities take every core)
    selection = choose_coefficients(job.make_model, cfg, [record], named=job.named, T=job.T,
                                    max_bridge=job.max_bridge, threads=1).selection
    choice_wall_s = time.perf_counter() - start
    if not selection.chosen:
        # 'auto' alone on data that determine no coefficient: a filter of the current alone
        # (or of nothing) would tell less than the running default set, which stays
        raise ChoiceFailed('the data chose no coefficient (every candidate left out, reasons '
                           'in auto_left_out_<name>)', selection)
    model = job.make_model(selection.chosen)
    vehicle = model.vehicle
    initial = np.array([job.running.get(n, vehicle.values[vehicle.index(n)])
                        for n in selection.chosen], dtype=float)
    chosen_cfg = replace(job.cfg, coefficients=list(selection.chosen), initial=initial,
                         theta_cov0=None)
    stream = StreamIdentifier(model, chosen_cfg, job.T, job.max_gap, gate=job.gate,
                              max_bridge=job.max_bridge, max_command_age=job.max_command_age)
    chosen_filter = ChosenFilter(stream, job.guard_on)
    chosen_filter.feed(job.entries)
    return ChoiceResult(selection, model, chosen_cfg, chosen_filter, choice_wall_s,
                        time.perf_counter() - start)


def failure_text(err):
    """One line saying why a choice failed: the message of a package error (it names the
    problem), the exception's type too for anything else (a bug, said as such)."""
    text = str(err).splitlines()[0] if str(err) else ''
    if isinstance(err, AuvIdentError):
        return text or type(err).__name__
    return f'internal error: {type(err).__name__}: {text}'


class AutoChoice:
    """The state of one live choice (module docstring): what is kept, the job, the outcome.

    named : coefficients always chosen (file spelling); window_s : auto_window (s)
    runner : work -> Future (:func:`run_inline`, :func:`run_in_thread`)

    Attributes the caller reads: state (CHOOSING, CHOSEN, FAILED), selection (the
    core.identification.selection.Selection once chosen), reason (why it failed), news ([(level,
    text)] lines to log, 'info' or 'error', then clear), data_s (s of odometry kept).
    """

    def __init__(self, named, window_s, runner=None):
        self.named = tuple(named)
        self.window_s = float(window_s)
        self.runner = run_inline if runner is None else runner
        self.state = CHOOSING
        self.kept = []              # the record (module docstring); None once it is over
        self.t_first = None         # s, first kept odometry
        self.t_last = None
        self.job = None             # the Future of the running job
        self.taken = 0              # entries the job took
        self.window_data_s = math.nan   # s of odometry the choice was made from
        self.selection = None
        self.reason = ''
        self.choice_wall_s = math.nan
        self.job_wall_s = math.nan
        self.samples = 0            # odometry samples the chosen filter was fed at the switch
        self.switch_stamp_ns = None
        self.news = []

    @property
    def data_s(self):
        """s of odometry kept so far (first to last stamp)."""
        return 0.0 if self.t_first is None else self.t_last - self.t_first

    @property
    def running(self):
        """True while the job runs."""
        return self.job is not None

    # -- what the session keeps (nothing once the choice is over) --

    def keep_command(self, t, u):
        """Keep an accepted command u (7,) stamped t (s)."""
        if self.kept is not None:
            self.kept.append((COMMAND, t, u))

    def keep_command_rejected(self, t):
        """Keep the stamp t (s) of a rejected command (the stream's command_rejected)."""
        if self.kept is not None:
            self.kept.append((COMMAND_REJECTED, t))

    def keep_odometry(self, t, stamp_ns, y, r, code, trusted=True):
        """Keep an accepted odometry sample; returns True when the window just filled (the
        caller starts the job). code : the stream's code ('time jump': a confirmed backward
        jump of the time line); trusted False: a sensor fault was active (session/stuck.py),
        so the chosen filter does not take its update as good either."""
        if self.kept is None:
            return False
        if code == 'time jump' and self.job is None:
            # a new time line: the window restarts on it; commands stamped up to now may be
            # the new line's (the stream held them for the jump), later ones are the old one's
            self.kept = [e for e in self.kept if e[0] != ODOMETRY and e[1] <= t]
            self.t_first = None
        self.kept.append((ODOMETRY, t, stamp_ns, y, r, trusted))
        if self.t_first is None:
            self.t_first = t
        self.t_last = t
        return self.job is None and self.t_last - self.t_first >= self.window_s

    # -- the job --

    def start(self, job):
        """Hand the job (a ChoiceJob of every entry kept so far) to the runner."""
        self.taken = len(job.entries)
        self.window_data_s = self.data_s
        self.news.append(('info', f'choosing the coefficients from {self.window_data_s:.1f} s '
                                  f'of data ({sum(e[0] == ODOMETRY for e in job.entries)} '
                                  'odometry samples): the selection runs, messages keep being '
                                  'identified and kept meanwhile'))
        self.job = self.runner(lambda: choose_and_feed(job))

    def finished(self):
        """The job's ChoiceResult if it has finished (None if it still runs or there is
        none), the chosen filter fed what was kept meanwhile; ChoiceFailed (or whatever the
        job raised) if it failed. Call in the thread the messages arrive in."""
        job = self.job
        if job is None or not job.done():
            return None
        self.job = None
        result = job.result()           # raises the job's exception
        result.chosen_filter.feed(self.kept[self.taken:])
        return result

    def poll(self):
        """The ChoiceResult to switch to if the job has just finished with one (as
        :meth:`finished`); None if there is none, it still runs, or it failed: the failure
        is then recorded (:meth:`fail`) and the running set stays."""
        try:
            return self.finished()
        except Exception as err:                 # noqa: BLE001 - the running set stays
            self.fail(err)
            return None

    def chose(self, result, stamp_ns):
        """Record the switch to result's set (CHOSEN); the kept record is dropped."""
        sel = result.selection
        self.state = CHOSEN
        self.selection = sel
        self.choice_wall_s = result.choice_wall_s
        self.job_wall_s = result.job_wall_s
        self.samples = result.chosen_filter.samples
        self.switch_stamp_ns = stamp_ns
        self.kept = None
        f = result.chosen_filter
        lost = f.samples - f.updates
        self.news += [('info', line) for line in sel.summary()]
        self.news.append((
            'info', f'switched to the chosen set: {len(sel.chosen)} coefficients from '
                    f'{self.window_data_s:.1f} s of data (choice {self.choice_wall_s:.2f} s '
                    f'wall, with the feeding {self.job_wall_s:.2f} s); its filter took '
                    f'{f.updates} of the {f.samples} odometry samples kept'
                    + (f' ({lost} rejected: {dict(f.rejected)})' if lost else '')
                    + f'; the estimate now has {len(f.names)} parameters ('
                    + ', '.join(f.names) + '), a new length for its subscribers'))

    def fail(self, err):
        """Record a failed choice (FAILED): the running set stays; the kept record is
        dropped."""
        self.state = FAILED
        self.reason = failure_text(err)
        self.selection = getattr(err, 'selection', None)
        self.kept = None
        self.news.append(('error', f'automatic choice of coefficients failed: {self.reason}; '
                                   'the running set stays'))

    # -- what the caller shows --

    def diagnosis_line(self, running_names):
        """The live diagnosis's line about the choice (running_names: what is identified)."""
        coefs = ', '.join(running_names)
        if self.state == CHOOSING:
            if self.running:
                return (f'choosing coefficients from the data ({self.window_data_s:.1f} of '
                        f'{self.window_s:g} s: the selection runs); identifying {coefs} '
                        'meanwhile')
            return (f'choosing coefficients from the data ({self.data_s:.1f} of '
                    f'{self.window_s:g} s); identifying {coefs} meanwhile')
        if self.state == CHOSEN:
            sel = self.selection
            return (f'coefficients chosen from {self.window_data_s:.1f} s of data: '
                    f'{len(sel.chosen)} of {sel.candidates} candidates ({", ".join(sel.chosen)})'
                    f"; {len(sel.left_out)} left out at the vehicle file's values, each with "
                    'its reason (auto_left_out_<name>)')
        return (f'automatic choice of coefficients failed: {self.reason}; identifying {coefs} '
                '(the running set) instead')

    def diagnostic_values(self):
        """[(key, text)] for /diagnostics: auto_state, auto_window_s, auto_data_s, auto_named,
        auto_chosen, auto_left_out_count, auto_choice_wall_s, auto_error, then
        auto_left_out_<name> with the reason of every coefficient left out."""
        sel = self.selection
        data_s = self.data_s if self.state == CHOOSING and not self.running \
            else self.window_data_s
        values = [('auto_state', self.state), ('auto_window_s', repr(self.window_s)),
                  ('auto_data_s', f'{data_s:.3f}' if math.isfinite(data_s) else 'n/a'),
                  ('auto_named', ','.join(self.named)),
                  ('auto_chosen', '' if sel is None else ','.join(sel.chosen)),
                  ('auto_left_out_count', '' if sel is None else str(len(sel.left_out))),
                  ('auto_choice_wall_s', f'{self.choice_wall_s:.3f}'
                   if math.isfinite(self.choice_wall_s) else 'n/a'),
                  ('auto_error', self.reason)]
        if sel is not None:
            values += [(f'auto_left_out_{name}', why) for name, why in sel.left_out.items()]
        return values

    def document(self):
        """The estimate file's ``selection`` block: the state, window and data; once chosen
        also Selection.document() (as the offline JSON's), the wall times and the switch
        stamp; after a failure, why."""
        doc = {'state': self.state, 'window_s': self.window_s, 'named': list(self.named)}
        if self.state == CHOOSING:
            doc['data_s'] = self.data_s
            return doc
        doc['data_s'] = self.window_data_s if math.isfinite(self.window_data_s) else None
        if self.state == FAILED:
            doc['error'] = self.reason
            if self.selection is not None:
                doc['left_out'] = dict(self.selection.left_out)
            return doc
        doc.update(self.selection.document())
        doc.update({'choice_wall_s': self.choice_wall_s, 'job_wall_s': self.job_wall_s,
                    'samples': self.samples, 'switch_stamp_ns': self.switch_stamp_ns})
        return doc
