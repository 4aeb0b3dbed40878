"""python -m auv_ident bench: EKF speed against filterpy on the same model and data.

Same run for all (NPS AUV II, 5 coefficients, 'ident' manoeuvre, 20 Hz). Figures:

- steps_per_s: our EKF's compiled offline loop (core.filter.ekf.run_filter), predict + update;
- streaming_steps_per_s: our per-message API (AugmentedEKF.step), what the node calls;
- filterpy_steps_per_s: filterpy 2.0 ExtendedKalmanFilter (Joseph form) driven by the same
  compiled model functions (our RK4 step and its Jacobian as F; H a selection matrix);
- realtime_factor: simulated seconds per wall second of the offline EKF pass (the batch
  refinement is reported separately);
- model_rk4_jacobian_us_per_step: the part both filters share (RK4 step + exact Jacobian), and
  filter_algebra_ratio_vs_filterpy: the ratio once that shared cost is taken out;
- memory: resident-set growth from a 10-minute to a 1-hour run (the loop keeps no history).
"""
import resource
import time

from numba import njit
import numpy as np

from auv_ident.core.filter import ekf as K
from auv_ident.core.filter.augmented import AugmentedEKF, FilterConfig
from auv_ident.core.filter.ekf import new_workspace, rk4_step_into
from auv_ident.core.identification.batch import identify, run_ekf
from auv_ident.core.identification.results import Record
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import COEFFICIENTS, EULER, Input, N_STATE, VEHICLE
from auv_ident.core.simulation.simulate import simulate
from auv_ident.vehicles import load_vehicle


def _filterpy_rate(m, cfg, Y, U, T, n_steps):
    from filterpy.kalman import ExtendedKalmanFilter
    f0 = AugmentedEKF(m, cfg, T)
    n = f0.n
    H = np.zeros((N_STATE, n))
    H[:, VEHICLE] = np.eye(N_STATE)
    ekf = ExtendedKalmanFilter(dim_x=n, dim_z=N_STATE)
    ekf.x, ekf.P = f0.initial_estimate(Y[0], U[0, Input.N_RPM])
    ekf.Q = f0.Q0.copy()
    ekf.R = f0.R0.copy()
    xa_next = np.empty(n)
    Fa = np.empty((n, n))

    def hx(x):
        return x[VEHICLE]

    def hjac(x):
        return H

    def residual(a, b):
        d = a - b
        d[EULER] = (d[EULER] + np.pi) % (2 * np.pi) - np.pi
        return d
    # compile (or load from numba's cache) the model for these argument types before timing
    # (rk4_jacobian_step, not rk4_step_into: from Python its call is the cheaper of the two)
    K.rk4_jacobian_step(ekf.x.copy(), U[0], m.compiled, T, True, xa_next, Fa)
    t0 = time.perf_counter()
    for k in range(1, n_steps + 1):
        K.rk4_jacobian_step(ekf.x, U[k - 1], m.compiled, T, True, xa_next, Fa)
        ekf.F = Fa
        ekf.x = xa_next.copy()           # predict_x: the same RK4 step
        ekf.P = Fa @ ekf.P @ Fa.T + ekf.Q
        ekf.update(Y[k], hjac, hx, R=ekf.R, residual=residual)
    dt = time.perf_counter() - t0
    return n_steps / dt, ekf.x[COEFFICIENTS]


# Not cached: it inlines the core's kernels, and a cache of this file would not see an edit of
# theirs (the core keys its own cache on all its compiled sources, core/compiled_cache.py).
@njit
def _model_loop(X, U, theta, cm, T):
    n = N_STATE + theta.shape[0]
    xa = np.empty(n)
    xa[N_STATE:] = theta
    x1 = np.empty(n)
    Fa = np.empty((n, n))
    ws = new_workspace(n, cm.c0.shape[0], cm.thr.shape[0] if cm.lagged else 0)
    for k in range(X.shape[0]):
        xa[:N_STATE] = X[k]
        rk4_step_into(xa, U[k], cm, T, True, x1, Fa, ws)
    return x1


def _model_step_us(m, run, n_steps):
    """Cost of the shared part, one RK4 step with its exact Jacobian (us per step), timed in a
    compiled loop so that no Python call overhead is counted."""
    args = (m.theta_true, m.compiled, run.T)
    _model_loop(run.x[:2], run.u[:2], *args)
    t0 = time.perf_counter()
    _model_loop(run.x[:n_steps], run.u[:n_steps], *args)
    return (time.perf_counter() - t0) / n_steps * 1e6


def _rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def best_interleaved(measures, repeats):
    """{name: best of `repeats` results} for measures returning a rate (higher is better), the
    measures taking turns within each round so that all see the same machine (on a shared VM a
    slow spell would otherwise land on one of them and swing their ratio)."""
    rates = dict.fromkeys(measures, 0.0)
    for _ in range(repeats):
        for name, measure in measures.items():
            rates[name] = max(rates[name], measure())
    return rates


def bench(duration=600.0, filterpy_steps=3000, repeats=5):
    v = load_vehicle('nps_auv2')
    names = list(v.identify_default)
    truth = Model(v)
    m = Model(v, names)
    run = simulate(truth, 'ident', duration=duration, seed=1)
    cfg = FilterConfig(coefficients=names, initial_offset=0.5)
    T = run.T
    # warm up the compiled code (numba caches it on disk; first call loads it)
    run_ekf(AugmentedEKF(m, cfg, T), [Record(run.t[:50], run.y[:50], run.u[:50])])

    def compiled_loop():
        f = AugmentedEKF(m, cfg, T)
        t0 = time.perf_counter()
        steps = run_ekf(f, [Record(run.t, run.y, run.u)]).steps
        return steps / (time.perf_counter() - t0)

    n_stream = min(3000, len(run.t) - 1)

    def streaming_api():                  # per message, what the node calls
        f = AugmentedEKF(m, cfg, T)
        f.start(run.y[0], run.u[0, Input.N_RPM])
        t0 = time.perf_counter()
        for k in range(1, n_stream + 1):
            f.step(run.u[k - 1], run.y[k])
        return n_stream / (time.perf_counter() - t0)

    rates = best_interleaved({
        'ours': compiled_loop, 'streaming': streaming_api,
        'filterpy': lambda: _filterpy_rate(m, cfg, run.y, run.u, T,
                                           min(filterpy_steps, len(run.t) - 1))[0]}, repeats)
    steps_per_s, stream_rate, fp_rate = rates['ours'], rates['streaming'], rates['filterpy']
    model_us = _model_step_us(m, run, 3000)
    t0 = time.perf_counter()
    identify(m, [Record(run.t, run.y, run.u)], cfg, T=T, refine_pass=True)
    full_s = time.perf_counter() - t0
    # memory: a 1-hour run through the same loop must not grow the process
    long = simulate(truth, 'ident', duration=3600.0, seed=2)
    rss0 = _rss_mb()
    f = AugmentedEKF(m, cfg, T)
    t0 = time.perf_counter()
    run_ekf(f, [Record(long.t, long.y, long.u)])
    hour_s = time.perf_counter() - t0
    rss1 = _rss_mb()
    return {
        'steps_per_s': steps_per_s,
        'streaming_steps_per_s': stream_rate,
        'filterpy_steps_per_s': fp_rate,
        'ratio_vs_filterpy': steps_per_s / fp_rate,
        'streaming_ratio_vs_filterpy': stream_rate / fp_rate,
        'realtime_factor': duration * steps_per_s / len(run.t),   # over the best pass
        'model_rk4_jacobian_us_per_step': model_us,
        'filter_algebra_ratio_vs_filterpy': (1e6 / fp_rate - model_us)
        / max(1e-9, 1e6 / steps_per_s - model_us),
        'one_hour_20hz_ekf_s': hour_s,
        'identify_with_refinement_s': full_s,
        'rss_growth_mb_1h_run': rss1 - rss0,
        'setup': {'vehicle': 'nps_auv2', 'coefficients': names, 'maneuver': 'ident',
                  'rate_hz': 1.0 / T, 'duration_s': duration, 'augmented_states': 12 + len(names),
                  'measured_channels': 12},
    }


def format_bench(b):
    s = b['setup']
    return '\n'.join([
        f"EKF benchmark: {s['vehicle']}, {len(s['coefficients'])} coefficients "
        f"({s['augmented_states']} augmented states, {s['measured_channels']} measurements), "
        f"{s['rate_hz']:.0f} Hz '{s['maneuver']}' run of {s['duration_s']:.0f} s",
        f"  auv_ident compiled loop : {b['steps_per_s']:>10.0f} steps/s",
        f"  auv_ident streaming API : {b['streaming_steps_per_s']:>10.0f} steps/s",
        f"  filterpy EKF, same model: {b['filterpy_steps_per_s']:>10.0f} steps/s",
        f"  ratio vs filterpy       : {b['ratio_vs_filterpy']:>10.1f} x (streaming "
        f"{b['streaming_ratio_vs_filterpy']:.1f} x)",
        f"  real-time factor        : {b['realtime_factor']:>10.0f} x (EKF pass)",
        f"  shared model cost       : {b['model_rk4_jacobian_us_per_step']:>10.1f} us/step "
        f"(RK4 step + exact Jacobian, called by both filters)",
        f"  filter algebra only     : {b['filter_algebra_ratio_vs_filterpy']:>10.1f} x faster "
        "than filterpy (step time minus the shared model cost)",
        f"  1 h of 20 Hz data       : {b['one_hour_20hz_ekf_s']:>10.2f} s (EKF pass); "
        f"RSS growth {b['rss_growth_mb_1h_run']:.1f} MB",
        f"  identify incl. batch refinement, {s['duration_s']:.0f} s run: "
        f"{b['identify_with_refinement_s']:.2f} s",
    ])
