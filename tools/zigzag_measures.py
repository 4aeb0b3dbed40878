"""Print the zig-zag measures of the HSVA KVLCC2 runs, their steering gear and thrust model.

    .venv/bin/python tools/zigzag_measures.py [--data ../shared/realdata/kvlcc2_hsva]

Reads HSVA_CPMC_KVLCC2_Z_{10_10,20_10}_{S,P}.dat (SIMMAN 2008 free-running tests; not part of
the repository, see docs/zigzag.md) and prints Markdown tables: the IMO measures per run, the
steering gear fitted per rudder reversal and to all of them together, and the thrust models
T(u) and T(u, v, r), and the closed-loop zig-zag of a first-order Nomoto model (fitted per
test to the runs' yaw rate) through the identified gear and with the ideal helm.
docs/zigzag.md holds its output.
"""
import argparse
from pathlib import Path
import sys

import numpy as np

from auv_ident.analysis.zigzag import (
    closed_loop,
    closed_loop_table,
    gear_table,
    load_hsva_runs,
    measured_measures,
    measures_table,
    thrust_table,
)
from auv_ident.core.errors import AuvIdentError
from auv_ident.core.identification.thrust_fit import DEFAULT_TERMS, fit_thrust_model, SPEED_TERMS
from auv_ident.core.model.state import State
from auv_ident.core.simulation.nomoto import fit_nomoto
from auv_ident.core.simulation.prediction import fit_percent
from auv_ident.core.simulation.steering import identify_steering_gear, SteeringGear

REPO = Path(__file__).resolve().parents[1]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--data', default=str(REPO.parent / 'shared' / 'realdata' / 'kvlcc2_hsva'),
                    help='directory of the HSVA files (default: ../shared/realdata/kvlcc2_hsva '
                    'relative to the repository root)')
    ap.add_argument('--ideal-rate', type=float, default=15.8,
                    help="deg/s, the ideal helm's rate (default 15.8, the nominal model-scale "
                    'rate quoted in issue #20; SOLAS 2.32 deg/s Froude-scaled to 1:45.714 is '
                    '15.7)')
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
    print("\n## Closed loop with a first-order Nomoto model per test (fitted to the pair's "
          'yaw rate)\n')
    ideal = SteeringGear.ideal(args.ideal_rate)
    rows, fits = {}, []
    for test in ('_10_10_', '_20_10_'):
        pair = {n: r for n, r in runs.items() if test in n}
        nomoto = fit_nomoto(pair.values())
        fits.append(f'{test.strip("_").replace("_", "/", 1)}: K = {nomoto.K:.4f} 1/s, '
                    f'T = {nomoto.T:.2f} s, delta_0 = {np.degrees(nomoto.delta_0):.3f} deg, '
                    f'yaw-rate rms {np.degrees(nomoto.rms_r):.3f} deg/s')
        for name, run in pair.items():
            m, sim_g, sim_i = closed_loop(run, nomoto.f, ident, ideal)
            psi = np.unwrap(run.x[:, State.PSI])
            fit = fit_percent(psi, np.interp(run.t, sim_g.t, np.unwrap(sim_g.x[:, State.PSI])))
            rows[name] = (m, sim_g.measures, sim_i.measures, fit)
    print(closed_loop_table(rows))
    print('\n' + '\n'.join(f'- {line}' for line in fits))
    print(f'- ideal helm: no dead time, {args.ideal_rate:g} deg/s; identified gear: '
          f'{ident.gear.delay:.3f} s, {ident.gear.rate_deg_s:.2f} deg/s, '
          f'T_s {ident.gear.time_constant:.3f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
