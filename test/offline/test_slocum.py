"""The Slocum binary log reader (offline/slocum.py): small logs written here byte by byte
from the format's description (both byte orders, an inline and a cached sensor list, every
state, a cut file, every bad-input error), then the comet glider's 20 real logs: every file
read, times monotonic, and the pressure they hold against the processed file's
(``gliderflight_data.npy``, made by another program, dbdreader, from the same logs)."""
import numpy as np
import pytest
import slocum_data

from auv_ident.offline.slocum import (
    read_slocum,
    read_slocum_files,
    SlocumFileError,
    STATE_NEW,
    STATE_NOT_UPDATED,
    STATE_SAME,
)

SENSORS = [('m_present_time', 'timestamp', 8), ('m_depth', 'm', 4), ('x_mode', 'enum', 1),
           ('x_count', 'nodim', 2), ('m_unused', 'X', 4)]
CODES = {1: 'i1', 2: 'i2', 4: 'f4', 8: 'f8'}


def sensor_lines(in_use=(True, True, True, True, False)):
    lines, k = [], 0
    for i, ((name, units, size), used) in enumerate(zip(SENSORS, in_use)):
        lines.append(f's: {"T" if used else "F"} {i:4d} {k if used else -1:4d} {size} {name} '
                     f'{units}')
        k += used
    return lines


def log_bytes(cycles, order='>', factored=False, crc='0badcafe', end=True):
    """A log of the cycles, each a list of (state, value) per sensor in use (4 of them)."""
    n = 4
    tags = [('dbd_label', 'DBD(dinkum_binary_data)file'), ('encoding_ver', '5'),
            ('num_ascii_tags', '9'), ('all_sensors', 'F'), ('total_num_sensors', '5'),
            ('sensors_per_cycle', str(n)), ('state_bytes_per_cycle', '1'),
            ('sensor_list_crc', crc), ('sensor_list_factored', '1' if factored else '0')]
    out = ''.join(f'{k}:    {v}\n' for k, v in tags).encode()
    if not factored:
        out += ''.join(line + '\n' for line in sensor_lines()).encode()
    out += b'sa' + np.array([0x1234], order + 'i2').tobytes()
    out += np.array([123.456], order + 'f4').tobytes()
    out += np.array([123456789.12345], order + 'f8').tobytes()
    used = [s for s, u in zip(SENSORS, (True, True, True, True)) if u]
    for cycle in cycles:
        byte = 0
        for i, (state, _) in enumerate(cycle):
            byte |= state << (6 - 2 * i)
        out += b'd' + bytes([byte])
        for (state, value), (_, _, size) in zip(cycle, used):
            if state == STATE_NEW:
                out += np.array([value], order + CODES[size]).tobytes()
    return out + (b'X' if end else b'')


CYCLES = [[(2, 1000.0), (2, 1.5), (2, 3), (2, -7)],
          [(2, 1001.0), (1, None), (0, None), (2, 300)],
          [(2, 1002.5), (2, 2.25), (2, -2), (1, None)]]


@pytest.mark.parametrize('order', ['>', '<'])
def test_states_values_and_byte_order(tmp_path, order):
    path = tmp_path / 'a.dbd'
    path.write_bytes(log_bytes(CYCLES, order))
    log = read_slocum(path)
    assert log.big_endian == (order == '>') and log.complete
    assert log.names == ['m_present_time', 'm_depth', 'x_mode', 'x_count']
    assert log.state.tolist() == [[2, 2, 2, 2], [2, STATE_SAME, STATE_NOT_UPDATED, 2],
                                  [2, 2, 2, STATE_SAME]]
    assert log.values[:, 1].tolist() == [1.5, 1.5, 2.25]     # held through states 0 and 1
    assert log.values[:, 2].tolist() == [3, 3, -2]
    assert log.values[:, 3].tolist() == [-7, 300, 300]
    t, v = log.get('m_depth')
    assert t.tolist() == [1000.0, 1002.5] and v.tolist() == [1.5, 2.25]
    t, v = log.get('m_depth', repeats=True)
    assert t.tolist() == [1000.0, 1001.0, 1002.5]
    assert log.units('m_depth') == 'm' and log.time_sensor == 'm_present_time'


def test_factored_list_from_the_cache_and_a_cut_file(tmp_path):
    path = tmp_path / 'b.ebd'
    path.write_bytes(log_bytes(CYCLES, factored=True, end=False)[:-1])    # last value cut
    with pytest.raises(SlocumFileError, match='0badcafe.cac'):
        read_slocum(path)
    cache = tmp_path / 'cache'
    cache.mkdir()
    (cache / '0badcafe.cac').write_text('\n'.join(sensor_lines()) + '\n')
    log = read_slocum(path, cache_dirs=[cache])
    assert not log.complete and log.values.shape == (2, 4)


@pytest.mark.parametrize('damage, match', [
    (lambda b: b.replace(b'sa\x12\x34', b'sa\x56\x78'), 'known bytes read as neither'),
    (lambda b: b.replace(b'dbd_label', b'xxx_label'), 'no dbd_label'),
    (lambda b: b.replace(b'sensors_per_cycle:    4', b'sensors_per_cycle:    5'),
     'sensors_per_cycle 5'),
    (lambda b: b.replace(b'total_num_sensors:    5', b'total_num_sensors:    x'),
     'not an integer'),
    (lambda b: b.replace(b' 4 m_depth', b' 3 m_depth'), '3 bytes'),
    (lambda b: b[:-1] + b'Q', "b'Q' where a cycle"),
    (lambda b: b'\x00' * 600, 'not terminated'),
])
def test_bad_files_name_the_culprit(tmp_path, damage, match):
    path = tmp_path / 'c.dbd'
    path.write_bytes(damage(log_bytes(CYCLES)))
    with pytest.raises(SlocumFileError, match=match) as err:
        read_slocum(path)
    assert str(path) in str(err.value)


def test_every_real_log_read_with_monotonic_times():
    data = slocum_data.require()
    paths = sorted(data.glob('*.dbd')) + sorted(data.glob('*.ebd'))
    assert len(paths) == 20
    for path in paths:
        log = read_slocum(path)
        assert log.complete and log.big_endian, path
        t, _ = log.get(log.time_sensor)
        assert len(t) == log.values.shape[0] and np.all(np.isfinite(t)), path
        # the first cycle of a file repeats the time of the second (the values at file open)
        assert np.all(np.diff(t) >= 0) and np.all(np.diff(t)[1:] > 0), path
        assert 1466704000 < t[0] < t[-1] < 1466720000, path      # 23 June 2016, 17:46-22:13
    logs = read_slocum_files(paths)
    firsts = [lg.get(lg.time_sensor)[0][0] for lg in logs]
    assert firsts == sorted(firsts)


def _stacked(logs, name, time_name=None):
    t, v = [], []
    for log in logs:
        tk, vk = log.get(name)
        if time_name is not None:
            tk = log.values[log.state[:, log.index(name)] == STATE_NEW, log.index(time_name)]
        t.append(tk)
        v.append(vk)
    t, v = np.concatenate(t), np.concatenate(v)
    order = np.argsort(t, kind='stable')
    return t[order], v[order]


def test_pressure_agrees_with_the_processed_file():
    """The processed file's time is the CTD's own stamp and its pressure the science
    computer's sci_water_pressure: at the same stamps they are the same numbers; the glider's
    own m_pressure (every ~4 s, another sensor) follows within its lag."""
    data = slocum_data.require()
    npy = np.load(data / slocum_data.NPY_NAME)
    science = read_slocum_files(sorted(data.glob('*.ebd')))
    t_ctd, p_sci = _stacked(science, 'sci_water_pressure', 'sci_ctd41cp_timestamp')
    same = np.isin(npy[0], t_ctd)
    assert same.mean() > 0.97
    at = np.searchsorted(t_ctd, npy[0][same])
    assert np.allclose(p_sci[at], npy[1][same], atol=1e-6)
    engineering = read_slocum_files(sorted(data.glob('*.dbd')))
    t_eng, p_eng = _stacked(engineering, 'm_pressure')
    diff = np.interp(npy[0], t_eng, p_eng) - npy[1]
    assert abs(np.median(diff)) < 0.02                     # bar, 0.2 m
    assert np.percentile(np.abs(diff), 95) < 0.08          # descent 0.15 m/s x 4 s sampling
    depth_t, depth = _stacked(engineering, 'm_depth')
    # m_depth is the glider's 10 m/bar x m_pressure, to float32 rounding at most cycles
    depth_diff = np.abs(np.interp(depth_t, t_eng, p_eng) * 10.0 - depth)
    assert np.percentile(depth_diff, 90) < 1e-5 and depth_diff.max() < 0.25
