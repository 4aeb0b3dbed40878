"""Closed-loop zig-zag simulation of any model, the way a basin or a trial executes it.

``sim = simulate_zigzag(f, x0, rudder_deg, switch_deg, duration, gear, thrust=...,
thrust_index=...)``:

- the model is a callable ``f(x (12,), u (m,)) -> x_dot (12,)`` (e.g.
  ``lambda x, u: model.f(x, u, theta)``); the rudder goes into ``u[rudder_index]`` (rad,
  positive to port, default :data:`~auv_ident.core.model.state.Input.DELTA_R`); the rest of u comes
  from ``inputs`` (a fixed (m,) vector or a callable x -> (m,)), and where the thrust is not
  given but modelled, ``thrust(x)`` (N, e.g. a
  :class:`~auv_ident.core.identification.thrust_fit.ThrustModel`) is written into
  ``u[thrust_index]`` at every evaluation;
- at ``execute_time`` (s) the helm orders ``rudder_deg`` to the ``first`` side ('starboard':
  delta = -rudder, the heading then grows); each time the heading deviation from the heading
  at the execute passes ``switch_deg`` on the side the ship is turning to, the helm orders the
  rudder to the other side; every order goes through the steering gear
  (:class:`~auv_ident.core.simulation.steering.SteeringGear`: dead time, rate limit, servo time
  constant, angle limit), whose rudder angle is closed-form in time;
- integration: classical RK4 on a fixed grid of ``step`` (s), each step split where the rudder
  motion is not smooth (a servo start, the end of its ramp), so the rudder is exact at every
  RK4 stage; the instant the heading passes the switch angle comes from the cubic Hermite
  interpolant of psi and its derivative over the step, and when the order (plus the dead time)
  falls inside the step just taken, the step is taken again from its start with the new order
  in place. The result does not depend on where the grid falls relative to the orders.

``simulate_zigzag(..., gear=SteeringGear.ideal(rate_deg_s))`` is the ideal helm: no dead time,
the nominal rate; the difference between the two runs is the helm's effect on the measures.

Returns :class:`ZigzagSimulation`: ``t`` (N,) s, ``x`` (N, 12) (Euler angles wrapped),
``rudder`` and ``order`` (N,) rad, ``inputs`` (N, m), ``thrust`` (N,) N (None without a thrust
model), the orders as (time, angle) pairs and the measures of
:mod:`auv_ident.core.simulation.zigzag` computed with the ordered angles and the execute time.
"""
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import brentq

from auv_ident.core.angles import wrap_angle
from auv_ident.core.errors import ConfigError, DataError, DomainError
from auv_ident.core.model.state import EULER, Input, N_INPUT, N_STATE, State
from auv_ident.core.simulation.steering import SteeringGear
from auv_ident.core.simulation.zigzag import zigzag_measures, ZigzagMeasures

DEG = np.pi / 180.0
DEFAULT_STEP = 0.05    # s


@dataclass
class ZigzagSimulation:
    """A simulated zig-zag (module docstring); ``stopped`` says why it ended early (a
    DomainError of the model: the rows after it are not there) or why it has no measures
    (``measures`` None), else None."""

    t: np.ndarray
    x: np.ndarray
    rudder: np.ndarray
    order: np.ndarray
    inputs: np.ndarray
    thrust: object
    orders: list = field(default_factory=list)
    measures: object = None
    stopped: object = None


class _Helm:
    """The ordered angles and the rudder angle they give through the gear (closed form)."""

    def __init__(self, gear: SteeringGear, delta0: float) -> None:
        self.gear = gear
        self.orders: list[tuple[float, float]] = []     # (order time, ordered angle)
        # (servo start, start angle, target)
        self.segments: list[tuple[float, float, float]] = [(-np.inf, delta0, delta0)]

    def order(self, t_order: float, angle: float) -> None:
        angle = float(np.clip(angle, -self.gear.limit, self.gear.limit))
        self.orders.append((t_order, angle))
        t_srv = t_order + self.gear.delay
        # later segments were planned with an earlier state of the order list: none can be
        # after t_srv, since orders come in time order and the dead time is fixed
        self.segments.append((t_srv, self.rudder(t_srv), angle))

    def forget_after(self, n_orders: int) -> None:
        del self.orders[n_orders:]
        del self.segments[n_orders + 1:]

    def rudder(self, t: float, left: bool = False) -> float:
        """The rudder angle at t (rad); left: its limit from the left, which differs at a
        servo start only for an instant rudder."""
        for t_srv, a, b in reversed(self.segments):
            if (t > t_srv) if left else (t >= t_srv):
                return self.gear.response(t - t_srv, a, b) if np.isfinite(t_srv) else a
        return self.segments[0][1]

    def ordered(self, t: float) -> float:
        angle = self.segments[0][1]
        for t_o, a in self.orders:
            if t >= t_o:
                angle = a
        return angle

    def breaks(self, t0: float, t1: float) -> list[float]:
        """The instants in (t0, t1) where the rudder's motion is not smooth."""
        g = self.gear
        out = []
        for t_srv, a, b in self.segments[1:]:
            span = abs(b - a)
            if np.isfinite(g.rate):
                ramp = max(span - g.rate * g.time_constant, 0.0) / g.rate
            else:
                ramp = 0.0
            for tb in (t_srv, t_srv + ramp):
                if t0 < tb < t1:
                    out.append(tb)
        return sorted(out)


def _input_source(inputs: Any, n_inputs: int) -> Callable[[np.ndarray], np.ndarray]:
    if inputs is None:
        base = np.zeros(n_inputs)
        return lambda x: base.copy()
    if callable(inputs):
        return lambda x: np.array(inputs(x), dtype=float)
    base = np.asarray(inputs, dtype=float)
    if base.ndim != 1:
        raise ConfigError(f'inputs must be an (m,) vector or a callable, got shape {base.shape}')
    return lambda x: base.copy()


def simulate_zigzag(f: Callable[[np.ndarray, np.ndarray], Any], x0: ArrayLike, rudder_deg: float,
                    switch_deg: float, duration: float, gear: SteeringGear,
                    thrust: Callable[[np.ndarray], float] | None = None, inputs: Any = None,
                    rudder_index: int = Input.DELTA_R, thrust_index: int | None = None,
                    n_inputs: int = N_INPUT, first: str = 'starboard', execute_time: float = 0.0,
                    step: float = DEFAULT_STEP, delta0: float = 0.0) -> ZigzagSimulation:
    """Closed-loop zig-zag (module docstring).

    Parameters
    ----------
    f : callable (x (12,), u (m,)) -> x_dot (12,)
    x0 : (12,) state at t = 0 (m/s, rad/s, m, rad)
    rudder_deg, switch_deg : deg, the ordered rudder angle and switch heading (> 0)
    duration : s, the length of the run from t = 0
    gear : SteeringGear
    thrust : callable x (12,) -> N, or None; thrust_index : its place in u (required with it)
    inputs : None (zeros), (m,) vector or callable x -> (m,): u before the rudder and thrust
    rudder_index : the rudder's place in u; n_inputs : m when inputs is None
    first : 'starboard' or 'port'; execute_time : s, the first order (>= 0)
    step : s, the RK4 grid step; delta0 : rad, the rudder before the execute

    Returns
    -------
    ZigzagSimulation
    """
    _check_orders(first, rudder_deg, switch_deg, duration, execute_time, step)
    if thrust is not None and thrust_index is None:
        raise ConfigError('a thrust model needs thrust_index: the place of the thrust in u')
    x0 = np.array(x0, dtype=float)
    if x0.shape != (N_STATE,) or not np.all(np.isfinite(x0)):
        raise ConfigError(f'x0 must be {N_STATE} finite numbers, got {x0}')
    base = _input_source(inputs, n_inputs)
    helm = _Helm(gear, float(delta0))
    side = 1.0 if first == 'starboard' else -1.0   # sign of the heading deviation sought
    helm.order(float(execute_time), -side * rudder_deg * DEG)
    switch = switch_deg * DEG

    def u_of(t: float, x: np.ndarray, left: bool = False) -> np.ndarray:
        u = base(x)
        u[rudder_index] = helm.rudder(t, left)
        if thrust is not None:
            u[thrust_index] = float(thrust(x))
        return u

    def rhs(t: float, x: np.ndarray, left: bool = False) -> np.ndarray:
        return np.asarray(f(x, u_of(t, x, left)), dtype=float)

    def advance(t0: float, t1: float, x: np.ndarray) -> np.ndarray:
        cuts = [t0] + helm.breaks(t0, t1) + [t1]
        for a, b in zip(cuts[:-1], cuts[1:]):
            h = b - a
            k1 = rhs(a, x)
            k2 = rhs(a + 0.5 * h, x + 0.5 * h * k1)
            k3 = rhs(a + 0.5 * h, x + 0.5 * h * k2)
            k4 = rhs(b, x + h * k3, left=True)   # the sub-step ends before a break
            x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        return x

    n = int(np.floor(duration / step + 1e-9)) + 1
    t = np.arange(n) * step
    X = np.empty((n, N_STATE))
    X[0] = x0
    psi0 = x0[State.PSI] if execute_time == 0.0 else None
    stopped = None
    k = 0
    while k < n - 1:
        t0, t1 = t[k], t[k + 1]
        n_orders = len(helm.orders)
        try:
            x1 = advance(t0, t1, X[k])
            if not np.all(np.isfinite(x1)):
                raise DomainError(f'the state became non-finite at t = {t1:.3f} s')
            if psi0 is None and t1 >= execute_time:
                a = (execute_time - t0) / (t1 - t0)
                psi0 = (1 - a) * X[k, State.PSI] + a * x1[State.PSI]
            if psi0 is not None:
                y0 = side * (X[k, State.PSI] - psi0) - switch
                y1 = side * (x1[State.PSI] - psi0) - switch
                if y0 < 0.0 <= y1 and t0 >= execute_time:
                    d0 = side * rhs(t0, X[k])[State.PSI]
                    d1 = side * rhs(t1, x1, left=True)[State.PSI]
                    tc = _hermite_root(t0, t1, y0, y1, d0, d1)
                    side = -side
                    helm.order(tc, -side * rudder_deg * DEG)
                    if tc + gear.delay < t1:
                        x1 = advance(t0, t1, X[k])    # again, with the order in place
        except DomainError as exc:
            helm.forget_after(n_orders)
            stopped = str(exc)
            break
        X[k + 1] = x1
        k += 1
    t, X = t[:k + 1], X[:k + 1]
    U = np.array([u_of(ti, xi) for ti, xi in zip(t, X)])
    rudder = U[:, rudder_index].copy()
    order = np.array([helm.ordered(ti) for ti in t])
    T = U[:, thrust_index].copy() if thrust is not None else None
    measures, why_none = _measures(t, X, rudder, execute_time, rudder_deg, switch_deg)
    Xw = X.copy()
    Xw[:, EULER] = wrap_angle(Xw[:, EULER])
    return ZigzagSimulation(t=t, x=Xw, rudder=rudder, order=order, inputs=U, thrust=T,
                            orders=list(helm.orders), measures=measures,
                            stopped=stopped or why_none)


def _check_orders(first: str, rudder_deg: float, switch_deg: float, duration: float,
                  execute_time: float, step: float) -> None:
    """ConfigError unless the helm's orders and the run's grid make sense (simulate_zigzag)."""
    if first not in ('starboard', 'port'):
        raise ConfigError(f"first must be 'starboard' or 'port', got {first!r}")
    if not (rudder_deg > 0 and switch_deg > 0):
        raise ConfigError(f'rudder and switch angles must be > 0 deg, got {rudder_deg}, '
                          f'{switch_deg}')
    if not (step > 0 and duration > step and 0.0 <= execute_time < duration):
        raise ConfigError(f'need step > 0, duration > step and 0 <= execute_time < duration; '
                          f'got step {step}, duration {duration}, execute_time {execute_time}')


def _measures(t: np.ndarray, X: np.ndarray, rudder: np.ndarray, execute_time: float,
              rudder_deg: float, switch_deg: float) -> tuple[ZigzagMeasures | None, str | None]:
    """(the zig-zag measures of the simulated run or None, why None or None)."""
    if len(t) < 3 or not np.any(rudder != rudder[0]):
        return None, None
    try:
        return zigzag_measures(t, X[:, State.PSI], rudder, execute_time=execute_time,
                               rudder_deg=rudder_deg, switch_deg=switch_deg), None
    except DataError as exc:
        # a run too short for the rudder to hold its angle has no measures; its series are
        # still the simulation's result
        return None, f'no zig-zag measures: {exc}'


def _hermite_root(t0: float, t1: float, y0: float, y1: float, d0: float, d1: float) -> float:
    """The root in (t0, t1] of the cubic Hermite interpolant of y (values y0 < 0 <= y1,
    derivatives d0, d1 at the ends)."""
    h = t1 - t0
    if y1 == 0.0:
        return t1

    def y(s: float) -> float:
        s2, s3 = s * s, s * s * s
        return ((2 * s3 - 3 * s2 + 1) * y0 + (s3 - 2 * s2 + s) * h * d0
                + (-2 * s3 + 3 * s2) * y1 + (s3 - s2) * h * d1)

    return t0 + h * brentq(y, 0.0, 1.0, xtol=1e-12)
