"""The glider campaign on the comet glider's real dives (analysis/glider.py, issue #31): the
processed file imported as a bag, the flight model calibrated on one half of the record and
judged on the other, both ways. Asserted: the issue's goals as the campaign reaches them
(docs/glider.md prints the table), and what it says the dives cannot identify. Skipped
without ../shared/realdata/slocum_comet."""
import numpy as np
import pytest
import slocum_data

from auv_ident.analysis.glider import format_campaign, run_campaign, run_variants
from auv_ident.cli import main as cli_main
from auv_ident.core.glider.vehicle import glider_from_file
from auv_ident.offline.glider_import import read_glider_bag
from auv_ident.vehicles import resolve_vehicle_path

BASELINE_RMS = 0.037        # m/s: gliderflight's steady calibration on the second half (#31)


@pytest.fixture(scope='module')
def record(tmp_path_factory):
    data = slocum_data.require()
    bag = tmp_path_factory.mktemp('comet') / 'bag'
    logs = [str(p) for p in sorted(data.glob('*.[de]bd'))]      # for the water temperature
    assert cli_main(['import', '--format', 'npy', str(data / slocum_data.NPY_NAME), *logs,
                     '--out', str(bag)]) == 0
    return read_glider_bag(bag)


@pytest.fixture(scope='module')
def prior():
    return glider_from_file(resolve_vehicle_path('slocum_comet')).params


@pytest.fixture(scope='module')
def campaign(record, prior):
    return run_campaign(record, prior)


def test_no_term_ours_leaves_out_improves_both_halves(record, prior):
    """Each term ours leaves out (a time lag of the pitch, the pump or the density, the
    compressibility, gliderflight's 70 kg, a wider fit window, a hull temperature lagging the
    water's), added alone, calibrated on one half and judged on the other paired with ours:
    none is closer to the DVL than ours on both halves by more than twice the difference's
    1-sigma over the dives; the pump read 5 s early is worse on both by more than 3 sigma
    (the pairing can tell a wrong term)."""
    result = run_variants(record, prior)
    assert len(result['variants']) == 9
    for label, runs in result['variants'].items():
        better = [run['versus_ours']['difference'] < -2.0 * run['versus_ours']
                  ['difference_std'] for run in runs.values()]
        assert not all(better), label
        for run in runs.values():
            assert run['seconds'] < 60.0
    for run in result['variants']['pump advanced 5 s'].values():
        c = run['versus_ours']
        assert c['difference'] > 3.0 * c['difference_std'] > 0.0


def test_the_dynamic_model_predicts_the_dvl_on_dives_it_never_saw(campaign):
    ours = campaign['models']['dynamic']
    steady = campaign['models']['steady (gliderflight style)']
    for fitted in ('first', 'second'):
        run = ours['runs'][fitted]
        v = run['validation']['consistent']
        # the goal, within 0.5 cm/s, by more than the bias's 1-sigma over the dives
        # (+0.32 (0.10) and +0.07 (0.15) cm/s)
        assert abs(v['speed_bias']) + v['speed_bias_std'] < 0.005
        assert v['speed_dives'] in (8, 9)
        assert v['speed_rms'] < BASELINE_RMS
        assert v['speed_rms'] < steady['runs'][fitted]['validation']['consistent']['speed_rms']
        # paired on the same samples, the steady baseline is worse by >10 of the
        # difference's 1-sigma over the dives (2.8 and 2.7 cm/s)
        c = steady['runs'][fitted]['versus_ours']
        assert c['difference'] > 0.02 and c['difference'] > 10.0 * c['difference_std']
        assert v['speed_samples'] > 1500
        assert run['seconds'] < 60.0
        assert set(run['verdicts'].values()) == {'identifiable'}
    # the halves' estimates agree within their combined 3 sigma
    assert max(ours['agreement'].values()) < 3.0
    c0 = [ours['runs'][h]['estimates']['drag_zero_lift'][0] for h in ('first', 'second')]
    assert all(0.14 < c < 0.17 for c in c0)             # Merckelbach et al. 2019: 0.14-0.2
    # every DVL sample, the last dive included: the bias exceeds the goal on the second half,
    # where that dive lies, and only there
    assert ours['runs']['first']['validation']['all']['speed_bias'] > 0.005
    assert abs(ours['runs']['second']['validation']['all']['speed_bias']) < 0.005


def test_the_inertia_is_what_the_dynamic_variants_differ_by(campaign):
    """gliderflight's dynamic calibration differs from ours by the mass (70 kg against the
    prior's 60), which the depth rate sees only through the inertia: freed, the halves put
    it at 71 and 62 kg +- 3.5-3.8 (1.7 combined sigma), and the predictions of ours, of
    the gliderflight-style dynamic calibration and of ours with the mass freed differ by
    less than 0.05 cm/s of RMS, within twice the difference's 1-sigma over the dives: a
    difference this record cannot tell."""
    inertia = campaign['models']['dynamic + mass (inertia)']
    masses = [inertia['runs'][h]['estimates']['mass'] for h in ('first', 'second')]
    assert all(55.0 < m < 80.0 and 2.0 < s < 6.0 for m, s in masses)
    assert max(inertia['agreement'].values()) < 3.0
    for label in ('dynamic + mass (inertia)', 'dynamic (gliderflight style)'):
        for run in campaign['models'][label]['runs'].values():
            c = run['versus_ours']
            assert abs(c['difference']) < 0.0005
            assert abs(c['difference']) < 2.0 * c['difference_std']
    # gliderflight's example problem (C_D0 and m, V_g held at 70/1004 m^3) at its
    # least-squares minimum: on the second half 1.20 cm/s (gliderflight's Nelder-Mead stops at
    # 1.18), within its 1-sigma of ours; on the first worse than ours by 0.08 (0.03) cm/s
    example = campaign['models']["dynamic (gliderflight's example)"]['runs']
    c = example['first']['versus_ours']
    assert 0.0115 < c['rms_a'] < 0.0125 and abs(c['difference']) < 2.0 * c['difference_std']
    c = example['second']['versus_ours']
    assert c['difference'] > 0.0005 and c['difference'] > 2.0 * c['difference_std']
    assert all(abs(example[h]['estimates']['mass'][0] - 70.1) < 0.05 for h in example)


def test_the_hull_thermal_expansion_with_the_water_temperature_is_refuted(campaign):
    """With the water's temperature as the hull's, the aluminium's alpha_T (6.9e-5 1/K)
    makes the prediction worse, and freed it comes out far below it (the hull lags the
    water through a 12 K thermocline in a 5 min dive): ours leaves it out."""
    prior = campaign['models']['dynamic + thermal expansion (prior)']['runs']
    fitted = campaign['models']['dynamic + thermal expansion (fitted)']['runs']
    ours = campaign['models']['dynamic']['runs']
    for half in ('first', 'second'):
        assert (prior[half]['validation']['consistent']['speed_rms']
                > ours[half]['validation']['consistent']['speed_rms'] + 0.003)
        value, std = fitted[half]['estimates']['thermal_expansion']
        assert value + 5.0 * std < 6.9e-5


def test_what_the_dives_cannot_identify_and_the_dvl_dive_set_apart(campaign):
    for verdicts in campaign['identifiability'].values():
        assert verdicts['compressibility']['verdict'] == 'not excited'
        assert verdicts['induced_drag']['correlated_with'] == 'drag_zero_lift'
        assert verdicts['mass']['correlated_with'] == 'hull_volume'
        assert verdicts['mass']['max_correlation'] > 0.999
    # the instruments' check: the last dive fails it, far outside the others' spread, and
    # every other dive passes well inside the limit (the verdict does not hang on the limit)
    check = campaign['dvl_check']
    dropped = [d for d in check['dives'] if not d['kept']]
    assert len(check['dives']) == 18 and len(dropped) == 1
    assert dropped[0]['median_aoa_deg'] > 15.0 and dropped[0]['start'] > 1466718000.0
    assert dropped[0]['z'] > 2.0 * check['z_limit']
    assert max(abs(d['z']) for d in check['dives'] if d['kept']) < 0.5 * check['z_limit']
    assert 2.0 < check['centre_deg'] < 5.0 and 3.0 < check['z_limit'] < 4.0
    # that dive is flown as every other (the same pump, pitch and depth rate: the pressure
    # sees one glide); only the DVL differs: 0.20 m/s, two thirds of the others' median
    # (0.29) and a quarter below the slowest of them (0.28)
    kept = [d for d in check['dives'] if d['kept']]
    last = dropped[0]
    for key, tol in (('pumped_cc', 1.0), ('pitch_deg', 0.2), ('depth_rate', 0.002)):
        assert min(d[key] for d in kept) - tol < last[key] < max(d[key] for d in kept) + tol
    assert last['dvl_speed'] < 0.75 * min(d['dvl_speed'] for d in kept)
    assert last['dvl_speed'] < 0.7 * np.median([d['dvl_speed'] for d in kept])
    # the DVL reads a third below what the depth rate and the pitch imply at the other
    # dives' angle of attack; the others' within 10 %
    assert last['dvl_speed'] < 0.7 * last['implied_speed']
    assert all(abs(d['dvl_speed'] / d['implied_speed'] - 1.0) < 0.1 for d in kept)
    lines = format_campaign(campaign)
    assert any(line.startswith('| dynamic | first half | second half |') for line in lines)
    assert any(line.endswith('| +9.1 | FLAGGED |') for line in lines)
    # the flagged dive named on the first line, with its evidence on the next; then which
    # figure meets the bias goal: the one with the flagged dive out, not the one with it
    assert lines[0].startswith('data quality: 1 of 18 DVL dives flagged: 2016-06-23T21:41:50')
    assert lines[1].startswith('  flagged: the dive from 2016-06-23T21:41:50 (second half): '
                               'DVL 0.196 m/s where')
    goal = next(line for line in lines if line.startswith(
        '  fitted on the first half, validated on the second: speed bias'))
    assert goal.endswith('flagged dives out +0.32 (0.10) cm/s: met; all dives +1.46 (1.15) '
                         'cm/s: not met')
    assert lines.index(goal) < lines.index(next(line for line in lines
                                                 if line.startswith('| model |')))
    # the paired table: its RMS, ours, the difference (1-sigma over the dives)
    assert ('| dynamic (gliderflight style) | first half | second half | 1.20 | 1.24 | '
            '-0.03 (0.04) | 8 |') in lines
