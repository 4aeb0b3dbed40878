"""Campaign: `--coefficients auto,<the vehicle's default set>` against a hand-picked
20-coefficient set (NPS AUV II) on bags the identifier did not make (offline/independent_data.py),
with a truth vehicle whose other coefficients are 0.8-1.2x the vehicle file's.

Per seed: one 600 s bag of the vehicle (20 Hz odometry, white noise at the documented level,
commands periodic at 20 Hz, every coefficient but the default set (the vehicle file's
identify_default; NPS AUV II: the paper's five) scaled by U(0.8, 1.2), added mass included),
then

    python -m auv_ident identify --vehicle V --bag BAG --coefficients SET --json OUT

for SET = auto,<default set> and, for NPS AUV II, the hand-picked HAND_SET (and, with --methods
auto,hand,five, the default set alone: does the diagnosis flag it?). Errors are against the
bag's truth.json. Printed: per seed the default set (error % / |error|/1-sigma), the wall
time of the command and the diagnosis; then per method the median |error| % of each of them,
the share of (seed, coefficient) cases with the truth within 3 sigma (the default set, and
every identified coefficient) and the median |error|/sigma (of both; an honest sigma gives
~0.67), then one line per method saying so with the number of bags. These are measurements,
not assertions.

    PYTHONPATH=. .venv/bin/python tools/auto_selection_campaign.py [--vehicle nps_auv2]
        [--out DIR] [--seeds 1,2,3] [--duration 600] [--reuse] [--methods auto,hand]

With --reuse, bags and results already in --out are kept (a result with its command's wall
time), so more seeds can be added to a campaign.
"""
import argparse
import json
import os
from pathlib import Path
import resource
import subprocess
import sys
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from auv_ident.offline.independent_data import DataConfig, generate  # noqa: E402
from auv_ident.vehicles import load_vehicle  # noqa: E402

# NPS AUV II's hand-picked set: the paper's five and fifteen more
HAND_SET = ('Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v', 'Y_v', 'Y_r', 'Y_dr', 'N_v', 'N_r', 'N_dr',
            'M_uw', 'M_uq', 'K_p', 'Z_dsn', 'X_vv', 'K_vw', 'Z_vv', 'M_vv', 'N_vw')


def method_sets(vehicle, default_set):
    """{method: --coefficients text}: 'auto' (auto plus the default set), 'five' (the default
    set alone; named after NPS AUV II's five) and, for NPS AUV II, 'hand'."""
    sets = {'auto': 'auto,' + ','.join(default_set), 'five': ','.join(default_set)}
    if vehicle == 'nps_auv2':
        sets['hand'] = ','.join(HAND_SET)
    return sets


def make_bag(out, vehicle, default_set, seed, duration, reuse):
    """The seed's bag (perturbed truth, the default set kept); returns its truth.json."""
    if not (reuse and (out / 'truth.json').is_file()):
        cfg = DataConfig(vehicle=vehicle, duration=duration, seed=seed, rpm=500.0,
                         odom_rate=20.0, commands='periodic', command_rate=20.0, perturb=0.2,
                         perturb_keep=tuple(default_set))
        generate(cfg, out, overwrite=True)
    return json.loads((out / 'truth.json').read_text())


def identify(vehicle, bag, coefficients, out_json, reuse=False):
    """Run the command line; returns its JSON document with 'wall' and 'cpu' (s, the
    command's wall-clock and CPU (user + system) time, kept in OUT.wall next to it), or a
    failure dict. reuse: take a result already made."""
    wall_file = Path(str(out_json) + '.wall')
    if reuse and Path(out_json).is_file() and wall_file.is_file():
        doc = json.loads(Path(out_json).read_text())
        times = wall_file.read_text().split()
        doc['wall'] = float(times[0])
        doc['cpu'] = float(times[1]) if len(times) > 1 else float('nan')
        return doc
    cmd = [sys.executable, '-m', 'auv_ident', 'identify', '--vehicle', vehicle, '--bag',
           str(bag), '--coefficients', coefficients, '--json', str(out_json), '--force']
    env = dict(os.environ, PYTHONPATH=str(REPO))
    t0 = time.perf_counter()
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    p = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if p.returncode not in (0, 3):    # 3: computed, NOT consistent/plausible
        return {'failed': True, 'stderr': p.stderr[-2000:], 'wall': wall}
    doc = json.loads(Path(out_json).read_text())
    doc['wall'], doc['cpu'] = wall, cpu
    wall_file.write_text(f'{wall:.3f} {cpu:.3f}\n')
    return doc


def errors(doc, truth):
    """{name: (error %, |error|/sigma)} of every identified coefficient."""
    out = {}
    for n, c in doc['coefficients'].items():
        tv = truth['coefficients'][n]
        err = c['estimate'] - tv
        out[n] = (100.0 * err / abs(tv), abs(err) / c['std'] if c['std'] > 0 else np.inf)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--vehicle', default='nps_auv2')
    ap.add_argument('--out', default='/tmp/auv_ident_auto_selection')
    ap.add_argument('--seeds', default='1,2,3')
    ap.add_argument('--duration', type=float, default=600.0)
    ap.add_argument('--methods', default='auto,hand')
    ap.add_argument('--reuse', action='store_true',
                    help='keep bags and results already made (a rerun reprints the table)')
    args = ap.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(',') if s.strip()]
    vehicle = load_vehicle(args.vehicle)
    PAPER_SET = tuple(vehicle.identify_default)
    METHODS = method_sets(args.vehicle, PAPER_SET)
    methods = [m.strip() for m in args.methods.split(',') if m.strip()]
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        ap.error(f'--methods: {", ".join(unknown)} not available for {args.vehicle} '
                 f'(available: {", ".join(METHODS)})')
    print(f'{vehicle.title}, {args.duration:.0f} s, 20 Hz, white noise, truth vehicle: '
          f'every coefficient but {", ".join(PAPER_SET)} x U(0.8, 1.2) (added mass too); load '
          f'average at start {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores')
    for m in methods:
        print(f'  {m}: --coefficients {METHODS[m]}')
    print(f'{"seed":<5}{"method":<7}{"n":>3}' + ''.join(f'{n:>16}' for n in PAPER_SET)
          + f'{"wall s":>8}{"cpu s":>7}  diagnosis')
    table = {m: {'five': [], 'all': [], 'wall': [], 'cpu': []} for m in methods}
    summary = {}
    for seed in seeds:
        out = Path(args.out) / f'seed{seed}'
        truth = make_bag(out, args.vehicle, PAPER_SET, seed, args.duration, args.reuse)
        for m in methods:
            doc = identify(args.vehicle, out / 'bag', METHODS[m], out / f'{m}.json', args.reuse)
            summary[f'{seed}/{m}'] = doc
            if doc.get('failed'):
                last = doc['stderr'].strip().splitlines()[-1:] or ['?']
                print(f'{seed:<5}{m:<7} FAILED: {last[0]}')
                continue
            e = errors(doc, truth)
            table[m]['five'].append([e[n] for n in PAPER_SET])
            table[m]['all'].extend(e.values())
            table[m]['wall'].append(doc['wall'])
            table[m]['cpu'].append(doc['cpu'])
            diag = doc['diagnosis']
            verdict = ('consistent' if diag['consistent'] else 'NOT consistent')
            print(f'{seed:<5}{m:<7}{len(e):>3}'
                  + ''.join(f'{e[n][0]:>+9.2f}/{e[n][1]:>5.1f}' for n in PAPER_SET)
                  + f'{doc["wall"]:>8.1f}{doc["cpu"]:>7.1f}  {verdict}')
    print()
    print(f'{"method":<7}' + ''.join(f'{n:>9}' for n in PAPER_SET)
          + f'{"3sig 5":>9}{"3sig all":>10}{"med z":>7}{"z all":>7}{"wall s":>8}{"cpu s":>7}'
          '   (median |error| %; median wall and CPU time of the command)')
    for m in methods:
        five = np.array(table[m]['five'])
        if five.size == 0:
            continue
        med = np.median(np.abs(five[:, :, 0]), axis=0)
        z5 = five[:, :, 1].ravel()
        z_all = np.array([z for _, z in table[m]['all']])
        print(f'{m:<7}' + ''.join(f'{v:>9.2f}' for v in med)
              + f'{100 * np.mean(z5 <= 3):>8.0f}%{100 * np.mean(z_all <= 3):>9.0f}%'
              + f'{np.median(z5):>7.2f}{np.median(z_all):>7.2f}'
              + f'{np.median(table[m]["wall"]):>8.1f}{np.median(table[m]["cpu"]):>7.1f}')
        print(f'  {m}: {len(five)} bags; median |error|/sigma {np.median(z5):.2f} (the default '
              f'set), {np.median(z_all):.2f} (every identified coefficient); truth within 3 '
              f'sigma in {100 * np.mean(z5 <= 3):.0f} % of {z5.size} and '
              f'{100 * np.mean(z_all <= 3):.0f} % of {z_all.size} cases (an honest sigma: ~0.67 '
              'and ~99.7 %)')
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / 'campaign.json').write_text(json.dumps(summary, indent=1, default=str))
    print(f'(details in {Path(args.out) / "campaign.json"}; 3sig = truth within 3 sigma, of the '
          'five and of every identified coefficient; med z, z all = median |error|/sigma of '
          'the five, of every identified coefficient; '
          f'load average at the end {os.getloadavg()[0]:.1f})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
