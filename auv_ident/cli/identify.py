"""identify, simulate, montecarlo, campaign: making a model, from simulated runs or bags."""
import sys

import numpy as np

from auv_ident.cli.common import (
    check_outputs,
    force_arg,
    ident_args,
    option_name,
    progress_meter,
    scheduler_arg,
    settings_args,
    settings_of,
    sim_current,
    trust_status,
    vehicle_arg,
    vehicle_model,
)
from auv_ident.core.errors import AuvIdentError
from auv_ident.core.model.state import Input


def cmd_simulate(args):
    from auv_ident.core.model.sensors import DEFAULT_PROCESS_STD
    from auv_ident.core.simulation.simulate import save_run_csv, simulate
    if args.out and args.out.endswith('.csv'):
        check_outputs(args, '--out')       # a bag directory: the bag writer never overwrites
    m = vehicle_model(args)
    run = simulate(m, args.maneuver, duration=args.duration, T=args.dt, seed=args.seed,
                   rpm=args.rpm, process_std=DEFAULT_PROCESS_STD if args.process_noise else None,
                   current=sim_current(args.current),
                   velocity_reference=args.velocity_reference)
    s = run.summary()
    fs = s['final_state']
    print(f"{m.vehicle.title}: manoeuvre {run.maneuver}, {s['duration_s']:.1f} s at "
          f"T = {run.T} s ({s['samples']} samples), seed {run.seed}")
    print('final state: ' + ', '.join(f'{k} = {v:.4g}' for k, v in fs.items()))
    print(f"speed: mean {s['speed_m_s']['mean']:.3f} m/s (min {s['speed_m_s']['min']:.3f}, "
          f"max {s['speed_m_s']['max']:.3f}); depth {s['depth_m']['min']:.2f} .. "
          f"{s['depth_m']['max']:.2f} m; max |roll| {s['roll_deg_max']:.2f} deg")
    if run.current is not None:
        print('water current ' + ', '.join(f'{v:g}' for v in run.current) + ' m/s (N, E, D); '
              f'velocity measured over {run.velocity_reference}')
    if args.out:
        if args.out.endswith('.csv'):
            save_run_csv(run, args.out)
        else:
            from auv_ident.offline.sim_bag import write_run_bag
            write_run_bag(run, args.out, command='python -m auv_ident ' + ' '.join(sys.argv[1:]))
        print(f'wrote {args.out}')
    return 0


# what identify --simulate takes of the identifier settings (the rest are the replay's: --bag)
SIMULATED_SETTINGS = ('vehicle', 'coefficients', 'noise_mode', 'initial_offset', 'tau',
                      'mass_inverse', 'current', 'current_down', 'velocity_reference')


def cmd_identify(args):
    if args.simulate and args.bag:
        raise AuvIdentError('give either --simulate MANEUVER or --bag PATH, not both')
    check_outputs(args, '--json', '--estimate-out')
    settings = settings_of(args)
    if args.bag and len(args.bag) > 1 and args.estimate_out:
        # the several-bags path writes no warm start; said before the work, not ignored
        raise AuvIdentError('--estimate-out: one --bag only (a warm start is written from one '
                            "bag's identification); drop it or identify one bag")
    if args.bag and len(args.bag) > 1:
        from auv_ident.analysis.bag_identify import identify_bags
        doc, table = identify_bags(args.bag, settings, refine_pass=not args.no_refine)
        print(table)
    elif args.bag and settings.input_map and _raw_map(settings.input_map):
        from auv_ident.analysis.raw_identify import identify_raw_bag
        if {'noise_std', 'q_state'} & settings.given:
            raise AuvIdentError('--noise-std and --q-state: the raw-sensor path does not take '
                                'them (the fused odometry path does)')
        if args.estimate_out:
            raise AuvIdentError('--estimate-out: not written for a raw-sensor map yet')
        doc, table = identify_raw_bag(args.bag[0], settings)
        print(table)
    elif args.bag:
        from auv_ident.analysis.bag_identify import identify_bag
        doc, table = identify_bag(args.bag[0], settings, refine_pass=not args.no_refine)
        print(table)
        if args.estimate_out and doc['stuck_at_end']:
            # the node never saves an estimate formed while a sensor is stuck as its last good
            # one (session/stuck.py); its warm start must not carry one either
            print(f'--estimate-out {args.estimate_out}: not written: the odometry '
                  f"{doc['stuck_at_end']} is still stuck at the end of the bag, so the estimate "
                  'was formed while the fault was active', file=sys.stderr)
        elif args.estimate_out:
            from auv_ident.session.estimate_file import estimate_document, write_estimate_json
            names = list(doc['coefficients'])
            write_estimate_json(args.estimate_out, estimate_document(
                doc['vehicle'], names, [doc['coefficients'][n]['estimate'] for n in names],
                doc['covariance'], None, doc['steps']))
            print(f"wrote {args.estimate_out} (the identifier node's warm_start)")
    else:
        doc = _identify_simulated(args, settings)
    if args.json:
        from auv_ident.analysis import results
        results.write_json(args.json, doc)
        print(f'wrote {args.json}')
    return trust_status(doc)


def _raw_map(input_map):
    """True if the input map has raw-sensor inputs (identified by analysis/raw_identify)."""
    from auv_ident.analysis.raw_identify import has_raw_sensors
    return has_raw_sensors(input_map)


def _identify_simulated(args, settings):
    """identify --simulate: prints the result, returns its JSON document."""
    from auv_ident.analysis import experiments as ex, results
    from auv_ident.vehicles import load_vehicle
    if args.estimate_out:
        raise AuvIdentError('--estimate-out needs --bag')
    other = sorted(settings.given - set(SIMULATED_SETTINGS))
    if other:
        raise AuvIdentError(f'{", ".join(map(option_name, other))}: the identifier\'s replay of a '
                            'bag (--bag) takes it, a simulated run does not')
    v = load_vehicle(settings.vehicle)
    names = results.coefficient_list(v, settings.coefficients)
    mode = settings.noise_mode
    cfg = results.make_config(names, noise_mode=mode, initial_offset=settings.initial_offset,
                              tau=settings.tau)
    pr = progress_meter('batch refinement', 40 * len(names))
    opt = settings.current_option
    sim = ex.identify_simulated(
        v, names, cfg, maneuver=args.simulate or ex.DEFAULT_MANEUVER, seed=args.seed,
        duration=args.duration, rpm=args.rpm, refine_pass=not args.no_refine,
        mass_inverse=settings.mass_inverse, progress=pr.update, current=opt,
        sim_current=sim_current(args.sim_current),
        velocity_reference=settings.velocity_reference)
    pr.close()
    res, run = sim.result, sim.run
    print(res.diagnosis.messages[0])
    print(f'{v.title}: identified {", ".join(names)} from a simulated '
          f'{run.maneuver!r} run of {run.t[-1]:.0f} s at T = {run.T} s, seed {run.seed}, '
          f'{run.u[0, Input.N_RPM]:.0f} rpm, sensor noise 1-sigma (u..psi) '
          + ' '.join(f'{s:g}' for s in run.noise_std))
    print(f'initial guesses {100 * settings.initial_offset:+.0f} % from truth; noise '
          f'adaptation: {mode}; ' + ('EKF pass + batch refinement (filter-error ML)'
                                     if not args.no_refine else 'EKF pass only'))
    print(f'water current: {opt.describe()}'
          + ('' if run.current is None else '; simulated in '
             + ', '.join(f'{c:g}' for c in run.current) + ' m/s (N, E, D)'))
    doc = results.result_dict(v, res, {'maneuver': run.maneuver, 'seed': run.seed,
                                       'duration_s': float(run.t[-1]), 'noise_mode': mode},
                              current_truth=run.current if run.current is not None
                              else np.zeros(3))
    print(results.doc_table(doc))
    print(f'{res.steps} EKF steps, mean NIS/dof {res.mean_nis_per_dof:.3f}, '
          f'wall {res.wall_s:.2f} s'
          + ''.join('\n- ' + m for m in res.diagnosis.messages[1:]))
    return doc


def cmd_montecarlo(args):
    from auv_ident.analysis import experiments as ex, results
    from auv_ident.vehicles import load_vehicle
    check_outputs(args, '--json')
    settings = settings_of(args)
    v = load_vehicle(settings.vehicle)
    names = results.coefficient_list(v, settings.coefficients)
    offsets = [float(o) for o in args.offsets.split(',')]
    pr = progress_meter('monte carlo', args.seeds * len(offsets))
    st = ex.montecarlo(v, names, seeds=args.seeds, offsets=offsets,
                       noise_mode=settings.noise_mode,
                       maneuver=args.maneuver, duration=args.duration, rpm=args.rpm,
                       refine_pass=not args.no_refine, jobs=args.jobs, progress=pr.update,
                       tau=settings.tau, scheduler=args.scheduler, noise_level=args.noise_level,
                       noise_tau=args.noise_tau, perturb=args.perturb)
    pr.close()
    print(f'{v.title}: {args.seeds} seeds x offsets {offsets}, manoeuvre {args.maneuver!r}, '
          f'{args.duration:.0f} s, noise adaptation {st["noise_mode"]}, '
          + ('refined' if st['refined'] else 'EKF only') + f', wall {st["wall_s"]:.0f} s'
          + ('' if args.noise_level == 1.0 and args.noise_tau == 0.0 else
             f'; sensor noise {args.noise_level:g}x the assumed, AR(1) tau {args.noise_tau:g} s '
             '(not told)')
          + ('' if not args.perturb else f'; truth: other coefficients x U(1 -+ '
             f'{args.perturb:g}) (not told)'))
    print(ex.montecarlo_table(st))
    if args.json:
        results.write_json(args.json, st)
        print(f'wrote {args.json}')
    return 0


def cmd_campaign(args):
    from auv_ident.analysis.campaign import run_campaign
    bars = []

    def progress_bar(total):
        bars.append(progress_meter('campaign', total))
        return bars[-1].update
    try:
        out = run_campaign(args.bags, args.out, vehicle=args.vehicle,
                           coefficients=args.coefficients, refine=not args.no_refine,
                           scheduler=args.scheduler, workers=args.workers,
                           progress_bar=progress_bar)
    finally:
        for bar in bars:
            bar.close()
    print(f"campaign: {out['bags']} bags ({out['skipped']} already done, skipped); "
          f"identified now: {out['ok']} ok, {out['error']} error, on {out['workers']} "
          f"worker(s), wall {out['wall_s']:.1f} s")
    print(f"wrote {out['csv']} and {out['trends']}")
    return 0


def add_commands(sub):
    """This family's subcommands on the parser's ``sub`` (argparse subparsers)."""
    sp = sub.add_parser('simulate', help='simulate a manoeuvre and print a summary')
    vehicle_arg(sp)
    sp.add_argument('--maneuver', default='zigzag',
                    help='zigzag, steps, prbs, roll or a CSV; a thruster vehicle (ROV): tank, '
                         'surge, sway, heave, yaw, steps')
    sp.add_argument('--duration', type=float, default=200.0, help='s')
    sp.add_argument('--dt', type=float, default=0.05, help='sample time T, s')
    sp.add_argument('--rpm', type=float, default=None, help="shaft speed (vehicle's cruise rpm)")
    sp.add_argument('--seed', type=int, default=0)
    sp.add_argument('--process-noise', action='store_true')
    sp.add_argument('--current', metavar='N,E[,D]',
                    help='fly in a constant water current, m/s NED (where the water goes)')
    sp.add_argument('--velocity-reference', dest='velocity_reference', default='ground',
                    choices=('ground', 'water'),
                    help='what the simulated DVL measures: ground (bottom lock, default) or '
                         'water (water track)')
    sp.add_argument('--out', help='write the run: FILE.csv, or a bag directory (never '
                                  'overwritten)')
    force_arg(sp)
    sp.set_defaults(func=cmd_simulate)

    sp = sub.add_parser('identify', help='identify coefficients from a simulated run or a bag',
                        description='Every identifier setting is an option; with --bag they '
                                    "apply to the identifier's replay of the bag (a setting "
                                    "not given: what the bag's metadata says, else the "
                                    'default), with --simulate the '
                                    + ', '.join(map(option_name, SIMULATED_SETTINGS))
                                    + ' do. Several bags: noise mode fixed, current none '
                                      'unless a known one is given.')
    sp.add_argument('--simulate', metavar='MANEUVER', help='ident, zigzag, prbs, ... or a CSV')
    sp.add_argument('--bag', action='append',
                    help='rosbag2 MCAP directory (or .mcap file); repeat it for one model from '
                         'several runs of the vehicle')
    sp.add_argument('--seed', type=int, default=0)
    sp.add_argument('--duration', type=float, default=600.0, help='s (simulated runs)')
    sp.add_argument('--estimate-out', dest='estimate_out', metavar='FILE',
                    help='bags: also write the coefficients as an estimate file, the identifier '
                         "node's warm_start (e.g. the set --coefficients auto chose)")
    sp.add_argument('--sim-current', dest='sim_current', metavar='N,E[,D]',
                    help='with --simulate: fly the run in this water current, m/s NED')
    ident_args(sp)
    settings_args(sp)
    sp.set_defaults(func=cmd_identify)

    sp = sub.add_parser('montecarlo', help='accuracy and consistency over seeds and starts')
    sp.add_argument('--seeds', type=int, default=20)
    sp.add_argument('--offsets', default='0.5,-0.5', help='initial offsets, comma-separated')
    sp.add_argument('--maneuver', default='ident')
    sp.add_argument('--duration', type=float, default=600.0)
    sp.add_argument('--jobs', type=int, default=2,
                    help='worker processes of the local Dask cluster (1: serially in this '
                         'process, no cluster); ignored with --scheduler')
    sp.add_argument('--noise-level', dest='noise_level', type=float, default=1.0,
                    help='the simulated sensor noise is this many times the one the filter '
                         'assumes (not told to it)')
    sp.add_argument('--noise-tau', dest='noise_tau', type=float, default=0.0,
                    help='first-order correlation time of the simulated sensor noise, s '
                         '(0: white)')
    sp.add_argument('--perturb', type=float, default=0.0,
                    help='truth vehicle: every coefficient not identified (added mass aside) '
                         'x U(1 - P, 1 + P) per seed (not told)')
    scheduler_arg(sp)
    ident_args(sp)
    settings_args(sp, ('vehicle', 'coefficients', 'noise_mode', 'tau'))
    sp.set_defaults(func=cmd_montecarlo)

    sp = sub.add_parser('campaign', help='identify every bag of a folder on Dask: '
                                         'campaign.csv and trends.png')
    sp.add_argument('--bags', required=True, metavar='DIR_OR_GLOB',
                    help='a folder (searched recursively for bags) or a glob pattern')
    sp.add_argument('--vehicle', default=None,
                    help="vehicle name or YAML path (default: each bag's metadata; its "
                         'content is sent to the workers)')
    sp.add_argument('--coefficients', default='',
                    help="comma-separated names (default: the vehicle's set)")
    sp.add_argument('--no-refine', action='store_true', help='EKF pass only (no refinement)')
    sp.add_argument('--workers', type=int, default=2,
                    help='worker processes of the local Dask cluster (ignored with --scheduler)')
    scheduler_arg(sp)
    sp.add_argument('--out', required=True,
                    help='folder of campaign.csv and trends.png; re-running with the same '
                         "folder skips the bags already 'ok'")
    sp.set_defaults(func=cmd_campaign)
