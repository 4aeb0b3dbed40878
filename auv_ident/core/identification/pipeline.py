"""One identification as every command reports it, of one run or several: the noise model from
the data, the EKF pass, the batch refinement with error bars the residuals support
(core/identification/noise_fit.py), the coefficients given or chosen from the data
(core/identification/selection.py), identifiability and the diagnosis
(core/identification/diagnosis.py), the water current split off.

`identify --simulate`, `identify --bag` (one bag or several), `report`, `montecarlo` and
`campaign` all go through :func:`identify_with_diagnosis`, so every result carries its noise
model, identifiability and a diagnosis whose first message says whether the error bars can be
trusted.
"""
from collections.abc import Callable
import math
import time
from typing import Any

import numpy as np

from auv_ident.core.errors import ConfigError
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.filter.timing import nominal_sample_time
from auv_ident.core.identification.diagnosis import assess
from auv_ident.core.identification.noise_fit import identify_with_noise_model
from auv_ident.core.identification.results import (
    Identification,
    PassEstimate,
    Record,
    SelectionRequest,
    Start,
)
from auv_ident.core.identification.selection import identify_auto
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import State

JUDGE_NIS = ('configured', 'reported', None)


def identify_with_diagnosis(model: Model | None, cfg: FilterConfig, runs: list[Record],
                            T: float | None = None, refine_pass: bool = True,
                            progress: Callable[..., Any] | None = None, hist_every: int = 0,
                            ekf_pass: PassEstimate | None = None,
                            auto: SelectionRequest | None = None,
                            judge_nis: str | None = 'configured',
                            truth: np.ndarray | None = None,
                            start: Start | None = None) -> Identification:
    """Identify with the noise model from the data, judge, split the current off.

    model : the Model identified (None with `auto`)
    cfg : FilterConfig of the configured noise (the start of the noise model)
    runs : list of core.identification.results.Record; one run is a list of one, several give
        one coefficient set for all (each run from its own initial state, error bars from all)
    T : s, the nominal sample time (None: the first run's median interval)
    ekf_pass : PassEstimate of an EKF pass already made with the configured noise (the bag
        replay's: the live node's), kept when the configured noise holds
    auto : SelectionRequest: the coefficients are chosen from the data (identify_auto; the
        Identification's selection says which and why)
    judge_nis : the mean NIS/dof the diagnosis records: of the pass with the configured noise
        ('configured': what the live node would see), of the EKF pass reported ('reported'),
        or none (None)
    truth : the true coefficients (p_coef,) when known
    start : Start: where the identification starts when not at cfg's guesses (the user's
        --initial, a warm start); the noise model is still read off a pass from cfg's
        (identify_with_noise_model); not with `auto`, which starts at the file's values

    Returns an Identification whose histories (hist_every), R_final, Q_final, initial and steps
    are those of the EKF pass whose estimate is reported, and whose mean_nis_per_dof is that of
    the pass with the configured noise.
    """
    if (model is None) == (auto is None):
        raise ConfigError('identify_with_diagnosis: give a model or an automatic choice')
    if judge_nis not in JUDGE_NIS:
        raise ConfigError(f'judge_nis = {judge_nis!r}: one of {JUDGE_NIS}')
    t0 = time.perf_counter()
    T = nominal_sample_time(runs[0].t) if T is None else T
    if auto is None:
        est = identify_with_noise_model(model, cfg, runs, T=T, refine_pass=refine_pass,
                                        progress=progress, ekf_pass=ekf_pass,
                                        hist_every=hist_every, start=start)
    else:
        est = identify_auto(auto.make_model, cfg, runs, named=auto.named, T=T,
                            refine_pass=refine_pass, progress=progress, hist_every=hist_every)
    fit = est.noise
    reported = fit.reported_pass
    nis = {'configured': fit.configured_pass.mean_nis_per_dof,
           'reported': reported.mean_nis_per_dof, None: math.nan}[judge_nis]
    U = np.concatenate([np.asarray(r.U) for r in runs])
    depth = np.concatenate([np.asarray(r.Y)[:, State.Z] for r in runs])
    diagnosis = assess(est.model.vehicle, est.model.theta_names, est.estimate, est.cov, fit, U,
                       T, nis, refined=refine_pass, depth=depth,
                       information_cov=est.statistical_cov, selection=est.selection)
    return Identification.of(est, runs, initial=reported.theta0[:est.model.p_coef].copy(),
                             truth=truth, steps=reported.steps,
                             wall_s=time.perf_counter() - t0,
                             mean_nis_per_dof=fit.configured_pass.mean_nis_per_dof,
                             refined=refine_pass, history=reported.history,
                             R_final=reported.R, Q_final=reported.Q, diagnosis=diagnosis)
