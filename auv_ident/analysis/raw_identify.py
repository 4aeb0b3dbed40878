"""`identify --bag BAG --input-map MAP` where MAP has raw-sensor inputs (IMU, DVL, pressure,
pose): the bag's messages as RawMeasurement records (offline/raw_bag.py) through
core/identification/raw.py identify_raw, printed as identify's table with the sensor errors as
extra rows.

No consistent/NOT consistent verdict is printed: the raw identification reports the mean NIS
per degree of freedom of each sensor and the long-run (colour) factor of each channel group,
not a test of them, so those figures are printed as they are.
"""
from auv_ident.analysis import results
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.identification.raw import identify_raw
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.offline.raw_bag import raw_bag_records, raw_sensor_config
from auv_ident.session.input_map import load_input_map
from auv_ident.vehicles import load_vehicle


def has_raw_sensors(input_map):
    """True if the map (name, path or InputMap) has sensor inputs (read offline only)."""
    return bool(load_input_map(input_map).sensors)


def identify_raw_bag(path, settings, passes=2):
    """(JSON document, printable table) of the raw-sensor identification of bag ``path``
    through ``settings.input_map``: the vehicle and coefficients of ``settings``, the
    filter's default FilterConfig, ``passes`` passes (identify_raw)."""
    imap = load_input_map(settings.input_map)
    v = load_vehicle(settings.vehicle)
    names = results.coefficient_list(v, settings.coefficients)
    records, t0 = raw_bag_records(path, imap, v)
    res = identify_raw(Model(v, names), FilterConfig(), records, raw_sensor_config(imap),
                       passes=passes)
    lines = [f'{v.title}: identified {", ".join(names)} from the raw sensors of bag {path} '
             f'({len(records)} records; {res.passes} passes, {res.wall_s:.1f} s)',
             'fused: ' + ', '.join(f'{k} {n}' for k, n in sorted(res.fused.items()))
             + ('; not fused: ' + ', '.join(f'{k} {n}' for k, n in sorted(res.skipped.items()))
                if res.skipped else ''),
             'mean NIS/dof: ' + ', '.join(f'{k} {x:.2f}' for k, x in sorted(res.mean_nis.items()))
             + '; long-run factors: ' + ', '.join(f'{k} {x:.2f}'
                                                   for k, x in sorted(res.long_run.items())),
             f'{"parameter":<22}{"estimate":>14}{"1-sigma":>12}']
    for n, e, s in zip(res.names, res.estimate, res.std):
        lines.append(f'{n:<22}{e:>14.6g}{s:>12.3g}')
    for n, (e, s) in res.errors.items():
        lines.append(f'{n + " (sensor)":<22}{e:>14.6g}{s:>12.3g}')
    doc = {'vehicle': v.name, 'bag': str(path), 'method': 'raw sensors (identify_raw)',
           'time_origin_ns': int(t0),
           'coefficients': {n: {'estimate': float(e), 'std': float(s)}
                            for n, e, s in zip(res.names, res.estimate, res.std)},
           'covariance': res.covariance.tolist(),
           'sensor_errors': {n: {'estimate': float(e), 'std': float(s)}
                             for n, (e, s) in res.errors.items()},
           'fused': dict(res.fused), 'skipped': dict(res.skipped),
           'mean_nis': dict(res.mean_nis), 'long_run': dict(res.long_run),
           'passes': res.passes}
    return doc, '\n'.join(lines)
