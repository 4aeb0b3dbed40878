"""The live identifier's per-message logic for an input map with raw sensors (IMU, DVL,
pressure, pose: issue #28), without ROS: :class:`RawSession`.

Each message is one step of core/filter/raw.py :class:`RawSensorFilter`, the same asynchronous
multi-rate filter that ``identify --bag BAG --input-map MAP`` runs over the bag's records
(core/identification/raw.py identify_raw; its first pass): a sensor message is a measurement
update of just the states it sees at its own header stamp (session/raw_messages.py turns it
into a NED/FRD RawMeasurement), a command is held on change (session/inputs.py CommandHolder)
and enters once every fed actuator has been heard. Messages must arrive in stamp order (a
player or a driver publishing live does so); one stamped before the filter's time is not fused
('out of order', counted), as offline.

Time: s from the first message's stamp (offline: from the earliest stamp of the bag), so a bag
played in order gives the offline pass's times exactly.

A filter fault (core DivergenceError / DomainError) restarts the filter from the start-up
configuration and is counted; the last good estimate is kept.
"""
from dataclasses import dataclass, field
import math

import numpy as np

from auv_ident.core.errors import DivergenceError, DomainError
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.filter.raw import RawMeasurement, RawSensorFilter
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import Input, N_INPUT
from auv_ident.core.model.vehicle import Vehicle
from auv_ident.session.estimate_file import estimate_document
from auv_ident.session.guard import Event, Health
from auv_ident.session.input_map import IMU, InputMap, InputMapError, load_input_map, NAVSAT
from auv_ident.session.inputs import CommandHolder
from auv_ident.session.messages import ConversionError, header_stamp_ns
from auv_ident.session.raw_messages import (
    imu_covariance,
    imu_vectors,
    is_ned,
    navsat_origin,
    raw_record,
    raw_sensor_config,
    RAW_TYPES,
)
from auv_ident.session.settings import (
    coefficient_list,
    coefficient_request,
    IdentifierSettings,
    ParameterError,
    settings_fields,
    vehicle_named,
)

CONVERGED_REL_STD = 0.05     # every coefficient's 1-sigma below this fraction of |estimate|
# What the raw-sensor filter takes of the identifier settings: frames, mountings, rates and
# units come from the input map, the noise from the filter's own configuration; any other
# setting given would be silently ignored (a frame or a current the user believes applied)
RAW_SETTINGS = ('vehicle', 'coefficients', 'input_map', 'publish_rate_hz', 'intake_period_s')


def check_raw_settings(settings: IdentifierSettings) -> None:
    """ParameterError naming the first setting set away from its default that the raw-sensor
    path does not use (the others listed in its message). Away from the default, not
    'given': the node passes every parameter, set or not."""
    unused = sorted(f.name for f in settings_fields()
                    if f.name not in RAW_SETTINGS and getattr(settings, f.name) != f.default)
    if unused:
        also = f' (also given: {", ".join(unused[1:])})' if len(unused) > 1 else ''
        raise ParameterError(unused[0], 'not used with raw sensors: the input map says the '
                                        'frames, mountings and units, the raw filter takes '
                                        'only ' + ', '.join(RAW_SETTINGS) + also)


def check_raw_vehicle(vehicle: Vehicle) -> None:
    """ParameterError naming ``vehicle`` when the raw-sensor path cannot drive it: its
    filter takes the fin vehicles' command vector (state.Input), not thruster commands."""
    if vehicle.thrusters:
        raise ParameterError('vehicle', f'{vehicle.name}: a thruster-driven vehicle '
                                        f'({len(vehicle.thrusters)} thrusters); the raw-sensor '
                                        "path reads fin vehicles' commands only for now: give "
                                        'its navigation solution (nav_msgs/Odometry) with the '
                                        'thrusters through an odometry input map (config/inputs/'
                                        'bluerov2_heavy.yaml, docs/your_data.md)')


def has_raw_sensors(settings: IdentifierSettings) -> bool:
    """True if the settings' input map has raw-sensor inputs (then the live node runs a
    RawSession); ParameterError naming input_map for a map that cannot be read."""
    try:
        return bool(load_input_map(settings.input_map).sensors)
    except InputMapError as err:
        raise ParameterError('input_map', str(err)) from None


def _health(level: str, message: str) -> Health:
    # no NIS window here: the per-sensor mean NIS is in the diagnostic values
    return Health(level, message, math.nan, (math.nan, math.nan), 0)


@dataclass
class RawCounters:
    """What the messages did: fused per kind, not fused per reason, commands taken, filter
    restarts, the last error's text."""

    fused: dict[str, int] = field(default_factory=dict)
    skipped: dict[str, int] = field(default_factory=dict)
    commands: int = 0
    rejected: int = 0
    errors: int = 0
    last_error: str = ''


class RawSession:
    """Online raw-sensor identification (module docstring). settings : IdentifierSettings whose
    input_map has raw sensors; its vehicle and coefficients are identified with the filter's
    default FilterConfig (as identify --bag with that map)."""

    def __init__(self, settings: IdentifierSettings) -> None:
        check_raw_settings(settings)
        self.settings = settings
        self.vehicle = vehicle_named(settings.vehicle)
        check_raw_vehicle(self.vehicle)
        try:
            self.input_map: InputMap = load_input_map(settings.input_map)
            for e in self.input_map.sensors:
                if e.type not in RAW_TYPES:
                    raise InputMapError(f'{self.input_map.where}: input {e.name!r} ({e.type}): '
                                        'not read live yet; raw sensors read: '
                                        + ', '.join(RAW_TYPES))
            self.holder = CommandHolder.of(self.input_map, self.vehicle)
            # NavSatFix input -> its first fix, the origin of its north/east (as offline)
            self.navsat_origins: dict[str, tuple[float, float]] = {}
        except InputMapError as err:
            raise ParameterError('input_map', str(err)) from None
        auto, coefficients = coefficient_request(self.vehicle, settings.coefficients)
        if auto:
            raise ParameterError('coefficients', '[auto, ...] is not available with raw '
                                 'sensors: name the coefficients')
        canon, _, _ = coefficient_list(self.vehicle, coefficients, None, '', None)
        self.model = Model(self.vehicle, canon)
        self.names = list(self.model.theta_names)
        self.sensors = raw_sensor_config(self.input_map)
        self._entries = {e.name: e for e in self.input_map.inputs}
        self.counters = RawCounters()
        self.time_origin_ns: int | None = None
        self.last_good: Event | None = None
        # per IMU input: (what its covariance was made of, the (6, 6) made: _imu_covariance)
        self._imu_cov: dict[str, tuple[tuple, np.ndarray | None]] = {}
        self.filter = self._new_filter()

    def _new_filter(self) -> RawSensorFilter:
        # the whitened innovations are identify_raw's; kept here they grew without end
        return RawSensorFilter(self.model, FilterConfig(), self.sensors, keep_white=False)

    def warm_up(self) -> None:
        """Load (or compile) the filter's steps now, before the first message: a throwaway
        filter takes a command and two level IMU messages (start, time update, IMU update);
        a vehicle that cannot cruise on it is left to compile at its first message."""
        f = self._new_filter()
        level = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
        u = np.zeros(N_INPUT)
        # a cruising command: the start trims to a steady surge speed, which needs thrust
        u[Input.N_RPM] = self.vehicle.cruise_rpm
        u[Input.THRUST] = self.vehicle.cruise_thrust or 0.0
        for m in (RawMeasurement('command', 0.0, u),
                  RawMeasurement('imu', 0.0, level), RawMeasurement('imu', 0.01, level)):
            try:
                f.process(m)
            except (DomainError, DivergenceError):
                return

    def input_entry(self, name: str):
        return self._entries[name]

    def reset(self) -> None:
        """Restart the filter from the start-up configuration (the last good estimate kept)."""
        self.filter = self._new_filter()
        self.time_origin_ns = None

    def _t(self, stamp_ns: int) -> float:
        if self.time_origin_ns is None:
            self.time_origin_ns = int(stamp_ns)
        return (int(stamp_ns) - self.time_origin_ns) * 1e-9

    def on_input(self, name: str, msg, receive_ns: int | None = None) -> Event:
        """One message of input `name` (stamp: its header, or receive_ns for a headerless
        command); returns an Event: 'update' (fused, good: the estimate is published),
        'command', 'rejected' (not fused: reason) or 'error' (the filter restarted)."""
        e = self._entries[name]
        try:
            stamp = header_stamp_ns(msg) if e.stamped else None
        except ConversionError as err:
            return self._reject(name, 'conversion', str(err), None)
        stamp = receive_ns if stamp is None else stamp
        if stamp is None:
            return self._reject(name, 'no stamp', 'no stamp', None)
        if e.type == IMU:
            return self._on_imu(name, e, msg, stamp)
        try:
            if e.role == 'command':
                u = self.holder.update(e, msg, stamp)
                if u is None:
                    return Event('command', f'{name}: holding', stamp, code='holding')
                m = RawMeasurement('command', self._t(stamp), u)
            else:
                if e.type == NAVSAT and e.name not in self.navsat_origins:
                    origin = navsat_origin(e, msg)
                    if origin is not None:
                        self.navsat_origins[e.name] = origin
                m = raw_record(e, msg, self._t(stamp), self.navsat_origins.get(e.name))
        except (ConversionError, InputMapError, ValueError, TypeError, AttributeError) as err:
            return self._reject(name, 'conversion', f'{type(err).__name__}: {err}', stamp)
        return self.process(name, m, stamp)

    def _on_imu(self, name: str, e, msg, stamp: int) -> Event:
        """An IMU message (most of the messages: 400 Hz) straight into
        RawSensorFilter.process_imu, its covariance converted once while it repeats; the same
        filter step and Event as raw_record then :meth:`process`."""
        t = self._t(stamp)
        try:
            ned = is_ned(e, msg)
            q, rates = imu_vectors(msg, ned)
            cov = self._imu_covariance(name, msg, ned)
        except (ConversionError, ValueError, TypeError, AttributeError) as err:
            return self._reject(name, 'conversion', f'{type(err).__name__}: {err}', stamp)
        return self.process(name, None, stamp, (t, q, rates, cov))

    def _imu_covariance(self, name: str, msg, ned: bool) -> np.ndarray | None:
        """raw_messages.imu_covariance of the message, the same array while the message's two
        covariances repeat (a driver sends fixed ones): the filter then reuses its noise
        matrix, and the conversion (~15 us) is not redone per message."""
        key = (ned, np.asarray(msg.orientation_covariance, dtype=float).tobytes(),
               np.asarray(msg.angular_velocity_covariance, dtype=float).tobytes())
        held = self._imu_cov.get(name)
        if held is not None and held[0] == key:
            return held[1]
        cov = imu_covariance(msg, ned)
        self._imu_cov[name] = (key, cov)
        return cov

    def process(self, name: str, m: RawMeasurement | None, stamp_ns: int | None,
                imu: tuple | None = None) -> Event:
        """One RawMeasurement through the filter (on_input's second half); with m None, the
        IMU message imu = (t, q, rates, covariance) through RawSensorFilter.process_imu."""
        try:
            what = (self.filter.process(m) if m is not None
                    else self.filter.process_imu(*imu, sensor=name))
        except (DivergenceError, DomainError) as err:
            self.counters.errors += 1
            self.counters.last_error = f'{name}: {err}'
            self.reset()
            return Event('error', f'{name}: {err}; filter restarted', stamp_ns, code='filter')
        if what == 'command':
            self.counters.commands += 1
            return Event('command', '', stamp_ns)
        if what != 'fused':
            self.counters.skipped[what] = self.counters.skipped.get(what, 0) + 1
            return Event('rejected', f'{name}: {what}', stamp_ns, code=what)
        kind = 'imu' if m is None else m.kind
        self.counters.fused[kind] = self.counters.fused.get(kind, 0) + 1
        est, std, cov, finite = self.filter.coefficient_block()
        if not finite:
            return self.process_fault(name, stamp_ns)
        ev = Event('update', '', stamp_ns, est, std, cov, good=True)
        self.last_good = ev
        return ev

    def process_fault(self, name: str, stamp_ns: int | None) -> Event:
        self.counters.errors += 1
        self.counters.last_error = f'{name}: the estimate became non-finite'
        self.reset()
        return Event('error', self.counters.last_error + '; filter restarted', stamp_ns,
                     code='filter')

    def _reject(self, name: str, code: str, reason: str, stamp_ns: int | None) -> Event:
        self.counters.rejected += 1
        return Event('rejected', f'{name}: {reason}', stamp_ns, code=code)

    def document(self) -> dict:
        """The estimate file's document (session/estimate_file.py) of the last good estimate
        (the start-up guesses before any), with 'input_mode' 'raw sensors', the sensor errors
        and the counts."""
        ev = self.last_good
        if ev is None:
            base = self.filter.base
            doc = estimate_document(self.vehicle.name, self.names, base.theta0,
                                    base.theta_cov0, None, 0)
        else:
            doc = estimate_document(self.vehicle.name, self.names, ev.estimate, ev.cov,
                                    ev.stamp_ns, sum(self.counters.fused.values()))
        doc['input_mode'] = 'raw sensors'
        doc['sensor_errors'] = {n: {'estimate': v, 'std': s}
                                for n, (v, s) in self.sensor_errors().items()}
        doc['fused'] = dict(self.counters.fused)
        doc['not_fused'] = dict(self.counters.skipped)
        return doc

    def sensor_errors(self) -> dict[str, tuple[float, float]]:
        """name -> (estimate, 1-sigma) of each estimated sensor error (filter's own)."""
        f = self.filter
        if f.xf is None or f.P is None:
            return {}
        return {n: (float(f.xf[i]), float(np.sqrt(max(f.P[i, i], 0.0))))
                for n, i in f.lay.errors.items()}

    def health(self) -> Health:
        """ERROR after a filter restart with no update since; WARN waiting for data; OK
        converged (every coefficient's 1-sigma < 5 % of |estimate|) or converging."""
        if self.filter.xf is None:
            if self.counters.errors:
                return _health('ERROR', 'filter restarted: ' + self.counters.last_error)
            return _health('WARN', 'waiting for data')
        ev = self.last_good
        pc = self.model.p_coef
        if ev is not None and np.all(ev.std[:pc] < CONVERGED_REL_STD * np.abs(ev.estimate[:pc])):
            return _health('OK', 'converged')
        return _health('OK', 'converging')

    def diagnostic_values(self) -> list[tuple[str, str]]:
        """The /diagnostics key-values: counts, then the last good estimate per parameter and
        the sensor errors."""
        c = self.counters
        out = [('input_mode', 'raw sensors'), ('commands', str(c.commands)),
               ('rejected', str(c.rejected)), ('errors', str(c.errors)),
               ('last_error', c.last_error), ('restarts', str(self.filter.restarts))]
        out += [(f'fused_{k}', str(n)) for k, n in sorted(c.fused.items())]
        out += [(f'not_fused_{k.replace(" ", "_")}', str(n)) for k, n in sorted(c.skipped.items())]
        f = self.filter
        for k in sorted(f.nis_sum):
            if f.dof_sum.get(k):
                out.append((f'mean_nis_per_dof_{k}', repr(f.nis_sum[k] / f.dof_sum[k])))
        ev = self.last_good
        if ev is not None:
            out.append(('last_stamp', str(ev.stamp_ns)))
            for n, v, s in zip(self.names, ev.estimate, ev.std):
                out += [(n, repr(float(v))), (f'{n}_std', repr(float(s)))]
        for n, (v, s) in self.sensor_errors().items():
            out += [(n, repr(v)), (f'{n}_std', repr(s))]
        return out
