"""The column map of a measured run: which file column holds which quantity, in which unit,
frame, sign and time base, and the conversion of those columns into our state (NED/FRD, SI).

A column map is a YAML mapping (``import --format csv --columns MAP.yaml``; the HSVA format
uses the built-in :data:`HSVA_MAP`). Top-level keys are quantities, plus two settings::

    world: ned          # ned (default): world NED, body FRD; enu: world ENU, body FLU (REP-103)
    delimiter: ','      # CSV field separator (default ',')
    time:   {column: t, unit: s}                    # base: run (default) or unix, see below
    x:      {column: north, unit: m}
    psi:    {column: heading, unit: deg, sign: -1}
    xdot:   {column: vn, unit: m/s, frame: earth}
    rudder: {column: delta, unit: deg}
    thrust: {column: T, unit: N}

Quantities (:data:`QUANTITIES`) and their units (:data:`UNITS`, every entry must name one):

- ``time`` (s, ms, us, ns): the sample time. ``base: run`` (default): from the run's own
  origin, stamps are ``--start`` + time; ``base: unix``: since 1970-01-01T00:00:00Z, the stamps.
- ``x y z`` (m): position in the world frame; ``xdot ydot zdot`` (m/s, kn): velocity over
  ground in the world frame (``frame: earth``), rotated into body axes with the attitude.
- ``u v w`` (m/s, kn), ``p q r`` (rad/s, deg/s): body velocities (``frame: body``).
- ``phi theta psi`` (rad, deg): ZYX Euler angles (SNAME/Fossen: roll, pitch, yaw/heading).
- ``rudder`` (rad, deg): the rudder angle in our sign, delta_r: positive = trailing edge to
  port, which turns the vehicle to port (negative yaw rate) as N_dr < 0 says in the vehicle
  files; a log with the opposite convention maps it with ``sign: -1``.
- ``stern_planes``, ``bow_planes``, ``bow_plane_port``, ``bow_plane_starboard`` (rad, deg):
  the other fins of the input vector (core/model/state.py ``Input``: delta_s, delta_b,
  delta_bp, delta_bs), in the vehicle files' signs.
- ``thrust`` (N, kN): the measured propeller thrust; ``shaft`` (rpm, rps, rad/s): shaft speed.

Multi-rate logs (every sensor at its own rate, one row per time any of them sampled): a blank
cell is "no sample of this quantity at this row". A state channel is then not measured at that
row; an input holds its last value (commands are logged on change). A row with a NaN or Inf
in a mapped cell is skipped and counted (importers.py). A decimal comma (``0,5``) is refused
with a message that says so: a ';'-separated log writes its numbers with a decimal point.

Entry fields: ``column`` (the header name, required), ``unit`` (required: a wrong guess between
deg and rad is silent garbage otherwise), ``sign`` (1 or -1, default 1: multiplies the value in
the file, before any frame conversion), ``frame`` (optional check, body or earth: must be the
quantity's), ``base`` (time only), ``pwm`` (inputs logged as a pulse width, unit ``us``, as
ArduPilot's RCOU: ``{neutral: 1500, half_range: 400, full_scale: 20, unit: deg}``, the value is
``(us - neutral) / half_range * full_scale``). With ``world: enu`` every quantity is read
in ENU/FLU (x east, y north, z up, yaw counterclockwise from east, body y to port) and converted as
:mod:`auv_ident.session.messages` documents: position (y, x, -z), Euler angles
(phi, -theta, pi/2 - psi), body vectors (x, -y, -z).

Body velocities from earth-fixed ones: with ``zdot`` given, ``nu = R(phi, theta, psi)^T
[xdot ydot zdot]`` (the angles not given taken as 0); without it, only the horizontal
components exist, so they are rotated about the vertical by psi alone (the heading axes of
surface-ship practice: ``u = xdot cos psi + ydot sin psi``, ``v = -xdot sin psi + ydot cos
psi``; at a roll of 0.5 deg the neglected cos(phi) factor is 1 - 4e-5) and w stays unmeasured.

Every check raises :class:`ColumnMapError` naming the map (file) and the entry.
"""
from decimal import Decimal, InvalidOperation, ROUND_HALF_EVEN
import math
import re

import numpy as np
import yaml

from auv_ident.core.errors import ConfigError
from auv_ident.core.model.state import State

# quantity -> (kind, frame or None, State index or None)
QUANTITIES = {
    'time': ('time', None, None),
    'x': ('length', 'earth', State.X), 'y': ('length', 'earth', State.Y),
    'z': ('length', 'earth', State.Z),
    'phi': ('angle', None, State.PHI), 'theta': ('angle', None, State.THETA),
    'psi': ('angle', None, State.PSI),
    'u': ('speed', 'body', State.U), 'v': ('speed', 'body', State.V),
    'w': ('speed', 'body', State.W),
    'p': ('rate', 'body', State.P), 'q': ('rate', 'body', State.Q),
    'r': ('rate', 'body', State.R),
    'xdot': ('speed', 'earth', None), 'ydot': ('speed', 'earth', None),
    'zdot': ('speed', 'earth', None),
    'rudder': ('fin', None, None),
    'stern_planes': ('fin', None, None), 'bow_planes': ('fin', None, None),
    'bow_plane_port': ('fin', None, None), 'bow_plane_starboard': ('fin', None, None),
    'thrust': ('force', None, None),
    'shaft': ('shaft', None, None),
}
# kind -> unit -> factor to SI (time: to ns; shaft: to rpm, the unit of our input vector)
UNITS = {
    'time': {'s': 1_000_000_000, 'ms': 1_000_000, 'us': 1_000, 'ns': 1},
    'length': {'m': 1.0},
    'speed': {'m/s': 1.0, 'kn': 1852.0 / 3600.0},
    'angle': {'rad': 1.0, 'deg': math.pi / 180.0},
    'fin': {'rad': 1.0, 'deg': math.pi / 180.0, 'us': None},
    'rate': {'rad/s': 1.0, 'deg/s': math.pi / 180.0},
    'force': {'N': 1.0, 'kN': 1000.0},
    'shaft': {'rpm': 1.0, 'rps': 60.0, 'rad/s': 60.0 / (2.0 * math.pi), 'us': None},
}
PWM_FIELDS = ('neutral', 'half_range', 'full_scale', 'unit')
SETTINGS = {'world': ('ned', 'enu'), 'delimiter': None}
FIELDS = ('column', 'unit', 'sign', 'frame', 'base', 'pwm')
TIME_BASES = ('run', 'unix')
# the inputs, and the actuator of core/model/state.py Input each one is
INPUTS = ('rudder', 'stern_planes', 'bow_planes', 'bow_plane_port', 'bow_plane_starboard',
          'shaft', 'thrust')
INPUT_OF = dict(zip(INPUTS, range(7)))

# world ENU/FLU -> NED/FRD: quantity -> (quantity it becomes, sign, offset)
_ENU_TO_NED = {
    'x': ('y', 1.0, 0.0), 'y': ('x', 1.0, 0.0), 'z': ('z', -1.0, 0.0),
    'xdot': ('ydot', 1.0, 0.0), 'ydot': ('xdot', 1.0, 0.0), 'zdot': ('zdot', -1.0, 0.0),
    'phi': ('phi', 1.0, 0.0), 'theta': ('theta', -1.0, 0.0), 'psi': ('psi', -1.0, math.pi / 2),
    'u': ('u', 1.0, 0.0), 'v': ('v', -1.0, 0.0), 'w': ('w', -1.0, 0.0),
    'p': ('p', 1.0, 0.0), 'q': ('q', -1.0, 0.0), 'r': ('r', -1.0, 0.0),
}


class ColumnMapError(ConfigError):
    """A column map is wrong: the message names the map and the entry."""


class ColumnMap:
    """A checked column map (see the module docstring).

    Attributes
    ----------
    entries : dict quantity -> dict(column, unit, sign, frame, base), as checked
    world : 'ned' or 'enu'; delimiter : str; where : the map's name for messages
    """

    def __init__(self, doc, where='column map'):
        self.where = str(where)
        if not isinstance(doc, dict) or not doc:
            raise ColumnMapError(f'{self.where}: must be a mapping of quantities to '
                                 f'{{column: ..., unit: ...}}, got {doc!r}')
        self.world = 'ned'
        self.delimiter = ','
        self.entries = {}
        for key, val in doc.items():
            if key in SETTINGS:
                self._setting(key, val)
            elif key in QUANTITIES:
                self.entries[key] = self._entry(key, val)
            else:
                raise ColumnMapError(
                    f'{self.where}: unknown quantity {key!r}; known: '
                    f'{", ".join(QUANTITIES)} (and the settings {", ".join(SETTINGS)})')
        self._check_together()

    def _setting(self, key, val):
        if key == 'world':
            if val not in SETTINGS['world']:
                raise ColumnMapError(f'{self.where}: world must be ned or enu, got {val!r}')
            self.world = val
        elif not isinstance(val, str) or len(val) != 1:
            raise ColumnMapError(f'{self.where}: delimiter must be one character, got {val!r}')
        else:
            self.delimiter = val

    def _entry(self, name, val):
        where = f'{self.where}: {name}'
        if not isinstance(val, dict):
            raise ColumnMapError(f'{where}: must be a mapping like {{column: NAME, unit: '
                                 f'UNIT}}, got {val!r}')
        extra = [k for k in val if k not in FIELDS]
        if extra:
            raise ColumnMapError(f'{where}: unknown field(s) {", ".join(map(str, extra))}; '
                                 f'known: {", ".join(FIELDS)}')
        kind, frame, _ = QUANTITIES[name]
        column = val.get('column')
        if not isinstance(column, str) or not column.strip():
            raise ColumnMapError(f"{where}: give the file's column name, e.g. "
                                 f'{{column: {name}, ...}}')
        units = UNITS[kind]
        if 'unit' not in val:
            raise ColumnMapError(f'{where}: give its unit (one of {", ".join(units)})')
        if val['unit'] not in units:
            raise ColumnMapError(f'{where}: unknown unit {val["unit"]!r}; {name} takes '
                                 f'{", ".join(units)}')
        sign = val.get('sign', 1)
        if isinstance(sign, bool) or sign not in (1, -1):
            raise ColumnMapError(f'{where}: sign must be 1 or -1, got {sign!r}')
        if 'frame' in val and val['frame'] != frame:
            if frame is None:
                raise ColumnMapError(f'{where}: frame does not apply to {name} (body or earth '
                                     'is for positions and velocities)')
            other = {'u': 'xdot', 'v': 'ydot', 'w': 'zdot', 'xdot': 'u', 'ydot': 'v',
                     'zdot': 'w'}.get(name)
            kind_text = {'earth': 'an earth-fixed', 'body': 'a body'}.get(val['frame'])
            hint = (f': for {kind_text} velocity use {other}' if other and kind_text else '')
            raise ColumnMapError(f'{where}: frame {val["frame"]!r}, but {name} is a '
                                 f'{frame}-frame quantity{hint}')
        pwm = self._pwm(name, val, where)
        base = val.get('base', 'run')
        if 'base' in val and name != 'time':
            raise ColumnMapError(f'{where}: base applies to time only')
        if base not in TIME_BASES:
            raise ColumnMapError(f'{where}: base must be run or unix, got {base!r}')
        return {'column': column.strip(), 'unit': val['unit'], 'sign': int(sign),
                'frame': frame, 'base': base, 'pwm': pwm}

    def _pwm(self, name, val, where):
        """The checked pwm field of an input in microseconds (None for other units)."""
        if val['unit'] != 'us' or QUANTITIES[name][0] == 'time':    # time: us = microseconds
            if 'pwm' in val:
                raise ColumnMapError(f'{where}: pwm applies to unit us only')
            return None
        if name not in INPUTS:
            raise ColumnMapError(f'{where}: unit us (a PWM pulse width) is for the inputs '
                                 f'({", ".join(INPUTS)})')
        kind = QUANTITIES[name][0]
        others = [u for u in UNITS[kind] if u != 'us']
        pwm = val.get('pwm')
        if not isinstance(pwm, dict) or 'full_scale' not in pwm or 'unit' not in pwm:
            raise ColumnMapError(f'{where}: unit us (a PWM pulse width) needs pwm: {{neutral: '
                                 f'1500, half_range: 400, full_scale: VALUE, unit: '
                                 f'{others[-1]}}}, full_scale the {name} at neutral + '
                                 'half_range')
        extra = [k for k in pwm if k not in PWM_FIELDS]
        if extra:
            raise ColumnMapError(f'{where}: pwm: unknown field(s) {", ".join(map(str, extra))}; '
                                 f'known: {", ".join(PWM_FIELDS)}')
        if pwm['unit'] not in others:
            raise ColumnMapError(f'{where}: pwm unit {pwm["unit"]!r}; use one of '
                                 f'{", ".join(others)}')
        out = {'unit': pwm['unit']}
        for key, default in (('neutral', 1500.0), ('half_range', 400.0), ('full_scale', None)):
            v = pwm.get(key, default)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or (key != 'neutral' and v <= 0):
                raise ColumnMapError(f'{where}: pwm {key} = {v!r} must be a finite'
                                     + (' positive' if key != 'neutral' else '') + ' number')
            out[key] = float(v)
        return out

    def _check_together(self):
        e = self.entries
        if 'time' not in e:
            raise ColumnMapError(f'{self.where}: no time entry, e.g. time: {{column: t, '
                                 'unit: s}}')
        for body, earth in (('u', 'xdot'), ('v', 'ydot'), ('w', 'zdot')):
            if body in e and earth in e:
                raise ColumnMapError(f'{self.where}: both {body} and {earth}: give body '
                                     'velocities or earth-fixed ones, not both')
        horizontal = [q for q in ('xdot', 'ydot') if q in e]
        if ('zdot' in e and len(horizontal) < 2) or len(horizontal) == 1:
            raise ColumnMapError(f'{self.where}: earth-fixed velocities need xdot and ydot '
                                 '(and zdot for w): a body velocity mixes them')
        if horizontal and 'psi' not in e:
            raise ColumnMapError(f'{self.where}: earth-fixed velocities need the heading psi '
                                 'to be rotated into body axes')
        if not any(QUANTITIES[q][2] is not None or q in ('xdot', 'ydot') for q in e):
            raise ColumnMapError(f'{self.where}: no state quantity mapped (x, y, z, phi, '
                                 'theta, psi, u, v, w, p, q, r, xdot, ydot, zdot)')

    @property
    def columns(self):
        """The file columns the map reads, in the map's order (each once)."""
        return list(dict.fromkeys(ent['column'] for ent in self.entries.values()))

    @property
    def time_base(self):
        return self.entries['time']['base']

    def document(self):
        """The map as a plain dict (settings, then quantities), for metadata and messages."""
        out = {'world': self.world, 'delimiter': self.delimiter}
        for name, ent in self.entries.items():
            d = {'column': ent['column'], 'unit': ent['unit']}
            if ent['sign'] != 1:
                d['sign'] = ent['sign']
            if ent['frame']:
                d['frame'] = ent['frame']
            if ent['pwm']:
                d['pwm'] = dict(ent['pwm'])
            if name == 'time':
                d['base'] = ent['base']
            out[name] = d
        return out

    def time_ns(self, cells, where_cell):
        """The time column as int64 ns (exact decimal conversion, no float rounding).

        cells : list of str; where_cell(i) : text naming cell i (file, line, column)."""
        ent = self.entries['time']
        factor = UNITS['time'][ent['unit']] * ent['sign']
        out = np.empty(len(cells), dtype=np.int64)
        for i, cell in enumerate(cells):
            refuse_decimal_comma(cell, where_cell(i))
            try:
                d = Decimal(cell.strip())
                if not d.is_finite():
                    raise InvalidOperation
                out[i] = int((d * factor).to_integral_value(ROUND_HALF_EVEN))
            except (InvalidOperation, ValueError, OverflowError):
                raise ColumnMapError(f'{where_cell(i)}: time {cell.strip()!r} is not a finite '
                                     'number') from None
        return out

    def to_ned(self, values):
        """Convert the mapped quantities into our frames and units.

        values : dict quantity -> (N,) float array as read (file units and signs; NaN: no
            sample at that row), time excluded
        Returns ``(x (N, 12) NED/FRD SI, measured (12,) bool, inputs)``: unmeasured states are
        0, a measured one NaN at the rows without its sample (or without a sample of what it
        is computed from: the heading of an earth-fixed velocity); inputs is a dict of the
        inputs present (fins rad, 'thrust' N, 'shaft' rpm), NaN where not logged.
        """
        n = len(next(iter(values.values())))
        si = {}
        for name, arr in values.items():
            kind = QUANTITIES[name][0]
            ent = self.entries[name]
            arr = np.asarray(arr, dtype=float)
            if ent['pwm']:      # pulse width -> fraction of the full scale -> its unit
                p = ent['pwm']
                si[name] = ((arr - p['neutral']) / p['half_range']
                            * (p['full_scale'] * UNITS[kind][p['unit']] * ent['sign']))
            else:
                si[name] = arr * (UNITS[kind][ent['unit']] * ent['sign'])
        if self.world == 'enu':
            ned = {}
            for name, arr in si.items():
                target, sign, offset = _ENU_TO_NED.get(name, (name, 1.0, 0.0))
                ned[target] = offset + sign * arr
            si = ned
        x = np.zeros((n, 12))
        measured = np.zeros(12, dtype=bool)
        for name, arr in si.items():
            idx = QUANTITIES[name][2]
            if idx is not None:
                x[:, idx] = arr
                measured[idx] = True
        if 'xdot' in si:
            if 'zdot' in si:
                # full rotation: nu = R^T v_n, R = Rz(psi) Ry(theta) Rx(phi)
                vn = np.stack([si['xdot'], si['ydot'], si['zdot']], axis=1)
                R = _rotations(x[:, State.PHI], x[:, State.THETA], x[:, State.PSI])
                nu = np.einsum('kji,kj->ki', R, vn)
                x[:, State.U:State.W + 1] = nu
                measured[[State.U, State.V, State.W]] = True
            else:
                # horizontal components only: rotate about the vertical by psi
                c, s = np.cos(x[:, State.PSI]), np.sin(x[:, State.PSI])
                x[:, State.U] = si['xdot'] * c + si['ydot'] * s
                x[:, State.V] = -si['xdot'] * s + si['ydot'] * c
                measured[[State.U, State.V]] = True
        x[:, State.PHI] = _wrap(x[:, State.PHI])
        x[:, State.PSI] = _wrap(x[:, State.PSI])
        inputs = {name: si[name] for name in INPUTS if name in si}
        return x, measured, inputs


_DECIMAL_COMMA = re.compile(r'[+-]?\d*,\d+([eE][+-]?\d+)?')


def refuse_decimal_comma(cell, where, error=ColumnMapError):
    """`error` naming the cell if it is a number written with a decimal comma."""
    text = cell.strip()
    if ',' in text and _DECIMAL_COMMA.fullmatch(text):
        raise error(f'{where}: {text!r} has a decimal comma; write numbers with a '
                             f'decimal point ({text.replace(",", ".")}) and separate the '
                             "fields with another character (delimiter: ';')")


def _wrap(a):
    """Angles (rad) wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


def _rotations(phi, theta, psi):
    """(N, 3, 3) rotations body FRD -> world NED, Rz(psi) Ry(theta) Rx(phi) (Fossen 2.18)."""
    cr, sr, cp, sp, cy, sy = (np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta),
                              np.cos(psi), np.sin(psi))
    return np.stack([
        np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], axis=1),
        np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], axis=1),
        np.stack([-sp, cp * sr, cp * cr], axis=1)], axis=1)


def load_column_map(path):
    """Read and check a column map YAML file; returns a :class:`ColumnMap`."""
    try:
        with open(path, encoding='utf-8') as fh:
            doc = yaml.safe_load(fh)
    except OSError as exc:
        raise ColumnMapError(f'{path}: cannot read the column map: {exc.strerror}') from None
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ColumnMapError(f'{path}: not a YAML column map: '
                             f'{str(exc).splitlines()[0]}') from None
    return ColumnMap(doc, where=str(path))


# The HSVA free-running model tests (SIMMAN 2008 KVLCC2): the file's 12 columns, named here
# (the files have no header), and their meaning checked against the data (docs/bags.md).
HSVA_COLUMNS = ('t', 'x0', 'y0', 'psi', 'xdot0', 'ydot0', 'r', 'phi', 'delta', 'n', 'thrust',
                'torque')
HSVA_MAP = {
    'world': 'ned',
    'time': {'column': 't', 'unit': 's'},
    'x': {'column': 'x0', 'unit': 'm'},
    'y': {'column': 'y0', 'unit': 'm'},
    'psi': {'column': 'psi', 'unit': 'deg'},
    'xdot': {'column': 'xdot0', 'unit': 'm/s', 'frame': 'earth'},
    'ydot': {'column': 'ydot0', 'unit': 'm/s', 'frame': 'earth'},
    'r': {'column': 'r', 'unit': 'deg/s', 'frame': 'body'},
    'phi': {'column': 'phi', 'unit': 'deg'},
    'rudder': {'column': 'delta', 'unit': 'deg', 'sign': 1},
    'shaft': {'column': 'n', 'unit': 'rps'},
    'thrust': {'column': 'thrust', 'unit': 'N'},
}
