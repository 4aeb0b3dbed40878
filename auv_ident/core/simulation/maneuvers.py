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
"""
import csv
import os

import numpy as np

from auv_ident.core.errors import ConfigError
from auv_ident.core.model.state import FINS, Input, N_INPUT

DEG = np.pi / 180.0
MANEUVERS = ('ident', 'zigzag', 'steps', 'prbs', 'roll')
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
