"""A diagnosis that speaks: do the data contradict the identification's assumptions?

Checks, in the order a user needs them:

1. Model adequacy: the residuals of a model that holds do not follow the inputs. The
   cross-correlation of each measured channel's residuals with each varying input over lags
   of 0-2 s (core/identification/uncertainty.py :func:`input_correlation`, standardised by
   Bartlett's variance, which accounts for coloured sensor noise) beyond XCORR_Z standard
   deviations means the model leaves out or gets wrong something the inputs drive: coefficients
   that are not identified are off (a prior from empirical formulas is 10-50 % off), or the
   structure lacks a term. Then the estimates absorb the error (bias), and no error bar covers a
   bias: the result is NOT consistent. Remedy: identify more coefficients (--coefficients auto).
   Measured on independent NPS AUV II bags (600 s, 20 Hz): white noise 2.3, coloured noise
   (AR(1), tau 1 s, 2x) 1.6, every other coefficient 0.8-1.2x the file's 5.5.
   The inputs are taken twice: their levels and their changes between measured samples
   (uncertainty.command_changes, the inputs prewhitened). An error in the response to each
   change (a thruster's lag the file leaves out) follows the changes within a fraction of a
   second but the held levels only weakly, and under loud coloured noise the levels' test
   missed it: a BlueROV2 bag with a 0.3 s motor lag and AR(1) noise at 10x (tools/
   rov_trust_grid.py) gave 4.3 sd against the PWM levels and was called consistent with X_u
   at 5.4 sigma; against the changes 10.6 sd at a lag of 0.3 s. The same bag without the lag:
   2.9 and 2.7.
2. The batch refinement converged.
3. The noise model: the configured measurement noise against the innovations (level, AR(1)
   correlation, whiteness per channel), and what was done about it
   (core/identification/noise_fit.py). A channel whose correlation time exceeds the run (or
   which is constant: lag-1 correlation 1) is not noise but a bias or a missing sensor: NOT
   consistent, naming it (:func:`not_noise_channels`); position and heading, which the model
   only integrates, drift with the model error and are noted instead.
4. Identifiability: per coefficient the relative 1-sigma the run supports, correlations, and a
   verdict with the excitation that would help.
"""
from collections.abc import Sequence
from dataclasses import replace
import math
from typing import Any

import numpy as np

from auv_ident.core.identification.plausibility import (
    depth_contradicts_down,
    implausible_coefficients,
    what_to_check,
)
from auv_ident.core.identification.results import Diagnosis, percent, Selection, times
from auv_ident.core.identification.uncertainty import (
    command_changes,
    identifiability_from_information,
    input_correlation,
    LJUNG_BOX_LAGS,
    split_rows,
    Verdicts,
    with_gaps,
)
from auv_ident.core.model.current import MAX_CURRENT_STD
from auv_ident.core.model.state import State, STATE_NAMES
from auv_ident.core.model.vehicle import EQUATIONS, Vehicle

XCORR_Z = 4.5           # residual-input cross-correlation beyond this many sd: inadequate
XCORR_SECONDS = 2.0     # lags of the cross-correlation (s)

# What excites the terms of each equation (the manoeuvre a weak coefficient needs), by the
# equation the coefficient belongs to; added-mass terms need accelerations.
EXCITATION = {
    'X': 'speed changes: steps of the shaft speed, or long turns (surge drag terms)',
    'Y': 'rudder zig-zags with legs held 20-40 s (sway velocity and yaw rate build up)',
    'Z': 'stern-plane steps every 5-6 s between +-10 and +-20 deg (heave and pitch)',
    'K': 'rudder held 20-40 s per leg at the highest speed that is safe (roll follows the '
         'sway speed: K ~ u v)',
    'M': 'stern-plane steps every 5-6 s (pitch rate and angle of attack)',
    'N': 'rudder zig-zags with legs held 20-40 s (yaw rate and sway)',
}
ADDED_MASS_EXCITATION = 'quick fin reversals at the rate limit (accelerations)'
# the same for a hovering thruster vehicle (an ROV flown by a pilot's sticks,
# core/simulation/maneuvers.py)
PILOT_EXCITATION = {
    'X': 'surge stick steps of several sizes with rests between (surge drag at several '
         'speeds, the decays)',
    'Y': 'sway stick steps of several sizes with rests between',
    'Z': 'heave stick steps of several sizes, both ways',
    'K': "roll: moved only through the thrusters' offsets and combined motion; a vehicle "
         'with roll thrusters: roll steps',
    'M': "pitch: moved only through the thrusters' offsets and combined motion; a vehicle "
         'with pitch thrusters: pitch steps',
    'N': 'yaw stick steps of several sizes with rests between',
}
PILOT_ADDED_MASS = 'quick stick reversals and a sweep (0.05-0.5 Hz) of that stick (accelerations)'
PILOT_GAIN = ("each stick both ways (the forward and the reverse side of every thruster's "
              'curve), at several sizes')
PILOT_LAG = ('quick stick steps and reversals (the thrust rises over the time constant after '
             'each change of command), measured at a rate well above 1 / tau')


CURRENT_EXCITATION = ('turns: the current is separable from the coefficients only through '
                      'heading changes')


def excitation_advice(vehicle: Vehicle, name: str) -> str:
    """The manoeuvre that would excite coefficient `name` of `vehicle` (or a water-current
    component, 'current_*'), in words."""
    if name.startswith('current_'):
        return CURRENT_EXCITATION
    c = vehicle.coefficients[vehicle.index(name)]
    if c.is_thrust_gain:
        return PILOT_GAIN
    if c.is_thrust_lag:
        return PILOT_LAG
    if c.is_added_mass:
        return PILOT_ADDED_MASS if vehicle.hovers else ADDED_MASS_EXCITATION
    return (PILOT_EXCITATION if vehicle.hovers else EXCITATION).get(
        EQUATIONS[c.equation], 'a manoeuvre that moves the terms it multiplies')


def current_std_limits(names: Sequence[str]) -> np.ndarray:
    """(p,) per parameter the 1-sigma (m/s) to judge it by instead of the relative one: a
    water-current component may be ~0, so it is judged in m/s (MAX_CURRENT_STD); NaN for a
    coefficient (judged relative to its value)."""
    return np.array([MAX_CURRENT_STD if n.startswith('current_') else math.nan
                     for n in names])


def with_advice(vehicle: Vehicle, verdicts: Verdicts) -> Verdicts:
    """The verdicts (core/identification/uncertainty.py) with the excitation advice for the weak
    ones."""
    for name, d in verdicts.items():
        if d['verdict'] != 'identifiable':
            d['advice'] = excitation_advice(vehicle, name)
    return verdicts


def weak_notes(verdicts: Verdicts) -> list[str]:
    """One line per parameter that is not identifiable: its verdict, its 1-sigma (m/s for a
    current component, else % of its value), a correlation above 0.9, and the advice."""
    notes = []
    for n, d in verdicts.items():
        if d['verdict'] == 'identifiable':
            continue
        partner = (f', correlated {d["max_correlation"]:.2f} with {d["correlated_with"]}'
                   if d['correlated_with'] and d['max_correlation'] > 0.9 else '')
        size = (f'1-sigma {d["crb_std"]:.2g} m/s' if n.startswith('current_')
                else f'1-sigma {percent(d["rel_std"])} of its value')
        notes.append(f'{n} is {d["verdict"]} ({size}{partner}): {d["advice"]}')
    return notes


def coefficient_verdicts(vehicle: Vehicle, names: Sequence[str], estimate: np.ndarray,
                         information: np.ndarray, cov: np.ndarray | None) -> Verdicts:
    """identifiability() of the run (from its information J^T J (p, p)) with the excitation
    advice for the weak ones."""
    return with_advice(vehicle, identifiability_from_information(
        information, estimate, names, cov=cov, absolute_std=current_std_limits(names)))


BARS_COVER = ('(the error bars include it as far as the residuals allow the left-out '
              'coefficients to be off: consider analysis)')


def inadequacy_remedy(vehicle: Vehicle, selection: Selection | None) -> str:
    """What to do about a model the residuals call inadequate, something not just done: with
    named coefficients, identify more (--coefficients auto); after an automatic choice (which
    did that), the left-out coefficients the residuals point at, to name, and the manoeuvre
    that would determine them, or a look at the model's structure when they point at none."""
    if selection is None:
        return '(bias no error bar covers): identify more coefficients (--coefficients auto)'
    named = ','.join(['auto'] + list(selection.named))
    suspects = [n for n in selection.suspects if n in selection.left_out]
    if not suspects:
        return (f'{BARS_COVER}: the automatic choice (--coefficients auto, used here) finds no '
                'left-out coefficient the residuals point at: a term the model lacks, or inputs '
                'that are not what the vehicle received (commands, not measured fin angles?)')
    reasons = '; '.join(f'{n}: {selection.left_out[n]}' for n in suspects)
    moves = sorted({excitation_advice(vehicle, n) for n in suspects})
    return (f'{BARS_COVER}: the automatic choice (--coefficients auto, used here) left out '
            f'{", ".join(suspects)}'
            f', which the residuals point at ({reasons}); name them to identify them '
            f'(--coefficients {named},{",".join(suspects)}'
            + (' --mass-inverse exact' if any(selection.left_out[n].startswith('added mass')
                                              for n in suspects) else '')
            + ') or add runs that determine them: '
            + '; '.join(moves))


# The measured channels the model only integrates: position (x y z) and heading (psi) have no
# restoring force or moment, so an EKF's innovations in them are the run's model error
# integrated (a current, unmodelled forces, the velocity's own noise between updates): a drift
# whose correlation time grows with the run whatever the sensor. The run-length rule cannot
# tell that from a missing sensor there; a field never filled repeats exactly and is the
# stuck-value check's (session/stuck.py, #27 item 1), a sensor bias is absorbed by the state.
INTEGRATED_CHANNELS = ('x', 'y', 'z', 'psi')


def not_noise_channels(model: dict[str, dict[str, Any]]) -> list[tuple[str, str]]:
    """[(channel, why)] of the channels of a noise model (core/identification/uncertainty.py
    noise_model, per channel its lag-1 correlation 'ar1' over 'samples' innovations) whose
    correlation time exceeds the run: ar1 >= exp(-1 / samples), i.e. -dt / ln(ar1) >= samples
    x dt (a constant channel has ar1 1, time constant inf). Such innovations are not noise
    that averages out over the run but a bias or a sensor that is not there (a field a driver
    never fills); no error bar covers them, so the result is NOT consistent. The channels the
    model only integrates (INTEGRATED_CHANNELS) are not judged by this rule
    (:func:`drifting_channels`)."""
    return [(name, f'the {name} innovations are not noise: lag-1 correlation '
                   f'{d["ar1"]:.4f} (time constant {_tau(d):.3g} s), longer than the run '
                   f'({d["samples"]} samples): a bias or a missing sensor (a field the driver '
                   'never fills); check that channel, or leave it out (--measured)')
            for name, d in _beyond_the_run(model) if name not in INTEGRATED_CHANNELS]


def drifting_channels(model: dict[str, dict[str, Any]]) -> list[tuple[str, str]]:
    """[(channel, note)] of the INTEGRATED_CHANNELS whose innovations are correlated beyond
    the run (the rule of :func:`not_noise_channels`): the model error integrated, said in a
    note, not a verdict."""
    return [(name, f'the {name} innovations drift (lag-1 correlation {d["ar1"]:.5f}, time '
                   f'constant {_tau(d):.3g} s, longer than the run): the model error '
                   f'integrated into a channel without restoring force, not judged as noise '
                   '(a field never filled is caught as a stuck sensor)')
            for name, d in _beyond_the_run(model) if name in INTEGRATED_CHANNELS]


def _beyond_the_run(model: dict[str, dict[str, Any]]) -> list[tuple[str, dict[str, Any]]]:
    """The (name, channel) of a noise model whose lag-1 correlation is at least
    exp(-1 / samples)."""
    return [(name, d) for name, d in model.items()
            if int(d.get('samples', 0)) and d['ar1'] >= math.exp(-1.0 / int(d['samples']))]


def _tau(d: dict[str, Any]) -> float:
    """A noise-model channel's time constant (s; inf for a constant or unit correlation)."""
    tau = d.get('tau_s', math.inf)
    return math.inf if tau is None else float(tau)


def diagnose(fit: Any = None, xcorr: list[tuple[float, str, str, int]] | None = None,
             dt: float | None = None, mean_nis_per_dof: float = math.nan,
             verdicts: Verdicts | None = None, refined: bool = True,
             remedy: str = '(bias no error bar covers): identify more coefficients '
                           '(--coefficients auto)') -> dict[str, Any]:
    """The diagnosis of one identification.

    Parameters
    ----------
    fit : core.identification.noise_fit.NoiseFit (or None)
    xcorr : input_correlation() output on the refined residuals (or None: not checked)
    dt : s, the sample time the cross-correlation lags are in
    mean_nis_per_dof : of the EKF pass with the configured noise
    verdicts : coefficient_verdicts() output (or None)
    refined : whether a refinement ran (its convergence is then checked)
    remedy : what the inadequacy message advises (:func:`inadequacy_remedy`)

    Returns
    -------
    dict {'consistent': bool, 'messages': [str, ...] (the first says whether the result can be
    trusted and why), 'checks': {...} (the figures behind them)}
    """
    problems: list[str] = []
    notes: list[str] = []
    checks: dict[str, Any] = {}
    if xcorr:
        z, channel, inp, lag = xcorr[0]
        checks['residual_input_correlation'] = {'z': float(z), 'channel': channel,
                                                'input': inp,
                                                'lag_s': None if dt is None else lag * dt,
                                                'limit': XCORR_Z}
        if abs(z) > XCORR_Z:
            problems.append(
                f'the model is inadequate: the {channel} residuals follow {inp} (cross-'
                f'correlation {abs(z):.1f} sd, limit {XCORR_Z:g}'
                + (f', at a lag of {lag * dt:.2g} s' if dt is not None else '')
                + '); coefficients that are not identified are wrong or missing, and the '
                'estimates absorb that error ' + remedy)
    if refined and fit is not None:
        checks['refinement_converged'] = bool(fit.refine_converged)
        if not fit.refine_converged:
            problems.append(f'the batch refinement did not converge ({fit.refine_message})')
    if fit is not None:
        not_noise = not_noise_channels(fit.model)
        checks['not_noise_channels'] = [n for n, _ in not_noise]
        problems.extend(text for _, text in not_noise)
        notes.extend(text for _, text in drifting_channels(fit.model))
        checks['noise_model_used'] = bool(fit.used)
        checks['covariance'] = fit.covariance
        coloured = [n for n, d in fit.model.items() if not d['white']]
        checks['coloured_channels'] = coloured
        notes.extend(fit.notes)
        if fit.covariance == 'sandwich':
            # with the noise model used, the sandwich was weighed against the AR(1) covariance
            # (core/identification/noise_fit.py)
            notes.append('error bars from the sandwich covariance (residuals correlated in '
                         'time; up to {} the {} ones)'.format(
                             times(float(max(fit.inflation)), 2),
                             "noise model's AR(1)" if fit.used else 'white-noise'))
    if math.isfinite(mean_nis_per_dof):
        checks['mean_nis_per_dof'] = float(mean_nis_per_dof)
    if verdicts:
        notes.extend(weak_notes(verdicts))
    consistent = not problems
    head = ('consistent: the data agree with the assumptions of the identification; the '
            'error bars hold' if consistent else
            'NOT consistent: ' + problems[0])
    return {'consistent': consistent, 'messages': [head] + problems[1:] + notes,
            'checks': checks}


def not_consistent(diagnosis: Diagnosis, problems: Sequence[str],
                   check: str) -> Diagnosis:
    """The diagnosis made NOT consistent by problems of the data found outside it (each a
    clause, e.g. a stuck sensor the replay found: analysis/bag_identify.py): the consistency
    line names the first, the others follow it (before the problems it had already), and
    checks[check] lists them. No problems: the diagnosis unchanged."""
    if not problems:
        return diagnosis
    messages = list(diagnosis.messages)
    lines = ['NOT consistent: ' + problems[0]] + list(problems[1:])
    at = next((i for i, m in enumerate(messages)
               if m.startswith(('consistent: ', 'NOT consistent: '))), None)
    if at is None:
        messages = lines + messages
    elif messages[at].startswith('NOT '):
        messages[at:at + 1] = lines + [messages[at][len('NOT consistent: '):]]
    else:
        messages[at:at + 1] = lines
    return replace(diagnosis, consistent=False, messages=messages,
                   checks={**diagnosis.checks, check: list(problems)})


def assess(vehicle: Vehicle, names: Sequence[str], estimate: np.ndarray, cov: np.ndarray,
           fit: Any, U: np.ndarray, dt: float, mean_nis_per_dof: float = math.nan,
           refined: bool = True, depth: np.ndarray | None = None,
           information_cov: np.ndarray | None = None,
           selection: Selection | None = None) -> Diagnosis:
    """Identifiability and diagnosis of an identification made with
    core.identification.noise_fit.identify_with_noise_model (its NoiseFit holds the refined
    residuals and their Jacobian's information and scores). U (N, 7): the inputs of the record
    the refinement ran on; dt (s): its sample time. Several runs (fit.bounds, U the runs'
    inputs stacked as the residuals): the cross-correlation is taken on the runs stacked with
    NaN gaps longer than its lags, so no lag pairs a residual of one run with an input of
    another. depth : (N,) the runs' measured z (m, NED; NaN where not measured) for the frame's
    plausibility, or None.
    information_cov : the covariance of what the run's information alone says (an automatic
    choice's, without the consider covariance of the left-out coefficients): the verdicts are
    judged by it, since a coefficient the run determines well is not 'not excited' because the
    coefficients left at the file's values widen its bar (None: cov). selection : the automatic
    choice that was made (its advice then names what it left out), or None. Returns a
    core.identification.results.Diagnosis (its identifiability None without the refined
    residuals); an estimate that is not plausible for the vehicle file
    (core/identification/plausibility.py) puts 'NOT plausible: ...' on its first line."""
    verdicts = xcorr = None
    if fit is not None and fit.white is not None:
        lags = max(1, int(round(XCORR_SECONDS / dt)))
        white, U = fit.white, np.asarray(U, dtype=float)
        several = fit.bounds is not None and len(fit.bounds) > 2
        if several and U.shape[0] != white.shape[0]:
            raise ValueError(f'U has {U.shape[0]} rows, the stacked residuals '
                             f'{white.shape[0]}')
        # the inputs' levels and their changes (the prewhitened inputs: a lag in the response
        # to each change shows there under loud coloured noise, not against the held levels)
        dU = command_changes(white, U, fit.bounds if several else None)
        if several:
            # input_correlation's autocorrelations reach 4 max(lags, LJUNG_BOX_LAGS) lags
            gap = 4 * max(lags, LJUNG_BOX_LAGS) + 1
            white = with_gaps(split_rows(white, fit.bounds), gap)
            U = with_gaps(split_rows(U, fit.bounds), gap)
            dU = with_gaps(split_rows(dU, fit.bounds), gap)
        xcorr = sorted(
            input_correlation(white, U, lags, STATE_NAMES, vehicle.input_names)
            + input_correlation(white, dU, lags, STATE_NAMES,
                                [f'the changes of {n}' for n in vehicle.input_names]),
            key=lambda c: -abs(c[0]))
        verdicts = coefficient_verdicts(vehicle, names, np.asarray(estimate), fit.information,
                                        cov if information_cov is None else information_cov)
    diagnosis = Diagnosis(identifiability=verdicts,
                          **diagnose(fit, xcorr, dt, mean_nis_per_dof, verdicts, refined,
                                     remedy=inadequacy_remedy(vehicle, selection)))
    return judge_plausibility(diagnosis, vehicle, names, estimate, cov, depth)


def judge_plausibility(diagnosis: Diagnosis, vehicle: Vehicle, names: Sequence[str],
                       estimate: np.ndarray, cov: np.ndarray,
                       depth: np.ndarray | None = None) -> Diagnosis:
    """The diagnosis with the plausibility of the estimates for the vehicle file
    (core/identification/plausibility.py): coefficients of a forbidden sign or far outside the
    file's prior, and a depth that puts a submerged vehicle above the water, each named on the
    first line as NOT plausible, with what to check; the consistency line follows."""
    std = np.sqrt(np.clip(np.diag(np.asarray(cov, dtype=float)), 0.0, None))
    found = implausible_coefficients(vehicle, list(names), np.asarray(estimate, dtype=float),
                                     std)
    frame = '' if depth is None else depth_contradicts_down(
        depth, heave_free=bool(vehicle.free_states[State.W]))
    if not found and not frame:
        return diagnosis
    reasons = [f.reason for f in found] + ([frame] if frame else [])
    if found:
        head = what_to_check(found, frame)
    else:
        head = f'NOT plausible: {frame}'
    return replace(diagnosis, plausible=False, implausible=reasons,
                   messages=[head] + list(diagnosis.messages))
