"""Command line: python -m auv_ident {simulate,derivatives,identify,montecarlo,bench,...}.

Expected errors (bad options, bad files, states outside the model's domain) print one clear
line on stderr and exit with status 2; no traceback.
"""
import argparse
import csv
import json
import math
import sys

import numpy as np

from .core.errors import AuvIdentError


def _model(args, theta_names=()):
    from .core.model import Model
    from .core.vehicle import load_vehicle
    return Model(load_vehicle(args.vehicle), theta_names,
                 mass_inverse=getattr(args, 'mass_inverse', 'default'))


def cmd_simulate(args):
    from .core.simulate import DEFAULT_PROCESS_STD, save_run_csv, simulate
    m = _model(args)
    run = simulate(m, args.maneuver, duration=args.duration, T=args.dt, seed=args.seed,
                   rpm=args.rpm, process_std=DEFAULT_PROCESS_STD if args.process_noise else None)
    s = run.summary()
    fs = s['final_state']
    print(f"{m.vehicle.title}: manoeuvre {run.maneuver}, {s['duration_s']:.1f} s at "
          f"T = {run.T} s ({s['samples']} samples), seed {run.seed}")
    print('final state: ' + ', '.join(f'{k} = {v:.4g}' for k, v in fs.items()))
    print(f"speed: mean {s['speed_m_s']['mean']:.3f} m/s (min {s['speed_m_s']['min']:.3f}, "
          f"max {s['speed_m_s']['max']:.3f}); depth {s['depth_m']['min']:.2f} .. "
          f"{s['depth_m']['max']:.2f} m; max |roll| {s['roll_deg_max']:.2f} deg")
    if args.out:
        if args.out.endswith('.csv'):
            save_run_csv(run, args.out)
        else:
            from .sim_bag import write_run_bag
            write_run_bag(run, args.out)
        print(f'wrote {args.out}')
    return 0


IN_COLS = ('u', 'v', 'w', 'p', 'q', 'r', 'x', 'y', 'z', 'phi', 'theta', 'psi',
           'delta_r', 'delta_s', 'delta_b', 'delta_bp', 'delta_bs', 'n_rpm')
OUT_COLS = tuple(c + '_dot' for c in IN_COLS[:12])


def cmd_derivatives(args):
    from .core.model import OK, STATUS_TEXT
    m = _model(args)
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
        wr = csv.writer(fout)
        wr.writerow(OUT_COLS)
        for rownum, row in enumerate(rd, start=2):
            try:
                vals = np.array([float(row[i]) for i in idx])
            except (ValueError, IndexError):
                print(f'{args.input}: row {rownum}: not 18 numbers', file=sys.stderr)
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


NODES = ('simulator', 'identifier', 'record', 'play')


def run_node(argv):
    """python -m auv_ident run NODE [--ros-args ...]: the same node as `ros2 run auv_ident NODE`."""
    if not argv or argv[0] not in NODES:
        print(f'usage: python -m auv_ident run {{{",".join(NODES)}}} [--ros-args ...]',
              file=sys.stderr)
        return 2
    import importlib
    mod = importlib.import_module(f'auv_ident.nodes.{argv[0]}_node')
    return mod.main([f'auv_ident_{argv[0]}'] + list(argv[1:])) or 0


def build_parser():
    p = argparse.ArgumentParser(prog='python -m auv_ident', description=__doc__.split('\n')[0])
    sub = p.add_subparsers(dest='cmd', required=True)

    def vehicle_arg(sp):
        sp.add_argument('--vehicle', default='nps_auv2',
                        help='nps_auv2, remus100, isimi, or a vehicle YAML path')
        sp.add_argument('--mass-inverse', dest='mass_inverse', default='default',
                        choices=('default', 'exact', 'mss_literal'),
                        help="default: the vehicle file's choice (NPS AUV II: MSS literal)")

    sp = sub.add_parser('simulate', help='simulate a manoeuvre and print a summary')
    vehicle_arg(sp)
    sp.add_argument('--maneuver', default='zigzag', help='zigzag, steps, prbs, roll or a CSV')
    sp.add_argument('--duration', type=float, default=200.0, help='s')
    sp.add_argument('--dt', type=float, default=0.05, help='sample time T, s')
    sp.add_argument('--rpm', type=float, default=None, help="shaft speed (vehicle's cruise rpm)")
    sp.add_argument('--seed', type=int, default=0)
    sp.add_argument('--process-noise', action='store_true')
    sp.add_argument('--out', help='write the run: FILE.csv, or a bag directory')
    sp.set_defaults(func=cmd_simulate)

    sp = sub.add_parser('derivatives', help='evaluate x_dot = f(x, u) on a CSV table')
    vehicle_arg(sp)
    sp.add_argument('input')
    sp.add_argument('output')
    sp.set_defaults(func=cmd_derivatives)
    return p


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] == 'run':
        return run_node(argv[1:])
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (AuvIdentError, OSError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
