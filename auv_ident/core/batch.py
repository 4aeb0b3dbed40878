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

The water current's identified components (core/current.py) are parameters of both passes
like the coefficients: random-walk states of the augmented EKF, and constants of the
maximum-likelihood fit (scaled in m/s, where the coefficients are scaled by their size).

Time is what the stamps say: both passes take the sample times t and cross each interval by
the rules of timing.py (RK4 steps of at most max_step with the command held, a restart of the
vehicle states after a gap longer than max_bridge), the rules of the streaming identifier.
"""
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from . import ekf as K
from .current import split_current
from .errors import ConfigError, DimensionError, DivergenceError, DomainError
from .filter import AugmentedEKF, FilterConfig
from .model import Model, STATUS_TEXT
from .state import Input, N_INPUT, N_STATE, State
from .timing import check_times, DEFAULT_MAX_BRIDGE, nominal_sample_time, time_steps


@dataclass
class Result:
    """Outcome of identify(): final estimates with 1-sigma and covariance."""

    names: list
    estimate: np.ndarray
    std: np.ndarray
    cov: np.ndarray
    ekf_estimate: np.ndarray
    ekf_std: np.ndarray
    initial: np.ndarray
    truth: object          # array or None
    steps: int
    wall_s: float
    mean_nis_per_dof: float
    refined: bool
    history: dict = field(default_factory=dict)
    R_final: object = None
    Q_final: object = None
    current: object = None   # core.current.CurrentEstimate, or None (still water, not asked)

    def error_pct(self, which='estimate'):
        if self.truth is None:
            return None
        est = getattr(self, which)
        return 100.0 * (est - self.truth) / np.abs(self.truth)


def _record(t, Y, U):
    """(t, Y, U) as contiguous float arrays, checked: t (N,) strictly increasing finite times
    (s), Y (N, 12), U (N, 6)."""
    Y = np.ascontiguousarray(Y, dtype=float)
    U = np.ascontiguousarray(U, dtype=float)
    if (Y.ndim != 2 or Y.shape[1] != N_STATE or U.shape != (Y.shape[0], N_INPUT)
            or Y.shape[0] == 0):
        raise DimensionError(f'Y must be (N, 12) and U (N, 6) with N >= 1; got {Y.shape} and '
                             f'{U.shape}')
    return check_times(t, Y.shape[0]), Y, U


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


def run_ekf(f, t, Y, U, hist_every=0, want_white=False, max_step=None,
            max_bridge=DEFAULT_MAX_BRIDGE):
    """Run the AugmentedEKF `f` over a record with the compiled loop, started from Y[0].

    Parameters
    ----------
    f : AugmentedEKF (its state is replaced by the result)
    t : (N,) sample times (s), strictly increasing; jitter, dropouts and gaps allowed
    Y : (N, 12) measurements (NaN: missing)
    U : (N, 6) inputs, U[k] the command in force over [t_k, t_k+1) (zero-order hold)
    hist_every : record histories every this many samples (0: none)
    want_white : return the whitened innovations (N, 12)
    max_step : s, longest RK4 step of a time update (None: the filter's sample time f.T)
    max_bridge : s, a longer interval restarts the vehicle states (timing.py)

    Returns (stats, histories, whitened innovations); the histories' 't' is the time of each
    recorded sample since the first (s). Raises DomainError/DivergenceError naming the
    sample.
    """
    t, Y, U = _record(t, Y, U)
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
                              'covariance lost positive definiteness (try --noise-mode fixed)')
    hist = {'t': t[::hist_every][:nh] - t[0], 'theta': out.theta, 'std': out.std,
            'nis': out.nis[:, 0], 'dof': out.nis[:, 1], 'R_diag': out.rq[:, :N_STATE],
            'Q_theta_diag': out.rq[:, N_STATE:]} if nh else {}
    return stats, hist, out.white


class FilterErrorResiduals:
    """The filter-error method's residuals as a function of theta: for candidate values of the
    model's parameters, the whitened innovations ``r_k = S_k^{-1/2} nu_k`` (N, 12) of a 12-state
    EKF with those values fixed (NaN where a channel has no measurement). The refinement
    minimises their sum of squares; the automatic selection (selection.py) differentiates them
    with respect to every candidate coefficient.

    model : Model whose theta are the parameters; cfg : FilterConfig (its noise, q_state and
    measured channels are used); t, Y, U, T, max_step, max_bridge as for refine.
    """

    def __init__(self, model, cfg, t, Y, U, T=None, max_step=None,
                 max_bridge=DEFAULT_MAX_BRIDGE):
        t, Y, U = _record(t, Y, U)
        T = nominal_sample_time(t) if T is None else T
        self.model, self.Y, self.U = model, Y, U
        fixed_cfg = FilterConfig(coefficients=[], initial=None, q_state=cfg.q_state,
                                 noise_std=cfg.noise_std, measured=cfg.measured, mode='fixed')
        state_model = Model(model.vehicle, (), mass_inverse=model.mass_inverse,
                            coefficient_values=model.c, current=model.current,
                            velocity_reference=model.velocity_reference)
        f = AugmentedEKF(state_model, fixed_cfg, T)
        self.settings = f.settings()
        self.timeline = _timeline(f, t, Y, U, max_step, max_bridge)
        self.x0, self.P0 = f.initial_estimate(Y[0], U[0, Input.N_RPM])
        self.out = K.new_outputs(N_STATE, Y.shape[0], want_white=True)
        self.white = self.out.white

    def __call__(self, theta):
        """(ok, white): ok False when the filter stopped (the model left its domain or the
        covariance failed); white (N, 12) is the buffer, overwritten by the next call."""
        self.white[:] = np.nan
        K.run_filter(self.x0, self.P0, self.Y, self.U, self.model.compiled_fixed(theta),
                     self.settings, self.timeline, self.out)
        return self.out.stats[0] == K.OK, self.white


def refine(model, cfg, t, Y, U, theta_start, T=None, max_step=None,
           max_bridge=DEFAULT_MAX_BRIDGE, max_nfev=60, progress=None, details=False):
    """Pass 2: filter-error maximum likelihood for theta, started at theta_start (p,).

    t, Y, U, max_step, max_bridge as for run_ekf; T (s) the nominal sample time (None: the
    median interval of t). Returns (theta, cov, cost per residual), and with details=True a
    fourth item, a dict: 'J' (N * 12, p) the Jacobian of the whitened innovations with respect
    to theta, 'white' (N, 12) those innovations at the solution (NaN: no measurement),
    'converged' (bool), 'message' (the optimiser's), 'nfev'. cov is (J^T J)^-1 times the cost
    per residual when that exceeds 1 (the white-noise covariance; core/uncertainty.py has the
    one for coloured residuals)."""
    p = model.p
    fer = FilterErrorResiduals(model, cfg, t, Y, U, T=T, max_step=max_step,
                               max_bridge=max_bridge)
    white = fer.white
    scale = parameter_scale(model, theta_start)

    def residuals(z):
        if progress is not None:
            progress()
        # theta enters through the coefficients of a 12-state filter
        ok, _ = fer(z * scale)
        if not ok:
            return np.full(white.size, 1e3)
        r = white.ravel()
        return np.where(np.isfinite(r), r, 0.0)

    z0 = theta_start / scale
    sol = least_squares(residuals, z0, method='lm', x_scale=np.ones(p), max_nfev=max_nfev * p,
                        diff_step=1e-5)
    J = sol.jac / scale[None, :]
    n_res = np.count_nonzero(sol.fun)
    s2 = 2.0 * sol.cost / max(1, n_res - p)
    try:
        cov = np.linalg.inv(J.T @ J) * max(1.0, s2)
    except np.linalg.LinAlgError:
        raise DivergenceError('batch refinement: the coefficients are not identifiable from '
                              'this run (singular information matrix)') from None
    if not details:
        return sol.x * scale, cov, s2
    residuals(sol.x)            # the innovations at the solution (the last call may differ)
    return sol.x * scale, cov, s2, {'J': J, 'white': white.copy(), 'converged': sol.status > 0,
                                    'message': sol.message, 'nfev': sol.nfev}


def parameter_scale(model, theta):
    """Scale of each parameter in the fit (p,): |theta| for a coefficient (a relative step),
    1 m/s for a current component (which may well be 0)."""
    scale = np.abs(np.asarray(theta, dtype=float)).copy()
    scale[model.p_coef:] = 1.0
    return scale


def identify(model, t, Y, U, cfg, T=None, refine_pass=True, hist_every=0, truth=None,
             progress=None, max_step=None, max_bridge=DEFAULT_MAX_BRIDGE):
    """Identify model.theta_names from measurements Y (N, 12) stamped t (N,) (s) and inputs
    U (N, 6), U[k] the command held over [t_k, t_k+1).

    T (s): the nominal sample time (None: the median interval of t); max_step, max_bridge: as
    for run_ekf; truth: the true coefficients (p_coef,), if known. Returns a Result: the
    coefficients in names/estimate/std/cov, the water current (if the model identifies or
    is given one) in Result.current."""
    t0 = time.perf_counter()
    t, Y, U = _record(t, Y, U)
    T = nominal_sample_time(t) if T is None else T
    f = AugmentedEKF(model, cfg, T)
    stats, hist, _ = run_ekf(f, t, Y, U, hist_every=hist_every, max_step=max_step,
                             max_bridge=max_bridge)
    ekf_est, ekf_cov = f.theta, f.theta_cov
    est, cov = ekf_est, ekf_cov
    if refine_pass and model.p > 0:
        est, cov, _ = refine(model, cfg, t, Y, U, ekf_est, T=T, max_step=max_step,
                             max_bridge=max_bridge, progress=progress)
    est_c, cov_c, ekf_c, ekf_cov_c, current = split_current(model, est, cov, ekf_est, ekf_cov,
                                                            Y[:, State.PSI])
    wall = time.perf_counter() - t0
    return Result(names=list(model.theta_names[:model.p_coef]), estimate=est_c,
                  std=np.sqrt(np.diag(cov_c)), cov=cov_c, ekf_estimate=ekf_c,
                  ekf_std=np.sqrt(np.diag(ekf_cov_c)), initial=f.theta0[:model.p_coef].copy(),
                  truth=None if truth is None else np.asarray(truth, float),
                  steps=int(stats[1]), wall_s=wall,
                  mean_nis_per_dof=float(stats[2] / max(1.0, stats[3])), refined=refine_pass,
                  history=hist, R_final=f.R.copy(), Q_final=f.Q.copy(), current=current)
