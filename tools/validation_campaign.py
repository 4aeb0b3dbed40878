"""Validation campaign: does the identified model predict a run it never saw better than the
vehicle file's model?

For each seed, a truth vehicle differs from the NPS AUV II file by factors U(0.8, 1.2)
(offline/independent_data.py, perturb 0.2), in one of two ways (--prior-error):

- ``identified`` (default): only the identified coefficients differ (perturb_keep = every
  coefficient NOT identified, added mass included), so the file and the truth differ exactly
  where identification can correct them. The truth vehicle depends on the set. Not for the
  ``auto`` set, whose coefficients are known only after the identification.
- ``all``: every coefficient of the vehicle differs (perturb_keep = ()): the same truth vehicle
  for every set. The factors are drawn per coefficient in file order whatever is kept, so a
  coefficient perturbed in both modes has the same factor in both. What differs from
  ``identified``: the coefficients not identified are wrong too, and so is the added mass
  (each pair M[i, j], M[j, i] by one factor; coefficients that are 0 in the file stay 0). NPS
  AUV II's file uses MSS's literal mass inverse, which no added-mass value changes, so the
  truth vehicle uses the exact inverse of its perturbed mass matrix (independent_data's note
  'mass_inverse mss_literal -> exact'): the identified model (the file's literal inverse
  with the identified coefficients) cannot represent the true added mass.

The truth vehicle flies two independent runs (bags made by the independent generator, not by
auv_ident's simulator): run A (seed s) and run B (seed s + 100: another manoeuvre, other noise,
same truth vehicle). Then

    python -m auv_ident report --bag A/bag --vehicle nps_auv2 --coefficients SET \\
        --validate B/bag --out OUT

identifies SET on A (prior and initial guesses from the vehicle file) and validates on B's
measurements (SET ``auto``: ``auto,Z_ds,Z_q,Z_w,M_ds,K_v``, the set chosen from A's data,
core/identification/selection.py). Printed per (set, seed): mean fit % over u v w p q r of the
identified, the prior and, as the ceiling the sensor noise leaves, the true model; the gain
(identified - prior); the yaw-rate (r) fit of the three; the mean fit over x y z phi theta psi; the
largest
|error| % over the identified coefficients of the identified and of the file's values against
the truth; the number identified; the wall time of the report command. The true model flies
like the others (analysis.validation.validate_on_run, B's initial state and commands, still
water): with ``identified`` the vehicle file with the identified coefficients at their truth
values (= the truth vehicle), with ``all`` the whole truth vehicle file (truth_vehicle.yaml).

Where the limit lies: run B is also written with its noise-free truth states
(truth_states.npz), and per model the free run's mean fit over u v w p q r against them is
given ("noise-free"), with the fit of the noise-free states against the measurements (the
"noise ceiling": what a perfect model scores on the measured data). The identified and prior
free runs for this are flown again as the report flies them (the same function, the estimates
and identified current of result.json); ``report_reproduced`` in campaign.json is the largest
difference of their measured fits from the report's.

With --mass-inverse exact the report command gets --mass-inverse exact: the identified and
the prior model form M^-1 = inv(M_RB + M_A) (NPS AUV II's file: MSS's literal inverse, the same
to 2e-3), so that added-mass coefficients can be identified (and chosen by auto); the reports
and campaign.json are then SET-exact and campaign-exact.json.

    PYTHONPATH=. .venv/bin/python tools/validation_campaign.py [--out DIR]
        [--sets paper,twenty,auto] [--seeds 1,2] [--prior-error identified|all]
        [--mass-inverse default|exact] [--duration 600] [--validation-duration 300]
        [--case a|b] [--reuse]

With --reuse, bags already generated are kept (reports are always made again).
"""
import argparse
import json
import os
from pathlib import Path
import subprocess
import sys
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from auv_ident.analysis.bag_identify import bag_source  # noqa: E402
from auv_ident.analysis.validation import validate_on_run  # noqa: E402
from auv_ident.core.model.state import NU_NAMES, STATE_NAMES  # noqa: E402
from auv_ident.core.simulation.prediction import fit_percent  # noqa: E402
from auv_ident.offline.independent_data import DataConfig, generate  # noqa: E402
from auv_ident.session.settings import IdentifierSettings  # noqa: E402
from auv_ident.vehicles import load_vehicle  # noqa: E402

PAPER = ('Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v')
SETS = {
    'paper': PAPER,
    'twenty': PAPER + ('Y_v', 'Y_r', 'Y_dr', 'N_v', 'N_r', 'N_dr', 'M_uw', 'M_uq', 'K_p',
                       'Z_dsn', 'X_vv', 'K_vw', 'Z_vv', 'M_vv', 'N_vw'),
    'auto': ('auto',) + PAPER,      # chosen from the data, the paper's five always in
}
# the sampling and command cases of tools/independent_baseline.py
CASES = {
    'a': dict(odom_rate=20.0, commands='periodic', command_rate=20.0),
    'b': dict(odom_rate=10.0, odom_jitter=0.1, dropout=0.05, commands='on_change'),
}
PRIOR_ERRORS = ('identified', 'all')
POSE = tuple(n for n in STATE_NAMES if n not in NU_NAMES)


def named(set_name):
    """The coefficient names of a set (for auto: the ones always identified)."""
    return tuple(n for n in SETS[set_name] if n != 'auto')


def case_dir(args):
    """Where a campaign's bags, reports and campaign.json go."""
    base = Path(args.out) / args.case
    return base if args.prior_error == 'identified' else base / 'prior-all'


def make_bags(set_name, seed, args):
    """Run A (the truth vehicle) and run B (the same truth vehicle, seed + 100); returns their
    directories. --prior-error identified: the set's coefficients perturbed, one truth per set;
    all: every coefficient, one truth per seed shared by the sets."""
    if args.prior_error == 'identified':
        names = named(set_name)
        keep = tuple(n for n in load_vehicle('nps_auv2').names if n not in names)
        out = case_dir(args) / set_name / f'seed{seed}'
    else:
        keep = ()
        out = case_dir(args) / 'bags' / f'seed{seed}'
    a_dir, b_dir = out / 'A', out / 'B'
    if not (args.reuse and (a_dir / 'truth.json').is_file()):
        generate(DataConfig(vehicle='nps_auv2', duration=args.duration, seed=seed, perturb=0.2,
                            perturb_keep=keep, **CASES[args.case]), a_dir, overwrite=True)
    truth_vehicle = str(a_dir / 'truth_vehicle.yaml')
    if not (args.reuse and (b_dir / 'truth.json').is_file()
            and (b_dir / 'truth_states.npz').is_file()):
        generate(DataConfig(vehicle=truth_vehicle, duration=args.validation_duration,
                            seed=seed + 100, write_states=True, **CASES[args.case]), b_dir,
                 overwrite=True)
    return a_dir, b_dir


def true_model_validation(a_dir, b_dir, names, truth, prior_error, coefficients):
    """The true model flown through run B as validate_on_run flies the others (module
    docstring); returns B's run (bag_source) and the model's RunValidation (scores under
    'identified')."""
    run = bag_source(str(b_dir / 'bag'), IdentifierSettings.from_values(vehicle='nps_auv2',
                                                                        coefficients=coefficients))
    if prior_error == 'all':        # the whole truth vehicle file, added mass and M^-1 too
        vehicle, names, values = load_vehicle(str(a_dir / 'truth_vehicle.yaml')), [], []
    else:                           # the file with the identified coefficients' truth values
        vehicle, values = load_vehicle('nps_auv2'), [truth[n] for n in names]
    return run, validate_on_run(vehicle, list(names), np.asarray(values, dtype=float), None,
                                run.t, run.Y, run.U, source='B')


def noise_free_fits(run, vals, states_path):
    """Mean fit % over u v w p q r of each model's free run against run B's noise-free truth
    states, and of those states against the measurements (the noise ceiling).

    run : B's bag_source; vals : {model: (RunValidation, its key in .free)} flown on run.
    Returns {model: fit, ..., 'noise_ceiling': fit}."""
    z = np.load(states_path)
    stamp, x_true = z['stamp_ns'], z['x_true']
    val = next(iter(vals.values()))[0]
    stamps = int(run.time_origin_ns) + np.round(val.t * 1e9).astype(np.int64)
    idx = np.clip(np.searchsorted(stamp, stamps), 0, len(stamp) - 1)
    ok = np.any(np.isfinite(val.Y), axis=1) & (np.abs(stamp[idx] - stamps) < 1000)
    X = np.full_like(val.Y, np.nan)
    X[ok] = x_true[idx[ok]]
    nu = [STATE_NAMES.index(n) for n in NU_NAMES]

    def mean_fit(ref, pred):
        return float(np.mean([fit_percent(ref[ok, i], pred[ok, i]) for i in nu]))

    out = {m: mean_fit(X, v.free[key]) for m, (v, key) in vals.items()}
    out['noise_ceiling'] = mean_fit(val.Y, X)
    return out


def _rel_errors(values, truth, names):
    """{name: 100 (value - truth) / |truth|} over the names whose truth is non-zero."""
    return {n: 100.0 * (values[n] - truth[n]) / abs(truth[n]) for n in names
            if n in truth and truth[n] != 0.0}


def label(set_name, args):
    """The set's name in the tables and its reports' directory (SET, or SET-exact)."""
    return set_name if args.mass_inverse == 'default' else f'{set_name}-{args.mass_inverse}'


def run_case(set_name, seed, args):
    a_dir, b_dir = make_bags(set_name, seed, args)
    out = case_dir(args) / label(set_name, args) / f'seed{seed}'
    coefficients = ','.join(SETS[set_name])
    cmd = [sys.executable, '-m', 'auv_ident', 'report', '--bag', str(a_dir / 'bag'),
           '--vehicle', 'nps_auv2', '--coefficients', coefficients,
           '--validate', str(b_dir / 'bag'), '--out', str(out / 'report'), '--force']
    if args.mass_inverse != 'default':
        cmd += ['--mass-inverse', args.mass_inverse]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)),
                       capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode:
        return {'set': label(set_name, args), 'seed': seed, 'failed': p.stderr.strip()[-500:],
                'wall': wall}
    doc = json.loads((out / 'report' / 'result.json').read_text())
    truth_doc = json.loads((a_dir / 'truth.json').read_text())
    truth, file_values = truth_doc['coefficients'], truth_doc['file_coefficients']
    ident = list(doc['coefficients'])
    errs = _rel_errors({n: c['estimate'] for n, c in doc['coefficients'].items()}, truth, ident)
    prior_errs = _rel_errors(file_values, truth, ident)
    val = doc['validation']
    run, best = true_model_validation(a_dir, b_dir, ident, truth, args.prior_error,
                                      ','.join(named(set_name)))
    # the identified and the prior model flown again as the report flew them
    cur = doc['current']
    again = validate_on_run(
        load_vehicle('nps_auv2').with_mass_inverse(doc['mass_inverse']), ident,
        np.array([c['estimate'] for c in doc['coefficients'].values()]),
        None if not cur else [cur['north'], cur['east'], cur['down']], run.t, run.Y, run.U,
        source='B')
    reproduced = max(abs(again.channels[ch]['fit_percent' + sfx] - d['fit_percent' + sfx])
                     for ch, d in val['channels'].items() for sfx in ('', '_prior')
                     if d['fit_percent' + sfx] is not None)
    noise_free = noise_free_fits(run, {'identified': (again, 'identified'),
                                       'prior': (again, 'prior'),
                                       'true': (best, 'identified')},
                                 b_dir / 'truth_states.npz')

    def mean(ch_names, suffix):
        vals = [val['channels'][c]['fit_percent' + suffix] for c in ch_names
                if c in val['channels']]
        vals = [v for v in vals if v is not None]
        return float(np.mean(vals)) if len(vals) == len(ch_names) else None

    return {'set': label(set_name, args), 'seed': seed, 'prior_error': args.prior_error,
            'mass_inverse': doc['mass_inverse'], 'wall': wall,
            'identified': ident, 'n_identified': len(ident),
            'mean_fit': {'identified': val['mean_fit_percent_nu']['identified'],
                         'prior': val['mean_fit_percent_nu']['prior'],
                         'true': best.mean_fit()},
            'r_fit': {'identified': val['channels']['r']['fit_percent'],
                      'prior': val['channels']['r']['fit_percent_prior'],
                      'true': best.channels['r']['fit_percent']},
            'pose_mean_fit': {'identified': mean(POSE, ''), 'prior': mean(POSE, '_prior'),
                              'true': best.mean_fit(names=POSE)},
            'fit': {ch: {'identified': d['fit_percent'], 'prior': d['fit_percent_prior'],
                         'true': best.channels[ch]['fit_percent']}
                    for ch, d in val['channels'].items()},
            'max_abs_error_pct': {'identified': max(map(abs, errs.values()), default=None),
                                  'prior': max(map(abs, prior_errs.values()), default=None)},
            'errors_pct': errs, 'prior_errors_pct': prior_errs,
            'k100': {ch: (d['rmse'], d['rmse_prior'])
                     for ch, d in val['prediction']['K100']['channels'].items()},
            'noise_free_mean_fit': noise_free, 'report_reproduced': reproduced,
            'consistent': doc['diagnosis']['consistent'],
            'command': ' '.join(cmd[1:])}


def _f(v, fmt='6.1f'):
    return format('-', f'>{len(format(0.0, fmt))}') if v is None else format(v, fmt)


def _three(d, fmt='5.1f'):
    return ' / '.join(_f(d[k], fmt) for k in ('identified', 'prior', 'true'))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--out', default='/tmp/auv_ident_validation_campaign')
    ap.add_argument('--sets', default='paper,twenty', help=f'of {", ".join(SETS)}')
    ap.add_argument('--seeds', default='1')
    ap.add_argument('--prior-error', dest='prior_error', default='identified',
                    choices=PRIOR_ERRORS,
                    help='which coefficients of the truth vehicle differ from the file: the '
                         'identified ones (default) or all')
    ap.add_argument('--mass-inverse', dest='mass_inverse', default='default',
                    choices=('default', 'exact'),
                    help="the report's --mass-inverse (default: the vehicle file's)")
    ap.add_argument('--duration', type=float, default=600.0, help='s, identification run A')
    ap.add_argument('--validation-duration', type=float, default=300.0, help='s, run B')
    ap.add_argument('--case', default='a', choices=sorted(CASES))
    ap.add_argument('--reuse', action='store_true', help='keep bags already generated')
    args = ap.parse_args(argv)
    sets = args.sets.split(',')
    unknown = [s for s in sets if s not in SETS]
    if unknown:
        ap.error(f'unknown set(s) {unknown}: choose from {", ".join(SETS)}')
    if 'auto' in sets and args.prior_error == 'identified':
        ap.error('the auto set chooses its coefficients from the data: with --prior-error '
                 'identified there is no truth vehicle to make before it (use --prior-error all)')
    rows = []
    for seed in args.seeds.split(','):
        for s in sets:
            rows.append(run_case(s, int(seed), args))
            r = rows[-1]
            print(f'done: {label(s, args)} seed {seed}, wall {r["wall"]:.0f} s'
                  + (' FAILED' if 'failed' in r else ''), file=sys.stderr, flush=True)
    which = ('the identified coefficients x U(0.8, 1.2), the others as in the file'
             if args.prior_error == 'identified' else
             'every coefficient x U(0.8, 1.2) (added mass too, exact M^-1)')
    print(f'NPS AUV II truth vehicles: {which}; case {args.case} {CASES[args.case]}; A '
          f'{args.duration:.0f} s (identified), B {args.validation_duration:.0f} s (validated; '
          f"seed + 100, same truth vehicle); models' M^-1: {args.mass_inverse}")
    print(f'{"set":<11}{"seed":>5}{"n":>4}  {"mean fit u..r ident/prior/true":>31}  {"gain":>5}'
          f'  {"r fit ident/prior/true":>23}  {"x..psi ident/prior/true":>23}  '
          f'{"max|err| % ident/file":>21}  {"wall s":>6}')
    for r in rows:
        if 'failed' in r:
            print(f'{r["set"]:<11}{r["seed"]:>5}  FAILED: {r["failed"]}')
            continue
        m, e = r['mean_fit'], r['max_abs_error_pct']
        print(f'{r["set"]:<11}{r["seed"]:>5}{r["n_identified"]:>4}  {_three(m):>31}  '
              f'{_f(m["identified"] - m["prior"], "5.1f")}  {_three(r["r_fit"]):>23}  '
              f'{_three(r["pose_mean_fit"]):>23}  '
              f'{_f(e["identified"], "8.2f")} / {_f(e["prior"], "5.1f")}  {r["wall"]:6.0f}')
        print('    fit % per channel (ident/prior/true): '
              + ', '.join(f'{ch} {_three(d, ".1f")}' for ch, d in r['fit'].items()
                          if ch in NU_NAMES))
        nf = r['noise_free_mean_fit']
        print(f'    noise-free mean fit u..r (ident/prior/true): {_three(nf, ".1f")}; noise '
              f'ceiling {nf["noise_ceiling"]:.1f}')
        print('    K=100 RMSE x, y, psi (ident/prior): '
              + ', '.join(f'{ch} {r["k100"][ch][0]:.3g}/{r["k100"][ch][1]:.3g}'
                          for ch in ('x', 'y', 'psi')))
    out = case_dir(args) / ('campaign.json' if args.mass_inverse == 'default'
                            else f'campaign-{args.mass_inverse}.json')
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(rows, indent=1))
    print(f'(details in {out}; reports in {case_dir(args)}/SET/seedN/report)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
