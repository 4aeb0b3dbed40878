"""Command line: python -m auv_ident {simulate,identify,report,bag,import,derivatives,...}.

Expected errors (bad options, bad files, states outside the model's domain) print one clear
line on stderr and exit with status 2; no traceback. `identify` and `report` exit with status
EXIT_UNTRUSTED (3) when they computed a result that should not be trusted: NOT consistent (the
data contradict the identification's assumptions) or NOT plausible (the estimates contradict
the vehicle file or the physics); the first line of the output, result.json's `diagnosis`
and report.md say why.
"""
import argparse
import csv
import os
import sys

import numpy as np

from auv_ident.core.errors import AuvIdentError
from auv_ident.core.model.state import Input
from auv_ident.session.settings import ParameterError


def _model(args, theta_names=()):
    from auv_ident.core.model.hydrodynamics import Model
    from auv_ident.vehicles import load_vehicle
    return Model(load_vehicle(args.vehicle), theta_names,
                 mass_inverse=getattr(args, 'mass_inverse', 'default'))


def _sim_current(text):
    """--current N,E[,D] of simulate: (3,) m/s NED, or None."""
    from auv_ident.core.model.current import parse_current
    if text is None:
        return None
    opt = parse_current(text, what='--current')
    if opt.estimate:
        raise AuvIdentError("simulate --current takes N,E[,D] in m/s (the water's velocity, "
                            'NED), not "estimate"')
    return opt.fixed


def cmd_simulate(args):
    from auv_ident.core.model.sensors import DEFAULT_PROCESS_STD
    from auv_ident.core.simulation.simulate import save_run_csv, simulate
    if args.out and args.out.endswith('.csv'):
        _check_outputs(args, '--out')       # a bag directory: the bag writer never overwrites
    m = _model(args)
    run = simulate(m, args.maneuver, duration=args.duration, T=args.dt, seed=args.seed,
                   rpm=args.rpm, process_std=DEFAULT_PROCESS_STD if args.process_noise else None,
                   current=_sim_current(args.current),
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


def _progress(label, total):
    from auv_ident.analysis.progress import Progress
    pr = Progress(total, label)
    return pr


# what identify --simulate takes of the identifier settings (the rest are the replay's: --bag)
SIMULATED_SETTINGS = ('vehicle', 'coefficients', 'noise_mode', 'initial_offset', 'tau',
                      'mass_inverse', 'current', 'current_down', 'velocity_reference')


def _settings(args):
    """The IdentifierSettings of the options given (the rest: the defaults, or a bag's
    metadata where it says them)."""
    from auv_ident.session.settings import IdentifierSettings, settings_fields
    return IdentifierSettings.from_values(**{f.name: getattr(args, f.name, None)
                                             for f in settings_fields()})


EXIT_UNTRUSTED = 3     # a result computed, but NOT consistent or NOT plausible (docstring)


def _trust_status(doc):
    """0 for a result whose diagnosis says it can be trusted, else EXIT_UNTRUSTED."""
    diagnosis = doc.get('diagnosis') or {}
    trusted = diagnosis.get('consistent', True) and diagnosis.get('plausible', True)
    return 0 if trusted else EXIT_UNTRUSTED


def _option(name):
    return '--' + name.replace('_', '-')


def _check_outputs(args, *options, folder=False):
    """Before any work: each output option given (e.g. '--json') names a path that can be
    written, and one that exists is overwritten only with --force (a result, a model or a
    report is never replaced silently). folder: the outputs are folders (report --out)."""
    from auv_ident.core.safe_files import unwritable_reason
    for option in options:
        path = getattr(args, option.lstrip('-').replace('-', '_'), None)
        if not path:
            continue
        if os.path.lexists(path) and not args.force:
            raise AuvIdentError(f'{option} {path}: exists already; give --force to overwrite '
                                'it')
        reason = unwritable_reason(path, folder=folder)
        if reason:
            raise AuvIdentError(f'{option} {path}: {reason}')


def cmd_identify(args):
    if args.simulate and args.bag:
        raise AuvIdentError('give either --simulate MANEUVER or --bag PATH, not both')
    _check_outputs(args, '--json', '--estimate-out')
    settings = _settings(args)
    if args.bag and len(args.bag) > 1:
        from auv_ident.analysis.bag_identify import identify_bags
        doc, table = identify_bags(args.bag, settings, refine_pass=not args.no_refine)
        print(table)
    elif {'noise_std', 'q_state'} & settings.given:
        raise AuvIdentError('--noise-std and --q-state apply to several bags (identify --bag A '
                            '--bag B ...)')
    elif args.bag and settings.input_map and _raw_map(settings.input_map):
        from auv_ident.analysis.raw_identify import identify_raw_bag
        if args.estimate_out:
            raise AuvIdentError('--estimate-out: not written for a raw-sensor map yet')
        doc, table = identify_raw_bag(args.bag[0], settings)
        print(table)
    elif args.bag:
        from auv_ident.analysis.bag_identify import identify_bag
        doc, table = identify_bag(args.bag[0], settings, refine_pass=not args.no_refine)
        print(table)
        if args.estimate_out:
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
    return _trust_status(doc)


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
        raise AuvIdentError(f'{", ".join(map(_option, other))}: the identifier\'s replay of a '
                            'bag (--bag) takes it, a simulated run does not')
    v = load_vehicle(settings.vehicle)
    names = results.coefficient_list(v, settings.coefficients)
    mode = settings.noise_mode
    cfg = results.make_config(names, noise_mode=mode, initial_offset=settings.initial_offset,
                              tau=settings.tau)
    pr = _progress('batch refinement', 40 * len(names))
    opt = settings.current_option
    sim = ex.identify_simulated(
        v, names, cfg, maneuver=args.simulate or ex.DEFAULT_MANEUVER, seed=args.seed,
        duration=args.duration, rpm=args.rpm, refine_pass=not args.no_refine,
        mass_inverse=settings.mass_inverse, progress=pr.update, current=opt,
        sim_current=_sim_current(args.sim_current),
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
    _check_outputs(args, '--json')
    settings = _settings(args)
    v = load_vehicle(settings.vehicle)
    names = results.coefficient_list(v, settings.coefficients)
    offsets = [float(o) for o in args.offsets.split(',')]
    pr = _progress('monte carlo', args.seeds * len(offsets))
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
        bars.append(_progress('campaign', total))
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
          + ', '.join(f"{ch} {_pct(d['fit_percent'])}/{_pct(d['fit_percent_prior'])}"
                      for ch, d in fits.items()))
    for line in screening_lines(val['screening']):
        print(line)
    zz = val['zigzag']
    if zz['detected']:
        o = zz['overshoot_deg']
        print(f"closed-loop {zz['test']} zig-zag, overshoots (deg) measured / identified / "
              'prior: ' + '; '.join(
                  '/'.join(_pct(o[k][i]) if i < len(o[k]) else '-'
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
    _check_outputs(args, '--out', folder=True)
    if args.export:
        from auv_ident.analysis.export import check_formats
        check_formats(args.export)      # before the work, not after it
    if args.model:
        return cmd_model_report(args)
    settings = _settings(args)
    out = make_report(args.out, settings, simulate_maneuver=args.simulate, bag=args.bag,
                      seed=args.seed, duration=args.duration,
                      command='python -m auv_ident ' + ' '.join(sys.argv[1:]),
                      sim_current=_sim_current(args.sim_current), validate_bag=args.validate,
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
          + ', '.join(f"{ch} {_pct(d['fit_percent'])}/{_pct(d['fit_percent_prior'])}"
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
    return _trust_status(doc)


def _report_exports(args, model_path, bags):
    """report --export FORMAT: the reported model exported into the report folder."""
    if not args.export:
        return
    from auv_ident.analysis.export import export_into
    for path in export_into(args.out, model_path, args.export, vehicle=args.vehicle,
                            bags=bags, echo=print):
        print(f'wrote {path}')


def _pct(v):
    return '-' if v is None else f'{v:.1f}'


def cmd_compare_methods(args):
    from auv_ident.analysis import compare_methods as cm
    from auv_ident.analysis.results import write_json
    if args.simulate and args.bag:
        raise AuvIdentError('give either --simulate MANEUVER or --bag PATH, not both')
    _check_outputs(args, '--json')
    methods = cm.parse_methods(args.methods)
    settings = _settings(args)
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
    _check_outputs(args, '--json')
    b = bench(duration=args.duration)
    print(format_bench(b))
    if args.json:
        from auv_ident.analysis.results import write_json
        write_json(args.json, b)
        print(f'wrote {args.json}')
    return 0


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
                                             'python -m auv_ident ' + ' '.join(sys.argv[1:]))))
        return 0
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


def cmd_export(args):
    from auv_ident.analysis.export import export_model, fit_path, FITTED
    if args.format not in FITTED and (args.bag or args.fit_out):
        raise AuvIdentError(f'--bag and --fit-out are for the fitted formats '
                            f'({", ".join(FITTED)}), not --format {args.format}')
    if args.format in FITTED and not args.fit_out:
        args.fit_out = str(fit_path(args.out))
    _check_outputs(args, '--out', '--fit-out')
    path = export_model(args.model, args.out, fmt=args.format, vehicle=args.vehicle,
                        gz_added_mass=args.gz_added_mass, echo=print, bags=args.bag,
                        fit_out=args.fit_out)
    print(f'wrote {path} ({args.format})')
    return 0


def cmd_derivatives(args):
    from auv_ident.core.model.hydrodynamics import OK, STATUS_TEXT
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


NODES = ('simulator', 'identifier', 'record', 'play')


def run_node(argv):
    """python -m auv_ident run NODE [--ros-args ...]: as `ros2 run auv_ident NODE`."""
    if not argv or argv[0] not in NODES:
        print(f'usage: python -m auv_ident run {{{",".join(NODES)}}} [--ros-args ...]',
              file=sys.stderr)
        return 2
    import importlib
    mod = importlib.import_module(f'auv_ident.ros.{argv[0]}_node')
    return mod.main([f'auv_ident_{argv[0]}'] + list(argv[1:])) or 0


def build_parser():
    from auv_ident.analysis.report import REPORT_SETTINGS
    p = argparse.ArgumentParser(prog='python -m auv_ident', description=__doc__.split('\n')[0])
    sub = p.add_subparsers(dest='cmd', required=True)

    def vehicle_arg(sp):
        sp.add_argument('--vehicle', default='nps_auv2',
                        help='nps_auv2, remus100, isimi, or a vehicle YAML path')
        sp.add_argument('--mass-inverse', dest='mass_inverse', default='default',
                        choices=('default', 'exact', 'mss_literal'),
                        help="default: the vehicle file's choice (NPS AUV II: MSS literal)")

    def force_arg(sp):
        sp.add_argument('--force', action='store_true',
                        help='overwrite an output that exists already (without it the command '
                             'stops at once, before any work, and says so)')

    def scheduler_arg(sp):
        sp.add_argument('--scheduler', default=None, metavar='ADDRESS',
                        help='run on this existing Dask cluster (tcp://host:8786, or a '
                             'scheduler file) instead of a local one (docs/campaigns.md)')

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

    def settings_args(sp, names=None):
        """An option for each identifier setting (or those named), made from its field:
        --name-with-dashes, help, choices, default (session/settings.py); lists are
        comma-separated. Not given: None (the default, or what a bag's metadata says)."""
        from auv_ident.session.settings import help_text, settings_fields
        for f in settings_fields():
            if names is not None and f.name not in names:
                continue
            kind, shown = f.metadata['kind'], f.default
            if isinstance(shown, tuple):
                shown = ','.join(map(str, shown)) or 'none'
            kw = {'dest': f.name, 'default': None,
                  'help': (help_text(f) + f' (default: {shown})').replace('%', '%%')}
            if kind == 'bool':
                kw.update(action='store_const', const=True)
            elif f.metadata['choices']:
                kw['choices'] = f.metadata['choices']
            elif kind in ('strings', 'floats'):
                kw['metavar'] = 'A,B,...'
            elif kind == 'float':
                kw['type'] = float
            sp.add_argument(_option(f.name), **kw)

    def ident_args(sp):
        sp.add_argument('--fixed-noise', dest='noise_mode', action='store_const', const='fixed',
                        help='same as --noise-mode fixed')
        sp.add_argument('--no-refine', action='store_true',
                        help='EKF pass only (no batch refinement)')
        sp.add_argument('--json', help='write the result as JSON')
        sp.add_argument('--rpm', type=float, default=None)
        force_arg(sp)

    sp = sub.add_parser('identify', help='identify coefficients from a simulated run or a bag',
                        description='Every identifier setting is an option; with --bag they '
                                    "apply to the identifier's replay of the bag (a setting "
                                    "not given: what the bag's metadata says, else the "
                                    'default), with --simulate the '
                                    + ', '.join(map(_option, SIMULATED_SETTINGS))
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
    return p


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] == 'run':
        return run_node(argv[1:])
    if argv and argv[0] == 'loadtest':
        from auv_ident.ros.loadtest import main as loadtest_main
        return loadtest_main(argv[1:]) or 0
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ParameterError as err:      # an identifier setting: its option
        print(f'error: {_option(err.name)}: {err.message}', file=sys.stderr)
        return 2
    except (AuvIdentError, OSError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
