"""Identification over a whole record: the augmented EKF's pass (compiled loop), then an
optional batch refinement by the filter-error method.

Pass 1, the paper's method: the augmented EKF (ekf.py) runs once over the data, as it would
online; its final estimate and covariance are the online answer.

Pass 2 (offline, on by default): maximum likelihood over the whole record by the filter-error
method (Maine & Iliff 1981; Jategaonkar 2015, ch. 5): for a candidate theta, a 12-state EKF with
theta FIXED produces innovations nu_k and their covariances S_k; theta minimises
sum_k nu_k^T S_k^-1 nu_k (Levenberg-Marquardt on normal equations summed over chunks of
samples, levenberg_marquardt.py, started from pass 1). Its covariance is (J^T J)^-1 scaled by
the residual variance when that exceeds 1. Why: an EKF's one pass carries linearisation and
initial-transient bias (about 2 % on Z_w at 500 rpm, shared/method_notes.md); the batch pass
uses every sample against one consistent theta.

The water current's identified components (core/model/current.py) are parameters of both passes
like the coefficients: random-walk states of the augmented EKF, and constants of the
maximum-likelihood fit (scaled in m/s, where the coefficients are scaled by their size).

Finite differences run on threads (:func:`difference_threads`): the compiled filter releases
the GIL, so the columns of a Jacobian (one filter run each) share the machine's cores; the
numbers are the same as one thread gives.

Time is what the stamps say: both passes take the sample times t and cross each interval by
the rules of timing.py (RK4 steps of at most max_step with the command held, a restart of the
vehicle states after a gap longer than max_bridge), the rules of the streaming identifier.
"""
from concurrent.futures import ThreadPoolExecutor
import os
import threading
import time

import numpy as np

from auv_ident.core.errors import ConfigError, DimensionError, DivergenceError, DomainError
from auv_ident.core.filter import ekf as K
from auv_ident.core.filter.augmented import AugmentedEKF, FilterConfig
from auv_ident.core.filter.timing import (
    check_times,
    DEFAULT_MAX_BRIDGE,
    nominal_sample_time,
    time_steps,
)
from auv_ident.core.identification.levenberg_marquardt import (
    ChunkedForwardDifferences,
    levenberg_marquardt,
)
from auv_ident.core.identification.results import (
    Estimate,
    FilterPass,
    Identification,
    Record,
    Refinement,
)
from auv_ident.core.identification.uncertainty import Ar1ScoreSums
from auv_ident.core.model.hydrodynamics import Model, STATUS_TEXT
from auv_ident.core.model.state import Input, N_INPUT, N_STATE


def _record(t, Y, U):
    """(t, Y, U) as contiguous float arrays, checked: t (N,) strictly increasing finite times
    (s), Y (N, 12), U (N, 7 + thrusters: the model checks its own width)."""
    Y = np.ascontiguousarray(Y, dtype=float)
    U = np.ascontiguousarray(U, dtype=float)
    if (Y.ndim != 2 or Y.shape[1] != N_STATE or U.ndim != 2 or U.shape[0] != Y.shape[0]
            or U.shape[1] < N_INPUT or Y.shape[0] == 0):
        raise DimensionError(f'Y must be (N, 12) and U (N, {N_INPUT} + thrusters) with N >= 1; '
                             f'got {Y.shape} and {U.shape}')
    return check_times(t, Y.shape[0]), Y, U


def _records(runs):
    """The runs (Records) with their arrays contiguous and checked (_record); at least one."""
    if not runs:
        raise DimensionError('identification needs at least one run')
    return [Record(*_record(r.t, r.Y, r.U)) for r in runs]


def _timeline(f, t, Y, U, max_step, max_bridge):
    """The Timeline of the record for the filter f (the rules of timing.py): time steps of at
    most max_step (s; None: f.T), and the start states of the restarts after the gaps longer
    than max_bridge (s), each from its measurement and shaft speed as at the start."""
    max_step = f.T if max_step is None else float(max_step)
    if not max_step > 0.0 or not np.isfinite(max_step):
        raise ConfigError(f'max_step = {max_step!r} s must be a positive number')
    if not float(max_bridge) > 0.0:
        raise ConfigError(f'max_bridge = {max_bridge!r} s must be positive')
    n_sub, h = time_steps(t, max_step, float(max_bridge))
    starts = np.flatnonzero(n_sub[1:] == 0) + 1
    x0 = np.empty((starts.size, N_STATE))
    sd0 = np.empty((starts.size, N_STATE))
    for r, k in enumerate(starts):
        x0[r], sd0[r] = f.initial_state(Y[k], U[k, Input.N_RPM])
    return K.Timeline(n_sub, h, x0, sd0)


def _divergence_advice(f):
    """What to try after a divergence, never what is already set: an adaptive noise mode can
    run away (fixed holds R and Q); with fixed noise the noise given does not fit the data."""
    if f.cfg.mode != 'fixed':
        return '(try --noise-mode fixed)'
    r = np.asarray(f.cfg.noise_std, dtype=float)
    return (f'with fixed noise: the measurement 1-sigma given (here {r.min():.3g} to '
            f"{r.max():.3g}, from noise_std or the messages' covariances) or the process noise "
            'does not fit the data; check noise_std and q_state (--noise-source parameter '
            "ignores the messages' covariances)")


def _run_one(f, t, Y, U, hist_every, want_white, max_step, max_bridge):
    """The compiled loop over one checked record from Y[0]: (stats, histories, whitened
    innovations); the filter's state is replaced by the result."""
    N = Y.shape[0]
    m = f.model
    timeline = _timeline(f, t, Y, U, max_step, max_bridge)
    xa0, P0 = f.initial_estimate(Y[0], U[0, Input.N_RPM])
    out = K.new_outputs(f.n, N, hist_every, want_white)
    K.run_filter(xa0, P0, Y, U, m.compiled, f.settings(), timeline, out)
    stats = out.stats
    nh = out.theta.shape[0]
    st = int(stats[0])
    f.xa, f.P, f.Q, f.R, f.steps = out.xa, out.P, out.Q, out.R, int(stats[1])
    if st != K.OK:
        k = int(stats[1])
        if st in STATUS_TEXT:
            raise DomainError(f'EKF stopped at sample {k} (t = {t[k]:.2f} s): '
                              f'{STATUS_TEXT[st]}')
        raise DivergenceError(f'EKF diverged at sample {k} (t = {t[k]:.2f} s): the '
                              'covariance lost positive definiteness ' + _divergence_advice(f))
    hist = {'t': t[::hist_every][:nh] - t[0], 'theta': out.theta, 'std': out.std,
            'nis': out.nis[:, 0], 'dof': out.nis[:, 1], 'R_diag': out.rq[:, :N_STATE],
            'Q_theta_diag': out.rq[:, N_STATE:]} if nh else {}
    return stats, hist, out.white


def run_ekf(f, runs, hist_every=0, want_white=False, max_step=None,
            max_bridge=DEFAULT_MAX_BRIDGE):
    """Run the AugmentedEKF `f` over one run or several in turn with the compiled loop.

    Each run starts its vehicle states from its own first measurement, the coefficients (and
    any identified current) from where the previous run left them, with their covariance
    (AugmentedEKF.set_prior).

    Parameters
    ----------
    f : AugmentedEKF (its state is replaced by the result)
    runs : list of Record (t strictly increasing; jitter, dropouts and gaps allowed; Y NaN:
        missing; U[k] the command in force over [t_k, t_k+1), zero-order hold)
    hist_every : record histories every this many samples (0: none)
    want_white : keep each run's whitened innovations (N_i, 12) (FilterPass.whites)
    max_step : s, longest RK4 step of a time update (None: the filter's sample time f.T)
    max_bridge : s, a longer interval restarts the vehicle states (timing.py)

    Returns a FilterPass: stats (5,) summed over the runs (stats[0] the last status), the last
    run's histories (their 't' the time of each recorded sample since that run's first, s),
    theta0 the first run's start. Raises DomainError/DivergenceError naming the sample.
    """
    runs = _records(runs)
    theta0 = f.theta0.copy()
    total = np.zeros(5)
    whites = []
    hist = {}
    for i, r in enumerate(runs):
        if i > 0:       # carry the coefficients' estimate and covariance into the next run
            f.set_prior(f.theta, f.theta_cov)
        stats, hist, white = _run_one(f, r.t, r.Y, r.U, hist_every, want_white, max_step,
                                      max_bridge)
        total[1:] += stats[1:]
        total[0] = stats[0]
        if want_white:
            whites.append(white.copy())
    return FilterPass(stats=total, history=hist, R=f.R.copy(), Q=f.Q.copy(), theta0=theta0,
                      theta=f.theta.copy(), theta_cov=f.theta_cov.copy(),
                      mean_nis_per_dof=float(total[2] / max(1.0, total[3])),
                      steps=int(total[1]), whites=whites)


class FilterErrorResiduals:
    """The filter-error method's residuals as a function of theta: for candidate values of the
    model's parameters, the whitened innovations ``r_k = S_k^{-1/2} nu_k`` of a 12-state EKF
    with those values fixed (NaN where a channel has no measurement), over one run or several
    runs of the vehicle (each filtered from its own first measurement; their innovations
    stacked in order, run i in rows bounds[i]:bounds[i + 1] of ``white``). The refinement
    minimises their sum of squares; the automatic selection (selection.py) differentiates them
    with respect to every candidate coefficient.

    model : Model whose theta are the parameters; cfg : FilterConfig (its noise, q_state and
    measured channels are used); runs : a list of Record (as for run_ekf); T (s) the
    nominal sample time (None: the first run's median interval); max_step, max_bridge as for
    run_ekf.
    """

    def __init__(self, model, cfg, runs, T=None, max_step=None,
                 max_bridge=DEFAULT_MAX_BRIDGE):
        if not runs:
            raise DimensionError('the filter-error residuals need at least one run')
        runs = _records(runs)
        T = nominal_sample_time(runs[0].t) if T is None else T
        self.model = model
        fixed_cfg = FilterConfig(coefficients=[], initial=None, q_state=cfg.q_state,
                                 noise_std=cfg.noise_std, measured=cfg.measured, mode='fixed')
        state_model = Model(model.vehicle, (), mass_inverse=model.mass_inverse,
                            coefficient_values=model.c, current=model.current,
                            velocity_reference=model.velocity_reference)
        f = AugmentedEKF(state_model, fixed_cfg, T)
        self.settings = f.settings()
        # per run: (Y, U, timeline, x0, P0)
        self.legs = []
        for r in runs:
            timeline = _timeline(f, r.t, r.Y, r.U, max_step, max_bridge)
            x0, P0 = f.initial_estimate(r.Y[0], r.U[0, Input.N_RPM])
            self.legs.append((r.Y, r.U, timeline, x0, P0))
        self.bounds = np.cumsum([0] + [r.Y.shape[0] for r in runs])
        self._local = threading.local()     # each thread fills its own output buffers
        self.white = self._buffers()[1]

    def _buffers(self):
        """This thread's (filter outputs per run, stacked whitened innovations (sum N, 12))."""
        buffers = getattr(self._local, 'buffers', None)
        if buffers is None:
            outs = [K.new_outputs(N_STATE, leg[0].shape[0], want_white=True)
                    for leg in self.legs]
            white = (outs[0].white if len(outs) == 1
                     else np.full((int(self.bounds[-1]), N_STATE), np.nan))
            buffers = self._local.buffers = (outs, white)
        return buffers

    def __call__(self, theta):
        """(ok, white): ok False when a filter stopped (the model left its domain or the
        covariance failed); white (sum N, 12) is the calling thread's buffer (``self.white``
        for the thread that built this object), overwritten by its next call."""
        cm = self.model.compiled_fixed(theta)
        outs, white = self._buffers()
        for i, ((Y, U, timeline, x0, P0), out) in enumerate(zip(self.legs, outs)):
            out.white[:] = np.nan
            K.run_filter(x0, P0, Y, U, cm, self.settings, timeline, out)
            if out.stats[0] != K.OK:
                return False, white
            if len(outs) > 1:
                white[self.bounds[i]:self.bounds[i + 1]] = out.white
        return True, white

    def vector(self, theta):
        """The residual vector at theta (sum N * 12,), a new array: 0 where no measurement,
        None when a filter stopped. Safe to call from several threads at once."""
        ok, white = self(theta)
        return np.nan_to_num(white.ravel()) if ok else None

    def chunks(self, theta, chunk=None):
        """The residual vector at theta (what :meth:`vector` gives) in pieces: a generator of
        the whitened innovations of `chunk` samples at a time (None: REFINE_CHUNK), each
        (rows * 12,) with NaN as 0, a view of one buffer overwritten by the next piece; it
        yields None and stops when a filter stops (the model left its domain).

        The filter is run a chunk at a time: the next chunk starts from the posterior of the
        last sample before it, behind a sample with no measurement (an update without
        channels copies the state), so its time update and everything after are the
        whole run's, bit for bit. Memory: a chunk's buffers, whatever the record's length."""
        chunk = REFINE_CHUNK if chunk is None else int(chunk)
        chunk = max(1, min(chunk, max(leg[0].shape[0] for leg in self.legs)))
        cm = self.model.compiled_fixed(theta)
        out = K.new_outputs(N_STATE, chunk + 1, want_white=True)
        y = np.empty((chunk + 1, N_STATE))
        y[0] = np.nan
        flat = np.empty(chunk * N_STATE)
        for Y, U, tl, x0, P0 in self.legs:
            N = Y.shape[0]
            restarts = np.flatnonzero(tl.n_sub[1:] == 0) + 1
            for k0 in range(0, N, chunk):
                k1 = min(N, k0 + chunk)
                n = k1 - k0
                if k0 == 0:
                    K.run_filter(x0, P0, Y[:k1], U[:k1], cm, self.settings,
                                 K.Timeline(tl.n_sub[:k1], tl.h[:k1], tl.x0, tl.sd0), out)
                    white = out.white[:n]
                else:
                    r = int(np.searchsorted(restarts, k0))  # restarts before sample k0
                    y[1:n + 1] = Y[k0:k1]
                    K.run_filter(out.xa.copy(), out.P.copy(), y[:n + 1], U[k0 - 1:k1], cm,
                                 self.settings, K.Timeline(tl.n_sub[k0 - 1:k1],
                                                           tl.h[k0 - 1:k1], tl.x0[r:],
                                                           tl.sd0[r:]), out)
                    white = out.white[1:n + 1]
                if out.stats[0] != K.OK:
                    yield None
                    return
                piece = flat[:n * N_STATE]
                np.copyto(piece, white.reshape(-1))
                np.nan_to_num(piece, copy=False)
                yield piece

    def forward_differences(self, theta, steps, threads=None):
        """Forward-difference derivatives of the residual vector with respect to each
        parameter: column i = (r(theta + steps[i] e_i) - r(theta)) / steps[i], the columns
        computed on `threads` threads (None: :func:`difference_threads`).

        Returns (r (sum N * 12,) at theta, J (sum N * 12, p), failed: indices whose step took
        the model out of its domain, their columns zero). Raises DomainError if the filter
        fails at theta itself."""
        theta = np.asarray(theta, dtype=float)
        r0 = self.vector(theta)
        if r0 is None:
            raise DomainError('the filter-error residuals cannot be computed at the given '
                              'parameters (the model leaves its domain on this record)')

        def column(i):
            th = theta.copy()
            th[i] += steps[i]
            return self.vector(th)

        J = np.zeros((r0.size, theta.size))
        failed = []
        with ThreadPoolExecutor(threads or difference_threads()) as pool:
            for i, r in enumerate(pool.map(column, range(theta.size))):
                if r is None:
                    failed.append(i)
                else:
                    J[:, i] = (r - r0) / steps[i]
        return r0, J, failed


RELATIVE_STEP = 1e-5    # forward-difference step of the refinement, relative to each parameter
LM_TOLERANCE = 1e-8     # ftol, xtol and gtol of the Levenberg-Marquardt fit (MINPACK lmder's)
# samples per piece of the refinement's residuals and Jacobian: 4 p x 12 x REFINE_CHUNK floats
# of Jacobian and filter buffers at once (2.4 MB at p = 6) instead of 12 N x p twice (70 MB at
# N = 60 000); the pieces are synchronised across the difference threads, so shorter ones
# would cost more waiting
REFINE_CHUNK = 1024


def difference_threads():
    """Threads for finite differences: the CPUs this process may run on, or the
    AUV_IDENT_THREADS environment variable (a positive integer) when set."""
    text = os.environ.get('AUV_IDENT_THREADS', '').strip()
    if text:
        try:
            n = int(text)
        except ValueError:
            n = 0
        if n < 1:
            raise ConfigError(f'AUV_IDENT_THREADS={text!r}: expected a positive integer')
        return n
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:          # not on Linux
        return max(1, os.cpu_count() or 1)


def refine(model, cfg, runs, theta_start, T=None, max_step=None, max_bridge=DEFAULT_MAX_BRIDGE,
           max_nfev=60, progress=None, details=False, ar1=None):
    """Pass 2: filter-error maximum likelihood for theta, started at theta_start (p), over one
    run or several of one vehicle: one theta for all of them.

    runs : a list of Record (as for run_ekf), each filtered from its own first measurement; the
    residual vector is the runs' whitened innovations stacked in order, and the covariance uses
    all of them. T (s): the nominal sample time (None: the first run's median interval);
    max_step, max_bridge as for run_ekf. Returns a Refinement: theta, cov, the cost per
    residual, the information J^T J (p, p) and the per-sample scores J_k^T r_k (sum N, p) of
    the whitened innovations' Jacobian J with respect to theta, whether the optimiser
    converged, its message and evaluations, and with details=True the innovations at the
    solution, white (sum N, 12) (NaN: no measurement). cov is (J^T J)^-1 times the cost per
    residual when that exceeds 1 (the white-noise covariance; core/identification/
    uncertainty.py has the one for coloured residuals). ar1: None, or (rho (12,), variance
    (12,)) of the whitened innovations' AR(1) noise model: then also ar1_cov, the fit's
    covariance under that noise (uncertainty.ar1_covariance), from one more pass of the
    Jacobian at the solution, a chunk at a time (uncertainty.Ar1ScoreSums).

    The fit is MINPACK lmder's Levenberg-Marquardt on normal equations summed a chunk of
    REFINE_CHUNK samples at a time (core/identification/levenberg_marquardt.py): the
    Jacobian (12 N, p) is never held, only a chunk of it."""
    p = model.p
    fer = FilterErrorResiduals(model, cfg, runs, T=T, max_step=max_step,
                               max_bridge=max_bridge)
    white = fer.white
    scale = parameter_scale(model, theta_start)
    lock = threading.Lock()

    def residuals(z):
        if progress is not None:
            with lock:          # the Jacobian's columns are evaluated on several threads
                progress()
        # theta enters through the coefficients of a 12-state filter
        r = fer.vector(z * scale)
        return np.full(white.size, 1e3) if r is None else r

    def stream(z):
        if progress is not None:
            with lock:
                progress()
        return fer.chunks(z * scale)

    z0 = theta_start / scale
    with ThreadPoolExecutor(difference_threads()) as pool:
        # the Jacobian's p columns, a chunk of samples at a time, on the pool's threads
        fd = ChunkedForwardDifferences(residuals, stream, N_STATE, RELATIVE_STEP,
                                       mapper=pool.map)
        # diag ones: the parameters are already scaled by their size (least_squares' x_scale=1)
        sol = levenberg_marquardt(fd.norm, fd.normal_equations, z0, max_nfev * p,
                                  LM_TOLERANCE, LM_TOLERANCE, LM_TOLERANCE, diag=np.ones(p))
        if sol.information is None:     # the last step ended the fit: its sums at x
            fd.normal_equations(sol.x)
        ar1_cov = None
        if ar1 is not None:
            # one more pass at sol.x: fd's sums stay those of the solution
            ar1_cov = _ar1_covariance(fd, residuals, white, sol.x, ar1, fer.bounds, scale)
    assert fd.base is not None and fd.scores is not None
    r = fd.base[1]                      # the residuals at sol.x
    information = fd.information / np.outer(scale, scale)     # J^T J in theta's units
    n_res = np.count_nonzero(r)
    s2 = 2.0 * sol.cost / max(1, n_res - p)
    try:
        cov = np.linalg.inv(information) * max(1.0, s2)
    except np.linalg.LinAlgError:
        raise DivergenceError('batch refinement: the coefficients are not identifiable from '
                              'this run (singular information matrix)') from None
    if details and ar1 is None:  # (the AR(1) pass left white at the solution already)
        residuals(sol.x)        # the innovations at the solution (the last call may differ)
    return Refinement(estimate=sol.x * scale, cov=cov, cost=s2, information=information,
                      scores=fd.scores / scale, converged=sol.status > 0,
                      message=sol.message, nfev=sol.nfev,
                      white=white.copy() if details else None, ar1_cov=ar1_cov)


def _ar1_covariance(fd, residuals, white, z, ar1, bounds, scale):
    """refine's ar1_cov (its docstring): the Jacobian at the solution z (scaled parameters)
    streamed through Ar1ScoreSums over the samples the innovations at z have; theta's units.
    None where the information is singular."""
    residuals(z)                        # white: the innovations at the solution
    present = np.isfinite(white)
    p = z.size
    sums = Ar1ScoreSums(ar1[0], ar1[1], bounds, p)

    class _Observer:
        start = sums.start

        @staticmethod
        def add(k, J, r):
            J3 = J.reshape(-1, N_STATE, p)
            sums.add(k, J3, present[k:k + J3.shape[0]])
    fd.normal_equations(z, observer=_Observer)
    try:
        return sums.covariance(fd.information) * np.outer(scale, scale)
    except np.linalg.LinAlgError:
        return None


def parameter_scale(model, theta):
    """Scale of each parameter in the fit (p,): |theta| for a coefficient (a relative step),
    1 m/s for a current component (which may well be 0)."""
    scale = np.abs(np.asarray(theta, dtype=float)).copy()
    scale[model.p_coef:] = 1.0
    return scale


def identify(model, runs, cfg, T=None, refine_pass=True, hist_every=0, truth=None,
             progress=None, max_step=None, max_bridge=DEFAULT_MAX_BRIDGE):
    """Identify model.theta_names from one run or several of the vehicle, with the configured
    noise (core/identification/pipeline.py identifies with the noise model from the data).

    runs : list of Record (measurements Y (N, 12) stamped t (N,) (s), inputs U (N, 7), U[k]
        the command held over [t_k, t_k+1))
    T (s): the nominal sample time (None: the first run's median interval); max_step,
    max_bridge: as for run_ekf; truth: the true coefficients (p_coef,), if known.

    The EKF pass runs the runs one after the other (run_ekf). The refinement fits one theta to
    all runs' innovations stacked (refine), so the 1-sigma uses all the data. Returns an
    Identification: the coefficients in names/estimate/std/cov, the water current (if the
    model identifies or is given one) in current; steps and mean_nis_per_dof over all runs,
    history that of the last run."""
    t0 = time.perf_counter()
    runs = _records(runs)
    T = nominal_sample_time(runs[0].t) if T is None else T
    f = AugmentedEKF(model, cfg, T)
    ekf = run_ekf(f, runs, hist_every=hist_every, max_step=max_step, max_bridge=max_bridge)
    est = Estimate(model=model, ekf_estimate=ekf.theta, ekf_cov=ekf.theta_cov,
                   estimate=ekf.theta, cov=ekf.theta_cov)
    if refine_pass and model.p > 0:
        ref = refine(model, cfg, runs, ekf.theta, T=T, max_step=max_step,
                     max_bridge=max_bridge, progress=progress)
        est.estimate, est.cov = ref.estimate, ref.cov
    return Identification.of(est, runs, initial=ekf.theta0[:model.p_coef].copy(), truth=truth,
                             steps=ekf.steps, wall_s=time.perf_counter() - t0,
                             mean_nis_per_dof=ekf.mean_nis_per_dof, refined=refine_pass,
                             history=ekf.history, R_final=ekf.R, Q_final=ekf.Q)
