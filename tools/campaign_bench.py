"""Measure the campaign engine (auv_ident/analysis/engine.py) and print the figures of
docs/campaigns.md: throughput with 1 and 2 local workers (bags per minute), the overhead
against a plain serial loop in one process, and what the per-worker warm-up does.

    .venv/bin/python tools/campaign_bench.py [--bags 16] [--duration 120] [--workers 1,2]
        [--cold] [--keep DIR]

Every figure comes from one run on this machine (its load average is printed with them). The
bags are simulated (nps_auv2, manoeuvre 'ident', seeds 0..N-1), written once to a temporary
folder (or DIR with --keep, reused when it holds the bags). What is compared:

- serial: `identify_bag` on every bag, one after the other, in this process, after one
  untimed identification (so that neither side pays the compilation);
- campaign, W workers: `run_campaign` on a new local cluster: the wall time of the start
  (cluster up, every worker warmed up) and of the campaign (first task submitted to last row
  written, plus trends.png), and the CPU time of the worker processes during the campaign
  (every thread: the task, Dask's event loop, heartbeats) against the serial loop's; on a
  machine others share, the CPU time is the steadier measure of the engine's overhead;
- without warm-up (1 worker): the first task pays loading the compiled kernels;
- --cold: workers with empty numba and kernel caches: the warm-up compiles once per worker;
  and without the warm-up, the first task of the worker compiles.
"""
import argparse
import csv
import os
from pathlib import Path
import sys
import tempfile
import time

if __package__ in (None, ''):  # run as a script: the package is the repository root's
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from distributed import Client  # noqa: E402

from auv_ident.analysis import engine  # noqa: E402
from auv_ident.analysis.bag_identify import identify_bag  # noqa: E402
from auv_ident.analysis.campaign import find_bags, run_campaign, warm_up_plugin  # noqa: E402
from auv_ident.bags.sim_bag import SIM_EPOCH_NS, write_run_bag  # noqa: E402
from auv_ident.core.model import Model  # noqa: E402
from auv_ident.core.simulate import simulate  # noqa: E402
from auv_ident.vehicles import load_vehicle  # noqa: E402

VEHICLE = 'nps_auv2'
IDLE_S = 10.0      # s of an idle cluster over which the workers' own CPU use is measured
DAY_NS = 86_400 * 1_000_000_000


def make_bags(folder, n, duration):
    """n simulated bags in folder (kept if already there); their paths."""
    model = Model(load_vehicle(VEHICLE))
    for k in range(n):
        path = os.path.join(folder, f'mission{k:03d}')
        if not os.path.isdir(path):
            run = simulate(model, 'ident', duration=duration, seed=k)
            write_run_bag(run, path, epoch_ns=SIM_EPOCH_NS + k * DAY_NS)
    return find_bags(os.path.join(folder, 'mission*'))[:n]


def task_walls(out):
    """wall_s of the rows of OUT/campaign.csv, sorted by bag: mission number = the order the
    tasks were submitted in (and, on one worker, run in)."""
    with open(os.path.join(out, 'campaign.csv'), newline='', encoding='utf-8') as fh:
        return [float(r['wall_s']) for r in csv.DictReader(fh)]


def _process_cpu_s():
    import psutil     # a dependency of distributed: on every worker
    t = psutil.Process().cpu_times()
    return t.user + t.system


def measured_campaign(bag_glob, out, workers):
    """run_campaign on a local cluster started here, the warm-up registered before (the same
    plugin run_campaign registers, so it is not run twice): (summary, start_s, warm-up s per
    worker, CPU of an idle worker in cores (its event loop, heartbeats, monitoring; measured
    over IDLE_S before the campaign), worker CPU s during the campaign)."""
    t0 = time.perf_counter()
    with engine.local_cluster(workers) as lc, Client(lc.scheduler_address) as client:
        plugin = warm_up_plugin(engine.VehicleText.read(VEHICLE), '', True)
        client.register_plugin(plugin)
        start_s = time.perf_counter() - t0
        warm = engine.warm_up_times(client, plugin.name)
        idle0, t_idle = client.run(_process_cpu_s), time.perf_counter()
        time.sleep(IDLE_S)
        idle1 = client.run(_process_cpu_s)
        idle_s = time.perf_counter() - t_idle
        idle = sum(idle1[w] - idle0[w] for w in idle0) / len(idle0) / idle_s
        cpu0 = sum(client.run(_process_cpu_s).values())
        s = campaign(bag_glob, out, workers, scheduler=lc.scheduler_address)
        cpu = sum(client.run(_process_cpu_s).values()) - cpu0
    return s, start_s, warm, idle, cpu


def campaign(bag_glob, out, workers, **kw):
    s = run_campaign(bag_glob, out, vehicle=VEHICLE, workers=workers, **kw)
    assert s['ok'] == s['bags'], f'{s["error"]} bags failed: see {out}/campaign.csv'
    return s


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--bags', type=int, default=16)
    ap.add_argument('--duration', type=float, default=120.0, help='s of each bag')
    ap.add_argument('--workers', default='1,2', help='local worker counts to measure')
    ap.add_argument('--cold', action='store_true',
                    help='also measure workers with empty compile caches')
    ap.add_argument('--keep', help='folder for the bags (kept, reused)')
    args = ap.parse_args(argv)
    counts = [int(w) for w in args.workers.split(',')]
    tmp = tempfile.TemporaryDirectory(prefix='auv_ident_campaign_bench_')
    folder = args.keep or os.path.join(tmp.name, 'bags')
    os.makedirs(folder, exist_ok=True)
    bags = make_bags(folder, args.bags, args.duration)
    n = len(bags)
    bag_glob = os.path.join(folder, 'mission*')
    print(f'{n} bags of {args.duration:.0f} s ({VEHICLE}, manoeuvre ident), EKF pass + '
          f'refinement; {os.cpu_count()} cores, load average at start '
          + ' '.join(f'{x:.2f}' for x in os.getloadavg()))

    identify_bag(bags[0], vehicle=VEHICLE)          # compile/load, untimed
    t0, c0 = time.perf_counter(), time.process_time()
    for b in bags:
        identify_bag(b, vehicle=VEHICLE)
    serial, serial_cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f'serial loop in one process: wall {serial:.1f} s, {60 * n / serial:.1f} bags/min '
          f'({serial / n:.2f} s per bag), CPU {serial_cpu:.1f} s')

    for w in counts:
        s, start_s, warm, idle, cpu = measured_campaign(bag_glob,
                                                        os.path.join(tmp.name, f'out{w}'), w)
        wall = start_s + s['wall_s']
        print(f'campaign, {w} worker(s): start {start_s:.1f} s (cluster + warm-up, warm-up per '
              f'worker ' + ', '.join(f'{v:.1f}' for v in warm.values()) + ' s), campaign '
              f'{s["wall_s"]:.1f} s (tasks {s["tasks_s"]:.1f} s): {60 * n / wall:.1f} bags/min '
              f'with the start, {60 * n / s["tasks_s"]:.1f} in the tasks; speed-up over the '
              f'serial loop {serial / s["tasks_s"]:.2f}x in the tasks, {serial / wall:.2f}x '
              f'with the start; worker CPU {cpu:.1f} s = {100 * (cpu / serial_cpu - 1):+.1f} % '
              f'against the serial loop; an idle worker uses {100 * idle:.1f} % of a core '
              f'(x {w} worker(s) x the campaign\'s {s["wall_s"]:.1f} s = '
              f'{idle * w * s["wall_s"]:.1f} s of the difference)')

    s = campaign(bag_glob, os.path.join(tmp.name, 'out_nowarm'), 1, warm_up=False)
    walls = task_walls(os.path.join(tmp.name, 'out_nowarm'))
    print(f'without warm-up, 1 worker: wall {s["wall_s"]:.1f} s, tasks {s["tasks_s"]:.1f} s; '
          f'task walls: first {walls[0]:.2f} s, the others {sum(walls[1:]) / (n - 1):.2f} s '
          'on average' if n > 1 else '')

    if args.cold:
        with tempfile.TemporaryDirectory(prefix='auv_ident_cold_') as cold:
            env = {'NUMBA_CACHE_DIR': os.path.join(cold, 'numba'),
                   'AUV_IDENT_KERNEL_CACHE': os.path.join(cold, 'kernels')}
            w = max(counts)
            s = campaign(bag_glob, os.path.join(tmp.name, 'out_cold'), w, worker_env=env)
            walls = task_walls(os.path.join(tmp.name, 'out_cold'))
            warm = ', '.join(f'{v:.1f}' for v in s['warm_up_s'].values())
            print(f'cold caches, {w} worker(s): warm-up (compilation) per worker {warm} s; '
                  f'then task walls {min(walls):.2f}-{max(walls):.2f} s (no task compiles); '
                  f'wall {s["wall_s"]:.1f} s')
        with tempfile.TemporaryDirectory(prefix='auv_ident_cold_') as cold:
            env = {'NUMBA_CACHE_DIR': os.path.join(cold, 'numba'),
                   'AUV_IDENT_KERNEL_CACHE': os.path.join(cold, 'kernels')}
            s = campaign(bag_glob, os.path.join(tmp.name, 'out_cold1'), 1, worker_env=env,
                         warm_up=False)
            walls = task_walls(os.path.join(tmp.name, 'out_cold1'))
            print(f'cold caches, 1 worker, no warm-up: the first task {walls[0]:.2f} s '
                  f'(it compiles), the others {sum(walls[1:]) / max(1, n - 1):.2f} s on average; '
                  f'wall {s["wall_s"]:.1f} s')
    tmp.cleanup()
    return 0


if __name__ == '__main__':
    sys.exit(main())
