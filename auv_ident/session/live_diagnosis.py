"""The live identifier's diagnosis: what the running filter can say about its own error bars.

Offline, ``identify`` judges a result by its refined residuals (core/identification/diagnosis.py:
residual- input cross-correlation, whiteness per channel, the refinement's convergence, a noise
model). Live there is only the EKF: its innovations and its covariance. So the live diagnosis says

- whether the innovations agree with the filter's noise model: the mean NIS per degree of
  freedom over the health window (session/guard.py) against its chi-square band. Above the
  band the filter is over-confident (noise larger or coloured, or the model wrong) and its
  1-sigma do NOT hold: ``consistent`` false, said on the first line. Below the band it is
  conservative (a note). While the window fills, nothing is judged yet.
- whether the noise model the filter runs with holds (session/noise_learning.py, noise mode
  'fixed'): the live form of the offline noise model. Until a fit of the innovations' level
  and AR(1) colour finds it holding, ``consistent`` is false (after a re-run with a learnt
  model too, until a fit confirms it); once it holds with a learnt colour, the NIS below its
  band is what the colour inflation implies, not a conservative filter.
- per parameter, how well the data so far determine it, from the EKF covariance
  (core/identification/uncertainty.py :func:`verdicts_from_covariance`): 'identifiable', 'weak'
  (with the correlated partner) or 'not excited' (its 1-sigma still above NOT_INFORMED_RATIO of the
  prior's), with the excitation that would help (core/identification/diagnosis.py). A water-current
  component is judged on its 1-sigma in m/s (core.identification.diagnosis.current_std_limits), as
  offline.

Without the noise learning (learn_noise false or an adaptive noise mode) the live verdict cannot
see coloured noise that keeps the NIS in its band. It never sees a bias from wrong fixed
coefficients: `identify --bag` on the recorded run can (docs/method.md).
"""
from collections.abc import Sequence
import math
from typing import Any

import numpy as np

from auv_ident.core.identification.diagnosis import current_std_limits, weak_notes, with_advice
from auv_ident.core.identification.uncertainty import Verdicts, verdicts_from_covariance
from auv_ident.core.model.vehicle import Vehicle
from auv_ident.session.guard import NIS_WINDOW
from auv_ident.session.noise_learning import (
    HOLDS,
    LEARN_EVERY,
    NoiseLearner,
    RELEARNT,
)

NOT_INFORMED_RATIO = 0.9    # 1-sigma above this fraction of the prior's: the data told nothing


def live_verdicts(vehicle: Vehicle, names: Sequence[str], estimate: np.ndarray, cov: np.ndarray,
                  prior_std: np.ndarray) -> Verdicts:
    """Per identified parameter its verdict
    (core.identification.uncertainty.verdicts_from_covariance) from the
    filter covariance cov (p, p) and the prior 1-sigma prior_std (p,), with advice for the
    ones that are not identifiable."""
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    informed = sd < NOT_INFORMED_RATIO * np.asarray(prior_std, dtype=float)
    return with_advice(vehicle, verdicts_from_covariance(
        cov, estimate, names, informed=informed, absolute_std=current_std_limits(names)))


def _noise_not_holding(noise: NoiseLearner) -> str:
    """The first line while the learnt noise model is not confirmed."""
    worst = noise.worst()
    what = ('' if worst is None else
            f' (e.g. {worst[0]}: its innovations carry {worst[1]:.3g}x the variance the filter '
            'assumes, level and colour together)')
    if noise.reruns == 0:
        done = 'not yet re-run with the noise model learnt from its innovations'
    else:
        done = (f're-run with the noise model learnt from its innovations ({noise.reruns} '
                'time(s))')
    return (f'NOT consistent: the measurement noise is not what the filter assumes{what}; the '
            f'filter was {done}: its error bars do not hold until a fit confirms the model '
            f'(every {LEARN_EVERY} updates; {noise.next_rerun()})')


def live_diagnosis(health: Any, verdicts: Verdicts,
                   noise: NoiseLearner | None = None) -> dict[str, Any]:
    """{'consistent': True | False | None (not judged yet), 'messages': [first line, ...]}
    from the filter's Health (session/guard.py judge_health), live_verdicts() and the noise
    learner (None: none)."""
    m, (lo, hi), n = health.mean_nis_per_dof, health.band, health.window
    notes = weak_notes(verdicts)
    if health.level == 'ERROR' and health.message.startswith('stuck sensor'):
        return {'consistent': False,
                'messages': [f'NOT consistent: {health.message}; the estimate shown is the last '
                             'good one, from before the fault'] + notes}
    if health.level == 'ERROR':
        return {'consistent': False,
                'messages': [f'NOT consistent: the filter is {health.message} (a reset or '
                             'innovations far beyond the noise model): its error bars do not '
                             'hold'] + notes}
    if noise is not None and noise.state == RELEARNT:
        return {'consistent': False, 'messages': [_noise_not_holding(noise)] + notes}
    if n < NIS_WINDOW or not math.isfinite(m):
        return {'consistent': None,
                'messages': [f'not judged yet: {n} of {NIS_WINDOW} updates in the window']
                + notes}
    if m > hi:
        return {'consistent': False,
                'messages': [f'NOT consistent: the innovations are larger than the filter '
                             f'expects (mean NIS/dof {m:.3g} above its 99.9 % band '
                             f'[{lo:.3g}, {hi:.3g}]): the sensor noise is larger or coloured, '
                             'or the model is wrong; the error bars are too small. Identify '
                             'the recorded run offline (identify --bag) for a noise model and '
                             'honest error bars'] + notes}
    # re-runs with a learnt model that holds (0: the configured model, not learnt)
    learnt = noise.reruns if noise is not None and noise.state == HOLDS else 0
    if learnt:
        head = ('consistent: the noise model learnt from the innovations holds (re-run '
                f'{learnt}; mean NIS/dof {m:.3g}')
        head += (f', below [{lo:.3g}, {hi:.3g}] as its colour implies)' if m < lo
                 else f' in [{lo:.3g}, {hi:.3g}])')
    else:
        head = ('consistent: the innovations agree with the noise model (mean NIS/dof '
                f'{m:.3g} in [{lo:.3g}, {hi:.3g}])')
    if m < lo and not learnt:
        head += '; below the band: the filter is conservative (error bars wider than needed)'
    return {'consistent': True, 'messages': [head] + notes}
