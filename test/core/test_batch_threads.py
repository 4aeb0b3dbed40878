"""The finite differences of the batch methods run on threads (core/identification/batch.py): the
numbers
must be those of one thread, bit for bit, and a bad thread count must be one clear error."""
import tracemalloc

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.optimize._numdiff import approx_derivative

from auv_ident.core.errors import ConfigError
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.identification import batch
from auv_ident.core.identification.batch import (
    difference_threads,
    FilterErrorResiduals,
    ForwardJacobian,
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


def test_refinement_is_scipy_least_squares_to_the_bit(record):
    """refine calls MINPACK's lmder itself with its own forward differences (to keep one
    Jacobian, not seven): the same numbers as least_squares(method='lm', diff_step=1e-5) on
    the same residuals, bit for bit."""
    v, run, cfg = record
    model = Model(v, NAMES)
    start = model.theta_file * 1.1
    runs = [Record(run.t, run.y, run.u)]
    ours = refine(model, cfg, runs, start, T=run.T, max_nfev=5)
    fer = FilterErrorResiduals(model, cfg, runs, T=run.T)
    scale = batch.parameter_scale(model, start)

    def residuals(z):
        r = fer.vector(z * scale)
        return np.full(fer.white.size, 1e3) if r is None else r

    sol = least_squares(residuals, start / scale, method='lm', x_scale=np.ones(model.p),
                        max_nfev=5 * model.p, diff_step=1e-5)
    J = sol.jac / scale[None, :]
    s2 = 2.0 * sol.cost / max(1, np.count_nonzero(sol.fun) - model.p)
    assert np.array_equal(ours.estimate, sol.x * scale)
    assert np.array_equal(ours.jacobian, J)
    assert np.array_equal(ours.cov, np.linalg.inv(J.T @ J) * max(1.0, s2))
    assert ours.message == sol.message and ours.converged == (sol.status > 0)


def test_refinement_keeps_few_copies_of_the_jacobian(record):
    """The refinement's peak memory (tracemalloc: numpy's and MINPACK's arrays) is a few
    (M, p) Jacobians: its own and MINPACK's (scipy's least_squares held about 7.5; 3.5
    measured after)."""
    v, run, cfg = record
    model = Model(v, NAMES)
    runs = [Record(run.t, run.y, run.u)]
    start = model.theta_file * 1.1
    refine(model, cfg, runs, start, T=run.T, max_nfev=2)     # compiled, imported
    tracemalloc.start()
    try:
        refine(model, cfg, runs, start, T=run.T, max_nfev=2)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    jacobian_bytes = len(run.t) * 12 * model.p * 8
    assert peak < 5.0 * jacobian_bytes, peak / jacobian_bytes


def test_forward_jacobian_is_scipys_two_point_rule():
    """Column i = (r(z + h_i e_i) - r(z)) / ((z_i + h_i) - z_i), h as scipy's 2-point
    relative step (a zero parameter gets sqrt(eps)): scipy's approx_derivative's numbers."""
    A = np.array([[1.0, 2.0, -0.5], [0.3, -4.0, 2.5], [7.0, 0.1, 0.0], [1e-3, 5.0, 1.0]])

    def residuals(z):
        return np.sin(A @ z) + z[0] * z[2]

    z = np.array([0.7, -1.3, 0.0])
    jac = ForwardJacobian(residuals, 4, 3, rel_step=1e-5)
    ours = jac(z).copy()
    ref = approx_derivative(residuals, z, method='2-point', rel_step=1e-5)
    assert np.array_equal(ours, ref)
    jac.fun(z + 1.0)                    # another point: the buffer is computed anew
    assert np.array_equal(jac(z + 1.0),
                          approx_derivative(residuals, z + 1.0, method='2-point',
                                            rel_step=1e-5))


def test_forward_jacobian_writes_columns_in_place():
    """With residuals_into, each column's r(z + h_i e_i) is written into the Jacobian's own
    row, not returned as a new (M,) vector (one per difference thread at the refinement's
    peak, docs/reliability.md bounded memory): the same numbers, less than one vector traced."""
    m = 200_000
    A = np.random.default_rng(1).standard_normal((m, 3))

    def residuals(z):
        return np.sin(A @ z)

    def residuals_into(z, out):
        np.matmul(A, z, out=out)
        np.sin(out, out=out)

    z = np.array([0.7, -1.3, 0.0])
    ref = ForwardJacobian(residuals, m, 3).rows(z).copy()
    jac = ForwardJacobian(residuals, m, 3, residuals_into=residuals_into)
    jac.fun(z)                          # r(z), which the columns start from
    tracemalloc.start()
    try:
        rows = jac.rows(z)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert np.array_equal(rows, ref)
    assert peak < 8 * m, peak / (8 * m)
