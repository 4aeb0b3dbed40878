"""Equation-error least squares (Jategaonkar 2015, ch. 6; Klein & Morelli 2006, regression
methods): the force equations regressed on the coefficients that enter them linearly.

The model is M nu_dot = F(nu, eta, delta, c) (model/hydrodynamics.py) and every hydrodynamic or
control coefficient c_j has one monomial term in one equation e_j: c_j s_j z_a z_b ... (s_j =
(rho/2) L^k for prime values, model/vehicle.py), linear in c_j. With the measured velocities
smoothed and differentiated (Savitzky-Golay, a local cubic over window_s seconds: nu_s,
nu_dot_s), each sample gives per equation e

    y_e = [M (nu_dot_s - f_0(nu_s, eta_s, delta))]_e = sum_{j in e} c_j x_j,
    x_j = dF_e / dc_j = s_j z_a z_b ...

with f_0 the model's x_dot with the identified coefficients set to 0 (the known terms: the
other coefficients, rigid-body Coriolis, restoring, propeller, cross-flow) and M the mass matrix
the model uses (M = (model's M^-1)^-1, so the literal MSS inverse of NPS AUV II is honoured).
The coefficients of each equation are one ordinary least-squares fit; their 1-sigma is the
Newey-West sandwich on the regression residuals (core/identification/uncertainty.py), because
smoothing makes neighbouring residuals correlated over the window and the white-noise formula s^2
(X^T X)^-1 would be too narrow by about sqrt(window samples).

Refused, with the reason per coefficient (:func:`refusals`):
- added-mass coefficients (X_udot, Z_wdot, ...): they are entries of M, multiplying the
  differentiated acceleration, not monomials of F; the regression here takes M as known;
- coefficients whose term needs a velocity that is not measured;
- the water current (not a force coefficient; the regression assumes still water).

Assumptions: still water, the measured velocities and roll/pitch are the states (no sensor
lag), noise small against the motion. Noise in the regressors (errors in variables) biases the
estimates toward 0: the smoothing window trades that against the lag it adds.
"""
from dataclasses import dataclass, field
import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.errors import ConfigError, DataError
from auv_ident.core.filter.timing import DEFAULT_MAX_BRIDGE, nominal_sample_time
from auv_ident.core.identification.uncertainty import sandwich_covariance
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import N_NU, N_STATE, State, STATE_NAMES
from auv_ident.core.model.vehicle import EQUATIONS

DEFAULT_WINDOW_S = 2.0     # s, Savitzky-Golay window of the smoothing and differentiation
POLYORDER = 3              # local cubic: nu_dot is the local quadratic's value
# channels the regression needs measured: the velocities (all six enter M nu_dot) and roll and
# pitch (restoring forces)
NEEDED = (State.U, State.V, State.W, State.P, State.Q, State.R, State.PHI, State.THETA)


@dataclass
class EquationErrorResult:
    """names (p,), estimate and std (p,; NaN where refused), refused {name: reason}, per
    equation the coefficient of determination R^2 of its fit, samples used, wall_s (s)."""

    names: list
    estimate: np.ndarray
    std: np.ndarray
    refused: dict
    r_squared: dict = field(default_factory=dict)
    samples: int = 0
    wall_s: float = 0.0


def refusals(model: Model, measured: np.ndarray) -> dict[str, str]:
    """{name: reason} of the model's parameters the equation error cannot estimate."""
    v = model.vehicle
    out = {}
    for name in model.theta_names:
        if name in model.current_names:
            out[name] = ('a water-current component, not a force coefficient (the equation '
                         'error assumes still water)')
            continue
        c = v.coefficients[v.index(name)]
        if c.is_thrust_lag:
            out[name] = ("the thrusters' time constant: the thrust at an instant depends on the "
                         'command history through it, not a term of F at that instant; use '
                         'the EKF (identify) or output error')
            continue
        if c.is_added_mass:
            out[name] = (f'added mass: an entry of the mass matrix M (it multiplies '
                         f'{STATE_NAMES[c.added_mass_col]}_dot), not a monomial of the force '
                         'F, which the regression is linear in; use another method')
            continue
        missing = sorted({STATE_NAMES[f % N_NU] for f in c.factors
                          if f < 12 and not measured[f % N_NU]})
        if missing:
            out[name] = f'its term needs {", ".join(missing)}, which is not measured'
    return out


def _runs(t: np.ndarray, ok: np.ndarray, max_bridge: float) -> list[np.ndarray]:
    """Index arrays of the maximal runs of samples with ok set and no interval longer than
    max_bridge (s) inside."""
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return []
    cut = np.flatnonzero(np.diff(t[idx]) > max_bridge) + 1
    return np.split(idx, cut)


def smoothing_window(window_s: float, T: float) -> int:
    """The Savitzky-Golay window in samples (odd) for window_s seconds at step T (s)."""
    win = int(round(window_s / T)) | 1
    if win <= POLYORDER + 1:
        raise ConfigError(f'equation error: the smoothing window {window_s} s is {win} samples '
                          f'at T = {T} s; it needs more than {POLYORDER + 1}')
    return win


def smoothed_runs(t: np.ndarray, Y: np.ndarray, U: np.ndarray, T: float, win: int,
                  max_bridge: float) -> list[tuple[Any, ...]]:
    """Per run of measured samples, on a uniform grid (step T) over it: the smoothed states
    (n, 12: u..r, phi, theta filled, the rest 0), their smoothed rates nu_dot (n, 6) and the
    inputs held at the grid times (n, 6); runs shorter than two windows are left out."""
    from scipy.signal import savgol_filter  # here: scipy.signal loads scipy.stats (bounded memory)
    ok = np.all(np.isfinite(Y[:, list(NEEDED)]), axis=1)
    out = []
    for run in _runs(t, ok, max_bridge):
        tr = t[run]
        grid = np.arange(tr[0], tr[-1] + 0.5 * T, T)
        if grid.size < 2 * win:
            continue
        cols = np.column_stack([np.interp(grid, tr, Y[run, i]) for i in NEEDED])
        x = np.zeros((grid.size, N_STATE))
        x[:, list(NEEDED)] = savgol_filter(cols, win, POLYORDER, axis=0)
        nu_dot = savgol_filter(cols[:, :N_NU], win, POLYORDER, deriv=1, delta=T, axis=0)
        held = np.clip(np.searchsorted(t, grid, side='right') - 1, 0, len(t) - 1)
        out.append((x, nu_dot, U[held]))
    if not out:
        raise DataError('equation error: no stretch of measured velocities and attitude is '
                        f'two smoothing windows ({2 * win * T:g} s) long')
    return out


def equation_error(model: Model, t: ArrayLike, Y: np.ndarray, U: np.ndarray,
                   measured: np.ndarray | None = None, T: float | None = None,
                   window_s: float = DEFAULT_WINDOW_S,
                   max_bridge: float = DEFAULT_MAX_BRIDGE) -> EquationErrorResult:
    """Equation-error estimate of model.theta_names (module docstring).

    Parameters
    ----------
    model : core.model.hydrodynamics.Model with the parameters to identify
    t, Y, U : (N,) s stamps, (N, 12) measurements (NaN: missing), (N, 6) inputs held over
        [t_k, t_k+1)
    measured : (12,) bool, the channels the sensors provide (None: those with any finite
        sample)
    T : s, the grid step (None: the median interval); window_s: s, smoothing window;
    max_bridge : s, a longer interval between measurements splits the record

    Returns EquationErrorResult; refused coefficients have NaN estimates and their reason.
    """
    t0 = time.perf_counter()
    t = np.asarray(t, dtype=float)
    Y = np.asarray(Y, dtype=float)
    U = np.asarray(U, dtype=float)
    T = nominal_sample_time(t) if T is None else float(T)
    measured = (np.any(np.isfinite(Y), axis=0) if measured is None
                else np.asarray(measured, dtype=bool))
    p = model.p
    names = list(model.theta_names)
    refused = refusals(model, measured)
    estimate = np.full(p, np.nan)
    std = np.full(p, np.nan)
    fit = [j for j, n in enumerate(names) if n not in refused]
    result = EquationErrorResult(names=names, estimate=estimate, std=std, refused=refused)
    if not fit:
        result.wall_s = time.perf_counter() - t0
        return result
    unmeasured = [STATE_NAMES[i] for i in NEEDED if not measured[i]]
    if unmeasured:
        raise DataError('equation error needs the velocities and roll and pitch measured; '
                        f'not measured: {", ".join(unmeasured)}')
    win = smoothing_window(window_s, T)
    M = np.linalg.inv(model.Minv)
    zero = np.zeros(p)
    eq_of = np.array([model.vehicle.coefficients[model.vehicle.index(names[j])].equation
                      if j in fit else -1 for j in range(p)])
    forces, regs = [], []
    for x, nu_dot, u in smoothed_runs(t, Y, U, T, win, max_bridge):
        n = x.shape[0]
        known = np.empty((n, N_NU))        # M f_0: the known part of the force
        reg = np.empty((n, p))             # dF_e / dc_j for each coefficient's own equation
        for k in range(n):
            f0, _, Bt = model.jacobians(x[k], u[k], zero)
            known[k] = M @ f0[:N_NU]
            reg[k] = (M @ Bt[:N_NU])[eq_of.clip(0), np.arange(p)]
        # the same smoothing on the right-hand side as on nu_dot: the relation is linear in c,
        # so it survives, and a fin step (a jump of the regressor that the smoothed nu_dot
        # spreads over the window) is spread the same way on both sides
        from scipy.signal import savgol_filter  # not at the top: see smoothed_runs
        known = savgol_filter(known, win, POLYORDER, axis=0)
        reg = savgol_filter(reg, win, POLYORDER, axis=0)
        keep = slice(win // 2, n - win // 2)   # the polynomial is extrapolated at the ends
        forces.append((nu_dot @ M.T - known)[keep])
        regs.append(reg[keep])
    force = np.vstack(forces)           # y = M nu_dot - M f_0, per equation
    regressors = np.vstack(regs)
    n = force.shape[0]
    for eq in sorted(set(eq_of[fit])):
        cols = [j for j in fit if eq_of[j] == eq]
        A = regressors[:, cols]
        y = force[:, eq]
        c, *_ = np.linalg.lstsq(A, y, rcond=None)
        e = y - A @ c
        s = np.sqrt(e @ e / max(1, n - len(cols)))
        cov, _ = sandwich_covariance(A / s, (e / s)[:, None])
        estimate[cols] = c
        std[cols] = np.sqrt(np.diag(cov))
        result.r_squared[EQUATIONS[eq]] = float(1.0 - (e @ e) / np.sum((y - y.mean()) ** 2))
    result.samples = n
    result.wall_s = time.perf_counter() - t0
    return result
