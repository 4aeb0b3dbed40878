"""A session's accepted messages as the arrays the batch methods take.

The identifier keeps the commands and the measurements it accepted in arrival order (replay_bag
with keep_arrays, the live automatic choice's window: session/auto_choice.py). The batch methods
(core/identification/batch.py, core/identification/selection.py) want one record on the sample grid
instead: :func:`paired` pairs every measurement with the command in force at its stamp (the
streaming identifier's rule, core/filter/stream.py), and :func:`exact_hold` inserts the command
changes between samples as rows without a measurement, so that a batch filter follows the same
zero-order hold as the streaming one (core.filter.timing.with_command_changes).

What a replay keeps per message is :class:`Rows` (one float64 array grown by doubling) and
:class:`UpdateLog`, not a tuple and small arrays per message: those cost about 1.5 KB per
odometry sample (91 MB for the 60 000 samples of a 3000 s, 20 Hz bag), the rows 0.4 KB.
"""
from collections.abc import Iterator, Sequence

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.filter.timing import with_command_changes
from auv_ident.core.identification.results import Record
from auv_ident.core.model.state import N_INPUT, N_STATE


class Rows:
    """Rows of `width` numbers appended one at a time, kept in one array of `dtype` whose
    capacity doubles when full (amortised O(1) per row, 8 bytes a value).

    append(*parts): one row from scalars and arrays laid end to end; `array`: the (n, width)
    rows so far (a view, valid until the next append); len(): n."""

    def __init__(self, width: int, dtype: type = float, capacity: int = 64) -> None:
        self._a: np.ndarray = np.empty((capacity, width), dtype=dtype)
        self._n = 0

    def append(self, *parts: ArrayLike) -> None:
        if self._n == self._a.shape[0]:
            grown = np.empty((2 * self._n, self._a.shape[1]), dtype=self._a.dtype)
            grown[:self._n] = self._a
            self._a = grown
        row = self._a[self._n]
        i = 0
        for part in parts:
            if isinstance(part, (float, int)) and i < row.size:   # no array made (~1 us)
                row[i] = part
                i += 1
                continue
            x = part if isinstance(part, np.ndarray) and part.ndim == 1 else np.ravel(part)
            row[i:i + x.size] = x
            i += x.size
        if i != row.size:
            raise ValueError(f'a row of {i} values for {row.size} columns')
        self._n += 1

    def __len__(self) -> int:
        return self._n

    @property
    def array(self) -> np.ndarray:
        return self._a[:self._n]


class UpdateLog:
    """The accepted updates of a replay, (stamp_ns int, estimate (p,), std (p,)) each, in
    compact arrays (:class:`Rows`; a new part where p changes: coefficients ['auto', ...]
    switch sets once). Reads like the list of tuples it replaces: len, [k], iteration."""

    def __init__(self) -> None:
        self._parts: list[tuple[int, Rows, Rows]] = []    # (p, stamps, [estimate, std])

    def append(self, stamp_ns: int, estimate: np.ndarray, std: np.ndarray) -> None:
        p = len(estimate)
        if not self._parts or self._parts[-1][0] != p:
            self._parts.append((p, Rows(1, np.int64), Rows(2 * p)))
        _, stamps, values = self._parts[-1]
        stamps.append(stamp_ns)
        values.append(estimate, std)

    def __len__(self) -> int:
        return sum(len(stamps) for _, stamps, _ in self._parts)

    def __iter__(self) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
        for p, stamps, values in self._parts:
            for s, v in zip(stamps.array[:, 0], values.array):
                yield int(s), v[:p].copy(), v[p:].copy()

    def __getitem__(self, k: int) -> tuple[int, np.ndarray, np.ndarray]:
        n = len(self)
        if not -n <= k < n:
            raise IndexError(f'update {k} of {n}')
        k %= n
        for p, stamps, values in self._parts:
            if k < len(stamps):
                v = values.array[k]
                return int(stamps.array[k, 0]), v[:p].copy(), v[p:].copy()
            k -= len(stamps)
        raise IndexError(k)     # not reached: k < n


def paired(
        commands: Sequence[tuple[float, np.ndarray]] | np.ndarray | Rows,
        measurements: Sequence[tuple[float, np.ndarray]] | np.ndarray | Rows,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t, Y, U, t_cmd, U_cmd) of accepted messages.

    commands : [(t, u (7,)), ...] in arrival order, or their (M, 8) rows [t, u] (an array or
    Rows);
    measurements : [(t, y (12,)), ...], or their (N, 13) rows [t, y] (any order, distinct
    stamps)
    Returns t (N,) increasing, Y (N, 12) (NaN: unmeasured channel), U (N, 7) the command in
    force at t[k] (latest stamp <= t[k]; NaN rows where there is none yet), and the commands
    by stamp, t_cmd (M,), U_cmd (M, 7), where a later message with the same stamp wins."""
    cmd = _rows(commands, _width(commands))
    meas = _rows(measurements, N_STATE)
    order = np.argsort(cmd[:, 0], kind='stable')    # a later same-stamp one last
    cmd = cmd[order]
    cmd_t = cmd[:, 0]
    # by stamp: the filter takes them in order, an unfiltered session in arrival order
    meas = meas[np.argsort(meas[:, 0], kind='stable')]
    t = meas[:, 0].copy()
    Y = meas[:, 1:].copy()
    U = np.full((len(t), cmd.shape[1] - 1), np.nan)
    i = np.searchsorted(cmd_t, t, side='right')
    U[i > 0] = cmd[i[i > 0] - 1, 1:]
    # the last of each run of equal stamps
    last = np.ones(len(cmd_t), dtype=bool)
    last[:-1] = cmd_t[1:] != cmd_t[:-1]
    return t, Y, U, cmd_t[last].copy(), cmd[last, 1:].copy()


def _width(entries: Sequence[tuple[float, np.ndarray]] | np.ndarray | Rows) -> int:
    """The width of the values of command rows or pairs: N_INPUT, or more for a thruster
    vehicle (its thruster commands follow); N_INPUT when there are none to tell."""
    if isinstance(entries, Rows):
        entries = entries.array
    if isinstance(entries, np.ndarray):
        return entries.shape[1] - 1 if entries.ndim == 2 else N_INPUT
    return len(entries[0][1]) if len(entries) else N_INPUT


def _rows(entries: Sequence[tuple[float, np.ndarray]] | np.ndarray | Rows,
          width: int) -> np.ndarray:
    """(n, 1 + width) float rows [t, values] of (t, values) pairs or of such rows (an array
    or Rows)."""
    if isinstance(entries, Rows):
        entries = entries.array
    if isinstance(entries, np.ndarray):
        return np.asarray(entries, dtype=float).reshape(-1, 1 + width)
    out = np.empty((len(entries), 1 + width))
    for k, (tk, row) in enumerate(entries):
        out[k, 0] = tk
        out[k, 1:] = row
    return out


def exact_hold(t: np.ndarray, Y: np.ndarray, U: np.ndarray, t_cmd: np.ndarray,
               U_cmd: np.ndarray) -> Record:
    """The Record (core.identification.results) the batch methods take: the samples with a
    command, and the command changes between them as samples without a measurement (the exact
    zero-order hold the streaming filter followed)."""
    ok = np.all(np.isfinite(U), axis=1)
    t2, Y2, U2, _ = with_command_changes(t[ok], Y[ok], U[ok], t_cmd, U_cmd)
    return Record(t2, Y2, U2)


def median_noise_std(variances: Sequence[np.ndarray] | np.ndarray | Rows,
                     default_variances: ArrayLike) -> np.ndarray:
    """(12,) the measurement 1-sigma the filter used over a record, per channel: the square
    root of the median of the R diagonals of its accepted updates (the messages' covariances
    with noise_source 'message'), or of default_variances (noise_std squared) if there were
    none. A NaN entry (a channel the message did not measure: a multi-rate log's sensor
    without a sample) is left out of its channel's median; a channel never measured gets
    default_variances'."""
    default = np.asarray(default_variances, dtype=float)
    if isinstance(variances, Rows):
        variances = variances.array
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
