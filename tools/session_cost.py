"""Per-message Python cost of the identifier's session layer, layer by layer.

    PYTHONPATH=. .venv/bin/python tools/session_cost.py [--samples N] [--rounds R]
        [--against REV] [--profile]

One simulated NPS AUV II run (20 Hz, 'ident' manoeuvre, the 5 default coefficients) is fed,
sample by sample (command, then odometry), through four layers, each one containing the one
before it:

1. filter step: ``AugmentedEKF.predict`` + ``update`` (the compiled kernels and their thin
   Python wrappers), the filter work one odometry message costs;
2. ``StreamIdentifier.add_measurement`` (core/filter/stream.py: pairing with the command, time
   rules, covariance check after the update);
3. ``IdentSession.add_odometry`` (arrays: screening, coefficient checks, divergence guard,
   health windows, last good estimate);
4. ``IdentSession.on_odom`` (a nav_msgs/Odometry message: 3 plus reading the message).

Each odometry call is timed alone (perf_counter around it); the command calls are timed the
same way (``add_command`` and ``on_actuators``). The layers take turns round after round and
each figure is the best round's mean (us per message), so a slow spell of the shared machine
hits all alike; the differences between consecutive layers are each layer's own share.

``--against REV`` also times ``on_odom`` / ``on_actuators`` of the session layer of git
revision REV (its ``auv_ident/session``, extracted into a temporary package, over this tree's
core) in the same rounds, and checks that both give the same events and estimates.
``--profile`` prints a cProfile of one on_odom pass.
"""
import argparse
import cProfile
import importlib
import os
import pstats
import subprocess
import sys
import tempfile
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

from auv_ident.analysis.bench import best_interleaved  # noqa: E402
from auv_ident.core.model.hydrodynamics import Model  # noqa: E402
from auv_ident.core.model.state import Input  # noqa: E402
from auv_ident.core.simulation.simulate import simulate  # noqa: E402
from auv_ident.ros.sim_messages import ACTUATOR_TOPIC, sample_messages  # noqa: E402
from auv_ident.session.messages import (  # noqa: E402
    joint_state_to_actuators,
    odometry_to_state,
    stamp_to_ns,
)
from auv_ident.session.session import IdentSession  # noqa: E402
from auv_ident.session.settings import IdentifierSettings  # noqa: E402
from auv_ident.vehicles import load_vehicle  # noqa: E402

T = 0.05


def build_inputs(n_samples, seed=1):
    """(run, messages, arrays): the run, its [(topic, msg)] and the same data decoded."""
    run = simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=n_samples * T + 1.0,
                   T=T, seed=seed)
    messages, arrays = [], []
    for k in range(n_samples):
        for topic, _, msg in sample_messages(run, k, with_truth=False):
            messages.append((topic, msg))
            stamp_ns = stamp_to_ns(msg.header.stamp)
            if topic == ACTUATOR_TOPIC:
                arrays.append(('cmd', stamp_ns, joint_state_to_actuators(msg)[1]))
            else:
                x12 = odometry_to_state(msg, 'ned')[1]
                arrays.append(('odom', stamp_ns, x12, msg.header.frame_id,
                               msg.child_frame_id))
    return run, messages, arrays


def session_of(rev):
    """IdentSession of git revision `rev`: its auv_ident/session as a temporary package."""
    blob = subprocess.run(['git', '-C', REPO, 'archive', rev, 'auv_ident/session'],
                          check=True, capture_output=True).stdout
    dest = tempfile.mkdtemp(prefix='session_cost_')
    subprocess.run(['tar', '-x', '-C', dest], input=blob, check=True)
    package = 'session_at_' + ''.join(c if c.isalnum() else '_' for c in rev)
    folder = os.path.join(dest, package)
    os.rename(os.path.join(dest, 'auv_ident', 'session'), folder)
    for name in os.listdir(folder):
        if name.endswith('.py'):
            path = os.path.join(folder, name)
            with open(path, encoding='utf-8') as fh:
                text = fh.read().replace('auv_ident.session.', package + '.')
            with open(path, 'w', encoding='utf-8') as fh:
                fh.write(text)
    sys.path.insert(0, dest)
    return importlib.import_module(package + '.session').IdentSession


def new_session(cls):
    """A session of class `cls` at sample time T: one that takes the settings value (its module
    has IdentifierSettings), or keywords (an older revision, --against)."""
    settings = getattr(sys.modules[cls.__module__], 'IdentifierSettings', None)
    return cls(settings.from_values(sample_time=T)) if settings else cls(sample_time=T)


class Pass:
    """One pass of a session over the data; `odom` and `cmd` are the mean call times (us)."""

    def __init__(self, session, calls):
        clock = time.perf_counter
        odom, cmd = [], []
        for is_odom, call, args in calls(session):
            t0 = clock()
            call(*args)
            (odom if is_odom else cmd).append(clock() - t0)
        assert session.odom_rejected == 0 and session.errors == 0, session.reasons
        self.session = session
        self.odom = 1e6 * sum(odom) / len(odom)
        self.cmd = 1e6 * sum(cmd) / len(cmd)


def message_calls(messages):
    def calls(s):
        for topic, msg in messages:
            if topic == ACTUATOR_TOPIC:
                yield False, s.on_actuators, (msg,)
            else:
                yield True, s.on_odom, (msg,)
    return calls


def array_calls(arrays):
    def calls(s):
        for item in arrays:
            if item[0] == 'cmd':
                yield False, s.add_command, item[1:]
            else:
                yield True, s.add_odometry, item[1:]
    return calls


def pass_stream(arrays):
    """Mean us of StreamIdentifier.add_measurement over the data (the session's stream)."""
    s = IdentSession(IdentifierSettings.from_values(sample_time=T))
    stream = s.stream
    clock = time.perf_counter
    times = []
    for item in arrays:
        t = item[1] / 1e9
        if item[0] == 'cmd':
            stream.add_command(t, item[2])
        else:
            y = np.where(s.measured, item[2], np.nan)
            t0 = clock()
            out = stream.add_measurement(t, y)
            times.append(clock() - t0)
            assert out.accepted, out.reason
    return 1e6 * sum(times) / len(times)


def pass_filter(run, n_samples):
    """Mean us of AugmentedEKF.predict + update over the same samples."""
    ekf = IdentSession(IdentifierSettings.from_values(sample_time=T)).stream.ekf
    ekf.start(run.y[0], run.u[0][Input.N_RPM])
    clock = time.perf_counter
    times = []
    for k in range(1, n_samples):
        t0 = clock()
        ekf.predict(run.u[k - 1], T)
        ekf.update(run.y[k])
        times.append(clock() - t0)
    return 1e6 * sum(times) / len(times)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--samples', type=int, default=2000, help='odometry messages per pass')
    ap.add_argument('--rounds', type=int, default=7, help='rounds (best one counts)')
    ap.add_argument('--against', metavar='REV', help='also time the session layer of REV')
    ap.add_argument('--profile', action='store_true', help='cProfile one on_odom pass')
    args = ap.parse_args(argv)
    run, messages, arrays = build_inputs(args.samples)
    # numba load before timing
    IdentSession(IdentifierSettings.from_values(sample_time=T)).warm_up()
    sessions = {'on_odom': (IdentSession, message_calls(messages)),
                'add_odometry': (IdentSession, array_calls(arrays))}
    if args.against:
        sessions[f'on_odom {args.against}'] = (session_of(args.against),
                                               message_calls(messages))
    best, last = {}, {}

    def measure(name):
        cls, calls = sessions[name]
        p = Pass(new_session(cls), calls)
        last[name] = p
        best[name + ' cmd'] = min(best.get(name + ' cmd', np.inf), p.cmd)
        return 1.0 / p.odom                     # best_interleaved keeps the largest
    measures = {'filter': lambda: 1.0 / pass_filter(run, args.samples),
                'stream': lambda: 1.0 / pass_stream(arrays)}
    measures.update({name: (lambda name=name: measure(name)) for name in sessions})
    for m in measures.values():
        m()                                     # first pass: caches, numba, imports
    best.update({k: 1.0 / v for k, v in best_interleaved(measures, args.rounds).items()})

    print(f'us per message, best of {args.rounds} rounds of {args.samples} samples '
          '(nps_auv2 ident 20 Hz, 5 coefficients):')
    rows = [('filter step (AugmentedEKF.predict + update)', best['filter'], ''),
            ('StreamIdentifier.add_measurement', best['stream'],
             f'stream share {best["stream"] - best["filter"]:6.1f}'),
            ('IdentSession.add_odometry', best['add_odometry'],
             f'session share {best["add_odometry"] - best["stream"]:6.1f}'),
            ('IdentSession.on_odom', best['on_odom'],
             f'reading share {best["on_odom"] - best["add_odometry"]:6.1f}'),
            ('  on_odom minus the filter step', best['on_odom'] - best['filter'], ''),
            ('IdentSession.add_command', best['add_odometry cmd'], ''),
            ('IdentSession.on_actuators', best['on_odom cmd'], '')]
    if args.against:
        name = f'on_odom {args.against}'
        rows += [(f'{args.against}: IdentSession.on_odom', best[name], ''),
                 ('  on_odom minus the filter step', best[name] - best['filter'], ''),
                 (f'{args.against}: IdentSession.on_actuators', best[name + ' cmd'], '')]
        a, b = last['on_odom'].session, last[name].session
        same = (a.reasons == b.reasons and a.odom_accepted == b.odom_accepted
                and np.array_equal(a.last_good.estimate, b.last_good.estimate)
                and np.array_equal(a.last_good.cov, b.last_good.cov))
        rows.append((f'same events and estimate as {args.against}', None, str(same)))
    for label, value, note in rows:
        print(f'  {label:46s} {"" if value is None else f"{value:7.1f}":>7s}   {note}')
    if args.profile:
        prof = cProfile.Profile()
        prof.runcall(Pass, IdentSession(IdentifierSettings.from_values(sample_time=T)),
                     message_calls(messages))
        pstats.Stats(prof).sort_stats('tottime').print_stats(25)
    return 0


if __name__ == '__main__':
    sys.exit(main())
