"""bag, import, derivatives, vehicle check: the files a user brings (bags, logs, vehicle files)."""
import csv
import sys

import numpy as np

from auv_ident.cli.common import vehicle_arg, vehicle_model
from auv_ident.core.errors import AuvIdentError


def cmd_bag_info(args):
    from auv_ident.bags.info import bag_info, format_bag_info
    print('\n'.join(format_bag_info(bag_info(args.path))))
    return 0


def cmd_bag_repair(args):
    from auv_ident.bags.repair import repair_bag
    report = repair_bag(args.path, out=args.out)
    print('\n'.join(report.lines()))
    return 0


def cmd_import(args):
    from auv_ident.offline.import_bag import write_imported_bag
    from auv_ident.offline.importers import read_csv_run, read_hsva
    if args.format in ('slocum', 'npy'):
        from auv_ident.offline.glider_import import import_glider_files
        if args.columns or args.start or args.vehicle or args.input_map:
            raise AuvIdentError(f'--columns, --start, --vehicle and --input-map are not for '
                                f'--format {args.format}: glider logs carry their own times '
                                'and layout')
        print('\n'.join(import_glider_files(args.format, args.file, args.out,
                                             'python -m auv_ident ' + ' '.join(sys.argv[1:]),
                                             _pitch_correction(args.pitch_correction))))
        return 0
    if args.pitch_correction is not None:
        raise AuvIdentError(f'--pitch-correction is for --format slocum, not {args.format}')
    if len(args.file) != 1:
        raise AuvIdentError(f'--format {args.format} reads one file, not {len(args.file)}')
    args.file = args.file[0]
    if args.format == 'hsva':
        if args.columns:
            raise AuvIdentError('--columns is for --format csv (HSVA files have a fixed layout)')
        run = read_hsva(args.file)
    else:
        if not args.columns:
            raise AuvIdentError('--format csv needs --columns MAP.yaml (docs/bags.md, '
                                '"Importing measured runs")')
        run = read_csv_run(args.file, args.columns)
    write_imported_bag(run, args.out, vehicle=args.vehicle, start=args.start,
                       command='python -m auv_ident ' + ' '.join(sys.argv[1:]),
                       input_map=args.input_map)
    _print_import(run, args)
    return 0


def _pitch_correction(text):
    """--pitch-correction SCALE,OFFSET -> (scale, offset rad), or None."""
    if text is None:
        return None
    try:
        scale, offset = (float(v) for v in text.split(','))
    except ValueError:
        raise AuvIdentError(f'--pitch-correction {text!r}: SCALE,OFFSET, two numbers (e.g. '
                            '0.86,-0.004)') from None
    if not (0.5 <= scale <= 1.5) or not abs(offset) <= 0.2:
        raise AuvIdentError(f'--pitch-correction {text!r}: a scale within 0.5-1.5 and an '
                            'offset within 0.2 rad are an inclinometer calibration; this is not')
    return scale, offset


def _print_import(run, args):
    from auv_ident.offline.import_bag import DEFAULT_VEHICLE, unmapped_inputs
    t = run.t
    std = ', '.join(f'{n} {s:.3g}' for n, s in zip(run.measured_names,
                                                   run.noise_std[run.measured]))
    print(f'{run.source.name} ({run.fmt}): {len(t)} samples over {t[-1]:.3f} s, sample time '
          f'{run.sample_time:g} s')
    print(f"measured: {' '.join(run.measured_names)}; inputs: "
          f"{' '.join(sorted(run.inputs)) or 'none'}")
    counts = run.samples
    if len(set(counts.values())) > 1:   # a multi-rate log
        print('samples per channel: ' + ', '.join(f'{n} {c}' for n, c in counts.items()))
    if run.skipped:
        lines = ', '.join(map(str, run.skipped[:10])) + (', ...' if len(run.skipped) > 10
                                                          else '')
        print(f'skipped {len(run.skipped)} rows with NaN or Inf (lines {lines})')
    missing = unmapped_inputs(run, args.vehicle or DEFAULT_VEHICLE[run.fmt])
    if missing:
        print(f"note: the vehicle's model uses {', '.join(missing)}, which the file does not "
              'log: written as 0')
    print(f'noise 1-sigma estimates (SI): {std}')
    print(f'wrote {args.out}')


IN_COLS = ('u', 'v', 'w', 'p', 'q', 'r', 'x', 'y', 'z', 'phi', 'theta', 'psi',
           'delta_r', 'delta_s', 'delta_b', 'delta_bp', 'delta_bs', 'n_rpm')


THRUST_COL = 'thrust'     # N, optional (0 when absent): the input of measured_thrust vehicles


OUT_COLS = tuple(c + '_dot' for c in IN_COLS[:12])


def cmd_vehicle_check(args):
    """0: the file is ready; 1: it loads and flies, with warnings; 2: errors."""
    from auv_ident.analysis.vehicle_check import check_vehicle
    check = check_vehicle(args.vehicle)
    print('\n'.join(check.lines()))
    return 2 if not check.ok else (1 if check.warnings else 0)


def cmd_derivatives(args):
    from auv_ident.core.model.hydrodynamics import OK, STATUS_TEXT
    m = vehicle_model(args)
    bad = 0
    with open(args.input, newline='', encoding='utf-8') as fin, \
            open(args.output, 'w', newline='', encoding='utf-8') as fout:
        rd = csv.reader(fin)
        header = next(rd, None)
        if header is None:
            raise AuvIdentError(f'{args.input}: empty file (expected a header row)')
        header = [h.strip() for h in header]
        missing = [c for c in IN_COLS if c not in header]
        if missing:
            raise AuvIdentError(f'{args.input}: missing column(s) {", ".join(missing)}')
        idx = [header.index(c) for c in IN_COLS]
        if THRUST_COL in header:
            idx.append(header.index(THRUST_COL))
        wr = csv.writer(fout)
        wr.writerow(OUT_COLS)
        for rownum, row in enumerate(rd, start=2):
            try:
                vals = np.array([float(row[i]) for i in idx] + [0.0] * (19 - len(idx)))
            except (ValueError, IndexError):
                print(f'{args.input}: row {rownum}: not {len(idx)} numbers', file=sys.stderr)
                wr.writerow([''] * 12)
                bad += 1
                continue
            st = m.status(vals[:12], vals[12:])
            if st != OK:
                print(f'{args.input}: row {rownum}: {STATUS_TEXT[st]}', file=sys.stderr)
                wr.writerow([''] * 12)
                bad += 1
                continue
            wr.writerow([repr(float(v)) for v in m.f(vals[:12], vals[12:])])
    return 0 if bad == 0 else 1


def add_commands(sub):
    """This family's subcommands on the parser's ``sub`` (argparse subparsers)."""
    sp = sub.add_parser('bag', help='rosbag2 MCAP bags: info, repair')
    bag_sub = sp.add_subparsers(dest='bag_cmd', required=True)
    bp = bag_sub.add_parser('info', help='what `ros2 bag info` prints, for any rosbag2 MCAP bag')
    bp.add_argument('path', help='bag directory or .mcap file')
    bp.set_defaults(func=cmd_bag_info)
    bp = bag_sub.add_parser(
        'repair', help='make a bag whose recorder was killed complete and indexed again '
                       '(like `ros2 bag reindex`); says what was lost')
    bp.add_argument('path', help='bag directory or .mcap file')
    bp.add_argument('--out', help='write the repaired bag to this new directory '
                                  '(default: in place, originals kept as <file>.orig)')
    bp.set_defaults(func=cmd_bag_repair)

    sp = sub.add_parser('import', help='write a measured run (HSVA file, CSV log) as a bag in '
                                       'our topics and frames')
    sp.add_argument('file', nargs='+', help='the measured run: an HSVA .dat file, a CSV log, '
                                            "a Slocum glider's .dbd/.ebd logs or its npy file")
    sp.add_argument('--format', required=True, choices=('hsva', 'csv', 'slocum', 'npy'),
                    help='hsva: HSVA KVLCC2 free-running test file; csv: CSV log with --columns; '
                         'slocum: Slocum .dbd/.ebd logs (.cac sensor lists beside them); npy: '
                         "gliderflight's gliderflight_data.npy (docs/glider.md)")
    sp.add_argument('--columns', metavar='MAP.yaml',
                    help='csv: the column map (quantity, unit, frame, sign, time base per '
                         'column; docs/bags.md)')
    sp.add_argument('--out', required=True, help='bag directory to write (must not exist)')
    sp.add_argument('--vehicle', default=None,
                    help='stored in the bag for identify --bag (hsva default: kvlcc2_hsva)')
    sp.add_argument('--start', metavar='ISO8601',
                    help='UTC time of t = 0, e.g. 2006-05-17T10:00:00Z (default: nominal, '
                         '2006-01-01T00:00:00Z for hsva, 2024-01-01T00:00:00Z for csv)')
    sp.add_argument('--input-map', metavar='MAP', default=None,
                    help='write the bag in the topics and message forms of this input map '
                         '(config/inputs/NAME.yaml or a path; docs/your_data.md) instead of '
                         '/odom and /actuators')
    sp.add_argument('--pitch-correction', metavar='SCALE,OFFSET', default=None,
                    help="slocum: the inclinometer's calibration, pitch = SCALE m_pitch + "
                         'OFFSET (rad); the comet: 0.86,-0.004 (docs/glider.md)')
    sp.set_defaults(func=cmd_import)

    sp = sub.add_parser('derivatives', help='evaluate x_dot = f(x, u) on a CSV table')
    vehicle_arg(sp)
    sp.add_argument('input')
    sp.add_argument('output')
    sp.set_defaults(func=cmd_derivatives)

    sp = sub.add_parser('vehicle', help='vehicle files: check one before its first run')
    vehicle_sub = sp.add_subparsers(dest='vehicle_command', required=True)
    vp = vehicle_sub.add_parser('check', help='every missing or implausible key of a vehicle '
                                               'file at once, its trim and stability '
                                               '(docs/vehicles.md)')
    vp.add_argument('vehicle', help='vehicle YAML path or name (config/<name>.yaml)')
    vp.set_defaults(func=cmd_vehicle_check)
