"""The estimate file: one JSON document holding a coefficient estimate and its covariance.

Written atomically by the identifier node (``~/save``, on shutdown and every 10 s while
updates arrive; always the session's last good estimate, IdentSession.document()) and by
``identify --json``; read back by ``warm_start`` (:func:`load_estimate_json`)::

    {"vehicle": "nps_auv2",                 # vehicle name
     "coefficients": ["Z_ds", ...],         # p names, order of everything below
     "estimate": [..p floats..],            # vehicle file's units
     "std": [..p floats..],                 # 1-sigma, sqrt(diag(covariance))
     "covariance": [[..p..], ..p rows..],   # p x p, symmetric
     "stamp": 123.45,                       # s, odometry stamp of the last update (null: none)
     "stamp_ns": 123450000000,              # the same stamp in integer ns (null: none)
     "steps": 2400}                         # accepted odometry updates since start-up

With coefficients ['auto', ...] the identifier adds "selection" (session/auto_choice.py
AutoChoice.document(): the state of the live choice and, once made, the offline JSON's
selection block); warm_start reads only the keys above.
"""
import json
import os
from pathlib import Path

import numpy as np

from auv_ident.session.messages import NS_PER_S
from auv_ident.session.settings import ParameterError


def estimate_document(vehicle, names, estimate, cov, stamp_ns, steps, selection=None):
    """The JSON-ready dict of an estimate (schema in the module docstring); selection : the
    live choice's block (AutoChoice.document()), or None for none."""
    est = [float(v) for v in estimate]
    cov = np.asarray(cov, dtype=float)
    doc = {'vehicle': vehicle, 'coefficients': list(names), 'estimate': est,
           'std': [float(v) for v in np.sqrt(np.clip(np.diag(cov), 0.0, None))],
           'covariance': [[float(v) for v in row] for row in cov],
           'stamp': None if stamp_ns is None else stamp_ns / NS_PER_S,
           'stamp_ns': None if stamp_ns is None else int(stamp_ns),
           'steps': int(steps)}
    if selection is not None:
        doc['selection'] = selection
    return doc

def write_estimate_json(path, doc):
    """Write an estimate document atomically (temp file + rename); NaN/Inf refused."""
    path = Path(path)
    text = json.dumps(doc, indent=1, allow_nan=False) + '\n'
    # a plain open() (not mkstemp, which makes the file 0600) keeps the umask's permissions
    tmp = path.with_name(f'.{path.name}.{os.getpid()}.tmp')
    try:
        with open(tmp, 'w', encoding='utf-8') as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return path

def load_estimate_json(path):
    """Read an estimate file: (vehicle, names, estimate (p,), covariance (p, p)).

    Raises ParameterError('warm_start', ...) naming what is wrong."""
    try:
        with open(path, encoding='utf-8') as fh:
            doc = json.load(fh)
    except (OSError, ValueError) as err:
        raise ParameterError('warm_start', f'cannot read {path}: {err}') from None
    try:
        vehicle = str(doc['vehicle'])
        names = [str(n) for n in doc['coefficients']]
        est = np.asarray(doc['estimate'], dtype=float)
        cov = np.asarray(doc['covariance'], dtype=float)
    except (KeyError, TypeError, ValueError) as err:
        raise ParameterError('warm_start', f'{path}: not an estimate file ({err!r}); expected '
                                           'keys vehicle, coefficients, estimate, covariance') \
            from None
    p = len(names)
    if p == 0 or est.shape != (p,) or cov.shape != (p, p):
        raise ParameterError('warm_start', f'{path}: {p} coefficients but estimate shape '
                                           f'{est.shape} and covariance shape {cov.shape}')
    if not (np.all(np.isfinite(est)) and np.all(np.isfinite(cov))):
        raise ParameterError('warm_start', f'{path}: non-finite estimate or covariance')
    cov = 0.5 * (cov + cov.T)
    if np.any(np.linalg.eigvalsh(cov) <= 0):
        raise ParameterError('warm_start', f'{path}: covariance is not positive definite')
    return vehicle, names, est, cov
