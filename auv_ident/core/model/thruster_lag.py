"""The thrusters' first-order lag as the filters carry it: the delivered thrust as a side state
of the time update, exact for the held commands, with its derivative by the time constant.

Each thruster i's curve value f_ss,i = curve(c_i) (N, thrusters.py; the command c_i held over
a time step, zero-order hold) is split into its forward part P_ss = max(f_ss, 0) and its
reverse part N_ss = min(f_ss, 0) (the thrust gains scale the two sides, and the lag is
linear), and each part is delivered through tau f_dot = f_ss - f (Fossen 2021, sec. 9.3).
For a command held over a step from its start, a seconds into the step:

    P(a) = P_ss + (P_0 - P_ss) e^(-a/tau)                                  (N)
    S(a) = dP(a)/dtau = (P_0 - P_ss) e^(-a/tau) a / tau^2 + S_0 e^(-a/tau)  (N/s)

(the same for N), the exact solution: the RK4 stages of the step (a = 0, h/2, h/2, h) read
the delivered thrust there, so the step stays a fourth-order integration of the vehicle
with the thrust dynamics solved exactly. tau = 0 (or below) is an instantaneous thruster:
P = P_ss at every stage, S = 0, the steady kernel's numbers bit for bit.

Why a side state and not states of the filter: the delivered thrust is a deterministic
function of the commands (known) and of tau (a coefficient), so its covariance with anything
is S times tau's: carrying S and putting dP/dtau = S into the Jacobian's tau column
(hydrodynamics._thrusters) is the linearised filter over [x, theta, P, N] with the thrust
rows eliminated, without growing the state (8 thrusters would add 16 states to every step)
or touching the vehicles without a lag. After a measurement update moves tau by dtau the
thrust the full filter would hold moves by S dtau (lag_correct).

The state, per thruster, is `lag` (4, n): rows P_0, N_0, S_P,0, S_N,0 at the start of the
current step, and `lag_ok` (1,): 0 until the first step settles the thrust at its first
command's curve value (a record starts with the thrusters at their steady thrust, the
best guess without a history). tau is the coefficient with the multiplier `thruster_lag`
(c[cm.lag_idx]) or else each thruster's own `time_constant` (thr[i, T_TAU]; fixed, S = 0).
The stage's delivered thrusts go to the model through the extended input vector
(extended_inputs): u_in, then P (n), N (n), S_P (n), S_N (n).

Units: N, s; frames: body FRD (the thrust is along each thruster's d).
"""
from collections.abc import Callable
import math

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.model.hydrodynamics import kernel, Model, thrust_of
from auv_ident.core.model.state import N_INPUT
from auv_ident.core.model.thrusters import T_TAU

# rows of the lag state
L_P, L_N, L_SP, L_SN = 0, 1, 2, 3
N_LAG_ROWS = 4


def extended_inputs(n_inputs: int, n_thr: int) -> int:
    """Length of the extended input vector of a lagged vehicle (module docstring)."""
    return n_inputs + N_LAG_ROWS * n_thr


def new_lag(n_thr: int) -> tuple[np.ndarray, np.ndarray]:
    """(lag (4, n), lag_ok (1,)) of a record not yet started (module docstring)."""
    return np.zeros((N_LAG_ROWS, n_thr)), np.zeros(1, dtype=np.int64)


@kernel
def _tau(cm, c, i):
    """Thruster i's time constant (s) for coefficients c, and whether it is the identified
    coefficient (its derivative carried)."""
    if cm.lag_idx >= 0:
        return c[cm.lag_idx], True
    return cm.thr[i, T_TAU], False


@kernel
def lag_settle(cm, ui, lag, lag_ok):
    """The thrust settled at the commands ui: P, N the curve's parts, S = 0."""
    for i in range(cm.thr.shape[0]):
        f = thrust_of(cm.thr, i, ui[N_INPUT + i])
        lag[L_P, i] = f if f > 0.0 else 0.0
        lag[L_N, i] = f if f < 0.0 else 0.0
        lag[L_SP, i] = 0.0
        lag[L_SN, i] = 0.0
    lag_ok[0] = 1


@kernel
def _lag_one(cm, c, ui, lag, a, i):
    """Thruster i's (P, N, S_P, S_N) a seconds into the step with the commands ui held, from
    the step's start `lag` (module docstring)."""
    f = thrust_of(cm.thr, i, ui[N_INPUT + i])
    pss = f if f > 0.0 else 0.0
    nss = f if f < 0.0 else 0.0
    tau, carried = _tau(cm, c, i)
    if tau <= 0.0:
        return pss, nss, 0.0, 0.0
    e = math.exp(-a / tau)
    dp = lag[L_P, i] - pss
    dn = lag[L_N, i] - nss
    if not carried:
        return pss + dp * e, nss + dn * e, 0.0, 0.0
    g = e * a / (tau * tau)
    return pss + dp * e, nss + dn * e, dp * g + lag[L_SP, i] * e, dn * g + lag[L_SN, i] * e


@kernel
def lag_inputs(cm, c, ui, lag, a, ui_ext):
    """ui_ext (extended_inputs) = [ui, P, N, S_P, S_N] a seconds into the step."""
    n = cm.thr.shape[0]
    m = ui.shape[0]
    for j in range(m):
        ui_ext[j] = ui[j]
    for i in range(n):
        p, q, sp, sq = _lag_one(cm, c, ui, lag, a, i)
        ui_ext[m + L_P * n + i] = p
        ui_ext[m + L_N * n + i] = q
        ui_ext[m + L_SP * n + i] = sp
        ui_ext[m + L_SN * n + i] = sq


@kernel
def lag_advance(cm, c, ui, lag, lag_ok, h):
    """Carry the lag state over a step of h seconds with the commands ui held (settling it
    first when the record has just started)."""
    if lag_ok[0] == 0:
        lag_settle(cm, ui, lag, lag_ok)
    for i in range(cm.thr.shape[0]):
        p, q, sp, sq = _lag_one(cm, c, ui, lag, h, i)
        lag[L_P, i] = p
        lag[L_N, i] = q
        lag[L_SP, i] = sp
        lag[L_SN, i] = sq


@kernel
def lag_correct(lag, dtau):
    """A measurement update moved tau by dtau (s): the delivered thrust the filter holds moves
    by S dtau (module docstring)."""
    for i in range(lag.shape[1]):
        lag[L_P, i] += lag[L_SP, i] * dtau
        lag[L_N, i] += lag[L_SN, i] * dtau


class LaggedDerivative:
    """f(x, u) of a lagged vehicle's model (the steady thrust: a trim, a settled state) with
    `step`, the RK4 step that carries the delivered thrust as the filters do (rk4_step_into's
    stages, thruster_lag.lag_inputs), for the Python integrators (simulation, prediction):
    core/simulation/prediction.free_run and simulate use `step` when f has one, after `reset`
    (the thrust settles at the first command)."""

    def __init__(self, model: Model, theta: ArrayLike | None = None) -> None:
        self.model = model
        self.theta = theta
        self.cm = model.compiled
        th = model.theta_file if theta is None else np.asarray(theta, dtype=float)
        self.c = np.concatenate([model.coefficients_with(th), model.current_with(th)])
        self.lag, self.lag_ok = new_lag(len(model.vehicle.thrusters))
        self.ui_ext = np.empty(model.n_inputs_lagged)

    def __call__(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.model.f(x, u, self.theta)

    def reset(self) -> None:
        """A new record: the thrust settles at the next step's command."""
        self.lag_ok[0] = 0

    def _stage(self, x: np.ndarray, u: np.ndarray, a: float) -> np.ndarray:
        lag_inputs(self.cm, self.c, u, self.lag, a, self.ui_ext)
        return self.model.f(x, self.ui_ext, self.theta)

    def step(self, x: np.ndarray, u: np.ndarray, h: float) -> np.ndarray:
        """One RK4 step of h (s) with the commands u held and the thrust delivered through its
        lag; the lag state moves on to the step's end."""
        u = np.ascontiguousarray(u, dtype=float)
        if self.lag_ok[0] == 0:
            lag_settle(self.cm, u, self.lag, self.lag_ok)
        k1 = self._stage(x, u, 0.0)
        k2 = self._stage(x + 0.5 * h * k1, u, 0.5 * h)
        k3 = self._stage(x + 0.5 * h * k2, u, 0.5 * h)
        k4 = self._stage(x + h * k3, u, h)
        lag_advance(self.cm, self.c, u, self.lag, self.lag_ok, h)
        return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def derivative(model: Model, theta: ArrayLike | None = None) -> Callable[..., np.ndarray]:
    """The model's f(x, u) at theta for the Python integrators: model.f itself for a vehicle
    without a lag, a LaggedDerivative (with its `step`) for one with."""
    if model.vehicle.lagged:
        return LaggedDerivative(model, theta)

    def f(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return model.f(x, u, theta)
    return f
