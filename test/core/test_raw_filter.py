"""The asynchronous multi-rate raw-sensor pass (core/filter/raw.py, core/identification/raw.py)
on runs of the independent generator (offline/independent_data.py generate_raw)."""
import math

import numpy as np
import pytest

from auv_ident.analysis.raw_comparison import sensors_of
from auv_ident.core.errors import ConfigError, DataError
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.filter.raw import RawMeasurement, RawSensorConfig, RawSensorFilter
from auv_ident.core.identification.raw import identify_raw
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import COEFFICIENTS
from auv_ident.offline.independent_data import DataConfig, generate_raw, RawConfig
from auv_ident.vehicles import load_vehicle

NAMES = ['Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v']


@pytest.fixture(scope='module')
def quiet_run():
    """20 s, noise at 1 % of the documented level, every sensor error drawn."""
    cfg = RawConfig(data=DataConfig(duration=20.0, seed=5, integrator='rk4', rk4_dt=0.005),
                    noise_level=(0.01, 0.01), noise_tau=(0.0, 0.0))
    return cfg, generate_raw(cfg)


@pytest.fixture(scope='module')
def model():
    return Model(load_vehicle('nps_auv2'), NAMES)


def test_quiet_run_gives_the_truth_and_the_sensor_errors(quiet_run, model):
    cfg, run = quiet_run
    res = identify_raw(model, FilterConfig(), run.records, sensors_of(cfg), passes=2)
    truth = np.array([run.truth['coefficients'][n] for n in NAMES])
    err = np.abs(res.estimate - truth) / np.abs(truth)
    assert np.all(err < 0.01), dict(zip(NAMES, err))
    te = run.truth['sensor_errors']
    mis, mis_sd = res.errors['dvl_misalignment']
    assert abs(mis - te['dvl_misalignment']) < max(3 * mis_sd, math.radians(0.05))
    assert abs(math.degrees(te['dvl_misalignment'])) >= 1.0
    for k, b in zip(('gyro_bias_p', 'gyro_bias_q', 'gyro_bias_r'), te['gyro_bias']):
        assert abs(res.errors[k][0] - b) < 5e-5
    assert res.fused['imu'] == run.truth['counts']['imu']
    assert res.fused['dvl'] == run.truth['counts']['dvl']
    assert res.skipped == {}
    # the noise shown by the first pass's innovations is below the declared (1 %): the weights
    # stay the declared ones, settled after the two passes asked for
    assert res.passes == 2
    assert res.noise_scale['attitude'] == 1.0


def test_ignoring_the_dvl_misalignment_biases_the_sway_and_heave_terms(quiet_run, model):
    """The same quiet run with the DVL errors held at 0: what a filter without the error terms
    makes of a 1-2 deg misalignment (the reason they are states)."""
    cfg, run = quiet_run
    held = RawSensorConfig(mountings=sensors_of(cfg).mountings,
                           estimate=('gyro_bias_p', 'gyro_bias_q', 'gyro_bias_r'))
    res = identify_raw(model, FilterConfig(), run.records, held, passes=2)
    truth = np.array([run.truth['coefficients'][n] for n in NAMES])
    err = np.abs(res.estimate - truth) / np.abs(truth)
    assert np.max(err) > 0.02, dict(zip(NAMES, err))


def test_records_out_of_order_are_one_error_naming_the_record(quiet_run, model):
    cfg, run = quiet_run
    recs = list(run.records[:200])
    recs[150], recs[151] = recs[151], recs[150]
    if recs[150].t == recs[151].t:
        recs[151] = RawMeasurement(recs[151].kind, recs[150].t - 0.001, recs[151].values,
                                   recs[151].covariance)
    with pytest.raises(DataError, match='record 151'):
        identify_raw(model, FilterConfig(), recs, sensors_of(cfg), passes=1)


def test_messages_before_a_command_and_an_orientation_wait(quiet_run, model):
    cfg, run = quiet_run
    sensors_only = [m for m in run.records if m.kind != 'command']
    f = RawSensorFilter(model, FilterConfig(), sensors_of(cfg))
    for m in sensors_only[:20]:
        assert f.process(m) == 'waiting'
    first_cmd = next(m for m in run.records if m.kind == 'command')
    assert f.process(first_cmd) == 'command'
    imu = next(m for m in sensors_only[20:] if m.kind == 'imu')
    assert f.process(imu) == 'fused'
    assert f.skipped == {'waiting': 20}


def test_a_silence_longer_than_the_bridge_restarts_the_vehicle_states(quiet_run, model):
    cfg, run = quiet_run
    recs = [m for m in run.records if not (5.0 <= m.t < 6.0)]
    f = RawSensorFilter(model, FilterConfig(), sensors_of(cfg))
    for m in recs:
        f.process(m)
    assert f.restarts == 1
    assert f.skipped.get('waiting', 0) < 10      # only until the next IMU message


def test_bad_records_and_settings_are_named():
    with pytest.raises(ConfigError, match='lidar'):
        RawMeasurement('lidar', 0.0, np.zeros(3))
    with pytest.raises(DataError, match='dvl at t = 1.5: 2 values'):
        RawMeasurement('dvl', 1.5, np.zeros(2))
    with pytest.raises(DataError, match='covariance'):
        RawMeasurement('dvl', 1.5, np.zeros(3), np.eye(2))
    with pytest.raises(ConfigError, match='dvl_reference'):
        RawSensorConfig(dvl_reference='bottom')
    with pytest.raises(ConfigError, match='gyro_drift'):
        RawSensorConfig(estimate=('gyro_drift',))
    with pytest.raises(ConfigError, match='passes'):
        identify_raw(Model(load_vehicle('nps_auv2'), NAMES), FilterConfig(), [], passes=0)


@pytest.mark.parametrize('dvl', ['ground', 'water'])
def test_bottom_and_water_track_with_a_current(dvl):
    """A 0.22 m/s current, the filter's velocities over ground, the current identified: a
    bottom-tracking DVL sees the velocity over ground, so the dynamics (acting on the velocity
    through the water) separate the current; a water-tracking one sees the velocity through the
    water, which gives the coefficients directly but nothing of the current without a position
    fix (its 1-sigma stays near the prior's)."""
    from dataclasses import replace
    cfg = RawConfig(data=DataConfig(duration=60.0, seed=5, integrator='rk4', rk4_dt=0.005,
                                    current_ned=(0.2, -0.1, 0.0), dvl=dvl),
                    noise_level=(0.01, 0.01), noise_tau=(0.0, 0.0))
    run = generate_raw(cfg)
    m = Model(load_vehicle('nps_auv2'), NAMES + ['current_n', 'current_e'])
    res = identify_raw(m, FilterConfig(), run.records,
                       replace(sensors_of(cfg), dvl_reference=dvl))
    truth = np.array([run.truth['coefficients'][n] for n in NAMES])
    assert np.all(np.abs(res.estimate[:5] - truth) < 0.01 * np.abs(truth))
    if dvl == 'ground':
        np.testing.assert_allclose(res.estimate[5:], [0.2, -0.1], atol=0.01)
    else:
        assert np.all(res.std[5:] > 0.1)


def _awkward_records(run):
    """The run's records with what the compiled IMU steps leave to Python: a 0.5 s silence (a
    restart), a non-finite IMU rate, an IMU message stamped before the estimate, and the IMU
    covariance array changing after 12 s."""
    recs = [r for r in run.records if not 5.0 < r.t < 5.5]
    k = next(i for i, r in enumerate(recs) if r.kind == 'imu' and r.t > 8.0)
    recs[k] = RawMeasurement('imu', recs[k].t, np.r_[recs[k].values[:4], np.nan, 0.0, 0.0])
    k2 = next(i for i, r in enumerate(recs) if r.kind == 'imu' and r.t > 9.0)
    recs.insert(k2 + 2, RawMeasurement('imu', recs[k2].t - 0.005, recs[k2].values))
    for i, r in enumerate(recs):
        if r.kind == 'imu' and r.t > 12.0:
            recs[i] = RawMeasurement('imu', r.t, r.values, np.diag([1e-4] * 3 + [1e-5] * 3))
    return recs


def _assert_same_pass(a, b):
    """Two filters over _awkward_records: the same restart, skips, counts, state, covariance,
    NIS and information sums, to the bit."""
    assert a.restarts == b.restarts == 1
    assert a.skipped == b.skipped and a.skipped['out of order'] == 1
    assert a.fused == b.fused
    np.testing.assert_array_equal(a.xf, b.xf)
    np.testing.assert_array_equal(a.P, b.P)
    assert a.nis_sum == b.nis_sum and a.dof_sum == b.dof_sum
    for g in a.info:
        np.testing.assert_array_equal(a.info[g], b.info[g])


def test_process_many_is_process_one_by_one_bit_for_bit(quiet_run, model):
    """The compiled IMU runs (raw_update.imu_run) do what process does message by message, the
    messages it leaves to Python included: a gap to restart after, a non-finite IMU rate, an
    IMU message stamped before the estimate, a covariance array changing mid-run."""
    cfg, run = quiet_run
    recs = _awkward_records(run)
    one, many = (RawSensorFilter(model, FilterConfig(), sensors_of(cfg)) for _ in range(2))
    for r in recs:
        one.process(r)
    many.process_many(recs)
    _assert_same_pass(one, many)
    for g in one.white:
        np.testing.assert_array_equal(np.array(one.white[g]), np.array(many.white[g]))


def test_process_imu_is_process_bit_for_bit(quiet_run, model):
    """The live node's one-message IMU step (process_imu: the compiled run of one, no record
    built) gives what process gives the same message, bit for bit, over the messages it
    leaves to Python too (the start, a gap, a non-finite rate, one stamped before the
    estimate, a covariance changing); and a filter that keeps no whitened innovations
    (keep_white False, the live node's) has the same estimates and figures."""
    cfg, run = quiet_run
    recs = _awkward_records(run)
    one = RawSensorFilter(model, FilterConfig(), sensors_of(cfg))
    live = RawSensorFilter(model, FilterConfig(), sensors_of(cfg), keep_white=False)
    for r in recs:
        what = one.process(r)
        if r.kind == 'imu':
            got = live.process_imu(r.t, tuple(r.values[:4]), tuple(r.values[4:]), r.covariance,
                                   r.sensor)
        else:
            got = live.process(r)
        assert got == what, r
    _assert_same_pass(one, live)
    assert one.white and not live.white
    est, std, cov, finite = live.coefficient_block()
    c = slice(COEFFICIENTS.start, COEFFICIENTS.start + model.p)
    assert finite and np.array_equal(est, one.xf[c]) and np.array_equal(cov, one.P[c, c])
    np.testing.assert_array_equal(std, np.sqrt(np.diag(one.P[c, c])))


def test_imu_messages_without_a_covariance_get_the_default_noise(quiet_run, model):
    """An IMU stream without covariances (a bag whose driver leaves them -1) is fused with the
    default IMU noise; the reused noise matrix started as "made of None", so such a stream
    was fused with zero noise and the filter blew up within 0.1 s."""
    cfg, run = quiet_run
    recs = [RawMeasurement('imu', r.t, r.values, None, r.sensor) if r.kind == 'imu' else r
            for r in run.records if r.t < 5.0]
    f = RawSensorFilter(model, FilterConfig(), sensors_of(cfg))
    for r in recs:
        f.process(r)
    assert f.fused['imu'] > 400 and f.restarts == 0
    assert np.all(np.isfinite(f.xf)) and np.all(np.isfinite(f.P))
