"""Trim: the steady straight run of a vehicle at a shaft speed (the start of every run)."""
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import brentq

from auv_ident.core.errors import DomainError
from auv_ident.core.model.state import Input, N_INPUT, N_STATE, State

if TYPE_CHECKING:
    from auv_ident.core.model.hydrodynamics import Model

DEFAULT_DEPTH = 10.0    # m, initial depth (a vehicle that holds heave, a ship, starts at 0)


def rest_inputs(model: 'Model') -> np.ndarray:
    """(n_inputs,) the inputs at rest: fins and shaft at zero, no thrust input, every thruster
    at its neutral command (1500 us for PWM; no thrust)."""
    ui = np.zeros(model.n_inputs)
    ui[N_INPUT:] = [t.neutral for t in model.vehicle.thrusters]
    return ui


def trim_speed(model: 'Model', rpm: float, thrust: float | None = None) -> float:
    """Steady surge speed (m/s) with fins at zero, shaft speed rpm and the thrust input thrust
    (N; None: the vehicle's cruise_thrust, used by measured_thrust propulsion only): X(u) = 0."""
    ui = rest_inputs(model)
    ui[Input.N_RPM] = rpm
    ui[Input.THRUST] = model.vehicle.cruise_thrust if thrust is None else thrust

    def surge(u: float) -> float:
        x = np.zeros(N_STATE)
        x[State.U] = u
        return model.f(x, ui)[State.U]
    lo, hi = 1e-3, 10.0
    if surge(lo) * surge(hi) > 0:
        raise DomainError(f'no steady surge speed in [{lo}, {hi}] m/s at {rpm} rpm, '
                          f'thrust {ui[Input.THRUST]} N')
    return brentq(surge, lo, hi, xtol=1e-12)


def initial_state(model: 'Model', rpm: float, depth: float = DEFAULT_DEPTH) -> np.ndarray:
    """The start of a run (12,): the straight run at rpm at `depth` (m), or for a thruster
    vehicle (ROV, hovering AUV: no cruise) at rest there."""
    x0 = np.zeros(N_STATE)
    x0[State.U] = 0.0 if model.vehicle.hovers else trim_speed(model, rpm)
    x0[State.Z] = depth if model.vehicle.free_states[State.Z] else 0.0
    return x0
