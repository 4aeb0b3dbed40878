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

The identifier adds "diagnosis", the live diagnosis of the estimate's error bars
(session/live_diagnosis.py) in the offline result's layout: {"consistent": true, false or null
(not judged yet), "messages": [first line, ...]}, and, with the noise learning on,
"live_noise_model" (session/noise_learning.py NoiseLearner.document(): state, re-runs, the
learnt scale and the last fit's variance factor per channel). With
coefficients ['auto', ...] it adds "selection" (session/auto_choice.py AutoChoice.document():
the state of the live choice and, once made, the offline JSON's selection block); warm_start
reads only the keys above.
"""
from collections.abc import Sequence
import json
import os
from pathlib import Path
import stat
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.safe_files import write_atomic
from auv_ident.session.messages import NS_PER_S
from auv_ident.session.settings import ParameterError


def estimate_document(vehicle: str, names: Sequence[str], estimate: Sequence[float] | np.ndarray,
                      cov: ArrayLike, stamp_ns: int | None, steps: int,
                      selection: dict[str, Any] | None = None) -> dict[str, Any]:
    """The JSON-ready dict of an estimate (schema in the module docstring); selection : the
    live choice's block (AutoChoice.document()), or None for none."""
    est = [float(v) for v in estimate]
    cov = np.asarray(cov, dtype=float)
    doc: dict[str, Any] = {'vehicle': vehicle, 'coefficients': list(names), 'estimate': est,
           'std': [float(v) for v in np.sqrt(np.clip(np.diag(cov), 0.0, None))],
           'covariance': [[float(v) for v in row] for row in cov],
           'stamp': None if stamp_ns is None else stamp_ns / NS_PER_S,
           'stamp_ns': None if stamp_ns is None else int(stamp_ns),
           'steps': int(steps)}
    if selection is not None:
        doc['selection'] = selection
    return doc


def write_estimate_json(path: str | os.PathLike[str], doc: dict[str, Any]) -> Path:
    """Write an estimate document atomically (a fresh temporary file, then one rename:
    core/safe_files.py; a symlink planted beside the target redirects nothing); NaN/Inf
    refused."""
    text = json.dumps(doc, indent=1, allow_nan=False) + '\n'
    return write_atomic(Path(path), text)

MAX_ESTIMATE_BYTES = 16 * 1024 * 1024   # an estimate of p coefficients is ~25 p^2 bytes


def _has_bool(value: object) -> bool:
    if isinstance(value, bool):
        return True
    return isinstance(value, list) and any(_has_bool(v) for v in value)



def load_estimate_json(
        path: str | os.PathLike[str],
) -> tuple[str, list[str], np.ndarray, np.ndarray]:
    """Read an estimate file: (vehicle, names, estimate (p,), covariance (p, p)).

    Raises ParameterError('warm_start', ...) naming what is wrong: also for what is not a
    regular file (a FIFO would block, /dev/zero never ends), a file over MAX_ESTIMATE_BYTES,
    JSON nested beyond what a parser should follow, and true/false where numbers belong."""
    try:
        st = os.stat(path)
        if not stat.S_ISREG(st.st_mode):
            raise ParameterError('warm_start', f'{path} is not a regular file (an estimate '
                                               'file written by save_path or --estimate-out)')
        if st.st_size > MAX_ESTIMATE_BYTES:
            raise ParameterError('warm_start', f'{path}: {st.st_size} bytes, more than an '
                                               f'estimate file holds ({MAX_ESTIMATE_BYTES})')
        with open(path, encoding='utf-8') as fh:
            doc = json.load(fh)
    except ParameterError:
        raise
    except (OSError, ValueError) as err:
        raise ParameterError('warm_start', f'cannot read {path}: {err}') from err
    except RecursionError as err:
        raise ParameterError('warm_start', f'{path}: JSON nested too deeply to be an estimate '
                                           'file') from err
    if not isinstance(doc, dict):
        raise ParameterError('warm_start', f'{path}: not an estimate file (a JSON '
                                           f'{type(doc).__name__}, not an object)')
    flags = [k for k in ('estimate', 'covariance') if _has_bool(doc.get(k))]
    if flags:
        raise ParameterError('warm_start', f'{path}: true/false in {flags[0]!r}, where numbers '
                                           'belong')
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
