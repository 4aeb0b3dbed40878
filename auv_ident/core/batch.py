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
"""
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from . import ekf as K
from .errors import DimensionError, DivergenceError, DomainError
from .filter import AugmentedEKF, FilterConfig
from .model import STATUS_TEXT


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

    def error_pct(self, which='estimate'):
        if self.truth is None:
            return None
        est = getattr(self, which)
        return 100.0 * (est - self.truth) / np.abs(self.truth)


def run_ekf(f, Y, U, hist_every=0, want_white=False):
    """Run an AugmentedEKF `f` (already started? no: from Y[0]) over Y, U with the compiled loop.

    Returns (stats, histories). Raises DomainError/DivergenceError naming the sample.
    """
    Y = np.ascontiguousarray(Y, dtype=float)
    U = np.ascontiguousarray(U, dtype=float)
    if Y.ndim != 2 or Y.shape[1] != 12 or U.shape != (Y.shape[0], 6):
        raise DimensionError(f'Y must be (N, 12) and U (N, 6); got {Y.shape} and {U.shape}')
    N = Y.shape[0]
    m = f.model
    xa0, P0 = f.initial_estimate(Y[0], U[0, 5])
    out = K.new_outputs(f.n, N, hist_every, want_white)
    K.run_filter(xa0, P0, Y, U, m.compiled, f.settings(), out)
    stats = out.stats
    nh = out.theta.shape[0]
    st = int(stats[0])
    f.xa, f.P, f.Q, f.R, f.steps = out.xa, out.P, out.Q, out.R, int(stats[1])
    if st != K.OK:
        k = int(stats[1])
        if st in STATUS_TEXT:
            raise DomainError(f'EKF stopped at sample {k} (t = {k * f.T:.2f} s): '
                              f'{STATUS_TEXT[st]}')
        raise DivergenceError(f'EKF diverged at sample {k} (t = {k * f.T:.2f} s): the '
                              'covariance lost positive definiteness (try --noise-mode fixed)')
    hist = {'t': np.arange(nh) * hist_every * f.T, 'theta': out.theta, 'std': out.std,
            'nis': out.nis[:, 0], 'dof': out.nis[:, 1], 'R_diag': out.rq[:, :12],
            'Q_theta_diag': out.rq[:, 12:]} if nh else {}
    return stats, hist, out.white


def refine(model, cfg, Y, U, T, theta_start, max_nfev=60, progress=None):
    """Pass 2: filter-error maximum likelihood for theta, started at theta_start.

    Returns (theta, cov, cost per residual)."""
    p = model.p
    fixed_cfg = FilterConfig(coefficients=[], initial=None, q_state=cfg.q_state,
                             noise_std=cfg.noise_std, measured=cfg.measured, mode='fixed')
    from .model import Model
    state_model = Model(model.vehicle, (), mass_inverse=model.mass_inverse,
                        coefficient_values=model.c)
    f = AugmentedEKF(state_model, fixed_cfg, T)
    settings = f.settings()
    Y = np.ascontiguousarray(Y, dtype=float)
    U = np.ascontiguousarray(U, dtype=float)
    N = Y.shape[0]
    x0, P0 = f.initial_estimate(Y[0], U[0, 5])
    out = K.new_outputs(12, N, want_white=True)
    white = out.white
    scale = np.abs(theta_start)

    def residuals(z):
        if progress is not None:
            progress()
        # theta enters through the coefficients of a 12-state filter
        white[:] = np.nan
        K.run_filter(x0, P0, Y, U, model.compiled_fixed(z * scale), settings, out)
        if out.stats[0] != K.OK:
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
    return sol.x * scale, cov, s2


def identify(model, Y, U, T, cfg, refine_pass=True, hist_every=0, truth=None, progress=None):
    """Identify model.theta_names from measurements Y (N, 12) and inputs U (N, 6) at T.

    U[k] is the command held over [t_k, t_k+1). Returns a Result."""
    t0 = time.perf_counter()
    f = AugmentedEKF(model, cfg, T)
    stats, hist, _ = run_ekf(f, Y, U, hist_every=hist_every)
    ekf_est, ekf_std = f.theta, f.theta_std
    est, cov = ekf_est, f.theta_cov
    if refine_pass and model.p > 0:
        est, cov, _ = refine(model, cfg, Y, U, T, ekf_est, progress=progress)
    wall = time.perf_counter() - t0
    return Result(names=list(model.theta_names), estimate=est, std=np.sqrt(np.diag(cov)),
                  cov=cov, ekf_estimate=ekf_est, ekf_std=ekf_std, initial=f.theta0.copy(),
                  truth=None if truth is None else np.asarray(truth, float),
                  steps=int(stats[1]), wall_s=wall,
                  mean_nis_per_dof=float(stats[2] / max(1.0, stats[3])), refined=refine_pass,
                  history=hist, R_final=f.R.copy(), Q_final=f.Q.copy())
