"""Tests of core/identification/uncertainty.py on problems with a known answer (linear least
squares)."""
import math

import numpy as np
import pytest

from auv_ident.core.identification import uncertainty
from auv_ident.core.identification.uncertainty import (
    ar1_covariance,
    autocorrelation,
    bandwidth,
    identifiability,
    noise_model,
    sandwich_covariance,
)


def _ar1(rng, n, m, rho, sigma=1.0):
    e = np.empty((n, m))
    e[0] = rng.normal(size=m) * sigma
    w = rng.normal(size=(n, m)) * sigma * np.sqrt(1.0 - rho ** 2)
    for k in range(1, n):
        e[k] = rho * e[k - 1] + w[k]
    return e


def _fit(rng, n, rho, sigma):
    """y_kj = sum_i X_kji theta_i + e_kj, fitted by least squares with unit weights."""
    m, p = 2, 3
    t = np.arange(n) * 0.05
    X = np.stack([np.stack([np.sin(0.3 * t), np.cos(0.11 * t), np.ones(n)], axis=1),
                  np.stack([np.cos(0.2 * t), np.sin(0.05 * t) ** 2, 0.5 * np.ones(n)],
                           axis=1)], axis=1)            # (n, m, p)
    theta = np.array([1.0, -2.0, 0.5])
    y = X @ theta + _ar1(rng, n, m, rho, sigma)
    J = X.reshape(n * m, p)
    est = np.linalg.lstsq(J, y.ravel(), rcond=None)[0]
    r = (y - X @ est)
    return est - theta, J, r


@pytest.mark.parametrize('rho,sigma', [(0.0, 1.0), (0.9, 2.0), (0.98, 0.5)])
def test_sandwich_bars_cover_the_truth_where_naive_ones_do_not(rho, sigma):
    rng = np.random.default_rng(7)
    z_sand, z_naive = [], []
    for _ in range(150):
        err, J, r = _fit(rng, 3000, rho, sigma)
        cov, info = sandwich_covariance(J, r)
        z_sand.append(np.abs(err) / np.sqrt(np.diag(cov)))
        z_naive.append(np.abs(err) / np.sqrt(np.diag(info['naive_cov'])))
    z_sand, z_naive = np.concatenate(z_sand), np.concatenate(z_naive)
    assert np.mean(z_sand < 3.0) >= 0.97
    assert 0.45 < np.median(z_sand) < 0.9            # an honest sigma gives ~0.67
    if rho == 0.0:
        assert np.mean(z_naive < 3.0) >= 0.97        # white: the two agree
    else:
        assert np.mean(z_naive < 3.0) < 0.85         # coloured: naive bars are too small


def test_autocorrelation_and_noise_model_read_an_ar1_process():
    rng = np.random.default_rng(1)
    e = _ar1(rng, 20000, 2, 0.0)
    e[:, 1] = _ar1(rng, 20000, 1, 0.9)[:, 0] * 3.0
    e[::7, 1] = np.nan                               # missing samples are skipped
    rho = autocorrelation(e[:, 1], 3)
    np.testing.assert_allclose(rho, [1.0, 0.9, 0.81, 0.729], atol=0.03)
    nm = noise_model(e, dt=0.1, names=['white', 'coloured'])
    assert nm['white']['white'] and abs(nm['white']['level'] - 1.0) < 0.03
    assert not nm['coloured']['white'] and abs(nm['coloured']['level'] - 3.0) < 0.2
    assert abs(nm['coloured']['tau_s'] - (-0.1 / np.log(0.9))) < 0.15
    assert bandwidth(e) > bandwidth(e[:, :1])


def test_ar1_covariance_is_honest_where_the_long_run_bound_is_too_wide():
    """AR(1) noise correlated over 50 samples, sensitivities that switch every 20 (a pilot's
    stick steps against slow sensor noise): the white-noise bars of the long-run variance (the
    noise model's effective 1-sigma) are far too wide, the AR(1) covariance's are honest
    (median |error|/sigma near 0.67, the truth within 3 sigma). Sensitivities constant over
    the correlation time: the two agree."""
    rng = np.random.default_rng(11)
    n, rho = 3000, 0.98
    k = np.arange(n)
    z_ar1, z_bound = [], []
    for _ in range(60):
        X = np.stack([np.sign(np.sin(2 * np.pi * k / 40.0)),
                      np.repeat(rng.choice([-1.0, 1.0], n // 20), 20)], axis=1)
        e = _ar1(rng, n, 1, rho)
        est = np.linalg.lstsq(X, e[:, 0], rcond=None)[0]       # the truth is 0
        r = e - (X @ est)[:, None]
        cov, rhos = ar1_covariance(X, r)
        bound = np.linalg.inv(X.T @ X) * np.mean(r ** 2) * (1 + rhos[0]) / (1 - rhos[0])
        z_ar1.append(np.abs(est) / np.sqrt(np.diag(cov)))
        z_bound.append(np.abs(est) / np.sqrt(np.diag(bound)))
    z_ar1, z_bound = np.concatenate(z_ar1), np.concatenate(z_bound)
    assert 0.5 < np.median(z_ar1) < 0.85 and np.mean(z_ar1 < 3.0) >= 0.97
    assert np.median(z_bound) < 0.3
    slow = np.stack([np.ones(n), np.linspace(0.0, 1.0, n)], axis=1)
    e = _ar1(rng, n, 1, 0.9)
    cov, rhos = ar1_covariance(slow, e)
    bound = np.linalg.inv(slow.T @ slow) * np.mean(e ** 2) * (1 + rhos[0]) / (1 - rhos[0])
    np.testing.assert_allclose(np.diag(cov), np.diag(bound), rtol=0.02)
    # the noise model's own AR(1) (whitened: variance (1 - rho) / (1 + rho)): the bound is
    # (J^T J)^-1, the white-noise covariance of the effective noise
    cov, _ = ar1_covariance(slow, e, rho=np.array([0.9]), variance=np.array([0.1 / 1.9]))
    np.testing.assert_allclose(np.diag(cov), np.diag(np.linalg.inv(slow.T @ slow)), rtol=0.02)


def test_ar1_covariance_counts_a_channels_own_samples_and_runs():
    """Rows where a channel is missing (another topic's rows) are no step of its noise: the
    covariance is that of the channel's samples alone; two runs are independent."""
    rng = np.random.default_rng(2)
    n = 400
    X = rng.normal(size=(n, 2))
    e = _ar1(rng, n, 1, 0.9)
    cov, rhos = ar1_covariance(X, e)
    rows = np.full((2 * n, 1), np.nan)           # a missing row after every sample
    rows[::2] = e
    Xr = np.zeros((2 * n, 2))
    Xr[::2] = X
    cov_gaps, rhos_gaps = ar1_covariance(Xr, rows)
    np.testing.assert_allclose(cov_gaps, cov, rtol=1e-10)
    assert rhos_gaps[0] == pytest.approx(rhos[0])
    split, _ = ar1_covariance(X, e, bounds=[0, n // 2, n])    # no pair across the runs
    assert not np.allclose(split, cov, rtol=1e-6)


def _pair_correlation(x, lag):
    """The correlation of the pairs (x[k + lag], x[k]) both present, x less its mean, by loop."""
    z = x - np.nanmean(x)
    a, b = z[lag:], z[:len(z) - lag]
    both = np.isfinite(a) & np.isfinite(b)
    a, b = a[both], b[both]
    return float(np.sum(a * b) / np.sqrt(np.sum(a * a) * np.sum(b * b)))


def test_autocorrelation_with_gaps_is_the_pairs_correlation_and_never_above_1():
    """A slow channel whose lag-1 pairs all fall in its stretch of large variance (a bag's
    odometry rows with command rows between them elsewhere): the variance of all samples
    made lag 1 read 3.0; the pairs' own correlation is below 1, and so is every lag of
    random gappy series."""
    rng = np.random.default_rng(5)
    x = np.concatenate([np.sin(np.arange(2000) * 0.002) * 10.0, rng.normal(size=10000)])
    x[2001::2] = np.nan             # no lag-1 pairs after the first 2000 samples
    rho = autocorrelation(x, 4)
    assert rho[1] == pytest.approx(_pair_correlation(x, 1), abs=1e-9)
    assert rho[1] <= 1.0 and rho[1] > 0.99
    for lag in (2, 3, 4):
        assert rho[lag] == pytest.approx(_pair_correlation(x, lag), abs=1e-9)
    for seed in range(20):
        r = np.random.default_rng(seed)
        y = np.cumsum(r.normal(size=3000)) * r.uniform(0.1, 10.0, size=3000) ** 2
        y[r.random(3000) < r.uniform(0.1, 0.7)] = np.nan
        assert np.all(np.abs(autocorrelation(y, 30)[1:]) <= 1.0)


def _pair_autocorrelation(x, max_lag):
    """autocorrelation's definition sample by sample: per lag the pairs both present, z = x
    less the mean of all samples present (NaN where a lag has no pairs)."""
    ok = np.isfinite(x)
    z = np.where(ok, x - x[ok].mean(), 0.0)
    out = np.full(max_lag + 1, np.nan)
    for lag in range(min(max_lag, len(x) - 1) + 1):
        both = ok[lag:] & ok[:len(x) - lag]
        a, b = z[lag:][both], z[:len(x) - lag][both]
        if both.any():
            out[lag] = math.fsum(a * b) / math.sqrt(math.fsum(a * a) * math.fsum(b * b))
    return out


@pytest.mark.parametrize('gaps', [0.0, 0.3])
def test_autocorrelation_of_few_lags_by_slices_is_the_definition_and_the_ffts(gaps,
                                                                              monkeypatch):
    """Up to DIRECT_MAX_LAG lags the four pair sums are dot products over shifted slices (the
    live noise learner's fits, noise_model's 20 lags); beyond, the FFT. Both give the
    definition, and each other to the FFT's rounding, with gaps and without (with none the
    squares' sums are the total less the ends a lag leaves out)."""
    rng = np.random.default_rng(11)
    e = rng.normal(size=6000)
    x = np.empty_like(e)
    x[0] = e[0]
    for k in range(1, len(e)):
        x[k] = 0.9 * x[k - 1] + e[k]
    x = 3.0 + 1e-3 * x          # an offset and a small scale: the mean must come off exactly
    x[rng.random(len(x)) < gaps] = np.nan
    lags = uncertainty.DIRECT_MAX_LAG
    direct = autocorrelation(x, lags)
    monkeypatch.setattr(uncertainty, 'DIRECT_MAX_LAG', -1)
    by_fft = autocorrelation(x, lags)
    exact = _pair_autocorrelation(x, lags)
    np.testing.assert_allclose(direct, exact, rtol=0.0, atol=1e-14)
    np.testing.assert_allclose(by_fft, direct, rtol=0.0, atol=1e-13)
    assert direct[1] == pytest.approx(0.9, abs=0.02)
    short = np.array([1.0, np.nan, 2.0, 4.0, np.nan, 3.0])    # fewer samples than lags
    np.testing.assert_array_equal(np.isnan(autocorrelation(short, 8)),
                                  np.isnan(_pair_autocorrelation(short, 8)))


def test_identifiability_verdicts():
    rng = np.random.default_rng(3)
    n = 2000
    a = rng.normal(size=n)
    J = np.stack([a, 1e-4 * rng.normal(size=n), a + 1e-3 * rng.normal(size=n),
                  rng.normal(size=n)], axis=1)
    out = identifiability(J, np.array([1.0, 1.0, 1.0, 1.0]), ['good', 'unexcited', 'twin',
                                                               'clear'])
    assert out['unexcited']['verdict'] == 'not excited'
    assert out['twin']['verdict'] in ('weak', 'not excited')
    assert out['twin']['correlated_with'] == 'good' and out['twin']['max_correlation'] > 0.95
    assert out['clear']['verdict'] == 'identifiable'
    assert out['clear']['rel_std'] == pytest.approx(1.0 / np.sqrt(n), rel=0.1)
    weak = identifiability(J[:, 3:], np.array([0.1]), ['small'])['small']
    assert weak['verdict'] == 'weak' and weak['correlated_with'] is None


def test_ar1_score_sums_in_chunks_are_the_whole_jacobians():
    """The refinement streams its Jacobian a chunk at a time (it never holds it): the AR(1)
    covariance summed over chunks cut anywhere (inside runs, at a run's start, one sample)
    equals the one of the whole Jacobian, gaps and runs included."""
    from auv_ident.core.identification.uncertainty import Ar1ScoreSums
    rng = np.random.default_rng(1)
    n, m, p = 500, 4, 3
    white = rng.normal(size=(n, m))
    white[rng.random((n, m)) < 0.2] = np.nan
    J3 = rng.normal(size=(n, m, p))
    J3[~np.isfinite(white)] = 0.0
    bounds = [0, 170, 333, n]
    rho, var = np.array([0.3, 0.9, -0.2, 0.0]), np.array([1.0, 0.5, 2.0, 1.2])
    whole, _ = ar1_covariance(J3.reshape(n * m, p), white, bounds=bounds, rho=rho,
                              variance=var)
    sums = Ar1ScoreSums(rho, var, bounds, p)
    sums.add(0, J3[:5], np.isfinite(white[:5]))     # a pass that is then started again
    sums.start()
    for a, b in [(0, 97), (97, 170), (170, 171), (171, 400), (400, n)]:
        sums.add(a, J3[a:b], np.isfinite(white[a:b]))
    J = J3.reshape(n * m, p)
    np.testing.assert_allclose(sums.covariance(J.T @ J), whole, rtol=1e-12, atol=0)
    # not a white-noise covariance: the correlation matters
    assert not np.allclose(whole, np.linalg.inv(J.T @ J) * 1.0, rtol=0.05)


def test_command_changes_are_taken_between_measured_samples_within_each_run():
    """The change of a command is counted at the next sample with a residual (a command row
    between two odometry samples has none), and not across the boundary of two stacked runs."""
    from auv_ident.core.identification.uncertainty import command_changes
    white = np.array([[0.1], [np.nan], [0.2], [0.3], [0.1], [np.nan], [0.2]])
    U = np.array([[0.0], [1.0], [1.0], [1.0], [5.0], [2.0], [2.0]])
    assert np.allclose(command_changes(white, U), [[np.nan], [np.nan], [1.0], [0.0], [4.0],
                                                   [np.nan], [-3.0]], equal_nan=True)
    # two runs, the second starting at row 4: its first measured row has no change
    assert np.allclose(command_changes(white, U, [0, 4, 7]),
                       [[np.nan], [np.nan], [1.0], [0.0], [np.nan], [np.nan], [-3.0]],
                       equal_nan=True)


def _lag_residuals(seed, size):
    """Residuals of a model that misses a 0.3 s lag of the response to a pilot's stick (held
    1-8 s at random levels, 20 Hz, 600 s): size x (lagged - immediate response) plus AR(1)
    noise of unit variance and a 3 s correlation time; and the stick."""
    rng = np.random.default_rng(seed)
    dt, n = 0.05, 12000
    u = np.zeros(n)
    k = 0
    while k < n:
        hold = int(rng.uniform(1, 8) / dt)
        u[k:k + hold] = rng.choice([-1, 0, 1]) * rng.uniform(0.2, 1)
        k += hold
    lagged = np.zeros(n)
    noise = np.zeros(n)
    rho = np.exp(-dt / 3.0)
    w = rng.standard_normal(n) * np.sqrt(1 - rho ** 2)
    for i in range(1, n):
        lagged[i] = lagged[i - 1] + dt / 0.3 * (u[i - 1] - lagged[i - 1])
        noise[i] = rho * noise[i - 1] + w[i]
    return (size * (lagged - u) + noise)[:, None], u[:, None]


def test_a_lag_under_loud_coloured_noise_shows_against_the_command_changes_not_the_levels():
    """A missed lag leaves residuals that follow each change of the command for a fraction of a
    second: against the held levels (correlated over seconds, so a wide Bartlett variance) it
    stays far under the diagnosis's limit, against the changes it is beyond it; with no lag
    neither is (the BlueROV2 bag of tools/rov_trust_grid.py with a 0.3 s motor lag at 10x
    noise: 4.3 sd against the levels, 10.6 against the changes)."""
    from auv_ident.core.identification.diagnosis import XCORR_Z
    from auv_ident.core.identification.uncertainty import command_changes, input_correlation
    for seed in (1, 2, 3):
        white, U = _lag_residuals(seed, 1.0)
        levels = input_correlation(white, U, 40, ['r'], ['t3'])[0][0]
        changes = input_correlation(white, command_changes(white, U), 40, ['r'], ['t3'])[0][0]
        assert abs(levels) < 2.0 < XCORR_Z < abs(changes), (seed, levels, changes)
        white, U = _lag_residuals(seed, 0.0)
        changes = input_correlation(white, command_changes(white, U), 40, ['r'], ['t3'])[0][0]
        assert abs(changes) < 2.0, (seed, changes)
