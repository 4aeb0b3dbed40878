"""Command messages of any form into the input vector, by an input map (session/input_map.py).

:func:`read_channels` reads the channels of one command message (JointState by joint name and
field, Float64MultiArray by index, Float64, WrenchStamped by field) and converts each value
into the input vector's unit (rad, rpm, N: unit, scale, offset, PWM). :class:`CommandHolder`
holds every actuator's last value (drivers publish on change): each command message updates
the actuators it carries, and once every fed actuator has been heard the whole vector is
handed to the session at the message's stamp (its header stamp, or for a message without a
header its receive time: the bag's log time offline, the node's clock live). Actuators no
input feeds are 0 (the vehicle's model does not use them: InputMap.check_vehicle).

Reading is duck-typed (attribute access), as session/messages.py: rclpy and rosbags messages
alike. A message that cannot be read raises :class:`ConversionError` naming the culprit.
"""
from collections.abc import Callable, Iterable, Sequence
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.model.state import INPUT_NAMES, N_INPUT
from auv_ident.core.model.vehicle import Vehicle
from auv_ident.session.input_map import (
    Channel,
    command_limits,
    FLOAT64,
    FLOAT64_ARRAY,
    InputEntry,
    InputMap,
    JOINT_STATE,
    WRENCH,
)
from auv_ident.session.messages import ConversionError, RPM_TO_RAD_S


def _joint_values(msg: Any, channels: Sequence[Channel]) -> list[tuple[Channel, Any]]:
    """[(channel, raw value)] of a JointState: joints matched by name in any order."""
    try:
        names = list(msg.name)
        arrays = {f: getattr(msg, f) for f in ('position', 'velocity')}
        arrays['effort'] = getattr(msg, 'effort', ())
    except AttributeError as exc:
        raise ConversionError(f'not a sensor_msgs/JointState: {exc}') from None
    index = {}
    for i, name in enumerate(names):
        if name in index:
            raise ConversionError(f'JointState.name lists joint {name!r} twice')
        index[name] = i
    lengths = {}
    out = []
    for c in channels:
        if c.field not in lengths:
            n = len(arrays[c.field])
            if n not in (0, len(names)) or (n == 0 and c.default is None):
                raise ConversionError(f'JointState.{c.field} has {n} entries for '
                                      f'{len(names)} names (the {c.name} is read from it)')
            lengths[c.field] = n
        if c.joint not in index:
            raise ConversionError(f'JointState lacks joint {c.joint!r} (the {c.name}); '
                                  f'present: {names}')
        if lengths[c.field] == 0:
            out.append((c, None))
        else:
            out.append((c, arrays[c.field][index[c.joint]]))
    return out


def _array_values(msg: Any, channels: Sequence[Channel]) -> list[tuple[Channel, Any]]:
    try:
        data = msg.data
        n = len(data)
    except (AttributeError, TypeError) as exc:
        raise ConversionError(f'not a std_msgs/Float64MultiArray: {exc}') from None
    out = []
    for c in channels:
        if c.index >= n:
            raise ConversionError(f'Float64MultiArray.data has {n} entries; the {c.name} is '
                                  f'read from index {c.index}')
        out.append((c, data[c.index]))
    return out


def _wrench_values(msg: Any, channels: Sequence[Channel]) -> list[tuple[Channel, Any]]:
    out = []
    for c in channels:
        part, axis = c.field.split('.')
        try:
            out.append((c, getattr(getattr(msg.wrench, part), axis)))
        except AttributeError:
            raise ConversionError(f'not a geometry_msgs/WrenchStamped: no wrench.{c.field}') \
                from None
    return out


def _float_values(msg: Any, channels: Sequence[Channel]) -> list[tuple[Channel, Any]]:
    try:
        return [(channels[0], msg.data)]
    except AttributeError:
        raise ConversionError('not a std_msgs/Float64: no data') from None


_READERS: dict[str, Callable[[Any, Sequence[Channel]], list[tuple[Channel, Any]]]] = {
    JOINT_STATE: _joint_values, FLOAT64_ARRAY: _array_values, WRENCH: _wrench_values,
            FLOAT64: _float_values}


def convert(channel: Channel, raw: Any, fin_limit: float,
            shaft_limit: float) -> float | None:
    """A channel's raw message value in the input vector's unit (rad, rpm, N); None: its
    default (the field array was empty)."""
    if raw is None:
        return channel.default
    try:
        x = float(raw)
    except (TypeError, ValueError):
        raise ConversionError(f'the {channel.name} value {raw!r} is not a number') from None
    if channel.scale != 1.0 or channel.offset != 0.0:
        x = x * channel.scale + channel.offset
    if channel.thruster:        # a thruster's command in its own unit (its curve takes it)
        return x
    unit = channel.unit
    if unit == 'rad/s':
        return x / RPM_TO_RAD_S     # as session/messages.py reads a shaft speed, to the bit
    if unit == 'us':
        neutral, half = channel.pwm
        x = (x - neutral) / half
    f = channel.factor(fin_limit, shaft_limit)
    return x if f == 1.0 else x * f


def unconvert(channel: Channel, value: float, fin_limit: float, shaft_limit: float) -> float:
    """The raw message value of a channel that :func:`convert` reads as `value` (input unit):
    what a writer in the map's layout puts into the message (import --input-map)."""
    unit = channel.unit
    if channel.thruster:
        x = value
    elif unit == 'rad/s':
        x = value * RPM_TO_RAD_S
    elif unit == 'us':
        neutral, half = channel.pwm
        x = value / channel.factor(fin_limit, shaft_limit) * half + neutral
    else:
        x = value / channel.factor(fin_limit, shaft_limit)
    if channel.scale != 1.0 or channel.offset != 0.0:
        x = (x - channel.offset) / channel.scale
    return x


def read_channels(entry: InputEntry, msg: Any, fin_limit: float,
                  shaft_limit: float) -> list[tuple[int, float | None]]:
    """[(actuator index, value in the input unit)] of one command message of `entry`
    (an input_map.InputEntry with role 'command'); ConversionError naming the culprit."""
    pairs = _READERS[entry.type](msg, entry.channels)
    return [(c.actuator, convert(c, raw, fin_limit, shaft_limit)) for c, raw in pairs]


class CommandHolder:
    """The last value of every fed actuator (on-change holding; module docstring).

    fed : input-vector indices some input feeds; limits : (fin rad, shaft rpm) of the vehicle
    """

    def __init__(self, fed: Iterable[int], limits: tuple[float, float],
                 rest: ArrayLike | None = None,
                 names: Sequence[str] = INPUT_NAMES) -> None:
        self.fed = tuple(sorted(fed))
        self.fin_limit, self.shaft_limit = limits
        # the inputs before any message: 0, a thruster at its neutral command (rest)
        self.u = np.zeros(N_INPUT) if rest is None else np.array(rest, dtype=float)
        n = len(self.u)
        self.names = tuple(names)
        self.heard = np.zeros(n, dtype=bool)
        self.stamp_ns = np.zeros(n, dtype=np.int64)     # of each actuator's last value
        self._all = np.zeros(n, dtype=bool)
        self._all[list(self.fed)] = True

    @classmethod
    def of(cls, input_map: InputMap, vehicle: Vehicle) -> 'CommandHolder':
        """The holder of a vehicle's input vector (its thrusters' commands after state.Input's
        channels) fed by input_map (its thruster channels resolved to the vehicle)."""
        rest = np.zeros(vehicle.n_inputs)
        rest[N_INPUT:] = [t.neutral for t in vehicle.thrusters]
        return cls(input_map.for_vehicle(vehicle).fed(), command_limits(vehicle), rest,
                   vehicle.input_names)

    def update(self, entry: InputEntry, msg: Any, stamp_ns: int) -> np.ndarray | None:
        """Read a command message stamped stamp_ns (int ns); returns the whole u copy once
        every fed actuator has been heard, else None (what is still missing: :meth:`missing`).
        ConversionError for an unreadable message (nothing is updated then)."""
        values = read_channels(entry, msg, self.fin_limit, self.shaft_limit)
        for i, v in values:
            self.u[i] = v
            self.heard[i] = True
            self.stamp_ns[i] = stamp_ns
        if self.heard[self._all].all():
            return self.u.copy()
        return None

    def missing(self) -> list[str]:
        """Names of the fed actuators not heard yet."""
        return [self.names[i] for i in self.fed if not self.heard[i]]

    def stale(self, stamp_ns: int, limit_s: float | None) -> list[str]:
        """Names of the fed actuators whose last value is older than limit_s at stamp_ns."""
        if limit_s is None:
            return []
        limit_ns = int(math.ceil(limit_s * 1e9))
        return [self.names[i] for i in self.fed
                if self.heard[i] and stamp_ns - int(self.stamp_ns[i]) > limit_ns]
