"""The first-order Nomoto steering model, fitted to the yaw rate of measured runs.

    T dr/dt + r = K (delta_r + delta_0),      dpsi/dt = r

K (1/s, negative with our signs: delta_r positive to port turns the ship to port, psi
decreasing), T (s), delta_0 (rad, the rudder offset that keeps a single-screw ship straight).
Every other state is held, so the model is a callable of the ``f(x, u) -> x_dot`` form for
:func:`auv_ident.core.simulation.zigzag_sim.simulate_zigzag`: the simplest model that turns like a
ship, used to show the closed loop and the steering gear's effect on the measures where no
manoeuvring model of the ship is at hand. Linear: one K, T for all rudder angles, so a ship
whose yaw is nonlinear (KVLCC2, close to course-unstable) needs a fit per rudder angle.

Fit (:func:`fit_nomoto`): output error on the yaw rate, r simulated from the run's first
measured r with the measured rudder held between samples (the exact zero-order-hold
solution of the linear ODE), least squares over all samples of all runs.

Reference: K. Nomoto, T. Taguchi, K. Honda, S. Hirano (1957), On the steering qualities of
ships, International Shipbuilding Progress 4; Fossen (2021), sec. 7.1.
"""
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from auv_ident.core.errors import DataError
from auv_ident.core.model.state import Input, N_STATE, State


@dataclass
class NomotoModel:
    """K (1/s), T (s), delta_0 (rad); rms_r : rad/s, the fit's yaw-rate residual rms."""

    K: float
    T: float
    delta_0: float = 0.0
    rms_r: float = float('nan')
    rudder_index: int = Input.DELTA_R

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """x_dot (12,) of the state x (12,) and input u: only r and psi change."""
        xd = np.zeros(N_STATE)
        xd[State.R] = (self.K * (u[self.rudder_index] + self.delta_0) - x[State.R]) / self.T
        xd[State.PSI] = x[State.R]
        return xd

    def yaw_rate(self, t: np.ndarray, delta: np.ndarray, r0: float) -> np.ndarray:
        """(N,) rad/s: r on the stamps t (s) from r0 with delta (rad) held between samples."""
        r = np.empty(len(t))
        r[0] = r0
        a = np.exp(-np.diff(t) / self.T)
        target = self.K * (np.asarray(delta)[:-1] + self.delta_0)
        for k in range(len(t) - 1):
            r[k + 1] = a[k] * r[k] + (1.0 - a[k]) * target[k]
        return r


def fit_nomoto(runs: Sequence[Any]) -> NomotoModel:
    """NomotoModel fitted (module docstring) to runs: measured runs (t, x, inputs['rudder'])
    or (t (N,) s, r (N,) rad/s, delta (N,) rad) tuples."""
    data = []
    for run in runs:
        if isinstance(run, tuple):
            t, r, d = (np.asarray(a, dtype=float) for a in run)
        else:
            t, r, d = run.t, run.x[:, State.R], run.inputs['rudder']
        if not (len(t) == len(r) == len(d) >= 3) or np.any(np.diff(t) <= 0):
            raise DataError('a Nomoto fit needs t, r, delta of one length (>= 3) with '
                            'increasing t')
        data.append((t, r, d))
    if not data:
        raise DataError('fit_nomoto needs at least one run')

    def residuals(p: np.ndarray) -> np.ndarray:
        m = NomotoModel(K=p[0], T=p[1], delta_0=p[2])
        return np.concatenate([m.yaw_rate(t, d, r[0]) - r for t, r, d in data])

    # start: a turning ship's order of magnitude (K ~ -U/L, T ~ L/U for U/L ~ 0.1-1 1/s)
    sol = least_squares(residuals, [-0.1, 10.0, 0.0], x_scale=[0.01, 1.0, 0.01],
                        bounds=([-np.inf, 1e-2, -0.2], [np.inf, 1e3, 0.2]))
    return NomotoModel(K=float(sol.x[0]), T=float(sol.x[1]), delta_0=float(sol.x[2]),
                       rms_r=float(np.sqrt(np.mean(sol.fun ** 2))))
