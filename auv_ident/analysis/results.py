"""Identification results as users see them: the coefficient table, the JSON document, and the
data a batch method takes (:class:`Source`)."""
from dataclasses import dataclass
import json

import numpy as np

from auv_ident.core.errors import ConfigError
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.model.sensors import DEFAULT_NOISE_STD
from auv_ident.session.settings import names_of

DEFAULT_NOISE_MODE = 'fixed'  # docs/method.md "Noise adaptation": fixed Q/R wins on accuracy

def coefficient_list(vehicle, coefficients):
    """Names of the `coefficients` setting ('A,B,C' or a sequence, read by
    session.settings.names_of; empty: the vehicle's paper default), validated."""
    names = list(names_of('coefficients', coefficients or ()))
    if names and names[0].lower() == 'auto':
        raise ConfigError('--coefficients auto chooses from a recorded run: use it with '
                          'identify --bag or report --bag (a simulated run: simulate --out '
                          'BAGDIR first)')
    names = names or list(vehicle.identify_default)
    if not names:
        raise ConfigError(f'no coefficients chosen and {vehicle.name} has no identify_default')
    return [vehicle.names[vehicle.index(n)] for n in names]

def make_config(names, noise_mode=DEFAULT_NOISE_MODE, initial_offset=0.5, initial=None,
                noise_std=None, tau=10.0):
    return FilterConfig(coefficients=list(names), initial=initial, initial_offset=initial_offset,
                        mode=noise_mode, tau=tau,
                        noise_std=DEFAULT_NOISE_STD.copy() if noise_std is None else noise_std)

@dataclass
class Source:
    """Data to identify from: a simulated run or a bag, as arrays on the sample grid.

    U[k] is the command in force over [t_k, t_k+1) (the pairing rule of core/filter/stream.py);
    X_true, truth and current_truth are known only for simulated data."""

    vehicle: object
    names: list
    t: np.ndarray
    Y: np.ndarray
    U: np.ndarray
    T: float
    noise_std: np.ndarray
    description: str
    X_true: object = None
    truth: object = None
    seed: object = None
    maneuver: str = ''
    current_truth: object = None        # (3,) m/s NED the run flew in, if known
    velocity_reference: str = 'ground'  # what Y's u v w are (ground or water)
    time_origin_ns: int = 0             # absolute stamp of t = 0 (a bag's; 0 if simulated)
    # a bag read without the filter (bag_source filtering False): offline/replay.py
    # rejections' (dict, line) of what its screening dropped; None otherwise
    screening: object = None

def paper_values(vehicle, name):
    """(paper's estimate, paper's error % text) or (None, None)."""
    p = vehicle.paper or {}
    est = (p.get('estimated') or {}).get(name)
    err = (p.get('error_pct') or {}).get(name)
    return est, err

def current_dict(cur, truth=None):
    """The JSON `current` of a result (schema in docs/report.md): the estimate in m/s NED and
    its 1-sigma, the EKF pass's, what was estimated, and whether the run separates it from the
    coefficients. cur: core.model.current.CurrentEstimate; truth: (3,) if known."""
    if cur is None:
        return None
    d = {'north': float(cur.estimate[0]), 'east': float(cur.estimate[1]),
         'down': float(cur.estimate[2]), 'std': [float(v) for v in cur.std],
         'estimated': list(cur.names), 'velocity_reference': cur.velocity_reference,
         'speed': cur.speed, 'direction_deg': cur.direction_deg,
         'ekf': {'north': float(cur.ekf_estimate[0]), 'east': float(cur.ekf_estimate[1]),
                 'down': float(cur.ekf_estimate[2]), 'std': [float(v) for v in cur.ekf_std]},
         'truth': None, 'error': None}
    if truth is not None:
        tr = np.asarray(truth, dtype=float)
        d['truth'] = [float(v) for v in tr]
        d['error'] = [float(v) for v in cur.estimate - tr]
    if cur.identifiability:
        d['identifiability'] = dict(cur.identifiability)
    return d


def current_warnings(cur):
    """Warning lines about the current (empty if it is well determined or not estimated)."""
    if cur is None or not cur.identifiability or cur.identifiability.get('separable', True):
        return []
    ident = cur.identifiability
    return ['warning: the water current is not separable from the coefficients in this run ('
            + '; '.join(ident['reasons']) + '). ' + ident['advice']]


def result_dict(vehicle, res, extra=None, current_truth=None):
    """The JSON document of `identify --json` (schema in docs/report.md) of an
    Identification (core.identification.results); `extra`: more entries, after the
    identification's (its noise_model, identifiability and diagnosis where extra places
    them, if it does)."""
    err = res.error_pct()
    ekf_err = res.error_pct('ekf_estimate')
    coeffs = {}
    for i, n in enumerate(res.names):
        pe, perr = paper_values(vehicle, n)
        coeffs[n] = {
            'estimate': float(res.estimate[i]), 'std': float(res.std[i]),
            'truth': None if res.truth is None else float(res.truth[i]),
            'error_pct': None if err is None else float(err[i]),
            'initial': float(res.initial[i]),
            'ekf_estimate': float(res.ekf_estimate[i]), 'ekf_std': float(res.ekf_std[i]),
            'ekf_error_pct': None if ekf_err is None else float(ekf_err[i]),
            'paper_estimate': pe, 'paper_error_pct': perr,
        }
    d = {'vehicle': vehicle.name, 'coefficients': coeffs, 'steps': res.steps,
         'wall_s': res.wall_s, 'refined': res.refined,
         'mean_nis_per_dof': res.mean_nis_per_dof,
         'covariance': res.cov.tolist(), 'units': 'vehicle file units ('
         + ('SNAME prime, (rho/2) L^k' if vehicle.raw.get('scaling') != 'dimensional'
            else 'dimensional SI') + ')',
         'current': current_dict(res.current, current_truth),
         'warnings': current_warnings(res.current)}
    extra = extra or {}
    judged = {} if res.diagnosis is None else {
        'noise_model': None if res.noise is None else res.noise.document(),
        'identifiability': res.diagnosis.identifiability,
        'diagnosis': res.diagnosis.document()}
    for key, value in judged.items():
        if value is not None and key not in extra:
            d[key] = value
    if extra:
        d.update(extra)
    return d


def _fmt(v, width=12):
    """A right-aligned table cell, always with a space before it (a 12-character value such as
    -0.000977573 would otherwise run into the cell on its left)."""
    text = f'{v:.6g}' if v is not None else '-'
    return ' ' + text.rjust(width - 1) if len(text) >= width else text.rjust(width)


def result_table(vehicle, res, doc=None):
    """The coefficient table: truth, estimate, 1-sigma, error %, and the paper's figures; then
    the water current and any warning."""
    return doc_table(result_dict(vehicle, res) if doc is None else doc)


def current_table(cur):
    """Lines of the water current (a result document's `current`), '' if none."""
    if not cur:
        return ''
    lines = [f'{"current (m/s)":<14}{"truth":>10}{"estimate":>12}{"1-sigma":>12}{"EKF pass":>12}']
    for i, (name, key) in enumerate((('north', 'north'), ('east', 'east'), ('down', 'down'))):
        est = cur[key]
        est_txt = f'{est:>12.5f}' if f'current_{name[0]}' in cur['estimated'] else \
            f'{"(given) " + format(est, ".3g"):>12}'
        truth = cur['truth'][i] if cur.get('truth') else None
        lines.append(f'{name:<14}' + (f'{truth:>10.4f}' if truth is not None else f'{"-":>10}')
                     + est_txt + f'{cur["std"][i]:>12.2g}' + f'{cur["ekf"][key]:>12.5f}')
    lines.append(f'current speed {cur["speed"]:.4f} m/s towards {cur["direction_deg"]:.1f} deg '
                 f'(where the water goes, clockwise from north); velocity reference '
                 f'{cur["velocity_reference"]}')
    ident = cur.get('identifiability')
    if ident:
        lines.append(f'headings covered {ident["heading_span_deg"]:.0f} deg; largest correlation '
                     f'with a coefficient {ident["max_correlation"]:.2f} '
                     f'({ident["correlated_with"]})')
    return '\n'.join(lines)


def doc_table(doc):
    """The coefficient table of a result document (result_dict / identify --json), with the
    water current and the warnings after it."""
    lines = [f'{"coefficient":<12}{"truth":>12}{"estimate":>12}{"1-sigma":>12}{"error %":>10}'
             f'{"paper est.":>12}{"paper err %":>12}']
    for n, c in doc['coefficients'].items():
        err = c['error_pct']
        perr = c['paper_error_pct']
        lines.append(f'{n:<12}{_fmt(c["truth"])}{_fmt(c["estimate"])}{_fmt(c["std"])}'
                     + (f'{err:>+10.3f}' if err is not None else f'{"-":>10}')
                     + _fmt(c['paper_estimate']) + f'{perr if perr is not None else "-":>12}')
    cur = current_table(doc.get('current'))
    if cur:
        lines.append(cur)
    lines += list(doc.get('warnings') or [])
    return '\n'.join(lines)


def write_json(path, doc):
    with open(path, 'w', encoding='utf-8') as fh:
        json.dump(doc, fh, indent=2)
