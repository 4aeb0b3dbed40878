"""Identification speed from raw sensors against fused odometry, side by side on one run.

    .venv/bin/python tools/raw_speed_bench.py [--duration 600] [--seed 20] [--rounds 2]
        [--profile] [--bags DIR]

One run of the independent generator (offline/independent_data.py generate_raw: 100 Hz IMU,
5 Hz DVL with dropouts, 10 Hz pressure, commands on change) is identified
(analysis/raw_comparison.py, as tools/raw_sensor_campaign.py does):

- raw: core/identification/raw.py identify_raw over the raw records (its default passes);
- fused: the generator's navigation EKF's 20 Hz odometry of the same run through
  identify_with_diagnosis (noise model, EKF pass, refinement), what `identify --bag` runs on an
  /odom bag.

Each is run `rounds` times, taking turns (a slow spell of the shared machine hits both), and
its best round is printed in seconds, with the ratio raw / fused (issue 28's goal: at most 2).
A first untimed call of each compiles numba's kernels. --bags DIR also writes the run as two
bags, the raw sensors (with their input map, as offline/raw_example.py writes them) and the
navigation filter's odometry with the commands (/odom + /actuators), and times what a user
runs end to end, reading included: `identify --bag DIR/raw --input-map DIR/map.yaml` against
`identify --bag DIR/fused --noise-source parameter` (analysis identify_raw_bag and
identify_bag; the odometry carries no covariance). --profile prints cProfile's 25 most
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


def write_bags(run, cfg, folder):
    """(raw bag, its map, fused bag) of the run in ``folder`` (module docstring)."""
    import numpy as np
    import yaml

    from auv_ident.offline.independent_data import fused_odometry
    from auv_ident.offline.raw_example import EPOCH_NS, input_map, record_message, TOPICS
    from auv_ident.offline.sim_bag import joint_state_msg, odometry_msg, write_message_bag
    os.makedirs(folder, exist_ok=True)
    raw = write_message_bag(os.path.join(folder, 'raw'), TOPICS, {},
                            (record_message(r) for r in run.records), None)
    map_path = os.path.join(folder, 'map.yaml')
    with open(map_path, 'w', encoding='utf-8') as fh:
        yaml.safe_dump(input_map(cfg), fh, sort_keys=False)
    t, Y = fused_odometry(run, cfg, FUSED_RATE)
    msgs = [('/odom', EPOCH_NS + int(round(tk * 1e9)), y) for tk, y in zip(t, Y)]
    msgs += [('/actuators', EPOCH_NS + int(round(tk * 1e9)), u)
             for tk, u in zip(run.cmd_t, run.cmd_values)]
    msgs.sort(key=lambda m: (m[1], m[0] == '/odom'))   # a command before odometry at a tie
    fused = write_message_bag(
        os.path.join(folder, 'fused'),
        {'/odom': 'nav_msgs/msg/Odometry', '/actuators': 'sensor_msgs/msg/JointState'},
        {'vehicle': 'nps_auv2'},
        ((topic, ns, odometry_msg(ns, np.asarray(v)) if topic == '/odom'
          else joint_state_msg(ns, np.asarray(v))) for topic, ns, v in msgs), None)
    return raw, map_path, fused


def time_bags(run, cfg, folder, rounds):
    """Best-of-rounds seconds of identify --bag on the raw and the fused bag (module
    docstring), after one untimed call of each (numba's kernels)."""
    from auv_ident.analysis.bag_identify import identify_bag
    from auv_ident.analysis.raw_identify import identify_raw_bag
    from auv_ident.session.settings import IdentifierSettings
    raw, map_path, fused = write_bags(run, cfg, folder)
    names = list(PAPER_FIVE)
    jobs = {'raw': lambda: identify_raw_bag(raw, IdentifierSettings.from_values(
                coefficients=names, input_map=map_path)),
            'fused': lambda: identify_bag(fused, IdentifierSettings.from_values(
                coefficients=names, noise_source='parameter'))}
    best = {k: float('inf') for k in jobs}
    for _ in range(rounds):
        for name, fn in jobs.items():
            t = time.perf_counter()
            fn()
            best[name] = min(best[name], time.perf_counter() - t)
    return best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--duration', type=float, default=600.0, help='s of run (600)')
    ap.add_argument('--seed', type=int, default=20)
    ap.add_argument('--rounds', type=int, default=2)
    ap.add_argument('--profile', action='store_true')
    ap.add_argument('--bags', metavar='DIR', help='also time identify --bag end to end on the '
                                                  'run written as bags into DIR (new)')
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
    if a.bags:
        bags = time_bags(run, cfg, a.bags, a.rounds)
        print(f'identify --bag, reading included: raw sensors {bags["raw"]:.2f} s, fused '
              f'odometry {bags["fused"]:.2f} s, ratio {bags["raw"] / bags["fused"]:.2f}')
    if a.profile:
        prof = cProfile.Profile()
        prof.runcall(raw)
        pstats.Stats(prof).sort_stats('cumulative').print_stats(25)


if __name__ == '__main__':
    main()
