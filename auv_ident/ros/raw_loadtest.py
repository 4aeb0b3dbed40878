"""Load test of the identifier node with raw sensors (the raw mode of the load test):

    python -m auv_ident.ros.raw_loadtest [--seconds 60] [--imu-rate 400] [--rate 1.0]
        [--publish-rate HZ] [--intake-period S] [--json OUT]

A raw example run (offline/raw_example.py: the independent generator's IMU at --imu-rate Hz,
5 Hz DVL with dropouts, 10 Hz pressure, commands on change) is written as a bag with its input
map; a real identifier process with that map gets it from the player (ros/play_node.py with
the map) at --rate x real time. Figures: every message processed (the identifier's estimate
file, written on SIGINT, counts the fused messages per sensor; compared with the offline
pass's counts), the identifier's CPU time (user + system, all threads, from /proc) from just
before playback to its end, per message played, the same over the steady part of playback
(:func:`steady_cpu_per_message`: without the player's start and the last queue's work-off),
and the per-message work alone
(session/raw_session.py RawSession.on_input, no ROS) timed in this process.

DDS stays on this machine: every process runs with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
and a ROS_DOMAIN_ID in 1..101 (ros/loadtest.py loopback_env).
"""
import argparse
import json
import signal
import subprocess
import sys
import tempfile
import time

from auv_ident.bags.reader import read_bag
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.identification.raw import identify_raw
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.offline.raw_bag import raw_bag_records, raw_sensor_config
from auv_ident.offline.raw_example import write_raw_example
from auv_ident.ros.loadtest import _cpu_s, intake_text, loopback_env
from auv_ident.session.input_map import load_input_map
from auv_ident.session.raw_session import RawSession
from auv_ident.session.settings import DEFAULT_INTAKE_PERIOD_S, IdentifierSettings
from auv_ident.vehicles import load_vehicle

NAMES = ['Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v']
STEADY_SETTLE_S = 3.0   # s after the CPU window's start before the steady figure's window


def _cmd(node, *params):
    cmd = [sys.executable, '-m', 'auv_ident', 'run', node, '--ros-args']
    for p in params:
        cmd += ['-p', p]
    return cmd


def compute_per_message(bag, map_path):
    """(s per message, messages) of RawSession.on_input over the bag, in this process."""
    imap = load_input_map(str(map_path))
    s = RawSession(IdentifierSettings.from_values(input_map=str(map_path), coefficients=NAMES))
    s.warm_up()
    by_topic = {e.bag_topic: e.name for e in imap.inputs}
    msgs = [(by_topic[t], ns, m) for t, ns, m in read_bag(bag, imap.topic_types)]
    t0 = time.perf_counter()
    for name, ns, m in msgs:
        s.on_input(name, m, ns)
    return (time.perf_counter() - t0) / len(msgs), len(msgs)


def run_raw_loadtest(seconds=60.0, imu_rate=400.0, rate=1.0, folder=None, publish_rate_hz=0.0,
                     intake_period_s=DEFAULT_INTAKE_PERIOD_S):
    """The figures (module docstring) as a dict; ``publish_rate_hz`` and ``intake_period_s``:
    the identifier's settings (0: an estimate after every fused message; each message taken as
    it arrives)."""
    env = loopback_env()
    work = tempfile.mkdtemp(prefix='auv_ident_rawload_') if folder is None else str(folder)
    bag, map_path = write_raw_example(work, duration=seconds, seed=5, imu_rate=imu_rate)
    imap = load_input_map(str(map_path))
    v = load_vehicle('nps_auv2')
    records, _ = raw_bag_records(bag, imap, v)
    ref = identify_raw(Model(v, NAMES), FilterConfig(), records, raw_sensor_config(imap),
                       passes=1)
    played = sum(1 for _ in read_bag(bag, imap.topic_types))
    out = f'{work}/estimate.json'
    ident = subprocess.Popen(_cmd('identifier', f'input_map:={map_path}',
                                  f'coefficients:=[{",".join(NAMES)}]', f'save_path:={out}',
                                  f'publish_rate_hz:={float(publish_rate_hz)!r}',
                                  f'intake_period_s:={float(intake_period_s)!r}'),
                             env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                             text=True)
    try:
        topics = ','.join(e.bag_topic for e in imap.inputs)
        player = subprocess.Popen(_cmd('play', f'bag:={bag}', f'input_map:={map_path}',
                                       f'rate:={rate}', f'wait_for_subscribers:=[{topics}]',
                                       'wait_for_subscribers_s:=120.0',
                                       'wait_for_all_acked_s:=30.0'),
                                  env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                  text=True)
        # the identifier's start-up (imports, compile, discovery) is not the load: its CPU is
        # counted from the moment the player starts publishing (the subscriptions matched)
        cpu0, wall0 = None, None
        trace = []          # (monotonic s, identifier CPU s) while the player plays
        while player.poll() is None:
            if cpu0 is None and _cpu_s(player.pid) > 0 and _matched(player):
                cpu0, wall0 = _cpu_s(ident.pid), time.monotonic()
            if cpu0 is not None:
                trace.append((time.monotonic(), _cpu_s(ident.pid)))
            time.sleep(0.05)
        # the player exits once the identifier acknowledged every message (in its DDS queue);
        # a second of it working off the queue is in the CPU figure, the rest is drained at
        # the SIGINT (toolkit.drain) before the estimate file is written
        time.sleep(1.0)
        cpu1, wall1 = _cpu_s(ident.pid), time.monotonic()
        ident.send_signal(signal.SIGINT)
        _, err = ident.communicate(timeout=60.0)
        if ident.returncode != 0:
            raise RuntimeError(f'identifier exited {ident.returncode}: {err[-2000:]}')
    finally:
        for p in (ident,):
            if p.poll() is None:
                p.kill()
                p.communicate()
    with open(out, encoding='utf-8') as fh:
        doc = json.load(fh)
    expected = {k: n for k, n in ref.fused.items() if k != 'command'}
    per_msg, n_msgs = compute_per_message(bag, map_path)
    cpu = (cpu1 - cpu0) if cpu0 is not None else float('nan')
    steady = steady_cpu_per_message(trace, played / (seconds / rate))
    return {'seconds': seconds, 'imu_rate_hz': imu_rate, 'rate': rate, 'played': played,
            'publish_rate_hz': float(publish_rate_hz),
            'intake_period_s': float(intake_period_s),
            'fused': doc['fused'], 'expected_fused': expected, 'not_fused': doc['not_fused'],
            'every_message_processed': doc['fused'] == expected and not doc['not_fused'],
            'identifier_cpu_s': cpu, 'wall_s': (wall1 - wall0) if wall0 else float('nan'),
            'cpu_ms_per_message': 1e3 * cpu / played,
            'steady_cpu_ms_per_message': 1e3 * steady,
            'compute_ms_per_message': 1e3 * per_msg, 'compute_messages': n_msgs}


def steady_cpu_per_message(trace, messages_per_s, settle_s=STEADY_SETTLE_S):
    """The identifier's CPU (s) per message in the steady part of playback: from
    ``settle_s`` after the CPU window's start to the player's last second, over the messages
    the player published meanwhile at its steady rate ``messages_per_s`` (the bag's messages
    over its length, at the played rate); NaN when the run is too short. The whole window's
    figure also holds the identifier's share of the player's start (matching its endpoints)
    and of the last queue's work-off."""
    if not trace:
        return float('nan')
    t_start, t_end = trace[0][0] + settle_s, trace[-1][0] - 1.0
    inside = [(t, c) for t, c in trace if t_start <= t <= t_end]
    if len(inside) < 2 or inside[-1][0] - inside[0][0] < 5.0:
        return float('nan')
    (ta, ca), (tb, cb) = inside[0], inside[-1]
    return (cb - ca) / ((tb - ta) * messages_per_s)


def _matched(player):
    # the player publishes once every subscriber it waits for has matched; its CPU rising
    # above start-up is not observable from here, so the start is taken at its first second
    # of CPU time, which it spends in its imports and discovery before publishing
    return _cpu_s(player.pid) >= 1.0


def format_raw_loadtest(d):
    return '\n'.join([
        f'raw-sensor load: {d["seconds"]:g} s bag, IMU {d["imu_rate_hz"]:g} Hz + DVL 5 Hz + '
        f'pressure 10 Hz + commands, played at {d["rate"]:g}x: {d["played"]} messages; '
        + (f'estimates published at {d["publish_rate_hz"]:g} Hz' if d.get('publish_rate_hz')
           else 'an estimate per fused message') + '; ' + intake_text(d.get('intake_period_s')),
        f'fused {d["fused"]} (offline pass: {d["expected_fused"]}); not fused {d["not_fused"]};'
        f' every message processed: {d["every_message_processed"]}',
        f'identifier CPU {d["identifier_cpu_s"]:.2f} s over {d["wall_s"]:.1f} s wall: '
        f'{d["cpu_ms_per_message"]:.3f} ms per message; steady playback (from '
        f'{STEADY_SETTLE_S:g} s in to the last second) {d["steady_cpu_ms_per_message"]:.3f} ms '
        f'per message; the session alone {d["compute_ms_per_message"]:.3f} ms per message'])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=60.0)
    ap.add_argument('--imu-rate', type=float, default=400.0)
    ap.add_argument('--rate', type=float, default=1.0)
    ap.add_argument('--publish-rate', type=float, default=0.0, metavar='HZ',
                    help="the identifier's publish_rate_hz (default 0: after every message)")
    ap.add_argument('--intake-period', type=float, default=DEFAULT_INTAKE_PERIOD_S, metavar='S',
                    help="the identifier's intake_period_s (default "
                         f'{DEFAULT_INTAKE_PERIOD_S:g}; 0: each message as it arrives)')
    ap.add_argument('--json', default=None)
    a = ap.parse_args(argv)
    d = run_raw_loadtest(a.seconds, a.imu_rate, a.rate, publish_rate_hz=a.publish_rate,
                         intake_period_s=a.intake_period)
    print(format_raw_loadtest(d))
    if a.json:
        with open(a.json, 'w', encoding='utf-8') as fh:
            json.dump(d, fh, indent=1)
    return 0 if d['every_message_processed'] else 1


if __name__ == '__main__':
    sys.exit(main())
