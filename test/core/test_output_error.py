"""core.identification.output_error: multiple-shooting output error recovers the coefficients of a
short
noise-light run, estimates the output noise, and cuts segments where the stamps say."""
from method_runs import LIGHT_NOISE_STD, light_run, relative_error
import numpy as np
import pytest

from auv_ident.core.errors import DataError
from auv_ident.core.identification.output_error import output_error, segment_index, segment_starts
from auv_ident.core.model.state import State


def test_output_error_recovers_the_truth_on_a_noise_light_run():
    """90 s, a fifth of the documented noise, started 50 % off: within 1 % (measured
    0.06-0.37 %) and 3 of its 1-sigma; the residual level it estimates is the simulated noise
    (within 10 %)."""
    model, run = light_run()
    truth = model.theta_file
    r = output_error(model, run.t, run.y, run.u, 1.5 * truth, LIGHT_NOISE_STD, T=run.T)
    assert relative_error(r.theta, truth).max() < 0.01
    assert np.all(np.abs(r.theta - truth) < 3.0 * r.theta_std)
    fitted = [State.U, State.W, State.Q, State.THETA]
    assert np.allclose(r.noise_std[fitted], LIGHT_NOISE_STD[fitted], rtol=0.1)
    assert r.segments == 5 and r.converged


def test_segments_start_every_segment_s_and_after_a_gap():
    t = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 10.0, 11.0, 12.0])
    Y = np.zeros((8, 12))
    Y[5] = np.nan                     # nothing measured right after the gap
    n_sub = np.array([0, 1, 1, 1, 1, 0, 1, 1])      # a restart (gap) before t = 10
    start = segment_starts(t, Y, n_sub, segment_s=2.0)
    assert start.tolist() == [True, False, True, False, True, False, True, False]
    assert segment_index(start, n_sub).tolist() == [0, 0, 1, 1, 2, -1, 3, 3]


def test_output_error_without_a_measured_start_says_so():
    model, run = light_run()
    Y = run.y[:50].copy()
    Y[:, State.Q] = np.nan
    with pytest.raises(DataError, match='q'):
        output_error(model, run.t[:50], Y, run.u[:50], model.theta_file, LIGHT_NOISE_STD)
