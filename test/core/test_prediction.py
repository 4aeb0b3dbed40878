"""core.simulation.prediction: the fit measures against hand computations, and the free run /
K-step
prediction of a model against a closed-form solution."""
import numpy as np
import pytest

from auv_ident.core.errors import ConfigError
from auv_ident.core.model.state import State
from auv_ident.core.simulation.prediction import (
    angle_channels,
    fit_percent,
    free_run,
    k_step_prediction,
    rmse,
    theil,
)


def test_fit_rmse_theil_by_hand():
    y = np.array([1.0, 2.0, 3.0, 4.0])
    y_hat = np.array([1.0, 2.5, 2.5, 4.0])
    # ||y - y_hat|| = sqrt(0.5), ||y - 2.5|| = sqrt(5)
    assert fit_percent(y, y_hat) == pytest.approx(100 * (1 - np.sqrt(0.5 / 5.0)))
    assert rmse(y, y_hat) == pytest.approx(np.sqrt(0.5 / 4))
    assert theil(y, y_hat) == pytest.approx(
        np.sqrt(0.5 / 4) / (np.sqrt(30 / 4) + np.sqrt((1 + 6.25 + 6.25 + 16) / 4)))
    assert fit_percent(y, y) == 100.0
    assert fit_percent(y, np.full(4, 2.5)) == pytest.approx(0.0)
    assert np.isnan(fit_percent(np.ones(3), np.zeros(3)))
    # non-finite samples are left out of both
    assert fit_percent(np.r_[y, np.nan], np.r_[y_hat, 0.0]) == fit_percent(y, y_hat)
    with pytest.raises(ConfigError):
        fit_percent(y, y_hat[:3])


def test_angle_channels_score_the_heading_change_not_the_wrap():
    Y = np.zeros((3, 12))
    Y[:, State.PSI] = [3.1, -3.1, -3.0]        # through +-pi
    Y_hat = Y.copy()
    Y_hat[:, State.PSI] = [3.1, 3.1833, -3.0]  # the same heading as 2 pi - 3.1
    Ym, Yp = angle_channels(Y, Y_hat)
    assert np.all(np.diff(Ym[:, State.PSI]) > 0)
    assert np.abs(Yp[:, State.PSI] - Ym[:, State.PSI]).max() < 1e-3


def _decay(x, u):
    xdot = np.zeros(12)
    xdot[State.U] = -0.5 * x[State.U] + u[0]
    return xdot


def test_free_run_matches_closed_form_on_irregular_stamps():
    t = np.cumsum(np.r_[0.0, np.random.default_rng(1).uniform(0.02, 0.3, 60)])
    U = np.ones((len(t), 1))
    x0 = np.zeros(12)
    X = free_run(_decay, t, U, x0)
    exact = 2.0 * (1.0 - np.exp(-0.5 * t))
    assert np.abs(X[:, State.U] - exact).max() < 1e-8


def test_k_step_prediction_restarts_from_the_measurement():
    t = np.arange(0.0, 5.0, 0.1)
    U = np.zeros((len(t), 1))
    Y = np.zeros((len(t), 12))
    Y[:, State.U] = 1.0          # measured: constant, the model decays
    X1 = k_step_prediction(_decay, t, U, Y, 1)
    X10 = k_step_prediction(_decay, t, U, Y, 10)
    assert X1[0, State.U] == 1.0
    assert np.allclose(X1[1:, State.U], np.exp(-0.05))
    # 10 steps ahead the decay is exp(-0.5), the largest error of a 10-step prediction
    assert X10[10, State.U] == pytest.approx(np.exp(-0.5), rel=1e-8)
    assert X10[11, State.U] == pytest.approx(np.exp(-0.05), rel=1e-8)
    with pytest.raises(ConfigError):
        k_step_prediction(_decay, t, U, Y, 0)
