"""Augmented unscented Kalman filter: the coefficients identified by the unscented transform
instead of the EKF's linearisation (Julier & Uhlmann 1997; Wan & van der Merwe 2000).

Augmented state x* = [x (12 vehicle states, core/model/state.py), theta (p parameters)], as in the
augmented EKF (ekf.py), with the same prior, process noise Q (per RK4 step), measurement noise
R, measured channels, stamps and gaps (timing.py via batch's timeline): only the way the
state's distribution is carried through the model differs, so the two can be compared on the
same data.

Time update (the scaled unscented transform of Wan & van der Merwe 2000): with
n = 12 + p, lambda = alpha^2 (n + kappa) - n and S the lower Cholesky factor of P,

    X_0 = x*,  X_i = x* + sqrt(n + lambda) S[:, i],  X_(n+i) = x* - sqrt(n + lambda) S[:, i]
    W_0^m = lambda / (n + lambda),  W_0^c = W_0^m + 1 - alpha^2 + beta,
    W_i^m = W_i^c = 1 / (2 (n + lambda))  (i = 1 .. 2n);

every sigma point crosses the interval through one RK4 step of the model with the command
held (ekf.rk4_step_into without its Jacobian: the same discretisation as the EKF), and

    x*^- = sum_i W_i^m X_i^-,   P^- = sum_i W_i^c (X_i^- - x*^-)(X_i^- - x*^-)^T + Q.

phi, theta, psi are angles: their mean is taken as X_0's value plus the weighted mean of the
wrapped differences to it, and their deviations are wrapped, so a heading near +-pi averages
to +-pi and not to 0. The sigma points are drawn afresh before each RK4 step (additive process
noise).

Defaults alpha = 1, beta = 2, kappa = 0 give W_0^m = 0 and non-negative weights, so P^- is
positive semi-definite by construction (a small alpha makes W_0 large and negative, which with
17 states and coefficients 50 % off lost positive definiteness); the sigma points then lie
sqrt(n) 1-sigma from the mean.

Measurement update: the measurement is a selection of states (y = H x* + v, NaN channels
skipped). For a linear h the unscented transform is exact (predicted measurement H x*^-,
P_xz = P^- H^T, P_zz = H P^- H^T + R from the sigma points of (x*^-, P^-)), so the update is
the Kalman update with the angle innovations wrapped to (-pi, pi] and the Joseph form: the
EKF's own compiled update (ekf.update) is used.
"""
from dataclasses import dataclass
import math
import time
from typing import Any

import numpy as np

from auv_ident.core.angles import wrap_angle
from auv_ident.core.errors import ConfigError, DivergenceError, DomainError
from auv_ident.core.filter import ekf
from auv_ident.core.filter.augmented import AugmentedEKF, FilterConfig
from auv_ident.core.filter.propagation import propagate_sigma_points
from auv_ident.core.filter.timing import DEFAULT_MAX_BRIDGE, nominal_sample_time
from auv_ident.core.identification.batch import _record, _timeline
from auv_ident.core.model.hydrodynamics import Model, OK, STATUS_TEXT
from auv_ident.core.model.state import EULER, Input, N_STATE
from auv_ident.core.model.thruster_lag import lag_advance


@dataclass
class UnscentedSettings:
    """Scaling of the unscented transform (Wan & van der Merwe 2000): alpha spread of the sigma
    points (1: sqrt(n + kappa) 1-sigma), beta prior knowledge of the distribution (2: Gaussian),
    kappa secondary scaling (0)."""

    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0

    def weights(self, n: int) -> tuple[float, np.ndarray, np.ndarray]:
        """(lambda, W^m (2n+1,), W^c (2n+1,)) for a state of size n."""
        a, b, k = float(self.alpha), float(self.beta), float(self.kappa)
        lam = a * a * (n + k) - n
        if not (a > 0.0 and n + lam > 0.0):
            raise ConfigError(f'unscented scaling alpha = {a}, kappa = {k}: need alpha > 0 and '
                              f'n + lambda = {n + lam:g} > 0 for n = {n}')
        Wm = np.full(2 * n + 1, 0.5 / (n + lam))
        Wc = Wm.copy()
        Wm[0] = lam / (n + lam)
        Wc[0] = Wm[0] + 1.0 - a * a + b
        return lam, Wm, Wc


@dataclass
class UkfResult:
    """The UKF's answer over a record: the final augmented estimate and covariance, the
    parameters' part of them, steps, mean NIS per degree of freedom, wall time (s)."""

    names: list
    xa: np.ndarray
    P: np.ndarray
    theta: np.ndarray
    theta_cov: np.ndarray
    steps: int
    mean_nis_per_dof: float
    wall_s: float

    @property
    def theta_std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.theta_cov))


def sigma_points(xa: np.ndarray, P: np.ndarray, gamma: float) -> np.ndarray:
    """(2n+1, n) sigma points x*, x* +- gamma S[:, i] with S the lower Cholesky factor of P.
    Raises DivergenceError when P is not positive definite."""
    try:
        S = np.linalg.cholesky(0.5 * (P + P.T))
    except np.linalg.LinAlgError:
        raise DivergenceError('UKF: the covariance lost positive definiteness') from None
    D = gamma * S.T
    return np.vstack([xa[None, :], xa[None, :] + D, xa[None, :] - D])


def unscented_mean_cov(X: np.ndarray, Wm: np.ndarray,
                       Wc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean (n,) and covariance (n, n) of sigma points X (2n+1, n), the Euler angles
    averaged and differenced on the circle (module docstring)."""
    ref = X[0, EULER]
    D = X.copy()
    D[:, EULER] = wrap_angle(X[:, EULER] - ref)
    mean = Wm @ D
    mean[EULER] = wrap_angle(ref + mean[EULER])
    D -= Wm @ D
    cov = (D * Wc[:, None]).T @ D
    return mean, 0.5 * (cov + cov.T)


class MeasurementUpdate:
    """The measurement update of the UKF: the EKF's compiled Kalman update (ekf.update: angle
    innovations wrapped, channels fused one at a time for a diagonal R, which for a linear
    measurement is the batch update, Joseph form), with its scratch allocated once."""

    def __init__(self, n: int, ws: Any) -> None:
        self.ws = ws
        self.xa = np.empty(n)
        self.P = np.empty((n, n))
        self.innov = np.empty(N_STATE)
        self.S_diag = np.empty(N_STATE)
        self.white = np.empty(N_STATE)

    def __call__(self, xa: np.ndarray, P: np.ndarray, y: np.ndarray, measured: np.ndarray,
                 R: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, int]:
        """(xa+, P+, NIS, channels used) after fusing the finite measured channels of y (12,).
        Raises DivergenceError when the posterior is not a covariance."""
        st, nis, m = ekf.update(xa, P, np.ascontiguousarray(y, dtype=float), measured, R,
                              self.xa, self.P, self.innov, self.S_diag, self.white, self.ws)
        if st != OK:
            raise DivergenceError('UKF: the measurement update lost positive definiteness')
        return self.xa.copy(), self.P.copy(), float(nis), int(m)


def run_ukf(model: Model, cfg: FilterConfig, t: np.ndarray, Y: np.ndarray, U: np.ndarray,
            T: float | None = None, max_step: float | None = None,
            max_bridge: float = DEFAULT_MAX_BRIDGE,
            unscented: 'UnscentedSettings | None' = None) -> UkfResult:
    """Run the augmented UKF over a record, started from Y[0] as the EKF pass is.

    Parameters
    ----------
    model : core.model.hydrodynamics.Model with the parameters to identify (model.theta_names)
    cfg : core.filter.augmented.FilterConfig (prior, q_state, q_theta_rel, noise_std, measured);
    only
        mode 'fixed' (the UKF does not adapt Q and R)
    t : (N,) s, strictly increasing stamps; Y (N, 12) measurements (NaN: missing); U (N, 6)
        inputs, U[k] held over [t_k, t_k+1)
    T : s, nominal sample time (None: the median interval); max_step, max_bridge (s): as for
        batch.run_ekf (RK4 steps of at most max_step, restart of the vehicle states after a
        longer gap)
    unscented : UnscentedSettings (None: the defaults)

    Returns UkfResult. Raises DomainError (a sigma point left the model's domain) or
    DivergenceError, naming the sample.
    """
    if cfg.mode != 'fixed':
        raise ConfigError(f'the UKF runs with fixed Q and R; noise mode {cfg.mode!r} is the '
                          "EKF's (use noise_mode 'fixed')")
    t0 = time.perf_counter()
    t, Y, U = _record(t, Y, U)
    T = nominal_sample_time(t) if T is None else T
    f = AugmentedEKF(model, cfg, T)          # the EKF pass's prior, Q, R and time line
    settings = f.settings()
    timeline = _timeline(f, t, Y, U, max_step, max_bridge)
    xa, P = f.initial_estimate(Y[0], U[0, Input.N_RPM])
    n = f.n
    lam, Wm, Wc = (unscented or UnscentedSettings()).weights(n)
    gamma = math.sqrt(n + lam)
    Q, R, measured = settings.Q0, settings.R0, np.asarray(settings.measured, dtype=bool)
    ws = ekf.workspace_for(n, model.compiled)
    X_out = np.empty((2 * n + 1, n))
    kalman_update = MeasurementUpdate(n, ws)
    cm = model.compiled
    sum_nis = sum_dof = 0.0
    r = 0
    k = 0
    try:
        for k in range(Y.shape[0]):
            if k > 0:
                if timeline.n_sub[k] == 0:       # a gap: restart the vehicle states
                    xa, P = xa.copy(), P.copy()
                    ekf.restart_states(xa, P, timeline.x0[r], timeline.sd0[r])
                    ws.lag_ok[0] = 0             # the thrust settled over the gap
                    r += 1
                for _ in range(timeline.n_sub[k]):
                    X = sigma_points(xa, P, gamma)
                    st = propagate_sigma_points(X, U[k - 1], cm, timeline.h[k], X_out, ws)
                    if st != OK:
                        raise DomainError(f'UKF stopped at sample {k} (t = {t[k]:.2f} s): a '
                                          f"sigma point left the model's domain: "
                                          f'{STATUS_TEXT[st]}')
                    if cm.lagged:    # the thrust carried on at the mean's time constant
                        th = xa[N_STATE:]
                        c = np.concatenate([model.coefficients_with(th), model.current_with(th)])
                        lag_advance(cm, c, U[k - 1], ws.lag, ws.lag_ok, timeline.h[k])
                    xa, P = unscented_mean_cov(X_out, Wm, Wc)
                    P = P + Q
            xa, P, nis, m = kalman_update(xa, P, Y[k], measured, R)
            sum_nis += nis
            sum_dof += m
    except DivergenceError as err:
        raise DivergenceError(f'{err} at sample {k} (t = {t[k]:.2f} s)') from err
    theta = xa[N_STATE:].copy()
    return UkfResult(names=list(model.theta_names), xa=xa, P=P, theta=theta,
                     theta_cov=P[N_STATE:, N_STATE:].copy(), steps=int(Y.shape[0]),
                     mean_nis_per_dof=sum_nis / max(1.0, sum_dof),
                     wall_s=time.perf_counter() - t0)
