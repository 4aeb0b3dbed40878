"""Identification from raw sensors: an asynchronous, multi-rate pass of the augmented EKF in which
every message is a measurement update of just the states its sensor sees, at its own stamp
(issue 28 item 2). The same class serves a batch pass over a list of records
(core/identification/raw.py ``identify_raw``) and a live caller feeding one message at a
time (:meth:`RawSensorFilter.process`); the fused-odometry path (augmented.py, stream.py, batch.py)
is not touched.

Records (:class:`RawMeasurement`), in time order; ``values`` per kind (NED/FRD, SI):

============ =========================================== ======================================
kind         values                                      covariance (None or zeros: defaults)
============ =========================================== ======================================
imu          (7,) qx qy qz qw (sensor -> NED; NaN: no    (6, 6) orientation (rad^2, world
             orientation), p q r (rad/s, sensor frame)   axes) then rates ((rad/s)^2)
dvl          (3,) m/s in the DVL frame                   (3, 3) (m/s)^2
depth        (1,) m down (of the sensor)                 (1, 1) m^2
pressure     (1,) Pa absolute                            (1, 1) Pa^2
position     (2,) x y or (3,) x y z, m NED               (2, 2) or (3, 3) m^2
command      (7,) the input vector (state.Input)         unused
============ =========================================== ======================================

``sensor`` names the mounting in :attr:`RawSensorConfig.mountings` (default: the kind's name).

Time: from one record to the next the filter runs the model's RK4 time update with the command
in force (held on change, the latest command record at or before the interval's start), in
steps of at most ``max_step`` (timing.time_step: the rules of the fused path); an interval
longer than ``max_bridge`` with no record at all restarts the vehicle states at the next IMU
orientation (coefficients and sensor errors kept), as the fused path restarts after a gap.

The filter starts at the first IMU orientation after the first command: attitude and rates from
it, velocity from the latest DVL (if within max_bridge), depth from the latest depth or
pressure, the rest from a straight trim (AugmentedEKF.initial_estimate). Until then records are
counted as 'waiting'.

Process noise: the fused filter's per-step Q (FilterConfig q_state, q_theta_rel,
current_walk), given per nominal step T, is applied as a rate: Q h / T over a step of h s, so
the same motion gets the same noise whatever the sensors' rates.

Each update records its whitened innovations per channel group (``white``) and the information
it gave each parameter (``info``: 1/P_post - 1/P_prior of its variance), from which
core/identification/raw.py corrects the error bars for coloured noise.
"""
from collections.abc import Sequence
from dataclasses import dataclass, field
import math
from typing import Any

import numpy as np

from auv_ident.core.errors import ConfigError, DataError, DivergenceError, DomainError
from auv_ident.core.filter import ekf
from auv_ident.core.filter.augmented import AugmentedEKF, FilterConfig
from auv_ident.core.filter.raw_update import (
    coefficient_block,
    imu_run,
    imu_update,
    joseph_update,
    propagate_steps,
)
from auv_ident.core.filter.timing import DEFAULT_MAX_BRIDGE, interval, time_step
from auv_ident.core.model import raw_sensors as rs
from auv_ident.core.model.hydrodynamics import Model, STATUS_TEXT
from auv_ident.core.model.sensors import DEFAULT_NOISE_STD, DEFAULT_T
from auv_ident.core.model.state import (
    ANGULAR,
    COEFFICIENTS,
    EULER,
    Input,
    LINEAR,
    N_INPUT,
    N_STATE,
    State,
)

KINDS = ('imu', 'dvl', 'depth', 'pressure', 'position', 'command')
VALUE_SIZES = {'imu': (7,), 'dvl': (3,), 'depth': (1,), 'pressure': (1,), 'position': (2, 3),
               'command': (N_INPUT,)}
# the channel groups: each has its default noise, its noise scale and its whitened innovations
# (depth and pressure share 'depth', in metres; the IMU is 'attitude' and 'gyro')
GROUPS = ('attitude', 'gyro', 'dvl', 'depth', 'position')
# default 1-sigma of each sensor error's prior and per sqrt(s) random walk (units: ERROR_UNITS)
ERROR_SD0 = {'gyro_bias_p': 0.005, 'gyro_bias_q': 0.005, 'gyro_bias_r': 0.005,
             'dvl_misalignment': math.radians(5.0), 'dvl_scale': 0.03, 'depth_offset': 0.5}
# a MEMS gyro's bias instability is ~1e-5 rad/s over minutes: a slow walk lets it follow that
ERROR_WALK = {'gyro_bias_p': 1e-5, 'gyro_bias_q': 1e-5, 'gyro_bias_r': 1e-5,
              'dvl_misalignment': 0.0, 'dvl_scale': 0.0, 'depth_offset': 0.0}
DEFAULT_ESTIMATE = ('gyro_bias_p', 'gyro_bias_q', 'gyro_bias_r', 'dvl_misalignment',
                    'dvl_scale')


@dataclass(frozen=True)
class RawMeasurement:
    """One raw message: kind (KINDS), t (s, its stamp; relative to a start is best, see
    timing.py), values and covariance as the module docstring's table, sensor the name of its
    mounting ('' : the kind's own)."""

    kind: str
    t: float
    values: np.ndarray
    covariance: np.ndarray | None = None
    sensor: str = ''

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ConfigError(f'raw measurement kind {self.kind!r}; use one of '
                              + ', '.join(KINDS))
        v = np.asarray(self.values, dtype=float).ravel()
        sizes = VALUE_SIZES[self.kind]
        if v.shape[0] not in sizes:
            raise DataError(f'{self.kind} at t = {self.t}: {v.shape[0]} values, expected '
                            + ' or '.join(map(str, sizes)))
        object.__setattr__(self, 'values', v)
        if self.covariance is not None:
            c = np.asarray(self.covariance, dtype=float)
            m = 6 if self.kind == 'imu' else v.shape[0]
            if c.size != m * m:
                raise DataError(f'{self.kind} at t = {self.t}: covariance of {c.size} entries, '
                                f'expected {m}x{m}')
            # the same array when it is already m x m: the filter reuses what it made of it
            object.__setattr__(self, 'covariance', c if c.shape == (m, m) else c.reshape(m, m))


@dataclass(frozen=True)
class RawSensorConfig:
    """The sensor suite of a raw-sensor pass.

    mountings : sensor name -> rs.Mounting (lever arm, rotation to the body); a kind without
        an entry sits at the body origin, aligned
    dvl_reference : 'ground' (bottom track) or 'water' (water track)
    estimate : the sensor errors to estimate (rs.ERROR_NAMES); the others are held at 0
    error_sd0, error_walk : per error its prior 1-sigma and random walk (unit/sqrt(s)), over
        ERROR_SD0 / ERROR_WALK
    noise_std : per channel group ('attitude' (3,) rad, 'gyro' (3,) rad/s, 'dvl' (3,) m/s,
        'depth' (1,) m, 'position' (3,) m) the 1-sigma used where a message's covariance is
        missing or zero (default: sensors.DEFAULT_NOISE_STD)
    noise_scale : per channel group a factor on its measurement covariance (>= 0; default 1):
        what identify_raw's later passes set from the earlier passes' innovations
    rho, g, p_surface : kg/m^3, m/s^2, Pa: depth = (p - p_surface) / (rho g)
    max_step, max_bridge : s, the time update's longest RK4 step and longest interval bridged
    """

    mountings: dict[str, rs.Mounting] = field(default_factory=dict)
    dvl_reference: str = 'ground'
    estimate: tuple[str, ...] = DEFAULT_ESTIMATE
    error_sd0: dict[str, float] = field(default_factory=dict)
    error_walk: dict[str, float] = field(default_factory=dict)
    noise_std: dict[str, Any] = field(default_factory=dict)
    noise_scale: dict[str, float] = field(default_factory=dict)
    rho: float = rs.SEAWATER_DENSITY
    g: float = rs.GRAVITY
    p_surface: float = rs.STANDARD_ATMOSPHERE
    max_step: float = DEFAULT_T
    max_bridge: float = DEFAULT_MAX_BRIDGE

    def __post_init__(self) -> None:
        if self.dvl_reference not in ('ground', 'water'):
            raise ConfigError(f'dvl_reference = {self.dvl_reference!r}; use ground or water')
        bad = [e for e in self.estimate if e not in rs.ERROR_NAMES]
        if bad:
            raise ConfigError(f'unknown sensor error {bad[0]!r}; use ' + ', '.join(rs.ERROR_NAMES))
        for g, f in self.noise_scale.items():
            if g not in GROUPS or not (np.isfinite(f) and f > 0):
                raise ConfigError(f'noise_scale {g!r}: {f!r}; groups {GROUPS}, factors > 0')
        for name in ('rho', 'g', 'max_step', 'max_bridge'):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f'{name} = {v!r} must be a positive number')
        if self.max_bridge < self.max_step:
            raise ConfigError('max_bridge must be at least max_step')

    def error_names(self) -> list[str]:
        """The estimated errors in rs.ERROR_NAMES order."""
        return [e for e in rs.ERROR_NAMES if e in self.estimate]

    def mount(self, name: str) -> rs.Mounting:
        return self.mountings.get(name, _ORIGIN)

    def default_std(self, group: str) -> np.ndarray:
        base = {'attitude': DEFAULT_NOISE_STD[EULER], 'gyro': DEFAULT_NOISE_STD[ANGULAR],
                'dvl': DEFAULT_NOISE_STD[LINEAR], 'depth': DEFAULT_NOISE_STD[[State.Z]],
                'position': DEFAULT_NOISE_STD[6:9]}[group]
        return np.asarray(self.noise_std.get(group, base), dtype=float)


_ORIGIN = rs.Mounting()


class RawSensorFilter:
    """The asynchronous multi-rate augmented EKF over raw sensor messages (module docstring).

    model : the Model identified (its theta_names); cfg : FilterConfig (priors, process noise;
    its noise_std and measured are not used: each message brings its own); sensors :
    RawSensorConfig; T : s, the nominal step the FilterConfig's per-step noise refers to.
    keep_white : keep every update's whitened innovations in :attr:`white` (what
    identify_raw's error bars are made of); a live filter that runs for hours passes False
    (they grew by ~390 B a message, 0.56 GB an hour at 400 Hz, and nothing read them).
    """

    def __init__(self, model: Model, cfg: FilterConfig, sensors: RawSensorConfig | None = None,
                 T: float = DEFAULT_T, errors0: np.ndarray | None = None,
                 keep_white: bool = True) -> None:
        self.model = model
        self.keep_white = keep_white
        self.sensors = sensors or RawSensorConfig()
        self.base = AugmentedEKF(model, cfg, T)
        self.err_names = self.sensors.error_names()
        self.lay = rs.Layout.of(list(model.theta_names), self.err_names)
        self.nb = self.base.n
        n = self.lay.n
        sd0 = {**ERROR_SD0, **self.sensors.error_sd0}
        walk = {**ERROR_WALK, **self.sensors.error_walk}
        self.err_sd0 = np.array([sd0[e] for e in self.err_names])
        # the sensor errors' start (errors0, in err_names order: a previous pass's estimate)
        self.err0 = (np.zeros(len(self.err_names)) if errors0 is None
                     else np.asarray(errors0, dtype=float).copy())
        if self.err0.shape != (len(self.err_names),):
            raise ConfigError(f'errors0: {len(self.err_names)} values ({self.err_names}) '
                              f'expected, got {self.err0.shape}')
        # process noise per second: the fused filter's per-step Q over its step T, the errors'
        # walks squared
        self.q_rate = np.concatenate([np.diag(self.base.Q0) / self.base.T,
                                      np.array([walk[e] ** 2 for e in self.err_names])])
        self._q_cache: dict[float, np.ndarray] = {}
        self.ws = ekf.workspace_for(self.nb, model.compiled)
        self.F12 = np.zeros((N_STATE, n))
        self.M = np.empty((N_STATE, n))
        self.O = np.empty((N_STATE, N_STATE))
        self.xb = np.empty(self.nb)
        self.P_out = np.empty((n, n))
        self.gain = np.empty(n)
        self.default_R = {g: np.diag(self.sensors.default_std(g) ** 2) for g in GROUPS}
        self.noise_scale = {g: float(self.sensors.noise_scale.get(g, 1.0)) for g in GROUPS}
        self.bias_idx = np.array([self.lay.errors.get(e, -1) for e in rs.ERROR_NAMES[:3]],
                                 dtype=np.int64)
        # what self._imu_R was made of: the covariance's bytes (None: the message gave none;
        # b'': nothing yet)
        self._imu_cov_key: bytes | None = b''
        self._imu_R = np.zeros((6, 6))
        self.xf: np.ndarray | None = None
        self.P: np.ndarray | None = None
        self.t: float | None = None         # stamp of the estimate
        self.u: np.ndarray | None = None    # command in force
        self.need_restart = False
        self.restarts = 0
        self.last: dict[str, RawMeasurement] = {}
        self.fused: dict[str, int] = {}
        self.skipped: dict[str, int] = {}
        self.nis_sum: dict[str, float] = {}
        self.dof_sum: dict[str, int] = {}
        self.white: dict[str, list[np.ndarray]] = {}
        # one IMU message's stamp, orientation, rates and whitened innovation (process_imu)
        self._one_t, self._one_q, self._one_rate = np.empty(1), np.empty((1, 4)), np.empty((1, 3))
        self._one_w = np.empty((1, 6))
        p = model.p
        self.info: dict[str, np.ndarray] = {}
        self.p = p

    # ---- the pass, one message at a time
    def process(self, m: RawMeasurement) -> str:
        """Take one message; returns what was done with it: 'fused', 'command', or the reason
        it was not fused ('waiting' before the start, 'out of order', 'non-finite', 'gap'
        restart pending). DivergenceError / DomainError when the filter fails."""
        if self.t is not None and m.t < self.t:
            return self._skip('out of order')
        if not np.all(np.isfinite(m.values)) and m.kind != 'imu':
            return self._skip('non-finite')
        if m.kind == 'command':
            if self.xf is not None:
                self._propagate(m.t)
            self.u = m.values.copy()
            self.fused['command'] = self.fused.get('command', 0) + 1
            return 'command'
        if self.xf is None or self.need_restart:
            self.last[m.kind] = m
            if m.kind != 'imu' or self.u is None or not np.all(np.isfinite(m.values[:4])):
                return self._skip('waiting')
            self._start(m)
            return 'fused'
        self._propagate(m.t)
        if self.need_restart:        # the gap just crossed: wait for an IMU orientation
            return self.process(m)
        getattr(self, '_update_' + m.kind)(m)
        self.fused[m.kind] = self.fused.get(m.kind, 0) + 1
        return 'fused'

    def process_many(self, records: Sequence[RawMeasurement]) -> None:
        """Every record in turn, as :meth:`process` one by one (the same arithmetic, the same
        counts and figures), with each run of consecutive IMU messages of one mounting and
        one covariance array while the filter is running passed to the compiled
        raw_update.imu_run in one call: a 100 Hz IMU is most of a run's messages, and its
        per-message Python overhead was most of the pass's time."""
        i, N = 0, len(records)
        while i < N:
            m = records[i]
            if m.kind != 'imu' or self.xf is None or self.need_restart:
                self.process(m)
                i += 1
                continue
            j = i + 1
            while (j < N and records[j].kind == 'imu' and records[j].sensor == m.sensor
                   and records[j].covariance is m.covariance):
                j += 1
            done = self._imu_run(records[i:j])
            if done == 0:
                # the first one is Python's (out of order, non-finite, a gap)
                self.process(m)
                done = 1
            i += done

    def process_imu(self, t: float, q: Sequence[float], rates: Sequence[float],
                    covariance: np.ndarray | None = None, sensor: str = '') -> str:
        """One IMU message (t s, q the orientation x y z w, rates p q r rad/s, covariance and
        sensor as RawMeasurement's) taken as :meth:`process` takes
        ``RawMeasurement('imu', t, [*q, *rates], covariance, sensor)``: the same arithmetic,
        counts and figures; while the filter runs, through the compiled raw_update.imu_run
        without building the record (the live node's 400 Hz stream: its Python per message
        was most of the node's CPU). Returns what process returns."""
        if self.xf is not None and not self.need_restart:
            self._one_t[0] = t
            self._one_q[0] = q
            self._one_rate[0] = rates
            if self._imu_compiled(sensor, covariance, self._one_t, self._one_q, self._one_rate,
                                  self._one_w):
                return 'fused'
        # the start, a gap, a stamp before the estimate's or a non-finite value: Python's
        return self.process(RawMeasurement('imu', t, np.array([*q, *rates], dtype=float),
                                           covariance, sensor))

    def coefficient_block(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
        """(estimate (p,), 1-sigma (p,), covariance (p, p), all finite) of the coefficients,
        new arrays (raw_update.coefficient_block); the filter must have started."""
        assert self.xf is not None and self.P is not None
        return coefficient_block(self.xf, self.P, COEFFICIENTS.start, self.p)

    def _imu_run(self, run: Sequence[RawMeasurement]) -> int:
        """raw_update.imu_run over IMU messages of one mounting and covariance; the number
        done (the rest: process_many goes on with them)."""
        m0 = run[0]
        K = len(run)
        ts = np.fromiter((m.t for m in run), float, K)
        V = np.stack([m.values for m in run])
        return self._imu_compiled(m0.sensor, m0.covariance, ts, np.ascontiguousarray(V[:, :4]),
                                  np.ascontiguousarray(V[:, 4:]), np.empty((K, 6)))

    def _imu_compiled(self, sensor: str, covariance: np.ndarray | None, ts: np.ndarray,
                      qs: np.ndarray, rates: np.ndarray, W: np.ndarray) -> int:
        """raw_update.imu_run over K IMU messages of one mounting and covariance (ts (K,),
        qs (K, 4), rates (K, 3); W (K, 6) gets their whitened innovations); the number done."""
        assert self.xf is not None and self.P is not None and self.t is not None
        mount = self.sensors.mount(sensor or 'imu')
        self._imu_noise_of(covariance)
        info = self.info.get('attitude+gyro')
        info = np.zeros(self.p) if info is None else info.copy()
        nis = np.array([self.nis_sum.get('imu', 0.0)])
        done, st, t = imu_run(self.xf, self.P, self.u, self.model.compiled, self.t, ts, qs,
                              rates, mount.rotation, self._imu_R, self.bias_idx, self.q_rate,
                              self.sensors.max_step, self.sensors.max_bridge, self.xb,
                              self.F12, self.M, self.O, self.P_out, self.ws, W,
                              self.gain, info, nis)
        self.t = t
        if st != ekf.OK:
            if st == -1:
                raise DivergenceError(f'imu update at t = {self.t} s: the estimate or its '
                                      'covariance became unusable')
            self._check(st, 'time update')
        if done:
            self.info['attitude+gyro'] = info
            self.nis_sum['imu'] = float(nis[0])
            self.dof_sum['imu'] = self.dof_sum.get('imu', 0) + 6 * done
            self.fused['imu'] = self.fused.get('imu', 0) + done
            if self.keep_white:
                self.white.setdefault('attitude', []).extend(W[:done, :3].copy())
                self.white.setdefault('gyro', []).extend(W[:done, 3:].copy())
        return int(done)

    def _skip(self, reason: str) -> str:
        self.skipped[reason] = self.skipped.get(reason, 0) + 1
        return reason

    # ---- start and restart
    def _start(self, imu: RawMeasurement) -> None:
        """Start (or restart after a gap) at an IMU orientation: the fused filter's initial
        estimate from a 12-channel pseudo measurement of what the latest messages say."""
        mount = self.sensors.mount(imu.sensor or 'imu')
        R_body = rs.rotation_of_quaternion(imu.values[:4]) @ mount.rotation.T
        y0 = np.full(N_STATE, np.nan)
        y0[EULER] = rs.euler_of_rotation(R_body)
        if np.all(np.isfinite(imu.values[4:])):
            y0[ANGULAR] = mount.rotation @ imu.values[4:]
        d = self.last.get('dvl')
        if d is not None and imu.t - d.t <= self.sensors.max_bridge:
            dm = self.sensors.mount(d.sensor or 'dvl')
            y0[LINEAR] = dm.rotation @ d.values
        for kind in ('depth', 'pressure'):
            z = self.last.get(kind)
            if z is not None:
                y0[State.Z] = (z.values[0] if kind == 'depth' else
                               (z.values[0] - self.sensors.p_surface)
                               / (self.sensors.rho * self.sensors.g))
        std = np.concatenate([self.sensors.default_std('dvl'), self.sensors.default_std('gyro'),
                              self.sensors.default_std('position'),
                              self.sensors.default_std('attitude')])
        self.base.noise_std = std
        rpm = float(self.u[Input.N_RPM]) if self.u is not None else 0.0
        xa0, P0 = self.base.initial_estimate(y0, rpm)
        n = self.lay.n
        if self.xf is None:
            self.xf = np.concatenate([xa0, self.err0])
            self.P = np.zeros((n, n))
            self.P[:self.nb, :self.nb] = P0
            self.P[self.nb:, self.nb:] = np.diag(self.err_sd0 ** 2)
        else:
            assert self.P is not None
            x0 = xa0[:N_STATE].copy()
            sd0 = np.sqrt(np.diag(P0)[:N_STATE])
            ekf.restart_states(self.xf, self.P, x0, sd0)
            self.restarts += 1
        self.need_restart = False
        self.t = imu.t
        self._update_imu(imu)
        self.fused['imu'] = self.fused.get('imu', 0) + 1

    # ---- time update
    def _q(self, h: float) -> np.ndarray:
        Q = self._q_cache.get(h)
        if Q is None:
            Q = np.diag(self.q_rate * h)
            if len(self._q_cache) < 64:
                self._q_cache[h] = Q
        return Q

    def _propagate(self, t: float) -> None:
        """The time update from the estimate's stamp to t with the command in force."""
        assert self.t is not None and self.xf is not None and self.P is not None
        dt = interval(self.t, t)
        if dt <= 0.0:
            return
        steps, h = time_step(dt, self.sensors.max_step, self.sensors.max_bridge)
        self.t = t
        if steps == 0:
            self.need_restart = True
            return
        assert self.u is not None
        st = propagate_steps(self.xf, self.P, self.u, self.model.compiled, h, steps, self._q(h),
                             self.xb, self.F12, self.M, self.O, self.P_out, self.ws)
        self._check(st, 'time update')

    def _check(self, st: int, what: str) -> None:
        if st == ekf.OK:
            return
        if st in STATUS_TEXT:
            raise DomainError(f'{what} at t = {self.t} s: {STATUS_TEXT[st]}')
        raise DivergenceError(f'{what} at t = {self.t} s: the estimate became non-finite')

    # ---- measurement updates
    def _fuse(self, kind: str, groups: tuple[tuple[str, int], ...], nu: np.ndarray,
              H: np.ndarray, Rm: np.ndarray) -> None:
        """Joint update with innovation nu (m,), Jacobian H (m, n), noise Rm (m, m) (Joseph
        form, raw_update.joseph_update); records the whitened innovation by channel group
        (groups: (name, channels) in order) and the information per parameter under the
        groups' joined name."""
        assert self.xf is not None and self.P is not None
        m = nu.shape[0]
        w = np.empty(m)
        st, nis = joseph_update(self.xf, self.P, np.ascontiguousarray(nu, dtype=float),
                                np.ascontiguousarray(H, dtype=float),
                                np.ascontiguousarray(Rm, dtype=float), self.P_out, w,
                                self.gain)
        self._after_update(kind, groups, st, nis, w)

    def _after_update(self, kind: str, groups: tuple[tuple[str, int], ...], st: int,
                      nis: float, w: np.ndarray) -> None:
        """After a compiled update: its check, the heading wrapped, the bookkeeping."""
        assert self.xf is not None
        if st != 0:
            raise DivergenceError(f'{kind} update at t = {self.t} s: the estimate or its '
                                  'covariance became unusable')
        m = w.shape[0]
        self.xf[State.PSI] = ekf.wrap(self.xf[State.PSI])
        self.P, self.P_out = self.P_out, self.P
        c = COEFFICIENTS.start
        info_group = groups[0][0] if len(groups) == 1 else '+'.join(g for g, _ in groups)
        self.info[info_group] = self.info.get(info_group, 0.0) + self.gain[c:c + self.p]
        if self.keep_white:
            i = 0
            for g, k in groups:
                self.white.setdefault(g, []).append(w[i:i + k])
                i += k
        self.nis_sum[kind] = self.nis_sum.get(kind, 0.0) + nis
        self.dof_sum[kind] = self.dof_sum.get(kind, 0) + m

    def _noise(self, cov: np.ndarray | None, group: str) -> np.ndarray:
        """The message's covariance, or the default 1-sigma's where it gives none (zero or
        non-finite diagonal)."""
        R0 = self.default_R[group]
        f = self.noise_scale[group]
        if cov is None:
            return f * R0
        m = R0.shape[0]
        c = cov[:m, :m]
        if not (np.isfinite(c).all() and (np.diagonal(c) > 0).all()):
            return f * R0
        return f * c

    def _update_imu(self, m: RawMeasurement) -> None:
        """Attitude and rates in one update (either may be missing: NaN)."""
        assert self.xf is not None
        mount = self.sensors.mount(m.sensor or 'imu')
        cov = m.covariance
        if np.isfinite(m.values).all():
            self._update_imu_compiled(m, mount)
            return
        parts = []
        if np.all(np.isfinite(m.values[:4])):
            nu, H = rs.attitude_innovation(self.xf, m.values[:4], mount, self.lay.n)
            parts.append(('attitude', nu, H,
                          self._noise(None if cov is None else cov[:3, :3], 'attitude')))
        if np.all(np.isfinite(m.values[4:])):
            h, H = rs.gyro(self.xf, mount, self.lay)
            parts.append(('gyro', m.values[4:] - h, H,
                          self._noise(None if cov is None else cov[3:, 3:], 'gyro')))
        if not parts:
            return
        if len(parts) == 1:
            g, nu, H, Rm = parts[0]
            self._fuse('imu', ((g, 3),), nu, H, Rm)
            return
        Rm = np.zeros((6, 6))
        Rm[:3, :3] = parts[0][3]
        Rm[3:, 3:] = parts[1][3]
        if cov is not None and np.all(np.isfinite(cov)) and np.all(np.diag(cov) > 0):
            f = math.sqrt(self.noise_scale['attitude'] * self.noise_scale['gyro'])
            Rm[:3, 3:] = f * cov[:3, 3:]
            Rm[3:, :3] = f * cov[3:, :3]
        self._fuse('imu', (('attitude', 3), ('gyro', 3)),
                   np.concatenate([parts[0][1], parts[1][1]]),
                   np.vstack([parts[0][2], parts[1][2]]), Rm)

    def _imu_noise(self, cov: np.ndarray | None) -> np.ndarray:
        """(6, 6) the IMU message's noise (attitude then rates) with the groups' scales."""
        Rm = np.zeros((6, 6))
        Rm[:3, :3] = self._noise(None if cov is None else cov[:3, :3], 'attitude')
        Rm[3:, 3:] = self._noise(None if cov is None else cov[3:, 3:], 'gyro')
        if cov is not None and np.all(np.isfinite(cov)) and np.all(np.diag(cov) > 0):
            f = math.sqrt(self.noise_scale['attitude'] * self.noise_scale['gyro'])
            Rm[:3, 3:] = f * cov[:3, 3:]
            Rm[3:, :3] = f * cov[3:, :3]
        return Rm

    def _imu_noise_of(self, cov: np.ndarray | None) -> None:
        """Set self._imu_R to the IMU noise of ``cov``, reused while consecutive messages
        carry the same covariance values: the live reader builds an array per message, and
        the checks and the matrix cost more than the compiled update (tools/node_cost.py)."""
        key = None if cov is None else cov.tobytes()
        if key != self._imu_cov_key:
            self._imu_R = self._imu_noise(cov)
            self._imu_cov_key = key

    def _update_imu_compiled(self, m: RawMeasurement, mount: rs.Mounting) -> None:
        """Attitude and rates through raw_update.imu_update, with the noise matrix of
        :meth:`_imu_noise_of`."""
        assert self.xf is not None and self.P is not None
        self._imu_noise_of(m.covariance)
        w = np.empty(6)
        st, nis = imu_update(self.xf, self.P, m.values[:4], m.values[4:], mount.rotation,
                             self._imu_R, self.bias_idx, self.P_out, w, self.gain)
        self._after_update('imu', (('attitude', 3), ('gyro', 3)), st, nis, w)

    def _update_dvl(self, m: RawMeasurement) -> None:
        assert self.xf is not None
        h, H = rs.dvl(self.xf, self.sensors.mount(m.sensor or 'dvl'), self.lay,
                      self.sensors.dvl_reference, self.model.velocity_reference,
                      self.model.current)
        self._fuse('dvl', (('dvl', 3),), m.values - h, H, self._noise(m.covariance, 'dvl'))

    def _update_depth(self, m: RawMeasurement) -> None:
        assert self.xf is not None
        h, H = rs.depth(self.xf, self.sensors.mount(m.sensor or 'depth'), self.lay)
        self._fuse('depth', (('depth', 1),), m.values - h, H, self._noise(m.covariance, 'depth'))

    def _update_pressure(self, m: RawMeasurement) -> None:
        assert self.xf is not None
        s = self.sensors
        h, H = rs.pressure(self.xf, s.mount(m.sensor or 'pressure'), self.lay, s.rho, s.g,
                           s.p_surface)
        scale = s.rho * s.g
        # in metres, so that the depth and pressure innovations share one channel group
        Rm = self._noise(None if m.covariance is None else m.covariance / scale ** 2, 'depth')
        self._fuse('pressure', (('depth', 1),), (m.values - h) / scale, H / scale, Rm)

    def _update_position(self, m: RawMeasurement) -> None:
        assert self.xf is not None
        k = m.values.shape[0]
        h, H = rs.position(self.xf, self.sensors.mount(m.sensor or 'position'), self.lay, k)
        Rm = (self._noise(m.covariance, 'position') if m.covariance is not None else
              self.noise_scale['position'] * self.default_R['position'])[:k, :k]
        self._fuse('position', (('position', k),), m.values - h, H, Rm)
