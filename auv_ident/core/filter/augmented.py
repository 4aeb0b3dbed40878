"""The augmented EKF for streaming use (one predict + update per message) and its set-up:
what to identify and how (:class:`FilterConfig`), the initial estimate and covariance
(:func:`initial_covariance`, the one place P0 is assembled) and the covariance repair used by the
streaming identifier. The compiled per-step algebra is in ekf.py, the batch methods over a whole
record in batch.py.

Augmented state x* = [x (12 vehicle states, :mod:`state`), theta (p parameters: the
coefficients, then any water-current components the model identifies,
core/model/hydrodynamics.py)].
"""
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.errors import ConfigError, DimensionError, DivergenceError, DomainError
from auv_ident.core.filter import ekf
from auv_ident.core.model.current import ned_current
from auv_ident.core.model.hydrodynamics import Model, STATUS_TEXT
from auv_ident.core.model.sensors import DEFAULT_NOISE_STD
from auv_ident.core.model.state import (
    COEFFICIENTS,
    CURRENT_NAMES,
    N_CURRENT,
    N_STATE,
    State,
    VEHICLE,
)
from auv_ident.core.model.thruster_lag import lag_advance, lag_correct
from auv_ident.core.model.trim import trim_speed

# Per-step process-noise 1-sigma of the 12 states in the EKF, in the states' units. Small: the
# coefficients are learnt from how well the model predicts the motion, and a large state Q lets
# the filter explain the motion by state corrections instead (100x these values made the
# coefficients' 1-sigma about 5x larger on NPS AUV II). Raise it for real vehicles with
# unmodelled forces (waves, currents, tether).
DEFAULT_Q_STATE = np.array([2e-6, 2e-6, 2e-6, 2e-7, 2e-7, 2e-7,
                            1e-5, 1e-5, 1e-5, 2e-7, 2e-7, 2e-7])
# start-up 1-sigma of channels the sensor suite does not measure (AugmentedEKF.initial_state),
# in the order of state.State (u v w: m/s, p q r: rad/s, x y z: m, phi theta psi: rad)
UNMEASURED_SD0 = np.array([0.3, 0.3, 0.3, 0.05, 0.05, 0.05, 100, 100, 10, 0.2, 0.2, np.pi])
# m/s, initial 1-sigma of an identified water-current component: currents of 0.05-0.5 m/s are
# common (shared/real_data.md), so 0.5 m/s covers them without claiming to know the direction
DEFAULT_CURRENT_SD0 = 0.5
# m/s, initial 1-sigma of an identified DOWN component: vertical currents are small (mm/s to a
# few cm/s outside upwelling and internal waves), and a wide prior lets the start of the run
# trade it against the heave coefficients (Z_w 50 % off drove it to 0.2 m/s and the relative
# surge negative within 0.3 s on a 10 Hz independent bag)
DEFAULT_CURRENT_DOWN_SD0 = 0.05
# m/s, 1-sigma of the current guessed from the first measurement (AugmentedEKF.start_current):
# how far from its straight trim through the water a cruising vehicle typically starts a log
CURRENT_GUESS_SD = 0.1


@dataclass
class FilterConfig:
    """What to identify and how. Units follow the vehicle file (coefficients) and SI.

    coefficients : names (the vehicle's identify_default if empty)
    initial : initial guesses (same order), or None for truth * (1 + initial_offset)
    initial_offset : relative start offset when `initial` is None (paper's experiment: +-0.5)
    p0_rel : initial 1-sigma of each coefficient as a fraction of |initial guess|
    q_theta_rel : per-step random-walk 1-sigma of each coefficient, fraction of |initial guess|
    q_state : (12,) per-step process noise 1-sigma of the states
    noise_std : (12,) measurement noise 1-sigma (R = diag(noise_std^2))
    measured : (12,) bool, channels the sensor suite provides
    mode : 'fixed', 'paper', 'paper_q' or 'matching' (see ekf.py)
    tau : s, time constant of the forgetting factor gamma = 1 - exp(-T/tau)
    lam : the paper's lambda (2e-3)
    theta_cov0 : (p, p) initial covariance of the coefficients (symmetric positive definite, the
        coefficients' units squared), e.g. from a previous run's estimate; None for
        diag((p0_rel |initial guess|)^2)
    current_initial : (3,) m/s NED, initial guess of the identified current components (the
        model's theta holds which; the others are the model's fixed current)
    current_sd0 : m/s, initial 1-sigma of each identified horizontal current component
    current_down_sd0 : m/s, initial 1-sigma of the down component (when identified)
    current_walk : m/s/sqrt(s), random-walk intensity of the identified current: 0 (default)
        for a constant current; otherwise the current may wander by current_walk sqrt(t) over
        t seconds (per time update of h s the walk adds current_walk^2 h to its variance), i.e.
        by its prior 1-sigma within the time constant (current_sd0 / current_walk)^2
        (1e-3 m/s/sqrt(s): 0.06 m/s per hour, tidal; time constant 2.5e5 s at 0.5 m/s)

    In this config "coefficients" (initial, theta_cov0, p) are the model's coefficients only
    (model.p_coef); the current components have their own settings.
    """

    coefficients: list = field(default_factory=list)
    initial: ArrayLike | None = None
    initial_offset: float = 0.5
    p0_rel: float = 1.0
    q_theta_rel: float = 1e-5
    q_state: np.ndarray = field(default_factory=lambda: DEFAULT_Q_STATE.copy())
    noise_std: np.ndarray = field(default_factory=lambda: DEFAULT_NOISE_STD.copy())
    measured: np.ndarray = field(default_factory=lambda: np.ones(N_STATE, dtype=bool))
    mode: str = 'fixed'
    tau: float = 10.0
    lam: float = 2e-3
    r_bound: float = 4.0
    q_floor: float = 1e-4
    theta_cov0: ArrayLike | None = None
    current_initial: ArrayLike | None = None
    current_sd0: float = DEFAULT_CURRENT_SD0
    current_down_sd0: float = DEFAULT_CURRENT_DOWN_SD0
    current_walk: float = 0.0

    def validate(self, p: int) -> None:
        """ConfigError / DimensionError naming the first bad field, for a filter of p
        coefficients."""
        if self.mode not in ekf.MODES:
            raise ConfigError(f'noise adaptation mode {self.mode!r}; use one of '
                              + ', '.join(ekf.MODES))
        self._validate_state_noise()
        _positive(self, ('p0_rel', 'tau', 'lam', 'r_bound'), '')
        if not np.isfinite(self.q_theta_rel) or self.q_theta_rel < 0:
            raise ConfigError(f'q_theta_rel = {self.q_theta_rel!r} must be >= 0')
        if self.initial is not None and np.asarray(self.initial).shape != (p,):
            raise DimensionError(f'initial guesses: expected {p} values, got '
                                 f'{np.asarray(self.initial).shape}')
        if self.theta_cov0 is not None:
            check_theta_cov(self.theta_cov0, p)
        self._validate_current()

    def _validate_state_noise(self) -> None:
        """The vehicle states' process and measurement noise and the measured channels."""
        for name, arr, shape in (('q_state', self.q_state, (N_STATE,)),
                                 ('noise_std', self.noise_std, (N_STATE,)),
                                 ('measured', self.measured, (N_STATE,))):
            a = np.asarray(arr)
            if a.shape != shape:
                raise DimensionError(f'{name} must have shape {shape}, got {a.shape}')
        for name in ('q_state', 'noise_std'):
            a = np.asarray(getattr(self, name), dtype=float)
            if not np.all(np.isfinite(a)) or np.any(a < 0):
                raise ConfigError(f'{name} must be finite and non-negative (a 1-sigma), got {a}')
        m = np.asarray(self.measured, dtype=bool)
        if np.any(np.asarray(self.noise_std)[m] <= 0):
            raise ConfigError('noise_std must be positive on every measured channel')

    def _validate_current(self) -> None:
        """The water current's prior and random walk."""
        _positive(self, ('current_sd0', 'current_down_sd0'), ' m/s')
        if not np.isfinite(self.current_walk) or self.current_walk < 0:
            raise ConfigError(f'current_walk = {self.current_walk!r} m/s/sqrt(s) must be >= 0')
        if self.current_initial is not None:
            c = np.asarray(self.current_initial, dtype=float)
            if c.shape != (N_CURRENT,) or not np.all(np.isfinite(c)):
                raise ConfigError(f'current_initial must be 3 finite numbers (north, east, down '
                                  f'm/s), got {self.current_initial!r}')


def _positive(config: FilterConfig, names: Sequence[str], unit: str) -> None:
    """ConfigError unless each field `names` of `config` is a positive finite number."""
    for name in names:
        v = getattr(config, name)
        if not np.isfinite(v) or v <= 0:
            raise ConfigError(f'{name} = {v!r}{unit} must be a positive number')


def check_theta_cov(C: ArrayLike, p: int) -> np.ndarray:
    """C as a (p, p) coefficient covariance (float array, symmetrised), or ConfigError /
    DimensionError naming what is wrong (shape, non-finite, asymmetric, not positive definite)."""
    given = np.asarray(C, dtype=float)
    if given.shape != (p, p):
        raise DimensionError(f'theta_cov0 must have shape ({p}, {p}), got {given.shape}')
    if not np.all(np.isfinite(given)):
        raise ConfigError(f'theta_cov0 has non-finite entries: {given.tolist()}')
    if not np.allclose(given, given.T, rtol=0.0, atol=1e-12 * np.abs(given).max()):
        raise ConfigError(f'theta_cov0 is not symmetric: {given.tolist()}')
    sym: np.ndarray = 0.5 * (given + given.T)
    if not is_positive_definite(sym):
        raise ConfigError(f'theta_cov0 is not positive definite: {sym.tolist()}')
    return sym


def default_theta_cov(theta0: ArrayLike, p0_rel: float) -> np.ndarray:
    """diag((p0_rel |theta0|)^2) (p, p): the coefficients' initial covariance when none is given
    (FilterConfig.p0_rel)."""
    return np.diag((p0_rel * np.abs(np.asarray(theta0, dtype=float))) ** 2)


def initial_covariance(sd0: ArrayLike, theta_cov: ArrayLike) -> np.ndarray:
    """P0 of the augmented state ((12 + p) x (12 + p)): diag(sd0^2) for the vehicle states
    (sd0 (12,), their 1-sigma in the states' units), theta_cov (p, p) for the coefficients, no
    correlation between the two blocks. The one place P0 is assembled."""
    sd0 = np.asarray(sd0, dtype=float)
    theta_cov = np.asarray(theta_cov, dtype=float)
    n = N_STATE + theta_cov.shape[0]
    P = np.zeros((n, n))
    P[VEHICLE, VEHICLE] = np.diag(sd0 ** 2)
    P[COEFFICIENTS, COEFFICIENTS] = theta_cov
    return P


class AugmentedEKF:
    """The augmented EKF for streaming use (one predict+update per sample).

    Parameters
    ----------
    model : core.model.hydrodynamics.Model built with the coefficients to identify
    (model.theta_names) cfg : FilterConfig
    T : float, sample time (s)
    """

    def __init__(self, model: Model, cfg: FilterConfig, T: float) -> None:
        if not np.isfinite(T) or T <= 0:
            raise ConfigError(f'sample time T = {T!r} s must be positive')
        self.model = model
        self.cfg = cfg
        self.T = float(T)
        pc = model.p_coef
        cfg.validate(pc)
        self.names = list(model.theta_names)
        th0 = (model.theta_file[:pc] * (1.0 + cfg.initial_offset) if cfg.initial is None
               else np.asarray(cfg.initial, dtype=float).copy())
        if not np.all(np.isfinite(th0)):
            raise ConfigError(f'initial guesses must be finite, got {th0}')
        if np.any(th0 == 0):
            raise ConfigError('an initial guess of exactly 0 gives no scale for its covariance: '
                              f'{dict(zip(self.names, th0))}')
        cov_c = (default_theta_cov(th0, cfg.p0_rel) if cfg.theta_cov0 is None
                 else check_theta_cov(cfg.theta_cov0, pc))
        # the identified current components: their own prior and random walk (absolute, m/s)
        cur = [CURRENT_NAMES.index(n) for n in model.current_names]
        vc0 = (np.zeros(N_CURRENT) if cfg.current_initial is None
               else np.asarray(cfg.current_initial, dtype=float))
        self.theta0 = np.concatenate([th0, vc0[cur]])
        self.theta_cov0 = np.zeros((model.p, model.p))
        self.theta_cov0[:pc, :pc] = cov_c
        cur_sd0 = np.array([cfg.current_down_sd0 if i == 2 else cfg.current_sd0 for i in cur])
        self.theta_cov0[pc:, pc:] = np.diag(cur_sd0 ** 2)
        # the identified current's start: the prior (current_initial), or, when none is given
        # and the velocities are over ground, a guess from the first measurement (start_current)
        self.guess_current = bool(cur) and (cfg.current_initial is None
                                            and model.velocity_reference == 'ground')
        # the parameters' 1-sigma scale (the unit of repair_covariance, the guard's blow-up
        # limit): p0_rel |initial guess| for coefficients, current_sd0 for the current
        self.prior_scale = np.concatenate([cfg.p0_rel * np.abs(th0),
                                           cur_sd0])
        p = model.p
        n = N_STATE + p
        self.n = n
        # scratch reused by every step (and a lagged vehicle's delivered thrust)
        self.ws = ekf.workspace_for(n, model.compiled)
        self.R0 = np.diag(np.asarray(cfg.noise_std, dtype=float) ** 2)
        # measurement 1-sigma the start-up covariance of the measured states is taken from
        # (a caller with per-message noise, e.g. the session's message covariances, updates it)
        self.noise_std = np.asarray(cfg.noise_std, dtype=float).copy()
        # a held state (core/model/planar.py) gets no process noise and no measurement: it stays
        # where it starts, uncorrelated with the rest
        free = model.vehicle.free_states
        q = np.concatenate([np.where(free, np.asarray(cfg.q_state, float), 0.0),
                            cfg.q_theta_rel * np.abs(th0),
                            np.full(len(cur), cfg.current_walk * np.sqrt(self.T))])
        self.Q0 = np.diag(q ** 2)
        self.measured = np.asarray(cfg.measured, dtype=bool) & free
        self.mode = ekf.MODES[cfg.mode]
        self.gamma = 1.0 - np.exp(-self.T / cfg.tau)
        # Innovation gate (None: off): gate[m] is the largest NIS accepted from an update with
        # m channels; a larger one is not fused (self.gated), see update().
        self.gate: np.ndarray | None = None
        self.reset()

    # the augmented state (n,) and its covariance (n, n); None until start()
    xa: Any
    P: Any

    def reset(self) -> None:
        self.gated = False
        self.ws.lag_ok[0] = 0       # a new record: the thrust settles at its first command
        self.Q = self.Q0.copy()
        self.R = self.R0.copy()
        self.xa = None
        self.P = None
        self.steps = 0
        self.nis = np.nan
        self.dof = 0
        self.innov = np.full(N_STATE, np.nan)
        self.S_diag = np.full(N_STATE, np.nan)
        self.white = np.full(N_STATE, np.nan)

    def initial_state(self, y0: np.ndarray, rpm: float) -> tuple[np.ndarray, np.ndarray]:
        """x0 from the first measurement; unmeasured channels from a straight, level trim. A
        held state starts at 0 with the 1-sigma of an unmeasured one (positive, as the filter
        requires of every variance; it never changes, core/model/planar.py)."""
        y0 = np.asarray(y0, dtype=float)
        x0 = np.zeros(N_STATE)
        sd0 = self.noise_std.copy()
        ok = self.measured & np.isfinite(y0)
        x0[ok] = y0[ok]
        if not ok[State.U]:     # a hovering vehicle (ROV) starts at rest
            x0[State.U] = 0.0 if self.model.vehicle.hovers else trim_speed(self.model, rpm)
        sd0[~ok] = UNMEASURED_SD0[~ok]
        return x0, sd0

    def use_measurement_variances(self, r: ArrayLike) -> None:
        """Make r (12,) the measurement variances (state units squared): R itself in the
        'fixed' mode, R0 in the adaptive ones (the reference the adaptation starts from and is
        bounded by), and the start-up covariance's (noise_std). For a caller whose noise
        changes per message (the session's message covariances)."""
        if self.mode == ekf.MODES['fixed']:
            np.fill_diagonal(self.R, r)
        np.fill_diagonal(self.R0, r)
        self.noise_std = np.sqrt(r)

    def reference_std(self) -> np.ndarray:
        """(n,) 1-sigma scale of each augmented state: noise_std on measured channels, the
        start-up 1-sigma of unmeasured ones, the parameters' prior scale (p0_rel |theta0| for
        the coefficients, current_sd0 for the current). The unit in
        which :func:`repair_covariance` floors eigenvalues."""
        sd = np.asarray(self.cfg.noise_std, dtype=float).copy()
        use = ~self.measured | ~(sd > 0)
        sd[use] = UNMEASURED_SD0[use]
        th = self.prior_scale
        return np.concatenate([sd, np.where(th > 0, th, 1.0)])

    def set_prior(self, theta0: ArrayLike, theta_cov0: ArrayLike) -> None:
        """Start the coefficients (at the next start()) from theta0 (p,) with covariance
        theta_cov0 (p, p), e.g. a previous estimate; Q_theta keeps its scale."""
        th0 = np.asarray(theta0, dtype=float)
        if th0.shape != (self.model.p,) or not np.all(np.isfinite(th0)):
            raise ConfigError(f'prior coefficients must be {self.model.p} finite values, got '
                              f'{th0}')
        self.theta_cov0 = check_theta_cov(theta_cov0, self.model.p)
        self.theta0 = th0.copy()
        self.guess_current = False

    def initial_estimate(self, y0: np.ndarray, rpm: float) -> tuple[np.ndarray, np.ndarray]:
        """(xa0 (n,), P0 (n, n)): the augmented state and covariance before the first
        measurement y0 (12,) at shaft speed rpm; coefficients from the prior (theta0,
        theta_cov0)."""
        x0, sd0 = self.initial_state(y0, rpm)
        theta0, cov0 = self.theta0, self.theta_cov0
        if self.guess_current:
            guess = self.start_current(y0, rpm)
            if guess is not None:
                pc = self.model.p_coef
                theta0, cov0 = theta0.copy(), cov0.copy()
                theta0[pc:] = guess
                # the guess is as good as the trim assumption: CURRENT_GUESS_SD
                var = np.minimum(np.diag(cov0)[pc:], CURRENT_GUESS_SD ** 2)
                cov0[pc:, :] = 0.0
                cov0[:, pc:] = 0.0
                cov0[pc:, pc:] = np.diag(var)
        return np.concatenate([x0, theta0]), initial_covariance(sd0, cov0)

    def start_current(self, y0: np.ndarray, rpm: float) -> np.ndarray | None:
        """The identified current components' start guess (m/s) from the first measurement y0
        over ground at shaft speed rpm, or None (keep the prior theta0).

        The vehicle is taken to be in its straight, level trim through the water, so the
        current in the body frame is (u - u_trim(rpm), v, w [down only when identified, else
        0]), turned to NED with y0's attitude; initial_estimate gives it the 1-sigma
        CURRENT_GUESS_SD. Why: at the start the current is seen only through a few steps of the
        dynamics, while the coefficients are still far off (50 % at the default start); with
        the wide prior (current_sd0) the filter explains their error by the current (a heave
        coefficient 50 % off and an unknown current leave the relative speed as a free scale of
        the heave and pitch forces), and within a second the relative surge can reach zero,
        outside the propeller model's domain (seen on independent 10 Hz bags: the along-track
        current estimate ran from 0.2 to 0.8 m/s in 1.2 s). None when u or v is not measured,
        no trim exists at rpm, or the guess lies beyond 3 prior 1-sigma."""
        pc = self.model.p_coef
        y0 = np.asarray(y0, dtype=float)
        ok = self.measured & np.isfinite(y0)
        if not (ok[State.U] and ok[State.V]):
            return None
        try:
            u_trim = trim_speed(self.model, rpm)
        except DomainError:
            return None
        names = self.model.current_names
        w = y0[State.W] if ('current_d' in names and ok[State.W]) else 0.0
        ang = [y0[i] if ok[i] else 0.0 for i in (State.PHI, State.THETA, State.PSI)]
        vc = ned_current((y0[State.U] - u_trim, y0[State.V], w), *ang)
        guess = vc[[CURRENT_NAMES.index(n) for n in names]]
        if not np.all(np.abs(guess) <= 3.0 * self.prior_scale[pc:]):
            return None
        return guess

    def start(self, y0: np.ndarray, rpm: float) -> None:
        """Start the filter from the measurement y0 (12,) at shaft speed rpm (fused)."""
        self.xa, self.P = self.initial_estimate(y0, rpm)
        self._update(y0)

    def restart(self, y0: np.ndarray, rpm: float) -> None:
        """Restart the vehicle states from the measurement y0 (12,) at shaft speed rpm (fused),
        as start() does, keeping the coefficients' estimate and covariance (after a gap, see
        timing.py)."""
        x0, sd0 = self.initial_state(y0, rpm)
        xa, P = self.xa.copy(), self.P.copy()
        ekf.restart_states(xa, P, x0, sd0)
        self.xa, self.P = xa, P
        self.ws.lag_ok[0] = 0       # the thrust settled over the gap
        self._update(y0)

    def _check(self, st: int, what: str) -> None:
        if st == ekf.OK:
            return
        if st in STATUS_TEXT:
            raise DomainError(f'{what}: {STATUS_TEXT[st]} (estimate {self.xa})')
        raise DivergenceError(f'{what}: covariance lost positive definiteness or the estimate '
                              f'became non-finite at step {self.steps}')

    def _update(self, y: np.ndarray) -> None:
        y = np.ascontiguousarray(y, dtype=float)
        if y.shape != (N_STATE,):
            raise DimensionError(f'measurement must have {N_STATE} entries, got {y.shape}')
        xa_b = np.empty(self.n)
        P_b = np.empty((self.n, self.n))
        theta_prev = self.xa[COEFFICIENTS].copy()
        st, nis, m = ekf.update(self.xa, self.P, y, self.measured, self.R, xa_b, P_b,
                              self.innov, self.S_diag, self.white, self.ws)
        self._check(st, 'measurement update')
        self.gated = False
        if self.gate is not None and m > 0 and not nis <= self.gate[m]:
            # an outlier: keep the prior (as for a missing sample), adapt nothing
            self.nis, self.dof, self.gated = nis, m, True
            return
        ekf.adapt(self.mode, self.gamma, self.cfg.lam, self.T, self.cfg.r_bound, self.cfg.q_floor,
                theta_prev, xa_b, self.innov, self.S_diag, self.P, self.Q, self.R, self.Q0,
                self.R0)
        cm = self.model.compiled
        if cm.lagged and cm.lag_idx >= 0 and cm.theta_pos[cm.lag_idx] >= 0:
            j = int(cm.theta_pos[cm.lag_idx])     # the thrust follows the time constant's update
            lag_correct(self.ws.lag, xa_b[N_STATE + j] - theta_prev[j])
        self.xa, self.P = xa_b, P_b
        self.nis, self.dof = nis, m
        self.steps += 1

    def predict(self, u_prev: np.ndarray, T: float | None = None) -> None:
        """Time update over T (s; default the configured T) with the inputs u_prev held."""
        m = self.model
        T = self.T if T is None else float(T)
        u_prev = np.ascontiguousarray(u_prev, dtype=float)
        if u_prev.shape != (m.n_inputs,):     # the kernel reads them unchecked
            raise DimensionError(f'inputs must have {m.n_inputs} entries (state.Input, then one '
                                 f'per thruster), got {u_prev.shape}')
        xa_b = np.empty(self.n)
        P_b = np.empty((self.n, self.n))
        st = ekf.predict(self.xa, self.P, u_prev, self.Q, m.compiled, T, xa_b, P_b, self.ws)
        self._check(st, 'time update')
        if m.compiled.lagged:       # the delivered thrust at the end of the step
            lag_advance(m.compiled, self.ws.c, u_prev, self.ws.lag, self.ws.lag_ok, T)
        self.xa, self.P = xa_b, P_b

    def update(self, y: np.ndarray) -> None:
        """Measurement update with y (12,), NaN for channels missing in this sample.

        With an innovation gate set (``self.gate``) and an NIS above ``gate[m]``, nothing is
        fused: the state and covariance stay the prior, Q and R are not adapted,
        ``self.gated`` is True and ``self.nis``/``self.dof`` hold the rejected update's."""
        self._update(y)

    def step(self, u_prev: np.ndarray, y: np.ndarray, T: float | None = None) -> None:
        """Predict over T with the inputs u_prev held, then update with y."""
        self.predict(u_prev, T)
        self._update(y)

    def settings(self) -> Any:
        """The FilterSettings of this filter (its initial Q and R, adaptation, sample time)."""
        c = self.cfg
        return ekf.FilterSettings(self.measured, self.Q0, self.R0, self.mode, self.gamma, c.lam,
                                self.T, c.r_bound, c.q_floor)

    @property
    def theta(self) -> np.ndarray:
        return self.xa[COEFFICIENTS].copy()

    @property
    def theta_cov(self) -> np.ndarray:
        return self.P[COEFFICIENTS, COEFFICIENTS].copy()

    @property
    def theta_std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.P)[COEFFICIENTS])


# eigenvalue floor of repair_covariance, in units of the reference variances
COV_REPAIR_FLOOR = 1e-10


def repair_covariance(P: np.ndarray, ref_std: np.ndarray,
                      floor: float = COV_REPAIR_FLOOR) -> tuple[np.ndarray, float]:
    """Nearest usable covariance to P: symmetrise, then floor the eigenvalues.

    The eigenvalues are those of C = D^-1 sym(P) D^-1 with D = diag(ref_std) (the states'
    reference 1-sigmas, so that m/s, rad and coefficients of any scale are comparable); every
    eigenvalue below `floor` is raised to it and P = D V diag(max(lambda, floor)) V^T D is
    rebuilt (symmetric by construction). Returns (P_repaired, smallest eigenvalue of C before
    the repair). Raises DivergenceError if P has a non-finite entry (nothing to repair).
    """
    P = np.asarray(P, dtype=float)
    d = np.asarray(ref_std, dtype=float)
    if not np.all(np.isfinite(P)):
        raise DivergenceError('covariance has non-finite entries: cannot be repaired')
    with np.errstate(all='ignore'):
        C = 0.5 * (P + P.T) / np.outer(d, d)
        if not np.all(np.isfinite(C)):
            raise DivergenceError('covariance overflows its reference scale: cannot be repaired')
        try:
            lam, V = np.linalg.eigh(C)
        except np.linalg.LinAlgError as err:
            raise DivergenceError('covariance eigen-decomposition failed: cannot be '
                                  'repaired') from err
        fixed = (V * np.maximum(lam, floor)) @ V.T
        fixed = 0.5 * (fixed + fixed.T) * np.outer(d, d)
    if not np.all(np.isfinite(fixed)):
        raise DivergenceError('repaired covariance is not finite')
    return fixed, float(lam[0])


def is_positive_definite(P: np.ndarray) -> bool:
    """True if P is finite, symmetric to rounding and has a Cholesky factor."""
    if not np.all(np.isfinite(P)):
        return False
    try:
        np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        return False
    return True
