"""Simulator core: integrate a vehicle under a manoeuvre and add sensor noise (no ROS).

Sensor-noise defaults: :mod:`auv_ident.core.model.sensors`. With a water current (constant in NED,
Fossen 2021 sec. 10.3; the model's equations in core/model/hydrodynamics.py) the true state holds
the velocity over ground, and the velocity sensor measures it over ground (DVL in bottom lock) or
through the water (``velocity_reference='water'``: u v w minus R^T v_c).
"""
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.angles import wrap_angle
from auv_ident.core.errors import ConfigError
from auv_ident.core.model.current import body_current
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.integrators import rk4_step
from auv_ident.core.model.sensors import DEFAULT_NOISE_STD, DEFAULT_T
from auv_ident.core.model.state import (
    EULER,
    INPUT_NAMES,
    LINEAR,
    N_CURRENT,
    N_NU,
    N_STATE,
    NU,
    State,
    STATE_NAMES,
    VELOCITY_REFERENCES,
)
from auv_ident.core.model.thruster_lag import LaggedDerivative
from auv_ident.core.model.trim import initial_state
from auv_ident.core.model.vehicle import P_FIN
from auv_ident.core.simulation import maneuvers


@dataclass
class Run:
    """A simulated run sampled at T: t (N,), x true states (N, 12), y measurements (N, 12),
    u applied commands (N, 7 + thrusters): u[k] is held over [t_k, t_k+1)."""

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
    current: np.ndarray | None = None  # (3,) m/s NED, the water current (None: still water)
    velocity_reference: str = 'ground'  # what y's u v w are
    # the names of u's columns: state.Input's, then a thruster vehicle's thrusters
    input_names: tuple = INPUT_NAMES

    def summary(self) -> dict[str, Any]:
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


def simulate(model: Model, maneuver: str = 'zigzag', duration: float = 200.0, T: float = DEFAULT_T,
             seed: int = 0, rpm: float | None = None, noise_std: ArrayLike | None = None,
             process_std: ArrayLike | None = None, x0: ArrayLike | None = None, substeps: int = 1,
             current: ArrayLike | None = None, velocity_reference: str = 'ground') -> Run:
    """Integrate the model with RK4 (step T/substeps) and sample every T.

    Parameters
    ----------
    model : core.model.hydrodynamics.Model  (the truth; its coefficient values are the true ones)
    maneuver : str            name in maneuvers.MANEUVERS or a CSV path
    duration : float          s
    noise_std : (12,) array   measurement noise 1-sigma (DEFAULT_NOISE_STD); zeros for none
    process_std : (6,) array  white acceleration noise on nu_dot, or None for none
    current : (3,) array      m/s NED, a constant water current (where the water goes); None
                              or zeros for still water. The run starts in the trimmed straight
                              run through the water (x0 over ground, unless x0 is given).
    velocity_reference : 'ground' or 'water', what the measured u v w are
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
    if velocity_reference not in VELOCITY_REFERENCES:
        raise ConfigError(f'velocity_reference = {velocity_reference!r}; use ground or water')
    vc = None
    trim = initial_state(model, rpm) if x0 is None else None   # through the water
    if current is not None:
        vc = np.asarray(current, dtype=float)
        if vc.shape != (N_CURRENT,) or not np.all(np.isfinite(vc)):
            raise ConfigError(f'current must be 3 finite numbers (N, E, D m/s), got {current!r}')
        if np.any(vc != 0.0):
            # the truth with the current, its state over ground
            model = Model(model.vehicle, (), mass_inverse=model.mass_inverse,
                          coefficient_values=model.c, current=vc)
        else:
            vc = None
    rng = np.random.default_rng(seed)
    n = int(round(duration / T)) + 1
    t = np.arange(n) * T
    if model.vehicle.hovers:        # an ROV: a pilot's sticks mixed into thruster commands
        u = maneuvers.thruster_commands(maneuver, t, model.vehicle, seed=seed)
    else:
        u = maneuvers.commands(maneuver, t, rpm=rpm, seed=seed,
                               fin_limit=model.vehicle.par[P_FIN],
                               thrust=model.vehicle.cruise_thrust)
    x = np.empty((n, N_STATE))
    if x0 is None:
        x[0] = trim
        if vc is not None:
            x[0, LINEAR] += body_current(vc, *x[0, EULER])
    else:
        x[0] = x0
    h = T / substeps
    f = model.f
    # a vehicle whose thrusters lag: its RK4 steps carry the delivered thrust (from rest:
    # settled at the first command)
    lagged = LaggedDerivative(model) if model.vehicle.lagged else None
    for k in range(n - 1):
        xk = x[k]
        for _ in range(substeps):
            xk = rk4_step(f, xk, u[k], h) if lagged is None else lagged.step(xk, u[k], h)
        if process_std is not None:
            # white acceleration over one sample: velocity increment ~ N(0, (sigma^2) T)
            xk = xk.copy()
            xk[NU] += rng.normal(0.0, 1.0, N_NU) * np.asarray(process_std) * np.sqrt(T)
        x[k + 1] = xk
    x[:, State.PSI] = wrap_angle(x[:, State.PSI])
    meas = x
    if vc is not None and velocity_reference == 'water':
        meas = x.copy()
        meas[:, LINEAR] -= body_current(vc, x[:, State.PHI], x[:, State.THETA], x[:, State.PSI])
    y = meas + rng.normal(0.0, 1.0, x.shape) * noise_std
    y[:, EULER] = wrap_angle(y[:, EULER])
    return Run(model.vehicle.name, str(maneuver), T, seed, t, x, y, u, noise_std,
               np.zeros(6) if process_std is None else np.asarray(process_std, float),
               None if vc is None else vc.copy(), velocity_reference,
               model.vehicle.input_names)


def save_run_csv(run: Run, path: str) -> None:
    """Write a run as CSV: t, true states, measured states (y_*), inputs (documented in README)."""
    header = ['t'] + list(STATE_NAMES) + ['y_' + s for s in STATE_NAMES] + list(run.input_names)
    data = np.column_stack([run.t, run.x, run.y, run.u])
    np.savetxt(path, data, delimiter=',', header=','.join(header), comments='', fmt='%.17g')
