"""Simulator core: integrate a vehicle under a manoeuvre and add sensor noise (no ROS).

Sensor-noise defaults: :mod:`auv_ident.core.sensors`.
"""
from dataclasses import dataclass

import numpy as np

from . import maneuvers
from .angles import wrap_angle
from .errors import ConfigError
from .integrators import rk4_step
from .sensors import DEFAULT_NOISE_STD, DEFAULT_T
from .state import EULER, INPUT_NAMES, LINEAR, N_NU, N_STATE, NU, State, STATE_NAMES
from .trim import initial_state
from .vehicle import P_FIN


@dataclass
class Run:
    """A simulated run sampled at T: t (N,), x true states (N, 12), y measurements (N, 12),
    u applied commands (N, 6): u[k] is held over [t_k, t_k+1)."""

    vehicle: str
    maneuver: str
    T: float
    seed: int
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    u: np.ndarray
    noise_std: np.ndarray
    process_std: np.ndarray

    def summary(self):
        x = self.x
        U = np.linalg.norm(x[:, LINEAR], axis=1)
        return {
            'vehicle': self.vehicle, 'maneuver': self.maneuver, 'duration_s': float(self.t[-1]),
            'samples': len(self.t), 'T_s': self.T, 'seed': self.seed,
            'final_state': {n: float(v) for n, v in zip(STATE_NAMES, x[-1])},
            'speed_m_s': {'mean': float(U.mean()), 'min': float(U.min()), 'max': float(U.max())},
            'depth_m': {'min': float(x[:, State.Z].min()), 'max': float(x[:, State.Z].max())},
            'roll_deg_max': float(np.rad2deg(np.abs(x[:, State.PHI]).max())),
            'std': {'v': float(x[:, State.V].std()), 'w': float(x[:, State.W].std()),
                    'p': float(x[:, State.P].std())},
        }


def simulate(model, maneuver='zigzag', duration=200.0, T=DEFAULT_T, seed=0, rpm=None,
             noise_std=None, process_std=None, x0=None, substeps=1):
    """Integrate the model with RK4 (step T/substeps) and sample every T.

    Parameters
    ----------
    model : core.model.Model  (the truth; its coefficient values are the true ones)
    maneuver : str            name in maneuvers.MANEUVERS or a CSV path
    duration : float          s
    noise_std : (12,) array   measurement noise 1-sigma (DEFAULT_NOISE_STD); zeros for none
    process_std : (6,) array  white acceleration noise on nu_dot, or None for none
    """
    if not np.isfinite(duration) or duration <= 0:
        raise ConfigError(f'duration = {duration!r} s must be positive')
    if not np.isfinite(T) or T <= 0:
        raise ConfigError(f'sample time T = {T!r} s must be positive')
    rpm = model.vehicle.cruise_rpm if rpm is None else float(rpm)
    noise_std = DEFAULT_NOISE_STD.copy() if noise_std is None else np.asarray(noise_std, float)
    if (noise_std.shape != (N_STATE,) or np.any(noise_std < 0)
            or not np.all(np.isfinite(noise_std))):
        raise ConfigError(f'noise_std must be 12 non-negative numbers, got {noise_std}')
    rng = np.random.default_rng(seed)
    n = int(round(duration / T)) + 1
    t = np.arange(n) * T
    u = maneuvers.commands(maneuver, t, rpm=rpm, seed=seed,
                           fin_limit=model.vehicle.par[P_FIN])
    x = np.empty((n, N_STATE))
    x[0] = initial_state(model, rpm) if x0 is None else x0
    h = T / substeps
    f = model.f
    for k in range(n - 1):
        xk = x[k]
        for _ in range(substeps):
            xk = rk4_step(f, xk, u[k], h)
        if process_std is not None:
            # white acceleration over one sample: velocity increment ~ N(0, (sigma^2) T)
            xk = xk.copy()
            xk[NU] += rng.normal(0.0, 1.0, N_NU) * np.asarray(process_std) * np.sqrt(T)
        x[k + 1] = xk
    x[:, State.PSI] = wrap_angle(x[:, State.PSI])
    y = x + rng.normal(0.0, 1.0, x.shape) * noise_std
    y[:, EULER] = wrap_angle(y[:, EULER])
    return Run(model.vehicle.name, str(maneuver), T, seed, t, x, y, u, noise_std,
               np.zeros(6) if process_std is None else np.asarray(process_std, float))


def save_run_csv(run, path):
    """Write a run as CSV: t, true states, measured states (y_*), inputs (documented in README)."""
    header = (['t'] + list(STATE_NAMES) + ['y_' + s for s in STATE_NAMES] + list(INPUT_NAMES))
    data = np.column_stack([run.t, run.x, run.y, run.u])
    np.savetxt(path, data, delimiter=',', header=','.join(header), comments='', fmt='%.17g')
