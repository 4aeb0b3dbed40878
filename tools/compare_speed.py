"""Compare the EKF speed of two revisions of auv_ident's core, side by side in one process.

    .venv/bin/python tools/compare_speed.py OLD_REV [NEW_REV] [--steps N] [--rounds R]

NEW_REV defaults to the working tree. Each revision's `auv_ident/core` is extracted with
`git archive` into a temporary folder as its own package, both run the same simulated NPS AUV II
data (5 coefficients, 20 Hz), and the two take turns round after round; the figure of each is
its best round (us per step). On a shared VM a slow spell then hits both alike, which separate
runs of `python -m auv_ident bench` cannot promise: use this to decide whether a change is faster,
and the bench for the absolute figures. Printed: the RK4 step with its exact Jacobian (the model
part), the full EKF pass (predict + update), and the filter statistics of both runs (equal when
the change keeps the numbers). The per-message API (AugmentedEKF.step) is not raced here: with
two copies of the core in one process, the calls of whichever copy is typed second take numba's
Python type inference for their namedtuple arguments (Workspace) at every call (0.5 ms a step
instead of 18 us, measured with cProfile), an artefact of the two copies; compare it with runs
of the bench.
"""
import argparse
import importlib
import os
import subprocess
import sys
import tempfile
import time

from numba import njit
import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NAMES = ['Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v']


def extract_core(rev, dest, package):
    """auv_ident/core of `rev` as the package `package` in `dest` (config/ beside it)."""
    blob = subprocess.run(['git', '-C', REPO, 'archive', rev, 'auv_ident/core'],
                          check=True, capture_output=True).stdout
    subprocess.run(['tar', '-x', '-C', dest], input=blob, check=True)
    os.rename(os.path.join(dest, 'auv_ident', 'core'), os.path.join(dest, package))
    os.rmdir(os.path.join(dest, 'auv_ident'))


def _load_nps(package):
    """NPS AUV II from the revision's own vehicle module (load_vehicle before the layers split
    it out, vehicle_from_file after)."""
    veh = importlib.import_module(package + '.vehicle')
    if hasattr(veh, 'load_vehicle'):
        return veh.load_vehicle('nps_auv2')
    return veh.vehicle_from_file(os.path.join(REPO, 'config', 'nps_auv2.yaml'))


def runners(package, run, n_steps):
    """(model, full): callables that time n_steps of the model part and of the EKF pass.

    Two generations of the core's API are known: the flat kernel arguments and
    identify.run_ekf(f, Y, U) (up to 6c738cc), and the CompiledModel bundle with
    batch.run_ekf(f, t, Y, U) (after)."""
    ekf = importlib.import_module(package + '.ekf')
    mod = importlib.import_module(package + '.model')
    try:
        batch = importlib.import_module(package + '.batch')
        filt = importlib.import_module(package + '.filter')
    except ImportError:
        batch = filt = importlib.import_module(package + '.identify')
    m = mod.Model(_load_nps(package), NAMES)
    cfg = filt.FilterConfig(coefficients=NAMES, initial_offset=0.5)
    t, Y, U, X = run.t[:n_steps], run.y[:n_steps], run.u[:n_steps], run.x[:n_steps]
    step, new_ws = ekf.rk4_step_into, ekf.new_workspace
    n = 12 + len(NAMES)
    xa = np.concatenate([X[0], m.theta_file])
    x1, Fa = np.empty(n), np.empty((n, n))
    if hasattr(m, 'compiled'):
        @njit
        def model_loop(X, U, xa, x1, Fa, cm, T):
            ws = new_ws(xa.shape[0], cm.c0.shape[0])
            for k in range(X.shape[0]):
                xa[:12] = X[k]
                step(xa, U[k], cm, T, True, x1, Fa, ws)
            return x1
        margs = (m.compiled, run.T)

        def full():
            return batch.run_ekf(filt.AugmentedEKF(m, cfg, run.T), t, Y, U)[0]
    else:
        @njit
        def model_loop(X, U, xa, x1, Fa, c0, theta_idx, *margs):
            ws = new_ws(xa.shape[0], c0.shape[0])
            for k in range(X.shape[0]):
                xa[:12] = X[k]
                step(xa, U[k], c0, theta_idx, *margs, True, x1, Fa, ws)
            return x1
        margs = (m.c, m.theta_idx, *m.args[:-1], run.T)

        def full():
            return batch.run_ekf(filt.AugmentedEKF(m, cfg, run.T), Y, U)[0]

    def model():
        model_loop(X, U, xa, x1, Fa, *margs)
    return model, full


def race(candidates, n_steps, rounds):
    """Best round of each candidate (us per step), the candidates taking turns."""
    from auv_ident.analysis.bench import best_interleaved
    for f in candidates.values():
        f()                                    # compile / load before timing

    def rate(f):
        t0 = time.perf_counter()
        f()
        return n_steps / (time.perf_counter() - t0)
    best = best_interleaved({k: (lambda f=f: rate(f)) for k, f in candidates.items()}, rounds)
    return {k: 1e6 / v for k, v in best.items()}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('old', help='git revision to compare against (e.g. HEAD~1)')
    ap.add_argument('new', nargs='?', default=None, help='git revision (default: working tree)')
    ap.add_argument('--steps', type=int, default=1000, help='EKF steps per round (default 1000)')
    ap.add_argument('--rounds', type=int, default=100, help='rounds (default 100)')
    a = ap.parse_args(argv)
    tmp = tempfile.mkdtemp(prefix='auv_ident_speed_')
    os.symlink(os.path.join(REPO, 'config'), os.path.join(tmp, 'config'))
    pkgs = os.path.join(tmp, 'pkgs')      # <tmp>/pkgs/<package>/vehicle.py finds <tmp>/config
    os.makedirs(pkgs)
    extract_core(a.old, pkgs, 'core_old')
    if a.new is None:
        sys.path.insert(0, REPO)
        new_pkg = 'auv_ident.core'
    else:
        extract_core(a.new, pkgs, 'core_new')
        new_pkg = 'core_new'
    sys.path.insert(0, pkgs)
    from auv_ident.core.model.hydrodynamics import Model
    from auv_ident.core.simulation.simulate import simulate
    from auv_ident.vehicles import load_vehicle
    run = simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=a.steps / 20.0 + 1.0,
                   seed=1)
    old_model, old_full = runners('core_old', run, a.steps)
    new_model, new_full = runners(new_pkg, run, a.steps)
    label = a.new or 'working tree'
    print(f'old = {a.old}, new = {label}; NPS AUV II, 5 coefficients, {a.steps} steps, '
          f'best of {a.rounds} interleaved rounds (us per step)')
    for what, pair in (('RK4 step + Jacobian', (old_model, new_model)),
                       ('EKF pass (predict + update)', (old_full, new_full))):
        r = race({'old': pair[0], 'new': pair[1]}, a.steps, a.rounds)
        print(f'  {what:<28} old {r["old"]:7.3f}   new {r["new"]:7.3f}   '
              f'({(r["new"] / r["old"] - 1) * 100:+.1f} %)')
    so, sn = old_full(), new_full()
    rel = np.max(np.abs(sn - so) / np.maximum(np.abs(so), 1e-300))
    print('  filter statistics (status, steps, sum of NIS, dof, samples): '
          + ('identical' if np.array_equal(so, sn) else f'differ by up to {rel:.1e} relative'))


if __name__ == '__main__':
    main()
