"""Error bars that hold when the residuals are not white, the noise model read off the
residuals, and what the data can identify.

The batch refinement minimises ``sum_k r_k^T r_k`` over the whitened innovations
``r_k = S_k^{-1/2} nu_k`` (12 channels per sample, NaN where a channel is missing). If the
filter's noise model were right, the r_k would be white with unit variance and the coefficient
covariance would be ``(J^T J)^-1`` (J: the Jacobian of the stacked r with respect to theta).
Real sensors are coloured and their level is not what the file says, so:

- :func:`sandwich_covariance`: the covariance of an M-estimator with serially correlated
  scores, ``A^-1 B A^-1`` with ``A = J^T J`` and B the long-run covariance of the per-sample
  scores ``g_k = J_k^T r_k`` (Newey & West 1987, Bartlett weights). This is the estimator
  Morelli & Klein (1995, "Accurate parameter uncertainty estimation from flight data with
  coloured residuals") use for output-error flight data, written for the filter-error
  residuals. It covers a wrong noise level and any residual correlation, per channel and
  across channels, without a model of the noise. Its lag window L comes from the residuals
  (:func:`bandwidth`).
- :func:`noise_model`: per channel, the level of the innovations against the filter's
  prediction, the first-order (AR(1)) correlation and its time constant, and a Ljung-Box test
  of whiteness: what the report and the diagnosis say about the data.
- :func:`identifiability`: per coefficient the Cramer-Rao bound from the information the run
  carries, its largest correlation with another coefficient, and a verdict.

Everything here is plain numpy/scipy on arrays (no filter state), so the refinement, the
methods comparison and the report share it.
"""
from collections.abc import Sequence
import math
from typing import Any

import numpy as np

from auv_ident.core import chi2

# Verdicts of :func:`identifiability` (relative 1-sigma = CRB 1-sigma / |estimate|)
REL_STD_IDENTIFIABLE = 0.05     # below this: 'identifiable'
REL_STD_WEAK = 0.5              # up to this: 'weak'; above: 'not excited'
CORRELATION_WEAK = 0.95         # |correlation| with another coefficient above this: 'weak'
LJUNG_BOX_LAGS = 20             # lags of the whiteness test
WHITENESS_P = 1e-3              # p-value below which a channel's residuals are not white
MAX_BANDWIDTH_FRACTION = 0.1    # the sandwich's lag window is at most this fraction of N
DIRECT_MAX_LAG = 32             # autocorrelation by shifted dot products up to this lag, then FFT
SANDWICH_BLOCK = 4096           # samples of the Jacobian masked at once (sandwich_covariance)

# per coefficient name, its verdict (identifiability(): the 1-sigma, correlations, ...)
Verdicts = dict[str, dict[str, Any]]

def _finite_channels(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, m) residuals with NaN where missing -> same array with NaN set to 0, and mask."""
    r = np.asarray(r, dtype=float)
    ok = np.isfinite(r)
    return np.where(ok, r, 0.0), ok


def _lagged_products(a: np.ndarray, b: np.ndarray, max_lag: int) -> np.ndarray:
    """sum_k a[k + l] b[k] for l = 0..max_lag (FFT, zero-padded: no wrap-around)."""
    n = a.shape[0]
    nfft = 1 << int(2 * n - 1).bit_length()
    spec = np.fft.rfft(a, nfft) * np.conj(np.fft.rfft(b, nfft))
    return np.fft.irfft(spec, nfft)[:max_lag + 1]


def _pair_sums_direct(z: np.ndarray, ok: np.ndarray,
                      lags: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`autocorrelation`'s four sums over the pairs l = 0..lags apart, by dot products
    over shifted slices: (pairs, sum z[k + l] z[k], sum z[k + l]^2, sum z[k]^2), each
    (lags + 1,). z: (N,) with 0 where missing, ok: (N,) bool, the samples present.

    For the few lags of the whiteness test this is ~40x faster than the FFT's four products
    of the padded length (N = 6000, 20 lags: 35 us against 1.3 ms a channel; the live noise
    learner fits 12 channels every 100 updates) and exact to the FFT's rounding. With no
    sample missing the pairs are N - l and the squares' sums the total less the few samples
    a lag leaves out at either end (one dot product a lag)."""
    n = z.shape[0]
    shifts = range(lags + 1)
    sums = np.array([np.dot(z[k:], z[:n - k]) for k in shifts])
    z2 = z * z
    if ok.all():
        total = float(np.sum(z2))
        head = np.concatenate(([0.0], np.cumsum(z2[:lags])))       # sum of the first l
        tail = np.concatenate(([0.0], np.cumsum(z2[::-1][:lags])))  # sum of the last l
        return n - np.arange(lags + 1.0), sums, total - head, total - tail
    okf = ok.astype(float)
    pairs = np.array([np.dot(okf[k:], okf[:n - k]) for k in shifts])
    later = np.array([np.dot(z2[k:], okf[:n - k]) for k in shifts])
    earlier = np.array([np.dot(okf[k:], z2[:n - k]) for k in shifts])
    return pairs, sums, later, earlier


def autocorrelation(x: np.ndarray, max_lag: int) -> np.ndarray:
    """Sample autocorrelation of one channel for lags 0..max_lag (NaN samples skipped).

    Parameters
    ----------
    x : (N,) residuals of one channel (any unit; NaN = missing)
    max_lag : int, largest lag (samples)

    Returns
    -------
    (max_lag + 1,) autocorrelation, rho[0] = 1 (all NaN if the channel has under 3 samples or
    is constant); lag l is the correlation of the pairs of samples l apart that are both
    present: sum z[k + l] z[k] over the pairs, divided by the root of the product of the two
    members' own sums of squares over the same pairs (z: x less its mean). By Cauchy-Schwarz
    |rho[l]| <= 1 whatever the gaps; dividing by the variance of all samples instead (the
    textbook estimator, exact without gaps) reads above 1 when the pairs are the samples of
    larger variance (a bag's odometry rows between command rows: lag-1 correlation 1.03-1.13
    for a channel whose pairs correlate 0.994).
    """
    x = np.asarray(x, dtype=float)
    ok = np.isfinite(x)
    out = np.full(max_lag + 1, np.nan)
    if ok.sum() < 3:
        return out
    z = np.where(ok, x - x[ok].mean(), 0.0)
    if not np.any(z != 0.0):
        return out
    lags = min(max_lag, len(z) - 1)
    if lags <= DIRECT_MAX_LAG:
        pairs, sums, later, earlier = _pair_sums_direct(z, ok, lags)
    else:
        okf = ok.astype(float)
        pairs = np.rint(_lagged_products(okf, okf, lags))
        sums = _lagged_products(z, z, lags)
        z2 = z * z
        later = _lagged_products(z2, okf, lags)      # sum z[k + l]^2 over the pairs
        earlier = _lagged_products(okf, z2, lags)    # sum z[k]^2 over the pairs
    norm = np.sqrt(np.clip(later, 0.0, None) * np.clip(earlier, 0.0, None))
    # the FFT's rounding (1e-16 of the whole sum) must not carry a ratio past +-1
    tiny = 1e-12 * float(np.dot(z, z))
    with np.errstate(invalid='ignore', divide='ignore'):
        out[:lags + 1] = np.where((pairs > 0) & (norm > tiny),
                                  np.clip(sums / norm, -1.0, 1.0), np.nan)
    out[0] = 1.0
    return out


def ljung_box(rho: np.ndarray, n: int) -> tuple[float, float]:
    """Ljung-Box statistic and p-value of autocorrelations rho[1..h] from n samples."""
    h = len(rho) - 1
    lags = np.arange(1, h + 1)
    r = np.nan_to_num(rho[1:], nan=0.0)
    q = float(n * (n + 2) * np.sum(r ** 2 / (n - lags)))
    return q, float(chi2.sf(q, h))


def noise_model(white: np.ndarray, dt: float,
                names: Sequence[str] | None = None) -> dict[str, dict[str, Any]]:
    """What the whitened innovations say about the noise model, per channel.

    Parameters
    ----------
    white : (N, m) whitened innovations r = nu / sqrt(S_jj) of a filter run (NaN = missing)
    dt : float, s, the median sample interval (for the correlation time)
    names : m channel names (default 'c0', 'c1', ...)

    Returns
    -------
    dict name -> {'level': RMS of r (1 = the filter's noise model holds the level; above 1 the
    data are noisier than assumed), 'ar1': lag-1 autocorrelation, 'tau_s': the first-order
    correlation time -dt / ln(ar1) (0 for white, inf if ar1 >= 1), 'ljung_box': statistic,
    'p_white': its p-value, 'white': p_white >= WHITENESS_P, 'samples': count}.
    Channels with fewer than LJUNG_BOX_LAGS + 2 samples are left out.
    """
    white = np.asarray(white, dtype=float)
    m = white.shape[1]
    names = list(names) if names is not None else [f'c{j}' for j in range(m)]
    out = {}
    channels = np.ascontiguousarray(white.T)   # each channel's samples side by side: faster
    for j in range(m):
        x = channels[j]
        ok = np.isfinite(x)
        n = int(ok.sum())
        if n < LJUNG_BOX_LAGS + 2:
            continue
        rho = autocorrelation(x, LJUNG_BOX_LAGS)
        q, p = ljung_box(rho, n)
        a1 = float(rho[1]) if np.isfinite(rho[1]) else 0.0
        if a1 <= 0.0:
            tau = 0.0
        elif a1 >= 1.0:
            tau = math.inf
        else:
            tau = -dt / math.log(a1)
        out[names[j]] = {'level': float(np.sqrt(np.mean(x[ok] ** 2))), 'ar1': a1,
                         'tau_s': tau, 'ljung_box': q, 'p_white': p,
                         'white': bool(p >= WHITENESS_P), 'samples': n,
                         'acf': [float(v) for v in np.nan_to_num(rho, nan=0.0)]}
    return out


def bandwidth(white: np.ndarray, max_lag: int | None = None) -> int:
    """Lag window (samples) for :func:`sandwich_covariance`, from the residuals' correlation.

    Andrews (1991)'s plug-in rule for the Bartlett kernel with an AR(1) fit per channel:
    L = 1.1447 (alpha N)^(1/3), alpha = 4 rho^2 / ((1 - rho)^2 (1 + rho)^2), taking the
    largest over the channels (the most correlated channel sets the window), at least 1 and at
    most MAX_BANDWIDTH_FRACTION * N (or max_lag).
    """
    white = np.asarray(white, dtype=float)
    n = white.shape[0]
    cap = max(1, int(MAX_BANDWIDTH_FRACTION * n)) if max_lag is None else int(max_lag)
    best = 1.0
    for j in range(white.shape[1]):
        rho = autocorrelation(white[:, j], 1)[1]
        if not np.isfinite(rho) or rho <= 0.0:
            continue
        rho = min(rho, 0.999)
        alpha = 4.0 * rho ** 2 / ((1.0 - rho) ** 2 * (1.0 + rho) ** 2)
        best = max(best, 1.1447 * (alpha * n) ** (1.0 / 3.0))
    return int(min(cap, max(1, math.ceil(best))))


def long_run_variance(g: np.ndarray, lags: int) -> float:
    """Long-run variance of one series of scores g (N,) (NaN-free), the Newey-West estimate
    with Bartlett weights: sum_k g_k^2 + 2 sum_{l=1..L} (1 - l/(L+1)) sum_k g_k g_{k-l}
    (:func:`sandwich_covariance`'s B for one parameter; lags L in samples)."""
    g = np.asarray(g, dtype=float)
    lags = int(max(0, min(lags, g.shape[0] - 1)))
    ac = _lagged_products(g, g, lags)
    w = 1.0 - np.arange(lags + 1) / (lags + 1.0)
    return float(ac[0] + 2.0 * np.sum(w[1:] * ac[1:]))


def with_gaps(parts: Sequence[np.ndarray], gap: int) -> np.ndarray:
    """The arrays of several runs (each (N_i, ...)) stacked with `gap` rows of NaN between
    consecutive runs: autocorrelations and cross-correlations over at most `gap` lags
    (autocorrelation(), input_correlation(), which skip NaN samples) then never pair samples
    of different runs. One run: returned as it is (a float copy)."""
    parts = [np.asarray(a, dtype=float) for a in parts]
    if len(parts) == 1:
        return parts[0].copy()
    pad = np.full((int(gap),) + parts[0].shape[1:], np.nan)
    out = [parts[0]]
    for a in parts[1:]:
        out.extend((pad, a))
    return np.concatenate(out)


def split_rows(a: np.ndarray, bounds: Sequence[int]) -> list[np.ndarray]:
    """The list of a[bounds[i]:bounds[i + 1]]: stacked runs back into one array per run."""
    return [a[bounds[i]:bounds[i + 1]] for i in range(len(bounds) - 1)]


def sandwich_covariance(J: np.ndarray, white: np.ndarray, lags: int | None = None,
                        bounds: Sequence[int] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """Coefficient covariance of the least-squares fit, valid under correlated residuals.

    Parameters
    ----------
    J : (N * m, p) Jacobian of the stacked residuals r (row k * m + j: sample k, channel j)
        with respect to the coefficients
    white : (N, m) the residuals at the solution (NaN = missing; those rows of J count zero)
    lags : lag window L in samples (default :func:`bandwidth`)
    bounds : None (one run) or the sample indices where the stacked runs start and end
        ([0, N_1, N_1 + N_2, ..., N]): the lagged score products are summed within each run
        only (independent runs share no correlation)

    Returns
    -------
    cov : (p, p) ``A^-1 B A^-1``, A = J^T J, B = sum_{|l| <= L} (1 - |l|/(L+1)) Gamma_l,
        Gamma_l = sum_k g_k g_{k-l}^T, g_k = J_k^T r_k (the score of sample k)
    info : dict with 'lags', 'naive_cov' (A^-1 times the residual variance), and
        'inflation' (p,) = sqrt(diag(cov) / diag(A^-1)): how much wider the bars are than
        those of a white-noise model with the assumed level
    """
    white = np.asarray(white, dtype=float)
    n, m = white.shape
    p = J.shape[1]
    r, ok = _finite_channels(white)
    J3 = np.asarray(J, dtype=float).reshape(n, m, p)
    g = np.empty((n, p))                            # (N, p) scores
    A = np.zeros((p, p))
    # in blocks of samples: a masked copy of the whole Jacobian would be as large as J
    # (35 MB for an hour at 20 Hz; docs/reliability.md, bounded memory)
    for k in range(0, n, SANDWICH_BLOCK):
        Jk = J3[k:k + SANDWICH_BLOCK] * ok[k:k + SANDWICH_BLOCK, :, None]
        g[k:k + SANDWICH_BLOCK] = np.einsum('kmp,km->kp', Jk, r[k:k + SANDWICH_BLOCK])
        A += np.einsum('kmp,kmq->pq', Jk, Jk)
    return sandwich_from_sums(A, g, white, lags=lags, bounds=bounds)


def sandwich_from_sums(A: np.ndarray, g: np.ndarray, white: np.ndarray,
                       lags: int | None = None, bounds: Sequence[int] | None = None
                       ) -> tuple[np.ndarray, dict[str, Any]]:
    """:func:`sandwich_covariance` from the sums it is made of, for a Jacobian that is never
    formed whole (the refinement's, core/identification/levenberg_marquardt.py).

    A : (p, p) J^T J over the rows with a residual; g : (N, p) the per-sample scores
    g_k = J_k^T r_k; white : (N, m) the residuals (NaN = missing); lags, bounds, and the
    returned (cov, info): as for sandwich_covariance."""
    white = np.asarray(white, dtype=float)
    A = np.asarray(A, dtype=float)
    g = np.asarray(g, dtype=float)
    n = white.shape[0]
    p = A.shape[0]
    if g.shape != (n, p):
        raise ValueError(f'scores {g.shape} do not match {n} samples and {p} parameters')
    r, ok = _finite_channels(white)
    bounds = [0, n] if bounds is None else [int(b) for b in bounds]
    if bounds[0] != 0 or bounds[-1] != n or np.any(np.diff(bounds) < 0):
        raise ValueError(f'bounds {bounds} must rise from 0 to the {n} samples')
    if lags is None:
        # bandwidth() looks at lag 1 only: one NaN row between runs keeps it within each run
        lags = bandwidth(with_gaps(split_rows(white, bounds), 1),
                         max_lag=max(1, int(MAX_BANDWIDTH_FRACTION * n)))
    lags = int(max(0, min(lags, n - 1)))
    B = g.T @ g
    for gs in split_rows(g, bounds):
        for lag in range(1, min(lags, gs.shape[0] - 1) + 1):
            w = 1.0 - lag / (lags + 1.0)
            G = gs[lag:].T @ gs[:-lag]
            B += w * (G + G.T)
    A_inv = np.linalg.inv(A)
    cov = A_inv @ B @ A_inv
    cov = 0.5 * (cov + cov.T)
    used = int(ok.sum())
    s2 = float(np.sum(r ** 2)) / max(1, used - p)
    with np.errstate(invalid='ignore', divide='ignore'):
        inflation = np.sqrt(np.diag(cov) / np.diag(A_inv))
    return cov, {'lags': lags, 'naive_cov': A_inv * s2, 'inflation': inflation}


def ar1_covariance(J: np.ndarray, white: np.ndarray, bounds: Sequence[int] | None = None,
                   rho: np.ndarray | None = None,
                   variance: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Coefficient covariance of the least-squares fit when each channel's residuals are
    first-order (AR(1)) noise, its correlation and level given (the noise model the fit's
    weights came from) or read off those residuals.

    The fit's covariance under any noise is ``A^-1 B A^-1``, A = J^T J, B the covariance of the
    score J^T r. For AR(1) residuals of lag-1 correlation rho_j and mean square v_j per channel
    B = sum_j v_j J_j^T Gamma_j J_j, Gamma_j[k, l] = rho_j^|k - l| (k, l: channel j's samples
    within one run). Its two limits: sensitivities constant over the correlation time give
    J_j^T Gamma_j J_j = (1 + rho_j) / (1 - rho_j) J_j^T J_j, the long-run variance the noise
    model's effective 1-sigma (core/identification/noise_fit.py) puts in the white-noise
    covariance (J^T J)^-1, which is then exact; sensitivities that change within it (a
    thruster vehicle's stick steps against noise correlated over 1-3 s, or position
    innovations over minutes) carry more information than that bound allows, and B says how
    much. Unlike :func:`sandwich_covariance` it needs no lag window (the model's correlation
    reaches every lag) and no estimate of the long-run score covariance, whose Bartlett window
    reads low when the window is a large part of the run; it holds as far as the AR(1) model
    does (the sandwich is the check, core/identification/noise_fit.py).

    Parameters
    ----------
    J : (N * m, p) Jacobian of the stacked residuals (row k * m + j: sample k, channel j)
    white : (N, m) the residuals at the solution (NaN = missing)
    bounds : None (one run) or the rows where the stacked runs start and end ([0, ..., N]);
        the correlation acts within each run only
    rho, variance : (m,) or None, each channel's lag-1 correlation and the variance of its
        residuals (their unit); None or NaN: read off the residuals (lag-1 correlation of the
        channel's own consecutive samples, mean square)

    Returns
    -------
    cov : (p, p) the covariance; rho : (m,) each channel's lag-1 correlation (NaN: no
    samples); lags count a channel's own samples (its missing rows dropped), as the samples
    its noise correlates
    """
    white = np.asarray(white, dtype=float)
    n, m = white.shape
    p = J.shape[1]
    J3 = np.asarray(J, dtype=float).reshape(n, m, p)
    bounds = [0, n] if bounds is None else [int(b) for b in bounds]
    present = np.isfinite(white)
    rhos = np.full(m, np.nan)
    var = np.ones(m)
    for j in range(m):
        if present[:, j].sum() < 3:
            continue
        r1 = math.nan if rho is None else float(rho[j])
        if not np.isfinite(r1):
            runs = [np.flatnonzero(present[a:b, j]) + a for a, b in zip(bounds[:-1], bounds[1:])]
            r1 = autocorrelation(with_gaps([white[k, j] for k in runs if k.size], 1), 1)[1]
        rhos[j] = float(np.clip(np.nan_to_num(r1), -1.0, 1.0))
        v = math.nan if variance is None else float(variance[j])
        var[j] = v if np.isfinite(v) else float(np.mean(white[present[:, j], j] ** 2))
    sums = Ar1ScoreSums(np.nan_to_num(rhos), var, bounds, p)
    sums.add(0, J3, present & np.isfinite(rhos)[None, :])
    A = np.einsum('kjp,kjq->pq', J3 * present[:, :, None], J3 * present[:, :, None])
    return sums.covariance(A), rhos


class Ar1ScoreSums:
    """The score covariance B of :func:`ar1_covariance` summed a chunk of samples at a time
    (the refinement never holds the whole Jacobian: core/identification/levenberg_marquardt.py).

    B = sum_j v_j (S_j + S_j^T - X_j^T X_j), S_j = sum_k X_jk^T a_jk with a_jk = X_jk +
    rho_j a_j(k-1) the causal AR(1) filter of channel j's rows X_jk (p,) over its own present
    samples within a run (Gamma X = the causal plus the anti-causal sum less X, and the
    anti-causal one's products are the causal one's transposed); the filter's state is carried
    from chunk to chunk and reset where a run starts.

    rho, variance : (m,) each channel's lag-1 correlation and residual variance; bounds : the
    sample rows where the stacked runs start and end ([0, ..., N]); p : the parameters."""

    def __init__(self, rho: np.ndarray, variance: np.ndarray, bounds: Sequence[int], p: int):
        self.rho = np.asarray(rho, dtype=float)
        self.variance = np.asarray(variance, dtype=float)
        self.starts = {int(b) for b in bounds}
        self.p = p
        self.start()

    def start(self) -> None:
        """Empty sums (a new pass over the samples)."""
        m, p = self.rho.size, self.p
        self.S = np.zeros((m, p, p))
        self.XX = np.zeros((m, p, p))
        self.state = np.zeros((m, p))

    def add(self, at: int, J3: np.ndarray, present: np.ndarray) -> None:
        """Samples at .. at + K - 1: J3 (K, m, p) their rows of the Jacobian, present (K, m)
        which of them are measured (the others skipped: no step of the channel's noise)."""
        from scipy.signal import lfilter
        K = J3.shape[0]
        cuts = sorted(k - at for k in self.starts if at <= k < at + K)
        for j in range(self.rho.size):
            r1 = self.rho[j]
            for a, b in zip([0] + cuts, cuts + [K]):
                if a > 0 or at in self.starts:
                    self.state[j] = 0.0     # a run starts: its noise owes nothing to the last
                X = J3[a:b, j, :][present[a:b, j]]
                if not X.shape[0]:
                    continue
                # a_k = X_k + rho a_(k-1), from the carried a (lfilter: y_0 = x_0 + zi)
                ahead, _ = lfilter([1.0], [1.0, -r1], X, axis=0,
                                   zi=(r1 * self.state[j])[None, :])
                self.state[j] = ahead[-1]
                self.S[j] += X.T @ ahead
                self.XX[j] += X.T @ X

    def covariance(self, A: np.ndarray) -> np.ndarray:
        """A^-1 B A^-1 for the information A = J^T J (p, p); LinAlgError if A is singular."""
        B = np.einsum('j,jpq->pq', self.variance,
                      self.S + np.transpose(self.S, (0, 2, 1)) - self.XX)
        A_inv = np.linalg.inv(A)
        cov = A_inv @ B @ A_inv
        return 0.5 * (cov + cov.T)


def identifiability(J: np.ndarray, estimate: np.ndarray, names: Sequence[str],
                    cov: np.ndarray | None = None,
                    absolute_std: np.ndarray | None = None) -> Verdicts:
    """Per coefficient: how well the run determines it, from its sensitivities.

    Parameters
    ----------
    J : (K, p) Jacobian of whitened residuals w.r.t. the coefficients (its J^T J is the Fisher
        information of the run under the filter's noise model)
    estimate : (p,) the coefficients (for relative figures)
    names : p names
    cov : (p, p) covariance to report the 1-sigma from (default the Cramer-Rao bound
        (J^T J)^-1; pass the sandwich covariance for honest figures under coloured residuals)
    absolute_std : (p,) or None, per parameter a 1-sigma to judge it by instead of the
        relative one (NaN: relative), see :func:`verdicts_from_covariance`

    Returns
    -------
    dict name -> {'crb_std': 1-sigma, 'rel_std': 1-sigma / |estimate|, 'max_correlation':
    largest |correlation| with another coefficient, 'correlated_with': that coefficient,
    'verdict': 'identifiable' (rel_std < REL_STD_IDENTIFIABLE and max |correlation| <=
    CORRELATION_WEAK), 'weak' (rel_std < REL_STD_WEAK, or a correlation above
    CORRELATION_WEAK) or 'not excited' (rel_std >= REL_STD_WEAK, or no information)}.
    """
    J = np.asarray(J, dtype=float)
    return identifiability_from_information(J.T @ J, estimate, names, cov=cov,
                                            absolute_std=absolute_std)


def identifiability_from_information(F: np.ndarray, estimate: np.ndarray,
                                     names: Sequence[str], cov: np.ndarray | None = None,
                                     absolute_std: np.ndarray | None = None) -> Verdicts:
    """:func:`identifiability` from the information F = J^T J (p, p) alone (the refinement's
    normal equations, summed without forming J)."""
    F = np.asarray(F, dtype=float)
    if cov is None:
        try:
            cov = np.linalg.inv(F)
        except np.linalg.LinAlgError:
            cov = np.linalg.pinv(F)
    return verdicts_from_covariance(cov, estimate, names, informed=np.diag(F) > 0,
                                    absolute_std=absolute_std)


def verdicts_from_covariance(cov: np.ndarray, estimate: np.ndarray, names: Sequence[str],
                             informed: np.ndarray | None = None,
                             absolute_std: np.ndarray | None = None) -> Verdicts:
    """The verdicts of :func:`identifiability` from a coefficient covariance alone (the batch
    refinement's, or the live EKF's P).

    informed : (p,) bool, whether the data carry any information on each coefficient (batch:
        a positive Fisher diagonal; live: the 1-sigma shrank below its prior's); None: all
    absolute_std : (p,) or None; where finite, the 1-sigma below which the parameter is
        'identifiable' (relative figures mean nothing for a parameter whose value may be 0,
        such as a water-current component); 'not excited' then needs an uninformed parameter
    """
    est = np.asarray(estimate, dtype=float)
    cov = np.asarray(cov, dtype=float)
    p = len(names)
    informed = np.ones(p, dtype=bool) if informed is None else np.asarray(informed, bool)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid='ignore', divide='ignore'):
        corr = cov / np.outer(sd, sd)
    out = {}
    for i, name in enumerate(names):
        others = [j for j in range(p) if j != i]
        if others:
            j_max = max(others, key=lambda j: abs(np.nan_to_num(corr[i, j])))
            c_max = float(abs(np.nan_to_num(corr[i, j_max])))
            partner = names[j_max]
        else:
            c_max, partner = 0.0, None
        rel = float(sd[i] / abs(est[i])) if est[i] != 0 else math.inf
        limit = None if absolute_std is None else absolute_std[i]
        if limit is not None and np.isfinite(limit):
            if not informed[i]:
                verdict = 'not excited'
            elif sd[i] < limit and c_max <= CORRELATION_WEAK:
                verdict = 'identifiable'
            else:
                verdict = 'weak'
        elif not informed[i] or not np.isfinite(rel) or rel >= REL_STD_WEAK:
            verdict = 'not excited'
        elif rel < REL_STD_IDENTIFIABLE and c_max <= CORRELATION_WEAK:
            verdict = 'identifiable'
        else:
            verdict = 'weak'
        out[name] = {'crb_std': float(sd[i]), 'rel_std': rel, 'max_correlation': c_max,
                     'correlated_with': partner, 'verdict': verdict}
    return out


def command_changes(white: np.ndarray, U: np.ndarray,
                    bounds: Sequence[int] | None = None) -> np.ndarray:
    """(N, q) each input's change since the previous sample with a residual, on the rows that
    have one (NaN elsewhere, and on each run's first such row: bounds as for split_rows, None
    for one run). The commands' first differences are the input prewhitened: a pilot's held
    sticks or a slow fin schedule are correlated over seconds, so the cross-correlation with
    their levels has a wide Bartlett variance, while an error in the response to a change (a
    thruster's lag, an actuator's rate) shows against the changes within a fraction of a
    second. Rows without a residual (a command between two odometry samples) are skipped: the
    change is counted at the next measured sample, the first whose prediction it enters."""
    white = np.asarray(white, dtype=float)
    U = np.asarray(U, dtype=float)
    out = np.full_like(U, np.nan)
    starts = [0, U.shape[0]] if bounds is None else list(bounds)
    for a, b in zip(starts[:-1], starts[1:]):
        rows = a + np.flatnonzero(np.isfinite(white[a:b]).any(axis=1))
        out[rows[1:]] = U[rows[1:]] - U[rows[:-1]]
    return out


def input_correlation(white: np.ndarray, U: np.ndarray, max_lag: int,
                      names: Sequence[str] | None = None,
                      input_names: Sequence[str] | None = None,
                      ) -> list[tuple[float, str, str, int]]:
    """Cross-correlation of the residuals with the inputs: does the model leave out something
    the inputs drive? (the residual test of system identification, e.g. MATLAB's `resid`).

    For every measured channel j and every input i that varies, r_ji(l) = corr(white_j[k],
    U_i[k - l]) for l = 0..max_lag, standardised by Bartlett's large-sample variance
    var r(l) ~ (1/n) sum_m rho_jj(m) rho_ii(m), which accounts for the autocorrelation of both
    (coloured sensor noise does not correlate with the inputs, however slow it is; a missing or
    wrong term does).

    Parameters
    ----------
    white : (N, m) residuals (NaN = missing); U : (N, q) inputs on the same samples
    max_lag : largest lag (samples) of the input before the residual

    Returns
    -------
    list of (z, channel name, input name, lag) sorted by |z|, largest first: z = r / sd(r)
    """
    white = np.asarray(white, dtype=float)
    U = np.asarray(U, dtype=float)
    n, m = white.shape
    names = list(names) if names is not None else [f'c{j}' for j in range(m)]
    input_names = (list(input_names) if input_names is not None
                   else [f'u{i}' for i in range(U.shape[1])])
    out: list[tuple[float, str, str, int]] = []
    acf_lags = max(max_lag, LJUNG_BOX_LAGS) * 4
    acf_u = {}
    for i in range(U.shape[1]):
        ui = U[:, i]
        if np.nanstd(ui) <= 0:
            continue
        acf_u[i] = autocorrelation(ui, acf_lags)
    for j in range(m):
        x = white[:, j]
        ok = np.isfinite(x)
        if ok.sum() < 10 * max(1, max_lag):
            continue
        acf_x = autocorrelation(x, acf_lags)
        z_x = np.where(ok, x - x[ok].mean(), 0.0)
        sx = math.sqrt(float(np.mean(z_x[ok] ** 2)))
        if sx <= 0:
            continue
        for i, acf_ui in acf_u.items():
            ui = U[:, i]
            good = ok & np.isfinite(ui)
            zu = np.where(good, ui - ui[good].mean(), 0.0)
            su = math.sqrt(float(np.mean(zu[good] ** 2)))
            if su <= 0:
                continue
            cnt = int(good.sum())
            band = np.nan_to_num(acf_x) * np.nan_to_num(acf_u[i])
            var = (1.0 + 2.0 * float(np.sum(band[1:]))) / cnt
            sd = math.sqrt(max(var, 1.0 / cnt))
            # r(l) = sum_k x[k + l] u[k] over the samples where both are present
            cross = _lagged_products(z_x * good, zu, max_lag) / cnt / (sx * su)
            out.extend((float(r) / sd, names[j], input_names[i], lag)
                       for lag, r in enumerate(cross))
    out.sort(key=lambda e: -abs(e[0]))
    return out
