"""The glider flight model (core/glider): the steady glide's force balance, the dynamic model
settling on it, and calibrations on synthetic dives with known parameters (flown by the
dynamic model itself, with white pressure noise and a coloured vertical water velocity): the
known values recovered within the sandwich error bars, the unidentifiable terms said so; bad
input named."""
from dataclasses import replace
import math

from glider_dives import dvl_on_descents, PRIOR, synthetic_dives, TRUE
import numpy as np
import pytest

from auv_ident.core.errors import ConfigError, DataError
from auv_ident.core.glider.calibration import calibrate, identifiability
from auv_ident.core.glider.flight import (
    angle_of_attack,
    dynamic_flight,
    steady_flight,
)
from auv_ident.core.glider.record import GliderRecord
from auv_ident.core.glider.validation import (
    compare_speeds,
    consistent_dvl,
    dive_groups,
    score,
)


def test_steady_glide_balances_the_forces():
    params = PRIOR
    pitch = np.array([-0.6, -0.38, -0.33, 0.33, 0.38, 0.6])
    alpha = angle_of_attack(pitch, params.drag_zero_lift, params.induced_drag,
                            params.lift_slope)
    assert np.all(np.sign(alpha) == -np.sign(pitch)) and np.all(np.abs(alpha) < 0.1)
    # the front of the polar: h(a) = C_La a tan(|theta| + a) - C_D0 - C_D1 a^2 has two roots
    # at these pitches; the flight is the first (h < 0 on a fine grid below it)
    for th, a in zip(np.abs(pitch), np.abs(alpha)):
        grid = np.linspace(0.0, a, 2000)[:-1]
        h = (params.lift_slope * grid * np.tan(th + grid) - params.drag_zero_lift
             - params.induced_drag * grid ** 2)
        assert np.all(h < 0)
    # flatter than the best glide (tan gamma = 2 sqrt(C_D0 C_D1) / C_La: 18.4 deg at a pitch
    # of 11.5 deg with the published values):
    # no steady flight
    flat = angle_of_attack(np.array([-0.1, 0.0, 0.15]), params.drag_zero_lift,
                           params.induced_drag, params.lift_slope)
    assert np.all(np.isnan(flat))
    gamma = pitch - alpha
    cd = params.drag_zero_lift + params.induced_drag * alpha ** 2
    assert np.allclose(np.tan(gamma), -cd / (params.lift_slope * alpha), rtol=1e-9)
    n = len(pitch)
    rec = GliderRecord(t=np.arange(n) * 1.0, pressure=np.full(n, 2e5), pitch=pitch,
                       pumped_volume=np.where(pitch < 0, -200e-6, 200e-6),
                       density=np.full(n, 1005.0))
    flight = steady_flight(params, rec)
    q = 0.5 * 1005.0 * params.wing_area * flight.speed ** 2
    drag, lift = q * cd, q * params.lift_slope * alpha
    B = flight.buoyancy
    assert np.allclose(drag, B * np.sin(gamma)) and np.allclose(lift, -B * np.cos(gamma))
    assert np.all(flight.depth_rate * np.sign(-pitch) > 0)      # down when diving
    # pumped against the pitch (an inflection): no steady glide
    rec.pumped_volume[:] = -rec.pumped_volume
    assert np.all(steady_flight(params, rec).speed == 0.0)


def test_dynamic_flight_settles_on_the_steady_glide():
    params = PRIOR
    t = np.arange(0.0, 400.0)
    rec = GliderRecord(t=t, pressure=np.full(len(t), 2e5), pitch=np.full(len(t), -0.4),
                       pumped_volume=np.full(len(t), -200e-6), density=np.full(len(t), 1005.0))
    dyn, steady = dynamic_flight(params, rec), steady_flight(params, rec)
    assert dyn.speed[0] == 0.0 and dyn.speed[20] < steady.speed[20]
    assert dyn.speed[-1] == pytest.approx(steady.speed[-1], rel=1e-6)
    assert dyn.angle_of_attack[-1] == pytest.approx(steady.angle_of_attack[-1], rel=1e-5)


@pytest.mark.parametrize('seed', [1, 2, 3])
def test_calibration_recovers_known_parameters_within_its_error_bars(seed):
    rec = synthetic_dives(TRUE, seed)
    # from the published values: Cd0 0.15, V_g 60/1005
    cal = calibrate(rec, PRIOR, 'dynamic', ('hull_volume', 'drag_zero_lift', 'compressibility'))
    for name, (value, std) in cal.estimates().items():
        truth = getattr(TRUE, name)
        assert abs(value - truth) < 3.0 * std, (name, value, truth, std)
    v, s = cal.estimates()['drag_zero_lift']
    # informative bars: well inside the prior's uncertainty (0.01, 1e-4 m^3)
    assert s < 0.01 and cal.estimates()['hull_volume'][1] < 3e-5
    assert cal.lags > 1 and cal.seconds < 60.0
    # the flown speed (a perfect "DVL"): the parameters' errors leave well under 1 cm/s
    check = consistent_dvl(rec)
    assert check.keep.any() and all(d.kept for d in check.dives)
    s = score(dynamic_flight(cal.params, rec), rec, check.keep, cal.window)
    assert abs(s.speed_bias) < 0.01 and s.speed_rms < 0.01 and s.speed_fit > 75.0


def test_a_trial_step_beyond_the_physical_values_is_refused_not_raised():
    """From a prior far off (a lift slope of 4 against 7.5), Levenberg-Marquardt's first step
    (up to 100 scale units) lands on a negative C_D0: the step is refused and the fit goes on
    below that of V_g alone, rather than the parameter check's error escaping the fit."""
    rec = synthetic_dives(TRUE, 6)
    start = replace(PRIOR, lift_slope=4.0)
    volume_only = calibrate(rec, start, 'dynamic', ('hull_volume',))
    cal = calibrate(rec, start, 'dynamic', ('hull_volume', 'drag_zero_lift'))
    assert cal.params.drag_zero_lift > 0.0 and cal.rms < volume_only.rms


def test_what_constant_pitch_dives_cannot_identify():
    rec = synthetic_dives(TRUE, 4)
    cal = calibrate(rec, PRIOR, 'dynamic', ('hull_volume', 'drag_zero_lift'))
    verdicts = identifiability(rec, cal, extra=('lift_slope', 'induced_drag', 'mass'))
    assert cal.verdicts['hull_volume']['verdict'] == 'identifiable'
    # at one pitch the angle of attack is one number: lift and induced drag trade with C_D0,
    # and the mass with the hull volume (only rho V_g - m counts)
    for name in ('lift_slope', 'induced_drag', 'mass'):
        assert verdicts[name]['verdict'] != 'identifiable', (name, verdicts[name])
    assert verdicts['mass']['correlated_with'] == 'hull_volume'
    assert verdicts['mass']['max_correlation'] > 0.99


def test_the_dvl_consistency_check_fails_the_dive_where_the_instruments_disagree():
    rec = dvl_on_descents(synthetic_dives(TRUE, 6))
    check = consistent_dvl(rec)
    assert len(check.dives) == 6 and all(d.kept for d in check.dives)
    assert abs(check.centre_deg) < 6.0 and 3.0 < check.z_limit < 4.0
    # the DVL reads 25 % slow on one dive (as the comet's last): the pressure and the pitch
    # then need an angle of attack near 10 deg more there, far outside the others' spread
    start = np.searchsorted(rec.t, check.dives[3].start)
    stop = np.searchsorted(rec.t, check.dives[4].start)
    slow = rec.speed_through_water.copy()
    slow[start:stop] *= 0.75
    check = consistent_dvl(replace(rec, speed_through_water=slow))
    assert [d.kept for d in check.dives] == [i != 3 for i in range(6)]
    assert check.dives[3].z > check.z_limit + 1.0 and check.dives[3].median_aoa_deg > 10.0
    assert not check.keep[start:stop].any() and check.keep[stop:].any()
    assert check.flagged == [check.dives[3]]
    # the evidence: the speed the dive's depth rate and pitch imply at the others' angle of
    # attack, which the DVL reads on the other dives to within the heave's +-5 % of the depth
    # rate; on the slow dive a quarter below what the others read against theirs
    ratios = np.array([d.dvl_speed / d.implied_speed for d in check.dives])
    others = np.delete(ratios, 3)
    assert np.all(np.abs(others - 1.0) < 0.15) and np.ptp(others) < 0.12
    assert abs(ratios[3] / np.median(others) - 0.75) < 0.05
    # too few dives for a spread: none judged, every one kept
    few = consistent_dvl(replace(rec, speed_through_water=np.where(
        rec.t < check.dives[3].start, slow, np.nan)))
    assert len(few.dives) == 3 and np.isnan(few.z_limit) and all(d.kept for d in few.dives)


def test_the_scores_error_bars_count_dives_not_samples():
    """A model off by a different constant on each dive (a current's, the DVL's per-dive
    processing): its bias's 1-sigma is the spread of the dive means over the dives (the
    cluster-robust one), not the samples' (200 a dive: ~15 times narrower)."""
    rec = dvl_on_descents(synthetic_dives(TRUE, 6))
    use = np.isfinite(rec.speed_through_water)
    groups = dive_groups(rec, use)
    offsets = np.array([0.004, -0.006, 0.011, 0.001, -0.003, 0.008])      # m/s, per dive
    assert len(groups) == len(offsets)
    speed = np.zeros(len(rec))
    for g, o in zip(groups, offsets):
        speed[g] = rec.speed_through_water[g] + o
    flight = replace(dynamic_flight(TRUE, rec), speed=speed)
    s = score(flight, rec, use, (10.0, 35.0))
    w = np.array([len(g) for g in groups]) / use.sum()
    expected = math.sqrt(6 / 5 * np.sum(w ** 2 * (offsets - np.sum(w * offsets)) ** 2))
    assert s.speed_bias == pytest.approx(np.sum(w * offsets))
    assert s.speed_bias_std == pytest.approx(expected) and s.speed_dives == 6
    # paired on the same samples: a model 1 cm/s further from the DVL on every sample than
    # another is worse by about 1 cm/s of RMS, though both share the per-dive offsets; the
    # same model against itself: no difference, no spread
    worse = compare_speeds(speed + 0.01, speed, rec, use)
    assert worse.difference == pytest.approx(worse.rms_a - worse.rms_b)
    d = 0.02 * offsets + 1e-4                   # per dive: (o + 0.01)^2 - o^2
    d_std = math.sqrt(6 / 5 * np.sum(w ** 2 * (d - np.sum(w * d)) ** 2))
    assert worse.difference_std == pytest.approx(d_std / (worse.rms_a + worse.rms_b))
    assert 0.005 < worse.difference < 0.011 and worse.difference > 2.0 * worse.difference_std
    assert worse.dives == 6 and worse.samples == use.sum()
    same = compare_speeds(speed, speed, rec, use)
    assert same.difference == 0.0 and same.difference_std == 0.0
    # one dive judged alone: no spread to judge by
    one = score(flight, rec, use & (rec.t < rec.t[groups[1][0]]), (10.0, 35.0))
    assert one.speed_dives == 1 and math.isnan(one.speed_bias_std)


def test_bad_input_is_named():
    with pytest.raises(ConfigError, match='drag_zero_lift'):
        replace(PRIOR, drag_zero_lift=-0.1)
    with pytest.raises(ConfigError, match='wing_span'):
        calibrate(synthetic_dives(TRUE, 5, n_cycles=1), PRIOR, 'dynamic', ('wing_span',))
    with pytest.raises(ConfigError, match='no parameter to calibrate'):
        calibrate(synthetic_dives(TRUE, 5, n_cycles=1), PRIOR, 'dynamic', ())
    with pytest.raises(DataError, match='pitch'):
        GliderRecord(t=np.arange(3.0), pressure=np.zeros(3), pitch=[0.0, np.nan, 0.0],
                     pumped_volume=np.zeros(3), density=np.full(3, 1000.0))
    with pytest.raises(DataError, match='rise'):
        GliderRecord(t=np.array([0.0, 1.0, 1.0]), pressure=np.zeros(3), pitch=np.zeros(3),
                     pumped_volume=np.zeros(3), density=np.full(3, 1000.0))
    shallow = synthetic_dives(TRUE, 5, n_cycles=1)
    with pytest.raises(DataError, match='depth window'):
        calibrate(shallow, PRIOR, window=(100.0, 200.0))
