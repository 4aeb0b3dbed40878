"""A user's glider, from a bag to a calibrated glider file and back to a verdict: the work of
``python -m auv_ident glider calibrate`` and ``glider validate`` (docs/glider.md, "Your
glider: calibrate and validate").

- :func:`calibrate_glider`: the flight model of a glider file calibrated on a bag's dives (the
  depth rate; :mod:`auv_ident.core.glider.calibration`), the parameters left at the file's
  values asked what the dives could say of them (identifiability), and
  :func:`format_calibration`'s lines, the first of which is the verdict;
- :func:`calibrated_file_text`: the glider file with the identified values, loadable by
  ``vehicle check`` and by both commands (as the prior of a later calibration too);
- :func:`validate_glider`: a glider file's dynamic flight judged against the DVL speed of
  dives (bias with its 1-sigma over the dives, RMS, fit %; the depth rate), after the
  instruments' consistency check over every dive of the bag (a dive whose DVL disagrees with
  its own pressure and pitch is flagged on the first line and its figures given apart).

Times are s since 1970-01-01 UTC; speeds m/s (printed in cm/s).
"""
from dataclasses import asdict, replace
import json
import math

import numpy as np

from auv_ident.analysis.glider import EXTRA, format_dvl_check, format_flagged, judge, utc_text
from auv_ident.core.errors import ConfigError, DataError
from auv_ident.core.glider.calibration import (
    calibrate,
    DEPTH_WINDOW,
    fit_window,
    identifiability,
    MIN_SAMPLES,
)
from auv_ident.core.glider.flight import dynamic_flight
from auv_ident.core.glider.record import GliderRecord
from auv_ident.core.glider.validation import (
    angle_of_attack_agreement,
    consistent_dvl,
    dvl_dives,
)
from auv_ident.core.glider.vehicle import GliderVehicle, NUMBERS

# what ours identifies on a Slocum's dives (docs/glider.md, "What the dives identify")
DEFAULT_FREE = ('hull_volume', 'drag_zero_lift')
IDENTIFIED = 'identifiable'
# the lift and drag coefficients a calibration may move from the glider file's (published)
# values before it is called implausible: a factor of 1.5 either way (published Slocum C_D0:
# 0.14-0.2, Merckelbach et al. 2019). Beyond it the usual cause is an uncalibrated pitch (the
# comet's raw m_pitch moves C_D0 from 0.155 to 0.240), else a file of another glider
COEFFICIENTS = ('drag_zero_lift', 'induced_drag', 'lift_slope')
PLAUSIBLE_FACTOR = 1.5


def utc(t: float) -> str:
    return utc_text(t) + 'Z'


def time_window(record: GliderRecord, start: float | None, end: float | None) -> GliderRecord:
    """The samples of a record from ``start`` (inclusive) to ``end`` (exclusive), s since
    1970, either None for the record's own end; DataError naming the window when it holds
    fewer than 3 samples."""
    keep = np.ones(len(record), dtype=bool)
    if start is not None:
        keep &= record.t >= start
    if end is not None:
        keep &= record.t < end
    if keep.sum() < 3:
        raise DataError(f'the window {utc(start) if start is not None else "start"} .. '
                        f'{utc(end) if end is not None else "end"} holds {int(keep.sum())} '
                        f'samples of the bag ({utc(record.t[0])} .. {utc(record.t[-1])})')
    return record.select(keep)


def calibrate_glider(record: GliderRecord, vehicle: GliderVehicle,
                     free: tuple[str, ...] = DEFAULT_FREE) -> dict:
    """Calibrate a glider file's dynamic flight model on a record (its temperature left out:
    docs/glider.md says why). Returns {'calibration': Calibration, 'others': name -> verdict
    dict of each parameter of EXTRA not freed, had it alone been freed beside them, 'dives': the
    number of dives, 'untrusted': the freed parameters the dives did not identify,
    'implausible': name -> calibrated / file's value of the lift and drag coefficients moved
    beyond PLAUSIBLE_FACTOR}."""
    if 'thermal_expansion' in free:
        raise ConfigError("thermal_expansion: the flight model leaves the hull's thermal "
                          "expansion out (with the water's temperature as the hull's it is "
                          'refuted: docs/glider.md)')
    record = replace(record, temperature=None)
    cal = calibrate(record, vehicle.params, 'dynamic', free)
    # each alone beside the freed ones, as docs/glider.md's table: what freeing it would cost
    others = {n: identifiability(record, cal, (n,))[n] for n in EXTRA if n not in free}
    ratios = {n: cal.value(n) / getattr(vehicle.params, n) for n in free if n in COEFFICIENTS}
    implausible = {n: r for n, r in ratios.items()
                   if not 1.0 / PLAUSIBLE_FACTOR <= r <= PLAUSIBLE_FACTOR}
    return {'calibration': cal, 'others': others,
            'dives': _dives(record),
            'untrusted': [n for n in free if cal.verdicts[n]['verdict'] != IDENTIFIED],
            'implausible': implausible}


def _dives(record: GliderRecord, top: float = 10.0, hysteresis: float = 5.0) -> int:
    """The glider's dives in the record: descents from above ``top`` m (the fit window's top)
    to below ``top + hysteresis`` m (the hysteresis: a glider heaved about the top by the
    water is not diving again)."""
    count, shallow = 0, True
    for z in record.depth:
        if shallow and z > top + hysteresis:
            count, shallow = count + 1, False
        elif z < top:
            shallow = True
    return count


def _value(v: float) -> str:
    return f'{v:.6g}'


def format_calibration(result: dict, vehicle: GliderVehicle, record: GliderRecord) -> list:
    """The lines `glider calibrate` prints; the first is the verdict."""
    cal = result['calibration']
    where = (f'{vehicle.name} calibrated on {result["dives"]} dives, {utc(record.t[0])} .. '
             f'{utc(record.t[-1])}, {cal.samples} samples of the depth rate at '
             f'{cal.window[0]:g}-{cal.window[1]:g} m')
    if result['untrusted']:
        first = (f'NOT identified: {", ".join(result["untrusted"])} '
                 '(the dives do not fix them: see the verdicts below): ' + where)
    elif result['implausible']:
        moved = ', '.join(f"{n} x {r:.2f} of the file's" for n, r in
                          result['implausible'].items())
        first = (f'NOT plausible: {moved} (beyond x {PLAUSIBLE_FACTOR:g} either way: is the '
                 "pitch calibrated, import --pitch-correction? is the file this glider's?): "
                 + where)
    else:
        first = 'identified: ' + where
    L = [first, '',
         '| parameter | file | calibrated | 1-sigma | verdict |', '|---|---|---|---|---|']
    for name, (value, std) in cal.estimates().items():
        L.append(f'| {name} | {_value(getattr(vehicle.params, name))} | {_value(value)} | '
                 f'{std:.2g} | {cal.verdicts[name]["verdict"]} |')
    L += ['', f'depth-rate RMS {100 * cal.rms:.2f} cm/s; error bars: sandwich covariance, '
          f'residuals correlated over {cal.lags} samples; {cal.seconds:.2f} s']
    if result['others']:
        L += ['', "held at the file's values; each freed alone beside them, the dives would "
              'say:', '',
              '| parameter | file | 1-sigma | max correlation (with) | verdict |',
              '|---|---|---|---|---|']
        for name, v in result['others'].items():
            L.append(f'| {name} | {_value(getattr(vehicle.params, name))} | '
                     f'{v["crb_std"]:.3g} | {_correlation(v)} | {v["verdict"]} |')
    return L


def _correlation(v: dict) -> str:
    c = v.get('max_correlation')
    return '-' if c is None or not math.isfinite(c) else f'{c:.3f} ({v.get("correlated_with")})'


def calibrated_file_text(raw: dict, vehicle: GliderVehicle, result: dict, source: str) -> str:
    """The glider file (YAML text) of ``raw`` (the file as read) with the calibration's
    values; ``source`` says where they come from (the bag, the window, the command). The
    model's lift slope is the hull's plus the wings': a calibrated one changes the hull's."""
    cal = result['calibration']
    values = {k: raw[k] for k in NUMBERS}
    notes = {}
    for name, (value, std) in cal.estimates().items():
        key = 'lift_slope_hull' if name == 'lift_slope' else name
        values[key] = value - raw['lift_slope_wings'] if name == 'lift_slope' else value
        notes[key] = (f'calibrated, 1-sigma {std:.2g} ({cal.verdicts[name]["verdict"]}); '
                      f'the file had {raw[key]!r}')
    prior = (f'{vehicle.prior}; {", ".join(cal.free)} calibrated by auv_ident on {source}')
    L = [f'# {vehicle.name}: a glider file (kind: glider, docs/glider.md) written by '
         f'`python -m auv_ident glider calibrate`', f'# from {vehicle.path}; {source}.',
         "# Each calibrated value's 1-sigma beside it; the others are that file's.",
         'kind: glider', f'name: {_quoted(raw["name"])}', f'prior: {_quoted(prior)}',
         f'pitch_source: {raw["pitch_source"]}']
    for key in NUMBERS:
        if key in notes:
            L.append(f'# {notes[key]}')
        L.append(f'{key}: {float(values[key])!r}')
    return '\n'.join(L) + '\n'


def _quoted(text: str) -> str:
    """A YAML double-quoted scalar (JSON's string syntax is YAML's)."""
    return json.dumps(str(text))


def validate_glider(record: GliderRecord, window: GliderRecord, vehicle: GliderVehicle) -> dict:
    """A glider file's dynamic flight over ``window`` (a part of ``record``) judged against
    the DVL speed; the consistency check runs over every dive of ``record`` (more dives, a
    firmer spread). Returns {'check': DvlConsistency dict or None (no DVL speed in the
    window), 'scores': judge()'s {'all', 'consistent'} ({'all'} without a DVL), 'flagged':
    the flagged dives in the window, 'angle_of_attack': AngleOfAttackAgreement dict or None,
    'untrusted': a dive flagged or the angle of attack disagreeing, 'dives', 'dvl_dives'}.
    DataError when the window holds no dive below the fit window's top."""
    window = replace(window, temperature=None)
    deep = int(fit_window(window).sum())
    if deep < MIN_SAMPLES:
        raise DataError(f'the window {utc(window.t[0])} .. {utc(window.t[-1])} holds {deep} '
                        f'samples between {DEPTH_WINDOW[0]:g} and {DEPTH_WINDOW[1]:g} m: no '
                        f'dive to judge (at least {MIN_SAMPLES})')
    flight = dynamic_flight(vehicle.params, window)
    if not np.isfinite(window.speed_through_water).any():
        return {'check': None, 'scores': {'all': judge(flight, window, window.t)['all']},
                'flagged': [], 'dives': _dives(window), 'untrusted': False,
                'dvl_elsewhere': bool(np.isfinite(record.speed_through_water).any())}
    check = consistent_dvl(record)
    kept_times = record.t[check.keep]
    scores = judge(flight, window, kept_times)
    flagged = [d for d in check.as_dict()['dives']
               if not d['kept'] and window.t[0] <= d['start'] <= window.t[-1]]
    agreement = angle_of_attack_agreement(flight, window, check, kept_times)
    return {'check': check.as_dict(), 'scores': scores, 'flagged': flagged,
            'dives': _dives(window), 'dvl_dives': len(dvl_dives(window)),
            'angle_of_attack': None if agreement is None else asdict(agreement),
            'untrusted': bool(flagged) or bool(agreement and agreement.disagrees)}


def format_validation(result: dict, vehicle: GliderVehicle, window: GliderRecord) -> list:
    """The lines `glider validate` prints; the first is the verdict (the instruments' check)."""
    span = f'{utc(window.t[0])} .. {utc(window.t[-1])}'
    if result['check'] is None:
        s = result['scores']['all']
        where = 'this window' if result['dvl_elsewhere'] else 'the bag'
        return [f'{vehicle.name} on {result["dives"]} dives, {span}: no DVL speed in {where}: '
                'the speed through water is not judged',
                f'depth rate (10-35 m) bias {100 * s["depth_rate_bias"]:+.2f} cm/s, RMS '
                f'{100 * s["depth_rate_rms"]:.2f} cm/s']
    L = format_flagged(result['check'], dive_table='the last table below')
    L[0] += f' (of the bag; {len(result["flagged"])} in this window)'
    a = result['angle_of_attack']
    if a is not None:
        line = (f"angle of attack: the model flies at {a['model_deg']:.2f} deg where the DVL, "
                f"the pressure and the pitch imply {a['implied_deg']:.2f} deg (the dives' "
                f"spread {a['spread_deg']:.2f} deg, z = {a['z']:+.1f}, limit "
                f"{a['z_limit']:.2f}): a speed about {100 * a['speed_error']:+.1f} "
                f"cm/s off for the same depth rate at its glide angle {a['glide_deg']:.1f} deg")
        if a['disagrees']:
            L.insert(0, 'NOT consistent: ' + line + '; is the pitch calibrated (import '
                     '--pitch-correction), the lift slope right? (docs/glider.md)')
        else:
            L.append(line + ": within the dives' scatter")
    L += ['', f'{vehicle.name} on {result["dvl_dives"]} DVL dives, {span}: speed through water '
          'against the DVL, depth rate against the pressure', '',
          '| dives | U bias cm/s (1-sigma over the dives) | U RMS cm/s | U fit % | DVL samples '
          '| dz/dt bias cm/s | dz/dt RMS cm/s |', '|---|---|---|---|---|---|---|']
    for label, key in (('all', 'all'), ('flagged out', 'consistent')):
        s = result['scores'][key]
        L.append(f'| {label} | {100 * s["speed_bias"]:+.2f} ({100 * s["speed_bias_std"]:.2f}) | '
                 f'{100 * s["speed_rms"]:.2f} | {s["speed_fit"]:.1f} | {s["speed_samples"]} | '
                 f'{100 * s["depth_rate_bias"]:+.2f} | {100 * s["depth_rate_rms"]:.2f} |')
    return L + format_dvl_check(result['check'])


def calibration_json(result: dict, vehicle: GliderVehicle, record: GliderRecord) -> dict:
    """The JSON document of a calibration (`glider calibrate --json`)."""
    cal = result['calibration']
    return {'vehicle': vehicle.path, 'start': float(record.t[0]), 'end': float(record.t[-1]),
            'dives': result['dives'], 'window_m': list(cal.window), 'samples': cal.samples,
            'estimates': {n: list(v) for n, v in cal.estimates().items()},
            'verdicts': {n: v['verdict'] for n, v in cal.verdicts.items()},
            'untrusted': result['untrusted'], 'implausible': result['implausible'],
            'depth_rate_rms': cal.rms, 'lags': cal.lags,
            'others': {n: {'std': v['crb_std'], 'verdict': v['verdict']}
                       for n, v in result['others'].items()},
            'params': asdict(cal.params), 'seconds': cal.seconds}
