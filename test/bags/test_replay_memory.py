"""What a bag replay keeps per odometry sample is compact float arrays (session/record.py Rows,
UpdateLog), not a tuple and small arrays per message: ``identify --bag`` on an hour of data
must not grow by kilobytes a sample (docs/reliability.md, bounded memory). What it loads and
what the sandwich covariance of its refinement allocates are checked here too."""
import subprocess
import sys
import tracemalloc

import numpy as np

from auv_ident.core.identification import uncertainty
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.simulation.simulate import simulate
from auv_ident.offline.replay import replay_bag
from auv_ident.offline.sim_bag import write_run_bag
from auv_ident.session.settings import IdentifierSettings
from auv_ident.vehicles import load_vehicle

# bytes per sample (tracemalloc) at the replay's peak and kept in its result; measured 1122 and
# 527 (the tuples and small arrays before: 2081 and 907). Kept: [t, u7], [t, y12], the R
# diagonal while replaying, the ReplayResult's paired arrays (t, Y, U, t_cmd, U_cmd: 28 values)
# and its updates (stamp, estimate and std of 7 parameters: 15 values), 8 bytes each
MAX_PEAK_PER_SAMPLE = 1500
MAX_KEPT_PER_SAMPLE = 700


def test_replay_keeps_compact_arrays_per_sample(tmp_path):
    run = simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=150.0, T=0.05, seed=2)
    path = tmp_path / 'run'
    write_run_bag(run, path)
    # the live noise learning keeps a record of its own, bounded (noise_learning.KEEP_LIMIT)
    settings = IdentifierSettings.from_values(learn_noise=False)
    replay_bag(path, settings)          # compiled, imported, cached
    tracemalloc.start()
    try:
        rr = replay_bag(path, settings)
        kept, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    n = len(run.t)
    assert rr.accepted == n and len(rr.updates) == n
    stamps = [u[0] for u in rr.updates]
    assert all(isinstance(s, int) for s in stamps) and stamps == sorted(stamps)
    assert rr.updates[-1][1].shape == rr.estimate.shape
    assert peak / n < MAX_PEAK_PER_SAMPLE, peak / n
    assert kept / n < MAX_KEPT_PER_SAMPLE, kept / n


def test_identify_path_does_not_import_scipy_stats():
    # scipy.stats (and scipy.signal, which loads it) cost about 20 MB resident at start-up
    # of every identify --bag; its path needs neither (selection's gamma cdf is
    # scipy.special.gammainc, equation_error imports savgol_filter where it smooths)
    code = ('import sys, auv_ident.cli, auv_ident.analysis.bag_identify, '
            'auv_ident.core.identification.pipeline; '
            "print(sorted(m for m in ('scipy.stats', 'scipy.signal', 'matplotlib', 'dask') "
            'if m in sys.modules))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == '[]', out.stdout


def test_sandwich_covariance_does_not_copy_the_jacobian():
    # the refinement's Jacobian is 576 bytes a sample (12 channels x 6 coefficients); a
    # masked copy of it doubled that at the sandwich covariance (measured 1.6 x J's bytes
    # traced; in blocks of samples: 0.78, the scores, residuals and their mask)
    rng = np.random.default_rng(0)
    n, m, p = 3 * uncertainty.SANDWICH_BLOCK + 5, 12, 6
    white = rng.standard_normal((n, m))
    white[::7, 3] = np.nan
    J = rng.standard_normal((n * m, p))
    bounds = [0, n // 3, n]
    uncertainty.sandwich_covariance(J, white, bounds=bounds)
    tracemalloc.start()
    try:
        cov, info = uncertainty.sandwich_covariance(J, white, bounds=bounds)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < J.nbytes, peak / J.nbytes
    # the same numbers as the whole masked Jacobian at once (to round-off)
    ok = np.isfinite(white)
    Jk = J.reshape(n, m, p) * ok[:, :, None]
    g = np.einsum('kmp,km->kp', Jk, np.where(ok, white, 0.0))
    A = np.einsum('kmp,kmq->pq', Jk, Jk)
    L = info['lags']
    B = g.T @ g
    for gs in (g[:bounds[1]], g[bounds[1]:]):
        for lag in range(1, L + 1):
            G = gs[lag:].T @ gs[:-lag]
            B += (1.0 - lag / (L + 1.0)) * (G + G.T)
    A_inv = np.linalg.inv(A)
    np.testing.assert_allclose(cov, A_inv @ B @ A_inv, rtol=1e-10, atol=0)
