"""Predicting measured runs with a model, and the goodness-of-fit measures users know.

A model is judged on what was measured: from a run's measured initial state, with its measured
inputs, how close does the model's free run (or its K-step-ahead prediction, re-started from the
measurement every K samples) stay to the measured channels?

Measures (per channel, y measured, y_hat predicted, both (N,)):

- fit % (MATLAB System Identification Toolbox ``compare``, NRMSE form):
  ``100 (1 - ||y - y_hat|| / ||y - mean(y)||)``; 100 is perfect, 0 is no better than the
  measured mean, negative is worse than it;
- RMSE ``sqrt(mean((y - y_hat)^2))`` in the channel's unit;
- Theil's inequality coefficient (Jategaonkar 2015, sec. 10.7)
  ``U = sqrt(mean((y - y_hat)^2)) / (sqrt(mean(y^2)) + sqrt(mean(y_hat^2)))``, in [0, 1]:
  0 is perfect, values below ~0.3 are the flight-test practice for an adequate model.

Angles: residuals of phi, theta, psi are wrapped to (-pi, pi] before any norm, and a heading
channel is unwrapped before its mean is taken, so a run through +-180 deg is scored on the
heading change it made, not on the wrap.

The integration holds each input over [t_k, t_k+1) (zero-order hold) with classical RK4 steps
no longer than ``max_step`` (s): stamps need not be uniform.
"""
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.angles import wrap_angle
from auv_ident.core.errors import ConfigError, DomainError
from auv_ident.core.model.integrators import rk4_step
from auv_ident.core.model.state import ANGLE_STATES, EULER, N_STATE

DEFAULT_MAX_STEP = 0.05      # s, the longest RK4 step of a prediction


def _pair(y: ArrayLike, y_hat: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    y = np.asarray(y, dtype=float)
    y_hat = np.asarray(y_hat, dtype=float)
    if y.shape != y_hat.shape or y.ndim != 1:
        raise ConfigError(f'measured and predicted channels must be (N,) arrays of one shape, '
                          f'got {y.shape} and {y_hat.shape}')
    ok = np.isfinite(y) & np.isfinite(y_hat)
    return y[ok], y_hat[ok]


def fit_percent(y: ArrayLike, y_hat: ArrayLike) -> float:
    """Normalised-RMSE fit (%) of a prediction y_hat to the measured y (MATLAB ``compare``).

    NaN when y is constant (the measure is undefined: nothing to explain) or has no finite
    samples."""
    y, y_hat = _pair(y, y_hat)
    if not len(y):
        return float('nan')
    spread = np.linalg.norm(y - y.mean())
    if spread == 0.0:
        return float('nan')
    return float(100.0 * (1.0 - np.linalg.norm(y - y_hat) / spread))


def rmse(y: ArrayLike, y_hat: ArrayLike) -> float:
    """Root-mean-square error, in the unit of the channel."""
    y, y_hat = _pair(y, y_hat)
    return float(np.sqrt(np.mean((y - y_hat) ** 2))) if len(y) else float('nan')


def theil(y: ArrayLike, y_hat: ArrayLike) -> float:
    """Theil's inequality coefficient in [0, 1] (0 perfect); NaN if both are identically 0."""
    y, y_hat = _pair(y, y_hat)
    if not len(y):
        return float('nan')
    den = np.sqrt(np.mean(y ** 2)) + np.sqrt(np.mean(y_hat ** 2))
    return float(np.sqrt(np.mean((y - y_hat) ** 2)) / den) if den > 0.0 else float('nan')


def angle_channels(Y: np.ndarray, Y_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The measured and predicted (N, 12) states with the Euler-angle columns made comparable:
    the measurement unwrapped, the prediction moved by whole turns onto it."""
    Y = np.array(Y, dtype=float)
    Y_hat = np.array(Y_hat, dtype=float)
    for i in ANGLE_STATES:
        col = Y[:, i]
        ok = np.isfinite(col)
        if ok.any():
            col[ok] = np.unwrap(col[ok])
        Y[:, i] = col
        Y_hat[:, i] = Y[:, i] + wrap_angle(Y_hat[:, i] - Y[:, i])
    return Y, Y_hat


def free_run(f: Callable[[np.ndarray, np.ndarray], np.ndarray], t: ArrayLike, U: np.ndarray,
             x0: ArrayLike, max_step: float = DEFAULT_MAX_STEP) -> np.ndarray:
    """Integrate x_dot = f(x, u) from x0 at t[0] through the stamps t with U held (ZOH).

    Parameters
    ----------
    f : callable (x (12,), u) -> x_dot (12,), e.g. ``lambda x, u: model.f(x, u, theta)``;
        one with a ``step(x, u, h)`` and ``reset()`` (thruster_lag.derivative of a vehicle
        whose thrusters lag) is stepped by it, its thrust settled at U[0]
    t : (N,) s, strictly increasing (need not be uniform)
    U : (N, m) inputs, U[k] held over [t_k, t_k+1)
    x0 : (12,) state at t[0]
    max_step : s, the longest RK4 step

    Returns
    -------
    (N, 12) predicted states (angles wrapped); rows after a DomainError (the model left its
    domain, e.g. the speed reached 0) are NaN, so a diverging model scores badly instead of
    stopping the validation.
    """
    t = np.asarray(t, dtype=float)
    U = np.asarray(U, dtype=float)
    if t.ndim != 1 or len(t) < 2 or np.any(np.diff(t) <= 0):
        raise ConfigError('a prediction needs at least 2 strictly increasing stamps')
    if len(U) != len(t):
        raise ConfigError(f'inputs have {len(U)} rows for {len(t)} stamps')
    X = np.full((len(t), N_STATE), np.nan)
    x = np.array(x0, dtype=float)
    X[0] = x
    step = getattr(f, 'step', None)
    if step is not None:
        f.reset()                    # type: ignore[attr-defined]
    for k in range(len(t) - 1):
        dt = t[k + 1] - t[k]
        n = max(1, int(np.ceil(dt / max_step - 1e-9)))
        h = dt / n
        try:
            for _ in range(n):
                x = rk4_step(f, x, U[k], h) if step is None else step(x, U[k], h)
        except DomainError:
            break
        if not np.all(np.isfinite(x)):
            break
        x[EULER] = wrap_angle(x[EULER])
        X[k + 1] = x
    return X


def k_step_prediction(f: Callable[[np.ndarray, np.ndarray], np.ndarray], t: ArrayLike,
                      U: np.ndarray, Y: np.ndarray, K: int,
                      max_step: float = DEFAULT_MAX_STEP) -> np.ndarray:
    """K-step-ahead prediction: restart the free run from the measured state Y[j] at every
    j = 0, K, 2K, ... and predict the next K samples from there.

    Y : (N, 12) measured states (the restart points; a restart at a non-finite row is skipped
    and that segment is NaN). Returns (N, 12): row i > 0 is predicted from the last restart
    before it (so a restart row holds the K-step prediction, not the measurement); row 0 is
    Y[0].
    """
    if int(K) < 1:
        raise ConfigError(f'prediction horizon K must be >= 1, got {K}')
    K = int(K)
    t = np.asarray(t, dtype=float)
    Y = np.asarray(Y, dtype=float)
    X = np.full((len(t), N_STATE), np.nan)
    X[0] = Y[0]
    for j in range(0, len(t) - 1, K):
        end = min(j + K, len(t) - 1)
        if not np.all(np.isfinite(Y[j])):
            continue
        X[j + 1:end + 1] = free_run(f, t[j:end + 1], U[j:end + 1], Y[j], max_step)[1:]
    return X
