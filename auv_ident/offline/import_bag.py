"""A measured run (:mod:`auv_ident.offline.importers`) written as a bag in our topics and frames:
``python -m auv_ident import``.

Topics, as a simulated bag's (:mod:`auv_ident.offline.sim_bag`, whose message builders and
writing path this uses), one message of each per sample, the actuators first:

- ``/odom`` nav_msgs/Odometry, NED/FRD (frame ids ``odom_ned`` / ``base_link_frd``): position,
  orientation ``q(phi, theta, psi)``, body velocities. Channels the file does not measure are
  written as 0 with the variance :data:`UNMEASURED_VARIANCE` (1e6 in the state's units squared:
  a 1-sigma of 1000 m, m/s, rad or rad/s). Our readers take finite positive message variances
  as the measurement noise (``noise_source message``), so an EKF fusing such a channel gives
  it a gain of ~1e-6 of a measured one's: the channel is in effect not used, while every
  message stays readable (NaN fields are rejected as non-finite unless the identifier's
  ``measured`` list excludes them, and 0 or -1 would mean "not stated": the reader would then
  fuse the 0 at its default noise as if it were measured). The planar vehicles hold those
  states anyway. Measured channels carry the variance of :func:`white_noise_std`'s estimate,
  or 0 (not stated: the reader falls back to its noise parameter) where there is none.
  Roll rate p is not derived from phi: a differentiated angle is not a measurement, and its
  error would be correlated with phi's.
- ``/actuators`` sensor_msgs/JointState, the six joints of JOINT_NAMES: the fins' positions
  (rad, our signs: 'rudder', 'stern_planes', 'bow_planes', 'bow_plane_port',
  'bow_plane_starboard'); 'propeller' velocity = shaft speed (rad/s) and effort = the
  measured thrust (N); all other entries 0. Inputs the file lacks are 0
  (``auv_ident.measured_inputs`` lists the present ones; ``import`` names those the
  vehicle's model uses).

A multi-rate CSV log (blank cells: a sensor without a sample at that row): the odometry of a
row carries the channels sampled there, the others 0 with :data:`UNMEASURED_VARIANCE` (as an
unmeasured channel, not used); a row without any state sample writes no odometry. The inputs
hold their last value; the actuators are written from the first row where every mapped input
has had a value (odometry before it is rejected as 'no command' by the identifier). Rows with
a NaN or Inf were skipped (``auv_ident.skipped_rows`` counts them).

Stamps (header and log time alike): for files with run-relative time (HSVA, CSV ``base:
run``), ``start + t`` with ``start`` given (``--start``, ISO 8601 with a UTC offset) or
nominal: HSVA files carry no date, so they are stamped from :data:`HSVA_EPOCH`
2006-01-01T00:00:00Z (the tests were run at HSVA in 2006; the day is not known), other CSV logs
from our simulated-bag epoch 2024-01-01T00:00:00Z; ``auv_ident.stamp_epoch_nominal`` says
which. Files with ``base: unix`` times are stamped with them.

metadata.yaml custom_data: ``auv_ident.vehicle``, ``frame`` (ned), ``simulated`` (false),
``format``, ``source`` (file name), ``source_sha256``, ``column_map`` (the map used, as one
line of JSON), ``measured`` and ``measured_inputs`` (names), ``noise_std_estimate`` (12
1-sigmas, NaN unmeasured), ``channel_samples`` (``name:count`` of each measured channel),
``skipped_rows``, ``sample_time``, ``samples``, ``stamp_epoch_ns``, ``stamp_epoch``,
``stamp_epoch_nominal``, ``command``.
"""
from datetime import datetime, timezone
import json

import numpy as np

from auv_ident.core.model.state import INPUT_NAMES, N_INPUT
from auv_ident.offline.column_map import ColumnMapError, INPUT_OF
from auv_ident.offline.sim_bag import (
    ACTUATOR_TOPIC,
    command_message,
    joint_state_msg,
    ODOM_TOPIC,
    odometry_msg,
    SIM_EPOCH,
    write_message_bag,
)
from auv_ident.session.input_map import (
    command_limits,
    InputMapError,
    load_input_map,
    ODOMETRY,
    vehicle_actuators,
    WRENCH,
)
from auv_ident.session.inputs import unconvert
from auv_ident.session.messages import NOT_MEASURED_VARIANCE, NS_PER_S
from auv_ident.vehicles import load_vehicle

HSVA_EPOCH = '2006-01-01T00:00:00Z'
UNMEASURED_VARIANCE = NOT_MEASURED_VARIANCE    # session/messages.py: the channel is skipped
TOPIC_TYPES = {ODOM_TOPIC: 'nav_msgs/msg/Odometry',
               ACTUATOR_TOPIC: 'sensor_msgs/msg/JointState'}
DEFAULT_VEHICLE = {'hsva': 'kvlcc2_hsva'}


def parse_epoch(text):
    """Integer ns since 1970-01-01T00:00:00Z of an ISO 8601 time with a UTC offset
    (``2006-01-01T00:00:00Z``, ``2025-06-03T14:05:00.25+02:00``)."""
    try:
        when = datetime.fromisoformat(str(text).strip())
    except ValueError:
        raise ColumnMapError(f'--start {text!r}: not an ISO 8601 time, e.g. '
                             f'{HSVA_EPOCH}') from None
    if when.tzinfo is None:
        raise ColumnMapError(f'--start {text!r}: give the UTC offset (Z or +hh:mm): a time '
                             'without one is ambiguous')
    delta = when - datetime(1970, 1, 1, tzinfo=timezone.utc)
    ns = (delta.days * 86_400 + delta.seconds) * NS_PER_S + delta.microseconds * 1_000
    if ns < 0:
        raise ColumnMapError(f'--start {text!r}: before 1970-01-01, not a ROS time')
    return ns


def _epoch(run, start):
    """(epoch_ns, text, nominal) of a run's stamps."""
    if run.absolute:
        if start is not None:
            raise ColumnMapError(f'--start {start!r}: {run.source} has absolute (base: unix) '
                                 'times, which are its stamps')
        return 0, '1970-01-01T00:00:00Z', False
    if start is None:
        text = HSVA_EPOCH if run.fmt == 'hsva' else SIM_EPOCH
        return parse_epoch(text), text, True
    return parse_epoch(start), str(start), False


def covariances(run, present=None):
    """(pose_cov, twist_cov) 6x6 of the run's odometry: variance of the noise estimate where
    measured (0: no estimate), :data:`UNMEASURED_VARIANCE` elsewhere; present (12,) bool: the
    channels sampled at this row of a multi-rate log (default: every measured one)."""
    sampled = run.measured if present is None else present
    var = np.where(sampled, np.nan_to_num(run.noise_std) ** 2, UNMEASURED_VARIANCE)
    return np.diag(var[6:12]), np.diag(var[0:6])


def input_arrays(run):
    """u (N, 7) [delta_r .. n_rpm thrust] (rad, rpm, N), core.model.state.Input order: the thrust
    is an input, written to the propeller joint's effort by joint_state_msg. Inputs the file
    does not map are 0; a mapped one is NaN before its first value in the log."""
    u = np.zeros((len(run.t_ns), N_INPUT))
    for name, values in run.inputs.items():
        u[:, INPUT_OF[name]] = values
    return u


def _default_layout(t_ns, u, x, pose_cov, twist_cov):
    """Today's layout: [(topic, message)] of one row's command (u, or None) and odometry (x,
    or None)."""
    out = [] if u is None else [(ACTUATOR_TOPIC, joint_state_msg(t_ns, u))]
    if x is not None:
        out.append((ODOM_TOPIC, odometry_msg(t_ns, x, 'ned', pose_cov, twist_cov)))
    return out


def imported_messages(run, epoch_ns, layout=_default_layout):
    """(topic, t_ns, rosbags message) of every row, the actuators first at each stamp: the
    actuators once every mapped input has had a value (then held), the odometry at the rows
    where some measured channel has a sample (the others written as 0 with
    UNMEASURED_VARIANCE: not used). layout(t_ns, u or None, x or None, pose_cov, twist_cov)
    -> [(topic, message)] writes them (default: /actuators and /odom; :class:`MapLayout`: the
    topics and forms of an input map)."""
    u = input_arrays(run)
    present = run.present
    full = bool(present[:, run.measured].all())
    pose_cov, twist_cov = covariances(run)
    known = np.isfinite(u).all(axis=1)
    for k, tk in enumerate(run.t_ns):
        t_ns = int(epoch_ns) + int(tk)
        cmd = u[k] if known[k] else None
        if full:
            out = layout(t_ns, cmd, run.x[k], pose_cov, twist_cov)
        elif present[k].any():
            pc, tc = covariances(run, present[k])
            out = layout(t_ns, cmd, np.where(present[k], run.x[k], 0.0), pc, tc)
        else:
            out = layout(t_ns, cmd, None, None, None)
        for topic, msg in out:
            yield topic, t_ns, msg


class MapLayout:
    """The rows of a run in the topics and message forms of an input map (session/input_map.py):
    the odometry on the map's Odometry topic in its frame (ned unless the map says enu), every
    command input's message with each channel's raw value (session/inputs.py unconvert: the
    map's units, scales, offsets, PWM), on every row where the commands are known. A replay
    through the same map reads back the run (import --input-map)."""

    def __init__(self, input_map, vehicle):
        self.map = load_input_map(input_map)
        self.map.check_vehicle(load_vehicle(vehicle))
        for e in self.map.commands:
            if e.type == WRENCH:
                raise InputMapError(f'{self.map.where}: input {e.name!r}: import writes no '
                                    'geometry_msgs/WrenchStamped commands')
        self.limits = command_limits(load_vehicle(vehicle))
        odom = self.map.odometry
        self.frame = 'enu' if odom.frame == 'enu' else 'ned'

    @property
    def topic_types(self):
        """{topic: type}, the commands first."""
        out = {e.bag_topic: e.type for e in self.map.commands}
        out[self.map.odometry.bag_topic] = ODOMETRY
        return out

    def __call__(self, t_ns, u, x, pose_cov, twist_cov):
        out = [] if u is None else [(e.bag_topic, self._command(e, t_ns, u))
                                    for e in self.map.commands]
        if x is not None:
            out.append((self.map.odometry.bag_topic,
                        odometry_msg(t_ns, x, self.frame, pose_cov, twist_cov)))
        return out

    def _command(self, entry, t_ns, u):
        raw = [(c, unconvert(c, float(u[c.actuator]), *self.limits)) for c in entry.channels]
        return command_message(entry.type, t_ns, raw)


def unmapped_inputs(run, vehicle):
    """Names (core/model/state.py INPUT_NAMES) of the actuators the vehicle's model uses that
    the run does not log (written as 0)."""
    v = load_vehicle(vehicle)
    logged = {INPUT_OF[name] for name in run.inputs}
    return [INPUT_NAMES[i] for i in vehicle_actuators(v) if i not in logged]


def import_metadata(run, vehicle, epoch_ns, epoch_text, nominal, command=''):
    """metadata.yaml custom_data of an imported run (module docstring)."""
    return {
        'auv_ident.vehicle': str(vehicle), 'auv_ident.frame': 'ned',
        'auv_ident.simulated': 'false', 'auv_ident.format': run.fmt,
        'auv_ident.source': run.source.name, 'auv_ident.source_sha256': run.sha256,
        'auv_ident.column_map': json.dumps(run.column_map, separators=(',', ':')),
        'auv_ident.measured': ' '.join(run.measured_names),
        'auv_ident.measured_inputs': ' '.join(sorted(run.inputs)),
        'auv_ident.noise_std_estimate': ' '.join(repr(float(v)) for v in run.noise_std),
        'auv_ident.channel_samples': ' '.join(f'{n}:{c}' for n, c in run.samples.items()),
        'auv_ident.skipped_rows': str(len(run.skipped)),
        'auv_ident.sample_time': repr(run.sample_time),
        'auv_ident.samples': str(len(run.t_ns)),
        'auv_ident.stamp_epoch_ns': str(int(epoch_ns)), 'auv_ident.stamp_epoch': epoch_text,
        'auv_ident.stamp_epoch_nominal': 'true' if nominal else 'false',
        'auv_ident.command': command,
    }


def write_imported_bag(run, path, vehicle=None, start=None, command='', compression='zstd',
                       input_map=None):
    """Write a MeasuredRun as a rosbag2 MCAP bag directory at path (must not exist).

    vehicle : stored as auv_ident.vehicle (default for HSVA files: kvlcc2_hsva; required for
        CSV logs); start : ISO 8601 time of t = 0 (default: the nominal epoch, module
        docstring); input_map : None (our /odom and /actuators), or an input map name or path
        whose topics and message forms the bag is written in (:class:`MapLayout`; stored as
        auv_ident.input_map). Returns path.
    """
    vehicle = vehicle or DEFAULT_VEHICLE.get(run.fmt)
    if not vehicle:
        raise ColumnMapError(f'{run.source}: give the vehicle (--vehicle NAME): it is stored '
                             'in the bag for identify --bag')
    epoch_ns, epoch_text, nominal = _epoch(run, start)
    if epoch_ns + int(run.t_ns[0]) < 0:
        raise ColumnMapError(f'{run.source}: the first stamp would be before 1970-01-01 '
                             f'({run.t_ns[0] / NS_PER_S:g} s from {epoch_text})')
    meta = import_metadata(run, vehicle, epoch_ns, epoch_text, nominal, command)
    if input_map is None:
        return write_message_bag(path, TOPIC_TYPES, meta, imported_messages(run, epoch_ns),
                                 compression)
    layout = MapLayout(input_map, vehicle)
    meta['auv_ident.input_map'] = str(input_map)
    meta['auv_ident.frame'] = layout.frame
    return write_message_bag(path, layout.topic_types, meta,
                             imported_messages(run, epoch_ns, layout), compression)
