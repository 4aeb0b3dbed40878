"""`identify --bag BAG --input-map MAP` where MAP has raw-sensor inputs (IMU, DVL, pressure,
pose): the bag's messages as RawMeasurement records (offline/raw_bag.py) through
core/identification/raw.py identify_raw, printed as identify's table with the sensor errors as
extra rows.

The first line is the verdict, as the fused path's (analysis/bag_identify.py): consistent, or
NOT consistent / NOT plausible with the reason, and `identify` exits 3 on a result not to be
trusted (cli.EXIT_UNTRUSTED). Each sensor is its own channel (raw_verdict):

- a stuck sensor: a sensor whose values repeat exactly for at least STUCK_SAMPLES messages
  spanning STUCK_SECONDS (session/stuck.py's rule, per sensor at its own rate) is a fault of
  the data; its repeats are not fed to the filter (drop_repeats);
- the innovations: a sensor whose mean NIS per degree of freedom, after the passes weighed
  each channel group by the level its innovations showed, is above NIS_LIMIT does not fit the
  model (a wrong mounting, frame or vehicle file);
- the model's domain: a pass that leaves it (a propeller state the vehicle file cannot produce,
  a diverging state) means the data contradict the vehicle file or the input map's frames (a
  bag in ENU read as NED, or the other way, turns the vehicle upside down): NOT consistent,
  with no estimate;
- the estimates' plausibility for the vehicle file (core/identification/diagnosis.py
  judge_plausibility).
"""
import numpy as np

from auv_ident.analysis import results
from auv_ident.analysis.bag_identify import _meta_truth
from auv_ident.core.errors import DivergenceError, DomainError
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.identification.diagnosis import judge_plausibility, not_consistent
from auv_ident.core.identification.raw import identify_raw
from auv_ident.core.identification.results import Diagnosis
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.offline.raw_bag import raw_bag_records, raw_sensor_config
from auv_ident.offline.replay import bag_custom_data
from auv_ident.offline.tf_static import tf_mountings
from auv_ident.session.input_map import load_input_map
from auv_ident.session.raw_session import check_raw_settings, check_raw_vehicle
from auv_ident.session.stuck import describe_spans, STUCK_SAMPLES, STUCK_SECONDS, StuckSpan
from auv_ident.vehicles import load_vehicle

NIS_LIMIT = 3.0    # mean NIS/dof of a sensor above this after the reweighted passes: no fit
MEASURED_KINDS = ('imu', 'dvl', 'pressure', 'depth', 'position')   # commands are not judged


def drop_repeats(records):
    """(records without the exact repeats of a sensor's previous values, the stuck-sensor
    faults as StuckSpan). Per sensor (kind and mounting name), at its own rate: a message whose
    values equal the previous one's bit for bit is a value republished, not a measurement (real
    noise never repeats a float), and is not fed; STUCK_SAMPLES such messages in a row spanning
    STUCK_SECONDS (s) are a fault (session/stuck.py's rule). Commands are kept as they are
    (drivers publish them on change)."""
    last, kept, spans = {}, [], []
    for m in records:
        if m.kind not in MEASURED_KINDS:
            kept.append(m)
            continue
        key = (m.kind, m.sensor)
        seen = last.get(key)
        if seen is not None and np.array_equal(seen[0], m.values):
            seen[2] += 1
            seen[3] = m.t
            continue
        if seen is not None:
            _close(key, seen, spans)
        last[key] = [m.values, m.t, 0, m.t]
        kept.append(m)
    for key, seen in last.items():
        _close(key, seen, spans)
    return kept, spans


def _close(key, seen, spans):
    """The run of repeats of one sensor's values a fault (a StuckSpan added to spans) if it is
    long enough (drop_repeats)."""
    _, since, repeats, t_last = seen
    if repeats + 1 >= STUCK_SAMPLES and t_last - since >= STUCK_SECONDS:
        name = key[0] + (f' ({key[1]})' if key[1] and key[1] != key[0] else '')
        spans.append(StuckSpan(name, since, t_last, repeats, active=False))


def raw_verdict(vehicle, res, spans, p_coef):
    """The Diagnosis of a raw-sensor identification (module docstring): stuck sensors (spans,
    drop_repeats), the sensors' mean NIS/dof against NIS_LIMIT, the plausibility of the first
    p_coef estimates (the coefficients; the current components follow them)."""
    checks = {'mean_nis_per_dof': dict(res.mean_nis), 'nis_limit': NIS_LIMIT,
              'noise_scale': dict(res.noise_scale), 'long_run': dict(res.long_run)}
    d = Diagnosis(True, ["consistent: every sensor's innovations fit the model within their "
                         'weighted noise (mean NIS/dof at most '
                         f'{NIS_LIMIT:g}), no sensor stuck'], checks)
    misfit = [f'{k} innovations mean NIS/dof {x:.2f} > {NIS_LIMIT:g} with its noise weighted '
              'from the data: the sensor does not fit the model (check its frame and mounting '
              'in the input map, and the vehicle file)'
              for k, x in sorted(res.mean_nis.items()) if not x <= NIS_LIMIT]
    d = not_consistent(d, misfit, 'innovations')
    if spans:
        d = not_consistent(d, [f'{describe_spans(spans)}: a stuck sensor, or a field the driver '
                               'never fills; those samples were not fed to the filter. Check '
                               'the sensor, or leave it out of the input map'], 'stuck')
    pc = p_coef
    return judge_plausibility(d, vehicle, res.names[:pc], res.estimate[:pc],
                              res.covariance[:pc, :pc])


def has_raw_sensors(input_map):
    """True if the map (name, path or InputMap) has sensor inputs (read offline only)."""
    return bool(load_input_map(input_map).sensors)


def identify_raw_bag(path, settings, passes=2):
    """(JSON document, printable table) of the raw-sensor identification of bag ``path``
    through ``settings.input_map``: the vehicle and coefficients of ``settings``, the
    filter's default FilterConfig, ``passes`` passes (identify_raw), the sensors' exact repeats
    not fed (drop_repeats); the first line the verdict (module docstring), also the document's
    'diagnosis' (cli exits 3 on a result not to be trusted)."""
    check_raw_settings(settings)
    imap = load_input_map(settings.input_map)
    v = load_vehicle(settings.vehicle)
    check_raw_vehicle(v)
    names = results.coefficient_list(v, settings.coefficients)
    records, t0 = raw_bag_records(path, imap, v)
    records, spans = drop_repeats(records)
    model = Model(v, names)
    try:
        res = identify_raw(model, FilterConfig(), records,
                           raw_sensor_config(imap, tf_mountings(path, imap)), passes=passes)
    except (DomainError, DivergenceError) as e:
        return _left_domain(path, v, names, e, spans, t0)
    diagnosis = raw_verdict(v, res, spans, model.p_coef)
    lines = [diagnosis.messages[0],
             f'{v.title}: identified {", ".join(names)} from the raw sensors of bag {path} '
             f'({len(records)} records; {res.passes} passes, {res.wall_s:.1f} s)',
             'fused: ' + ', '.join(f'{k} {n}' for k, n in sorted(res.fused.items()))
             + ('; not fused: ' + ', '.join(f'{k} {n}' for k, n in sorted(res.skipped.items()))
                if res.skipped else ''),
             'mean NIS/dof: ' + ', '.join(f'{k} {x:.2f}' for k, x in sorted(res.mean_nis.items()))
             + '; long-run factors: ' + ', '.join(f'{k} {x:.2f}'
                                                   for k, x in sorted(res.long_run.items())),
             f'{"parameter":<26}{"truth":>12}{"estimate":>14}{"1-sigma":>12}{"error %":>10}']
    truth = _meta_truth(bag_custom_data(path), model)
    coefs = _coefficients(res, truth)
    for n, c in coefs.items():
        err = c['error_pct']
        lines.append(f'{n:<26}{results._fmt(c["truth"])}{c["estimate"]:>14.6g}{c["std"]:>12.3g}'
                     + (f'{"-":>10}' if err is None else f'{err:>+10.2f}'))
    for n, (e, s) in res.errors.items():
        lines.append(f'{n + " (sensor)":<26}{"-":>12}{e:>14.6g}{s:>12.3g}')
    lines += ['- ' + m for m in diagnosis.messages[1:]]
    doc = {'vehicle': v.name, 'bag': str(path), 'method': 'raw sensors (identify_raw)',
           'time_origin_ns': int(t0),
           'coefficients': coefs, 'truth_source': None if truth is None else
           "the vehicle file (the bag's metadata says auv_ident simulated it)",
           'covariance': res.covariance.tolist(),
           'sensor_errors': {n: {'estimate': float(e), 'std': float(s)}
                             for n, (e, s) in res.errors.items()},
           'fused': dict(res.fused), 'skipped': dict(res.skipped),
           'mean_nis': dict(res.mean_nis), 'long_run': dict(res.long_run),
           'passes': res.passes, 'diagnosis': diagnosis.document()}
    return doc, '\n'.join(lines)


def _coefficients(res, truth):
    """name -> {estimate, std, truth, error_pct} of the identified parameters; truth (the
    coefficients', first in res.names) None when the bag does not record it."""
    out = {}
    for i, (n, e, s) in enumerate(zip(res.names, res.estimate, res.std)):
        t = None if truth is None or i >= len(truth) else float(truth[i])
        out[n] = {'estimate': float(e), 'std': float(s), 'truth': t,
                  'error_pct': None if not t else 100.0 * (float(e) - t) / abs(t)}
    return out


def _left_domain(path, v, names, error, spans, t0):
    """(document, table) of a raw pass that left the model's domain: NOT consistent, no
    estimate (module docstring); a stuck sensor found is named too."""
    problems = [f"the raw-sensor pass left the model's domain ({error}): the data contradict "
                "the vehicle file or the input map's frames (a bag in ENU read as NED, or the "
                "other way; check each sensor's frame and mounting, and the vehicle)"]
    if spans:
        problems.append(f'{describe_spans(spans)}: a stuck sensor; not fed to the filter')
    d = not_consistent(Diagnosis(True, [], {}), problems, 'domain')
    doc = {'vehicle': v.name, 'bag': str(path), 'method': 'raw sensors (identify_raw)',
           'time_origin_ns': int(t0), 'coefficients': {}, 'diagnosis': d.document()}
    table = '\n'.join([d.messages[0], f'{v.title}: no estimate of {", ".join(names)} from the '
                        f'raw sensors of bag {path}'] + ['- ' + m for m in d.messages[1:]])
    return doc, table
