"""Trim: the steady straight run of a vehicle at a shaft speed (the start of every run)."""
import numpy as np
from scipy.optimize import brentq

from .errors import DomainError
from .state import Input, N_INPUT, N_STATE, State

DEFAULT_DEPTH = 10.0    # m, initial depth


def trim_speed(model, rpm):
    """Steady surge speed (m/s) with fins at zero and shaft speed rpm: X(u) = 0."""
    ui = np.zeros(N_INPUT)
    ui[Input.N_RPM] = rpm

    def surge(u):
        x = np.zeros(N_STATE)
        x[State.U] = u
        return model.f(x, ui)[State.U]
    lo, hi = 1e-3, 10.0
    if surge(lo) * surge(hi) > 0:
        raise DomainError(f'no steady surge speed in [{lo}, {hi}] m/s at {rpm} rpm')
    return brentq(surge, lo, hi, xtol=1e-12)


def initial_state(model, rpm, depth=DEFAULT_DEPTH):
    x0 = np.zeros(N_STATE)
    x0[State.U] = trim_speed(model, rpm)
    x0[State.Z] = depth
    return x0
