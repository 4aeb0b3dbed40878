"""Resident memory of ``identify --bag`` against the length of the bag.

    PYTHONPATH=. .venv/bin/python tools/bag_memory.py [--duration 300 --duration 3000]
        [--vehicle remus100] [--dt 0.05]

For each duration, a simulated bag (``python -m auv_ident simulate --maneuver zigzag --out``,
in a temporary folder, removed at the end) is identified by ``python -m auv_ident identify
--vehicle V --bag BAG`` in a process of its own; its peak resident set size (os.wait4's
ru_maxrss, what /usr/bin/time -v reports as "Maximum resident set size") and wall time are
printed, then the growth per odometry sample between the shortest and the longest bag.
docs/reliability.md has the figures ("Bounded memory").
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time


def peak_rss_mb(argv, env=None):
    """(peak resident MB, wall s, exit code) of a command run to its end."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    proc.stderr.close()
    return usage.ru_maxrss / 1024.0, time.perf_counter() - t0, proc.returncode


def measure(durations, vehicle='remus100', dt=0.05, folder=None):
    """[(duration s, samples, peak MB, wall s)] of identify --bag on simulated bags."""
    out = []
    with tempfile.TemporaryDirectory(dir=folder) as tmp:
        for d in durations:
            bag = os.path.join(tmp, f'bag_{d:g}')
            subprocess.run([sys.executable, '-m', 'auv_ident', 'simulate', '--vehicle', vehicle,
                            '--maneuver', 'zigzag', '--duration', f'{d:g}', '--dt', f'{dt:g}',
                            '--seed', '1', '--out', bag], check=True, capture_output=True)
            mb, wall, rc = peak_rss_mb([sys.executable, '-m', 'auv_ident', 'identify',
                                        '--vehicle', vehicle, '--bag', bag])
            if rc != 0:
                raise RuntimeError(f'identify --bag {bag} exited {rc}')
            out.append((d, int(round(d / dt)) + 1, mb, wall))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--duration', type=float, action='append',
                    help='s of simulated data (repeatable; default 300 and 3000)')
    ap.add_argument('--vehicle', default='remus100')
    ap.add_argument('--dt', type=float, default=0.05, help='sample time, s')
    args = ap.parse_args(argv)
    rows = measure(sorted(args.duration or [300.0, 3000.0]), args.vehicle, args.dt)
    print(f'identify --vehicle {args.vehicle} --bag (zigzag, {1 / args.dt:g} Hz):')
    for d, n, mb, wall in rows:
        print(f'  {d:7.0f} s  {n:7d} samples  peak RSS {mb:7.1f} MB  wall {wall:6.1f} s')
    if len(rows) > 1:
        (_, n0, m0, _), (_, n1, m1, _) = rows[0], rows[-1]
        print(f'growth {(m1 - m0) * 1024 / (n1 - n0):.2f} KB per odometry sample')


if __name__ == '__main__':
    main()
