"""report, compare-methods, bench, export: judging a model and taking it where it is used."""
import sys

from auv_ident.cli.common import (
    check_outputs,
    force_arg,
    pct,
    settings_args,
    settings_of,
    sim_current,
    trust_status,
)
from auv_ident.core.errors import AuvIdentError


def _report_methods(text):
    """--methods of report: None (not given), or the validated method names ('all': every
    one)."""
    if text is None:
        return None
    from auv_ident.analysis.compare_methods import parse_methods
    return parse_methods('' if text.strip() == 'all' else text)


def cmd_model_report(args):
    """report --model MODEL.json --validate BAG: a saved model judged on an unseen run."""
    from auv_ident.analysis.model_report import make_model_report, screening_lines
    if args.simulate or args.bag or args.methods:
        raise AuvIdentError('report --model judges a saved model: --simulate, --bag and '
                            '--methods do not apply (the model says what it was identified '
                            'from)')
    if not args.validate:
        raise AuvIdentError('report --model needs --validate BAG: a run the model never saw')
    ident = [b.strip() for b in (args.ident_bags or '').split(',') if b.strip()] or None
    out = make_model_report(args.out, args.model, args.validate, vehicle=args.vehicle,
                            ident_bags=ident, input_map=args.input_map,
                            command='python -m auv_ident ' + ' '.join(sys.argv[1:]))
    val = out['result']['validation']
    fits = {ch: val['channels'][ch] for ch in ('r', 'psi') if ch in val['channels']}
    fits.update(val.get('derived_channels') or {})
    print(f"model {args.model} on {val['source']}: free-run fit % (identified / prior) "
          + ', '.join(f"{ch} {pct(d['fit_percent'])}/{pct(d['fit_percent_prior'])}"
                      for ch, d in fits.items()))
    for line in screening_lines(val['screening']):
        print(line)
    zz = val['zigzag']
    if zz['detected']:
        o = zz['overshoot_deg']
        print(f"closed-loop {zz['test']} zig-zag, overshoots (deg) measured / identified / "
              'prior: ' + '; '.join(
                  '/'.join(pct(o[k][i]) if i < len(o[k]) else '-'
                           for k in ('measured', 'predicted', 'prior'))
                  for i in range(len(o['measured']))))
        print('measured reversal lag past the switch angle (deg / s): ' + '; '.join(
            f'{d:.2f}/{t:.2f}' for d, t in zip(zz['reversal_lag_deg'], zz['reversal_lag_s'])))
    else:
        print(f"not a zig-zag run: {zz['reason']}")
    b = val.get('rudder_bias_diagnosis')
    if b:
        print(f"diagnosis (not scored): rudder bias {b['bias_deg']:+.2f} deg fits the yaw rate "
              f"best ({b['r_fit_percent_with_bias']:.1f} %)")
    print(f"report: {out['report']}, {out['html']}, {out['csv']}")
    _report_exports(args, args.model, None)     # over the model's own bags
    return 0


def cmd_report(args):
    from auv_ident.analysis.report import make_report
    from auv_ident.analysis.results import doc_table
    check_outputs(args, '--out', folder=True)
    if args.export:
        from auv_ident.analysis.export import check_formats
        check_formats(args.export)      # before the work, not after it
    if args.model:
        return cmd_model_report(args)
    settings = settings_of(args)
    out = make_report(args.out, settings, simulate_maneuver=args.simulate, bag=args.bag,
                      seed=args.seed, duration=args.duration,
                      command='python -m auv_ident ' + ' '.join(sys.argv[1:]),
                      sim_current=sim_current(args.sim_current), validate_bag=args.validate,
                      holdout=args.holdout, methods=_report_methods(args.methods))
    doc = out['result']
    verdict = (doc.get('diagnosis') or {}).get('messages') or []
    if verdict:  # the first line a user reads is whether to trust the result (as identify's)
        print(verdict[0])
    print(f"{doc.get('source', '')}: EKF pass + batch refinement, noise adaptation "
          f"{settings.noise_mode}")
    print(doc_table(doc))
    val = doc['validation']
    mean = val['mean_fit_percent_nu']
    print(f"validation against the measurements of {val['source']}: mean fit % over u v w p q r "
          + ', '.join(f'{m} {mean[m]:.1f}' if mean[m] is not None else f'{m} -'
                      for m in val['models'])
          + '; fit % per channel (identified / prior): '
          + ', '.join(f"{ch} {pct(d['fit_percent'])}/{pct(d['fit_percent_prior'])}"
                      for ch, d in val['channels'].items()))
    if val.get('screening'):
        print(f"{val['source']}, read without the filter: {val['screening']['line']}")
    true_val = doc.get('validation_true_model') or {}
    if true_val.get('rms'):
        print(f"validation on the held-out {true_val['maneuver']!r} manoeuvre (seed "
              f"{true_val['seed']}, process noise on), RMS error of the identified model "
              'against the true one: '
              + ', '.join(f"{k} {v:.3g} {true_val['rms_units'][k]}"
                          for k, v in true_val['rms'].items()))
    print(f"report: {out['report']} and {out['html']}")
    _report_exports(args, out['json'], [args.bag] if args.bag else None)
    return trust_status(doc)


def _report_exports(args, model_path, bags):
    """report --export FORMAT: the reported model exported into the report folder."""
    if not args.export:
        return
    from auv_ident.analysis.export import export_into
    for path in export_into(args.out, model_path, args.export, vehicle=args.vehicle,
                            bags=bags, echo=print):
        print(f'wrote {path}')


def cmd_compare_methods(args):
    from auv_ident.analysis import compare_methods as cm
    from auv_ident.analysis.results import write_json
    if args.simulate and args.bag:
        raise AuvIdentError('give either --simulate MANEUVER or --bag PATH, not both')
    check_outputs(args, '--json')
    methods = cm.parse_methods(args.methods)
    settings = settings_of(args)
    source, validation = cm.compare_sources(
        settings, simulate_maneuver=args.simulate, bag=args.bag, seed=args.seed,
        duration=args.duration, validate=args.validate, truth=args.truth)
    doc = cm.compare_methods(source, validation, methods=methods,
                             initial_offset=settings.initial_offset, holdout=args.holdout,
                             mass_inverse=settings.mass_inverse,
                             progress=lambda m: print(f'running {m} ...', file=sys.stderr))
    print(cm.methods_table(doc))
    if args.json:
        write_json(args.json, doc)
        print(f'wrote {args.json}')
    return 0


def cmd_bench(args):
    from auv_ident.analysis.bench import bench, format_bench
    check_outputs(args, '--json')
    b = bench(duration=args.duration)
    print(format_bench(b))
    if args.json:
        from auv_ident.analysis.results import write_json
        write_json(args.json, b)
        print(f'wrote {args.json}')
    return 0


def cmd_export(args):
    from auv_ident.analysis.export import export_model, fit_path, FITTED
    if args.format not in FITTED and (args.bag or args.fit_out):
        raise AuvIdentError(f'--bag and --fit-out are for the fitted formats '
                            f'({", ".join(FITTED)}), not --format {args.format}')
    if args.format in FITTED and not args.fit_out:
        args.fit_out = str(fit_path(args.out))
    check_outputs(args, '--out', '--fit-out')
    path = export_model(args.model, args.out, fmt=args.format, vehicle=args.vehicle,
                        gz_added_mass=args.gz_added_mass, echo=print, bags=args.bag,
                        fit_out=args.fit_out)
    print(f'wrote {path} ({args.format})')
    return 0


def add_commands(sub):
    """This family's subcommands on the parser's ``sub`` (argparse subparsers)."""
    from auv_ident.analysis.report import REPORT_SETTINGS
    sp = sub.add_parser('report', help='identification + validation against held-out '
                                       'measurements: report.md, report.html, PNG, JSON')
    settings_args(sp, REPORT_SETTINGS)
    sp.add_argument('--simulate', metavar='MANEUVER')
    sp.add_argument('--bag')
    sp.add_argument('--seed', type=int, default=0)
    sp.add_argument('--duration', type=float, default=600.0)
    sp.add_argument('--out', required=True, help='report folder (created; an existing one only '
                                                 'with --force)')
    force_arg(sp)
    sp.add_argument('--validate', metavar='BAG',
                    help='another bag of the same vehicle to validate on (default: the final '
                         '--holdout part of the identification run, left out of it)')
    sp.add_argument('--methods', metavar='LIST',
                    help="also run these identification methods on the same data and "
                         "validation run ('all', or e.g. ekf,ukf,output_error; "
                         "docs/methods.md) and add a section 'Methods side by side'")
    sp.add_argument('--holdout', type=float, default=0.25,
                    help='without --validate: fraction of the run held out at its end '
                         '(default 0.25)')
    sp.add_argument('--model', metavar='MODEL.json',
                    help='judge this saved model (identify --json) on --validate BAG instead '
                         'of identifying: free run, closed-loop zig-zag, rudder diagnosis '
                         '(docs/kvlcc2.md)')
    sp.add_argument('--ident-bags', dest='ident_bags', metavar='A,B',
                    help='with --model: the bags the steering gear and thrust model are '
                         "identified from (default: the model's identification bags)")
    sp.add_argument('--sim-current', dest='sim_current', metavar='N,E[,D]',
                    help='with --simulate: fly the run in this water current, m/s NED')
    sp.add_argument('--export', action='append', metavar='FORMAT',
                    help='also export the model into the report folder, as `export --format '
                         'FORMAT` would (repeatable: vehicle, uuv, gz, urdf-hydrodynamics, '
                         'python; files vehicle.yaml, uuv.xacro, gz.sdf, hydrodynamics.urdf, '
                         'model.py; docs/export.md)')
    sp.set_defaults(func=cmd_report)

    sp = sub.add_parser('compare-methods',
                        help='the same data through EKF, UKF, filter-error, output-error and '
                             'equation-error identification (docs/methods.md)')
    settings_args(sp, ('vehicle', 'coefficients', 'initial_offset', 'mass_inverse'))
    sp.add_argument('--simulate', metavar='MANEUVER', help='ident, zigzag, prbs, ... or a CSV')
    sp.add_argument('--bag', help='rosbag2 MCAP directory (or .mcap file) to identify from')
    sp.add_argument('--seed', type=int, default=0)
    sp.add_argument('--duration', type=float, default=600.0, help='s (simulated runs)')
    sp.add_argument('--methods', default='',
                    help='comma-separated subset of ekf,ukf,filter_error,output_error,'
                         'equation_error (default: all)')
    sp.add_argument('--validate', metavar='BAG',
                    help='validate on this bag (default: the final --holdout of the data, '
                         'left out of the identification)')
    sp.add_argument('--truth', metavar='JSON',
                    help='the true coefficients ("coefficients": {name: value}, e.g. the '
                         'truth.json of test/independent_data.py) for error %% on a bag not '
                         'written by our simulator')
    sp.add_argument('--holdout', type=float, default=0.2,
                    help='fraction of the record kept for validation without --validate')
    sp.add_argument('--json', help='write the comparison as JSON')
    force_arg(sp)
    sp.set_defaults(func=cmd_compare_methods)

    sp = sub.add_parser('bench', help='EKF speed vs filterpy, real-time factor, memory')
    sp.add_argument('--duration', type=float, default=600.0)
    sp.add_argument('--json')
    force_arg(sp)
    sp.set_defaults(func=cmd_bench)

    sp = sub.add_parser('export', help='write an identified model where it is used: an updated '
                                       'vehicle file, uuv_simulator or gz-sim hydrodynamics '
                                       '(docs/export.md)')
    sp.add_argument('model', help='result.json of identify --json or report, or the identifier '
                                  "node's estimate file (save_path)")
    sp.add_argument('--vehicle', help='the vehicle file or name the model was identified with '
                                      '(default: the one the model names)')
    sp.add_argument('--format', default='vehicle', help='vehicle (default), uuv (uuv_simulator '
                                                        'fossen xacro), gz (gz-sim '
                                                        'Hydrodynamics SDF), '
                                                        'urdf-hydrodynamics (ROS 2 '
                                                        'hydrodynamics / auv_controllers), '
                                                        'python (a numpy module, exact)')
    sp.add_argument('--gz-added-mass', default='link', choices=('link', 'plugin'),
                    help='--format gz: added mass as <fluid_added_mass> (link, default, Gazebo '
                         "Ionic+) or as the plugin's *Dot* terms with its Coriolis disabled")
    sp.add_argument('--bag', action='append', metavar='PATH',
                    help='uuv, gz, urdf-hydrodynamics: a run whose measured velocities are the '
                         "damping fit's envelope (repeatable; default: the model's own bags "
                         'when they are here, else a simulated run)')
    sp.add_argument('--out', required=True, help='file to write')
    sp.add_argument('--fit-out', help='uuv, gz, urdf-hydrodynamics: the fit %% per DOF as JSON '
                                      '(default: OUT.fit.json, next to the file)')
    sp.add_argument('--force', action='store_true', help='replace an existing --out')
    sp.set_defaults(func=cmd_export)
