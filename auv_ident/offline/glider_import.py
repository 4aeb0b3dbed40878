"""A Slocum glider's dives into our bags and back: ``import --format slocum`` (the raw .dbd/.ebd
logs, :mod:`auv_ident.offline.slocum`) and ``import --format npy`` (gliderflight's processed
``gliderflight_data.npy``, and the raw logs if given, for the water temperature it lacks),
and :func:`read_glider_bag`, which gives the flight model (:mod:`auv_ident.core.glider`) its
:class:`~auv_ident.core.glider.record.GliderRecord`.

One sample per CTD time (the science computer's ``sci_ctd41cp_timestamp``, ~1 s), stamped with
it (s since 1970 UTC: real stamps). Topics, at each stamp, the actuators first:

- ``/actuators`` sensor_msgs/JointState: our six joints (``JOINT_NAMES``: 'rudder' = the
  glider's fin m_fin in rad as it logs it, the others 0) and two more, which our 6-DOF readers
  ignore (they match joints by name): ``buoyancy_pump`` (position: the pumped volume
  m_ballast_pumped, m^3, positive more buoyant) and ``battery`` (position: m_battpos, m, NaN
  where not logged);
- ``/odom`` nav_msgs/Odometry, NED/FRD: z (depth, m: the pressure over the local density
  times g where the density is known, else the glider's own 10 m/bar), phi, theta, psi (rad)
  where logged; the rest 0 with the variance 1e6 (not measured), as
  :mod:`auv_ident.offline.import_bag` writes them;
- ``/glider/ctd`` std_msgs/Float64MultiArray, one dimension labelled with the fields
  :data:`CTD_FIELDS`: pressure (Pa, gauge), in-situ density (kg/m^3: the processed file's
  TEOS-10 one; from the raw logs' conductivity, temperature and pressure, EOS-80's
  (:mod:`auv_ident.core.glider.seawater`), NaN where the CTD gave no valid salinity),
  temperature (degC), conductivity (S/m);
- ``/dvl/speed_through_water`` geometry_msgs/TwistWithCovarianceStamped, only where the
  speed through water is valid (npy: the DVL's; raw logs: none), linear.x in m/s.

The raw logs' pitch is the glider's m_pitch as logged, or corrected at import with the
inclinometer's calibration (``pitch_correction``: theta = scale m_pitch + offset); the processed
file's is gliderflight's calibrated one (x 0.86, -0.004 rad for the comet).

metadata.yaml custom_data: ``auv_ident.vehicle`` (slocum_glider), ``frame`` (ned),
``simulated`` (false), ``format``, ``source`` (file names), ``source_sha256`` (of the files,
in order), ``measured`` (names), ``samples``, ``stamp_epoch_ns`` (0: the stamps are absolute),
``stamp_epoch``, ``stamp_epoch_nominal`` (false), ``noise_std_estimate`` (pressure Pa, pitch
rad: the white-noise 1-sigma of the data), ``command``, ``pitch_correction`` (scale,offset
applied to the raw m_pitch; 1.0,0.0 as logged).
"""
from dataclasses import dataclass
import hashlib
from pathlib import Path

import numpy as np
from rosbags.typesys import get_typestore, Stores

from auv_ident.bags.reader import bag_topics, read_bag
from auv_ident.core.glider.record import G, GliderRecord
from auv_ident.core.glider.seawater import ctd_density
from auv_ident.core.model.state import Input, N_INPUT, State
from auv_ident.offline.import_bag import UNMEASURED_VARIANCE
from auv_ident.offline.importers import RunFileError, white_noise_std
from auv_ident.offline.sim_bag import (
    ACTUATOR_TOPIC,
    ODOM_TOPIC,
    odometry_msg,
    write_message_bag,
)
from auv_ident.offline.slocum import read_slocum_files, STATE_NEW, STATE_SAME
from auv_ident.session.messages import actuator_joint_fields, JOINT_NAMES, NS_PER_S

CTD_TOPIC = '/glider/ctd'
DVL_TOPIC = '/dvl/speed_through_water'
TOPIC_TYPES = {ACTUATOR_TOPIC: 'sensor_msgs/msg/JointState', ODOM_TOPIC: 'nav_msgs/msg/Odometry',
               CTD_TOPIC: 'std_msgs/msg/Float64MultiArray',
               DVL_TOPIC: 'geometry_msgs/msg/TwistWithCovarianceStamped'}
CTD_FIELDS = ('pressure_Pa', 'density_kg_m3', 'temperature_degC', 'conductivity_S_m')
GLIDER_JOINTS = ('buoyancy_pump', 'battery')
VEHICLE = 'slocum_glider'
BAR = 1e5                   # Pa
CC = 1e-6                   # m^3
INCH = 0.0254               # m
SLOCUM_DEPTH_PER_BAR = 10.0     # m: the glider's own m_depth = 10 x m_pressure
# the processed file's rows (SOURCES.txt): t s, pressure bar, pitch rad, pumped cc,
# density kg/m^3, speed through water m/s
NPY_ROWS = 6

_STORE = get_typestore(Stores.ROS2_JAZZY)
_T = _STORE.types


@dataclass
class GliderLog:
    """A glider's imported record, (N,) arrays on the CTD times (NaN: not logged).

    t : s since 1970 UTC; pressure : Pa; density : kg/m^3; temperature : degC;
    conductivity : S/m; pitch, roll, heading : rad; pumped_volume : m^3;
    battery_position : m; fin : rad; speed_through_water : m/s
    fmt : 'slocum' or 'npy'; sources : file paths; sha256 : their digests
    pitch_correction : (scale, offset rad) applied to the raw logs' m_pitch ((1, 0): as
        logged; the processed file's pitch is gliderflight's calibrated one)
    """

    t: np.ndarray
    pressure: np.ndarray
    density: np.ndarray
    temperature: np.ndarray
    conductivity: np.ndarray
    pitch: np.ndarray
    roll: np.ndarray
    heading: np.ndarray
    pumped_volume: np.ndarray
    battery_position: np.ndarray
    fin: np.ndarray
    speed_through_water: np.ndarray
    fmt: str
    sources: list
    sha256: list
    pitch_correction: tuple = (1.0, 0.0)

    def depth(self):
        """(N,) m: pressure / (rho g) where the density is known, else 10 m/bar."""
        by_density = self.pressure / (np.where(np.isfinite(self.density), self.density,
                                               1.0) * G)
        return np.where(np.isfinite(self.density), by_density,
                        self.pressure / BAR * SLOCUM_DEPTH_PER_BAR)


def _nan(n):
    return np.full(n, np.nan)


def _digest(path):
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError as exc:
        raise RunFileError(f'{path}: cannot read: {exc.strerror}') from None


def read_gliderflight_npy(path):
    """The processed file (module docstring) as a :class:`GliderLog`."""
    path = Path(path)
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise RunFileError(f'{path}: not a numpy .npy file ({exc})') from None
    if data.ndim != 2 or data.shape[0] != NPY_ROWS:
        raise RunFileError(f'{path}: shape {data.shape}; gliderflight_data.npy holds '
                           f'{NPY_ROWS} rows (t, pressure bar, pitch rad, pumped cc, density, '
                           'U m/s)')
    t, p_bar, pitch, pumped_cc, density, speed = np.asarray(data, dtype=float)
    n = len(t)
    return GliderLog(t=t, pressure=p_bar * BAR, density=density, temperature=_nan(n),
                     conductivity=_nan(n), pitch=pitch, roll=_nan(n), heading=_nan(n),
                     pumped_volume=pumped_cc * CC, battery_position=_nan(n), fin=_nan(n),
                     speed_through_water=speed, fmt='npy', sources=[path],
                     sha256=[_digest(path)])


def add_ctd_from_logs(log, raw):
    """Give a processed log the water temperature and conductivity of the raw logs' CTD
    (interpolated onto its times: the same CTD stamps where both hold them; held beyond the
    raw logs' ends, seconds away), in place; their files join its sources."""
    for name in ('temperature', 'conductivity'):
        setattr(log, name, np.interp(log.t, raw.t, getattr(raw, name)))
    log.sources = list(log.sources) + list(raw.sources)
    log.sha256 = list(log.sha256) + list(raw.sha256)


def _stacked(logs, name, time_name=None):
    """(t, v) of a sensor's values over logs where it was written, new or the same again
    (time: the log's own, or time_name's value in the same cycles), sorted by time, duplicate
    times dropped (a file's first cycle repeats the last one's values). A glider logs a slow
    sensor (the pump) only when written: the repeats time its changes."""
    ts, vs = [], []
    for log in logs:
        if name not in log.names:
            continue
        new = np.isin(log.state[:, log.index(name)], (STATE_NEW, STATE_SAME))
        clock = log.time_sensor if time_name is None else time_name
        ts.append(log.values[new, log.index(clock)])
        vs.append(log.values[new, log.index(name)])
    if not ts:
        return np.zeros(0), np.zeros(0)
    t, v = np.concatenate(ts), np.concatenate(vs)
    order = np.argsort(t, kind='stable')
    t, v = t[order], v[order]
    keep = np.concatenate(([True], np.diff(t) > 0)) & np.isfinite(t) & np.isfinite(v)
    return t[keep], v[keep]


def _on(t, series, scale=1.0):
    """A sensor's values linearly interpolated onto t (held beyond its first and last
    samples: a sensor keeps its value until written again); NaN if it has none."""
    ts, vs = series
    if not len(ts):
        return _nan(len(t))
    return np.interp(t, ts, vs) * scale


def read_slocum_logs(paths, cache_dirs=None, pitch_correction=(1.0, 0.0)):
    """The raw logs (.dbd engineering, .ebd science, any number, any order) as a
    :class:`GliderLog` on the CTD times inside the engineering logs' span: the science values
    where the CTD stamped them, the engineering ones (4 s) interpolated linearly onto those
    times; the density from the CTD (EOS-80); the pitch scale m_pitch + offset
    (pitch_correction: the inclinometer's calibration, rad)."""
    paths = [Path(p) for p in paths]
    logs = read_slocum_files(paths, cache_dirs)
    t, p_bar = _stacked(logs, 'sci_water_pressure', 'sci_ctd41cp_timestamp')
    good = t > 0            # the CTD's stamp is 0 before its first sample
    t, p_bar = t[good], p_bar[good]
    if len(t) < 3:
        raise RunFileError(f'{", ".join(p.name for p in paths)}: fewer than 3 CTD samples '
                           '(sci_water_pressure with sci_ctd41cp_timestamp): give the .ebd '
                           'science logs')
    ctd = 'sci_ctd41cp_timestamp'
    # the CTD samples inside the engineering logs' time span (outside, no pitch or pump)
    span = _stacked(logs, 'm_present_time')[0]
    inside = (t >= span[0]) & (t <= span[-1]) if len(span) else np.zeros(len(t), bool)
    t, p_bar = t[inside], p_bar[inside]
    if len(t) < 3:
        raise RunFileError(f'{", ".join(p.name for p in paths)}: fewer than 3 CTD samples '
                           "inside the engineering logs' time: give the .dbd logs as well")
    temperature = _on(t, _stacked(logs, 'sci_water_temp', ctd))
    conductivity = _on(t, _stacked(logs, 'sci_water_cond', ctd))
    scale, offset = pitch_correction
    return GliderLog(
        t=t, pressure=p_bar * BAR,
        density=ctd_density(conductivity, temperature, p_bar * BAR),
        temperature=temperature, conductivity=conductivity,
        pitch=scale * _on(t, _stacked(logs, 'm_pitch')) + offset,
        roll=_on(t, _stacked(logs, 'm_roll')),
        heading=np.mod(_on(t, _stacked(logs, 'm_heading')), 2.0 * np.pi),
        pumped_volume=_on(t, _stacked(logs, 'm_ballast_pumped'), CC),
        battery_position=_on(t, _stacked(logs, 'm_battpos'), INCH),
        fin=_on(t, _stacked(logs, 'm_fin')), speed_through_water=_nan(len(t)),
        fmt='slocum', sources=paths, sha256=[lg.sha256 for lg in logs],
        pitch_correction=(float(scale), float(offset)))


def _odometry_state(log):
    """(x (N, 12), measured (12,)) of the log's depth and attitude."""
    n = len(log.t)
    x = np.zeros((n, 12))
    measured = np.zeros(12, dtype=bool)
    for i, col in ((State.Z, log.depth()), (State.PHI, log.roll), (State.THETA, log.pitch),
                   (State.PSI, log.heading)):
        if np.all(np.isfinite(col)):
            x[:, i] = col
            measured[i] = True
    return x, measured


def _joint_state(t_ns, fin, pumped, battery):
    u = np.zeros(N_INPUT)
    u[Input.DELTA_R] = fin if np.isfinite(fin) else 0.0
    position, velocity, effort = actuator_joint_fields(u)
    return _T['sensor_msgs/msg/JointState'](
        header=_header(t_ns), name=list(JOINT_NAMES) + list(GLIDER_JOINTS),
        position=np.array(position + [pumped, battery]),
        velocity=np.array(velocity + [0.0, 0.0]), effort=np.array(effort + [0.0, 0.0]))


def _header(t_ns, frame_id=''):
    sec, nanosec = divmod(int(t_ns), NS_PER_S)
    return _T['std_msgs/msg/Header'](stamp=_T['builtin_interfaces/msg/Time'](
        sec=sec, nanosec=nanosec), frame_id=frame_id)


def _ctd_msg(values):
    dim = _T['std_msgs/msg/MultiArrayDimension'](label=' '.join(CTD_FIELDS),
                                                 size=len(CTD_FIELDS), stride=len(CTD_FIELDS))
    return _T['std_msgs/msg/Float64MultiArray'](
        layout=_T['std_msgs/msg/MultiArrayLayout'](dim=[dim], data_offset=0),
        data=np.asarray(values, dtype=float))


def _dvl_msg(t_ns, speed, variance):
    cov = np.zeros(36)
    cov[0] = variance
    twist = _T['geometry_msgs/msg/Twist'](
        linear=_T['geometry_msgs/msg/Vector3'](x=float(speed), y=0.0, z=0.0),
        angular=_T['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0))
    return _T['geometry_msgs/msg/TwistWithCovarianceStamped'](
        header=_header(t_ns, 'base_link_frd'),
        twist=_T['geometry_msgs/msg/TwistWithCovariance'](twist=twist, covariance=cov))


def noise_estimates(log):
    """{name: white-noise 1-sigma} of the pressure (Pa), pitch (rad) and DVL speed (m/s)."""
    out = {'pressure': white_noise_std(log.pressure), 'pitch': white_noise_std(log.pitch)}
    speed = log.speed_through_water[np.isfinite(log.speed_through_water)]
    out['speed_through_water'] = white_noise_std(speed) if len(speed) else float('nan')
    return out


def glider_messages(log):
    """(topic, t_ns, message) of every sample, the actuators first at each stamp."""
    x, measured = _odometry_state(log)
    noise = noise_estimates(log)
    std = np.full(12, np.nan)
    std[State.Z] = noise['pressure'] / (1005.0 * G)
    std[State.THETA] = noise['pitch']
    var = np.where(measured, np.nan_to_num(std) ** 2, UNMEASURED_VARIANCE)
    pose_cov, twist_cov = np.diag(var[6:12]), np.diag(var[0:6])
    dvl_var = np.nan_to_num(noise['speed_through_water']) ** 2
    t_ns = np.round(log.t * NS_PER_S).astype(np.int64)
    for k in range(len(t_ns)):
        tk = int(t_ns[k])
        yield ACTUATOR_TOPIC, tk, _joint_state(tk, log.fin[k], log.pumped_volume[k],
                                               log.battery_position[k])
        yield ODOM_TOPIC, tk, odometry_msg(tk, x[k], 'ned', pose_cov, twist_cov)
        yield CTD_TOPIC, tk, _ctd_msg([log.pressure[k], log.density[k], log.temperature[k],
                                       log.conductivity[k]])
        if np.isfinite(log.speed_through_water[k]):
            yield DVL_TOPIC, tk, _dvl_msg(tk, log.speed_through_water[k], dvl_var)


def write_glider_bag(log, path, command='', compression='zstd'):
    """Write a :class:`GliderLog` as a rosbag2 MCAP bag directory (module docstring)."""
    if np.any(np.diff(log.t) <= 0):
        i = int(np.flatnonzero(np.diff(log.t) <= 0)[0]) + 1
        raise RunFileError(f'{log.sources[0]}: time does not increase at sample {i} '
                           f'({log.t[i - 1]!r} s, then {log.t[i]!r} s)')
    _, measured = _odometry_state(log)
    names = ['z', 'phi', 'theta', 'psi']
    meta = {
        'auv_ident.vehicle': VEHICLE, 'auv_ident.frame': 'ned', 'auv_ident.simulated': 'false',
        'auv_ident.format': log.fmt,
        'auv_ident.source': ' '.join(Path(p).name for p in log.sources),
        'auv_ident.source_sha256': ' '.join(log.sha256),
        'auv_ident.measured': ' '.join(n for n, i in zip(names, (State.Z, State.PHI,
                                                                 State.THETA, State.PSI))
                                       if measured[i]),
        'auv_ident.samples': str(len(log.t)),
        'auv_ident.stamp_epoch_ns': '0', 'auv_ident.stamp_epoch': '1970-01-01T00:00:00Z',
        'auv_ident.stamp_epoch_nominal': 'false',
        'auv_ident.noise_std_estimate': ' '.join(f'{k}={v!r}'
                                                 for k, v in noise_estimates(log).items()),
        'auv_ident.command': command,
        'auv_ident.pitch_correction': ','.join(repr(v) for v in log.pitch_correction),
    }
    topics = {k: v for k, v in TOPIC_TYPES.items()
              if k != DVL_TOPIC or np.isfinite(log.speed_through_water).any()}
    return write_message_bag(path, topics, meta, glider_messages(log), compression)


def read_glider_bag(path):
    """The :class:`~auv_ident.core.glider.record.GliderRecord` of a glider bag: pressure,
    density and temperature from ``/glider/ctd``, pitch from ``/odom``, the pumped volume from
    ``/actuators``, the DVL speed where ``/dvl/speed_through_water`` has one. The density must
    be there at every sample (the processed file's, or the raw logs' CTD's: EOS-80)."""
    ctd, pitch, pumped, dvl = {}, {}, {}, {}
    topics = [CTD_TOPIC, ODOM_TOPIC, ACTUATOR_TOPIC]
    present = bag_topics(path)
    if CTD_TOPIC not in present:
        raise RunFileError(f"{path}: no {CTD_TOPIC} topic: not a glider bag (a glider's logs "
                           'become one with import --format slocum|npy, docs/glider.md)')
    if DVL_TOPIC in present:
        topics.append(DVL_TOPIC)
    for topic, t_ns, msg in read_bag(path, topics={k: TOPIC_TYPES[k] for k in topics}):
        if topic == CTD_TOPIC:
            ctd[t_ns] = np.asarray(msg.data, dtype=float)
        elif topic == ODOM_TOPIC:
            q = msg.pose.pose.orientation
            pitch[t_ns] = np.arcsin(np.clip(2.0 * (q.w * q.y - q.z * q.x), -1.0, 1.0))
        elif topic == ACTUATOR_TOPIC:
            names = list(msg.name)
            if 'buoyancy_pump' not in names:
                raise RunFileError(f'{path}: {ACTUATOR_TOPIC} has no buoyancy_pump joint: '
                                   'not a glider bag')
            pumped[t_ns] = float(msg.position[names.index('buoyancy_pump')])
        else:
            dvl[t_ns] = float(msg.twist.twist.linear.x)
    stamps = np.array(sorted(ctd), dtype=np.int64)
    if not len(stamps) or set(stamps) != set(pitch) or set(stamps) != set(pumped):
        raise RunFileError(f'{path}: {CTD_TOPIC}, {ODOM_TOPIC} and {ACTUATOR_TOPIC} do not hold '
                           'the same stamps: not a bag written by import --format slocum/npy')
    values = np.array([ctd[s] for s in stamps])
    missing = ~np.isfinite(values[:, 1])
    if missing.any():
        raise RunFileError(f'{path}: {int(missing.sum())} of {len(stamps)} samples have no '
                           f'in-situ density in {CTD_TOPIC} (the first at '
                           f'{np.datetime64(int(stamps[missing][0] // NS_PER_S), "s")} UTC: the '
                           "CTD's conductivity or temperature missing there, or a salinity "
                           'outside 2-42); the flight model needs it at every sample')
    temperature = values[:, 2] if np.all(np.isfinite(values[:, 2])) else None
    return GliderRecord(t=stamps / NS_PER_S, pressure=values[:, 0],
                        pitch=np.array([pitch[s] for s in stamps]),
                        pumped_volume=np.array([pumped[s] for s in stamps]),
                        density=values[:, 1], temperature=temperature,
                        speed_through_water=np.array([dvl.get(s, np.nan) for s in stamps]))


def import_glider_files(fmt, files, out, command='', pitch_correction=None):
    """``import --format slocum|npy``: read, write the bag; returns the lines to print.
    pitch_correction: (scale, offset rad) of the raw logs' m_pitch, or None (as logged)."""
    if pitch_correction is not None and fmt != 'slocum':
        raise RunFileError('--pitch-correction is for --format slocum (the raw m_pitch); the '
                           "processed file's pitch is calibrated already")
    if fmt == 'npy':
        npys = [f for f in files if str(f).endswith('.npy')]
        if len(npys) != 1:
            raise RunFileError(f'--format npy reads one .npy file (gliderflight_data.npy), '
                               f'and Slocum logs for the temperature; given {len(npys)} .npy')
        log = read_gliderflight_npy(npys[0])
        logs = [f for f in files if f not in npys]
        if logs:
            add_ctd_from_logs(log, read_slocum_logs(logs))
    else:
        log = read_slocum_logs(files, pitch_correction=pitch_correction or (1.0, 0.0))
    write_glider_bag(log, out, command=command)
    noise = noise_estimates(log)
    _, measured = _odometry_state(log)
    return [f'{", ".join(Path(p).name for p in log.sources[:3])}'
            f'{" ..." if len(log.sources) > 3 else ""} ({fmt}): {len(log.t)} CTD samples over '
            f'{log.t[-1] - log.t[0]:.0f} s from {np.datetime64(int(log.t[0]), "s")} UTC',
            f'measured: depth, pitch{", roll, heading" if measured[State.PHI] else ""}; '
            f'density {"yes" if np.all(np.isfinite(log.density)) else "no"}; DVL speed '
            f'{int(np.isfinite(log.speed_through_water).sum())} samples',
            f"noise 1-sigma estimates: pressure {noise['pressure']:.3g} Pa, pitch "
            f"{noise['pitch']:.3g} rad",
            f'wrote {out}']
