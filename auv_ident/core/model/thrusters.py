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
same form.

Or a table (`table: {unit: N|kgf|lbf, command: [c_0 .. c_K-1], thrust: [f_0 .. f_K-1]}`, in
place of `forward`, `reverse` and `dead_band`): the manufacturer's measured points, the dead
band as the points of zero thrust. The command is saturated to +-`command_max` around neutral
as above, then to the table's ends (the table's end values beyond them), and the thrust
between points is the monotone piecewise cubic Hermite interpolant of Fritsch and Carlson in
the form of Fritsch and Butland (the slopes of scipy.interpolate.PchipInterpolator, see
pchip_slopes): it passes through every point, never overshoots them (a flat run of zeros,
the dead band, stays exactly 0) and has a continuous slope. Why not straight lines between
the points: the filter would take either (it never differentiates the curve: the commands are
inputs; the thrust gains multiply the curve's value, and that value is d/d(gain)), but a
continuous slope keeps a coarser table (every 16 us of the T200's 4 us steps) within the
measured points' own scatter, and a trim or a controller built on the curve can
differentiate it. The two are not indifferent to the result: on the independent BlueROV2
sessions whose truth is the straight line, the surge terms follow millinewtons of the curve at
small commands (the cubic leaves the dead band with slope 0: 0.054 N against the line's
0.098 N at 1529 us), and the file's cubic leaves X_u 8.7-11 % off (docs/vehicles.md, "The
table's truth"); state the thrust at small commands finely when it is known. The table's
thrust is in its `unit` (kgf: x 9.80665, as Blue Robotics publishes it; lbf x
4.4482216152605), held in N.

The thrust is finally saturated to [-thrust_max_reverse, thrust_max_forward] (N) when the file
gives them.

First-order lag (`time_constant`, s, optional, per thruster; or one coefficient of the file
with the multiplier `thruster_lag` shared by every thruster, which can be identified): the
thrust the ESC and motor deliver follows the curve's value f_ss with tau_m f_dot = f_ss - f
(Fossen 2021, sec. 9.3); a zero or absent time constant is an instantaneous thruster. The
model lags the curve's forward part max(f_ss, 0) and its reverse part min(f_ss, 0) apart (the
thrust gains scale the two sides, and a lag is linear, so lag(g_fwd f_fwd + g_rev f_rev) =
g_fwd lag(f_fwd) + g_rev lag(f_rev)); how the filter carries the lagged thrust:
core/model/thruster_lag.py.

Propeller torque (`torque_ratio`, N m per N, optional, 0 by default): a spinning propeller
turns the vehicle the other way about its shaft with a torque about proportional to its thrust
(both go as n|n|, Fossen 2021, sec. 9.3: Q / T = K_Q D / K_T at one advance ratio), so the
thruster's moment about its own axis is k_q f d: its column of T becomes [d; r x d + k_q d].
The sign is the propeller's handedness: the reaction turns the vehicle against the propeller's
rotation, so a propeller turning clockwise seen from behind (looking along d) while it pushes
along d gives k_q < 0, and reversing the command reverses thrust and torque together. The ratio
is K_Q D / K_T from the propeller's open-water coefficients at bollard pull, or a measured torque
over thrust; the file gives it or the torque is left out (0).

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
# a table's thrust unit -> N (kgf and lbf: the standard gravity 9.80665 m/s^2 by definition)
TABLE_UNITS = {'N': 1.0, 'kgf': 9.80665, 'lbf': 4.4482216152605}
TABLE_KEYS = ('unit', 'command', 'thrust')


def pchip_slopes(x: np.ndarray, f: np.ndarray) -> np.ndarray:
    """(K,) slopes (N per command unit) of the monotone cubic Hermite interpolant through the
    points (x strictly increasing, K >= 2): Fritsch and Butland's weighted harmonic mean of the
    neighbouring secants inside, 0 where they differ in sign or one is 0 (a flat run stays
    flat); the ends by the one-sided three-point formula, limited to keep monotone (the
    slopes scipy.interpolate.PchipInterpolator uses, so either evaluates the same curve)."""
    h = np.diff(x)
    m = np.diff(f) / h
    d = np.zeros(len(x))
    if len(x) == 2:
        d[:] = m[0]
        return d
    for k in range(1, len(x) - 1):
        if m[k - 1] * m[k] > 0.0:
            w1, w2 = 2.0 * h[k] + h[k - 1], h[k] + 2.0 * h[k - 1]
            d[k] = (w1 + w2) / (w1 / m[k - 1] + w2 / m[k])
    d[0] = _end_slope(h[0], h[1], m[0], m[1])
    d[-1] = _end_slope(h[-1], h[-2], m[-1], m[-2])
    return d


def _end_slope(h0: float, h1: float, m0: float, m1: float) -> float:
    d = ((2.0 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
    if np.sign(d) != np.sign(m0):
        return 0.0
    if np.sign(m0) != np.sign(m1) and abs(d) > 3.0 * abs(m0):
        return 3.0 * m0
    return float(d)


def hermite(table: np.ndarray, c: float) -> float:
    """The table's curve (3, K: command, thrust N, slope) at command c, c saturated to the
    table's ends: the cubic Hermite piece of the interval holding c."""
    x, f, d = table
    if c <= x[0]:
        return float(f[0])
    if c >= x[-1]:
        return float(f[-1])
    k = int(np.searchsorted(x, c, side='right')) - 1
    h = x[k + 1] - x[k]
    t = (c - x[k]) / h
    t2, t3 = t * t, t * t * t
    return float((2 * t3 - 3 * t2 + 1) * f[k] + (t3 - 2 * t2 + t) * h * d[k]
                 + (-2 * t3 + 3 * t2) * f[k + 1] + (t3 - t2) * h * d[k + 1])


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
    torque_ratio: float = 0.0               # m (N m of torque about d per N of thrust)
    # (3, K) the table's command, thrust (N) and slope (N per unit) at each point, or None:
    # the polynomial above (module docstring)
    table: np.ndarray | None = None

    @property
    def column(self) -> np.ndarray:
        """(6,) this thruster's column of the configuration matrix [d; r x d + k_q d] (N, N m
        per N; k_q the torque_ratio, module docstring)."""
        return np.concatenate([self.direction, np.cross(self.position, self.direction)
                               + self.torque_ratio * self.direction])

    def thrust(self, command: float) -> float:
        """Steady thrust (N, along d) for a command in this thruster's unit."""
        if self.command == 'force':
            f = float(command)
        elif self.table is not None:
            n0, cmax = self.neutral, self.command_max
            f = hermite(self.table, min(max(float(command), n0 - cmax), n0 + cmax))
        else:
            e = min(max(float(command) - self.neutral, -self.command_max), self.command_max)
            if abs(e) <= self.dead_band:
                return 0.0
            e -= math.copysign(self.dead_band, e)
            a1, a2 = self.forward if e > 0 else self.reverse
            f = a1 * e + math.copysign(a2 * e * e, e)
        return min(max(f, -self.thrust_max_reverse), self.thrust_max_forward)


# Columns of the thruster table the compiled model reads (one row per thruster, the file's
# order; hydrodynamics._thrusters): its configuration column [d; r x d + k_q d], whether it
# follows a thrust curve (1) or takes the force itself (0), the curve's constants and its own
# time constant (s; the lag coefficient replaces it when the file has one); a table's K
# points (T_NTAB = K, 0 for the polynomial) follow from column THR_COLS on: K commands, K
# thrusts (N), K slopes (the row is as long as the longest table; shorter ones end in zeros)
T_COL = 0               # 0..5
T_CURVE, T_NEUTRAL, T_CMAX, T_DEAD = 6, 7, 8, 9
T_FWD1, T_FWD2, T_REV1, T_REV2, T_FMAX_FWD, T_FMAX_REV = 10, 11, 12, 13, 14, 15
T_NTAB = 16
T_TAU = 17
THR_COLS = 18


def thruster_table(thrusters: Sequence[Thruster]) -> np.ndarray:
    """(n, THR_COLS + 3 K_max) float: the thrusters as the compiled model reads them (T_*
    columns, then each table's points)."""
    k_max = max((t.table.shape[1] for t in thrusters if t.table is not None), default=0)
    out = np.zeros((len(thrusters), THR_COLS + 3 * k_max))
    for i, t in enumerate(thrusters):
        if t.table is not None:
            k = t.table.shape[1]
            out[i, T_NTAB] = k
            out[i, THR_COLS:THR_COLS + 3 * k] = t.table.reshape(-1)
        out[i, T_COL:T_COL + 6] = t.column
        out[i, T_CURVE] = 0.0 if t.command == 'force' else 1.0
        out[i, T_NEUTRAL] = t.neutral
        out[i, T_CMAX] = t.command_max
        out[i, T_DEAD] = t.dead_band
        out[i, T_FWD1], out[i, T_FWD2] = t.forward
        out[i, T_REV1], out[i, T_REV2] = t.reverse
        out[i, T_FMAX_FWD] = t.thrust_max_forward
        out[i, T_FMAX_REV] = t.thrust_max_reverse
        out[i, T_TAU] = t.time_constant
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
    table = None
    if cmd == 'force':
        if 'table' in entry:
            raise ConfigError(f'{w}: table: a `command: force` thruster takes its thrust as '
                              'the command; a table belongs to a pwm_us, setpoint or rpm one')
        fwd = rev = (1.0, 0.0)
        dead = 0.0
    elif 'table' in entry:
        both = [k for k in ('forward', 'reverse', 'dead_band') if k in entry]
        if both:
            raise ConfigError(f'{w}: table and {", ".join(both)}: give the curve one way, the '
                              'table (its zero-thrust points are the dead band) or the '
                              'polynomial')
        table = _table(entry['table'], w, neutral, cmax)
        fwd = rev = (0.0, 0.0)
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
        time_constant=_number(entry, 'time_constant', w, 0.0, nonnegative=True),
        torque_ratio=_number(entry, 'torque_ratio', w, 0.0), table=table)


def _numbers(raw: object) -> np.ndarray | None:
    """raw as a float array when it is a list of finite numbers, else None."""
    if (not isinstance(raw, (list, tuple))
            or not all(isinstance(a, (int, float)) and not isinstance(a, bool)
                       and math.isfinite(a) for a in raw)):
        return None
    return np.array(raw, dtype=float)


def _table(raw: object, w: str, neutral: float, cmax: float) -> np.ndarray:  # noqa: C901
    """The `table:` of thruster w as (3, K): command, thrust (N), slope (pchip_slopes); one
    ConfigError naming `table` and what is wrong (module docstring: the table's form)."""
    form = ('give table: {unit: N|kgf|lbf, command: [...], thrust: [...]} (command in the '
            "thruster's command unit, increasing; thrust along d, never falling)")
    if not isinstance(raw, dict):
        raise ConfigError(f'{w}: table = {raw!r}; {form}')
    extra = sorted(set(map(str, raw)) - set(TABLE_KEYS))
    missing = [k for k in TABLE_KEYS if k not in raw]
    if extra or missing:
        raise ConfigError(f'{w}: table: ' + '; '.join(
            ([f'unknown key(s) {", ".join(extra)}'] if extra else [])
            + ([f'missing {", ".join(missing)}'] if missing else [])) + f'; {form}')
    unit = raw['unit']
    if unit not in TABLE_UNITS:
        raise ConfigError(f'{w}: table.unit = {unit!r}; the thrust unit is one of '
                          f'{", ".join(TABLE_UNITS)}')
    x, f = _numbers(raw['command']), _numbers(raw['thrust'])
    for key, a in (('command', x), ('thrust', f)):
        if a is None or len(a) < 2:
            raise ConfigError(f'{w}: table.{key} is not a list of at least two finite '
                              f'numbers; {form}')
    assert x is not None and f is not None        # for mypy: checked just above
    if len(x) != len(f):
        raise ConfigError(f'{w}: table.command has {len(x)} points and table.thrust '
                          f'{len(f)}: one thrust per command')
    if np.any(np.diff(x) <= 0.0):
        k = int(np.argmax(np.diff(x) <= 0.0))
        raise ConfigError(f'{w}: table.command is not increasing ({x[k]:g} then '
                          f'{x[k + 1]:g}): one point per command, in order')
    if np.any(np.diff(f) < 0.0):
        k = int(np.argmax(np.diff(f) < 0.0))
        raise ConfigError(f'{w}: table.thrust falls from {f[k]:g} to {f[k + 1]:g} {unit} '
                          f'(commands {x[k]:g} to {x[k + 1]:g}): a larger command never '
                          'pushes less (a curve measured the other way round is a thruster '
                          'pointing along -d)')
    lo, hi = neutral - cmax, neutral + cmax
    if x[0] < lo or x[-1] > hi or not x[0] <= neutral <= x[-1]:
        raise ConfigError(f'{w}: table.command spans {x[0]:g}..{x[-1]:g}, not inside the '
                          f'command range {lo:g}..{hi:g} around neutral {neutral:g}, or not '
                          'across neutral: check the command unit (and neutral, command_max)')
    if np.any(f[x < neutral] > 0.0) or np.any(f[x > neutral] < 0.0):
        raise ConfigError(f'{w}: table.thrust is not <= 0 below neutral {neutral:g} and >= 0 '
                          'above it: a command above neutral pushes along d')
    f = f * TABLE_UNITS[unit]
    return np.stack([x, f, pchip_slopes(x, f)])


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


def scaled_curves(raw: list, forward: float, reverse: float) -> list:
    """A vehicle file's `thrusters:` entries (raw YAML mappings) with every thrust curve scaled:
    the forward side (f > 0) by `forward`, the reverse side by `reverse`, polynomial
    coefficients, table thrusts and saturations alike (a truth whose thrusters differ from the
    file's, as worn propellers or another battery voltage make them). New mappings; raw is
    unchanged (the entries may share one table through a YAML alias)."""
    out = []
    for entry in raw:
        e = dict(entry)
        if 'table' in e:
            t = dict(e['table'])
            t['thrust'] = [v * (forward if v > 0 else reverse) for v in t['thrust']]
            e['table'] = t
        for key, k in (('forward', forward), ('reverse', reverse)):
            if key in e:
                e[key] = [a * k for a in e[key]]
        for key, k in (('thrust_max_forward', forward), ('thrust_max_reverse', reverse)):
            if key in e:
                e[key] = e[key] * k
        out.append(e)
    return out


def curve_text(t: Thruster) -> str:
    """One line saying thruster t's thrust curve (its form and numbers), for reports."""
    if t.command == 'force':
        return 'command = thrust (N)'
    head = f'e = {t.command} - {t.neutral:g} saturated to +-{t.command_max:g}'
    if t.table is not None:
        x, f = t.table[0], t.table[1]
        return (f'{head}; table of {len(x)} points, {x[0]:g}..{x[-1]:g} -> '
                f'{f[0]:.4g}..{f[-1]:.4g} N, monotone cubic (PCHIP) between them, its end '
                'values beyond')
    return (f'{head}, no thrust for |e| <= {t.dead_band:g}, then e_d = e -+ {t.dead_band:g}: '
            f'f = {t.forward[0]:.6g} e_d + {t.forward[1]:.6g} e_d^2 (e > 0), '
            f'{t.reverse[0]:.6g} e_d - {t.reverse[1]:.6g} e_d^2 (e < 0)')
