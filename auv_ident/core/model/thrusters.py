"""Thrusters of a thruster-driven vehicle (ROV, hovering AUV): the file's `thrusters:` list, each
thruster's thrust curve and the body wrench they make together.

A thruster i sits at r_i (m, body FRD, from the body origin) and pushes along the unit vector
d_i (FRD) with thrust f_i (N, positive along d_i). Together (Fossen 2021, sec. 11.2.1, the
thrust configuration matrix T):

    tau = sum_i [f_i d_i; r_i x f_i d_i] = T f,   T[:, i] = [d_i; r_i x d_i]      (6,)

in N and N m, the order of the body equations X Y Z K M N.

Thrust curve of one thruster, from its command c in the unit its `command:` names:

- `force`: c is the thrust itself (N); it is only saturated.
- `setpoint` (-1..1), `rpm` (shaft speed), `pwm_us` (ESC pulse width, microseconds): the
  command's distance from neutral e = c - c0 (c0 = `neutral`: 1500 us for pwm_us, 0 otherwise)
  is saturated to +-`command_max` (the ESC's range), a dead band of half width `dead_band` around
  neutral gives no thrust (the ESC's or the blades' stall zone: T200 at 16 V, 1472-1528 us
  in Blue Robotics' table), and beyond it e_d = e - sign(e) dead_band drives a polynomial
  with separate forward and reverse coefficients (the propeller is not symmetric):

      f = a1 e_d + a2 e_d^2          (e_d > 0, `forward: [a1, a2]`)
      f = a1 e_d - a2 e_d^2          (e_d < 0, `reverse: [a1, a2]`, so f < 0 for a1, a2 > 0)

  quadratic in shaft speed (momentum theory, f ~ n |n|) with a linear term, which a thrust
  table in PWM or setpoint (not proportional to shaft speed) needs for a good fit.

Why a polynomial in the command and not in the shaft speed alone: most ROV logs carry the ESC
command (PWM or a setpoint), not the shaft speed; a user with rpm chooses `command: rpm` and the
same form. The thrust is finally saturated to [-thrust_max_reverse, thrust_max_forward] (N)
when the file gives them.

First-order lag (`time_constant`, s, optional): the thrust the ESC and motor deliver follows
the curve's value f_ss with tau_m f_dot = f_ss - f (Fossen 2021, sec. 9.3); a zero or absent
time constant is an instantaneous thruster.

Units: SI, command units as named; frames body FRD.
"""
from collections.abc import Sequence
from dataclasses import dataclass
import math

import numpy as np

from auv_ident.core.errors import ConfigError

COMMAND_TYPES = ('force', 'setpoint', 'rpm', 'pwm_us')
# the command each type has at rest (no thrust): PWM ESCs stop at 1500 us (Blue Robotics
# BasicESC, T200 datasheet); a setpoint, a shaft speed and a force stop at 0
NEUTRAL = {'force': 0.0, 'setpoint': 0.0, 'rpm': 0.0, 'pwm_us': 1500.0}
# the command range each type has when the file gives none (+- from neutral): setpoint by its
# definition, PWM the 1100-1900 us of hobby ESCs; rpm and force have no natural range
COMMAND_MAX = {'setpoint': 1.0, 'pwm_us': 400.0}
UNIT_TOL = 1e-3       # |d| must be 1 to this: a longer vector is a typo, not a thrust gain


@dataclass(frozen=True)
class Thruster:
    """One thruster of the vehicle file (module docstring)."""

    name: str
    position: np.ndarray      # (3,) m, body FRD
    direction: np.ndarray     # (3,) unit vector, body FRD
    command: str              # one of COMMAND_TYPES
    neutral: float            # command at rest (its unit)
    command_max: float        # |command - neutral| saturates here (its unit; inf: none)
    dead_band: float          # half width of the no-thrust zone around neutral (its unit)
    forward: tuple            # (a1, a2): f = a1 e + a2 e^2 for e > 0 (N per unit, per unit^2)
    reverse: tuple            # (a1, a2): f = a1 e - a2 e^2 for e < 0
    thrust_max_forward: float = math.inf    # N
    thrust_max_reverse: float = math.inf    # N (positive number; f >= -this)
    time_constant: float = 0.0              # s, first-order lag; 0 instantaneous

    @property
    def column(self) -> np.ndarray:
        """(6,) this thruster's column of the configuration matrix [d; r x d] (N, N m per N)."""
        return np.concatenate([self.direction, np.cross(self.position, self.direction)])

    def thrust(self, command: float) -> float:
        """Steady thrust (N, along d) for a command in this thruster's unit."""
        if self.command == 'force':
            f = float(command)
        else:
            e = min(max(float(command) - self.neutral, -self.command_max), self.command_max)
            if abs(e) <= self.dead_band:
                return 0.0
            e -= math.copysign(self.dead_band, e)
            a1, a2 = self.forward if e > 0 else self.reverse
            f = a1 * e + math.copysign(a2 * e * e, e)
        return min(max(f, -self.thrust_max_reverse), self.thrust_max_forward)


# Columns of the thruster table the compiled model reads (one row per thruster, the file's
# order; hydrodynamics._thrusters): its configuration column [d; r x d], whether it follows a
# thrust curve (1) or takes the force itself (0), and the curve's constants
T_COL = 0               # 0..5
T_CURVE, T_NEUTRAL, T_CMAX, T_DEAD = 6, 7, 8, 9
T_FWD1, T_FWD2, T_REV1, T_REV2, T_FMAX_FWD, T_FMAX_REV = 10, 11, 12, 13, 14, 15
THR_COLS = 16


def thruster_table(thrusters: Sequence[Thruster]) -> np.ndarray:
    """(n, THR_COLS) float: the thrusters as the compiled model reads them (T_* columns)."""
    out = np.zeros((len(thrusters), THR_COLS))
    for i, t in enumerate(thrusters):
        out[i, T_COL:T_COL + 6] = t.column
        out[i, T_CURVE] = 0.0 if t.command == 'force' else 1.0
        out[i, T_NEUTRAL] = t.neutral
        out[i, T_CMAX] = t.command_max
        out[i, T_DEAD] = t.dead_band
        out[i, T_FWD1], out[i, T_FWD2] = t.forward
        out[i, T_REV1], out[i, T_REV2] = t.reverse
        out[i, T_FMAX_FWD] = t.thrust_max_forward
        out[i, T_FMAX_REV] = t.thrust_max_reverse
    return out


def configuration_matrix(thrusters: Sequence[Thruster]) -> np.ndarray:
    """(6, n) thrust configuration matrix T (module docstring): tau = T f."""
    if not thrusters:
        return np.zeros((6, 0))
    return np.stack([t.column for t in thrusters], axis=1)


def steady_thrusts(thrusters: Sequence[Thruster], commands: Sequence[float]) -> np.ndarray:
    """(n,) steady thrust of each thruster (N) for its command (in its unit)."""
    if len(commands) != len(thrusters):
        raise ConfigError(f'{len(commands)} thruster commands for {len(thrusters)} thrusters')
    return np.array([t.thrust(c) for t, c in zip(thrusters, commands)], dtype=float)


def lagged_thrusts(thrusters: Sequence[Thruster], f: np.ndarray, f_ss: np.ndarray,
                   dt: float) -> np.ndarray:
    """(n,) thrusts after dt (s) from f toward f_ss under each thruster's first-order lag
    (exact for a command held over dt: f + (f_ss - f)(1 - exp(-dt / time_constant)))."""
    out = np.array(f_ss, dtype=float)
    for i, t in enumerate(thrusters):
        if t.time_constant > 0.0:
            out[i] = f[i] + (f_ss[i] - f[i]) * -math.expm1(-dt / t.time_constant)
    return out


def wrench(thrusters: Sequence[Thruster], commands: Sequence[float]) -> np.ndarray:
    """(6,) steady body wrench [X Y Z K M N] (N, N m, FRD) of the thrusters for their
    commands: sum_i [f_i d_i; r_i x f_i d_i]."""
    return configuration_matrix(thrusters) @ steady_thrusts(thrusters, commands)


def _number(d: dict, key: str, where: str, default: float | None = None,
            nonnegative: bool = False) -> float:
    if key not in d:
        if default is None:
            raise ConfigError(f'{where}: missing key `{key}`')
        return default
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ConfigError(f'{where}: {key} = {v!r} is not a finite number')
    if nonnegative and v < 0:
        raise ConfigError(f'{where}: {key} = {v!r} must be >= 0')
    return float(v)


def _vector(d: dict, key: str, where: str) -> np.ndarray:
    v = d.get(key)
    if (not isinstance(v, (list, tuple)) or len(v) != 3
            or not all(isinstance(a, (int, float)) and not isinstance(a, bool)
                       and math.isfinite(a) for a in v)):
        raise ConfigError(f'{where}: {key} = {v!r}; give [x, y, z] (FRD, finite numbers)')
    return np.array(v, dtype=float)


def _pair(d: dict, key: str, where: str) -> tuple:
    v = d.get(key)
    if (not isinstance(v, (list, tuple)) or len(v) != 2
            or not all(isinstance(a, (int, float)) and not isinstance(a, bool)
                       and math.isfinite(a) and a >= 0 for a in v)):
        raise ConfigError(f'{where}: {key} = {v!r}; give [a1, a2] (linear and quadratic '
                          'coefficients, >= 0, f = a1 e + a2 e^2 along the thrust direction)')
    return float(v[0]), float(v[1])


def _thruster(entry: object, where: str) -> Thruster:  # noqa: C901 (one check per key)
    if not isinstance(entry, dict):
        raise ConfigError(f'{where}: a thruster is a mapping (name, r, d, command, ...), got '
                          f'{type(entry).__name__}')
    name = str(entry.get('name', '')) or where
    w = f'{where} ({name})'
    r = _vector(entry, 'r', w)
    d = _vector(entry, 'd', w)
    if abs(np.linalg.norm(d) - 1.0) > UNIT_TOL:
        raise ConfigError(f'{w}: d = {entry["d"]!r} has length {np.linalg.norm(d):.4g}; the '
                          'thrust direction is a unit vector (the gain is in the thrust curve)')
    cmd = entry.get('command')
    if cmd not in COMMAND_TYPES:
        raise ConfigError(f'{w}: command = {cmd!r}; known: {", ".join(COMMAND_TYPES)}')
    neutral = _number(entry, 'neutral', w, NEUTRAL[cmd])
    cmax = _number(entry, 'command_max', w, COMMAND_MAX.get(cmd, math.inf), nonnegative=True)
    if cmd == 'force':
        fwd = rev = (1.0, 0.0)
        dead = 0.0
    else:
        fwd = _pair(entry, 'forward', w)
        rev = _pair(entry, 'reverse', w)
        dead = _number(entry, 'dead_band', w, 0.0, nonnegative=True)
        if dead >= cmax:
            raise ConfigError(f'{w}: dead_band = {dead:g} is not below command_max = '
                              f'{cmax:g}: the thruster would never push')
    return Thruster(
        name=name, position=r, direction=d / np.linalg.norm(d), command=cmd, neutral=neutral,
        command_max=cmax, dead_band=dead, forward=fwd, reverse=rev,
        thrust_max_forward=_number(entry, 'thrust_max_forward', w, math.inf, nonnegative=True),
        thrust_max_reverse=_number(entry, 'thrust_max_reverse', w, math.inf, nonnegative=True),
        time_constant=_number(entry, 'time_constant', w, 0.0, nonnegative=True))


def thrusters_from_file(raw: object, where: str) -> tuple[list[Thruster], list[str]]:
    """The file's `thrusters:` list (absent: none) as Thrusters, and every problem found (one
    string per bad thruster, all of them, so a user fixes the list in one round)."""
    if raw is None:
        return [], []
    if not isinstance(raw, list):
        return [], [f'thrusters: a list of thrusters (docs/vehicles.md, Thrusters), got '
                    f'{type(raw).__name__}']
    out: list[Thruster] = []
    problems: list[str] = []
    for i, entry in enumerate(raw):
        try:
            out.append(_thruster(entry, f'thrusters[{i}]'))
        except ConfigError as err:
            problems.append(str(err))
    names = [t.name for t in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        problems.append(f'thrusters: names {", ".join(dup)} appear more than once (each names '
                        'its command channel)')
    return out, problems
