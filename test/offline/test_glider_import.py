"""``import --format npy|slocum`` (offline/glider_import.py): the comet glider's processed file
and raw logs written as bags (strictly decodable, real stamps, the 6-DOF readers see our
joints), read back into the flight model's record to the bit, the raw logs against the
processed file (the density from the raw CTD, the pitch with the inclinometer's correction),
and the bad inputs named. The real data come from ../shared/realdata (skipped
without them); the bad-input cases use small files written here."""
from collections import Counter

from mcap.reader import make_reader
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores
import slocum_data

from auv_ident.cli import main as cli_main
from auv_ident.offline.glider_import import (
    ACTUATOR_TOPIC,
    CTD_TOPIC,
    DVL_TOPIC,
    ODOM_TOPIC,
    read_glider_bag,
    read_gliderflight_npy,
    read_slocum_logs,
    TOPIC_TYPES,
    write_glider_bag,
)
from auv_ident.offline.importers import RunFileError
from auv_ident.offline.replay import bag_custom_data
from auv_ident.session.messages import joint_state_to_actuators, odometry_to_state

JAZZY = get_typestore(Stores.ROS2_JAZZY)


@pytest.fixture(scope='module')
def npy_bag(tmp_path_factory):
    data = slocum_data.require()
    out = tmp_path_factory.mktemp('glider') / 'npy'
    assert cli_main(['import', '--format', 'npy', str(data / slocum_data.NPY_NAME),
                     '--out', str(out)]) == 0
    return out


def test_npy_bag_holds_the_file_to_the_bit(npy_bag):
    npy = np.load(slocum_data.SLOCUM_DIR / slocum_data.NPY_NAME)
    counts = Counter()
    with open(npy_bag / 'npy_0.mcap', 'rb') as fh:      # strict rosbags decoding
        for _, channel, message in make_reader(fh).iter_messages(log_time_order=True):
            msg = JAZZY.deserialize_cdr(message.data, TOPIC_TYPES[channel.topic])
            counts[channel.topic] += 1
            if channel.topic == ODOM_TOPIC and counts[ODOM_TOPIC] == 100:
                t_sec, x12, _, _ = odometry_to_state(msg)
                assert abs(t_sec - npy[0, 99]) < 1e-6        # real stamps, 2016
                assert x12[10] == pytest.approx(npy[2, 99], abs=1e-12)
                assert x12[8] == pytest.approx(npy[1, 99] * 1e5 / (npy[4, 99] * 9.81))
            if channel.topic == ACTUATOR_TOPIC and counts[ACTUATOR_TOPIC] == 1:
                _, u6 = joint_state_to_actuators(msg)     # the 6-DOF reader skips our joints
                assert np.all(u6 == 0.0)
    n = npy.shape[1]
    assert counts == {ODOM_TOPIC: n, ACTUATOR_TOPIC: n, CTD_TOPIC: n,
                      DVL_TOPIC: int(np.isfinite(npy[5]).sum())}
    rec = read_glider_bag(npy_bag)
    assert np.max(np.abs(rec.t - npy[0])) < 1e-6
    assert np.array_equal(rec.pressure, npy[1] * 1e5) and np.array_equal(rec.density, npy[4])
    assert np.allclose(rec.pitch, npy[2], atol=1e-15)
    assert np.array_equal(rec.pumped_volume, npy[3] * 1e-6)
    assert np.array_equal(np.isnan(rec.speed_through_water), np.isnan(npy[5]))
    assert np.array_equal(rec.speed_through_water[np.isfinite(npy[5])],
                          npy[5][np.isfinite(npy[5])])
    meta = bag_custom_data(npy_bag)
    assert meta['auv_ident.format'] == 'npy' and meta['auv_ident.stamp_epoch_ns'] == '0'


def test_raw_logs_against_the_processed_file(tmp_path):
    data = slocum_data.require()
    log = read_slocum_logs(sorted(data.glob('*.[de]bd')))
    npy = read_gliderflight_npy(data / slocum_data.NPY_NAME)
    same = np.isin(npy.t, log.t)
    assert same.mean() > 0.97
    at = np.searchsorted(log.t, npy.t[same])
    assert np.allclose(log.pressure[at], npy.pressure[same], atol=1e-6)
    # the processed pitch is the logged one x 0.86 - 0.004 rad (gliderflight's correction);
    # both interpolate the 4 s engineering samples onto the CTD times
    diff = log.pitch[at] * 0.86 - 0.004 - npy.pitch[same]
    assert np.median(np.abs(diff)) < 0.005
    assert np.median(np.abs(log.pumped_volume[at] - npy.pumped_volume[same])) < 2e-6
    assert np.all(np.isfinite(log.temperature)) and 4.0 < np.min(log.temperature) < 20.0
    # m_battpos (in) in m: within the glider's +-1.5 in travel, moved dive against climb
    battery = log.battery_position
    assert np.all(np.abs(battery) < 1.5 * 0.0254) and np.ptp(battery) > 0.5 * 0.0254
    # the density from the raw CTD (EOS-80 at the PSS-78 salinity) against the processed
    # file's TEOS-10 one: an offset of -0.053 kg/m^3 (TEOS-10's Baltic composition anomaly,
    # which EOS-80 does not know), the same to 0.006 kg/m^3 from the surface to 42 m
    d = log.density[at] - npy.density[same]
    assert -0.06 < np.median(d) < -0.045 and np.ptp(np.percentile(d, [1, 99])) < 0.008
    out = tmp_path / 'raw'
    assert cli_main(['import', '--format', 'slocum', *map(str, sorted(data.glob('*.[de]bd'))),
                     '--out', str(out), '--pitch-correction', '0.86,-0.004']) == 0
    meta = bag_custom_data(out)
    assert meta['auv_ident.format'] == 'slocum' and meta['auv_ident.measured'] == 'z phi theta psi'
    assert meta['auv_ident.samples'] == str(len(log.t))
    assert meta['auv_ident.pitch_correction'] == '0.86,-0.004'
    rec = read_glider_bag(out)          # the bag holds the log's samples, in order
    assert len(rec.t) == len(log.t) and np.array_equal(rec.density, log.density)
    assert np.allclose(rec.pitch, 0.86 * log.pitch - 0.004, atol=1e-12)


def test_bad_glider_inputs_are_named(tmp_path, capsys):
    bad = tmp_path / 'bad.npy'
    np.save(bad, np.zeros((5, 10)))
    with pytest.raises(RunFileError, match=r'shape \(5, 10\)'):
        read_gliderflight_npy(bad)
    text = tmp_path / 'text.npy'
    text.write_text('not numpy')
    with pytest.raises(RunFileError, match='not a numpy'):
        read_gliderflight_npy(text)
    assert cli_main(['import', '--format', 'npy', str(bad), str(bad),
                     '--out', str(tmp_path / 'x')]) != 0
    assert 'given 2 .npy' in capsys.readouterr().err
    assert cli_main(['import', '--format', 'npy', str(bad), '--start', '2016-06-23T00:00:00Z',
                     '--out', str(tmp_path / 'w')]) != 0
    assert 'carry their own times' in capsys.readouterr().err
    assert cli_main(['import', '--format', 'hsva', str(bad), str(bad),
                     '--out', str(tmp_path / 'y')]) != 0
    assert 'reads one file, not 2' in capsys.readouterr().err
    for argv, culprit in (
            (['--format', 'npy', str(bad), '--pitch-correction', '0.86,0'], 'processed file'),
            (['--format', 'hsva', str(bad), '--pitch-correction', '0.86,0'], 'not hsva'),
            (['--format', 'slocum', str(bad), '--pitch-correction', '0.86'], 'two numbers'),
            (['--format', 'slocum', str(bad), '--pitch-correction', '86,-0.004'],
             'an inclinometer calibration; this is not')):
        assert cli_main(['import', *argv, '--out', str(tmp_path / 'p')]) == 2
        err = capsys.readouterr().err
        assert culprit in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / 'p').exists()
    t = np.arange(5.0) + 1.5e9
    t[3] = t[2]
    rows = np.vstack([t, np.ones(5), -0.4 * np.ones(5), np.zeros(5), np.full(5, 1005.0),
                      np.full(5, np.nan)])
    np.save(tmp_path / 'dup.npy', rows)
    with pytest.raises(RunFileError, match='time does not increase at sample 3'):
        write_glider_bag(read_gliderflight_npy(tmp_path / 'dup.npy'), tmp_path / 'z')
