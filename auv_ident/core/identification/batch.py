"""Identification over a whole record: the augmented EKF's pass (compiled loop), then an
optional batch refinement by the filter-error method.

Pass 1, the paper's method: the augmented EKF (ekf.py) runs once over the data, as it would
online; its final estimate and covariance are the online answer.

Pass 2 (offline, on by default): maximum likelihood over the whole record by the filter-error
method (Maine & Iliff 1981; Jategaonkar 2015, ch. 5): for a candidate theta, a 12-state EKF with
theta FIXED produces innovations nu_k and their covariances S_k; theta minimises
sum_k nu_k^T S_k^-1 nu_k (Gauss-Newton/Levenberg-Marquardt, scipy least_squares, started from
pass 1). Its covariance is (J^T J)^-1 scaled by the residual variance when that exceeds 1. Why:
an EKF's one pass carries linearisation and initial-transient bias (about 2 % on Z_w at 500 rpm,
shared/method_notes.md); the batch pass uses every sample against one consistent theta.

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
from scipy.optimize import _minpack, OptimizeResult

from auv_ident.core.errors import ConfigError, DimensionError, DivergenceError, DomainError
from auv_ident.core.filter import ekf as K
from auv_ident.core.filter.augmented import AugmentedEKF, FilterConfig
from auv_ident.core.filter.timing import (
    check_times,
    DEFAULT_MAX_BRIDGE,
    nominal_sample_time,
    time_steps,
)
from auv_ident.core.identification.results import (
    Estimate,
    FilterPass,
    Identification,
    Record,
    Refinement,
)
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
LM_TOLERANCE = 1e-8     # ftol, xtol and gtol of the Levenberg-Marquardt fit (least_squares')
# scipy.optimize.least_squares' status and messages of its 'lm' method, from MINPACK's info
_LM_STATUS = {0: -1, 1: 2, 2: 3, 3: 4, 4: 1, 5: 0}
_LM_MESSAGES = {
    -1: 'Improper input parameters status returned from `leastsq`',
    0: 'The maximum number of function evaluations is exceeded.',
    1: '`gtol` termination condition is satisfied.',
    2: '`ftol` termination condition is satisfied.',
    3: '`xtol` termination condition is satisfied.',
    4: 'Both `ftol` and `xtol` termination conditions are satisfied.'}


class ForwardJacobian:
    """The Jacobian of a residual vector by forward differences, in one buffer reused by every
    evaluation (scipy's least_squares(diff_step=...) keeps the p perturbed residual vectors,
    their differences, their quotients and the Jacobian at once). The numbers are scipy 1.17's
    2-point rule to the bit: step h_i = rel_step * sign(z_i) * |z_i| (sqrt(eps) * max(1, |z_i|)
    where that adds nothing to z_i), column i = (r(z + h_i e_i) - r(z)) / ((z_i + h_i) - z_i).

    residuals : z -> (M,) new array; mapper : map-like evaluating the p columns (a thread
    pool's map); residuals_into : None, or (z, out) -> None writing r(z) into out (M,), the
    same numbers without a new (M,) array per column (one fewer vector of 12 N values per
    thread at the refinement's peak, docs/reliability.md bounded memory). :meth:`fun` is the
    residual function to fit (it remembers its last point and value, the r(z) a Jacobian at
    that point starts from, as scipy's does); :meth:`rows` gives the Jacobian as (p, M) rows,
    a call as (M, p) (a Fortran-ordered view, as scipy's); both are the buffer, overwritten by
    the next evaluation at another point."""

    def __init__(self, residuals, m, p, rel_step=RELATIVE_STEP, mapper=map,
                 residuals_into=None):
        self.residuals = residuals
        self.residuals_into = residuals_into
        self.rel_step = rel_step
        self.mapper = mapper
        self._rows = np.empty((p, m))    # row i: column i of the Jacobian
        self._at = None                  # the point whose Jacobian the buffer holds
        self._last = None                # (z, r(z)) of the last fun call

    def fun(self, z):
        r = self.residuals(z)
        self._last = (np.array(z, dtype=float), r)
        return r

    def __call__(self, z):
        return self.rows(z).T

    def rows(self, z):
        z = np.array(z, dtype=float)
        out = self._rows
        if self._at is not None and np.array_equal(self._at, z):
            return out
        if self._last is not None and np.array_equal(self._last[0], z):
            r0 = self._last[1]
        else:
            r0 = self.fun(z)
        self._at = None                  # being overwritten
        sign = (z >= 0).astype(float) * 2 - 1
        h = self.rel_step * sign * np.abs(z)
        eps_step = np.finfo(float).eps ** 0.5
        h = np.where(((z + h) - z) == 0, eps_step * sign * np.maximum(1.0, np.abs(z)), h)

        def column(i):
            z1 = z.copy()
            z1[i] = z[i] + h[i]
            if self.residuals_into is None:
                np.subtract(self.residuals(z1), r0, out=out[i])
            else:
                self.residuals_into(z1, out[i])
                out[i] -= r0
            out[i] /= (z[i] + h[i]) - z[i]

        for _ in self.mapper(column, range(z.size)):
            pass
        self._at = z
        return out


def levenberg_marquardt(jac, z0, max_nfev):
    """least_squares(jac.fun, z0, jac=jac, method='lm', x_scale=1, max_nfev=max_nfev): the same
    MINPACK lmder call with the same arguments, without least_squares' copies of the (M, p)
    Jacobian (five more, 170 MB at M = 720 000, p = 6: measured); the Jacobian goes to MINPACK
    as the (p, M) rows it is computed in (col_deriv). jac : ForwardJacobian.

    Returns a scipy.optimize.OptimizeResult with x, fun, cost, jac (at x, (M, p): jac's
    buffer), status, message and nfev as least_squares gives them."""
    z0 = np.array(z0, dtype=float)
    x, info, ier = _minpack._lmder(jac.fun, jac.rows, z0, (), True, True, LM_TOLERANCE,
                                   LM_TOLERANCE, LM_TOLERANCE, max_nfev, 100.0,
                                   np.ones(z0.size))
    f, nfev = info['fvec'], int(info['nfev'])
    del info        # MINPACK's own copy of the Jacobian, no longer needed
    status = _LM_STATUS[ier]
    return OptimizeResult(x=x, fun=f, cost=0.5 * np.dot(f, f), jac=jac(x), status=status,
                          message=_LM_MESSAGES[status], nfev=nfev)


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
           max_nfev=60, progress=None, details=False):
    """Pass 2: filter-error maximum likelihood for theta, started at theta_start (p), over one
    run or several of one vehicle: one theta for all of them.

    runs : a list of Record (as for run_ekf), each filtered from its own first measurement; the
    residual vector is the runs' whitened innovations stacked in order, and the covariance uses
    all of them. T (s): the nominal sample time (None: the first run's median interval);
    max_step, max_bridge as for run_ekf. Returns a Refinement: theta, cov, the cost per
    residual, the Jacobian (sum N * 12, p) of the whitened innovations with respect to theta,
    whether the optimiser converged, its message and evaluations, and with details=True the
    innovations at the solution, white (sum N, 12) (NaN: no measurement). cov is (J^T J)^-1
    times the cost per residual when that exceeds 1 (the white-noise covariance;
    core/identification/uncertainty.py has the one for coloured residuals)."""
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

    def residuals_into(z, out):
        # residuals(z) written into out (a row of the Jacobian's buffer): the same numbers
        # (fer.vector is nan_to_num of the thread's innovations) without a new vector
        if progress is not None:
            with lock:
                progress()
        ok, w = fer(z * scale)
        if ok:
            np.copyto(out, w.reshape(-1))
            np.nan_to_num(out, copy=False)
        else:
            out[:] = 1e3

    z0 = theta_start / scale
    with ThreadPoolExecutor(difference_threads()) as pool:
        # the Jacobian's columns on the pool's threads, whatever scipy's version
        jac = ForwardJacobian(residuals, white.size, p, mapper=pool.map,
                              residuals_into=residuals_into)
        sol = levenberg_marquardt(jac, z0, max_nfev * p)
    J = sol.jac         # the Jacobian's own buffer, scaled in place (not another copy)
    J /= scale[None, :]
    n_res = np.count_nonzero(sol.fun)
    s2 = 2.0 * sol.cost / max(1, n_res - p)
    try:
        cov = np.linalg.inv(J.T @ J) * max(1.0, s2)
    except np.linalg.LinAlgError:
        raise DivergenceError('batch refinement: the coefficients are not identifiable from '
                              'this run (singular information matrix)') from None
    if details:
        residuals(sol.x)        # the innovations at the solution (the last call may differ)
    return Refinement(estimate=sol.x * scale, cov=cov, cost=s2, jacobian=J,
                      converged=sol.status > 0, message=sol.message, nfev=sol.nfev,
                      white=white.copy() if details else None)


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
