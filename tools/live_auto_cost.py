"""What the identifier's live `coefficients: [auto, ...]` costs (session/auto_choice.py).

    PYTHONPATH=. .venv/bin/python tools/live_auto_cost.py [--window 120] [--rate 20]
        [--named Z_ds,Z_q,Z_w,M_ds,K_v] [--windows 30,60,120,240] [--seed 5] [--paced]

One independent NPS AUV II bag (offline/independent_data.py: odometry at --rate Hz, commands
periodic at 20 Hz, white noise at the documented level, every coefficient 0.8-1.2x the vehicle
file's), 30 s longer than the longest window, fed in log-time order through an IdentSession
with coefficients [auto, NAMED...]:

1. per window (--windows, and --window): the choice alone
(core.identification.selection.choose_coefficients,
   wall and CPU s of the job's thread), the job with the feeding of the kept record (wall s),
   and the chosen set. The choice runs inline here, so these are its own costs;
2. with --paced, the node's situation: the window fed at once, then the rest at the bag's pace
   (real time) while the choice runs in a worker thread (auto_choice.run_in_thread); printed
   are the per-message times of the session calls while the worker ran and after it (the
   worker holds the GIL during each compiled filter run; what the callbacks wait for).

These are measurements, not assertions; the machine's load average is printed with them.
"""
import argparse
import os
from pathlib import Path
import sys
import tempfile
import time

import numpy as np

from auv_ident.bags.reader import read_bag
from auv_ident.offline.independent_data import ACTUATOR_TOPIC, DataConfig, generate, ODOM_TOPIC
from auv_ident.session.auto_choice import run_in_thread, run_inline
from auv_ident.session.session import IdentSession
from auv_ident.session.settings import IdentifierSettings


def messages_of(bag):
    return list(read_bag(bag, {ODOM_TOPIC: 'nav_msgs/msg/Odometry',
                               ACTUATOR_TOPIC: 'sensor_msgs/msg/JointState'}))


def feed(session, messages):
    for topic, _, msg in messages:
        (session.on_actuators if topic == ACTUATOR_TOPIC else session.on_odom)(msg)


def timed_inline(cpu):
    """An inline runner that also records the CPU time of the job: the process's (the
    sensitivities run on a pool thread; nothing else runs meanwhile)."""
    def runner(work):
        start = time.process_time()
        future = run_inline(work)
        cpu.append(time.process_time() - start)
        return future
    return runner


def one_window(messages, named, window):
    cpu = []
    s = IdentSession(IdentifierSettings.from_values(coefficients=['auto'] + named,
                                                    auto_window=window),
                     auto_runner=timed_inline(cpu))
    feed(s, messages)
    a = s.auto
    if a.state != 'chosen':
        return f'{window:6.0f} s: {a.state} {a.reason}'
    sel = a.selection
    return (f'{window:6.0f} s: {a.samples:5d} samples fed at the switch; choice '
            f'{a.choice_wall_s:6.2f} s wall, job (choice + feeding) {a.job_wall_s:6.2f} s wall, '
            f'{cpu[0]:6.2f} s CPU; {len(sel.chosen)} chosen: {", ".join(sel.chosen)}')


def paced(messages, named, window):
    """Feed the window at once, then the rest at the log times' pace, the choice in a worker
    thread; per-message call times (s) while it ran and after."""
    s = IdentSession(IdentifierSettings.from_values(coefficients=['auto'] + named,
                                                    auto_window=window), auto_runner=run_in_thread)
    t0_ns = messages[0][1]
    split = next(i for i, (_, t_ns, _) in enumerate(messages)
                 if (t_ns - t0_ns) * 1e-9 > window + 0.5)
    feed(s, messages[:split])
    assert s.auto.running, s.auto.state
    during, after = [], []
    start_wall, start_log = time.perf_counter(), messages[split][1]
    for topic, t_ns, msg in messages[split:]:
        due = start_wall + (t_ns - start_log) * 1e-9
        while time.perf_counter() < due:
            time.sleep(max(0.0, min(0.001, due - time.perf_counter())))
        running = s.auto.running
        c0 = time.perf_counter()
        (s.on_actuators if topic == ACTUATOR_TOPIC else s.on_odom)(msg)
        (during if running else after).append(time.perf_counter() - c0)
    return s, np.array(during), np.array(after)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--window', type=float, default=120.0)
    ap.add_argument('--windows', default='')
    ap.add_argument('--rate', type=float, default=20.0)
    ap.add_argument('--named', default='')
    ap.add_argument('--seed', type=int, default=5)
    ap.add_argument('--paced', action='store_true')
    args = ap.parse_args(argv)
    windows = sorted({args.window} | {float(w) for w in args.windows.split(',') if w})
    named = [n for n in args.named.split(',') if n]
    with tempfile.TemporaryDirectory(prefix='live_auto_cost_') as tmp:
        data = generate(DataConfig(duration=max(windows) + 30.0, seed=args.seed,
                                   odom_rate=args.rate, commands='periodic', perturb=0.2),
                        Path(tmp) / 'run')
        messages = messages_of(data.bag)
    print(f'load average {os.getloadavg()[0]:.2f}; odometry {args.rate:g} Hz; named: '
          f'{", ".join(named) or "none (identify_default runs meanwhile)"}')
    for window in windows:
        print(one_window(messages, named, window))
    if args.paced:
        s, during, after = paced(messages, named, args.window)
        a = s.auto
        print(f'paced, window {args.window:g} s, choice in a worker thread: {a.state}; '
              f'{len(during)} messages arrived while it ran (choice {a.choice_wall_s:.2f} s '
              f'wall): per-message call median {1e3 * np.median(during):.3f} ms, 99 % '
              f'{1e3 * np.quantile(during, 0.99):.2f} ms, max {1e3 * during.max():.2f} ms; '
              f'after: median {1e3 * np.median(after):.3f} ms, max {1e3 * after.max():.2f} ms')
    print(f'load average {os.getloadavg()[0]:.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
