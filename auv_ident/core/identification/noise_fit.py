"""Identification with a noise model read off the data (the paper's ARMA idea, done soundly).

The filter assumes white measurement noise of a given level. Real sensors are neither: a
navigation solution or a DVL averages over several pings, so consecutive samples share most of
their error (correlation times of 0.1-10 s), and the level is rarely what the data sheet says.
Treated as white at the stated level, coloured noise biases the EKF pass (it trusts every
sample as new information and chases the noise) and makes every error bar too small.

What this module does, per measured channel j, from the whitened innovations r_j of a first
EKF pass with the configured noise (core/identification/uncertainty.py :func:`noise_model`):

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
- the refined coefficients' covariance, when the effective noise was used, is the exact one of
  the fit under the AR(1) noise that effective noise stands for (core/identification/
  uncertainty.py :func:`ar1_covariance` with each channel's rho and, whitened, the variance
  (1 - rho) / (1 + rho): :func:`model_ar1`), not the white-noise (J^T J)^-1 of the effective
  1-sigma. That one is its limit for sensitivities constant over the noise's correlation time:
  a bound nearly met by the fin vehicles (NPS AUV II, AR(1) noise of 0.1-3 s against 5-40 s
  manoeuvres: |error|/sigma within 5 % of the bound's on 3 of 4 seeds, 13 % above on the
  fourth) but put the BlueROV2 Heavy's bars about
  twice too wide (stick steps and sweeps within noise correlated over 1-3 s, positions over
  minutes: NEES 2.5-6.4 against 12 on seeds 3, 5, 7 of offline/independent_rov.py; with this
  covariance seeds 1, 2, 3, 5, 7 give 36 against 60, median |error|/sigma 0.52, all within 3
  sigma). Read off the refined residuals instead, an AR(1) misses their long-range correlation
  (the same seeds: median 1.01, NEES 88 of 60). The Newey-West sandwich of the same module,
  valid whatever correlation is left, replaces it when it is materially wider (SANDWICH_WIDER)
  for some coefficient, never narrowing another's (:func:`never_narrower`).

Model error beyond the configured process noise (a real vehicle: unmodelled forces, filtered
channels whose stated noise is only their sample-to-sample scatter): when some measured
channel's innovations are more than PROCESS_NOISE_LEVEL times their predicted level, the
one-step prediction error is far above what the configured noise allows. That is either
measurement noise far above the configured one (a noise_std given too small, coloured noise
whose sample-to-sample scatter understates it) or model error. The measurement noise is tried
first: an EKF pass with each measured channel's noise multiplied by its level and the
configured process noise (:func:`noise_only_levels`). If that leaves every level within
PROCESS_NOISE_LEVEL, the measurement noise explains the data and the process noise is not
matched (the measurement noise model below is read off the configured pass, as without the
excess). Why: matched to coloured measurement noise, the process noise makes the filter follow
the noisy measurements, the damping is attenuated as in an errors-in-variables fit and the
error bars shrink (a BlueROV2 bag, offline/independent_rov.py seed 3, p 5.05x from the first
estimates: X_u 45 % off at 4.5 sigma under 'consistent'). On NPS AUV II, 60 s, either AR(1)
noise at 10x (tau 1 s; levels 8-14, 0.9-1.1 with the measurement noise alone) or white
acceleration noise of 0.01 on every nu_dot (levels up to 34, 0.7-1.3 alone), seeds 2 and 3:
the EKF pass with the measurement noise model alone within 1.8 and 2.9 sigma of the truth, with
the matched process noise 2.4, 7.9, 3.4 and 1.5 sigma
(tools/noise_explanations.py). Model error a larger measurement noise
does not explain (the HSVA KVLCC2 zig-zags below: r still 16x, y 6.8x) is taken as process noise
(covariance matching, Mehra 1972): the per-step process noise q_j of each measured channel is
multiplied by its innovation level (never lowered) and the pass repeated until every level is
within PROCESS_LEVEL_TOL of 1 (at most MAX_PROCESS_PASSES passes); the measurement noise model
above is then read off that pass. Measured on the HSVA KVLCC2 zig-zags Z_10_10_S + Z_20_10_S
imported as bags (r stated at 6e-7 rad/s): levels u 7.6, v 24.5, r 77 with the default (an
AUV's) process noise; matched in 5 passes, q u 2.9e-4 m/s, v 1.9e-4 m/s, r 3.6e-5 rad/s per
0.05 s step; reported EKF pass NIS/dof 0.66 (1228 before), every coefficient within 0.41 sigma
of the hand-tuned identification (docs/kvlcc2.md, "From bags").

One run or several (a list of core.identification.results.Record; one run is a list of one):
the EKF passes go over the runs in turn (core.identification.batch.run_ekf), the levels and
AR(1) coefficients are pooled over the runs (the whitened innovations of each run stacked with
NUM_GAP rows of NaN between them, so that no lag pairs samples of different runs), the
refinement fits all runs (core.identification.batch.refine) and the sandwich covariance sums the
lagged scores within each run.

With noise that matches the configuration (white, right level) nothing changes: the same numbers
as without this step.
"""
from dataclasses import dataclass, replace
import math

import numpy as np

from auv_ident.core.errors import DivergenceError, DomainError
from auv_ident.core.filter.augmented import AugmentedEKF
from auv_ident.core.filter.timing import nominal_sample_time
from auv_ident.core.identification.batch import refine, run_ekf
from auv_ident.core.identification.plausibility import DEFAULT_Z, is_self_damping
from auv_ident.core.identification.results import Estimate, FilterPass, NoiseFit
from auv_ident.core.identification.uncertainty import (
    LJUNG_BOX_LAGS,
    noise_model,
    sandwich_from_sums,
    with_gaps,
)
from auv_ident.core.model.state import STATE_NAMES

NOISE_MODEL_CHANGE = 1.5    # a channel's effective variance off by this factor: use the model
SANDWICH_WIDER = 1.2        # sandwich 1-sigma wider than the white one by this: use it
RETRY_NOISE_FACTORS = (3.0, 10.0)   # noise scalings tried when the configured pass fails
MAX_RHO = 0.995             # AR(1) coefficient used at most (a random walk has no long-run var)
PROCESS_NOISE_LEVEL = 5.0   # innovations this many times their predicted level: model error
PROCESS_LEVEL_TOL = 1.2     # process noise matched when every level is below this
MAX_PROCESS_PASSES = 12     # EKF passes of the matching at most
MAX_PROCESS_STEP = 10.0     # largest factor on q_j per pass
WRONG_SIGN_NOISE_LEVEL = 1.5    # noise within this of the configured: wrong signs not retried
NUM_GAP = LJUNG_BOX_LAGS    # NaN rows between runs in the pooled innovations (noise_model's lags)


def effective_std(configured_std, model, measured):
    """(12,) 1-sigma carrying the channel's level and AR(1) correlation (module docstring);
    channels without a model (unmeasured, too few samples) keep the configured value."""
    out = np.asarray(configured_std, dtype=float).copy()
    _, var = model_ar1(model, measured)
    for j, name in enumerate(STATE_NAMES):
        if name in model and measured[j]:
            out[j] *= model[name]['level'] / math.sqrt(var[j])
    return out


def model_ar1(model, measured):
    """(12,) lag-1 correlation and (12,) variance of the whitened innovations that the
    effective noise (:func:`effective_std`) assumes: per channel with a model rho (clipped as
    there) and (1 - rho) / (1 + rho), the AR(1) variance over its long-run variance; the other
    channels white of unit variance (their configured noise)."""
    rho, var = np.zeros(len(STATE_NAMES)), np.ones(len(STATE_NAMES))
    for j, name in enumerate(STATE_NAMES):
        d = model.get(name)
        if d is None or not measured[j]:
            continue
        rho[j] = min(max(d['ar1'], 0.0), MAX_RHO)
        var[j] = (1.0 - rho[j]) / (1.0 + rho[j])
    return rho, var


def _pass(model, cfg, runs, T, max_step, max_bridge, hist_every):
    """One EKF pass over the runs in turn (FilterPass, with each run's whitened
    innovations)."""
    return run_ekf(AugmentedEKF(model, cfg, T), runs, hist_every=hist_every, want_white=True,
                   max_step=max_step, max_bridge=max_bridge)


def _pooled(filter_pass):
    """(sum N + gaps, 12) the whitened innovations of a pass, the runs' with NUM_GAP NaN rows
    between them (no lag pairs samples of different runs)."""
    return with_gaps(filter_pass.whites, NUM_GAP)


def _levels(white, measured):
    """(12,) RMS of each measured channel's whitened innovations (NaN: none)."""
    out = np.full(white.shape[1], np.nan)
    for j in np.flatnonzero(measured):
        x = white[:, j]
        x = x[np.isfinite(x)]
        if x.size > LJUNG_BOX_LAGS and np.any(x != 0.0):     # all 0: no information
            out[j] = math.sqrt(float(np.mean(x ** 2)))
    return out


def _informative(model):
    """The channels of a noise model (uncertainty.noise_model) whose innovations carry
    information: a level of exactly 0 (or not finite) says nothing about the noise. It happens
    when every sample of a channel restarted the vehicle states from the measurement (each
    accepted sample more than max_bridge from the last, e.g. when nearly every message was
    rejected): the innovation of a restart is 0 by construction. Such a channel keeps its
    configured noise, as one without samples does."""
    return {name: d for name, d in model.items()
            if math.isfinite(d['level']) and d['level'] > 0.0}


@dataclass
class ProcessMatch:
    """The covariance matching's outcome (match_process_noise): the per-step process noise
    q_state (12,), the last EKF pass (made with it), the passes made and the innovation levels
    (12,) of the last pass."""

    q_state: np.ndarray
    last: FilterPass
    passes: int
    levels: np.ndarray


def match_process_noise(model, cfg, runs, T, first, max_step=None, max_bridge=0.25,
                        hist_every=0):
    """The per-step process noise that explains the one-step prediction errors (module
    docstring: covariance matching). first: the EKF pass with cfg (FilterPass with its
    whitened innovations). Returns a ProcessMatch."""
    measured = np.asarray(cfg.measured, dtype=bool)
    q = np.asarray(cfg.q_state, dtype=float).copy()
    last = first
    levels = _levels(_pooled(first), measured)
    passes = 0
    while passes < MAX_PROCESS_PASSES:
        ok = np.isfinite(levels)
        if not np.any(levels[ok] > PROCESS_LEVEL_TOL):
            break
        step = np.where(ok, np.clip(np.nan_to_num(levels, nan=1.0), 1.0, MAX_PROCESS_STEP), 1.0)
        # a channel without process noise of its own (0) starts from the noise it is measured
        # with: the scale of its one-step errors
        q_new = np.where((q > 0) | ~ok, q, np.asarray(cfg.noise_std, float)) * step
        try:
            trial = _pass(model, replace(cfg, q_state=q_new), runs, T, max_step, max_bridge,
                          hist_every)
        except (DomainError, DivergenceError):
            break
        passes += 1
        q, last = q_new, trial
        levels = _levels(_pooled(trial), measured)
    return ProcessMatch(q, last, passes, levels)


def wrong_signs(model, filter_pass):
    """The identified self-damping and diagonal added-mass coefficients (plausibility.
    is_self_damping) that an EKF pass ended with positive beyond DEFAULT_Z of its own 1-sigma:
    a pass that chased noise far above its configured level into a model no vehicle has. Such
    a pass can complete where another diverges (which one is a matter of the start and of the
    model's couplings: a BlueROV2 whose added-mass Coriolis follows its added mass took its
    X_udot and Y_vdot positive on a simulated tank session with twice the noise), so it is
    retried with more noise as a divergence is."""
    v = model.vehicle
    sd = np.sqrt(np.clip(np.diag(filter_pass.theta_cov), 0.0, None))
    return [name for name, est, s in zip(model.theta_names[:model.p_coef], filter_pass.theta, sd)
            if is_self_damping(v.coefficients[v.index(name)]) and est > DEFAULT_Z * s]


def _noise_as_configured(filter_pass, factor, measured):
    """True if a pass made with factor x the configured noise finds every measured channel's
    noise within WRONG_SIGN_NOISE_LEVEL of the configured level (its innovation levels times
    factor): then a configured pass that ended with wrong signs (wrong_signs) did not chase
    noise above its level. Measured: a 62 s KVLCC2 zig-zag with white noise of the configured
    level ended N_r positive; its 3x pass read 0.32-0.35 (1.05x), and the noise model read off
    that pass made the effective noise 3x too large (Y_v -500 %); the BlueROV2 session of
    wrong_signs' docstring read up to 1.67 at 3x (5x)."""
    lv = _levels(_pooled(filter_pass), measured) * factor
    lv = lv[np.isfinite(lv)]
    return bool(lv.size) and float(np.max(lv)) < WRONG_SIGN_NOISE_LEVEL


def noise_only_levels(model, cfg, runs, T, levels, max_step=None, max_bridge=0.25):
    """(12,) innovation levels of an EKF pass whose measurement noise is cfg's times each
    measured channel's level (levels: cfg's pass's, NaN: kept) and whose process noise is
    cfg's: the measurement noise alone as the explanation of the levels (module docstring).
    None if that pass leaves the model's domain or diverges."""
    scale = np.where(np.asarray(cfg.measured, dtype=bool) & np.isfinite(levels), levels, 1.0)
    cfg_noise = replace(cfg, noise_std=np.asarray(cfg.noise_std, dtype=float) * scale)
    try:
        trial = _pass(model, cfg_noise, runs, T, max_step, max_bridge, 0)
    except (DomainError, DivergenceError):
        return None
    return _levels(_pooled(trial), np.asarray(cfg.measured, dtype=bool))


def _noise_explains_note(levels0, noise_only, measured):
    """The note of a run whose innovation levels crossed PROCESS_NOISE_LEVEL but were
    explained by the measurement noise alone (fit_noise)."""
    big = [j for j in np.flatnonzero(measured) if np.nan_to_num(levels0[j]) > PROCESS_NOISE_LEVEL]
    top = max((j for j in np.flatnonzero(measured) if np.isfinite(noise_only[j])),
              key=lambda j: noise_only[j])
    return ('innovations ' + ', '.join(f'{STATE_NAMES[j]} {levels0[j]:.3g}x' for j in big)
            + f' their predicted level (over {PROCESS_NOISE_LEVEL:g}x), but measurement noise '
            f'at those levels explains them (a pass with it: largest level {STATE_NAMES[top]} '
            f'{noise_only[top]:.2g}x): the process noise was not matched (coloured '
            'measurement noise, not model error)')


def never_narrower(sand, inflation):
    """(p, p) the sandwich covariance sand with each coefficient's 1-sigma raised to the one
    it was compared with where the sandwich's is narrower (inflation: the sandwich's 1-sigma
    over that one): D sand D, D = diag(max(1, 1 / inflation)), the sandwich's correlations.
    Why: the sandwich is chosen when some coefficient's is materially wider, and replacing the
    whole covariance then shrank the others' (a BlueROV2 bag, offline/independent_rov.py seed 2
    without --noise-source parameter, --coefficients auto: X_udot 1.21x chose it, the other 15
    0.62-0.97x, Z_w then 3.37 and Y_vdot 3.23 sigma off under 'consistent'; 2.28 and 2.32 with
    the AR(1) covariance). Its lag window is read off the residuals and its estimate is noisy;
    a wider bar is kept, a narrower one is not trusted."""
    d = np.maximum(1.0, 1.0 / np.asarray(inflation, dtype=float))
    return np.asarray(sand, dtype=float) * np.outer(d, d)


def fit_noise(model, cfg, runs, T=None, max_step=None, max_bridge=0.25, hist_every=0):
    """Noise model of one run or several (runs: list of Record, as
    core.identification.batch.run_ekf takes them) from an EKF pass over them in turn with the
    configured noise; several: the levels and AR(1) coefficients pooled over the runs. Returns
    NoiseFit (used = whether the effective noise should replace the configured one;
    configured_pass = that EKF pass, with histories every hist_every samples; process_used =
    whether the process noise was matched to the data, effective_q the result).

    If that pass leaves the model's domain or diverges (noise far above the configured level
    makes an over-confident filter chase it, e.g. into a negative surge speed), or completes
    with a damping or added mass of the wrong sign (wrong_signs), the pass is made again with
    the noise scaled by RETRY_NOISE_FACTORS in turn, the noise model is read off the first
    pass that completes with the right signs (its levels relative to that scaled noise), and a
    note says so; if none does, the first that completed is used, and only if every pass
    diverges is the last error raised. A configured pass with wrong signs stands when the pass
    with more noise finds the noise at the configured level (_noise_as_configured): it did
    not chase noise, its signs are the data's. Innovations more than
    PROCESS_NOISE_LEVEL times their predicted level: the process noise is matched first
    (module docstring) and the measurement noise model read off the matched pass."""
    T = nominal_sample_time(runs[0].t) if T is None else T
    conf = np.asarray(cfg.noise_std, dtype=float)
    measured = np.asarray(cfg.measured, dtype=bool)
    failures = []
    wild = None     # the first pass that completed with wrong signs, if every one fails
    for factor in (1.0,) + RETRY_NOISE_FACTORS:
        base = conf * factor
        cfg_base = cfg if factor == 1.0 else replace(cfg, noise_std=base)
        try:
            first = _pass(model, cfg_base, runs, T, max_step, max_bridge, hist_every)
        except (DomainError, DivergenceError) as err:
            failures.append((factor, err))
            continue
        wrong = wrong_signs(model, first)
        if not wrong:
            break
        failures.append((factor, f'it ended with {", ".join(wrong)} positive: a damping or '
                                 'added mass that gives the motion energy'))
        wild = wild or (factor, base, cfg_base, first)
    else:
        if wild is None:
            raise failures[-1][1]
        factor, base, cfg_base, first = wild
    if wild is not None and wild[0] == 1.0 and factor != 1.0 and _noise_as_configured(
            first, factor, measured):
        # the pass with more noise finds the noise at the configured level: the configured
        # pass did not chase noise, its signs are the data's (plausibility judges them)
        factor, base, cfg_base, first = wild
        failures = []
    levels0 = _levels(_pooled(first), measured)
    q_conf = np.asarray(cfg.q_state, dtype=float)
    q, last, passes, noise_only = q_conf.copy(), first, 0, None
    if np.any(np.nan_to_num(levels0) > PROCESS_NOISE_LEVEL):
        noise_only = noise_only_levels(model, cfg_base, runs, T, levels0, max_step, max_bridge)
        if noise_only is None or np.any(np.nan_to_num(noise_only) > PROCESS_NOISE_LEVEL):
            matched = match_process_noise(model, cfg_base, runs, T, first, max_step,
                                          max_bridge, hist_every)
            q, last, passes = matched.q_state, matched.last, matched.passes
    nm = _informative(noise_model(_pooled(last), T, STATE_NAMES))
    eff = effective_std(base, nm, measured)
    ratio = (eff / conf) ** 2
    used = bool(factor != 1.0 or passes > 0
                or np.any((ratio > NOISE_MODEL_CHANGE) | (ratio < 1.0 / NOISE_MODEL_CHANGE)))
    fit = NoiseFit(model=nm, configured_std=conf, effective_std=eff if used else conf.copy(),
                   used=used, configured_pass=first, configured_q=q_conf,
                   effective_q=q, process_used=passes > 0, process_levels=levels0,
                   noise_only_levels=noise_only)
    if failures and factor != 1.0:
        fit.notes.append(
            f'the EKF with the configured noise failed ({failures[0][1]}): the noise is far '
            f'above the configured level; the noise model was read off a pass with {factor:g}x '
            'the configured noise')
    elif failures:
        fit.notes.append(
            f'the EKF with the configured noise ended implausible ({failures[0][1]}) and so '
            'did every pass with more noise; the noise model was read off the configured one')
    if passes:
        big = [j for j in np.flatnonzero(measured) if np.isfinite(levels0[j])]
        fit.notes.append(
            'model error far above the configured process noise (innovations '
            + ', '.join(f'{STATE_NAMES[j]} {levels0[j]:.3g}x' for j in big)
            + ' their predicted level): the per-step process noise was matched to the '
            f'innovations in {passes} EKF passes (' + ', '.join(
                f'{STATE_NAMES[j]} {q[j]:.2g}' for j in big if q[j] != q_conf[j])
            + ", the states' units per step)")
    if noise_only is not None and not passes:
        fit.notes.append(_noise_explains_note(levels0, noise_only, measured))
    if used and nm:
        worst = max(nm, key=lambda n: abs(math.log(ratio[STATE_NAMES.index(n)])))
        d = nm[worst]
        if (not passes
                or abs(math.log(ratio[STATE_NAMES.index(worst)])) > math.log(NOISE_MODEL_CHANGE)):
            fit.notes.append(
                f'the measurement noise is not what was configured: e.g. {worst} is '
                f'{d["level"] * factor:.2g}x the assumed level with a lag-1 correlation of '
                f'{d["ar1"]:.2f} (time constant {d["tau_s"]:.2g} s); identified with the '
                'noise model from the data (effective 1-sigma = level x sqrt((1 + rho) / '
                '(1 - rho)) x configured)')
    return fit


def identify_with_noise_model(model, cfg, runs, T=None, refine_pass=True, max_step=None,
                              max_bridge=0.25, progress=None, ekf_pass=None, hist_every=0,
                              start=None):
    """EKF pass and refinement with the noise model from the data, over one run or several
    (list of Record; several: one coefficient set for all, as core.identification.batch.
    identify).

    ekf_pass : PassEstimate of an EKF pass already made with the configured noise (e.g. the
        bag replay, the live node's path), kept when the configured noise holds
    start : Start (core.identification.results) where the EKF pass and so the refinement
        start, when not at cfg's initial guesses; the noise model is read off the pass from
        cfg's. Why: that pass decides whether the process noise is matched (fit_noise), and
        with too small a configured noise its filter chases the noise, so its innovation
        levels depend on where it starts (a BlueROV2 bag with coloured noise: p 3.1x its
        predicted level from the vehicle file's values, 5.05x from the first estimates of
        the automatic choice, over PROCESS_NOISE_LEVEL: its process noise was matched and
        the pruned re-identification ended X_u 45 % off at 4.5 sigma). The noise model is a
        property of the data, read off one reference pass, not of where a run starts.
    Returns an Estimate: the EKF pass with the effective noise (or ekf_pass), and
    (refine_pass) the refined estimate, started from the EKF pass, with the covariance the
    residuals support (module docstring); without refine_pass the final estimate and cov are
    the EKF pass's. The reported EKF pass (histories every hist_every samples, final R and Q)
    is its noise.ekf_run (None when ekf_pass was kept)."""
    T = nominal_sample_time(runs[0].t) if T is None else T
    fit = fit_noise(model, cfg, runs, T, max_step, max_bridge, hist_every=hist_every)
    cfg_run = cfg if start is None else replace(
        cfg, initial=np.asarray(start.initial, dtype=float),
        theta_cov0=None if start.theta_cov0 is None else np.asarray(start.theta_cov0, float))
    cfg_eff = (replace(cfg_run, noise_std=fit.effective_std.copy(),
                       q_state=fit.effective_q.copy()) if fit.used else cfg_run)
    if ekf_pass is not None and not fit.used:
        ekf_est = np.array(ekf_pass.estimate, dtype=float)
        ekf_cov = np.array(ekf_pass.cov, dtype=float)
    elif not fit.used and start is not None:    # the configured noise, from the start
        fit.ekf_run = _pass(model, cfg_run, runs, T, max_step, max_bridge, hist_every)
        ekf_est, ekf_cov = fit.ekf_run.theta.copy(), fit.ekf_run.theta_cov.copy()
    elif not fit.used:      # the configured noise holds: its pass is the EKF pass
        fit.ekf_run = fit.configured_pass
        ekf_est, ekf_cov = fit.ekf_run.theta, fit.ekf_run.theta_cov
    else:
        fit.ekf_run = _pass(model, cfg_eff, runs, T, max_step, max_bridge, hist_every)
        ekf_est, ekf_cov = fit.ekf_run.theta.copy(), fit.ekf_run.theta_cov.copy()
    fit.bounds = [int(b) for b in np.cumsum([0] + [len(r.t) for r in runs])]
    out = Estimate(model=model, ekf_estimate=ekf_est, ekf_cov=ekf_cov, estimate=ekf_est,
                   cov=ekf_cov, noise=fit)
    if not refine_pass or model.p == 0:
        return out
    # with the noise model used, also the fit's covariance under its AR(1) noise: the
    # effective noise's white covariance is the AR(1) long-run bound, exact only for
    # sensitivities constant over the correlation time (module docstring)
    ar1 = model_ar1(fit.model, np.asarray(cfg.measured, dtype=bool)) if fit.used else None
    ref = refine(model, cfg_eff, runs, ekf_est, T=T, max_step=max_step, max_bridge=max_bridge,
                 progress=progress, details=True, ar1=ar1)
    out.estimate, out.cov = ref.estimate, ref.cov
    fit.refine_converged = bool(ref.converged)
    fit.white, fit.information, fit.scores = ref.white, ref.information, ref.scores
    fit.refine_message = str(ref.message)
    fit.refine_cost = float(ref.cost)
    try:
        sand, sinfo = sandwich_from_sums(ref.information, ref.scores, ref.white,
                                         bounds=fit.bounds)
    except np.linalg.LinAlgError:
        return out
    if ref.ar1_cov is not None:
        out.cov = ref.ar1_cov
        fit.covariance = 'ar1'
    base_sd = np.sqrt(np.clip(np.diag(out.cov), 0.0, None))
    fit.inflation = np.sqrt(np.clip(np.diag(sand), 0.0, None)) / base_sd
    fit.lags = sinfo['lags']
    if np.any(fit.inflation > SANDWICH_WIDER):
        fit.covariance = 'sandwich'
        out.cov = never_narrower(sand, fit.inflation)
    return out
