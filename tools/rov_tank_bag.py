#!/usr/bin/env python3
"""Write a BlueROV2 Heavy tank-session bag whose truth is NOT the vehicle file: what
docs/vehicles.md (BlueROV2 Heavy) identifies and validates on.

Run from the package root:
    .venv/bin/python tools/rov_tank_bag.py --seed 13 --noise 1 --out bags/rov13

The truth: config/bluerov2_heavy.yaml with its T200 table +10 % on the forward
side and -5 % on the reverse side, X_uu x1.2, N_rr x0.8, Z_wdot x1.15, Y_vdot x0.9. The run: the
`tank` manoeuvre (a pilot's sticks, PWM on change, core/simulation/maneuvers.py) for --duration s,
integrated with RK4 at T/4 (the filter uses T), measurement noise first-order correlated (time
constant 0.5 s) at --noise times the default 1-sigma. The bag is our simulator's (its metadata
names the vehicle and the input map bluerov2_heavy); its /simulator/truth is the perturbed truth,
and 'truth' columns of identify/report, which read the vehicle file, are NOT this truth: compare
with TRUTH below.
"""
import argparse
import os
import sys
import tempfile

import numpy as np
import yaml

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from auv_ident.core.model.hydrodynamics import Model  # noqa: E402
from auv_ident.core.model.sensors import ar1_noise, DEFAULT_NOISE_STD  # noqa: E402
from auv_ident.core.model.thrusters import scaled_curves  # noqa: E402
from auv_ident.core.model.vehicle import vehicle_from_file  # noqa: E402
from auv_ident.core.simulation.simulate import simulate  # noqa: E402
from auv_ident.core.vehicle_files import read_yaml_file  # noqa: E402
from auv_ident.offline.sim_bag import write_run_bag  # noqa: E402
from auv_ident.vehicles import resolve_vehicle_path  # noqa: E402

FWD, REV = 1.10, 0.95
# coefficient -> factor of the truth
FACTORS = {'X_uu': 1.2, 'N_rr': 0.8, 'Z_wdot': 1.15, 'Y_vdot': 0.9}


def truth_file(folder):
    """The perturbed vehicle file in folder; returns its path."""
    raw = read_yaml_file(resolve_vehicle_path('bluerov2_heavy'))
    raw['thrusters'] = scaled_curves(raw['thrusters'], FWD, REV)
    for name, factor in FACTORS.items():
        raw['coefficients'][name] = [raw['coefficients'][name][0] * factor,
                                     *raw['coefficients'][name][1:]]
    path = os.path.join(folder, 'bluerov2_heavy.yaml')
    with open(path, 'w', encoding='utf-8') as fh:
        yaml.safe_dump(raw, fh)
    return path


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seed', type=int, default=13)
    ap.add_argument('--noise', type=float, default=1.0, help='x the default noise 1-sigma')
    ap.add_argument('--duration', type=float, default=600.0)
    ap.add_argument('--out', required=True)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        vehicle = vehicle_from_file(truth_file(folder))
        run = simulate(Model(vehicle), 'tank', duration=args.duration, seed=args.seed,
                       substeps=4, noise_std=np.zeros(12))
        truth = {n: vehicle.values[vehicle.index(n)] for n in vehicle.identify_default
                 if not n.startswith('thrust_gain')}
    run.noise_std = args.noise * DEFAULT_NOISE_STD
    run.y = run.y + ar1_noise(np.random.default_rng([args.seed, 1]), len(run.t), run.noise_std,
                              0.5, run.T)
    write_run_bag(run, args.out, command='tools/rov_tank_bag.py ' + ' '.join(sys.argv[1:]))
    print(f'wrote {args.out}; TRUTH: thrust_gain_fwd {FWD}, thrust_gain_rev {REV}, '
          + ', '.join(f'{n} {v:.6g}' for n, v in truth.items()))
    return 0


if __name__ == '__main__':
    sys.exit(main())
