"""One identification as every command reports it: the noise model from the data, the EKF pass,
the batch refinement with error bars the residuals support, identifiability and the diagnosis.

`identify --simulate`, `report` and `montecarlo` go through :func:`identify_with_diagnosis`
(`report --coefficients auto` through :func:`identify_auto_with_diagnosis`); `identify --bag`
(one bag or several) goes through :func:`identify_records` around the bag replay
(analysis/bag_identify.py), whose EKF pass is the live node's, and `--coefficients auto`
through :func:`diagnosed` after its own identification. So every result carries
`noise_model`, `identifiability` and a `diagnosis` whose first message says whether the error
bars can be trusted.
"""
import time

import numpy as np

from auv_ident.core.filter.timing import nominal_sample_time
from auv_ident.core.identification.batch import Result
from auv_ident.core.identification.diagnosis import assess
from auv_ident.core.identification.noise_fit import identify_runs_with_noise_model
from auv_ident.core.identification.selection import identify_auto
from auv_ident.core.model.current import split_current
from auv_ident.core.model.state import State


def diagnosed(model, records, T, fit, ekf_est, ekf_cov, est, cov, mean_nis_per_dof,
              refine_pass):
    """Identifiability and diagnosis (core.identification.diagnosis.assess) of an identification of
    the
    paired records [(t, Y, U), ...] made with the noise model (its NoiseFit `fit`), and the
    water current split off the estimates (core.model.current.split_current). Returns (estimate,
    cov, ekf estimate, ekf cov, current, verdicts, diagnosis) of the coefficients."""
    U = np.concatenate([np.asarray(r[2]) for r in records])
    verdicts, diagnosis = assess(model.vehicle, model.theta_names, est, cov, fit, U, T,
                                 mean_nis_per_dof, refined=refine_pass)
    psi = np.concatenate([np.asarray(r[1])[:, State.PSI] for r in records])
    est_c, cov_c, ekf_c, ekf_cov_c, cur = split_current(model, est, cov, ekf_est, ekf_cov, psi)
    return est_c, cov_c, ekf_c, ekf_cov_c, cur, verdicts, diagnosis


def identify_records(model, cfg, records, T, refine_pass=True, progress=None, ekf_pass=None,
                     hist_every=0, configured_nis=False):
    """The noise model, EKF pass, refinement
    (core.identification.noise_fit.identify_runs_with_noise_model),
    identifiability and diagnosis (:func:`diagnosed`) of one or several paired records.

    ekf_pass : (estimate, covariance) of an EKF pass already made with the configured noise
    configured_nis : judge by the mean NIS/dof of the pass with the configured noise (what the
        live node sees) instead of that of the EKF pass reported
    Returns (estimate, cov, ekf estimate, ekf cov, current, verdicts, diagnosis, NoiseFit)."""
    ekf_est, ekf_cov, est, cov, fit = identify_runs_with_noise_model(
        model, cfg, records, T=T, refine_pass=refine_pass, progress=progress,
        ekf_pass=ekf_pass, hist_every=hist_every)
    nis = (fit.configured_pass if configured_nis
           else fit.ekf_run or fit.configured_pass)['mean_nis_per_dof']
    return diagnosed(model, records, T, fit, ekf_est, ekf_cov, est, cov, nis,
                     refine_pass) + (fit,)


def identify_with_diagnosis(model, cfg, t, Y, U, T=None, refine_pass=True, hist_every=0,
                            truth=None, progress=None):
    """core.identification.batch.identify's Result, identified with the noise model from the data
    (core/identification/noise_fit.py), with its ``noise_model`` (NoiseFit.document()),
    ``identifiability`` (per coefficient verdicts, None without a refinement) and ``diagnosis``
    ({'consistent', 'messages', 'checks'}, core/identification/diagnosis.py) filled in.

    The histories (hist_every), R_final and Q_final are those of the EKF pass whose estimate
    is reported; mean_nis_per_dof is that of the pass with the configured noise (what the live
    node would see)."""
    t0 = time.perf_counter()
    T = nominal_sample_time(t) if T is None else T
    out = identify_records(model, cfg, [(t, Y, U)], T, refine_pass=refine_pass,
                           progress=progress, hist_every=hist_every, configured_nis=True)
    return _result(model, out, refine_pass, truth, t0)


def identify_auto_with_diagnosis(make_model, cfg, t, Y, U, named=(), T=None, refine_pass=True,
                                 hist_every=0, truth_of=None, progress=None):
    """:func:`identify_with_diagnosis` with the coefficients chosen from the data
    (`--coefficients auto[,NAME,...]`, core.identification.selection.identify_auto): the same
    Result, of the chosen set, judged the same way (its mean_nis_per_dof that of the chosen set's
    pass with the configured noise).

    make_model : names -> Model identifying them (and the water current as wanted)
    named : coefficients always identified
    truth_of : names -> their true values (None: truth unknown)
    Returns (Result, Model of the chosen set, core.identification.selection.Selection)."""
    t0 = time.perf_counter()
    T = nominal_sample_time(t) if T is None else T
    model, ekf_est, ekf_cov, est, cov, fit, selection = identify_auto(
        make_model, cfg, t, Y, U, named=named, T=T, refine_pass=refine_pass,
        progress=progress, hist_every=hist_every)
    nis = fit.configured_pass['mean_nis_per_dof']
    out = diagnosed(model, [(t, Y, U)], T, fit, ekf_est, ekf_cov, est, cov, nis,
                    refine_pass) + (fit,)
    truth = None if truth_of is None else truth_of(selection.chosen)
    return _result(model, out, refine_pass, truth, t0), model, selection


def _result(model, identified, refine_pass, truth, t0):
    """The Result of identify_records' output `identified` (module docstring)."""
    est_c, cov_c, ekf_c, ekf_cov_c, current, verdicts, diagnosis, fit = identified
    run = fit.ekf_run
    return Result(names=list(model.theta_names[:model.p_coef]), estimate=est_c,
                  std=np.sqrt(np.diag(cov_c)), cov=cov_c, ekf_estimate=ekf_c,
                  ekf_std=np.sqrt(np.diag(ekf_cov_c)),
                  initial=run['theta0'][:model.p_coef].copy(),
                  truth=None if truth is None else np.asarray(truth, float),
                  steps=run['steps'], wall_s=time.perf_counter() - t0,
                  mean_nis_per_dof=fit.configured_pass['mean_nis_per_dof'],
                  refined=refine_pass, history=run['hist'], R_final=run['R'],
                  Q_final=run['Q'], current=current, noise_model=fit.document(),
                  identifiability=verdicts, diagnosis=diagnosis)
