"""Campaign: the live identifier's error bars on bags it did not make
(offline/independent_data.py), with and without the noise learnt from its innovations
(session/noise_learning.py).

Per seed and noise: one bag of NPS AUV II (10 Hz odometry, the generator's defaults), its
messages fed in log-time order to the identifier's session (what the node does with them live:
offline/replay.py, the settings the node has by default, the noise level not told), with
learn_noise on and off. Noises: 'ar1' (AR(1), twice the documented level, correlated over
1 s) and 'white' (the documented level). Printed per run: |error|/sigma of the paper's five at
the end, the live diagnosis at the end and how many of its verdicts (every 100 odometry
samples) said NOT consistent, the re-runs and the wall time; then per noise and learning the
share of (seed, coefficient) cases with the truth within 3 sigma, the median |error|/sigma,
the runs with >= 4 of 5 within 3 sigma, the runs ending consistent and the runs ever NOT
consistent. Measurements, not assertions.

    PYTHONPATH=. .venv/bin/python tools/live_noise_campaign.py [--seeds 1,2,3,4]
        [--duration 120] [--out DIR]
"""
import argparse
import json
from pathlib import Path
import sys
import tempfile
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from auv_ident.bags.reader import read_bag  # noqa: E402
from auv_ident.offline.independent_data import DataConfig, generate  # noqa: E402
from auv_ident.session.session import IdentSession  # noqa: E402
from auv_ident.session.settings import IdentifierSettings  # noqa: E402

PAPER = ('Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v')
NOISES = {'ar1': dict(noise='ar1', noise_level=2.0, noise_tau=1.0),
          'white': dict(noise='white', noise_level=1.0)}
TOPICS = {'/odom': 'nav_msgs/msg/Odometry', '/actuators': 'sensor_msgs/msg/JointState'}


def live_run(bag, truth, learn):
    """Feed bag's messages to a session as the node would; returns the run's figures."""
    s = IdentSession(IdentifierSettings.from_values(learn_noise=learn))
    said, n = [], 0
    start = time.perf_counter()
    for topic, _, msg in read_bag(bag, TOPICS):
        if topic == '/actuators':
            s.on_actuators(msg)
            continue
        s.on_odom(msg)
        n += 1
        if n % 100 == 0:
            said.append(s.diagnosis()[1]['consistent'])
    wall = time.perf_counter() - start
    est, cov = s.best()
    sd = np.sqrt(np.diag(cov))
    z = {c: abs(est[s.names.index(c)] - truth[c]) / sd[s.names.index(c)] for c in PAPER}
    _, d = s.diagnosis()
    return {'z': z, 'consistent': d['consistent'], 'not_consistent': said.count(False),
            'verdicts': len(said), 'reruns': s.noise.reruns, 'wall_s': wall}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', default='1,2,3,4')
    ap.add_argument('--duration', type=float, default=120.0)
    ap.add_argument('--out', default=None, help='keep the bags here (default: a temp dir)')
    a = ap.parse_args(argv)
    seeds = [int(s) for s in a.seeds.split(',')]
    out = Path(a.out) if a.out else Path(tempfile.mkdtemp(prefix='live_noise_'))
    rows = {}
    for noise, opts in NOISES.items():
        for seed in seeds:
            d = out / f'{noise}_{seed}'
            if not (d / 'bag').exists():
                generate(DataConfig(seed=seed, duration=a.duration, **opts), d)
            truth = json.loads((d / 'truth.json').read_text())['coefficients']
            for learn in (True, False):
                r = live_run(str(d / 'bag'), truth, learn)
                rows.setdefault((noise, learn), []).append(r)
                print(f'{noise:5s} seed {seed} learn_noise {str(learn):5s}: '
                      + ' '.join(f'{c} {v:.2f}' for c, v in r['z'].items())
                      + f" | end {r['consistent']}, NOT consistent {r['not_consistent']}/"
                      f"{r['verdicts']}, re-runs {r['reruns']}, {r['wall_s']:.1f} s",
                      flush=True)
    print('\nnoise  learn_noise  within 3 sigma  median |error|/sigma  runs >= 4 of 5  '
          'runs ending consistent  runs ever NOT consistent')
    for (noise, learn), rs in rows.items():
        z = np.array([v for r in rs for v in r['z'].values()])
        good = sum(sum(v < 3.0 for v in r['z'].values()) >= 4 for r in rs)
        ever = sum(r['not_consistent'] > 0 for r in rs)
        ends = sum(r['consistent'] is True for r in rs)
        print(f'{noise:5s}  {str(learn):11s}  {np.mean(z < 3.0) * 100:13.0f} %  '
              f'{np.median(z):20.2f}  {good:7d} of {len(rs)}  {ends:14d} of {len(rs)}  '
              f'{ever:17d} of {len(rs)}')


if __name__ == '__main__':
    main()
