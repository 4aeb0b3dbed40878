"""`compare-methods`: the same data through the standard identification methods, side by side.

Methods (docs/methods.md says what each assumes and when to use it):

- ``ekf``: the augmented EKF pass (core/filter/ekf.py), with the noise model from the data
  (core/identification/noise_fit.py), as ``identify --no-refine``;
- ``ukf``: the augmented unscented Kalman filter (core/identification/ukf.py), same prior, Q, R and
time line;
- ``filter_error``: the filter-error maximum likelihood refinement (core/identification/batch.py
refine, via
  noise_fit.identify_with_noise_model), as ``identify``;
- ``output_error``: output-error maximum likelihood, multiple shooting
(core/identification/output_error.py);
- ``equation_error``: equation-error least squares (core/identification/equation_error.py).

Every method starts from the same initial guesses (the vehicle file's values times
1 + initial_offset, as ``identify``) and the recursive and likelihood methods use the same
measurement noise (the EKF pass's, from the data). Each is timed from the data to its answer
(wall_s; the filter-error time includes its own noise-model and EKF passes).

Validation: each method's model is run open loop (core/prediction.free_run) from the validation
run's first fully measured state with its commands, and scored per channel by fit %
(prediction.fit_percent, angles made comparable by angle_channels). The validation run is
another record (``--validate B``), or else the final ``holdout`` fraction of the identification
record, which is then left out of the identification (said in the result). A coefficient a
method refuses keeps its initial guess in that method's model.

ROS-free; the sources come from analysis/experiments.load_source.
"""
from dataclasses import dataclass, field, replace
import json
import math
import time

import numpy as np

from auv_ident.analysis.experiments import load_source
from auv_ident.analysis.report_format import finite_cell
from auv_ident.analysis.results import make_config
from auv_ident.core.errors import AuvIdentError, ConfigError
from auv_ident.core.identification.equation_error import equation_error
from auv_ident.core.identification.noise_fit import identify_with_noise_model
from auv_ident.core.identification.output_error import DEFAULT_SEGMENT_S, output_error
from auv_ident.core.identification.results import Record
from auv_ident.core.identification.ukf import run_ukf
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import State, STATE_NAMES
from auv_ident.core.model.thruster_lag import derivative
from auv_ident.core.simulation.prediction import angle_channels, fit_percent, free_run
from auv_ident.session.settings import IdentifierSettings

METHODS = ('ekf', 'ukf', 'filter_error', 'output_error', 'equation_error')
HOLDOUT_FRACTION = 0.2      # final part of the record kept for validation without --validate
# channels summarised in the table (all 12 are in the JSON)
TABLE_CHANNELS = ('u', 'v', 'w', 'p', 'q', 'r', 'phi', 'theta', 'psi', 'z')
_START = [State.U, State.V, State.W, State.P, State.Q, State.R, State.PHI, State.THETA,
          State.PSI]


def parse_methods(text):
    """Method names from 'a,b' (empty: all), validated."""
    names = [m.strip() for m in (text or '').split(',') if m.strip()] or list(METHODS)
    bad = [m for m in names if m not in METHODS]
    if bad:
        raise ConfigError(f'unknown method {bad[0]!r}; known: {", ".join(METHODS)}')
    return names


@dataclass
class MethodResult:
    """One method's answer: estimate and 1-sigma (p,) (NaN: not given), {name: reason} of the
    coefficients it refused, notes, and the noise model it read off the data (the EKF pass's,
    which the other methods then use)."""

    estimate: np.ndarray
    std: np.ndarray
    refused: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    noise: object = None


def _ekf(model, cfg, t, Y, U, T):
    est = identify_with_noise_model(model, cfg, [Record(t, Y, U)], T=T, refine_pass=False)
    return MethodResult(est.ekf_estimate, np.sqrt(np.diag(est.ekf_cov)),
                        notes=list(est.noise.notes), noise=est.noise)


def _filter_error(model, cfg, t, Y, U, T):
    est = identify_with_noise_model(model, cfg, [Record(t, Y, U)], T=T, refine_pass=True)
    fit = est.noise
    notes = [f'{fit.covariance} covariance']
    if not fit.refine_converged:
        notes.append(f'refinement did not converge: {fit.refine_message}')
    return MethodResult(est.estimate, np.sqrt(np.diag(est.cov)), notes=notes)


def _ukf(model, cfg, t, Y, U, T):
    r = run_ukf(model, cfg, t, Y, U, T=T)
    return MethodResult(r.theta, r.theta_std, notes=[f'mean NIS/dof {r.mean_nis_per_dof:.3f}'])


def _output_error(model, cfg, t, Y, U, T):
    theta0 = np.asarray(cfg.initial, dtype=float)
    r = output_error(model, t, Y, U, theta0, cfg.noise_std, T=T)
    notes = [f'{r.segments} segments of up to {DEFAULT_SEGMENT_S:g} s, starts estimated; fitted '
             + ' '.join(r.channels)]
    if not r.converged:
        notes.append('the search stopped at its evaluation limit')
    return MethodResult(r.theta, r.theta_std, notes=notes)


def _equation_error(model, cfg, t, Y, U, T):
    r = equation_error(model, t, Y, U, measured=cfg.measured, T=T)
    notes = [f'R^2 {eq} {v:.3f}' for eq, v in r.r_squared.items()]
    return MethodResult(r.estimate, r.std, dict(r.refused), notes)


RUNNERS = {'ekf': _ekf, 'ukf': _ukf, 'filter_error': _filter_error,
           'output_error': _output_error, 'equation_error': _equation_error}


def validation_fit(model, theta, t, Y, U):
    """{channel: fit %} of the model with theta (p,) run open loop from the first sample of
    (t, Y, U) whose dynamic states are all measured (NaN where the free run left the model's
    domain)."""
    ok = np.flatnonzero(np.all(np.isfinite(Y[:, _START]), axis=1))
    if ok.size == 0:
        raise ConfigError('validation run: no sample has the velocities and attitude measured '
                          'to start the free run from')
    k = ok[0]
    x0 = np.where(np.isfinite(Y[k]), Y[k], 0.0)
    X = free_run(derivative(model, theta), t[k:], U[k:], x0)   # a lagged thrust carried
    Ym, Xm = angle_channels(Y[k:], X)
    return {name: fit_percent(Ym[:, i], Xm[:, i]) for i, name in enumerate(STATE_NAMES)}


def _split(source, holdout):
    """(ident (t, Y, U), validation (t, Y, U), description) of the record cut at the final
    `holdout` fraction."""
    if not 0.0 < holdout < 1.0:
        raise ConfigError(f'holdout = {holdout!r}: a fraction in (0, 1)')
    t, Y, U = source.t, source.Y, source.U
    cut = int(round(len(t) * (1.0 - holdout)))
    desc = (f'the final {100 * holdout:.0f} % of the identification record (t >= '
            f'{t[cut] - t[0]:.1f} s), left out of the identification')
    return (t[:cut], Y[:cut], U[:cut]), (t[cut:], Y[cut:], U[cut:]), desc


def _jsonable(v):
    v = float(v)
    return v if math.isfinite(v) else None


def compare_methods(source, validation=None, methods=METHODS, initial_offset=0.5,
                    holdout=HOLDOUT_FRACTION, progress=None, mass_inverse='default'):
    """Run `methods` on a Source (analysis/results.Source) and validate each.

    validation : a Source to validate on (None: the final `holdout` fraction of `source`, left
        out of the identification)
    progress : callable(method name), called before each method
    mass_inverse : the identified model's M^-1 (core.model.hydrodynamics.Model; 'exact' to identify
    added
        mass with the methods that can)

    Returns the result dict (JSON-ready): 'source', 'vehicle', 'coefficients' (names),
    'truth' and 'initial' {name: value}, 'validation' {'description', 'samples'}, and
    'methods' {method: {'coefficients': {name: {'estimate', 'std', 'error_pct'[, 'refused']}},
    'wall_s', 'fit_percent' {channel: %}, 'notes'[, 'error']}}, and 'reference_fit_percent'
    {'initial guess': {channel: %}[, 'truth': ...]}: the fit % of the common start and, when the
    truth is known, of the true model (the ceiling the sensor noise leaves).
    """
    methods = list(methods)
    v = source.vehicle
    names = list(source.names)
    model = Model(v, names, mass_inverse=mass_inverse)
    truth = None if source.truth is None else np.asarray(source.truth, float)[:len(names)]
    theta0 = model.theta_true * (1.0 + initial_offset)
    if validation is None:
        (t, Y, U), (tv, Yv, Uv), vdesc = _split(source, holdout)
    else:
        t, Y, U = source.t, source.Y, source.U
        tv, Yv, Uv = validation.t, validation.Y, validation.U
        vdesc = validation.description
    T = source.T
    cfg = make_config(names, noise_mode='fixed', initial=theta0, noise_std=source.noise_std)
    doc = {'source': source.description, 'vehicle': v.name, 'coefficients': names,
           'truth': None if truth is None else {n: float(x) for n, x in zip(names, truth)},
           'initial': {n: float(x) for n, x in zip(names, theta0)},
           'initial_offset': initial_offset,
           'identification_samples': int(len(t)),
           'validation': {'description': vdesc, 'samples': int(len(tv))},
           'assumptions': 'still water (no current parameters); fixed Q and R; the same '
                          'initial guesses and measurement noise for every method',
           'methods': {}}
    if source.current_truth is not None and np.any(np.asarray(source.current_truth) != 0):
        doc['warnings'] = ['the run was flown in a water current and every method here '
                           'assumes still water: expect biased coefficients']
    cfg_run = cfg
    order = (['ekf'] if 'ekf' in methods else []) + [m for m in methods if m != 'ekf']
    for name in order:
        if progress is not None:
            progress(name)
        t0 = time.perf_counter()
        entry = {'coefficients': {}, 'wall_s': None, 'fit_percent': {}, 'notes': []}
        try:
            out = RUNNERS[name](model, cfg_run, t, Y, U, T)
        except (AuvIdentError, ArithmeticError, np.linalg.LinAlgError) as err:
            entry['error'] = f'{type(err).__name__}: {err}'
            entry['wall_s'] = time.perf_counter() - t0
            doc['methods'][name] = entry
            continue
        entry['wall_s'] = time.perf_counter() - t0
        est, std, refused = out.estimate, out.std, out.refused
        if out.noise is not None and out.noise.used:
            # the other methods use the noise the data showed
            cfg_run = replace(cfg, noise_std=out.noise.effective_std.copy())
        entry['notes'] = out.notes
        for i, n in enumerate(names):
            c = {'estimate': _jsonable(est[i]), 'std': _jsonable(std[i]),
                 'error_pct': (None if truth is None or not np.isfinite(est[i])
                               else float(100.0 * (est[i] - truth[i]) / abs(truth[i])))}
            if n in refused:
                c['refused'] = refused[n]
            entry['coefficients'][n] = c
        used = np.where(np.isfinite(est), est, theta0)
        entry['fit_percent'] = {k: _jsonable(x)
                                for k, x in validation_fit(model, used, tv, Yv, Uv).items()}
        doc['methods'][name] = entry
    doc['methods'] = {m: doc['methods'][m] for m in methods}
    # references for the fit %: the model at the common initial guess, and (when known) the
    # truth, whose fit is the ceiling the sensor noise leaves
    doc['reference_fit_percent'] = {'initial guess': {
        k: _jsonable(x) for k, x in validation_fit(model, theta0, tv, Yv, Uv).items()}}
    if truth is not None:
        doc['reference_fit_percent']['truth'] = {
            k: _jsonable(x) for k, x in validation_fit(model, truth, tv, Yv, Uv).items()}
    return doc


def read_truth(path, names):
    """(p,) the true values of `names` from a JSON file with a "coefficients" mapping (the
    truth.json that test/independent_data.py writes next to its bags). ConfigError naming the
    file and the missing coefficient otherwise."""
    try:
        with open(path, encoding='utf-8') as fh:
            doc = json.load(fh)
    except (OSError, ValueError) as err:
        raise ConfigError(f'--truth {path}: cannot read it as JSON ({err})') from None
    coefs = doc.get('coefficients') if isinstance(doc, dict) else None
    if not isinstance(coefs, dict):
        raise ConfigError(f'--truth {path}: no "coefficients" mapping')
    missing = [n for n in names if n not in coefs]
    if missing:
        raise ConfigError(f'--truth {path}: no value for {missing[0]}')
    try:
        return np.array([float(coefs[n]) for n in names])
    except (TypeError, ValueError):
        raise ConfigError(f'--truth {path}: a value of {", ".join(names)} is not a number') \
            from None


def compare_sources(settings=None, simulate_maneuver=None, bag=None, seed=0, duration=600.0,
                    validate=None, truth=None):
    """(source, validation or None) for the command line: --simulate M or --bag A, and
    --validate B (a bag); settings: IdentifierSettings of which the vehicle and coefficients
    apply (load_source); truth: a JSON file with the true coefficients (read_truth), for bags
    not written by our simulator."""
    settings = settings or IdentifierSettings()
    source = load_source(IdentifierSettings.from_values(
        **{n: getattr(settings, n) for n in settings.given & {'vehicle', 'coefficients'}}),
        simulate_maneuver=simulate_maneuver, bag=bag, seed=seed, duration=duration)
    if truth:
        source = replace(source, truth=read_truth(truth, source.names))
    validation = None
    if validate:
        validation = load_source(IdentifierSettings.from_values(
            vehicle=source.vehicle.name, coefficients=source.names), bag=validate)
    return source, validation


def methods_table(doc):
    """The printable comparison: per coefficient and method estimate, 1-sigma, error %; per
    method wall time and validation fit % of the main channels."""
    methods = list(doc['methods'])
    lines = [f'{doc["source"]}', f'validation: {doc["validation"]["description"]}']
    head = f'{"coefficient":<12}{"method":<16}{"estimate":>12}{"1-sigma":>12}{"error %":>10}'
    lines.append(head)
    for n in doc['coefficients']:
        truth = (doc['truth'] or {}).get(n)
        lines.append(f'{n:<12}{"(truth)" if truth is not None else "":<16}'
                     + (f'{truth:>12.6g}' if truth is not None else ''))
        for m in methods:
            e = doc['methods'][m]
            if 'error' in e:
                continue
            c = e['coefficients'][n]
            if 'refused' in c:
                lines.append(f'{"":<12}{m:<16}{"refused":>12}  {c["refused"]}')
                continue
            lines.append(f'{"":<12}{m:<16}{finite_cell(c["estimate"], ">12.6g")}'
                         f'{finite_cell(c["std"], ">12.3g")}'
                         f'{finite_cell(c["error_pct"], ">+10.3f")}')
    lines.append('fit % of each model run open loop over the validation run:')
    lines.append(f'{"method":<16}{"wall s":>8}  ' + ' '.join(f'{ch:>6}' for ch in TABLE_CHANNELS))
    for m in methods:
        e = doc['methods'][m]
        if 'error' in e:
            lines.append(f'{m:<16}{e["wall_s"]:>8.2f}  failed: {e["error"]}')
            continue
        fits = ' '.join(finite_cell(e['fit_percent'].get(ch), '>6.1f') for ch in TABLE_CHANNELS)
        lines.append(f'{m:<16}{e["wall_s"]:>8.2f}  {fits}')
    for ref, fits in (doc.get('reference_fit_percent') or {}).items():
        lines.append(f'{"(" + ref + ")":<16}{"":>8}  '
                     + ' '.join(f'{finite_cell(fits.get(ch), ">6.1f")}' for ch in TABLE_CHANNELS))
    for m in methods:
        notes = doc['methods'][m].get('notes')
        if notes:
            lines.append(f'{m}: ' + '; '.join(notes))
    lines += list(doc.get('warnings') or [])
    return '\n'.join(lines)


def methods_markdown(doc):
    """The comparison as Markdown (for a report's "methods" section): per method and coefficient
    the estimate, 1-sigma and error % (with error / 1-sigma when the truth is known), the wall
    time, then the validation fit % table with the references."""
    names = doc['coefficients']
    lines = [f'Data: {doc["source"]}. Validation: {doc["validation"]["description"]}.', '',
             '| method | ' + ' | '.join(names) + ' | wall s |',
             '|---|' + '---|' * (len(names) + 1)]
    for m, e in doc['methods'].items():
        if 'error' in e:
            lines.append(f'| {m} | failed: {e["error"]} |' + ' |' * len(names))
            continue
        cells = []
        for n in names:
            c = e['coefficients'][n]
            if 'refused' in c or c['estimate'] is None:
                cells.append('refused' if 'refused' in c else '-')
                continue
            cell = f'{c["estimate"]:.6g} ± {finite_cell(c["std"], ".2g")}'
            if c['error_pct'] is not None:
                z = ((c['estimate'] - doc['truth'][n]) / c['std']) if c['std'] else None
                cell += f' ({c["error_pct"]:+.2f} %' + (f', {z:+.1f} σ)' if z is not None
                                                          else ')')
            cells.append(cell)
        lines.append(f'| {m} | ' + ' | '.join(cells) + f' | {e["wall_s"]:.2f} |')
    lines += ['', 'Fit % of each model run open loop over the validation run:', '',
              '| model | ' + ' | '.join(TABLE_CHANNELS) + ' |',
              '|---|' + '---|' * len(TABLE_CHANNELS)]
    rows = [(m, e['fit_percent']) for m, e in doc['methods'].items() if 'error' not in e]
    rows += [(f'({ref})', fits) for ref, fits in (doc.get('reference_fit_percent') or {}).items()]
    for label, fits in rows:
        lines.append(f'| {label} | ' + ' | '.join(finite_cell(fits.get(ch), '.1f')
                                                 for ch in TABLE_CHANNELS) + ' |')
    refused = [f'{m}: {n} refused ({c["refused"]})' for m, e in doc['methods'].items()
               for n, c in e.get('coefficients', {}).items() if 'refused' in c]
    if refused:
        lines += [''] + [f'- {r}' for r in refused]
    return '\n'.join(lines)
