"""glider calibrate, glider validate: a glider's flight model from its bag (docs/glider.md,
"Your glider: calibrate and validate"); the work is analysis/glider_file.py's."""
import datetime
import os
import sys

from auv_ident.cli.common import check_outputs, EXIT_UNTRUSTED
from auv_ident.core.errors import AuvIdentError


def utc_time(text):
    """--from / --until: an ISO 8601 time (UTC unless it says its zone: 2016-06-23T19:55:00Z)
    or seconds since 1970-01-01 UTC -> s since 1970."""
    try:
        return float(text)
    except ValueError:
        pass
    try:
        when = datetime.datetime.fromisoformat(text.strip().replace('Z', '+00:00'))
    except ValueError:
        raise AuvIdentError(f'{text!r}: not a time (an ISO 8601 UTC time such as '
                            '2016-06-23T19:55:00Z, or seconds since 1970)') from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=datetime.timezone.utc)
    return when.timestamp()


def _inputs(args):
    """(GliderVehicle, raw file dict, whole record, the record's window) of the options."""
    from auv_ident.analysis.glider_file import time_window
    from auv_ident.core.glider.vehicle import glider_from_dict
    from auv_ident.core.vehicle_files import read_yaml_file
    from auv_ident.offline.glider_import import read_glider_bag
    from auv_ident.vehicles import resolve_vehicle_path
    path = resolve_vehicle_path(args.vehicle)
    raw = read_yaml_file(path)          # read once: checked here, rewritten by --vehicle-out
    vehicle = glider_from_dict(raw, path)
    start = None if args.start is None else utc_time(args.start)
    end = None if args.until is None else utc_time(args.until)
    if start is not None and end is not None and end <= start:
        raise AuvIdentError(f'--until {args.until} is not after --from {args.start}')
    if not os.path.exists(args.bag):
        raise AuvIdentError(f'--bag {args.bag}: no such bag')
    record = read_glider_bag(args.bag)
    return vehicle, raw, record, time_window(record, start, end)


def _window_text(args, window):
    from auv_ident.analysis.glider_file import utc
    return f'{args.bag}, {utc(window.t[0])} .. {utc(window.t[-1])}'


def cmd_calibrate(args):
    import json

    from auv_ident.analysis.glider_file import (
        calibrate_glider,
        calibrated_file_text,
        calibration_json,
        format_calibration,
    )
    check_outputs(args, '--json', '--vehicle-out')
    free = tuple(n.strip() for n in args.free.split(',') if n.strip())
    if not free:
        raise AuvIdentError(f'--free {args.free!r}: name the parameters to calibrate '
                            '(e.g. hull_volume,drag_zero_lift)')
    vehicle, raw, _, window = _inputs(args)
    result = calibrate_glider(window, vehicle, free)
    print('\n'.join(format_calibration(result, vehicle, window)))
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(calibration_json(result, vehicle, window), f, indent=1)
        print(f'wrote {args.json}')
    if args.vehicle_out:
        source = (f'{_window_text(args, window)} '
                  f'(python -m auv_ident {" ".join(sys.argv[1:])})')
        with open(args.vehicle_out, 'w') as f:
            f.write(calibrated_file_text(raw, vehicle, result, source))
        print(f'wrote {args.vehicle_out}')
    return EXIT_UNTRUSTED if result['untrusted'] or result['implausible'] else 0


def cmd_validate(args):
    from auv_ident.analysis.glider_file import format_validation, validate_glider
    vehicle, _, record, window = _inputs(args)
    result = validate_glider(record, window, vehicle)
    print('\n'.join(format_validation(result, vehicle, window)))
    return EXIT_UNTRUSTED if result['untrusted'] else 0


def _common(sp):
    sp.add_argument('--vehicle', required=True,
                    help='the glider file (kind: glider): a name in config/ or a path')
    sp.add_argument('--bag', required=True,
                    help='a glider bag (import --format npy, docs/glider.md)')
    sp.add_argument('--from', dest='start', metavar='TIME',
                    help='only the samples from this time (ISO 8601 UTC, e.g. '
                         '2016-06-23T19:55:00Z, or s since 1970)')
    sp.add_argument('--until', metavar='TIME', help='only the samples before this time')


def add_commands(sub):
    g = sub.add_parser('glider', help="a glider's flight model: calibrate it on a bag's dives, "
                                      'validate it against a DVL (docs/glider.md)')
    verbs = g.add_subparsers(dest='glider_cmd', required=True)
    sp = verbs.add_parser('calibrate', help="calibrate a glider file's flight model on the "
                                            "dives of a bag (the depth rate); exit 3 when a "
                                            'freed parameter is not identified or a drag or '
                                            "lift coefficient moves beyond x 1.5 of the file's")
    _common(sp)
    sp.add_argument('--free', default='hull_volume,drag_zero_lift',
                    help='the parameters to identify (default hull_volume,drag_zero_lift; '
                         'also mass, compressibility, lift_slope, induced_drag)')
    sp.add_argument('--vehicle-out', metavar='FILE.yaml',
                    help='write the calibrated glider file here')
    sp.add_argument('--json', help='write the calibration here')
    sp.add_argument('--force', action='store_true', help='overwrite --json / --vehicle-out')
    sp.set_defaults(func=cmd_calibrate)
    sp = verbs.add_parser('validate', help="a glider file's flight against the bag's DVL speed "
                                           'and depth rate; exit 3 when a DVL dive disagrees '
                                           'with its pressure and pitch, or the model flies at '
                                           'an angle of attack the dives do not show')
    _common(sp)
    sp.set_defaults(func=cmd_validate)
