"""Load test of the identifier node: ``python -m auv_ident loadtest`` (wired by auv_ident/cli).

A real identifier process (``python -m auv_ident run identifier``, sample_time = 1/rate_hz)
gets odometry and actuator commands of a simulated run (NPS AUV II, 'ident' manoeuvre) at
rate_hz in simulation time, published from this process at real_time_factor x real time.

Figures:

- counts: odometry and commands published; odometry accepted and rejected, commands taken,
  as the identifier reports them on /diagnostics (and the steps in its estimate file, written
  on SIGINT at the end); every message must be processed (accepted + rejected = published);
- latency per message, end to end: from just before ``publish(odom)`` here to the arrival
  here of the ``~/estimate`` with that odometry's stamp (DDS to the identifier, its callback,
  DDS back, our executor to our callback), p50 / p99 / max over the estimates received
  (~/estimate is KEEP_LAST depth 1, so a few can be overwritten before they are read; the
  count is reported). The estimates are received on rclpy's EventsExecutor, as the
  identifier runs. With ``--split`` they are received with their MessageInfo instead (on the
  SingleThreadedExecutor: Jazzy's EventsExecutor cannot pass it), and the same path is split
  at the estimate's DDS timestamps (system clock): publish(odom) -> the identifier publishes
  the estimate (source timestamp), -> DDS delivers it here (received timestamp), -> our
  callback runs. The slower receiver adds to the end-to-end figure of such a run;
- compute per message: the identifier's per-odometry work alone (IdentSession.on_odom, no
  ROS), timed in this process over the first compute_samples samples;
- memory: resident set size (VmRSS of /proc/<pid>/status) of the identifier process, sampled
  every 0.25 s: at the first estimate (after start-up and warm-up), once 10 % of the samples
  are out ("start", steady state), at the end, and the maximum; growth = end - start.

Publishing: every message is serialized before the clock starts, so the timed loop only
publishes bytes (building messages would delay publishes and compete with our receiver for
the GIL); the actuator command of sample k goes out just before its odometry.

Pacing: sample k is published at k / (rate_hz * real_time_factor) s of wall time (0: as fast
as possible), but never more than max_backlog samples ahead of the last estimate received,
so a slower machine is measured slower, not with lost messages (the identifier's queues hold
1000 messages).

DDS stays on this machine: the identifier and this process run with
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a ROS_DOMAIN_ID in 1..101 (this process's if it
is in that range, else a random one).
"""
import json
import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

from auv_ident.session.settings import DEFAULT_INTAKE_PERIOD_S

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RSS_PERIOD_S = 0.25
ESTIMATE_TOPIC = '/identifier/estimate'
PART_LABELS = {'to_estimate_publish': 'publish(odom) -> identifier publishes the estimate',
               'estimate_transfer': 'DDS back', 'receiver': 'our executor to the callback'}


def loopback_env(env=None):
    """The environment for every process of the load test: loopback DDS, domain 1..101.

    Also applied to os.environ, because the publisher node runs in this process."""
    env = dict(os.environ if env is None else env)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env.pop('ROS_LOCALHOST_ONLY', None)
    try:
        dom = int(env.get('ROS_DOMAIN_ID', ''))
    except ValueError:
        dom = -1
    if not 1 <= dom <= 101:
        env['ROS_DOMAIN_ID'] = str(random.SystemRandom().randint(1, 101))
    for key in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID'):
        os.environ[key] = env[key]
    os.environ.pop('ROS_LOCALHOST_ONLY', None)
    return env


def _rss_kb(pid):
    try:
        with open(f'/proc/{pid}/status', encoding='ascii') as fh:
            for line in fh:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        return None
    return None


def _cpu_s(pid=None):
    """CPU time (user + system, s) of process ``pid`` (None: this one), all threads."""
    if pid is None:
        t = os.times()
        return t.user + t.system
    try:
        with open(f'/proc/{pid}/stat', encoding='ascii') as fh:
            fields = fh.read().rsplit(')', 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
    except (OSError, ValueError, IndexError):
        return math.nan


def _percentiles(values_ms):
    a = np.asarray(values_ms, dtype=float)
    if a.size == 0:
        return {'n': 0, 'p50': math.nan, 'p99': math.nan, 'max': math.nan, 'mean': math.nan}
    return {'n': int(a.size), 'p50': float(np.percentile(a, 50)),
            'p99': float(np.percentile(a, 99)), 'max': float(a.max()), 'mean': float(a.mean())}


def compute_latency(run, n_samples):
    """Per-odometry compute time of IdentSession.on_odom (ms), without ROS."""
    from auv_ident.ros.sim_messages import sample_messages
    from auv_ident.session.session import IdentSession
    from auv_ident.session.settings import IdentifierSettings
    s = IdentSession(IdentifierSettings.from_values(sample_time=float(run.T)))
    s.warm_up()
    out = []
    for k in range(min(n_samples, len(run.t))):
        for topic, _, msg in sample_messages(run, k, with_truth=False):
            if topic == '/actuators':
                s.on_actuators(msg)
            else:
                t0 = time.perf_counter()
                s.on_odom(msg)
                out.append((time.perf_counter() - t0) * 1e3)
    return _percentiles(out)


class _Receiver:
    """The load test's side of the estimates and /diagnostics: per sample k, when its estimate
    arrived (perf_counter and system clock) and its DDS timestamps; the last diagnostics."""

    def __init__(self, n, T_ns, every_sample=True):
        self.n, self.T_ns = n, T_ns
        # False with the identifier's publish_rate_hz: the last sample may not be published
        self.every_sample = every_sample
        self.recv_t = np.full(n, np.nan)
        self.cb_wall = np.zeros(n, dtype=np.int64)
        self.est_source = np.zeros(n, dtype=np.int64)
        self.est_received = np.zeros(n, dtype=np.int64)
        self.last_k = -1
        self.estimates = 0
        self.bad_estimates = 0
        self.diag = None

    def on_estimate(self, msg, info=None):
        now = time.perf_counter()
        now_wall = time.time_ns()
        s_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        k = int(round(s_ns / self.T_ns))
        self.estimates += 1
        # math on the array.array values: no numpy conversion per estimate in the receiver
        if not (all(map(math.isfinite, msg.position)) and all(map(math.isfinite, msg.velocity))):
            self.bad_estimates += 1
        if 0 <= k < self.n and math.isnan(self.recv_t[k]):
            self.recv_t[k] = now
            self.cb_wall[k] = now_wall
            if info is not None:
                self.est_source[k] = info['source_timestamp']
                self.est_received[k] = info['received_timestamp']
            self.last_k = max(self.last_k, k)

    def on_diag(self, msg):
        for st in msg.status:
            if st.name == 'auv_ident identifier':
                self.diag = {v.key: v.value for v in st.values}

    def all_counted(self):
        """The last estimate is in, and a /diagnostics report counts every message."""
        d = self.diag
        return (d is not None and int(d['accepted']) + int(d['rejected'])
                + int(d.get('odom_lost', 0)) >= self.n
                and (self.last_k >= self.n - 1 or not self.every_sample))


class _RssSampler:
    """The identifier's resident memory, sampled every RSS_PERIOD_S in a thread."""

    def __init__(self, pid, stop):
        self.samples = []               # (perf_counter, kB)
        self._pid, self._stop = pid, stop
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self._stop.is_set():
            kb = _rss_kb(self._pid)
            if kb is not None:
                self.samples.append((time.perf_counter(), kb))
            self._stop.wait(RSS_PERIOD_S)

    def at(self, t):
        """The last sample at or before t (MB), NaN if none."""
        before = [kb for tt, kb in self.samples if t is not None and tt <= t]
        return before[-1] / 1024.0 if before else math.nan

    def figures(self, t_first_est, t_steady, t_end):
        rss_mb = np.array([kb for _, kb in self.samples], dtype=float) / 1024.0
        steady = self.at(t_steady)
        end = self.at(t_end)
        after_steady = [kb / 1024.0 for tt, kb in self.samples
                        if t_steady is not None and tt >= t_steady]
        return {'first_estimate': self.at(t_first_est), 'start': steady, 'end': end,
                'max': float(rss_mb.max()) if rss_mb.size else math.nan,
                'growth': end - steady,
                'max_growth': (max(after_steady) - steady) if after_steady else math.nan,
                'samples': int(rss_mb.size)}


class _Pacing:
    """What the paced publishing loop measured (perf_counter instants, s)."""

    def __init__(self):
        self.t_start = self.t_end = None
        self.t_first_est = None
        self.t_steady = None                # RSS from here on is the steady state
        self.waits = 0                      # waits for the identifier's backlog to shrink
        self.cpu_start = None


def _wait_for_identifier(node, pubs, proc, err_path, timeout):
    """Return once the identifier subscribed to both topics, matched (0.5 s for its side of
    the match) and publishes estimates; RuntimeError if it dies or times out."""
    from auv_ident.ros.toolkit import SubscriberWait
    wait = SubscriberWait(node, pubs, nodes=['identifier'],
                          topics=[p.topic_name for p in pubs], timeout=timeout, settle=0.5)
    while True:
        ready = wait.poll()
        if ready and node.count_publishers(ESTIMATE_TOPIC):
            return
        if proc.poll() is not None or ready is False:
            raise RuntimeError('identifier did not start: ' + _tail(err_path))
        time.sleep(0.02)


def _publish_paced(payloads, pubs, period, receiver, proc, err_path, max_backlog, progress,
                   pub_t, pub_wall):
    """Publish sample k's (actuators, odometry) bytes at t_start + k period, waiting while
    the identifier is more than max_backlog samples behind; returns the _Pacing."""
    pub_act, pub_odom = pubs
    n = len(payloads)
    pace = _Pacing()
    pace.t_start = time.perf_counter()
    pace.cpu_start = (_cpu_s(proc.pid), _cpu_s())
    k_steady = max(1, n // 10)
    for k in range(n):
        due = pace.t_start + k * period
        while True:
            now = time.perf_counter()
            if k - receiver.last_k > max_backlog:
                pace.waits += 1
                time.sleep(0.0005)
                if proc.poll() is not None:
                    raise RuntimeError('identifier died: ' + _tail(err_path))
                continue
            if now < due:
                time.sleep(min(due - now, 0.002))
                continue
            break
        act, odom = payloads[k]
        pub_act.publish(act)
        pub_t[k] = time.perf_counter()
        pub_wall[k] = time.time_ns()
        pub_odom.publish(odom)
        if pace.t_first_est is None and receiver.last_k >= 0:
            pace.t_first_est = time.perf_counter()
        if k == k_steady:
            pace.t_steady = time.perf_counter()
        if progress is not None and k % 2000 == 0:
            progress(k, n)
    pace.t_end = time.perf_counter()
    return pace


def _stop_identifier(proc):
    """SIGINT, as Ctrl-C; killed after 20 s. Returns its exit code."""
    proc.send_signal(signal.SIGINT)
    try:
        return proc.wait(timeout=20.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait()


def _read_json(path):
    try:
        with open(path, encoding='utf-8') as fh:
            return json.load(fh)
    except (OSError, ValueError):
        return None


def run_loadtest(rate_hz=200.0, sim_seconds=300.0, real_time_factor=1.0, vehicle='nps_auv2',
                 seed=0, max_backlog=600, compute_samples=5000, env=None, log_dir=None,
                 start_timeout=90.0, drain_timeout=60.0, progress=None, split=False,
                 samples_path=None, publish_rate_hz=0.0, intake_period_s=DEFAULT_INTAKE_PERIOD_S):
    """Run the load test (module docstring); returns a dict of figures (format_loadtest).

    ``split``: receive the estimates with their MessageInfo, to split the latency at the DDS
    timestamps (module docstring). ``samples_path``: write the per-message times there (.npz).
    ``publish_rate_hz``: the identifier's setting (0: an estimate per odometry, the latency
    mode; > 0: the latency is that of the estimates published). ``intake_period_s``: the
    identifier's setting (ros/intake.py; 0: each message as it arrives, the lowest latency).
    Raises RuntimeError if the identifier does not start or dies."""
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Odometry
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.experimental import EventsExecutor
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from auv_ident.core.model.hydrodynamics import Model
    from auv_ident.core.simulation.simulate import simulate
    from auv_ident.ros.sim_messages import sample_messages
    from auv_ident.ros.toolkit import STREAM_QOS
    from auv_ident.vehicles import load_vehicle

    if not (rate_hz > 0 and sim_seconds > 0 and real_time_factor >= 0):
        raise ValueError('rate_hz and sim_seconds must be > 0, real_time_factor >= 0')
    env = loopback_env(env)
    T = 1.0 / float(rate_hz)
    t_sim = time.perf_counter()
    run = simulate(Model(load_vehicle(vehicle)), 'ident', duration=float(sim_seconds), T=T,
                   seed=seed)
    sim_s = time.perf_counter() - t_sim
    n = len(run.t)
    compute = compute_latency(run, compute_samples) if compute_samples else None

    log_dir = tempfile.mkdtemp(prefix='auv_ident_loadtest_') if log_dir is None else str(log_dir)
    save = os.path.join(log_dir, 'estimate.json')
    err_path = os.path.join(log_dir, 'identifier.err')
    out = open(os.path.join(log_dir, 'identifier.out'), 'w')
    err = open(err_path, 'w')
    proc = subprocess.Popen(
        [sys.executable, '-m', 'auv_ident', 'run', 'identifier', '--ros-args',
         '-p', f'vehicle:={vehicle}', '-p', f'sample_time:={T!r}', '-p', f'save_path:={save}',
         '-p', f'publish_rate_hz:={float(publish_rate_hz)!r}',
         '-p', f'intake_period_s:={float(intake_period_s)!r}'],
        env=env, cwd=REPO, stdout=out, stderr=err)

    # Every message serialized before the clock starts: the timed loop only publishes bytes,
    # so building messages neither delays a publish nor competes with our receiver.
    payloads = [tuple(serialize_message(m) for tp, _, m in
                      sorted(sample_messages(run, k, with_truth=False),
                             key=lambda item: item[0] != '/actuators'))
                for k in range(n)]
    pub_t = np.full(n, np.nan)
    # the same path on the system clock, split at the DDS timestamps of the estimate
    pub_wall = np.zeros(n, dtype=np.int64)
    receiver = _Receiver(n, int(round(T * 1e9)), every_sample=not publish_rate_hz)
    stop = threading.Event()

    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node('auv_ident_loadtest', context=ctx)
    if split:
        # the SingleThreadedExecutor: Jazzy's EventsExecutor cannot pass the MessageInfo
        node.create_subscription(JointState, ESTIMATE_TOPIC,
                                 lambda msg, info: receiver.on_estimate(msg, info), STREAM_QOS)
        ex = SingleThreadedExecutor(context=ctx)
    else:
        node.create_subscription(JointState, ESTIMATE_TOPIC, receiver.on_estimate, STREAM_QOS)
        ex = EventsExecutor(context=ctx)
    node.create_subscription(DiagnosticArray, '/diagnostics', receiver.on_diag, 100)
    pubs = (node.create_publisher(JointState, '/actuators', STREAM_QOS),
            node.create_publisher(Odometry, '/odom', STREAM_QOS))
    ex.add_node(node)
    spin_thread = threading.Thread(target=lambda: _spin(ex, stop), daemon=True)
    spin_thread.start()
    rss = _RssSampler(proc.pid, stop)

    result = {}
    try:
        _wait_for_identifier(node, pubs, proc, err_path, start_timeout)
        period = 0.0 if real_time_factor == 0 else T / real_time_factor
        pace = _publish_paced(payloads, pubs, period, receiver, proc, err_path, max_backlog,
                              progress, pub_t, pub_wall)
        # drain: the last estimate, then a /diagnostics report counting every message
        deadline = time.monotonic() + drain_timeout
        while (time.monotonic() < deadline and not receiver.all_counted()
               and proc.poll() is None):
            time.sleep(0.05)
        t_drained = time.perf_counter()
        cpu_end = (_cpu_s(proc.pid), _cpu_s())
        time.sleep(2 * RSS_PERIOD_S)
        rss_end_t = time.perf_counter()
        rc = _stop_identifier(proc)
        d = receiver.diag or {}
        lat = (receiver.recv_t - pub_t) * 1e3
        got = np.isfinite(lat)
        lat = lat[got]
        parts = {}
        if split:
            parts = {'to_estimate_publish': (receiver.est_source - pub_wall)[got] * 1e-6,
                     'estimate_transfer':
                         (receiver.est_received - receiver.est_source)[got] * 1e-6,
                     'receiver': (receiver.cb_wall - receiver.est_received)[got] * 1e-6}
        if samples_path:
            np.savez(samples_path, pub_t=pub_t, recv_t=receiver.recv_t, pub_wall=pub_wall,
                     est_source=receiver.est_source, est_received=receiver.est_received,
                     cb_wall=receiver.cb_wall)
        saved = _read_json(save)
        result = {
            'vehicle': vehicle, 'rate_hz': float(rate_hz), 'sim_seconds': float(run.t[-1]),
            'publish_rate_hz': float(publish_rate_hz),
            'intake_period_s': float(intake_period_s),
            'samples': n, 'real_time_factor': float(real_time_factor),
            'achieved_real_time_factor':
                float(run.t[-1] / max(pace.t_end - pace.t_start, 1e-9)),
            'wall_publish_s': float(pace.t_end - pace.t_start),
            'wall_drain_s': float(t_drained - pace.t_end), 'simulate_s': sim_s,
            'published_odom': n, 'published_actuators': n,
            'accepted': int(d.get('accepted', -1)), 'rejected': int(d.get('rejected', -1)),
            'commands': int(d.get('commands', -1)),
            'commands_rejected': int(d.get('commands_rejected', -1)),
            'odom_lost': int(d.get('odom_lost', -1)),
            'filter_resets': int(d.get('errors', -1)),
            'internal_errors': int(d.get('internal_errors', -1)),
            'estimates_received': int(receiver.estimates),
            'non_finite_estimates': int(receiver.bad_estimates),
            'latency_ms': _percentiles(lat),
            'latency_parts_ms': {k: _percentiles(v) for k, v in parts.items()},
            'compute_ms': compute,
            # CPU per sample while publishing and draining: a figure the other processes on
            # the machine hardly disturb, unlike the latency tail
            'cpu_us_per_sample': {'identifier': (cpu_end[0] - pace.cpu_start[0]) / n * 1e6,
                                  'loadtest': (cpu_end[1] - pace.cpu_start[1]) / n * 1e6},
            'rss_mb': rss.figures(pace.t_first_est, pace.t_steady, rss_end_t),
            'backlog_waits': pace.waits, 'max_backlog': max_backlog,
            'identifier_exit_code': rc,
            'saved_steps': None if saved is None else int(saved['steps']),
            'log_dir': log_dir,
        }
    finally:
        stop.set()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        out.close()
        err.close()
        spin_thread.join(timeout=5.0)
        rss.thread.join(timeout=5.0)
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
        fastdds = os.path.join(os.path.dirname(sys.executable), 'fastdds')
        if os.path.exists(fastdds):
            subprocess.run([fastdds, 'shm', 'clean'], capture_output=True, check=False,
                           env=env)
    result['all_processed'] = (result['accepted'] + result['rejected'] == n
                               and result['commands'] + result['commands_rejected'] == n)
    return result


def _spin(ex, stop):
    while not stop.is_set():
        try:
            ex.spin_once(timeout_sec=0.05)
        except Exception:           # noqa: BLE001 - context shut down at the end
            if stop.is_set():
                return
            raise


def _tail(path, n=5):
    try:
        with open(path, encoding='utf-8', errors='replace') as fh:
            return ' | '.join(fh.read().strip().splitlines()[-n:])
    except OSError:
        return '(no log)'


def intake_text(period_s):
    """How the identifier took its inputs (setting intake_period_s), for a report line."""
    if period_s is None:
        return 'inputs taken as configured'
    if period_s == 0:
        return 'inputs taken as they arrive'
    return f'inputs taken in batches every {1e3 * period_s:g} ms'


def format_loadtest(d):
    """A printable report of run_loadtest's dict."""
    lat, rss = d['latency_ms'], d['rss_mb']
    lines = [
        f"load test: {d['vehicle']}, {d['samples']} samples = {d['sim_seconds']:.0f} s of "
        f"simulated time at {d['rate_hz']:g} Hz (odometry + actuator command per sample); "
        + (f"estimates published at {d['publish_rate_hz']:g} Hz" if d.get('publish_rate_hz')
           else 'an estimate per odometry') + '; ' + intake_text(d.get('intake_period_s')),
        f"pacing: target {d['real_time_factor']:g}x real time, achieved "
        f"{d['achieved_real_time_factor']:.2f}x ({d['wall_publish_s']:.1f} s publishing, "
        f"{d['wall_drain_s']:.1f} s draining; {d['backlog_waits']} backlog waits at "
        f"{d['max_backlog']} samples)",
        f"processed: odometry {d['accepted']} accepted + {d['rejected']} rejected of "
        f"{d['published_odom']} published; commands {d['commands']} + "
        f"{d['commands_rejected']} rejected of {d['published_actuators']}; "
        + ('EVERY MESSAGE PROCESSED' if d['all_processed'] else
           f"MESSAGES MISSING: {d['published_odom'] - d['accepted'] - d['rejected']} odometry, "
           f"of which the identifier counted {d.get('odom_lost', -1)} lost (odom_lost)")
        + f"; filter resets {d['filter_resets']}, internal errors {d['internal_errors']}",
        f"estimates received: {d['estimates_received']} (non-finite: "
        f"{d['non_finite_estimates']}); estimate file steps: {d['saved_steps']}",
        f"latency publish(odom) -> estimate received, ms: p50 {lat['p50']:.3f}, p99 "
        f"{lat['p99']:.3f}, max {lat['max']:.3f} (n = {lat['n']})",
    ]
    parts = d.get('latency_parts_ms')
    if parts:
        lines.append('  split at the DDS timestamps of the estimate (system clock), ms p50/p99: '
                     + '; '.join(f"{PART_LABELS[k]} {v['p50']:.3f}/{v['p99']:.3f}"
                                 for k, v in parts.items()))
    c = d.get('compute_ms')
    if c:
        lines.append(f"compute per odometry message (IdentSession.on_odom, no ROS), ms: p50 "
                     f"{c['p50']:.3f}, p99 {c['p99']:.3f}, max {c['max']:.3f} "
                     f"(n = {c['n']})")
    cpu = d.get('cpu_us_per_sample')
    if cpu:
        lines.append(f"CPU per sample (odometry + command, all threads), us: identifier "
                     f"{cpu['identifier']:.0f}, this process (publisher + receiver) "
                     f"{cpu['loadtest']:.0f}")
    lines.append(f"identifier RSS, MB: {rss['first_estimate']:.1f} at the first estimate, "
                 f"{rss['start']:.1f} at 10 % of the samples, {rss['end']:.1f} at the end, "
                 f"max {rss['max']:.1f}; growth {rss['growth']:+.2f} MB (max "
                 f"{rss['max_growth']:+.2f}) over {rss['samples']} samples")
    lines.append(f"identifier exit code {d['identifier_exit_code']}; logs in {d['log_dir']}")
    return '\n'.join(lines)


def main(argv=None):
    """``python -m auv_ident.ros.loadtest [--rate HZ] [--seconds S] [--rtf X] [--json OUT]``."""
    import argparse
    ap = argparse.ArgumentParser(prog='python -m auv_ident loadtest',
                                 description=__doc__.split('\n')[0])
    ap.add_argument('--rate', type=float, default=200.0, help='Hz (default 200)')
    ap.add_argument('--seconds', type=float, default=300.0, help='simulated s (default 300)')
    ap.add_argument('--rtf', type=float, default=1.0,
                    help='real-time factor of the publisher (default 1; 0 = as fast as the '
                         'identifier keeps up)')
    ap.add_argument('--vehicle', default='nps_auv2')
    ap.add_argument('--max-backlog', type=int, default=600,
                    help='samples the identifier may fall behind before the publisher waits '
                         '(default 600; larger than the run: never wait, the subscription '
                         'queue overflows when the identifier cannot keep up)')
    ap.add_argument('--json', help='write the figures as JSON')
    ap.add_argument('--split', action='store_true',
                    help='also split the latency at the DDS timestamps of the estimate (receives '
                         'on the SingleThreadedExecutor, which adds to the end-to-end figure)')
    ap.add_argument('--samples', help='write the per-message times as .npz (profiling)')
    ap.add_argument('--publish-rate', type=float, default=0.0, metavar='HZ',
                    help="the identifier's publish_rate_hz (default 0: an estimate per "
                         'odometry, the latency mode; > 0: the latency of the estimates '
                         'published)')
    ap.add_argument('--intake-period', type=float, default=DEFAULT_INTAKE_PERIOD_S,
                    metavar='S', help="the identifier's intake_period_s (default "
                                      f'{DEFAULT_INTAKE_PERIOD_S:g}; 0: each message as it '
                                      'arrives, the lowest latency)')
    args = ap.parse_args(argv)
    d = run_loadtest(rate_hz=args.rate, sim_seconds=args.seconds,
                     real_time_factor=args.rtf, vehicle=args.vehicle, split=args.split,
                     samples_path=args.samples, max_backlog=args.max_backlog,
                     publish_rate_hz=args.publish_rate, intake_period_s=args.intake_period)
    print(format_loadtest(d))
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as fh:
            json.dump(d, fh, indent=1, default=float)
    return 0 if d['all_processed'] else 1


if __name__ == '__main__':
    sys.exit(main())
