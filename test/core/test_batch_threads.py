"""The finite differences of the batch methods run on threads (core/identification/batch.py): the
numbers
must be those of one thread, bit for bit, and a bad thread count must be one clear error."""
import tracemalloc

import numpy as np
import pytest
from scipy.optimize import least_squares

from auv_ident.core.errors import ConfigError
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.identification import batch
from auv_ident.core.identification.batch import (
    difference_threads,
    FilterErrorResiduals,
    refine,
)
from auv_ident.core.identification.results import Record
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.simulation.simulate import simulate
from auv_ident.vehicles import load_vehicle

NAMES = ['Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v']


@pytest.fixture(scope='module')
def record():
    v = load_vehicle('nps_auv2')
    run = simulate(Model(v), 'ident', duration=30.0, seed=3)
    cfg = FilterConfig(coefficients=[], noise_std=run.noise_std, mode='fixed')
    return v, run, cfg


def test_forward_differences_on_threads_equal_one_thread(record):
    v, run, cfg = record
    model = Model(v, NAMES)
    theta = model.theta_file * 1.05
    steps = 1e-4 * np.abs(theta)
    fer = FilterErrorResiduals(model, cfg, [Record(run.t, run.y, run.u)], T=run.T)
    r1, J1, failed1 = fer.forward_differences(theta, steps, threads=1)
    r3, J3, failed3 = fer.forward_differences(theta, steps, threads=3)
    assert failed1 == failed3 == []
    assert np.array_equal(r1, r3) and np.array_equal(J1, J3)
    assert np.all(np.any(J1 != 0.0, axis=0))      # every column moved the residuals
    # the main thread's buffer still holds the residuals at theta (not a column's)
    assert np.array_equal(np.nan_to_num(fer.white.ravel()), r1)


def test_refinement_on_threads_equals_one_thread(record, monkeypatch):
    v, run, cfg = record
    model = Model(v, NAMES)
    start = model.theta_file * 1.1
    out = {}
    for threads in ('1', '2'):
        monkeypatch.setenv('AUV_IDENT_THREADS', threads)
        out[threads] = refine(model, cfg, [Record(run.t, run.y, run.u)], start, T=run.T,
                              max_nfev=5)
    assert np.array_equal(out['1'].estimate, out['2'].estimate)
    assert np.array_equal(out['1'].cov, out['2'].cov)


@pytest.mark.parametrize('text', ['0', '-2', 'two', '1.5'])
def test_a_bad_thread_count_is_named(monkeypatch, text):
    monkeypatch.setenv('AUV_IDENT_THREADS', text)
    with pytest.raises(ConfigError, match='AUV_IDENT_THREADS'):
        difference_threads()


def test_thread_count_defaults_to_the_usable_cpus(monkeypatch):
    monkeypatch.delenv('AUV_IDENT_THREADS', raising=False)
    assert difference_threads() == len(batch.os.sched_getaffinity(0))
    monkeypatch.setenv('AUV_IDENT_THREADS', '3')
    assert difference_threads() == 3


def test_refinement_agrees_with_minpack(record):
    """refine's Levenberg-Marquardt on chunked normal equations (levenberg_marquardt.py) lands
    where MINPACK's lmder (least_squares(method='lm', diff_step=1e-5), the Jacobian held
    whole) does on the same residuals, to the rounding of the normal equations: estimates
    within 1e-6 of a 1-sigma, the information, scores and covariance within 1e-6."""
    v, run, cfg = record
    model = Model(v, NAMES)
    start = model.theta_file * 1.1
    runs = [Record(run.t, run.y, run.u)]
    ours = refine(model, cfg, runs, start, T=run.T)
    fer = FilterErrorResiduals(model, cfg, runs, T=run.T)
    scale = batch.parameter_scale(model, start)

    def residuals(z):
        r = fer.vector(z * scale)
        return np.full(fer.white.size, 1e3) if r is None else r

    sol = least_squares(residuals, start / scale, method='lm', x_scale=np.ones(model.p),
                        max_nfev=60 * model.p, diff_step=1e-5)
    J = sol.jac / scale[None, :]
    s2 = 2.0 * sol.cost / max(1, np.count_nonzero(sol.fun) - model.p)
    cov = np.linalg.inv(J.T @ J) * max(1.0, s2)
    sd = np.sqrt(np.diag(cov))
    assert np.all(np.abs(ours.estimate - sol.x * scale) < 1e-6 * sd)
    # the sums at our solution against J at MINPACK's (their points differ by < 1e-6 sigma)
    assert np.allclose(ours.information, J.T @ J, rtol=1e-6, atol=0)
    scores = np.einsum('kmp,km->kp', J.reshape(-1, 12, model.p), sol.fun.reshape(-1, 12))
    assert np.allclose(ours.scores, scores, rtol=1e-6, atol=1e-6 * np.abs(scores).max())
    assert np.all(np.abs(ours.cov - cov) < 1e-6 * np.outer(sd, sd))
    assert ours.converged and sol.status > 0


def test_refinement_never_holds_the_jacobian(record, monkeypatch):
    """The refinement's peak memory (tracemalloc) is a few residual vectors of 12 N values
    (the current and trial residuals, the filter's buffer): its Jacobian (12 N, p), p = 5
    such vectors, exists a chunk of REFINE_CHUNK samples at a time only (8.9 vectors measured
    with 64-sample chunks; 26 with the whole record as one chunk, where each difference
    thread's filter output is a whole run's too)."""
    v, run, cfg = record
    model = Model(v, NAMES)
    runs = [Record(run.t, run.y, run.u)]
    start = model.theta_file * 1.1
    monkeypatch.setattr(batch, 'REFINE_CHUNK', 64)
    refine(model, cfg, runs, start, T=run.T, max_nfev=2)     # compiled, imported
    tracemalloc.start()
    try:
        refine(model, cfg, runs, start, T=run.T, max_nfev=2)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    vector_bytes = len(run.t) * 12 * 8
    assert peak < 11.0 * vector_bytes, peak / vector_bytes


def test_chunks_are_the_whole_runs_residuals(record):
    """The filter run a chunk at a time (FilterErrorResiduals.chunks) gives the whole run's
    whitened innovations bit for bit, across a gap (a restart of the states), missing
    measurements and two runs, for any chunk length."""
    v, run, cfg = record
    model = Model(v, NAMES)
    y = run.y.copy()
    y[100:140, 3] = np.nan
    t = run.t.copy()
    t[300:] += 2.0          # longer than max_bridge: the states restart at sample 300
    runs = [Record(t, y, run.u), Record(run.t[:200], run.y[:200], run.u[:200])]
    fer = FilterErrorResiduals(model, cfg, runs, T=run.T)
    assert np.count_nonzero(fer.legs[0][2].n_sub[1:] == 0) == 1
    theta = model.theta_file * 1.05
    whole = fer.vector(theta)
    for chunk in (1, 7, 300, 1000):
        pieces = [piece.copy() for piece in fer.chunks(theta, chunk)]
        assert np.array_equal(np.concatenate(pieces), whole), chunk
