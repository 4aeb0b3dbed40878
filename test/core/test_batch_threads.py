"""The finite differences of the batch methods run on threads (core/identification/batch.py): the
numbers
must be those of one thread, bit for bit, and a bad thread count must be one clear error."""
import numpy as np
import pytest

from auv_ident.core.errors import ConfigError
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.identification import batch
from auv_ident.core.identification.batch import difference_threads, FilterErrorResiduals, refine
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


def test_refinement_without_scipy_workers_gives_the_same(record, monkeypatch):
    """An older scipy (no least_squares(workers=...), e.g. Ubuntu 24.04's under ros2 run):
    the Jacobian's columns one after the other, the same numbers."""
    v, run, cfg = record
    model = Model(v, NAMES)
    start = model.theta_file * 1.1
    threaded = refine(model, cfg, [Record(run.t, run.y, run.u)], start, T=run.T, max_nfev=5)
    monkeypatch.setattr(batch, 'LEAST_SQUARES_WORKERS', False)
    serial = refine(model, cfg, [Record(run.t, run.y, run.u)], start, T=run.T, max_nfev=5)
    assert np.array_equal(threaded.estimate, serial.estimate)
    assert np.array_equal(threaded.cov, serial.cov)
