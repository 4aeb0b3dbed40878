"""Campaign: the paper's five NPS AUV II coefficients from raw sensors against a fused odometry of
the same run (issue 28). Each seed: one run of offline/independent_data.py's raw generator
(100 Hz IMU, 5 Hz DVL with 5 % dropouts, 10 Hz pressure, commands on change, a gyro bias, a
DVL misalignment of 1-2 deg and a scale error, coloured noise of a level and correlation time
drawn per run), identified from the raw records (identify_raw) and from the plain navigation
EKF's 20 Hz odometry through the package's pipeline (analysis/raw_comparison.py). Printed:
per coefficient the median |error| % of each, and over all (seed, coefficient) cases the share
of truths within 3 sigma and the median |error|/sigma; per seed the sensor errors found and the
records the raw pass did not fuse (every record is a good message: only those before the
filter's start may wait).

    PYTHONPATH=. .venv/bin/python tools/raw_sensor_campaign.py [--seeds 10] [--duration 300]
        [--first-seed 0] [--passes 2] [--json OUT]
"""
import argparse
import json
from pathlib import Path
import sys

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from auv_ident.analysis.raw_comparison import compare_case, summary  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seeds', type=int, default=10)
    ap.add_argument('--first-seed', type=int, default=0)
    ap.add_argument('--duration', type=float, default=300.0)
    ap.add_argument('--passes', type=int, default=2)
    ap.add_argument('--json', default=None, help='write the cases and the summary here')
    a = ap.parse_args(argv)
    cases = []
    for seed in range(a.first_seed, a.first_seed + a.seeds):
        c = compare_case(seed, a.duration, passes=a.passes)
        cases.append(c)
        te = c.true_errors
        print(f'seed {seed}: raw {a.duration:g} s in {c.raw_s:.1f} s, fused in {c.fused_s:.1f} s;'
              ' |error| % raw / fused: '
              + ', '.join(f'{n} {100 * r:.1f}/{100 * f:.1f}' for n, r, f in
                          zip(c.names, c.rel_error('raw'), c.rel_error('fused'))), flush=True)
        found = c.raw_errors
        print(f'    DVL misalignment {np.degrees(te["dvl_misalignment"]):+.2f} deg, found '
              f'{np.degrees(found["dvl_misalignment"][0]):+.2f} +- '
              f'{np.degrees(found["dvl_misalignment"][1]):.2f}; gyro bias (mrad/s) '
              + ' '.join(f'{1e3 * b:+.2f}' for b in te['gyro_bias']) + ', found '
              + ' '.join(f'{1e3 * found[k][0]:+.2f}+-{1e3 * found[k][1]:.2f}'
                         for k in ('gyro_bias_p', 'gyro_bias_q', 'gyro_bias_r'))
              + f'; DVL scale {te["dvl_scale"]:+.4f}, found {found["dvl_scale"][0]:+.4f} +- '
              f'{found["dvl_scale"][1]:.4f}', flush=True)
        print(f'    records {sum(c.records.values())} ('
              + ', '.join(f'{k} {n}' for k, n in sorted(c.records.items()))
              + f'): fused or taken {sum(c.raw_fused.values())}, not fused {c.raw_skipped or 0} '
              f'(before the start: {c.before_start})', flush=True)
    s = summary(cases)
    print(f'\n{len(cases)} runs of {a.duration:g} s, {a.passes} raw passes')
    print('coefficient   median |error| %: raw    fused')
    for n, row in s['coefficients'].items():
        print(f'  {n:10s}                 {row["raw"]:6.2f}  {row["fused"]:6.2f}')
    for w in ('raw', 'fused'):
        r = s[w]
        print(f'{w:5s}: within 3 sigma {100 * r["within_3_sigma"]:.0f} %, median |error|/sigma '
              f'{r["median_abs_z"]:.2f}, median |error| {r["median_error_pct"]:.2f} %, mean '
              f'{r["mean_error_pct"]:.2f} %')
    if a.json:
        doc = {'summary': s, 'cases': [{
            'seed': c.seed, 'names': c.names, 'truth': c.truth.tolist(), 'raw': c.raw.tolist(),
            'raw_std': c.raw_std.tolist(), 'fused': c.fused.tolist(),
            'fused_std': c.fused_std.tolist(), 'raw_errors': c.raw_errors,
            'true_errors': c.true_errors, 'raw_s': c.raw_s, 'fused_s': c.fused_s,
            'records': c.records, 'raw_fused': c.raw_fused, 'raw_skipped': c.raw_skipped,
            'before_start': c.before_start}
            for c in cases]}
        Path(a.json).write_text(json.dumps(doc, indent=1) + '\n', encoding='utf-8')
    return 0


if __name__ == '__main__':
    sys.exit(main())
