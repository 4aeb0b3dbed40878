"""The flight of a Slocum glider in the vertical plane of its glide, steady and dynamic.

Forces (N), after Merckelbach et al. 2019 (JTECH 36(2):281-296), written here from the physics:

- net buoyancy, vertical, positive up:
  ``B = g [rho (V_g (1 - epsilon p + alpha_T (T - T_0)) + V_bp) - m]``
  with rho the measured in-situ density, p the gauge pressure, T the water temperature (the
  hull's at equilibrium; left out when not measured), V_bp the pumped volume;
- drag, against the velocity: ``D = q S (C_D0 + C_D1 alpha^2)``, ``q = rho U^2 / 2``;
- lift, normal to the velocity: ``L = q S C_La alpha`` (hull and wings together);

alpha the angle of attack (nose above the velocity: positive), U the speed through water,
gamma = theta - alpha the glide angle (positive climbing), theta the pitch.

**Pitch is taken as measured, not modelled from the battery position.** The glider's attitude
controller moves the battery to hold a commanded pitch, and the moment balance that would give
theta from the battery position needs the centres of gravity and buoyancy and the hull's
pitching moment, none of which the depth rate can identify; the measured pitch (a calibrated
inclinometer, 1 s) carries all of that at no cost. The battery position stays in the bag as an
input for a later moment model.

Steady flight (:func:`steady_flight`): along and normal to the velocity ``D = B sin(gamma)``,
``L = -B cos(gamma)``, so ``tan(gamma) = -C_D / (C_L)`` fixes alpha from theta alone
(:func:`angle_of_attack`), and ``U^2 = 2 |B| / (rho S sqrt(C_D^2 + C_L^2))``. Where B and theta
disagree in sign (the glider pumps at an inflection) or the pitch is flatter than the best
glide there is no steady glide: U = 0, alpha = 0 (as gliderflight's steady model).

Dynamic flight (:func:`dynamic_flight`): the horizontal and vertical velocities (u_h, w_up)
obey ``M(theta) d/dt [u_h, w_up] = F`` with the mass matrix of the glider plus its added mass,
``k1 m`` along and ``k2 m`` normal to its axis, turned by the pitch; integrated with RK4 on the
sample times from rest at the surface (shallower than :data:`~.record.SURFACE_PRESSURE`, the
glider is held at rest: it drifts there with its antenna up).
"""
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
import math

import numpy as np

from auv_ident.core.compiled_cache import cached_njit
from auv_ident.core.errors import ConfigError
from auv_ident.core.glider.record import G, GliderRecord

MAX_ANGLE_OF_ATTACK = 0.35     # rad (20 deg): beyond, a Slocum's wings have stalled
ANGLE_GRID = 41                 # grid points on the search interval (at most 0.009 rad apart)
BISECTION_STEPS = 40            # then the root to 0.009 / 2^40 rad


@dataclass(frozen=True)
class GliderParameters:
    """The flight model's parameters (SI). No defaults: a glider's values are its vehicle
    file's (config/slocum_comet.yaml, read by :func:`auv_ident.core.glider.vehicle.
    glider_from_file`, which cites the published prior).

    mass : kg, in air; hull_volume : V_g m^3 at p = 0 and T_0
    drag_zero_lift : C_D0; induced_drag : C_D1 1/rad^2; lift_slope : C_La 1/rad (hull and wings)
    wing_area : S m^2, the reference area of these coefficients
    compressibility : epsilon 1/Pa; thermal_expansion : alpha_T 1/K, about
    reference_temperature T_0 degC
    added_mass_axial, added_mass_normal : k1, k2, fractions of the mass
    """

    mass: float
    hull_volume: float
    drag_zero_lift: float
    induced_drag: float
    lift_slope: float
    wing_area: float
    compressibility: float
    thermal_expansion: float
    reference_temperature: float
    added_mass_axial: float
    added_mass_normal: float

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if not math.isfinite(value):
                raise ConfigError(f'glider parameter {name} = {value!r}: not a finite number')
        for name in ('mass', 'hull_volume', 'drag_zero_lift', 'lift_slope', 'wing_area'):
            if getattr(self, name) <= 0:
                raise ConfigError(f'glider parameter {name} = {getattr(self, name)!r}: must be '
                                  'positive')

    def with_values(self, names: Sequence[str], values: Sequence[float] | np.ndarray
                    ) -> 'GliderParameters':
        return replace(self, **{n: float(v) for n, v in zip(names, values)})


@dataclass
class Flight:
    """A model's flight over a record: (N,) arrays.

    speed : U m/s, through water; angle_of_attack, glide_angle : rad (gamma positive
    climbing); depth_rate : m/s positive down (the glider's, relative to the water);
    horizontal_speed : m/s; buoyancy : B N positive up
    """

    speed: np.ndarray
    angle_of_attack: np.ndarray
    glide_angle: np.ndarray
    depth_rate: np.ndarray
    horizontal_speed: np.ndarray
    buoyancy: np.ndarray


def net_buoyancy(params: GliderParameters, record: GliderRecord) -> np.ndarray:
    """(N,) B (N, positive up), module docstring."""
    dilation = 1.0 - params.compressibility * record.pressure
    if record.temperature is not None:
        dilation = dilation + params.thermal_expansion * (record.temperature
                                                          - params.reference_temperature)
    return G * (record.density * (params.hull_volume * dilation + record.pumped_volume)
                - params.mass)


def angle_of_attack(pitch: np.ndarray, drag_zero_lift: float, induced_drag: float,
                    lift_slope: float) -> np.ndarray:
    """(N,) alpha (rad) of steady flight at pitch theta (rad), sign opposite to theta; NaN
    where there is none.

    With a = |alpha|, the glide is steeper than the pitch: h(a) = C_La a tan(|theta| + a) -
    C_D0 - C_D1 a^2 = 0. h(0) = -C_D0 < 0, and h has two roots at a glider's pitch: the small
    angle (3-4 deg at 22 deg pitch) is the flight, on the front of the drag polar, below the
    best glide ratio's a* = sqrt(C_D0 / C_D1) (7 deg), the other beyond it, where the flow
    separates. The root is bracketed on a grid of [0, a*] (at most
    :data:`MAX_ANGLE_OF_ATTACK`), then refined by bisection to float precision. Below the
    pitch of the best glide (11.5 deg with the published values: a glide angle of 18.4 deg,
    tan = 2 sqrt(C_D0 C_D1) / C_La) there is no root there: no steady glide (NaN).
    """
    pitch = np.asarray(pitch, dtype=float)
    th = np.abs(pitch)[:, None]
    best = math.sqrt(drag_zero_lift / induced_drag) if induced_drag > 0 else math.inf
    grid = np.linspace(0.0, min(best, MAX_ANGLE_OF_ATTACK), ANGLE_GRID)
    h = lift_slope * grid * np.tan(th + grid) - drag_zero_lift - induced_drag * grid ** 2
    above = h > 0
    found = above.any(axis=1)
    first = np.argmax(above, axis=1)
    lo = grid[np.maximum(first - 1, 0)]
    hi = grid[first]
    th = th[:, 0]
    for _ in range(BISECTION_STEPS):
        a = 0.5 * (lo + hi)
        up = lift_slope * a * np.tan(th + a) > drag_zero_lift + induced_drag * a * a
        hi = np.where(up, a, hi)
        lo = np.where(up, lo, a)
    return np.where(found, -np.sign(pitch) * 0.5 * (lo + hi), np.nan)


def steady_flight(params: GliderParameters, record: GliderRecord) -> Flight:
    """The steady glide at every sample (module docstring): a :class:`Flight`."""
    B = net_buoyancy(params, record)
    theta = record.pitch
    alpha = angle_of_attack(theta, params.drag_zero_lift, params.induced_drag,
                            params.lift_slope)
    gliding = (np.sign(B) == np.sign(theta)) & ~record.at_surface() & np.isfinite(alpha)
    alpha = np.nan_to_num(alpha)
    cd = params.drag_zero_lift + params.induced_drag * alpha ** 2
    cl = params.lift_slope * alpha
    speed = np.where(gliding, np.sqrt(2.0 * np.abs(B) / (record.density * params.wing_area
                                                         * np.hypot(cd, cl))), 0.0)
    gamma = theta - alpha
    return Flight(speed=speed, angle_of_attack=alpha, glide_angle=gamma,
                  depth_rate=-speed * np.sin(gamma), horizontal_speed=speed * np.cos(gamma),
                  buoyancy=B)


@cached_njit()
def _forces(u: float, w: float, rho: float, theta: float, B: float, S: float, cd0: float,
            cd1: float, cla: float) -> tuple[float, float]:
    """(F_h, F_up) N on the glider moving at (u, w) (horizontal, up) m/s."""
    speed2 = u * u + w * w
    if speed2 == 0.0:
        return 0.0, B
    speed = math.sqrt(speed2)
    alpha = theta - math.atan2(w, u)
    q = 0.5 * rho * S * speed2
    drag = q * (cd0 + cd1 * alpha * alpha)
    lift = q * cla * alpha
    # drag along -(u, w)/U, lift along (-w, u)/U (normal, to the upper side at alpha > 0)
    return (-drag * u - lift * w) / speed, (-drag * w + lift * u) / speed + B


@cached_njit()
def _accel(u: float, w: float, rho: float, theta: float, B: float, m: float, k1: float,
           k2: float, S: float, cd0: float, cd1: float, cla: float) -> tuple[float, float]:
    fh, fv = _forces(u, w, rho, theta, B, S, cd0, cd1, cla)
    # body axes: x along the hull (cos theta, sin theta), z normal (-sin theta, cos theta)
    c, s = math.cos(theta), math.sin(theta)
    fx = c * fh + s * fv
    fz = -s * fh + c * fv
    ax = fx / (m * (1.0 + k1))
    az = fz / (m * (1.0 + k2))
    return c * ax - s * az, s * ax + c * az


@cached_njit()
def _integrate(t: np.ndarray, rho: np.ndarray, theta: np.ndarray, B: np.ndarray,
               surface: np.ndarray, m: float, k1: float, k2: float, S: float, cd0: float,
               cd1: float, cla: float) -> tuple[np.ndarray, np.ndarray]:
    n = t.shape[0]
    u = np.zeros(n)
    w = np.zeros(n)
    for k in range(n - 1):
        if surface[k] or surface[k + 1]:
            continue            # at rest at the surface
        h = t[k + 1] - t[k]
        rm = 0.5 * (rho[k] + rho[k + 1])
        tm = 0.5 * (theta[k] + theta[k + 1])
        bm = 0.5 * (B[k] + B[k + 1])
        a1u, a1w = _accel(u[k], w[k], rho[k], theta[k], B[k], m, k1, k2, S, cd0, cd1, cla)
        a2u, a2w = _accel(u[k] + 0.5 * h * a1u, w[k] + 0.5 * h * a1w, rm, tm, bm,
                          m, k1, k2, S, cd0, cd1, cla)
        a3u, a3w = _accel(u[k] + 0.5 * h * a2u, w[k] + 0.5 * h * a2w, rm, tm, bm,
                          m, k1, k2, S, cd0, cd1, cla)
        a4u, a4w = _accel(u[k] + h * a3u, w[k] + h * a3w, rho[k + 1], theta[k + 1], B[k + 1],
                          m, k1, k2, S, cd0, cd1, cla)
        u[k + 1] = u[k] + h * (a1u + 2.0 * a2u + 2.0 * a3u + a4u) / 6.0
        w[k + 1] = w[k] + h * (a1w + 2.0 * a2w + 2.0 * a3w + a4w) / 6.0
    return u, w


def dynamic_flight(params: GliderParameters, record: GliderRecord) -> Flight:
    """The flight integrated in time with inertia and added mass (module docstring): a
    :class:`Flight`. The sample steps (1 s) are far below the glider's time constant
    (m (1 + k1) / (rho S C_D U) ~ 30 s), so RK4 on them is exact to the data's precision."""
    B = net_buoyancy(params, record)
    u, w = _integrate(record.t - record.t[0], record.density, record.pitch, B,
                      record.at_surface(), params.mass, params.added_mass_axial,
                      params.added_mass_normal, params.wing_area, params.drag_zero_lift,
                      params.induced_drag, params.lift_slope)
    speed = np.hypot(u, w)
    gamma = np.arctan2(w, u)
    return Flight(speed=speed, angle_of_attack=record.pitch - gamma, glide_angle=gamma,
                  depth_rate=-w, horizontal_speed=u, buoyancy=B)


FLIGHT_MODELS: dict[str, Callable[[GliderParameters, GliderRecord], Flight]] = {
    'steady': steady_flight, 'dynamic': dynamic_flight}
