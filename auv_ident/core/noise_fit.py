"""Identification with a noise model read off the data (the paper's ARMA idea, done soundly).

The filter assumes white measurement noise of a given level. Real sensors are neither: a
navigation solution or a DVL averages over several pings, so consecutive samples share most of
their error (correlation times of 0.1-10 s), and the level is rarely what the data sheet says.
Treated as white at the stated level, coloured noise biases the EKF pass (it trusts every
sample as new information and chases the noise) and makes every error bar too small.

What this module does, per measured channel j, from the whitened innovations r_j of a first
EKF pass with the configured noise (core/uncertainty.py :func:`noise_model`):

- level_j = RMS(r_j): how much noisier the channel is than assumed;
- rho_j = the lag-1 autocorrelation of r_j (first-order, AR(1), noise);
- the long-run variance of an AR(1) process is sigma^2 (1 + rho) / (1 - rho): the variance a
  white noise would need to carry the same information about slowly varying quantities such as
  the coefficients. The effective 1-sigma
      sigma_eff_j = sigma_j * level_j * sqrt((1 + rho_j) / (1 - rho_j))
  replaces the configured one when the data say the noise model is materially wrong
  (NOISE_MODEL_CHANGE: some channel's variance off by more than that factor either way).
  Measured on NPS AUV II with AR(1) noise, tau 1 s, twice the documented level (600 s, 20 Hz,
  4 seeds): the EKF pass went from errors of 2-28 sigma (Z_q -4 to -60 %) to within 1.9 sigma
  (median |error|/sigma 0.92), the refined estimate kept its accuracy.
- the refined coefficients' covariance is the sandwich (Newey-West) covariance of
  core/uncertainty.py, which stays valid whatever correlation is left in the residuals; it is
  used when it is materially wider than the white-noise one (SANDWICH_WIDER).

With noise that matches the configuration (white, right level) nothing changes: the same numbers
as without this step.
"""
from dataclasses import dataclass, field, replace
import math

import numpy as np

from .batch import refine, run_ekf
from .errors import DivergenceError, DomainError
from .filter import AugmentedEKF
from .state import STATE_NAMES
from .timing import nominal_sample_time
from .uncertainty import noise_model, sandwich_covariance

NOISE_MODEL_CHANGE = 1.5    # a channel's effective variance off by this factor: use the model
SANDWICH_WIDER = 1.2        # sandwich 1-sigma wider than the white one by this: use it
RETRY_NOISE_FACTORS = (3.0, 10.0)   # noise scalings tried when the configured pass fails
MAX_RHO = 0.995             # AR(1) coefficient used at most (a random walk has no long-run var)


@dataclass
class NoiseFit:
    """The noise model of a record and what was done with it.

    model : per channel name, noise_model()'s dict (level, ar1, tau_s, ljung_box, p_white,
        white, samples), from the innovations of the EKF pass with the configured noise
    configured_std, effective_std : (12,) the configured and the effective 1-sigma
    used : True if the effective noise replaced the configured one
    covariance : 'white' ((J^T J)^-1 times the residual variance) or 'sandwich'
    inflation : (p,) sandwich 1-sigma / white 1-sigma of each coefficient
    lags : the sandwich's lag window (samples)
    """

    model: dict
    configured_std: np.ndarray
    effective_std: np.ndarray
    used: bool
    covariance: str = 'white'
    inflation: np.ndarray = None
    lags: int = 0
    refine_converged: bool = True
    refine_message: str = ''
    notes: list = field(default_factory=list)
    white: np.ndarray = None        # (N, 12) whitened innovations at the refined solution
    jacobian: np.ndarray = None     # (N * 12, p) their Jacobian w.r.t. the coefficients
    # the EKF pass whose estimate is reported (the configured noise's, or the effective
    # noise's when used): {'stats', 'hist', 'R', 'Q', 'theta0'} (core.batch.run_ekf's)
    ekf_run: dict = None
    configured_pass: dict = None    # the same for the pass with the configured noise

    def document(self):
        """JSON-ready dict (the result's `noise_model`)."""
        return {
            'channels': {n: {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                             for k, v in d.items()} for n, d in self.model.items()},
            'configured_std': [float(v) for v in self.configured_std],
            'effective_std': [float(v) for v in self.effective_std],
            'used': bool(self.used), 'covariance': self.covariance,
            'inflation': None if self.inflation is None else [float(v) for v in self.inflation],
            'lags': int(self.lags), 'notes': list(self.notes)}


def effective_std(configured_std, model, measured):
    """(12,) 1-sigma carrying the channel's level and AR(1) correlation (module docstring);
    channels without a model (unmeasured, too few samples) keep the configured value."""
    out = np.asarray(configured_std, dtype=float).copy()
    for j, name in enumerate(STATE_NAMES):
        d = model.get(name)
        if d is None or not measured[j]:
            continue
        rho = min(max(d['ar1'], 0.0), MAX_RHO)
        out[j] *= d['level'] * math.sqrt((1.0 + rho) / (1.0 - rho))
    return out


def _pass_record(f, stats, hist):
    return {'stats': stats, 'hist': hist, 'R': f.R.copy(), 'Q': f.Q.copy(),
            'theta0': f.theta0.copy(), 'theta': f.theta.copy(), 'theta_cov': f.theta_cov.copy(),
            'mean_nis_per_dof': float(stats[2] / max(1.0, stats[3])), 'steps': int(stats[1])}


def fit_noise(model, cfg, t, Y, U, T=None, max_step=None, max_bridge=0.25, hist_every=0):
    """Noise model of a record from an EKF pass with the configured noise. Returns NoiseFit
    (used = whether the effective noise should replace the configured one; configured_pass =
    that EKF pass, with histories every hist_every samples).

    If that pass leaves the model's domain or diverges (noise far above the configured level
    makes an over-confident filter chase it, e.g. into a negative surge speed), the pass is
    made again with the noise scaled by RETRY_NOISE_FACTORS in turn, the noise model is read
    off the first pass that completes (its levels relative to that scaled noise), and a note
    says so; only if every pass fails is the last error raised."""
    T = nominal_sample_time(t) if T is None else T
    conf = np.asarray(cfg.noise_std, dtype=float)
    failures = []
    for factor in (1.0,) + RETRY_NOISE_FACTORS:
        base = conf * factor
        f = AugmentedEKF(model, cfg if factor == 1.0 else replace(cfg, noise_std=base), T)
        try:
            stats, hist, white = run_ekf(f, t, Y, U, hist_every=hist_every, want_white=True,
                                         max_step=max_step, max_bridge=max_bridge)
            break
        except (DomainError, DivergenceError) as err:
            failures.append((factor, err))
    else:
        raise failures[-1][1]
    nm = noise_model(white, T, STATE_NAMES)
    eff = effective_std(base, nm, np.asarray(cfg.measured, dtype=bool))
    ratio = (eff / conf) ** 2
    used = bool(factor != 1.0 or np.any((ratio > NOISE_MODEL_CHANGE)
                                        | (ratio < 1.0 / NOISE_MODEL_CHANGE)))
    fit = NoiseFit(model=nm, configured_std=conf, effective_std=eff if used else conf.copy(),
                   used=used, configured_pass=_pass_record(f, stats, hist))
    if failures:
        fit.notes.append(
            f'the EKF with the configured noise failed ({failures[0][1]}): the noise is far '
            f'above the configured level; the noise model was read off a pass with {factor:g}x '
            'the configured noise')
    if used:
        worst = max(nm, key=lambda n: abs(math.log(ratio[STATE_NAMES.index(n)])))
        d = nm[worst]
        fit.notes.append(
            f'the measurement noise is not what was configured: e.g. {worst} is '
            f'{d["level"] * factor:.2g}x the assumed level with a lag-1 correlation of '
            f'{d["ar1"]:.2f} (time constant {d["tau_s"]:.2g} s); identified with the noise '
            'model from the data (effective 1-sigma = level x sqrt((1 + rho) / (1 - rho)) x '
            'configured)')
    return fit


def identify_with_noise_model(model, cfg, t, Y, U, T=None, refine_pass=True, max_step=None,
                              max_bridge=0.25, progress=None, ekf_pass=None, hist_every=0):
    """EKF pass and refinement with the noise model from the data.

    ekf_pass : (estimate, covariance) of an EKF pass already made with the configured noise
        (e.g. the bag replay, the live node's path), kept when the configured noise holds
    Returns (ekf_estimate, ekf_cov, estimate, cov, NoiseFit): the EKF pass with the effective
    noise (or ekf_pass), and (refine_pass) the refined estimate, started from the EKF pass,
    with the covariance the residuals support (module docstring); without refine_pass
    estimate, cov are the EKF pass's. The reported EKF pass's record (histories every
    hist_every samples, final R and Q) is fit.ekf_run (None when ekf_pass was kept)."""
    T = nominal_sample_time(t) if T is None else T
    fit = fit_noise(model, cfg, t, Y, U, T, max_step, max_bridge, hist_every=hist_every)
    cfg_eff = replace(cfg, noise_std=fit.effective_std.copy()) if fit.used else cfg
    if ekf_pass is not None and not fit.used:
        ekf_est, ekf_cov = (np.array(a, dtype=float) for a in ekf_pass)
    elif not fit.used:      # the configured noise holds: its pass is the EKF pass
        fit.ekf_run = fit.configured_pass
        ekf_est, ekf_cov = fit.ekf_run['theta'], fit.ekf_run['theta_cov']
    else:
        f = AugmentedEKF(model, cfg_eff, T)
        stats, hist, _ = run_ekf(f, t, Y, U, hist_every=hist_every, max_step=max_step,
                                 max_bridge=max_bridge)
        fit.ekf_run = _pass_record(f, stats, hist)
        ekf_est, ekf_cov = f.theta.copy(), f.theta_cov.copy()
    if not refine_pass or model.p == 0:
        return ekf_est, ekf_cov, ekf_est, ekf_cov, fit
    est, cov, _, info = refine(model, cfg_eff, t, Y, U, ekf_est, T=T, max_step=max_step,
                               max_bridge=max_bridge, progress=progress, details=True)
    fit.refine_converged = bool(info['converged'])
    fit.white, fit.jacobian = info['white'], info['J']
    fit.refine_message = str(info['message'])
    try:
        sand, sinfo = sandwich_covariance(info['J'], info['white'])
    except np.linalg.LinAlgError:
        return ekf_est, ekf_cov, est, cov, fit
    white_sd = np.sqrt(np.diag(cov))
    fit.inflation = np.sqrt(np.clip(np.diag(sand), 0.0, None)) / white_sd
    fit.lags = sinfo['lags']
    if np.any(fit.inflation > SANDWICH_WIDER):
        fit.covariance = 'sandwich'
        cov = sand
    return ekf_est, ekf_cov, est, cov, fit
