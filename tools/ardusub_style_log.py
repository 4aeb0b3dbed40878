"""Write an ArduSub-style multi-rate CSV log of a simulated nps_auv2 run, the example of
docs/your_data.md ("An ArduSub / BlueROV2-style CSV log"): what a dataflash log flattened to one
row per time stamp looks like, every sensor at its own rate and blank where it has no sample.

    python tools/ardusub_style_log.py --out log.csv [--duration 300] [--seed 1]

Columns (ArduPilot's message.field names; docs/examples/ardusub_columns.yaml maps them):
TimeUS (us since boot), ATT.Roll ATT.Pitch ATT.Yaw (deg, 25 Hz; yaw clockwise from north),
IMU.GyrX GyrY GyrZ (rad/s, body FRD, 25 Hz), BARO.Alt (m, negative below the surface, 20 Hz),
DVL.Vx Vy Vz (m/s, body, 5 Hz, 5 % of the samples lost), RCOU.C1..C6 (PWM us, 10 Hz: C1..C5 the
rudder, stern, bow, port and starboard bow planes, 1500 +- 400 us = +- 20 deg; C6 the thruster
ESC, 1500 +- 400 us = +- 1500 rpm). The truth is the vehicle file's coefficients; the
measurement noise is the simulator's default, per sample.
"""
import argparse
import csv
import math
import sys

import numpy as np

from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import Input, State
from auv_ident.core.simulation.simulate import simulate
from auv_ident.vehicles import load_vehicle

BASE_T = 0.01           # s, the simulation step: every rate below is a multiple of it
EVERY = {'ATT': 4, 'BARO': 5, 'DVL': 20, 'RCOU': 10}   # 25, 20, 5, 10 Hz
HEADER = ['TimeUS', 'ATT.Roll', 'ATT.Pitch', 'ATT.Yaw', 'IMU.GyrX', 'IMU.GyrY', 'IMU.GyrZ',
          'BARO.Alt', 'DVL.Vx', 'DVL.Vy', 'DVL.Vz'] + [f'RCOU.C{i}' for i in range(1, 7)]
FIN_FULL_DEG, RPM_FULL = 20.0, 1500.0


def rows(duration, seed):
    run = simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=duration, T=BASE_T,
                   seed=seed)
    rng = np.random.default_rng(seed + 1)
    boot_us = 183_250_000       # the log starts some time after boot, as a real one
    for k in range(len(run.t)):
        due = {m: k % n == 0 for m, n in EVERY.items()}
        if not any(due.values()):
            continue
        y, u = run.y[k], run.u[k]
        row = [str(boot_us + round(run.t[k] * 1e6))]
        if due['ATT']:
            yaw = math.degrees(y[State.PSI]) % 360.0
            row += [f'{math.degrees(y[State.PHI]):.4f}', f'{math.degrees(y[State.THETA]):.4f}',
                    f'{yaw:.4f}'] + [f'{y[i]:.6f}' for i in (State.P, State.Q, State.R)]
        else:
            row += [''] * 6
        row += [f'{-y[State.Z]:.4f}'] if due['BARO'] else ['']
        if due['DVL'] and rng.random() >= 0.05:
            row += [f'{y[i]:.4f}' for i in (State.U, State.V, State.W)]
        else:
            row += [''] * 3
        if due['RCOU']:
            fins = [1500.0 + 400.0 * math.degrees(d) / FIN_FULL_DEG for d in u[:5]]
            esc = 1500.0 + 400.0 * u[Input.N_RPM] / RPM_FULL
            row += [f'{v:.3f}' for v in fins + [esc]]
        else:
            row += [''] * 6
        yield row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--out', required=True, help='CSV file to write')
    ap.add_argument('--duration', type=float, default=300.0, help='run length [s]')
    ap.add_argument('--seed', type=int, default=1)
    args = ap.parse_args(argv)
    with open(args.out, 'w', newline='', encoding='utf-8') as fh:
        w = csv.writer(fh)
        w.writerow(HEADER)
        n = 0
        for row in rows(args.duration, args.seed):
            w.writerow(row)
            n += 1
    print(f'wrote {args.out}: {n} rows over {args.duration:g} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
