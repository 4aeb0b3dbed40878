"""Measured runs read from other programs' files into our state, inputs and stamps:
:func:`read_hsva` (the HSVA KVLCC2 free-running model tests) and :func:`read_csv_run` (a CSV
log with a column map, :mod:`auv_ident.offline.column_map`). :mod:`auv_ident.offline.import_bag`
writes the result as a bag.

Both readers go through one path: the file becomes a table of named columns (cells kept as
text with their line numbers), the column map picks, checks and converts the columns
(units, signs, ENU -> NED, earth-fixed -> body velocities), and the measurement noise of each
measured channel is estimated from the data (:func:`white_noise_std`). Bad input raises one
:class:`RunFileError` (a :class:`~auv_ident.core.errors.DataError`) naming the file, line and
column, or a :class:`~auv_ident.offline.column_map.ColumnMapError` naming the map entry.

HSVA files (SIMMAN 2008, KVLCC2 model 2487, 1:45.714, free-running at HSVA, 2006), as the
data show them (docs/bags.md, "Importing measured runs"): ISO-8859-1 text, 4 header lines,
then rows of 12 numbers at 20 Hz, the t = 0 row included: ``t [s], x0, y0 [m], psi [deg],
xdot0, ydot0 [m/s], r [deg/s], phi [deg], delta [deg], n [rps], thrust [N], torque [N m]``.
x0, y0 are a NED-like world frame (x0 along the initial course, y0 to starboard of it: the
course atan2(ydot0, xdot0) follows psi to within the drift angle, and integrating xdot0,
ydot0 gives x0, y0 to 3 mm); xdot0, ydot0 are EARTH-fixed velocities (not body u, v); psi and
r are positive to starboard (r = dpsi/dt to 0.035 deg/s rms); delta is positive to port,
which is our delta_r's sign (the first rudder of a starboard-first zigzag is negative and psi
then grows). n is 10.2295 rps in every run; the torque has no input channel and is not
carried.
"""
import csv
from dataclasses import dataclass
import hashlib
import io
import math
from pathlib import Path

import numpy as np

from auv_ident.core.errors import DataError
from auv_ident.core.model.state import State, STATE_NAMES
from auv_ident.offline.column_map import (
    ColumnMap,
    ColumnMapError,
    HSVA_COLUMNS,
    HSVA_MAP,
    load_column_map,
    refuse_decimal_comma,
)

NS_PER_S = 1_000_000_000
HSVA_HEADER_LINES = 4
HSVA_ENCODING = 'iso-8859-1'
MIN_NOISE_SAMPLES = 5


class RunFileError(DataError):
    """A measured-run file cannot be read as given: names the file, line and column."""


@dataclass
class MeasuredRun:
    """A measured run in our conventions.

    t_ns : (N,) int64, sample times (ns), strictly increasing: from the run's origin (the
        file's t) if ``absolute`` is False, else since 1970-01-01T00:00:00Z
    x : (N, 12) state ``[u v w p q r x y z phi theta psi]`` NED/FRD (m/s, rad/s, m, rad);
        unmeasured channels 0
    measured : (12,) bool, the channels the file measures
    inputs : dict of (N,) arrays present among 'rudder' (rad, our delta_r sign), 'thrust' (N),
        'shaft' (rpm)
    noise_std : (12,) 1-sigma estimated from the data for the measured channels
        (:func:`white_noise_std`; 0: no estimate), NaN for the unmeasured ones
    source : Path of the file; sha256 : its hex digest; fmt : 'hsva' or 'csv'
    column_map : dict, the map used (:meth:`ColumnMap.document`)
    skipped : line numbers of the rows skipped for a NaN or Inf in a mapped cell

    A multi-rate CSV log (blank cells: no sample at that row) has NaN in x where a measured
    channel has no sample (:attr:`present`), and its inputs hold their last value (NaN before
    the first).
    """

    t_ns: np.ndarray
    x: np.ndarray
    measured: np.ndarray
    inputs: dict
    noise_std: np.ndarray
    source: Path
    sha256: str
    fmt: str
    column_map: dict
    absolute: bool = False
    skipped: tuple = ()

    @property
    def present(self):
        """(N, 12) bool: a sample of each measured channel at each row."""
        return np.isfinite(self.x) & self.measured

    @property
    def samples(self):
        """{channel name: number of samples} of the measured channels."""
        counts = self.present.sum(axis=0)
        return {STATE_NAMES[i]: int(counts[i]) for i in np.flatnonzero(self.measured)}

    @property
    def t(self):
        """(N,) sample times (s) from the first sample."""
        return (self.t_ns - self.t_ns[0]) / NS_PER_S

    @property
    def sample_time(self):
        """Median sample interval (s)."""
        return float(np.median(np.diff(self.t_ns))) / NS_PER_S if len(self.t_ns) > 1 else 0.0

    @property
    def measured_names(self):
        return [STATE_NAMES[i] for i in np.flatnonzero(self.measured)]


def white_noise_std(values):
    """Robust 1-sigma of the sample-to-sample (white) noise of a smooth signal.

    ``1.4826 MAD(d2) / sqrt(6)`` with d2 the second differences of the samples: for white noise
    of variance s^2 on a signal smooth at the sample rate, d2 has variance 6 s^2 (1, -2, 1), the
    motion's own part (acceleration x T^2, ~1e-4 of the noise-free signal's scale at 20 Hz)
    is negligible, and the median absolute deviation ignores spikes. It measures the white part
    only: noise correlated over several samples (a filtered signal) is partly invisible to it,
    so it is a lower bound for coloured noise (identify's noise model from the residuals then
    widens it, docs/method.md). Returns 0.0 for fewer than 5 samples or a signal whose second
    differences are mostly exactly 0 (quantized, held): no estimate.
    """
    v = np.asarray(values, dtype=float)
    if v.size < MIN_NOISE_SAMPLES:
        return 0.0
    d2 = np.diff(v, 2)
    mad = np.median(np.abs(d2 - np.median(d2)))
    return float(1.4826 * mad / math.sqrt(6.0))


def noise_std_estimate(x, measured):
    """(12,) :func:`white_noise_std` of each measured channel of x (N, 12) (angles unwrapped
    first), NaN for the unmeasured ones."""
    out = np.full(12, np.nan)
    for i in np.flatnonzero(measured):
        col = x[:, i]
        col = col[np.isfinite(col)]     # a multi-rate log: this channel's own samples
        if i in (State.PHI, State.THETA, State.PSI):
            col = np.unwrap(col)
        out[i] = white_noise_std(col)
    return out


class _Table:
    """A text table: column names and, per data row, (line number, cells as str)."""

    def __init__(self, path, names, rows):
        self.path = path
        self.names = list(names)
        self.rows = rows

    def cell_name(self, column, i):
        return f'{self.path}: line {self.rows[i][0]}, column {column!r}'

    def column_cells(self, column):
        j = self.names.index(column)
        return [cells[j] for _, cells in self.rows]

    def numbers(self, column, blank_ok=False):
        """(N,) float array of a column; a blank cell is NaN (no sample at that row) if
        blank_ok, any other cell that is not a finite number an error (a decimal comma named
        as such)."""
        out = np.empty(len(self.rows))
        j = self.names.index(column)
        for i, (_, cells) in enumerate(self.rows):
            cell = cells[j]
            if blank_ok and not cell.strip():
                out[i] = math.nan
                continue
            try:
                out[i] = float(cell)
            except ValueError:
                refuse_decimal_comma(cell, self.cell_name(column, i), RunFileError)
                out[i] = math.nan
            if not math.isfinite(out[i]):
                raise RunFileError(f'{self.cell_name(column, i)}: {cell.strip()!r} is not '
                                   'a finite number')
        return out

    def without_nan_rows(self, columns):
        """This table without the rows that hold a NaN or Inf in one of the columns, and the
        line numbers of those rows."""
        js = [self.names.index(c) for c in columns]
        keep, skipped = [], []
        for row in self.rows:
            bad = False
            for j in js:
                try:
                    bad = not math.isfinite(float(row[1][j]))
                except ValueError:
                    continue        # text, blank or a decimal comma: numbers() says
                if bad:
                    break
            (skipped if bad else keep).append(row)
        return _Table(self.path, self.names, keep), tuple(line for line, _ in skipped)


def _read_text(path, encoding, label):
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise RunFileError(f'{path}: cannot read: {exc.strerror}') from None
    try:
        text = data.decode(encoding)
    except UnicodeDecodeError as exc:
        raise RunFileError(f'{path}: not {label} text (byte {exc.start})') from None
    return path, text, hashlib.sha256(data).hexdigest()


def _convert(table, cmap, fmt, sha256, multi_rate=False):
    """The MeasuredRun of a table through a checked column map; multi_rate: blank cells are
    samples not taken (NaN), rows with a NaN or Inf skipped (a CSV log)."""
    if not table.rows:
        raise RunFileError(f'{table.path}: no data rows')
    missing = [c for c in cmap.columns if c not in table.names]
    if missing:
        raise ColumnMapError(f'{cmap.where}: column(s) {", ".join(map(repr, missing))} not in '
                             f'{table.path}; its columns: {", ".join(table.names)}')
    skipped = ()
    if multi_rate:
        table, skipped = table.without_nan_rows(cmap.columns)
        if not table.rows:
            raise RunFileError(f'{table.path}: every data row has a NaN or Inf')
    tcol = cmap.entries['time']['column']
    t_ns = cmap.time_ns(table.column_cells(tcol), lambda i: table.cell_name(tcol, i))
    steps = np.diff(t_ns)
    if np.any(steps <= 0):
        i = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise RunFileError(f'{table.cell_name(tcol, i)}: time does not increase '
                           f'({t_ns[i - 1] / NS_PER_S:.9g} s on line {table.rows[i - 1][0]}, '
                           f'then {t_ns[i] / NS_PER_S:.9g} s)')
    values = {name: table.numbers(ent['column'], blank_ok=multi_rate)
              for name, ent in cmap.entries.items() if name != 'time'}
    for name, arr in values.items():
        if np.isnan(arr).all():
            raise RunFileError(f'{table.path}: column {cmap.entries[name]["column"]!r} '
                               f'({name}) has no value in any row')
    x, measured, inputs = cmap.to_ned(values)
    inputs = {name: _held(arr) for name, arr in inputs.items()}
    return MeasuredRun(t_ns=t_ns, x=x, measured=measured, inputs=inputs,
                       noise_std=noise_std_estimate(x, measured), source=table.path,
                       sha256=sha256, fmt=fmt, column_map=cmap.document(),
                       absolute=cmap.time_base == 'unix', skipped=skipped)


def _held(values):
    """An input logged on change: each NaN (no entry at that row) replaced by the last value
    before it; NaN before the first."""
    v = np.asarray(values, dtype=float)
    idx = np.where(np.isfinite(v), np.arange(v.size), -1)
    np.maximum.accumulate(idx, out=idx)
    return np.where(idx >= 0, v[np.maximum(idx, 0)], np.nan)


def read_hsva(path):
    """Read an HSVA free-running test file (module docstring) into a :class:`MeasuredRun`.

    Every data row must hold the 12 numbers; the t = 0 row is data. Measured: u, v (rotated
    from the earth-fixed xdot0, ydot0 with psi), r, x, y, phi, psi; inputs rudder (rad),
    thrust (N) and shaft (rpm, 60 n).
    """
    path, text, sha = _read_text(path, HSVA_ENCODING, 'ISO-8859-1')
    lines = text.splitlines()
    if len(lines) <= HSVA_HEADER_LINES:
        raise RunFileError(f'{path}: {len(lines)} lines: an HSVA file has {HSVA_HEADER_LINES} '
                           'header lines, then data')
    rows = []
    for lineno, line in enumerate(lines[HSVA_HEADER_LINES:], start=HSVA_HEADER_LINES + 1):
        cells = line.split()
        if not cells:
            continue
        if len(cells) != len(HSVA_COLUMNS):
            raise RunFileError(f'{path}: line {lineno}: {len(cells)} fields, an HSVA row has '
                               f'{len(HSVA_COLUMNS)} ({" ".join(HSVA_COLUMNS)})')
        rows.append((lineno, cells))
    return _convert(_Table(path, HSVA_COLUMNS, rows), ColumnMap(HSVA_MAP, 'HSVA column map'),
                    'hsva', sha)


def read_csv_run(path, column_map):
    """Read a CSV log with a column map into a :class:`MeasuredRun`.

    path : CSV file (UTF-8, a header row of column names, then one row per sample; blank
        lines skipped); column_map : a YAML file path or a :class:`ColumnMap`

    A multi-rate log: a blank cell is no sample of that quantity at that row (a state channel
    not measured there, an input held); a row with a NaN or Inf in a mapped cell is skipped
    and counted (MeasuredRun.skipped); a number with a decimal comma is an error saying so.
    """
    cmap = column_map if isinstance(column_map, ColumnMap) else load_column_map(column_map)
    path, text, sha = _read_text(path, 'utf-8-sig', 'UTF-8')
    reader = csv.reader(io.StringIO(text, newline=''), delimiter=cmap.delimiter)
    header = None
    rows = []
    try:
        for cells in reader:
            if not any(c.strip() for c in cells):
                continue
            if header is None:
                header = [c.strip() for c in cells]
                continue
            if len(cells) != len(header):
                hint = (' (decimal commas? write numbers with a decimal point)'
                        if len(cells) > len(header) and cmap.delimiter == ',' else '')
                raise RunFileError(f'{path}: line {reader.line_num}: {len(cells)} fields, the '
                                   f'header has {len(header)}{hint}')
            rows.append((reader.line_num, cells))
    except csv.Error as exc:
        raise RunFileError(f'{path}: line {reader.line_num}: {exc}') from None
    if header is None:
        raise RunFileError(f'{path}: empty file (expected a header row of column names)')
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise RunFileError(f'{path}: header names column(s) {", ".join(map(repr, dup))} '
                           'more than once')
    if len(header) == 1 and any(c in header[0] for c in ';\t|') and len(cmap.columns) > 1:
        sep = next(c for c in ';\t|' if c in header[0])
        raise ColumnMapError(f'{path}: the header is one column {header[0]!r}: the fields '
                             f'are separated by {sep!r}, not {cmap.delimiter!r} (set '
                             f'delimiter: {sep!r} in {cmap.where})')
    return _convert(_Table(path, header, rows), cmap, 'csv', sha, multi_rate=True)
