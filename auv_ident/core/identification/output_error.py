"""Output-error maximum likelihood (Jategaonkar 2015, ch. 4; the paper's Eq. 3 cost), in its
multiple-shooting form.

The output-error method assumes measurement noise only: the model, run open loop with the
measured inputs from a known initial state, must reproduce the measured outputs, and theta
minimises the negative log-likelihood

    J(theta, R) = 1/2 sum_k e_k^T R^-1 e_k + N/2 ln det R,   e_k = y_k - x_hat_k(theta)

over the chosen output channels. For a given R it is a weighted least-squares problem, solved
by trust-region Gauss-Newton (scipy least_squares 'trf' with a sparse Jacobian, below) in
parameters scaled by their start value; R is then re-estimated from the residuals,
R = diag(1/N sum e_k e_k^T) (the maximum-likelihood R for the given theta, kept diagonal for
uncorrelated channels), and the two steps alternate until the cost stops falling (the
relaxation strategy of Jategaonkar ch. 4). 1-sigma: the Gauss-Newton information matrix,
cov = (J_w^T J_w)^-1 with J_w the Jacobian of the whitened residuals (the Cramer-Rao bound).

Why multiple shooting (the record cut into segments that each start afresh): an AUV's free
run drifts in position and heading (neutral modes: no force pulls x, y, psi back), and over
minutes the small velocity errors of a slightly wrong model integrate into large position and
heading errors that swamp the fit. The record is cut into segments of segment_s seconds; each
starts from the measured state at its first sample plus a correction estimated with theta for
the dynamic states (IC_CHANNELS: u v w p q r phi theta; Jategaonkar's initial conditions as
unknowns, one set per segment), and the fitted channels are the velocities and roll and pitch
(FIT_CHANNELS), which the dynamics keep bounded. Position and heading are not fitted. Each
segment's corrections touch only its own residuals, so the Jacobian is sparse and finite
differences perturb all segments' starts at once (p + 8 model runs per Jacobian). Segments
long against the slowest fitted time constant (heave and pitch settle within 2-5 s at 500 rpm
on NPS AUV II) keep the output-error character: each residual is a free-run prediction error.

Time is what the stamps say (timing.py): RK4 steps of at most max_step with the command held;
after an interval longer than max_bridge a new segment starts from the next measured state.
"""
from collections.abc import Sequence
from dataclasses import dataclass
import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix

from auv_ident.core.angles import wrap_angle
from auv_ident.core.errors import ConfigError, DataError, DivergenceError
from auv_ident.core.filter.propagation import simulate_segments
from auv_ident.core.filter.timing import DEFAULT_MAX_BRIDGE, nominal_sample_time, time_steps
from auv_ident.core.identification.batch import _record, parameter_scale
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import N_STATE, State, STATE_NAMES

# outputs fitted by default: the velocities, roll and pitch (bounded by the dynamics)
FIT_CHANNELS = (State.U, State.V, State.W, State.P, State.Q, State.R, State.PHI, State.THETA)
# states a segment's start needs from the measurement (the dynamics depend on these)
START_CHANNELS = (State.U, State.V, State.W, State.P, State.Q, State.R, State.PHI,
                  State.THETA, State.PSI)
# states of a segment's start estimated with theta (the noise of a measured start would be a
# transient error of the whole segment, which biases theta: Z_w -68 % on 10 s segments of a
# 120 s run when the starts were taken as measured)
IC_CHANNELS = (State.U, State.V, State.W, State.P, State.Q, State.R, State.PHI, State.THETA)
DEFAULT_SEGMENT_S = 20.0      # s, length of a shooting segment
MAX_RELAXATIONS = 4           # alternations of theta (Gauss-Newton) and R (from the residuals)
RELAXATION_TOL = 1e-3         # relative fall of the likelihood cost that ends them


@dataclass
class OutputErrorResult:
    """theta (p,) the estimate, cov (p, p) its Cramer-Rao covariance, noise_std (12,) the
    output 1-sigma estimated from the residuals (NaN: not fitted), segments, converged, nfev,
    wall_s (s)."""

    names: list
    theta: np.ndarray
    cov: np.ndarray
    noise_std: np.ndarray
    segments: int
    channels: list
    converged: bool
    nfev: int
    wall_s: float

    @property
    def theta_std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))


def segment_starts(t: np.ndarray, Y: np.ndarray, n_sub: np.ndarray,
                   segment_s: float) -> np.ndarray:
    """(N,) bool: the samples a segment starts from: the first sample whose START_CHANNELS are
    all measured, then the first such sample segment_s (s) or more after the last start, and
    the first such sample after a gap (n_sub == 0)."""
    ok = np.all(np.isfinite(Y[:, list(START_CHANNELS)]), axis=1)
    start = np.zeros(len(t), dtype=bool)
    last = -np.inf
    pending = True
    for k in range(len(t)):
        if k > 0 and n_sub[k] == 0:
            pending = True
        if ok[k] and (pending or t[k] - last >= segment_s - 1e-9):
            start[k] = True
            last = t[k]
            pending = False
    return start


def segment_index(start: np.ndarray, n_sub: np.ndarray) -> np.ndarray:
    """(N,) int: the segment each sample belongs to (0, 1, ... in order of the starts), -1
    before the first start and after a gap (n_sub == 0) until the next start."""
    seg = np.full(len(start), -1, dtype=np.int64)
    s = -1
    active = False
    for k in range(len(start)):
        if start[k]:
            s += 1
            active = True
        elif k > 0 and n_sub[k] == 0:
            active = False           # a gap: nothing is simulated until the next start
        if active:
            seg[k] = s
    return seg


def output_error(model: Model, t: np.ndarray, Y: np.ndarray, U: np.ndarray, theta0: ArrayLike,
                 noise_std: ArrayLike, T: float | None = None,
                 segment_s: float = DEFAULT_SEGMENT_S, channels: Sequence[int] = FIT_CHANNELS,
                 max_step: float | None = None, max_bridge: float = DEFAULT_MAX_BRIDGE,
                 max_nfev: int = 50) -> OutputErrorResult:
    """Output-error estimate of model.theta_names (module docstring).

    Parameters
    ----------
    model : core.model.hydrodynamics.Model with the parameters to identify
    t, Y, U : (N,) s stamps, (N, 12) measurements (NaN: missing), (N, 6) inputs held over
        [t_k, t_k+1)
    theta0 : (p,) start of the search (nonzero coefficients: they scale the search)
    noise_std : (12,) measurement 1-sigma: the first relaxation's weights, and the unit of the
        segments' initial-state corrections
    T : s nominal sample time (None: median interval); max_step (None: T), max_bridge: s
    segment_s : s, length of a shooting segment (the whole record: a value >= its length)
    channels : indices of the fitted outputs (default FIT_CHANNELS)
    max_nfev : iterations per relaxation, at most

    Returns OutputErrorResult. Raises DataError when no segment can start or too few samples
    are left, DivergenceError when the information matrix is singular.
    """
    t0 = time.perf_counter()
    t, Y, U = _record(t, Y, U)
    T = nominal_sample_time(t) if T is None else float(T)
    max_step = T if max_step is None else float(max_step)
    if not segment_s > 0.0:
        raise ConfigError(f'segment_s = {segment_s!r} s must be positive')
    theta0 = np.asarray(theta0, dtype=float)
    p = model.p
    if theta0.shape != (p,) or not np.all(np.isfinite(theta0)):
        raise ConfigError(f'output error: theta0 must be {p} finite values, got {theta0}')
    noise_std = np.asarray(noise_std, dtype=float)
    channels = [int(c) for c in channels]
    n_sub, h = time_steps(t, max_step, float(max_bridge))
    start = segment_starts(t, Y, n_sub, segment_s)
    if not start.any():
        raise DataError('output error: no sample has ' + ', '.join(
            STATE_NAMES[i] for i in START_CHANNELS) + ' all measured to start a segment from')
    seg = segment_index(start, n_sub)
    n_seg = int(start.sum())
    Yc = Y[:, channels]
    use = np.isfinite(Yc) & (seg >= 0)[:, None]
    if use.sum() < 2 * p + n_seg * len(IC_CHANNELS):
        raise DataError(f'output error: only {int(use.sum())} measured outputs to fit '
                        f'{p} parameters and {n_seg} segment starts')
    angle = np.isin(channels, (State.PHI, State.THETA, State.PSI))
    cm = model.compiled
    scale = parameter_scale(model, theta0)
    X = np.empty_like(Y)
    X0_measured = np.where(np.isfinite(Y[start]), Y[start], 0.0)    # (S, 12)
    ic = list(IC_CHANNELS)
    ic_scale = noise_std[ic]
    weights = 1.0 / noise_std[channels]

    def errors(z: np.ndarray) -> np.ndarray:
        X0 = X0_measured.copy()
        X0[:, ic] += z[p:].reshape(n_seg, len(ic)) * ic_scale
        simulate_segments(z[:p] * scale, X0, U, seg, n_sub, h, cm, X)
        e = Yc - X[:, channels]
        e[:, angle] = wrap_angle(np.where(np.isfinite(e[:, angle]), e[:, angle], 0.0))
        return e

    def residuals(z: np.ndarray, w: np.ndarray) -> np.ndarray:
        r = (errors(z) * w)[use]
        # a segment that left the model's domain counts as a large miss (the search backs off)
        return np.where(np.isfinite(r), r, 1e3)

    sparsity = jacobian_sparsity(seg, use, p, n_seg, len(ic))
    z = np.concatenate([theta0 / scale, np.zeros(n_seg * len(ic))])
    cost_prev = np.inf
    nfev = 0
    converged = False
    for _ in range(MAX_RELAXATIONS):
        sol = least_squares(residuals, z, args=(weights,), method='trf',
                            jac_sparsity=sparsity, tr_solver='lsmr', x_scale=1.0,
                            max_nfev=max_nfev, diff_step=1e-6)
        z = sol.x
        nfev += sol.nfev
        J = sol.jac
        e = errors(z)
        e[~use] = np.nan
        sd = np.sqrt(np.nanmean(e ** 2, axis=0))
        # R from the residuals; the likelihood is then N/2 ln det R + const
        cost = float(np.sum(np.sum(use, axis=0) * np.log(sd)))
        row_factor = np.broadcast_to(1.0 / (sd * weights), use.shape)[use]
        weights = 1.0 / sd
        J = J.multiply(row_factor[:, None]).tocsr() if hasattr(J, 'multiply') \
            else J * row_factor[:, None]
        converged = sol.status > 0
        if cost_prev - cost < RELAXATION_TOL * abs(cost_prev) or not np.isfinite(cost):
            break
        cost_prev = cost
    # Cramer-Rao bound of theta: its block of (J^T J)^-1, the segments' starts estimated too
    A = J.T @ J
    A = A.toarray() if hasattr(A, 'toarray') else np.asarray(A)
    try:
        cov = np.linalg.inv(A)[:p, :p] * np.outer(scale, scale)
    except np.linalg.LinAlgError:
        raise DivergenceError('output error: the parameters are not identifiable from these '
                              'outputs (singular information matrix)') from None
    noise = np.full(N_STATE, np.nan)
    noise[channels] = 1.0 / weights
    return OutputErrorResult(names=list(model.theta_names), theta=z[:p] * scale, cov=cov,
                             noise_std=noise, segments=n_seg,
                             channels=[STATE_NAMES[c] for c in channels], converged=converged,
                             nfev=nfev, wall_s=time.perf_counter() - t0)


def jacobian_sparsity(seg: np.ndarray, use: np.ndarray, p: int, n_seg: int, n_ic: int) -> Any:
    """Sparsity (M, p + n_seg n_ic) of the residuals' Jacobian: every residual depends on theta,
    and on the initial-state corrections of its own segment only (what lets the finite
    differences perturb the starts of all segments at once)."""
    k_idx = np.nonzero(use)[0]                 # sample of each residual, in residual order
    rows_theta = np.repeat(np.arange(k_idx.size), p)
    cols_theta = np.tile(np.arange(p), k_idx.size)
    rows_ic = np.repeat(np.arange(k_idx.size), n_ic)
    cols_ic = (p + seg[k_idx][:, None] * n_ic + np.arange(n_ic)[None, :]).ravel()
    rows = np.concatenate([rows_theta, rows_ic])
    cols = np.concatenate([cols_theta, cols_ic])
    return coo_matrix((np.ones(rows.size), (rows, cols)),
                      shape=(k_idx.size, p + n_seg * n_ic)).tocsr()
