"""Identification results as users see them: the coefficient table, the JSON document, and the
data a batch method takes (:class:`Source`)."""
import json
from dataclasses import dataclass

import numpy as np

from auv_ident.core.errors import ConfigError
from auv_ident.core.filter import FilterConfig
from auv_ident.core.sensors import DEFAULT_NOISE_STD

DEFAULT_NOISE_MODE = 'fixed'  # docs/method.md "Noise adaptation": fixed Q/R wins on accuracy

def coefficient_list(vehicle, text):
    """Names from 'A,B,C' (or the vehicle's paper default when empty), validated."""
    names = [n.strip() for n in (text or '').split(',') if n.strip()]
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

    U[k] is the command in force over [t_k, t_k+1) (the pairing rule of core/stream.py);
    X_true and truth are known only for simulated data."""

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

def paper_values(vehicle, name):
    """(paper's estimate, paper's error % text) or (None, None)."""
    p = vehicle.paper or {}
    est = (p.get('estimated') or {}).get(name)
    err = (p.get('error_pct') or {}).get(name)
    return est, err

def result_dict(vehicle, res, extra=None):
    """The JSON document of `identify --json` (schema in docs/report.md)."""
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
            else 'dimensional SI') + ')'}
    if extra:
        d.update(extra)
    return d

def _fmt(v, width=12):
    return f'{v:>{width}.6g}' if v is not None else f'{"-":>{width}}'

def result_table(vehicle, res):
    """The coefficient table: truth, estimate, 1-sigma, error %, and the paper's figures."""
    return doc_table(result_dict(vehicle, res))

def doc_table(doc):
    """The coefficient table of a result document (result_dict / identify --json)."""
    lines = [f'{"coefficient":<12}{"truth":>12}{"estimate":>12}{"1-sigma":>12}{"error %":>10}'
             f'{"paper est.":>12}{"paper err %":>12}']
    for n, c in doc['coefficients'].items():
        err = c['error_pct']
        perr = c['paper_error_pct']
        lines.append(f'{n:<12}{_fmt(c["truth"])}{_fmt(c["estimate"])}{_fmt(c["std"])}'
                     + (f'{err:>+10.3f}' if err is not None else f'{"-":>10}')
                     + _fmt(c['paper_estimate']) + f'{perr if perr is not None else "-":>12}')
    return '\n'.join(lines)

def write_json(path, doc):
    with open(path, 'w', encoding='utf-8') as fh:
        json.dump(doc, fh, indent=2)
