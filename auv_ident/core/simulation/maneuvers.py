"""Manoeuvres: commanded inputs u_cmd(t) = [delta_r delta_s delta_b delta_bp delta_bs n_rpm
thrust].

Fins in rad, shaft speed in rpm, thrust in N (constant). All are open-loop functions of time,
built once and evaluated on the sample grid, so a run is reproducible from (name, duration, T,
seed, rpm).

- `zigzag`: the paper's style (Section 4): rudder and stern planes switch between +-amplitudes
  that change from one half-period to the next (variable amplitudes inside +-20 deg); rudder
  period 40 s, stern planes 24 s; constant shaft speed.
- `steps`: step inputs on rudder and stern planes, held for tens of seconds (the paper's
  validation manoeuvre, Figs. 4-5).
- `prbs`: multi-level pseudo-random steps on rudder, stern planes and both bow planes (seeded),
  rate-limited, for richer excitation.
- `roll`: rudder square wave at the roll natural period, plus stern planes.
- `ident` (the identification default): the paper's style made richer. Rudder zig-zag at
  +-20 deg with seeded half-periods of 20-40 s (long holds build the sway speed and yaw rate that
  carry K_v and Y_v), stern planes and both bow planes stepping between seeded amplitudes of
  10, 15 and 20 deg (either sign) every 5-6 s (heave/pitch excitation for Z_w, Z_q, Z_ds, M_ds).
  All fins rate-limited to 10 deg/s.
- a CSV file path: columns t, delta_r, delta_s, delta_b, delta_bp, delta_bs, n_rpm and optionally
  thrust (header row), zero-order hold between rows.

A hovering thruster vehicle (ROV: `Vehicle.hovers`) is flown as a pilot flies it in a tank
(:func:`thruster_commands`): stick inputs in surge, sway, heave and yaw (-1..1), mixed into
each thruster's command the way ArduSub's manual mode does (a fixed linear mix in command units,
PWM_i = 1500 + 400 sum_k F_ik s_k, saturated), and sent on change:

- `surge`, `sway`, `heave`, `yaw`: that stick alone: steps of seeded amplitude (held 4-9 s, a
  rest of 3-6 s after each, either sign) for about 100 s, then a sweep (a chirp 0.05 -> 0.5 Hz
  over 60 s) and a rest;
- `steps` (the validation manoeuvre of `report`): steps of each stick in turn, 50 s each,
  no sweeps, repeated;
- `tank` (and `ident` for such a vehicle): a tank session, each of the four above in turn,
  then combined steps of two sticks at once (surge with yaw or sway, sway with yaw, heave with
  yaw), seeded;
  its length is the run's (10 minutes in the issue's test).

The sticks move in steps of STICK_STEP (a pilot's joystick resolution), so a command changes
only when a stick does.
"""
import csv
import os
from typing import TYPE_CHECKING

import numpy as np

from auv_ident.core.errors import ConfigError
from auv_ident.core.model.state import FINS, Input, N_INPUT

if TYPE_CHECKING:
    from auv_ident.core.model.vehicle import Vehicle

DEG = np.pi / 180.0
MANEUVERS = ('ident', 'zigzag', 'steps', 'prbs', 'roll')
THRUSTER_MANEUVERS = ('tank', 'surge', 'sway', 'heave', 'yaw', 'steps')
STICKS = {'surge': 0, 'sway': 1, 'heave': 2, 'yaw': 5}     # stick -> equation X Y Z K M N
# stick amplitudes a pilot uses in a tank (fraction of full stick): up to about 0.5 m/s in
# surge and 0.4 m/s in sway. Not faster: the BlueROV2 Heavy's added-mass (Munk) moments
# (a3 - a1) u w and (a2 - a3) v w grow with speed against a roll and pitch restoring of only
# BG = 1 cm, and at 0.7 m/s its model pitches and rolls by 40 deg and more (checked). Yaw far
# less: full yaw stick spins it at ~3 rad/s
STICK_LEVELS = {'surge': (0.15, 0.25, 0.35, 0.5), 'sway': (0.15, 0.25, 0.35, 0.45),
                'heave': (0.2, 0.35, 0.5, 0.7), 'yaw': (0.08, 0.12, 0.18, 0.25)}
STICK_STEP = 0.01           # joystick resolution (fraction of full stick)
SWEEP = (0.05, 0.5, 60.0)   # chirp: from Hz, to Hz, over s
FIN_RATE = 10.0 * DEG   # rad/s: rate limit of the fin actuators for prbs


def _square(t: np.ndarray, period: float, amplitudes: np.ndarray) -> np.ndarray:
    """Square wave whose k-th half-period has amplitude amplitudes[k % len] (sign alternates)."""
    k = np.floor(t / (period / 2.0)).astype(int)
    amp = np.asarray(amplitudes)[k % len(amplitudes)]
    return np.where(k % 2 == 0, amp, -amp)


def _rate_limit(sig: np.ndarray, dt: float, rate: float) -> np.ndarray:
    out = np.empty_like(sig)
    out[0] = sig[0]
    step = rate * dt
    for i in range(1, len(sig)):
        out[i] = out[i - 1] + np.clip(sig[i] - out[i - 1], -step, step)
    return out


def commands(name: str, t: np.ndarray, rpm: float = 500.0, seed: int = 0,
             fin_limit: float = 20.0 * DEG, thrust: float = 0.0) -> np.ndarray:
    """Commanded inputs on the time grid t (s): array (len(t), 7); the thrust input (N) is
    constant (a measured_thrust vehicle's cruise_thrust, 0 for the others)."""
    t = np.asarray(t, dtype=float)
    u = np.zeros((len(t), N_INPUT))
    u[:, Input.N_RPM] = rpm
    u[:, Input.THRUST] = thrust
    if name == 'zigzag':
        u[:, Input.DELTA_R] = _square(t, 40.0, np.array([20.0, 15.0, 20.0, 10.0]) * DEG)
        u[:, Input.DELTA_S] = _square(t, 24.0, np.array([15.0, 10.0, 20.0, 5.0]) * DEG)
    elif name == 'steps':
        u[:, Input.DELTA_R] = np.where((t >= 10) & (t < 60), 15 * DEG, 0.0) \
            + np.where((t >= 110) & (t < 160), -10 * DEG, 0.0)
        u[:, Input.DELTA_S] = np.where((t >= 30) & (t < 50), 10 * DEG, 0.0) \
            + np.where((t >= 80) & (t < 100), -10 * DEG, 0.0)
    elif name == 'roll':
        # rudder reversals every 5 s keep roll rate high; planes keep heave/pitch excited
        u[:, Input.DELTA_R] = _square(t, 10.0, np.array([20.0, 20.0, 15.0]) * DEG)
        u[:, Input.DELTA_S] = _square(t, 24.0, np.array([15.0, 10.0, 20.0, 5.0]) * DEG)
    elif name == 'ident':
        rng = np.random.default_rng(seed)
        dt = t[1] - t[0] if len(t) > 1 else 0.05
        n_total = len(t)
        rud = np.empty(0)
        sign = 1.0
        while len(rud) < n_total:
            n_held = int(round(rng.uniform(20.0, 40.0) / dt))
            rud = np.concatenate([rud, np.full(n_held, sign * 20.0 * DEG)])
            sign = -sign
        u[:, Input.DELTA_R] = _rate_limit(rud[:n_total], dt, FIN_RATE)
        levels = np.array([-20.0, -15.0, -10.0, 10.0, 15.0, 20.0]) * DEG
        for ch, hold in ((Input.DELTA_S, 5.0), (Input.DELTA_BP, 6.0), (Input.DELTA_BS, 6.0)):
            n_hold = max(1, int(round(hold / dt)))
            steps = rng.choice(levels, size=n_total // n_hold + 1)
            u[:, ch] = _rate_limit(np.repeat(steps, n_hold)[:n_total], dt, FIN_RATE)
    elif name == 'prbs':
        rng = np.random.default_rng(seed)
        dt = t[1] - t[0] if len(t) > 1 else 0.05
        levels = np.array([-20.0, -12.0, -6.0, 6.0, 12.0, 20.0]) * DEG
        for ch, hold in ((Input.DELTA_R, 8.0), (Input.DELTA_S, 5.0), (Input.DELTA_BP, 6.0),
                         (Input.DELTA_BS, 6.0)):
            n_hold = max(1, int(round(hold / dt)))
            steps = rng.choice(levels, size=len(t) // n_hold + 1)
            u[:, ch] = _rate_limit(np.repeat(steps, n_hold)[:len(t)], dt, FIN_RATE)
    elif os.path.isfile(name):
        return from_file(name, t)
    else:
        raise ConfigError(f'unknown manoeuvre {name!r}: use one of {", ".join(MANEUVERS)} '
                          'or a CSV file path')
    u[:, FINS] = np.clip(u[:, FINS], -fin_limit, fin_limit)
    return u


def from_file(path: str, t: np.ndarray) -> np.ndarray:
    """Zero-order-hold a manoeuvre table (CSV with a header) onto the grid t. The thrust
    column (N) is optional: 0 when absent."""
    cols: tuple[str, ...] = ('t', 'delta_r', 'delta_s', 'delta_b', 'delta_bp', 'delta_bs', 'n_rpm')
    with open(path, newline='', encoding='utf-8') as fh:
        rd = csv.DictReader(fh)
        missing = [c for c in cols if c not in (rd.fieldnames or [])]
        if missing:
            raise ConfigError(f'{path}: manoeuvre file lacks column(s) {", ".join(missing)}')
        if 'thrust' in (rd.fieldnames or []):
            cols = cols + ('thrust',)
        rows = []
        for i, row in enumerate(rd, start=2):
            try:
                vals = [float(row[c]) for c in cols] + [0.0] * (N_INPUT + 1 - len(cols))
            except ValueError:
                raise ConfigError(f'{path}: line {i}: not a number in {row}') from None
            if not np.all(np.isfinite(vals)):
                raise ConfigError(f'{path}: line {i}: NaN/Inf in {row}')
            rows.append(vals)
    if not rows:
        raise ConfigError(f'{path}: manoeuvre file has no rows')
    a = np.array(rows)
    if np.any(np.diff(a[:, 0]) <= 0):
        raise ConfigError(f'{path}: times in column t must increase strictly')
    idx = np.clip(np.searchsorted(a[:, 0], t, side='right') - 1, 0, len(a) - 1)
    return a[idx, 1:].copy()


def pilot_mix(vehicle: 'Vehicle') -> np.ndarray:
    """(n, 6) the pilot's fixed mix: thruster i's command fraction per unit stick in X Y Z K M N,
    the pseudo-inverse of the configuration matrix with each column scaled to a largest entry
    of 1 (full stick drives the busiest thruster to its full command, as ArduSub's motor
    factors do)."""
    from auv_ident.core.model.thrusters import configuration_matrix
    F = np.linalg.pinv(configuration_matrix(vehicle.thrusters))
    peak = np.abs(F).max(axis=0)
    return F / np.where(peak > 0, peak, 1.0)


def _stick_steps(rng: np.random.Generator, t: np.ndarray, t0: float, t1: float,
                 levels: tuple) -> np.ndarray:
    """Seeded steps on [t0, t1): amplitude from levels, either sign, held 4-9 s, then 3-6 s
    of rest; 0 outside."""
    s = np.zeros(len(t))
    k = t0
    while k < t1:
        hold = rng.uniform(4.0, 9.0)
        amp = rng.choice(levels) * rng.choice((-1.0, 1.0))
        s[(t >= k) & (t < min(k + hold, t1))] = amp
        k += hold + rng.uniform(3.0, 6.0)
    return s


def _stick_sweep(t: np.ndarray, t0: float, amp: float) -> np.ndarray:
    """A chirp of amplitude amp from SWEEP[0] to SWEEP[1] Hz over SWEEP[2] s from t0."""
    f0, f1, dur = SWEEP
    tau = t - t0
    inside = (tau >= 0) & (tau < dur)
    phase = 2 * np.pi * (f0 * tau + 0.5 * (f1 - f0) / dur * tau ** 2)
    return np.where(inside, amp * np.sin(phase), 0.0)


def _one_stick(name: str, t: np.ndarray, t0: float, rng: np.random.Generator) -> np.ndarray:
    """The `surge` .. `yaw` manoeuvre of one stick from t0: ~100 s of steps, a 60 s sweep at the
    middle level and 10 s of rest (180 s in all)."""
    levels = STICK_LEVELS[name]
    return (_stick_steps(rng, t, t0, t0 + 100.0, levels)
            + _stick_sweep(t, t0 + 110.0, levels[2]))


def sticks(name: str, t: np.ndarray, seed: int = 0) -> np.ndarray:
    """(len(t), 6) the pilot's sticks (-1..1) per equation X Y Z K M N of manoeuvre `name`
    (THRUSTER_MANEUVERS, or `ident`: the tank session), quantised to STICK_STEP."""
    t = np.asarray(t, dtype=float)
    rng = np.random.default_rng(seed)
    s = np.zeros((len(t), 6))
    if name in STICKS:
        for k in range(int(np.ceil((t[-1] + 1e-9) / 180.0)) if len(t) else 0):
            s[:, STICKS[name]] += _one_stick(name, t, 180.0 * k, rng)
    elif name == 'steps':
        for k in range(int(np.ceil((t[-1] + 1e-9) / 50.0)) if len(t) else 0):
            stick = tuple(STICKS)[k % len(STICKS)]
            s[:, STICKS[stick]] += _stick_steps(rng, t, 50.0 * k, 50.0 * (k + 1),
                                                STICK_LEVELS[stick])
    elif name in ('tank', 'ident'):
        block = 110.0 + SWEEP[2]                       # steps + rest + sweep
        t_one = 0.0
        for stick in STICKS:                           # each stick in turn
            s[:, STICKS[stick]] += _stick_steps(rng, t, t_one, t_one + 100.0,
                                                STICK_LEVELS[stick])
            s[:, STICKS[stick]] += _stick_sweep(t, t_one + 110.0, STICK_LEVELS[stick][2])
            t_one += block
            if t_one >= t[-1]:
                break
        # not heave with surge or sway: their added-mass (Munk) moments (a3 - a1) u w and
        # (a2 - a3) v w against a BG of 1 cm roll and pitch the Heavy by tens of degrees,
        # which a pilot does not fly
        pairs = (('surge', 'yaw'), ('surge', 'sway'), ('sway', 'yaw'), ('heave', 'yaw'))
        k = 0
        while t_one < t[-1]:                           # then two sticks at once
            a, b = pairs[k % len(pairs)]
            for stick in (a, b):
                s[:, STICKS[stick]] += _stick_steps(rng, t, t_one, t_one + 40.0,
                                                    STICK_LEVELS[stick])
            t_one += 45.0
            k += 1
    else:
        raise ConfigError(f'unknown manoeuvre {name!r} for a thruster vehicle: use one of '
                          f'{", ".join(THRUSTER_MANEUVERS)}')
    return np.round(np.clip(s, -1.0, 1.0) / STICK_STEP) * STICK_STEP


def thruster_commands(name: str, t: np.ndarray, vehicle: 'Vehicle',
                      seed: int = 0) -> np.ndarray:
    """(len(t), 7 + n) the inputs of a hovering thruster vehicle under manoeuvre `name`: the
    state.Input channels at 0, then each thruster's command (its unit; PWM us) from the
    pilot's sticks through pilot_mix, saturated to its range."""
    for th in vehicle.thrusters:
        if not np.isfinite(th.command_max):
            raise ConfigError(f'thruster {th.name}: command {th.command} has no range '
                              '(command_max) for a pilot to mix into')
    s = sticks(name, t, seed)
    frac = np.clip(s @ pilot_mix(vehicle).T, -1.0, 1.0)
    neutral = np.array([th.neutral for th in vehicle.thrusters])
    cmax = np.array([th.command_max for th in vehicle.thrusters])
    u = np.zeros((len(t), N_INPUT + len(vehicle.thrusters)))
    u[:, N_INPUT:] = neutral + cmax * frac
    return u
