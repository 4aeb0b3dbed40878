"""A session's accepted messages as the arrays the batch methods take.

The identifier keeps the commands and the measurements it accepted in arrival order (replay_bag
with keep_arrays, the live automatic choice's window: session/auto_choice.py). The batch methods
(core/identification/batch.py, core/identification/selection.py) want one record on the sample grid
instead: :func:`paired` pairs every measurement with the command in force at its stamp (the
streaming identifier's rule, core/filter/stream.py), and :func:`exact_hold` inserts the command
changes between samples as rows without a measurement, so that a batch filter follows the same
zero-order hold as the streaming one (core.filter.timing.with_command_changes).
"""
import bisect
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.filter.timing import with_command_changes
from auv_ident.core.identification.results import Record
from auv_ident.core.model.state import N_INPUT, N_STATE


def paired(
        commands: Sequence[tuple[float, np.ndarray]],
        measurements: Sequence[tuple[float, np.ndarray]],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t, Y, U, t_cmd, U_cmd) of accepted messages.

    commands : [(t, u (7,)), ...] in arrival order; measurements : [(t, y (12,)), ...] (any
    order, distinct stamps)
    Returns t (N,) increasing, Y (N, 12) (NaN: unmeasured channel), U (N, 7) the command in
    force at t[k] (latest stamp <= t[k]; NaN rows where there is none yet), and the commands
    by stamp,
    t_cmd (M,), U_cmd (M, 7), where a later message with the same stamp wins."""
    cmd = sorted(commands, key=lambda c: c[0])   # stable: a later same-stamp one last
    # by stamp: the filter takes them in order, an unfiltered session in arrival order
    measurements = sorted(measurements, key=lambda m: m[0])
    by_stamp = {}
    for tc, uc in cmd:
        by_stamp[tc] = uc
    cmd_t = [c[0] for c in cmd]
    t = np.array([m[0] for m in measurements], dtype=float)
    Y = (np.array([m[1] for m in measurements], dtype=float) if measurements
         else np.zeros((0, N_STATE)))
    U = np.full((len(t), N_INPUT), np.nan)
    for k, tk in enumerate(t):
        i = bisect.bisect_right(cmd_t, tk)
        if i > 0:
            U[k] = cmd[i - 1][1]
    stamps = sorted(by_stamp)
    U_cmd = (np.array([by_stamp[tc] for tc in stamps], dtype=float) if stamps
             else np.zeros((0, N_INPUT)))
    return t, Y, U, np.array(stamps, dtype=float), U_cmd


def exact_hold(t: np.ndarray, Y: np.ndarray, U: np.ndarray, t_cmd: np.ndarray,
               U_cmd: np.ndarray) -> Record:
    """The Record (core.identification.results) the batch methods take: the samples with a
    command, and the command changes between them as samples without a measurement (the exact
    zero-order hold the streaming filter followed)."""
    ok = np.all(np.isfinite(U), axis=1)
    t2, Y2, U2, _ = with_command_changes(t[ok], Y[ok], U[ok], t_cmd, U_cmd)
    return Record(t2, Y2, U2)


def median_noise_std(variances: Sequence[np.ndarray], default_variances: ArrayLike) -> np.ndarray:
    """(12,) the measurement 1-sigma the filter used over a record, per channel: the square
    root of the median of the R diagonals of its accepted updates (the messages' covariances
    with noise_source 'message'), or of default_variances (noise_std squared) if there were
    none. A NaN entry (a channel the message did not measure: a multi-rate log's sensor
    without a sample) is left out of its channel's median; a channel never measured gets
    default_variances'."""
    default = np.asarray(default_variances, dtype=float)
    if len(variances) == 0:
        return np.sqrt(default)
    v = np.array(variances)
    if not np.isnan(v).any():
        return np.sqrt(np.median(v, axis=0))
    out = default.copy()
    for i in range(v.shape[1]):
        col = v[:, i][~np.isnan(v[:, i])]
        if col.size:
            out[i] = np.median(col)
    return np.sqrt(out)
