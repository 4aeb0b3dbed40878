"""Identification speed from raw sensors against fused odometry, side by side on one run.

    .venv/bin/python tools/raw_speed_bench.py [--duration 600] [--seed 20] [--rounds 2]
        [--profile]

One run of the independent generator (offline/independent_data.py generate_raw: 100 Hz IMU,
5 Hz DVL with dropouts, 10 Hz pressure, commands on change) is identified
(analysis/raw_comparison.py, as tools/raw_sensor_campaign.py does):

- raw: core/identification/raw.py identify_raw over the raw records (its default passes);
- fused: the generator's navigation EKF's 20 Hz odometry of the same run through
  identify_with_diagnosis (noise model, EKF pass, refinement), what `identify --bag` runs on an
  /odom bag.

Each is run `rounds` times, taking turns (a slow spell of the shared machine hits both), and
its best round is printed in seconds, with the ratio raw / fused (issue 28's goal: at most 2).
A first untimed call of each compiles numba's kernels. --profile prints cProfile's 25 most
expensive functions of one raw identification (cumulative time).
"""
import argparse
import cProfile
import os
import pstats
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from auv_ident.analysis.raw_comparison import (  # noqa: E402
    FUSED_RATE,
    fused_record,
    PAPER_FIVE,
    sensors_of,
)
from auv_ident.core.filter.augmented import FilterConfig  # noqa: E402
from auv_ident.core.identification.pipeline import identify_with_diagnosis  # noqa: E402
from auv_ident.core.identification.raw import identify_raw  # noqa: E402
from auv_ident.core.identification.results import Record  # noqa: E402
from auv_ident.core.model.hydrodynamics import Model  # noqa: E402
from auv_ident.offline.independent_data import DataConfig, generate_raw, RawConfig  # noqa: E402
from auv_ident.vehicles import load_vehicle  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--duration', type=float, default=600.0, help='s of run (600)')
    ap.add_argument('--seed', type=int, default=20)
    ap.add_argument('--rounds', type=int, default=2)
    ap.add_argument('--profile', action='store_true')
    a = ap.parse_args(argv)
    cfg = RawConfig(data=DataConfig(duration=a.duration, seed=a.seed))
    t0 = time.perf_counter()
    run = generate_raw(cfg)
    record, _ = fused_record(run, cfg)
    print(f'run: {a.duration:g} s, seed {a.seed}, {len(run.records)} raw records, '
          f'{len(record.t)} fused odometry rows ({FUSED_RATE:g} Hz); made in '
          f'{time.perf_counter() - t0:.1f} s')
    model = Model(load_vehicle('nps_auv2'), list(PAPER_FIVE))
    sensors = sensors_of(cfg)

    def raw():
        return identify_raw(model, FilterConfig(), run.records, sensors)

    def fused():
        return identify_with_diagnosis(model, FilterConfig(), [record], T=1.0 / FUSED_RATE)

    # compile numba's kernels outside the timing (a short slice of each)
    identify_raw(model, FilterConfig(), run.records[:3000], sensors, passes=1)
    n = min(len(record.t), 600)
    identify_with_diagnosis(model, FilterConfig(),
                            [Record(record.t[:n], record.Y[:n], record.U[:n])],
                            T=1.0 / FUSED_RATE)
    best = {'raw': float('inf'), 'fused': float('inf')}
    passes = 0
    for _ in range(a.rounds):
        for name, fn in (('raw', raw), ('fused', fused)):
            t = time.perf_counter()
            out = fn()
            best[name] = min(best[name], time.perf_counter() - t)
            if name == 'raw':
                passes = out.passes
    print(f'raw sensors: {best["raw"]:.2f} s ({passes} passes, '
          f'{best["raw"] / passes:.2f} s a pass)')
    print(f'fused odometry: {best["fused"]:.2f} s (noise model, EKF pass, refinement)')
    print(f'ratio raw / fused: {best["raw"] / best["fused"]:.2f} (goal: at most 2)')
    if a.profile:
        prof = cProfile.Profile()
        prof.runcall(raw)
        pstats.Stats(prof).sort_stats('cumulative').print_stats(25)


if __name__ == '__main__':
    main()
