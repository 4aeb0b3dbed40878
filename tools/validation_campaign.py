"""Validation campaign: does the identified model predict a run it never saw better than the
vehicle file's model?

For each seed, a truth vehicle whose identified coefficients differ from the file's by factors
U(0.8, 1.2) (test/independent_data.py, perturb 0.2, perturb_keep = every coefficient NOT
identified, so the file and the truth differ exactly where identification can correct them) flies
two independent runs (bags made by the independent generator, not by auv_ident's simulator):
run A (seed s) and run B (seed s + 100: another manoeuvre, other noise, same truth vehicle).
Then

    python -m auv_ident report --bag A/bag --vehicle nps_auv2 --coefficients SET \\
        --validate B/bag --out OUT

identifies SET on A (prior and initial guesses from the vehicle file) and validates on B's
measurements. Printed: mean fit % over u v w p q r of the identified and the prior model and,
as the ceiling the sensor noise leaves, of the true model (analysis.validation.validate_on_run
with the truth values); the yaw-rate fit; the largest coefficient error against the truth.

    PYTHONPATH=. .venv/bin/python tools/validation_campaign.py [--out DIR] [--sets paper,twenty]
        [--seeds 1,2] [--duration 600] [--validation-duration 300] [--case a|b] [--reuse]
"""
import argparse
import json
import os
from pathlib import Path
import subprocess
import sys
import time

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / 'test'))
sys.path.insert(0, str(REPO))

from independent_data import DataConfig, generate  # noqa: E402
from auv_ident.analysis.bag_identify import bag_source  # noqa: E402
from auv_ident.analysis.validation import validate_on_run  # noqa: E402
from auv_ident.vehicles import load_vehicle  # noqa: E402

SETS = {
    'paper': ('Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v'),
    'twenty': ('Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v', 'Y_v', 'Y_r', 'Y_dr', 'N_v', 'N_r', 'N_dr',
               'M_uw', 'M_uq', 'K_p', 'Z_dsn', 'X_vv', 'K_vw', 'Z_vv', 'M_vv', 'N_vw'),
}
# the sampling and command cases of tools/independent_baseline.py
CASES = {
    'a': dict(odom_rate=20.0, commands='periodic', command_rate=20.0),
    'b': dict(odom_rate=10.0, odom_jitter=0.1, dropout=0.05, commands='on_change'),
}
NU = ('u', 'v', 'w', 'p', 'q', 'r')


def make_bags(out, names, seed, args):
    """Run A (perturbed truth vehicle) and run B (the same truth vehicle, seed + 100)."""
    keep = tuple(n for n in load_vehicle('nps_auv2').names if n not in names)
    a_dir, b_dir = out / 'A', out / 'B'
    if not (args.reuse and (a_dir / 'truth.json').is_file()):
        generate(DataConfig(vehicle='nps_auv2', duration=args.duration, seed=seed, perturb=0.2,
                            perturb_keep=keep, **CASES[args.case]), a_dir, overwrite=True)
    truth_vehicle = str(a_dir / 'truth_vehicle.yaml')
    if not (args.reuse and (b_dir / 'truth.json').is_file()):
        generate(DataConfig(vehicle=truth_vehicle, duration=args.validation_duration,
                            seed=seed + 100, **CASES[args.case]), b_dir, overwrite=True)
    return a_dir, b_dir


def run_case(set_name, seed, args):
    names = SETS[set_name]
    out = Path(args.out) / args.case / set_name / f'seed{seed}'
    a_dir, b_dir = make_bags(out, names, seed, args)
    cmd = [sys.executable, '-m', 'auv_ident', 'report', '--bag', str(a_dir / 'bag'),
           '--vehicle', 'nps_auv2', '--coefficients', ','.join(names),
           '--validate', str(b_dir / 'bag'), '--out', str(out / 'report')]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)),
                       capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode:
        return {'set': set_name, 'seed': seed, 'failed': p.stderr.strip()[-500:], 'wall': wall}
    doc = json.loads((out / 'report' / 'result.json').read_text())
    truth = json.loads((a_dir / 'truth.json').read_text())
    errs = {n: 100.0 * (c['estimate'] - truth['coefficients'][n]) / abs(truth['coefficients'][n])
            for n, c in doc['coefficients'].items()}
    prior_errs = {n: 100.0 * (truth['file_coefficients'][n] - truth['coefficients'][n])
                  / abs(truth['coefficients'][n]) for n in names}
    val = doc['validation']
    # the ceiling: the true model itself (truth values of the set, the rest is the file's) on B
    v = load_vehicle('nps_auv2')
    run = bag_source(str(b_dir / 'bag'), vehicle='nps_auv2', coefficients=','.join(names))
    best = validate_on_run(v, list(names), [truth['coefficients'][n] for n in names], None,
                           run.t, run.Y, run.U, source='B')
    return {'truth_mean_fit': best.mean_fit(), 'truth_r_fit': best.channels['r']['fit_percent'],
            'set': set_name, 'seed': seed, 'wall': wall, 'errors_pct': errs,
            'prior_errors_pct': prior_errs, 'mean_fit': val['mean_fit_percent_nu'],
            'fit': {ch: (d['fit_percent'], d['fit_percent_prior'])
                    for ch, d in val['channels'].items()},
            'k100': {ch: (d['rmse'], d['rmse_prior'])
                     for ch, d in val['prediction']['K100']['channels'].items()},
            'command': ' '.join(cmd[1:])}


def _f(v, fmt='6.1f'):
    return ' ' * (len(format(0.0, fmt))) if v is None else format(v, fmt)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--out', default='/tmp/auv_ident_validation_campaign')
    ap.add_argument('--sets', default='paper,twenty')
    ap.add_argument('--seeds', default='1')
    ap.add_argument('--duration', type=float, default=600.0, help='s, identification run A')
    ap.add_argument('--validation-duration', type=float, default=300.0, help='s, run B')
    ap.add_argument('--case', default='a', choices=sorted(CASES))
    ap.add_argument('--reuse', action='store_true', help='keep bags already generated')
    args = ap.parse_args(argv)
    rows = [run_case(s, int(seed), args) for s in args.sets.split(',')
            for seed in args.seeds.split(',')]
    print(f'NPS AUV II truth vehicles: identified coefficients x U(0.8, 1.2), the others as in '
          f'the file; case {args.case} {CASES[args.case]}; A {args.duration:.0f} s (identified),'
          f' B {args.validation_duration:.0f} s (validated; seed + 100, same truth vehicle)')
    print(f'{"set":<8}{"seed":>5}  {"mean fit u..r ident/prior/true":>32}  {"gain":>6}  '
          f'{"r fit ident/prior/true":>24}  {"max|err| % ident/prior":>23}  {"wall s":>6}')
    for r in rows:
        if 'failed' in r:
            print(f'{r["set"]:<8}{r["seed"]:>5}  FAILED: {r["failed"]}')
            continue
        mi, mp = r['mean_fit']['identified'], r['mean_fit']['prior']
        ri, rp = r['fit']['r']
        emax = max(abs(e) for e in r['errors_pct'].values())
        pmax = max(abs(e) for e in r['prior_errors_pct'].values())
        print(f'{r["set"]:<8}{r["seed"]:>5}  {_f(mi):>12} / {_f(mp)} / {_f(r["truth_mean_fit"])}'
              f'  {_f(mi - mp):>6}  {_f(ri):>8} / {_f(rp)} / {_f(r["truth_r_fit"])}  '
              f'{_f(emax, "8.2f"):>11} / {_f(pmax, "8.2f"):<9}  {r["wall"]:6.0f}')
        print('    fit % per channel (ident/prior): '
              + ', '.join(f'{ch} {_f(a, ".1f")}/{_f(b, ".1f")}' for ch, (a, b) in r['fit'].items()))
        print('    K=100 RMSE x, y, psi (ident/prior): '
              + ', '.join(f'{ch} {r["k100"][ch][0]:.3g}/{r["k100"][ch][1]:.3g}'
                          for ch in ('x', 'y', 'psi')))
    out = Path(args.out) / args.case / 'campaign.json'
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(rows, indent=1))
    print(f'(details in {out}; reports in {Path(args.out) / args.case}/SET/seedN/report)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
