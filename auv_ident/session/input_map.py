"""The input map: which of a vehicle's topics the identifier reads, and how (docs/your_data.md).

One YAML file, read and checked once where it enters (:func:`load_input_map`, the
``input_map`` identifier setting: a name in config/inputs/ or a path), into a frozen
:class:`InputMap`. The shipped default, ``config/inputs/odom_actuators.yaml``, is the layout
every tool used before the map existed: a nav_msgs/Odometry on ``odom`` and a
sensor_msgs/JointState on ``actuators`` with the six joint names of session/messages.py.

Schema, version 1::

    version: 1
    body_frame: flu          # the axes the mountings are given in: flu (REP-103, default) or frd
    tf_body_frame: base_link # the body's frame id in a bag's /tf_static (mountings read there)
    inputs:
      NAME:                  # any name; it names the input in every message
        topic: odom          # relative names resolve in the node's namespace; in a bag, '/' + it
        type: nav_msgs/msg/Odometry
        ...                  # what the type takes (below)

Per type (:data:`TYPES`; ``pkg/Type`` and ``pkg/msg/Type`` are both accepted):

- ``nav_msgs/msg/Odometry`` (the nav solution, fused today): ``frame`` (auto | ned | enu;
  default auto = the ``frame`` setting: REP-103 names are ENU/FLU, a _ned/_frd token NED/FRD),
  ``fields`` (the state channels used, among u v w p q r x y z phi theta psi; default all; the
  ``measured`` setting further restricts them). At most one.
- commands (on change: every actuator holds its last value until a message changes it):

  - ``sensor_msgs/msg/JointState``: ``channels`` list of ``{joint: NAME, field: position |
    velocity | effort (default position), actuator: A, unit, scale, offset, default}``;
  - ``std_msgs/msg/Float64MultiArray`` (Stonefish setpoints): ``channels`` of ``{index: I,
    actuator: A, unit, ...}``;
  - ``std_msgs/msg/Float64`` (gz-sim Thruster ``cmd_thrust``, ros2_control forward command
    controllers), one topic per actuator: ``actuator: A, unit, scale, offset``;
  - ``geometry_msgs/msg/WrenchStamped`` (commanded body wrench): ``channels`` of ``{field:
    force.x .. torque.z, actuator: A, unit}``.

  A is an actuator of the input vector (core/model/state.py ``Input``): :data:`ACTUATORS`, or
  the name of one of the vehicle file's thrusters (its ``thrusters:`` list, docs/vehicles.md):
  the value is then that thruster's command in its own unit, which ``unit`` names
  (:data:`THRUSTER_UNITS`: us for pwm_us, setpoint, rpm, N for force; raw * scale + offset,
  no other conversion: the thrust curve takes the command as the file gives it). Which
  thruster a name is, is checked against the vehicle (:meth:`InputMap.check_vehicle`).
  value = unit(raw * scale + offset) (scale default 1, -1 flips a sign; offset default 0, in
  the message's unit); units (:data:`UNITS`): fins rad | deg | normalized (x the vehicle's fin
  limit) | us (PWM: ``pwm: {neutral: 1500, half_range: 400}`` -> normalized); n_rpm rpm |
  rad/s | rps | normalized (x the vehicle's shaft limit) | us; thrust N | kN. A JointState
  field has its message's unit (position rad, velocity rad/s, effort N) unless ``unit`` says
  otherwise; Float64 and Float64MultiArray leave it open, so ``unit`` is required.
  ``default``: the value when the message's field array is empty (a JointState without
  efforts). Messages without a header (Float64, Float64MultiArray) are stamped with their
  receive time (the bag's log time offline).
- raw sensors (parsed, checked and handed over with their mounting; which ones the filter
  fuses: :data:`FUSED_TYPES`): ``sensor_msgs/msg/Imu`` (``fields`` among orientation,
  angular_velocity, linear_acceleration), ``geometry_msgs/msg/TwistWithCovarianceStamped``
  (a DVL: ``reference`` ground | water), ``sensor_msgs/msg/FluidPressure`` (depth:
  ``density`` kg/m^3, default 1025; ``gravity`` m/s^2, default 9.80665; ``surface_pressure``
  Pa, default 101325), ``geometry_msgs/msg/PoseWithCovarianceStamped`` (``measures`` depth |
  position), ``sensor_msgs/msg/NavSatFix`` (``datum: {latitude, longitude}`` deg, the world
  origin; without it the first fix is). Each takes ``frame`` (auto | ned | enu: the
  convention of its world frame and axes) and ``mounting: {lever_arm: [x, y, z] m, rotation:
  [roll, pitch, yaw], unit: deg | rad}``: the sensor's origin in the body frame and the
  rotation sensor -> body (ZYX), both in the ``body_frame`` axes; held in FRD
  (:class:`Mounting`).

Every check raises one :class:`InputMapError` naming the map and the entry; the checks that
need the vehicle (every actuator the vehicle's model uses is fed, none that it does not have)
are :meth:`InputMap.check_vehicle`, those that need the bag :meth:`InputMap.check_topics`.
"""
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
import math
import os
from typing import Any, NoReturn

import numpy as np
import yaml

from auv_ident.core.errors import ConfigError
from auv_ident.core.model.state import Input, INPUT_NAMES, N_FINS, N_INPUT, STATE_NAMES
from auv_ident.core.model.vehicle import (
    FACTOR_INDEX,
    P_FIN,
    P_NMAX,
    P_PROP,
    PROPULSION_MODELS,
    Vehicle,
)
from auv_ident.session.messages import euler_to_rotation_matrix, RPM_TO_RAD_S

VERSION = 1
DEFAULT_MAP = 'odom_actuators'
ACTUATORS = INPUT_NAMES     # delta_r delta_s delta_b delta_bp delta_bs n_rpm thrust
ACTUATOR_TEXT = {'delta_r': 'rudder', 'delta_s': 'stern planes', 'delta_b': 'bow planes',
                 'delta_bp': 'port bow plane', 'delta_bs': 'starboard bow plane',
                 'n_rpm': 'propeller shaft speed', 'thrust': 'measured propeller thrust'}

ODOMETRY = 'nav_msgs/msg/Odometry'
JOINT_STATE = 'sensor_msgs/msg/JointState'
FLOAT64_ARRAY = 'std_msgs/msg/Float64MultiArray'
FLOAT64 = 'std_msgs/msg/Float64'
WRENCH = 'geometry_msgs/msg/WrenchStamped'
IMU = 'sensor_msgs/msg/Imu'
DVL = 'geometry_msgs/msg/TwistWithCovarianceStamped'
PRESSURE = 'sensor_msgs/msg/FluidPressure'
POSE = 'geometry_msgs/msg/PoseWithCovarianceStamped'
NAVSAT = 'sensor_msgs/msg/NavSatFix'

# type -> role: what the identifier does with it
TYPES = {ODOMETRY: 'odometry', JOINT_STATE: 'command', FLOAT64_ARRAY: 'command',
         FLOAT64: 'command', WRENCH: 'command', IMU: 'sensor', DVL: 'sensor',
         PRESSURE: 'sensor', POSE: 'sensor', NAVSAT: 'sensor'}
# the types the filter fuses on this branch (raw sensors: issue #28 item 2, the filter side)
FUSED_TYPES = frozenset((ODOMETRY, JOINT_STATE, FLOAT64_ARRAY, FLOAT64, WRENCH))
# types whose messages carry a header stamp; the others take their receive (log) time
HEADERLESS = frozenset((FLOAT64_ARRAY, FLOAT64))

FRAMES = ('auto', 'ned', 'enu')
BODY_FRAMES = ('flu', 'frd')
JOINT_FIELDS = {'position': 'rad', 'velocity': 'rad/s', 'effort': 'N'}
WRENCH_FIELDS = tuple(f'{p}.{a}' for p in ('force', 'torque') for a in 'xyz')
IMU_FIELDS = ('orientation', 'angular_velocity', 'linear_acceleration')
VELOCITY_REFERENCES = ('ground', 'water')
POSE_MEASURES = ('depth', 'position')

# actuator kind -> unit -> multiplier into the input vector's unit (rad, rpm, N); 'normalized'
# and 'us' (None here) scale by the vehicle's limit (Channel.factor)
_ANGLE_UNITS: dict[str, float | None] = {'rad': 1.0, 'deg': math.pi / 180.0,
                                         'normalized': None, 'us': None}
UNITS: dict[str, dict[str, float | None]] = {
    'fin': _ANGLE_UNITS,
    'shaft': {'rpm': 1.0, 'rad/s': 1.0 / RPM_TO_RAD_S, 'rps': 60.0, 'normalized': None,
              'us': None},
    'force': {'N': 1.0, 'kN': 1000.0},
}
PWM_DEFAULT = (1500.0, 400.0)   # us: neutral and half range (ArduSub's 1100..1900)
# a thruster channel's unit -> the thruster command type (core/model/thrusters.py) it is
THRUSTER_UNITS = {'us': 'pwm_us', 'setpoint': 'setpoint', 'rpm': 'rpm', 'N': 'force'}

_COMMON = ('topic', 'type')
_KEYS = {
    'odometry': _COMMON + ('frame', 'fields'),
    JOINT_STATE: _COMMON + ('channels',), FLOAT64_ARRAY: _COMMON + ('channels',),
    WRENCH: _COMMON + ('channels',),
    FLOAT64: _COMMON + ('actuator', 'unit', 'scale', 'offset', 'pwm'),
    IMU: _COMMON + ('frame', 'mounting', 'fields'),
    DVL: _COMMON + ('frame', 'mounting', 'reference'),
    PRESSURE: _COMMON + ('frame', 'mounting', 'density', 'gravity', 'surface_pressure'),
    POSE: _COMMON + ('frame', 'mounting', 'measures'),
    NAVSAT: _COMMON + ('frame', 'mounting', 'datum'),
}
_CHANNEL_KEYS = ('actuator', 'unit', 'scale', 'offset', 'pwm', 'default')
_SELECTOR = {JOINT_STATE: ('joint', 'field'), FLOAT64_ARRAY: ('index',), WRENCH: ('field',)}


class InputMapError(ConfigError):
    """An input map is wrong, or does not fit the vehicle or the bag: names the map and entry."""


def actuator_kind(index: int) -> str:
    """'fin', 'shaft' or 'force' of an input-vector index."""
    if index < N_FINS:
        return 'fin'
    return 'shaft' if index == Input.N_RPM else 'force'


@dataclass(frozen=True)
class Channel:
    """One actuator value read from a command message.

    actuator : index into the input vector u (core/model/state.py Input; N_INPUT + i for the
        vehicle's thruster i, once resolved: InputMap.for_vehicle), -1 for a thruster channel
        not resolved yet
    thruster : the thruster's name (vehicle file) for a thruster channel, else ''
    joint, field : JointState joint name and field; index : Float64MultiArray index;
        field : WrenchStamped 'force.x' .. 'torque.z'
    unit, scale, offset : value = unit(raw * scale + offset) (module docstring)
    pwm : (neutral, half_range) us, for unit 'us'
    default : value (input unit) when the field array is empty, or None (then an error)
    """

    actuator: int
    unit: str
    scale: float = 1.0
    offset: float = 0.0
    pwm: tuple = PWM_DEFAULT
    default: float | None = None
    joint: str = ''
    field: str = ''
    index: int = -1
    thruster: str = ''

    @property
    def name(self) -> str:
        return self.thruster or ACTUATORS[self.actuator]

    def factor(self, fin_limit: float, shaft_limit: float) -> float:
        """Multiplier of (raw * scale + offset) into the input unit; for 'us' applied after
        (x - neutral) / half_range. fin_limit rad, shaft_limit rpm: the vehicle's. 1 for a
        thruster channel (its command in its own unit)."""
        if self.thruster:
            return 1.0
        f = UNITS[actuator_kind(self.actuator)][self.unit]
        if f is not None:
            return f
        return fin_limit if actuator_kind(self.actuator) == 'fin' else shaft_limit


@dataclass(frozen=True)
class Mounting:
    """A sensor's mounting in the body frame FRD: lever_arm (3,) m from the body origin to the
    sensor; rotation (3, 3) sensor axes -> body FRD axes."""

    lever_arm: tuple = (0.0, 0.0, 0.0)
    rotation: tuple = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))

    @property
    def matrix(self) -> np.ndarray:
        return np.array(self.rotation, dtype=float)


def mounting_in_frd(lever_arm: Any, rotation: Any, body_frame: str) -> Mounting:
    """The Mounting (held in FRD) of a lever arm (3,) m and a rotation (3, 3) sensor -> body
    given in the ``body_frame`` axes ('flu' or 'frd')."""
    arm = np.asarray(lever_arm, dtype=float)
    R = np.asarray(rotation, dtype=float)
    if body_frame == 'flu':     # FLU -> FRD: (x, -y, -z); R_frd = F R_flu F
        F = np.diag([1.0, -1.0, -1.0])
        arm = F @ arm
        R = F @ R @ F
    return Mounting(tuple(float(v) for v in arm), tuple(tuple(float(v) for v in row)
                                                          for row in R))


@dataclass(frozen=True)
class InputEntry:
    """One input of the map (module docstring).

    name, topic, type (pkg/msg/Type), role ('odometry', 'command', 'sensor')
    frame : 'auto', 'ned' or 'enu' (odometry and sensors)
    fields : the odometry's state channels or the IMU's fields used
    channels : tuple of Channel (commands)
    mounting : Mounting (sensors); mounting_given : whether the map gave it (else a bag's
        /tf_static may: offline/tf_static.py)
    options : the type's own settings (reference, measures, density, gravity,
        surface_pressure, datum), checked
    """

    name: str
    topic: str
    type: str
    role: str
    frame: str = 'auto'
    fields: tuple = ()
    channels: tuple = ()
    mounting: Mounting = field(default_factory=Mounting)
    mounting_given: bool = False
    options: tuple = ()

    @property
    def bag_topic(self) -> str:
        """The topic as a bag records it: relative names at the root."""
        return self.topic if self.topic.startswith('/') else '/' + self.topic

    @property
    def stamped(self) -> bool:
        """True if the messages carry a header stamp (else: receive time)."""
        return self.type not in HEADERLESS

    def option(self, key: str) -> Any:
        return dict(self.options)[key]


@dataclass(frozen=True)
class InputMap:
    """A checked input map: ``inputs`` (tuple of InputEntry, the file's order), ``where`` (the
    file, for messages), ``body_frame``, ``tf_body_frame`` (the body's frame id in a bag's
    /tf_static, default base_link: offline/tf_static.py)."""

    inputs: tuple
    where: str = 'input map'
    body_frame: str = 'flu'
    tf_body_frame: str = 'base_link'

    @property
    def odometry(self) -> 'InputEntry | None':
        """The Odometry input, or None."""
        return next((e for e in self.inputs if e.role == 'odometry'), None)

    @property
    def commands(self) -> tuple['InputEntry', ...]:
        return tuple(e for e in self.inputs if e.role == 'command')

    @property
    def sensors(self) -> tuple['InputEntry', ...]:
        return tuple(e for e in self.inputs if e.role == 'sensor')

    @property
    def topic_types(self) -> dict[str, str]:
        """{bag topic: type} of every input (what a recorder records, a bag must hold)."""
        return {e.bag_topic: e.type for e in self.inputs}

    def fed(self) -> dict[int, list[str]]:
        """{actuator index: [input names feeding it]} (thruster channels once resolved:
        for_vehicle)."""
        out: dict[int, list[str]] = {}
        for e in self.commands:
            for c in e.channels:
                out.setdefault(c.actuator, []).append(e.name)
        return out

    def for_vehicle(self, vehicle: Vehicle) -> 'InputMap':
        """This map with its thruster channels resolved to the vehicle's input vector
        (actuator N_INPUT + the thruster's place in the file); InputMapError for a thruster
        the vehicle has not, or a unit that is not its command's."""
        names = [t.name for t in vehicle.thrusters]
        entries = []
        for e in self.inputs:
            chans = []
            for c in e.channels:
                if c.thruster:
                    if c.thruster not in names:
                        raise InputMapError(
                            f'{self.where}: input {e.name!r}: vehicle {vehicle.name!r} has no '
                            f'thruster or actuator {c.thruster!r}; its thrusters: '
                            f'{", ".join(names) or "none"}; its actuators: '
                            + ', '.join(ACTUATORS))
                    th = vehicle.thrusters[names.index(c.thruster)]
                    if THRUSTER_UNITS[c.unit] != th.command:
                        raise InputMapError(
                            f'{self.where}: input {e.name!r}: thruster {c.thruster} takes '
                            f'command {th.command} (vehicle file), the map gives unit '
                            f'{c.unit}: use unit '
                            + next(u for u, k in THRUSTER_UNITS.items() if k == th.command))
                    c = replace(c, actuator=N_INPUT + names.index(c.thruster))
                chans.append(c)
            entries.append(replace(e, channels=tuple(chans)))
        return replace(self, inputs=tuple(entries))

    def check_vehicle(self, vehicle: Vehicle) -> None:
        """InputMapError unless every actuator the vehicle's model uses (its thrusters too) is
        fed by a command input (the others are held at 0), and the filter fuses every input."""
        resolved = self.for_vehicle(vehicle)
        for e in self.inputs:
            if e.type not in FUSED_TYPES:
                raise InputMapError(
                    f'{self.where}: input {e.name!r} ({e.type}): raw sensors are identified '
                    'by the raw-sensor filter (the identifier node with this map, identify '
                    '--bag BAG --input-map MAP: docs/raw_sensors.md), not by the odometry '
                    'session, which fuses a nav_msgs/msg/Odometry')
        fed = resolved.fed()
        missing = [vehicle.input_names[i] for i in vehicle_actuators(vehicle) if i not in fed]
        if missing:
            raise InputMapError(
                f'{self.where}: vehicle {vehicle.name!r} is driven by '
                + ', '.join(f'{a} ({ACTUATOR_TEXT.get(a, "thruster")})' for a in missing)
                + ', which no command input feeds: add a channel with actuator: '
                + missing[0])
        if self.odometry is None:
            raise InputMapError(f'{self.where}: no nav_msgs/msg/Odometry input: the filter '
                                'fuses the nav solution (raw sensors: docs/your_data.md)')

    def check_topics(self, present: dict[str, str], source: object) -> None:
        """InputMapError naming the first input whose topic the bag lacks or records with
        another type. present : {topic: type} of the bag; source : the bag, for messages."""
        for e in self.inputs:
            topic = e.bag_topic
            if topic not in present:
                listing = ', '.join(f'{t} ({present[t]})' for t in sorted(present)) or 'none'
                raise InputMapError(f'{source}: no {_ROLE_TEXT[e.role]} topic {topic!r} in the '
                                    f'bag (input {e.name!r} of {self.where}); topics present: '
                                    f'{listing}')
            if normalize_type(present[topic]) != e.type:
                raise InputMapError(f'{source}: topic {topic} has type {present[topic]}, '
                                    f'expected {e.type} (input {e.name!r} of {self.where})')


_ROLE_TEXT = {'odometry': 'odometry', 'command': 'actuator', 'sensor': 'sensor'}


def vehicle_actuators(vehicle: Vehicle) -> list[int]:
    """Sorted input-vector indices the vehicle's model uses: the fins its terms multiply
    (db2 = the port and starboard bow planes), the shaft speed of its propeller model (or of a
    propeller-epsilon term) and the measured thrust (a thrust term or measured_thrust)."""
    factors = {int(f) for f in vehicle.terms_i[:, 2:].ravel() if f >= 0}
    used = {i for i, name in enumerate(('dr', 'ds', 'db', 'dbp', 'dbs'))
            if FACTOR_INDEX[name] in factors}
    if FACTOR_INDEX['db2'] in factors:
        used |= {Input.DELTA_BP, Input.DELTA_BS}
    prop = int(vehicle.par[P_PROP])
    if prop in (PROPULSION_MODELS['healey_lienard'], PROPULSION_MODELS['quadratic_thrust']) \
            or FACTOR_INDEX['eps'] in factors:
        used.add(Input.N_RPM)
    if prop == PROPULSION_MODELS['measured_thrust'] or FACTOR_INDEX['thrust'] in factors:
        used.add(Input.THRUST)
    used |= set(range(N_INPUT, vehicle.n_inputs))      # every thruster's command
    return sorted(int(i) for i in used)


def command_limits(vehicle: Vehicle) -> tuple[float, float]:
    """(fin limit rad, shaft limit rpm) of a vehicle: the full scale of 'normalized' units."""
    return float(vehicle.par[P_FIN]), float(vehicle.par[P_NMAX])


def normalize_type(text: object) -> str:
    """'pkg/msg/Type' of 'pkg/Type' or 'pkg/msg/Type' (other text unchanged)."""
    parts = str(text).strip().split('/')
    if len(parts) == 2:
        return f'{parts[0]}/msg/{parts[1]}'
    return '/'.join(parts)


# --- parsing ------------------------------------------------------------------------------------


class _Parser:
    def __init__(self, where: str) -> None:
        self.where = where

    def fail(self, text: str) -> NoReturn:
        raise InputMapError(f'{self.where}: {text}')

    def keys(self, d: dict, allowed: Sequence[str], what: str) -> None:
        extra = [k for k in d if k not in allowed]
        if extra:
            self.fail(f'{what}: unknown key(s) {", ".join(map(str, extra))}; known: '
                      f'{", ".join(allowed)}')

    def number(self, d: dict, key: str, what: str, default: float,
               positive: bool = False) -> float:
        v = d.get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                or (positive and v <= 0):
            self.fail(f'{what}: {key} = {v!r} must be a finite{" positive" if positive else ""}'
                      ' number')
        return float(v)

    def choice(self, d: dict, key: str, what: str, choices: Sequence[str],
               default: str | None = None) -> str:
        v = d.get(key, default)
        if v not in choices:
            self.fail(f'{what}: {key} = {v!r}; use one of {", ".join(choices)}')
        return str(v)

    def entry(self, name: object, d: object, body_frame: str) -> InputEntry:
        what = f'input {name!r}'
        if not isinstance(d, dict):
            self.fail(f'{what}: must be a mapping with topic and type, got {d!r}')
        topic = d.get('topic')
        if not isinstance(topic, str) or not topic.strip() or ' ' in topic.strip():
            self.fail(f'{what}: topic = {topic!r}; give the topic name, e.g. topic: odom')
        if 'type' not in d:
            self.fail(f'{what}: give its message type (one of {", ".join(TYPES)})')
        typ = normalize_type(d['type'])
        if typ not in TYPES:
            self.fail(f'{what}: type {d["type"]!r} is not read; known: {", ".join(TYPES)}')
        role = TYPES[typ]
        self.keys(d, _KEYS['odometry' if role == 'odometry' else typ], what)
        out: dict[str, Any] = {'name': str(name), 'topic': topic.strip(), 'type': typ,
                               'role': role}
        if role == 'odometry':
            out['frame'] = self.choice(d, 'frame', what, FRAMES, 'auto')
            out['fields'] = self.names(d, 'fields', what, STATE_NAMES)
        elif role == 'command':
            out['channels'] = self.channels(typ, d, what)
        else:
            out['frame'] = self.choice(d, 'frame', what, FRAMES, 'auto')
            out['mounting'] = self.mounting(d.get('mounting', {}), what, body_frame)
            out['mounting_given'] = 'mounting' in d
            out['fields'], out['options'] = self.sensor(typ, d, what)
        return InputEntry(**out)

    def names(self, d: dict, key: str, what: str, known: Sequence[str]) -> tuple[str, ...]:
        if key not in d:
            return tuple(known)
        v = d[key]
        if not isinstance(v, list) or not v or any(n not in known for n in v) \
                or len(set(v)) != len(v):
            self.fail(f'{what}: {key} = {v!r}; give a list of distinct names among '
                      f'{" ".join(known)}')
        return tuple(v)

    def channels(self, typ: str, d: dict, what: str) -> tuple[Channel, ...]:
        if typ == FLOAT64:
            return (self.channel(typ, d, what, {}),)
        chans = d.get('channels')
        if not isinstance(chans, list) or not chans:
            self.fail(f'{what}: give channels, a list of {{{", ".join(_SELECTOR[typ])}, '
                      'actuator, unit}')
        out = []
        seen = set()
        for k, c in enumerate(chans):
            cw = f'{what} channel {k + 1}'
            if not isinstance(c, dict):
                self.fail(f'{cw}: must be a mapping, got {c!r}')
            self.keys(c, _SELECTOR[typ] + _CHANNEL_KEYS, cw)
            sel = self.selector(typ, c, cw)
            key = tuple(sel.items())
            if key in seen:
                self.fail(f'{cw}: ' + ' '.join(f'{k} {v}' for k, v in key) + ' is read twice')
            seen.add(key)
            out.append(self.channel(typ, c, cw, sel))
        actuators = [ch.name for ch in out]
        dup = sorted({a for a in actuators if actuators.count(a) > 1})
        if dup:
            self.fail(f'{what}: actuator {dup[0]} is fed by two channels')
        return tuple(out)

    def selector(self, typ: str, c: dict, cw: str) -> dict[str, Any]:
        if typ == JOINT_STATE:
            joint = c.get('joint')
            if not isinstance(joint, str) or not joint:
                self.fail(f'{cw}: give the joint name, e.g. joint: rudder')
            return {'joint': joint, 'field': self.choice(c, 'field', cw, tuple(JOINT_FIELDS),
                                                         'position')}
        if typ == FLOAT64_ARRAY:
            i = c.get('index')
            if isinstance(i, bool) or not isinstance(i, int) or i < 0:
                self.fail(f'{cw}: index = {i!r} must be an integer >= 0 (the data array '
                          'position)')
            return {'index': i}
        return {'field': self.choice(c, 'field', cw, WRENCH_FIELDS)}

    def thruster_channel(self, c: dict, cw: str, sel: dict[str, Any]) -> Channel:
        """A channel feeding a thruster of the vehicle file by name (resolved by
        InputMap.for_vehicle): its command in the unit the thruster takes."""
        name = str(c['actuator'])
        unit = c.get('unit')
        if unit not in THRUSTER_UNITS:
            self.fail(f'{cw}: {name!r} is no actuator of state.Input ('
                      + ', '.join(ACTUATORS) + '), so a thruster of the vehicle file: give '
                      f'the unit of its command, one of {", ".join(THRUSTER_UNITS)} (us: PWM)')
        if 'pwm' in c:
            self.fail(f'{cw}: a thruster takes its PWM in us as it is (its curve is in us): '
                      'leave pwm out')
        scale = self.number(c, 'scale', cw, 1.0)
        if scale == 0.0:
            self.fail(f'{cw}: scale 0 would hold {name} at the offset')
        default = c.get('default')
        if default is not None:
            default = self.number(c, 'default', cw, 0.0)
        return Channel(actuator=-1, unit=str(unit), scale=scale,
                       offset=self.number(c, 'offset', cw, 0.0), default=default,
                       thruster=name, **sel)

    def channel(self, typ: str, c: dict, cw: str, sel: dict[str, Any]) -> Channel:
        name = c.get('actuator')
        if not isinstance(name, str) or not name:
            self.fail(f'{cw}: actuator = {name!r}; give one of '
                      + ', '.join(f'{a} ({ACTUATOR_TEXT[a]})' for a in ACTUATORS)
                      + ', or a thruster name of the vehicle file')
        if name not in ACTUATORS:
            return self.thruster_channel(c, cw, sel)
        index = ACTUATORS.index(name)
        units = UNITS[actuator_kind(index)]
        default_unit = (JOINT_FIELDS[sel['field']] if typ == JOINT_STATE else None)
        if typ == JOINT_STATE and default_unit not in units:
            default_unit = None
        if 'unit' not in c and default_unit is None:
            self.fail(f'{cw}: give the unit of {name} (one of {", ".join(units)}): this '
                      'message leaves it open')
        unit = c.get('unit', default_unit)
        if unit not in units:
            self.fail(f'{cw}: unit {unit!r} does not fit {name}; use one of '
                      f'{", ".join(units)}')
        pwm = c.get('pwm', {})
        if not isinstance(pwm, dict):
            self.fail(f'{cw}: pwm must be {{neutral: us, half_range: us}}, got {pwm!r}')
        self.keys(pwm, ('neutral', 'half_range'), f'{cw} pwm')
        pwm = (self.number(pwm, 'neutral', cw + ' pwm', PWM_DEFAULT[0]),
               self.number(pwm, 'half_range', cw + ' pwm', PWM_DEFAULT[1], positive=True))
        default = c.get('default')
        if default is not None:
            default = self.number(c, 'default', cw, 0.0)
        scale = self.number(c, 'scale', cw, 1.0)
        if scale == 0.0:
            self.fail(f'{cw}: scale 0 would hold {name} at the offset')
        return Channel(actuator=index, unit=str(unit), scale=scale,
                       offset=self.number(c, 'offset', cw, 0.0), pwm=pwm, default=default,
                       **sel)

    def mounting(self, m: object, what: str, body_frame: str) -> Mounting:
        if not isinstance(m, dict):
            self.fail(f'{what}: mounting must be {{lever_arm: [x, y, z], rotation: [roll, '
                      f'pitch, yaw], unit: deg}}, got {m!r}')
        self.keys(m, ('lever_arm', 'rotation', 'unit'), f'{what} mounting')
        unit = self.choice(m, 'unit', f'{what} mounting', ('deg', 'rad'), 'deg')
        arm = self.vector3(m, 'lever_arm', f'{what} mounting')
        rot = self.vector3(m, 'rotation', f'{what} mounting')
        if unit == 'deg':
            rot = np.radians(rot)
        return mounting_in_frd(arm, euler_to_rotation_matrix(*rot), body_frame)

    def vector3(self, m: dict, key: str, what: str) -> np.ndarray:
        v = m.get(key, [0.0, 0.0, 0.0])
        try:
            a = np.array(v, dtype=float)
        except (TypeError, ValueError):
            a = np.zeros(0)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            self.fail(f'{what}: {key} = {v!r} must be a list of 3 finite numbers')
        return a

    def sensor(self, typ: str, d: dict,
               what: str) -> tuple[tuple[str, ...], tuple[tuple[str, Any], ...]]:
        if typ == IMU:
            return self.names(d, 'fields', what, IMU_FIELDS), ()
        if typ == DVL:
            return (), (('reference', self.choice(d, 'reference', what, VELOCITY_REFERENCES,
                                                  'ground')),)
        if typ == PRESSURE:
            return (), (('density', self.number(d, 'density', what, 1025.0, positive=True)),
                        ('gravity', self.number(d, 'gravity', what, 9.80665, positive=True)),
                        ('surface_pressure', self.number(d, 'surface_pressure', what,
                                                         101325.0)))
        if typ == POSE:
            if 'measures' not in d:
                self.fail(f'{what}: give measures: depth or position')
            return (), (('measures', self.choice(d, 'measures', what, POSE_MEASURES)),)
        datum = d.get('datum')
        if datum is None:
            # no datum: the first fix is the origin (session/raw_messages.py navsat_ned)
            return (), (('datum', None),)
        if not isinstance(datum, dict) or set(datum) != {'latitude', 'longitude'}:
            self.fail(f'{what}: give datum: {{latitude: deg, longitude: deg}}, the world '
                      'origin the fixes are measured from')
        lat = self.number(datum, 'latitude', what + ' datum', 0.0)
        lon = self.number(datum, 'longitude', what + ' datum', 0.0)
        if abs(lat) > 90.0 or abs(lon) > 180.0:
            self.fail(f'{what}: datum ({lat}, {lon}) is not a latitude, longitude in deg')
        return (), (('datum', (lat, lon)),)


def parse_input_map(doc: object, where: object = 'input map') -> InputMap:
    """The :class:`InputMap` of a parsed YAML document (module docstring); InputMapError
    naming the first problem."""
    p = _Parser(str(where))
    if not isinstance(doc, dict):
        p.fail(f'must be a mapping with version: {VERSION} and inputs:, got {type(doc).__name__}')
    p.keys(doc, ('version', 'body_frame', 'tf_body_frame', 'inputs'), 'the map')
    if doc.get('version') != VERSION:
        p.fail(f'version = {doc.get("version")!r}: this auv_ident reads input maps of version '
               f'{VERSION} (say version: {VERSION})')
    body_frame = p.choice(doc, 'body_frame', 'the map', BODY_FRAMES, 'flu')
    inputs = doc.get('inputs')
    if not isinstance(inputs, dict) or not inputs:
        p.fail('inputs: give a mapping of input names to {topic, type, ...}')
    entries = tuple(p.entry(name, d, body_frame) for name, d in inputs.items())
    topics = [e.bag_topic for e in entries]
    dup = sorted({t for t in topics if topics.count(t) > 1})
    if dup:
        p.fail(f'topic {dup[0]} is read by two inputs')
    if sum(e.role == 'odometry' for e in entries) > 1:
        p.fail('more than one nav_msgs/msg/Odometry input: the filter fuses one nav solution')
    if not any(e.role == 'command' for e in entries):
        p.fail('no command input (JointState, Float64MultiArray, Float64 or WrenchStamped): '
               'the model needs the actuators')
    tf_body = doc.get('tf_body_frame', 'base_link')
    if not isinstance(tf_body, str) or not tf_body.strip():
        p.fail(f"tf_body_frame = {tf_body!r}: give the body's frame id in /tf_static, e.g. "
               'base_link')
    return InputMap(entries, str(where), body_frame, tf_body.strip().lstrip('/'))


def input_maps_dir() -> str:
    """config/inputs/ of the installed or source tree."""
    from auv_ident.vehicles import config_dir
    return os.path.join(config_dir(), 'inputs')


def resolve_input_map(name_or_path: object) -> str:
    """The file of an input map name (config/inputs/NAME.yaml) or path; InputMapError if
    there is none."""
    text = str(name_or_path).strip() or DEFAULT_MAP
    if os.path.sep in text or text.endswith(('.yaml', '.yml')):
        path = text
    else:
        path = os.path.join(input_maps_dir(), text + '.yaml')
    if not os.path.isfile(path):
        folder = input_maps_dir()
        known = (sorted(f[:-5] for f in os.listdir(folder) if f.endswith('.yaml'))
                 if os.path.isdir(folder) else [])
        raise InputMapError(f'input map {name_or_path!r}: no file {path} (shipped maps: '
                            f'{", ".join(known) or "none"}; or give a path)')
    return path


_CACHE: dict[tuple[str, str], InputMap] = {}


def load_input_map(name_or_path: 'str | os.PathLike[str] | InputMap' = DEFAULT_MAP) -> InputMap:
    """Read and check an input map by name or path (module docstring), once per file
    content; InputMapError naming the file and the entry."""
    if isinstance(name_or_path, InputMap):
        return name_or_path
    path = resolve_input_map(name_or_path)
    try:
        with open(path, encoding='utf-8') as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputMapError(f'{path}: cannot read the input map: {exc}') from None
    key = (os.path.abspath(path), text)
    if key not in _CACHE:
        try:
            doc = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise InputMapError(f'{path}: not YAML: {str(exc).splitlines()[0]}') from None
        _CACHE[key] = parse_input_map(doc, path)
    return _CACHE[key]
