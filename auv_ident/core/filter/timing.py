"""Time in the core: the intervals between sample stamps and how the filter crosses them.

One definition of the rules for both paths, the streaming identifier (stream.py, a message at
a time) and the batch methods (batch.py: run_ekf, refine, identify over a record), so that the
same stamps give the same filter either way:

- interval: dt = t_k - t_{k-1} (s) at the stamps' resolution, 1 ns (:func:`interval`). ROS
  stamps are whole nanoseconds; float seconds add rounding below that (0.15 - 0.1 is not 0.05
  in floating point), which would make a uniform grid non-uniform in the last bit. Times far
  from zero lose more than that (float seconds near 1.7e9, a date, resolve 0.24 us): pass times
  relative to the first stamp.
- time update: over dt, with the command in force at t_{k-1} held (zero-order hold), in
  n = ceil(dt / max_step) RK4 steps of dt / n (:func:`time_step`). On a uniform grid whose
  step is max_step that is one step of exactly the sample time.
- gap: dt > max_bridge restarts the vehicle states from the measurement at t_k, keeping the
  coefficients and their covariance (n = 0 below). Open loop over a long gap the model drifts,
  and the filter, trusting its small process noise, reads the drift as coefficient error
  (measured on NPS AUV II, 'ident' manoeuvre: 2 s of missing odometry bridged left the
  coefficients 15-50 % off a minute later; restarted, 5 %).
"""
import math

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.compiled_cache import cached_njit
from auv_ident.core.errors import DataError

DEFAULT_MAX_BRIDGE = 0.25   # s, longest interval crossed by time updates (longer: restart)
NS = 1e9                    # stamps' resolution: 1 / NS s


@cached_njit()
def interval(t_prev, t):
    """t - t_prev (s) rounded to the stamps' resolution (1 ns)."""
    return np.rint((t - t_prev) * NS) / NS


@cached_njit()
def time_step(dt, max_step, max_bridge):
    """(n, h): the time update over dt (s) is n RK4 steps of h = dt / n (s), each at most
    max_step; n = 0 (h = dt) when dt > max_bridge, the vehicle states restart instead."""
    if dt > max_bridge:
        return 0, dt
    n = max(1, math.ceil(dt / max_step - 1e-9))
    return n, dt / n


@cached_njit()
def time_steps(t, max_step, max_bridge):
    """(n (N,) int, h (N,)): time_step of every interval of the stamps t (N,) (s); entry k
    crosses [t_{k-1}, t_k] (entry 0, before the first sample, is n = 0, h = 0)."""
    N = t.shape[0]
    n = np.zeros(N, dtype=np.int64)
    h = np.zeros(N)
    for k in range(1, N):
        n[k], h[k] = time_step(interval(t[k - 1], t[k]), max_step, max_bridge)
    return n, h


def check_times(t: ArrayLike, N: int | None = None) -> np.ndarray:
    """t as a float array (N,) of strictly increasing, finite sample times (s), or DataError
    naming the first bad entry (N: the expected length, e.g. the measurements' rows)."""
    t = np.ascontiguousarray(t, dtype=float)
    if t.ndim != 1 or (N is not None and t.shape[0] != N):
        raise DataError(f'sample times t must have shape ({N if N is not None else "N"},), '
                        f'got {t.shape}')
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise DataError(f'sample time t[{bad[0]}] = {float(t[bad[0]])!r} is not finite')
    dt = np.rint(np.diff(t) * NS) / NS
    bad = np.flatnonzero(~(dt > 0.0))
    if bad.size:
        k = bad[0] + 1
        raise DataError(f'sample times must increase strictly (at 1 ns resolution): t[{k}] = '
                        f'{float(t[k])!r} s is not after t[{k - 1}] = {float(t[k - 1])!r} s')
    return t


def nominal_sample_time(t: ArrayLike) -> float:
    """The median interval of the stamps t (N >= 2) (s, at 1 ns resolution): the sample time
    of a record with jitter and dropouts."""
    t = check_times(t)
    if t.shape[0] < 2:
        raise DataError('a sample time needs at least 2 samples (give T)')
    return float(np.median(np.rint(np.diff(t) * NS) / NS))


def commands_at(t_cmd: np.ndarray, U_cmd: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The command in force at each time t (N,): the latest command (row of U_cmd (M, 7))
    stamped at or before it (t_cmd (M,), increasing), NaN where none is (zero-order hold, the
    streaming identifier's rule). A command published only when it changes is thus held."""
    t_cmd = np.asarray(t_cmd, dtype=float)
    U_cmd = np.asarray(U_cmd, dtype=float)
    if U_cmd.ndim != 2 or U_cmd.shape[0] != t_cmd.shape[0]:
        raise DataError(f'commands: {t_cmd.shape[0]} stamps but U_cmd of shape {U_cmd.shape}')
    if np.any(np.diff(t_cmd) < 0):
        raise DataError('command stamps must not decrease')
    i = np.searchsorted(t_cmd, np.asarray(t, dtype=float), side='right') - 1
    U = np.full((i.shape[0], U_cmd.shape[1]), np.nan)
    U[i >= 0] = U_cmd[i[i >= 0]]
    return U


def with_command_changes(
        t: np.ndarray, Y: np.ndarray, U: np.ndarray, t_cmd: np.ndarray, U_cmd: np.ndarray,
        max_bridge: float = DEFAULT_MAX_BRIDGE,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Insert the command changes between samples as samples without a measurement.

    The batch filter holds U[k-1] over [t_{k-1}, t_k]; a command stamped inside that interval
    would then act only from t_k on (up to one sample period late, a bias in the control
    derivatives when odometry and commands are not stamped together). A row at the command's
    stamp with every channel missing (NaN: no measurement update) and that command as its input
    makes the time update follow the exact zero-order hold, as the streaming identifier does.
    Intervals longer than max_bridge are left alone (the vehicle states restart there).

    Parameters
    ----------
    t, Y, U : (N,), (N, m), (N, 7): samples, measurements (NaN = missing) and the command in
        force at each sample
    t_cmd, U_cmd : (M,), (M, 6): command stamps (increasing) and commands

    Returns
    -------
    t2, Y2, U2 : the merged record (N + inserted rows), and measured (N + inserted,) bool: True
        for the original samples
    """
    t = check_times(t)
    Y = np.asarray(Y, dtype=float)
    U = np.asarray(U, dtype=float)
    t_cmd = np.asarray(t_cmd, dtype=float)
    U_cmd = np.asarray(U_cmd, dtype=float)
    k = np.searchsorted(t, t_cmd, side='left')      # t[k-1] < c <= t[k]
    inside = (k > 0) & (k < t.shape[0])
    inside[inside] &= t_cmd[inside] < t[k[inside]]  # strictly inside (t_{k-1}, t_k)
    dt = np.zeros_like(t_cmd)
    dt[inside] = t[k[inside]] - t[k[inside] - 1]
    inside &= dt <= max_bridge
    if not np.any(inside):
        return t, Y, U, np.ones(t.shape[0], dtype=bool)
    t_new = t_cmd[inside]
    t2 = np.concatenate([t, t_new])
    order = np.argsort(t2, kind='stable')
    Y2 = np.concatenate([Y, np.full((t_new.shape[0], Y.shape[1]), np.nan)])[order]
    U2 = np.concatenate([U, U_cmd[inside]])[order]
    measured = np.concatenate([np.ones(t.shape[0], dtype=bool),
                               np.zeros(t_new.shape[0], dtype=bool)])[order]
    return t2[order], Y2, U2, measured
