"""Baseline: how the identifier does on bags it did not make (offline/independent_data.py).

Five cases, NPS AUV II, the paper's five coefficients (Z_ds, Z_q, Z_w, M_ds, K_v), 600 s:

  a  20 Hz odometry, no jitter, white noise, commands periodic at 20 Hz (the easy case)
  b  10 Hz, +-10 % stamp jitter, 5 % dropouts, commands only on change
  c  as b, with coloured noise (AR(1), tau 1 s) at twice the documented level
  d  as a, with a perturbed truth vehicle (every other coefficient x U(0.8, 1.2))
  e  as a, with a 0.1 m/s current from the north-east (flowing south-west), DVL over ground
  f, g, h (diagnostics, on request): as a at 10 Hz; as a with on-change commands; as a with
     +-10 % jitter and 5 % dropouts

For each bag: `python -m auv_ident identify --vehicle nps_auv2 --bag BAG --json OUT.json`
(EKF pass + batch refinement) and the same with `--no-refine` (EKF pass only); the errors are
against the truth in the bag's truth.json. These are measurements, not assertions.

    PYTHONPATH=. .venv/bin/python tools/independent_baseline.py [--out DIR] [--cases abcde]
        [--seed N] [--duration S] [--jobs N] [--reuse]
"""
import argparse
from concurrent.futures import ThreadPoolExecutor
import json
import math
import os
from pathlib import Path
import subprocess
import sys
import time

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from auv_ident.offline.independent_data import DataConfig, generate  # noqa: E402

PAPER_SET = ('Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v')
NE = 0.1 / math.sqrt(2.0)

CASES = {
    'a': ('20 Hz, no jitter, white, periodic 20 Hz commands',
          dict(odom_rate=20.0, commands='periodic', command_rate=20.0)),
    'b': ('10 Hz, +-10 % jitter, 5 % dropouts, commands on change',
          dict(odom_rate=10.0, odom_jitter=0.1, dropout=0.05, commands='on_change')),
    'c': ('as b + AR(1) noise tau 1 s, level 2x',
          dict(odom_rate=10.0, odom_jitter=0.1, dropout=0.05, commands='on_change',
               noise='ar1', noise_tau=1.0, noise_level=2.0)),
    'd': ('as a, truth vehicle perturbed +-20 % (paper set kept)',
          dict(odom_rate=20.0, commands='periodic', command_rate=20.0, perturb=0.2,
               perturb_keep=PAPER_SET)),
    'e': ('as a + 0.1 m/s current from the NE, DVL over ground',
          dict(odom_rate=20.0, commands='periodic', command_rate=20.0,
               current_ned=(-NE, -NE, 0.0), dvl='ground')),
    # diagnostics (not in the default run): one difference of b at a time
    'f': ('diagnostic: as a at 10 Hz odometry (rate alone)',
          dict(odom_rate=10.0, commands='periodic', command_rate=20.0)),
    'g': ('diagnostic: as a with commands on change (alone)',
          dict(odom_rate=20.0, commands='on_change', command_rate=20.0)),
    'h': ('diagnostic: as a with +-10 % jitter and 5 % dropouts (alone)',
          dict(odom_rate=20.0, odom_jitter=0.1, dropout=0.05, commands='periodic',
               command_rate=20.0)),
}


def identify(bag, out_json, refine):
    cmd = [sys.executable, '-m', 'auv_ident', 'identify', '--vehicle', 'nps_auv2', '--bag',
           str(bag), '--json', str(out_json), '--force'] + ([] if refine else ['--no-refine'])
    env = dict(os.environ, PYTHONPATH=str(REPO))
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode not in (0, 3):    # 3: computed, NOT consistent/plausible
        return {'failed': True, 'stderr': p.stderr[-2000:], 'stdout': p.stdout[-2000:],
                'wall': wall}
    doc = json.loads(Path(out_json).read_text())
    doc['wall'] = wall
    doc['stdout'] = p.stdout
    return doc


def run_case(key, args):
    desc, kw = CASES[key]
    out = Path(args.out) / key
    cfg = DataConfig(vehicle='nps_auv2', duration=args.duration, seed=args.seed, rpm=500.0, **kw)
    if not (args.reuse and (out / 'truth.json').is_file()):
        generate(cfg, out, overwrite=True)
    truth = json.loads((out / 'truth.json').read_text())
    refined = identify(out / 'bag', out / 'refined.json', True)
    ekf = identify(out / 'bag', out / 'ekf.json', False)
    return key, desc, truth, refined, ekf


def rows(key, desc, truth, doc, label):
    if doc.get('failed'):
        return [f'{key:<3}{label:<8} FAILED: ' + doc['stderr'].strip().splitlines()[-1]
                if doc['stderr'].strip() else 'FAILED']
    counts = truth['counts']
    cells = []
    for n in PAPER_SET:
        c = doc['coefficients'][n]
        est, std = (c['estimate'], c['std']) if label == 'refined' else \
            (c['ekf_estimate'], c['ekf_std'])
        tv = truth['coefficients'][n]
        err = 100.0 * (est - tv) / abs(tv)
        z = abs(est - tv) / std if std > 0 else float('inf')
        cells.append(f'{err:+8.2f}/{z:6.1f}')
    rej = doc.get('rejected', 0)
    line = (f'{key:<3}{label:<8}{doc["steps"]:>6}/{counts["odom_written"]:<6}{rej:>5}  '
            + ' '.join(cells) + f'{doc["mean_nis_per_dof"]:>8.2f}{doc["wall"]:>7.0f}')
    out = [line]
    if rej:
        out.append(f'{"":<11}rejections: {doc.get("rejection_reasons")}')
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--out', default='/tmp/auv_ident_independent_baseline')
    ap.add_argument('--cases', default='abcde')
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--duration', type=float, default=600.0)
    ap.add_argument('--jobs', type=int, default=1)
    ap.add_argument('--reuse', action='store_true', help='keep bags already generated')
    args = ap.parse_args(argv)
    keys = [k for k in args.cases if k in CASES]
    with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        results = list(pool.map(lambda k: run_case(k, args), keys))
    print(f'NPS AUV II, {args.duration:.0f} s, seed {args.seed}, 500 rpm; identify --vehicle '
          'nps_auv2 --bag BAG [--no-refine]; errors vs truth.json; cell = error % / '
          '|error|/1-sigma')
    for key, desc, *_ in results:
        print(f'  {key}: {desc}')
    head = (f'{"":<3}{"pass":<8}{"used/written":>12}{"rej":>6}  '
            + ' '.join(f'{n:>15}' for n in PAPER_SET) + f'{"NIS/dof":>8}{"wall s":>7}')
    print(head)
    print('-' * len(head))
    for key, desc, truth, refined, ekf in results:
        for line in rows(key, desc, truth, refined, 'refined'):
            print(line)
        for line in rows(key, desc, truth, ekf, 'EKF'):
            print(line)
    summary = {k: {'description': d, 'refined': {kk: v for kk, v in r.items() if kk != 'stdout'},
                   'ekf': {kk: v for kk, v in e.items() if kk != 'stdout'},
                   'truth_counts': t['counts']}
               for k, d, t, r, e in results}
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / 'baseline.json').write_text(json.dumps(summary, indent=1, default=str))
    print(f'(details in {Path(args.out) / "baseline.json"})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
