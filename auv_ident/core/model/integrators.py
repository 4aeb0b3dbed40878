"""Fixed-step integrators, kept apart from the model: they take any f(x, u) -> x_dot."""
from collections.abc import Callable

import numpy as np

Derivative = Callable[[np.ndarray, np.ndarray], np.ndarray]   # f(x, u) -> x_dot


def rk4_step(f: Derivative, x: np.ndarray, u: np.ndarray, h: float) -> np.ndarray:
    """One classical Runge-Kutta step of size h (s) with the input u held constant (ZOH)."""
    k1 = f(x, u)
    k2 = f(x + 0.5 * h * k1, u)
    k3 = f(x + 0.5 * h * k2, u)
    k4 = f(x + h * k3, u)
    return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def euler_step(f: Derivative, x: np.ndarray, u: np.ndarray, h: float) -> np.ndarray:
    """Forward Euler step (for comparison only)."""
    return x + h * f(x, u)
