"""Print the zig-zag measures of the HSVA KVLCC2 runs, their steering gear and thrust model.

    .venv/bin/python tools/zigzag_measures.py [--data ../shared/realdata/kvlcc2_hsva]

Reads HSVA_CPMC_KVLCC2_Z_{10_10,20_10}_{S,P}.dat (SIMMAN 2008 free-running tests; not part of
the repository, see docs/zigzag.md) and prints Markdown tables: the IMO measures per run, the
steering gear fitted per rudder reversal and to all of them together, and the thrust models
T(u) and T(u, v, r). docs/zigzag.md holds its output.
"""
import argparse
from pathlib import Path
import sys

from auv_ident.analysis.zigzag import (gear_table, HSVA_RUNS, load_hsva_runs,
                                       measured_measures, measures_table, thrust_table)
from auv_ident.core.errors import AuvIdentError
from auv_ident.core.steering import identify_steering_gear
from auv_ident.core.thrust_fit import DEFAULT_TERMS, fit_thrust_model, SPEED_TERMS

REPO = Path(__file__).resolve().parents[1]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--data', default=str(REPO.parent / 'shared' / 'realdata' / 'kvlcc2_hsva'),
                    help='directory of the HSVA files (default: ../shared/realdata/kvlcc2_hsva '
                    'relative to the repository root)')
    args = ap.parse_args(argv)
    try:
        runs = load_hsva_runs(args.data)
    except AuvIdentError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 2
    names = list(runs)
    ident = identify_steering_gear(list(runs.values()))
    print('## Zig-zag measures (execute = rudder onset - mean onset delay)\n')
    print(measures_table({n: measured_measures(r, ident) for n, r in runs.items()}))
    print('\n## Steering gear, per reversal and jointly\n')
    print(gear_table(ident, names))
    print('\n## Thrust at n = 10.2295 rps\n')
    models = {'T(u)': fit_thrust_model(runs.values(), SPEED_TERMS),
              'T(u, v, r)': fit_thrust_model(runs.values(), DEFAULT_TERMS)}
    print(thrust_table(models, names))
    return 0


if __name__ == '__main__':
    assert tuple(HSVA_RUNS)
    sys.exit(main())
