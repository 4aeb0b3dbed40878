"""What a sleep between messages does to the CPU of the same per-message work (the reason for
the live node's batched intake, ros/intake.py; docs/latency.md "Batched intake"):

    PYTHONPATH=. python tools/idle_penalty.py [--seconds 30] [--sleep-ms 2,20] [--batch 8]

A raw example run (offline/raw_example.py: 400 Hz IMU, 5 Hz DVL, 10 Hz pressure, commands) is
fed to a RawSession (session/raw_session.py, no ROS) three ways, each with a fresh session:
back to back; with a sleep of --sleep-ms after every message (what an executor that wakes for
each message does at 400 Hz: the thread sleeps between messages); and in batches of --batch
messages with the sleep after each batch (what a 20 ms intake does). The figure is the
thread's CPU time (time.thread_time) inside RawSession.on_input, per message: the sleeps
themselves cost no CPU, so any difference is the same work made dearer by the sleep (the
caches and the core's state after an idle spell).
"""
import argparse
import tempfile
import time

from auv_ident.bags.reader import read_bag
from auv_ident.offline.raw_example import write_raw_example
from auv_ident.session.input_map import load_input_map
from auv_ident.session.raw_session import RawSession
from auv_ident.session.settings import IdentifierSettings

NAMES = ['Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v']


def cpu_per_message(messages, map_path, sleep_s, batch):
    """Thread CPU (s) per message of RawSession.on_input over ``messages``, sleeping
    ``sleep_s`` after every ``batch`` messages (0: never)."""
    s = RawSession(IdentifierSettings.from_values(input_map=str(map_path), coefficients=NAMES))
    s.warm_up()
    cpu = 0
    for i, (name, ns, msg) in enumerate(messages):
        t0 = time.thread_time_ns()
        s.on_input(name, msg, ns)
        cpu += time.thread_time_ns() - t0
        if sleep_s > 0 and (i + 1) % batch == 0:
            time.sleep(sleep_s)
    return cpu * 1e-9 / len(messages)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=30.0, help='length of the example run')
    ap.add_argument('--sleep-ms', default='2', help='comma-separated sleeps to try (ms)')
    ap.add_argument('--batch', type=int, default=8, help='messages per batch (default 8)')
    a = ap.parse_args(argv)
    bag, map_path = write_raw_example(tempfile.mkdtemp(prefix='idle_penalty_'),
                                      duration=a.seconds, seed=5, imu_rate=400.0)
    imap = load_input_map(str(map_path))
    by_topic = {e.bag_topic: e.name for e in imap.inputs}
    messages = [(by_topic[t], ns, m) for t, ns, m in read_bag(bag, imap.topic_types)]
    print(f'{len(messages)} messages of a {a.seconds:g} s raw example (400 Hz IMU), '
          'RawSession.on_input, thread CPU per message:')
    print(f'  back to back: {1e6 * cpu_per_message(messages, map_path, 0.0, 1):.1f} us')
    for ms in (float(v) for v in a.sleep_ms.split(',')):
        each = cpu_per_message(messages, map_path, ms * 1e-3, 1)
        batched = cpu_per_message(messages, map_path, ms * 1e-3, a.batch)
        print(f'  {ms:g} ms sleep after every message: {1e6 * each:.1f} us; after every '
              f'{a.batch}: {1e6 * batched:.1f} us')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
