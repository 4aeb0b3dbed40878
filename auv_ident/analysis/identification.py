"""One identification as every command reports it: the noise model from the data, the EKF pass,
the batch refinement with error bars the residuals support, identifiability and the diagnosis.

`identify --simulate`, `report` and `montecarlo` go through :func:`identify_with_diagnosis`;
`identify --bag` makes the same calls around the bag replay (analysis/bag_identify.py), whose
EKF pass is the live node's. So every result carries `noise_model`, `identifiability` and a
`diagnosis` whose first message says whether the error bars can be trusted.
"""
import time

import numpy as np

from auv_ident.core.batch import Result
from auv_ident.core.current import split_current
from auv_ident.core.diagnosis import assess
from auv_ident.core.noise_fit import identify_with_noise_model
from auv_ident.core.state import State
from auv_ident.core.timing import nominal_sample_time


def identify_with_diagnosis(model, cfg, t, Y, U, T=None, refine_pass=True, hist_every=0,
                            truth=None, progress=None):
    """core.batch.identify's Result, identified with the noise model from the data
    (core/noise_fit.py), with its ``noise_model`` (NoiseFit.document()), ``identifiability``
    (per coefficient verdicts, None without a refinement) and ``diagnosis`` ({'consistent',
    'messages', 'checks'}, core/diagnosis.py) filled in.

    The histories (hist_every), R_final and Q_final are those of the EKF pass whose estimate
    is reported; mean_nis_per_dof is that of the pass with the configured noise (what the live
    node would see)."""
    t0 = time.perf_counter()
    T = nominal_sample_time(t) if T is None else T
    ekf_est, ekf_cov, est, cov, fit = identify_with_noise_model(
        model, cfg, t, Y, U, T=T, refine_pass=refine_pass, progress=progress,
        hist_every=hist_every)
    nis = fit.configured_pass['mean_nis_per_dof']
    verdicts, diagnosis = assess(model.vehicle, model.theta_names, est, cov, fit, U, T, nis,
                                 refined=refine_pass)
    est_c, cov_c, ekf_c, ekf_cov_c, current = split_current(model, est, cov, ekf_est, ekf_cov,
                                                            np.asarray(Y)[:, State.PSI])
    run = fit.ekf_run
    res = Result(names=list(model.theta_names[:model.p_coef]), estimate=est_c,
                 std=np.sqrt(np.diag(cov_c)), cov=cov_c, ekf_estimate=ekf_c,
                 ekf_std=np.sqrt(np.diag(ekf_cov_c)),
                 initial=run['theta0'][:model.p_coef].copy(),
                 truth=None if truth is None else np.asarray(truth, float),
                 steps=run['steps'], wall_s=time.perf_counter() - t0, mean_nis_per_dof=nis,
                 refined=refine_pass, history=run['hist'], R_final=run['R'], Q_final=run['Q'],
                 current=current, noise_model=fit.document(), identifiability=verdicts,
                 diagnosis=diagnosis)
    return res
