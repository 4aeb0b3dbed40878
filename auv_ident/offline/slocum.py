"""Reader of the Slocum glider's binary logs (Teledyne Webb "dinkum binary data", .dbd
engineering / .ebd science, and their .sbd/.tbd/.mbd/.nbd subsets), numpy only.

The format, from Teledyne Webb's description of "dinkum binary data" (encoding version 5) and
as the comet files (``../shared/realdata/slocum_comet``) show it:

1. An ASCII header of ``num_ascii_tags`` lines ``key:    value`` (``dbd_label``,
   ``encoding_ver``, ``total_num_sensors``, ``sensors_per_cycle``, ``state_bytes_per_cycle``,
   ``sensor_list_crc``, ``sensor_list_factored``, ``fileopen_time``, ...).
2. The sensor list, ``total_num_sensors`` lines ``s: T|F index cycle_index bytes name units``
   (``T``: the sensor is in this file's cycles, at position ``cycle_index``), unless
   ``sensor_list_factored`` is 1: the glider then leaves it out and it is read from the cache
   file ``<sensor_list_crc>.cac`` (the same lines), kept next to the logs or in a cache
   directory.
3. The known bytes, which give the byte order: ``'s'``, ``'a'``, the int16 0x1234, the
   float32 123.456 and the float64 123456789.12345 (16 bytes). Written big-endian on the
   glider; a little-endian writer is read as well.
4. Cycles, each ``'d'``, then ``state_bytes_per_cycle`` state bytes holding 2 bits per sensor
   of the cycle (4 sensors a byte, the first sensor in the two highest bits): 0 not updated,
   1 updated with the same value as before, 2 updated with a new value (then that value
   follows), 3 not used. The new values follow the state bytes in sensor order, each in its
   sensor's size: 1 byte int8, 2 bytes int16, 4 bytes float32, 8 bytes float64.
5. ``'X'``: the end of the file. A file cut short (the glider reset, a partial transfer) ends
   without it; the complete cycles before the cut are kept (``SlocumLog.complete`` False).

Every bad byte raises one :class:`SlocumFileError` naming the file and the byte offset.
"""
from dataclasses import dataclass
import hashlib
from pathlib import Path

import numpy as np

from auv_ident.offline.importers import RunFileError

KNOWN_BYTES = 16
STATE_NOT_UPDATED, STATE_SAME, STATE_NEW = 0, 1, 2
VALUE_TYPES = {1: 'i1', 2: 'i2', 4: 'f4', 8: 'f8'}
KNOWN_INT16 = 0x1234
KNOWN_FLOAT32 = 123.456
KNOWN_FLOAT64 = 123456789.12345
# the header's keys this reader needs
REQUIRED_TAGS = ('num_ascii_tags', 'total_num_sensors', 'sensors_per_cycle',
                 'state_bytes_per_cycle', 'sensor_list_crc')
# the sensor holding each cycle's time (s since 1970): engineering, then science files
TIME_SENSORS = ('m_present_time', 'sci_m_present_time')


class SlocumFileError(RunFileError):
    """A Slocum binary log cannot be read: names the file and the byte offset."""


@dataclass(frozen=True)
class Sensor:
    """One sensor of a log's cycles: name, units, size in bytes, position in the cycle."""

    name: str
    units: str
    size: int
    cycle_index: int


@dataclass
class SlocumLog:
    """The content of one Slocum binary log.

    header : dict of the ASCII tags (text values)
    sensors : the sensors in the cycles, in cycle order
    state : (n_cycles, n_sensors) int8, the 2-bit state of each sensor in each cycle
    values : (n_cycles, n_sensors) float64, the value each sensor holds after the cycle (the
        last one written; NaN before its first); a state-1 cycle repeats the previous value
    complete : False when the file ends without its end mark (a cut file)
    """

    path: Path
    sha256: str
    header: dict
    sensors: list
    state: np.ndarray
    values: np.ndarray
    complete: bool
    big_endian: bool

    @property
    def names(self):
        return [s.name for s in self.sensors]

    def index(self, name):
        for i, s in enumerate(self.sensors):
            if s.name == name:
                return i
        raise SlocumFileError(f'{self.path}: no sensor {name!r} in its cycles')

    def units(self, name):
        return self.sensors[self.index(name)].units

    @property
    def time_sensor(self):
        for name in TIME_SENSORS:
            if name in self.names:
                return name
        raise SlocumFileError(f'{self.path}: none of {", ".join(TIME_SENSORS)} in its cycles: '
                              'no time')

    def get(self, name, repeats=False):
        """(t, v): the cycles' times (s since 1970-01-01 UTC, the log's own present-time
        sensor) and values of one sensor where it was updated with a new value (state 2), or
        also where it was written again unchanged (state 1) if repeats."""
        j = self.index(name)
        col = self.state[:, j]
        keep = (col == STATE_NEW) | (repeats & (col == STATE_SAME))
        return self.values[keep, self.index(self.time_sensor)], self.values[keep, j]


def parse_header(data, path):
    """(tags dict, offset after the header) of a log's ASCII header."""
    tags = {}
    pos = 0
    n_tags = None
    while n_tags is None or len(tags) < n_tags:
        end = data.find(b'\n', pos)
        if end < 0 or end - pos > 512:
            raise SlocumFileError(f'{path}: byte {pos}: header line not terminated; not a '
                                  'Slocum binary log?')
        line = data[pos:end].decode('ascii', 'replace')
        key, sep, value = line.partition(':')
        if not sep:
            raise SlocumFileError(f'{path}: byte {pos}: header line {line!r} is not '
                                  '"key: value"')
        tags[key.strip()] = value.strip()
        pos = end + 1
        if key.strip() == 'num_ascii_tags':
            n_tags = _int_tag(tags, 'num_ascii_tags', path)
    if 'dbd_label' not in tags:
        raise SlocumFileError(f'{path}: no dbd_label in the header: not a Slocum binary log')
    for key in REQUIRED_TAGS:
        if key not in tags:
            raise SlocumFileError(f'{path}: header has no {key!r}')
    return tags, pos


def _int_tag(tags, key, path):
    try:
        return int(tags[key])
    except ValueError:
        raise SlocumFileError(f'{path}: header {key}: {tags[key]!r} is not an integer') from None


def parse_sensor_lines(lines, where):
    """The cycle's sensors (cycle order) of ``s: T|F index cycle_index bytes name units``
    lines."""
    sensors = []
    for k, line in enumerate(lines):
        cells = line.split()
        if len(cells) != 7 or cells[0] != 's:' or cells[1] not in ('T', 'F'):
            raise SlocumFileError(f'{where}: sensor line {k + 1} {line.strip()!r} is not '
                                  '"s: T|F index cycle_index bytes name units"')
        if cells[1] == 'F':
            continue
        try:
            cycle_index, size = int(cells[3]), int(cells[4])
        except ValueError:
            raise SlocumFileError(f'{where}: sensor line {k + 1}: index or size is not an '
                                  'integer') from None
        if size not in VALUE_TYPES:
            raise SlocumFileError(f'{where}: sensor {cells[5]}: {size} bytes; a value is 1, 2, '
                                  '4 or 8 bytes')
        sensors.append(Sensor(cells[5], cells[6], size, cycle_index))
    sensors.sort(key=lambda s: s.cycle_index)
    if [s.cycle_index for s in sensors] != list(range(len(sensors))):
        raise SlocumFileError(f'{where}: the sensors in use are not numbered 0..'
                              f'{len(sensors) - 1} in the cycle')
    return sensors


def cached_sensor_list(crc, path, cache_dirs):
    """The sensor lines of the cache file ``<crc>.cac`` in the first of cache_dirs holding
    it."""
    for d in cache_dirs:
        cac = Path(d) / f'{crc.lower()}.cac'
        if cac.is_file():
            return cac, cac.read_text('ascii', 'replace').splitlines()
    raise SlocumFileError(f'{path}: its sensor list is factored out (sensor_list_crc {crc}) '
                          f'and no {crc.lower()}.cac is in {", ".join(map(str, cache_dirs))}')


def _known_bytes(data, pos, path):
    """True if big-endian, from the 16 known bytes at pos."""
    block = data[pos:pos + KNOWN_BYTES]
    if len(block) < KNOWN_BYTES or block[0:1] != b's' or block[1:2] != b'a':
        raise SlocumFileError(f'{path}: byte {pos}: the known bytes (s, a, 0x1234, 123.456, '
                              '123456789.12345) are missing')
    for order, big in (('>', True), ('<', False)):
        i16 = np.frombuffer(block, order + 'i2', 1, 2)[0]
        f32 = np.frombuffer(block, order + 'f4', 1, 4)[0]
        f64 = np.frombuffer(block, order + 'f8', 1, 8)[0]
        if (i16 == KNOWN_INT16 and abs(f32 - KNOWN_FLOAT32) < 1e-3
                and abs(f64 - KNOWN_FLOAT64) < 1e-6):
            return big
    raise SlocumFileError(f'{path}: byte {pos}: the known bytes read as neither big- nor '
                          'little-endian 0x1234, 123.456, 123456789.12345')


def read_slocum(path, cache_dirs=None):
    """Read one Slocum binary log (module docstring) into a :class:`SlocumLog`.

    cache_dirs : directories searched for the ``<crc>.cac`` sensor list of a factored file
        (default: the log's own directory)
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise SlocumFileError(f'{path}: cannot read: {exc.strerror}') from None
    tags, pos = parse_header(data, path)
    n_total = _int_tag(tags, 'total_num_sensors', path)
    n_cycle = _int_tag(tags, 'sensors_per_cycle', path)
    n_state = _int_tag(tags, 'state_bytes_per_cycle', path)
    if tags.get('sensor_list_factored', '0') == '1':
        where, lines = cached_sensor_list(tags['sensor_list_crc'], path,
                                          cache_dirs or [path.parent])
    else:
        lines = []
        for _ in range(n_total):
            end = data.find(b'\n', pos)
            if end < 0:
                raise SlocumFileError(f'{path}: byte {pos}: the sensor list ends early')
            lines.append(data[pos:end].decode('ascii', 'replace'))
            pos = end + 1
        where = path
    if len(lines) != n_total:
        raise SlocumFileError(f'{where}: {len(lines)} sensor lines, the header of {path.name} '
                              f'says total_num_sensors {n_total}')
    sensors = parse_sensor_lines(lines, where)
    if len(sensors) != n_cycle or n_state != (n_cycle + 3) // 4:
        raise SlocumFileError(f'{path}: {len(sensors)} sensors in use and {n_state} state '
                              f'bytes; the header says sensors_per_cycle {n_cycle}')
    big = _known_bytes(data, pos, path)
    pos += KNOWN_BYTES
    state, values, complete = _read_cycles(data, pos, sensors, n_state, big, path)
    return SlocumLog(path=path, sha256=hashlib.sha256(data).hexdigest(), header=tags,
                     sensors=sensors, state=state, values=values, complete=complete,
                     big_endian=big)


def _read_cycles(data, pos, sensors, n_state, big, path):
    """(state, values, complete) of the cycles from byte pos on."""
    order = '>' if big else '<'
    n = len(sensors)
    size = np.array([s.size for s in sensors])
    buf = np.frombuffer(data, np.uint8)
    shifts = np.array([6, 4, 2, 0], dtype=np.uint8)
    current = np.full(n, np.nan)
    states, rows = [], []
    complete = False
    while pos < len(data):
        tag = data[pos:pos + 1]
        if tag == b'X':
            complete = True
            break
        if tag != b'd':
            raise SlocumFileError(f'{path}: byte {pos}: {tag!r} where a cycle ("d") or the end '
                                  'mark ("X") should be')
        if pos + 1 + n_state > len(data):
            break
        sb = buf[pos + 1:pos + 1 + n_state]
        st = ((sb[:, None] >> shifts) & 3).reshape(-1)[:n].astype(np.int8)
        new = np.flatnonzero(st == STATE_NEW)
        sizes = size[new]
        start = pos + 1 + n_state
        end = start + int(sizes.sum())
        if end > len(data):
            break
        offsets = start + np.concatenate(([0], np.cumsum(sizes)[:-1]))
        for nbytes, code in VALUE_TYPES.items():
            sel = sizes == nbytes
            if not sel.any():
                continue
            raw = buf[offsets[sel][:, None] + np.arange(nbytes)]
            current[new[sel]] = raw.copy().view(order + code).reshape(-1)
        states.append(st)
        rows.append(current.copy())
        pos = end
    if not rows:
        return np.zeros((0, n), np.int8), np.zeros((0, n)), complete
    return np.array(states), np.array(rows), complete


def read_slocum_files(paths, cache_dirs=None):
    """The :class:`SlocumLog` of each path, in the order of their first time."""
    logs = [read_slocum(p, cache_dirs) for p in paths]
    return sorted(logs, key=lambda lg: np.nanmin(lg.values[:, lg.index(lg.time_sensor)]))
