"""Measure the campaign engine (auv_ident/analysis/engine.py) and print the figures of
docs/campaigns.md: throughput with 1 and 2 local workers (bags per minute), the overhead
against a plain serial loop in one process, and what the per-worker warm-up does.

    .venv/bin/python tools/campaign_bench.py [--bags 16] [--duration 120] [--workers 1,2]
        [--repeat 3] [--cold] [--keep DIR]

Every figure comes from one run on this machine (its load average is printed with them). The
bags are simulated (nps_auv2, manoeuvre 'ident', seeds 0..N-1), written once to a temporary
folder (or under DIR with --keep, reused). What is compared:

- serial: `identify_bag` on every bag, one after the other, in a Python process of its own
  without Dask, after one untimed identification (so that neither side pays the compilation);
- campaign, W workers: a local cluster is started (its start: cluster up, every worker warmed
  up), then --repeat pairs of (serial loop, `run_campaign` on the cluster) run back to back;
  the best of each is compared (on a shared machine the best is the least disturbed). The
  campaign's "tasks" time runs from the first task submitted to the last row in hand. Also
  printed: the CPU time of the worker processes (every thread: the task, Dask's event loop,
  heartbeats) against the serial loop's, what an idle worker uses, and the engine's own time
  per task (a task submitted alone: the client's round trip minus the task's wall time);
- without warm-up (1 worker): the first task pays loading the compiled kernels;
- --cold: workers with empty numba and kernel caches: the warm-up compiles once per worker;
  and without the warm-up, the first task of the worker compiles.
"""
import argparse
import csv
import json
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

if __package__ in (None, ''):  # run as a script: the package is the repository root's
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from distributed import Client  # noqa: E402

from auv_ident.analysis import engine  # noqa: E402
from auv_ident.analysis.campaign import (  # noqa: E402
    find_bags,
    identify_bag_row,
    run_campaign,
    warm_up_plugin,
)
from auv_ident.core.model.hydrodynamics import Model  # noqa: E402
from auv_ident.core.simulation.simulate import simulate  # noqa: E402
from auv_ident.offline.sim_bag import SIM_EPOCH_NS, write_run_bag  # noqa: E402
from auv_ident.vehicles import load_vehicle  # noqa: E402

VEHICLE = 'nps_auv2'
IDLE_S = 10.0      # s of an idle cluster over which the workers' own CPU use is measured
ROUND_TRIPS = 10   # tasks submitted one at a time: the engine's cost per task
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
    import psutil  # a dependency of distributed: on every worker
    t = psutil.Process().cpu_times()
    return t.user + t.system


SERIAL_LOOP = """
import json, sys, time
from auv_ident.analysis.bag_identify import identify_bag
bags, vehicle = json.loads(sys.argv[1]), sys.argv[2]
identify_bag(bags[0], vehicle=vehicle)        # compile/load, untimed
t0, c0 = time.perf_counter(), time.process_time()
for b in bags:
    identify_bag(b, vehicle=vehicle)
print(json.dumps([time.perf_counter() - t0, time.process_time() - c0]))
"""


def serial_pass(bags):
    """identify_bag on every bag, one after the other, in a process of its own without Dask
    (in this one, the local cluster's scheduler thread would compete for the interpreter):
    (wall s, CPU s) of the loop, after one untimed identification."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        p for p in (str(Path(__file__).resolve().parents[1]), os.environ.get('PYTHONPATH'))
        if p))
    out = subprocess.run([sys.executable, '-c', SERIAL_LOOP, json.dumps(bags), VEHICLE],
                         env=env, capture_output=True, text=True, check=True)
    return tuple(json.loads(out.stdout.strip().splitlines()[-1]))


def measured_cluster(bag_glob, bags, tmp, workers, repeat):
    """A local cluster started here with the warm-up registered (the plugin run_campaign
    registers, so it is not run twice); its CPU when idle over IDLE_S (event loop,
    heartbeats, monitoring); then `repeat` pairs of a serial pass in this process and the
    campaign on the cluster (fresh output folder), back to back, so that both see the same
    load. Returns a dict of the figures."""
    t0 = time.perf_counter()
    with engine.local_cluster(workers) as lc, Client(lc) as client:
        plugin = warm_up_plugin(engine.VehicleText.read(VEHICLE), '', True)
        client.register_plugin(plugin)
        start_s = time.perf_counter() - t0
        warm = engine.warm_up_times(client, plugin.name)
        idle0, t_idle = client.run(_process_cpu_s), time.perf_counter()
        time.sleep(IDLE_S)
        idle1 = client.run(_process_cpu_s)
        idle_s = time.perf_counter() - t_idle
        idle = sum(idle1[w] - idle0[w] for w in idle0) / len(idle0) / idle_s
        job = {'bag': bags[0], 'vehicle': engine.VehicleText.read(VEHICLE),
               'coefficients': '', 'refine': True}
        round_trip = []
        for _ in range(ROUND_TRIPS):
            t1 = time.perf_counter()
            row = client.submit(identify_bag_row, job, pure=False).result()
            round_trip.append(time.perf_counter() - t1 - row['wall_s'])
        pairs = []
        for r in range(repeat):
            serial, serial_cpu = serial_pass(bags)
            cpu0 = sum(client.run(_process_cpu_s).values())
            s = campaign(bag_glob, os.path.join(tmp, f'out{workers}_{r}'), workers,
                         scheduler=lc.scheduler_address)
            cpu = sum(client.run(_process_cpu_s).values()) - cpu0
            pairs.append({'serial': serial, 'serial_cpu': serial_cpu, 'wall': s['wall_s'],
                          'tasks': s['tasks_s'], 'cpu': cpu})
    return {'start': start_s, 'warm': warm, 'idle': idle, 'pairs': pairs,
            'round_trip': sorted(round_trip)}


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
    ap.add_argument('--repeat', type=int, default=3,
                    help='pairs of (serial loop, campaign) per worker count; the best of each '
                         'is compared (the machine may be shared)')
    args = ap.parse_args(argv)
    counts = [int(w) for w in args.workers.split(',')]
    tmp = tempfile.TemporaryDirectory(prefix='auv_ident_campaign_bench_')
    # a folder of exactly these bags: the campaign takes every bag in it
    folder = os.path.join(args.keep or tmp.name, f'bags_{args.bags}x{args.duration:g}s')
    os.makedirs(folder, exist_ok=True)
    bags = make_bags(folder, args.bags, args.duration)
    n = len(bags)
    bag_glob = os.path.join(folder, 'mission*')
    print(f'{n} bags of {args.duration:.0f} s ({VEHICLE}, manoeuvre ident), EKF pass + '
          f'refinement; {os.cpu_count()} cores, load average at start '
          + ' '.join(f'{x:.2f}' for x in os.getloadavg()))

    for w in counts:
        m = measured_cluster(bag_glob, bags, tmp.name, w, args.repeat)
        pairs = m['pairs']
        serial = min(p['serial'] for p in pairs)
        tasks = min(p['tasks'] for p in pairs)
        wall = min(p['wall'] for p in pairs)
        print(f'{w} worker(s): cluster start {m["start"]:.1f} s, of which warm-up per worker '
              + ', '.join(f'{v:.1f}' for v in m['warm'].values()) + ' s; an idle worker uses '
              f'{100 * m["idle"]:.1f} % of a core; engine time per task (client round trip '
              f"minus the task's own wall time, {ROUND_TRIPS} tasks one at a time): median "
              f'{1000 * m["round_trip"][ROUND_TRIPS // 2]:.0f} ms, max '
              f'{1000 * m["round_trip"][-1]:.0f} ms')
        for p in pairs:
            print(f'  pair: serial loop {p["serial"]:.1f} s (CPU {p["serial_cpu"]:.1f} s), '
                  f'campaign {p["wall"]:.1f} s (tasks {p["tasks"]:.1f} s, worker CPU '
                  f'{p["cpu"]:.1f} s = {100 * (p["cpu"] / p["serial_cpu"] - 1):+.1f} %)')
        cpu = sorted(p['cpu'] / p['serial_cpu'] - 1 for p in pairs)[len(pairs) // 2]
        print(f'  best of {len(pairs)}: serial loop {serial:.1f} s = {60 * n / serial:.1f} '
              f'bags/min; campaign tasks {tasks:.1f} s = {60 * n / tasks:.1f} bags/min '
              f'(wall {100 * (tasks / serial - 1):+.1f} % against the serial loop, speed-up '
              f'{serial / tasks:.2f}x); with the cluster start '
              f'{60 * n / (m["start"] + wall):.1f} bags/min; worker CPU against the serial '
              f"loop's, median of the pairs: {100 * cpu:+.1f} %")

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
