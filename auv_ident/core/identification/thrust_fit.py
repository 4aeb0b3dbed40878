"""A propeller thrust model for runs at constant propeller rev, fitted to measured thrust.

``thrust = fit_thrust_model(runs)``: at constant rev n the open-water thrust
``T = rho n^2 D^4 K_T(J)``, ``J = u (1 - w) / (n D)``, with K_T close to linear or quadratic in
J, is a quadratic in the surge speed u: ``T = a + b u + c u^2`` (N, u in m/s). In a turn the
wake fraction w changes with the drift and the yaw rate, and a single screw sees drift to
either side differently, so the model may add terms in the sway speed v (m/s) and the yaw
rate r (rad/s). ``terms`` picks them by name from :data:`TERMS`; the coefficients come from
linear least squares over all samples of all runs, and every run is also predicted by the
model fitted on the others (leave-one-run-out), which is the figure that says whether a term
helps.

On the four HSVA KVLCC2 zig-zags (n = 10.2295 rps; tools/zigzag_measures.py, docs/zigzag.md)
the thrust residual is slow (it keeps its rms when smoothed over 1 s), not sensor noise; the
sway speed carries most of what u leaves.

runs : each a measured run (``t``, ``x`` (N, 12), ``inputs['thrust']`` (N,) N) or a tuple
``(x (N, 12), thrust (N,))``. The model is a callable: ``thrust(x)`` with x (12,) or (N, 12)
gives N.
"""
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from auv_ident.core.errors import ConfigError, DataError
from auv_ident.core.model.state import N_STATE, State

# name -> function of the state columns (u, v, r): the regressors a thrust model may use
TERMS = {
    '1': lambda u, v, r: np.ones_like(u),
    'u': lambda u, v, r: u,
    'uu': lambda u, v, r: u * u,
    'v': lambda u, v, r: v,
    'r': lambda u, v, r: r,
    'vv': lambda u, v, r: v * v,
    'rr': lambda u, v, r: r * r,
    'vr': lambda u, v, r: v * r,
}
TERM_UNITS = {'1': 'N', 'u': 'N s/m', 'uu': 'N s^2/m^2', 'v': 'N s/m', 'r': 'N s',
              'vv': 'N s^2/m^2', 'rr': 'N s^2', 'vr': 'N s^2/m'}
SPEED_TERMS = ('1', 'u', 'uu')
DEFAULT_TERMS = ('1', 'u', 'uu', 'v', 'r')


@dataclass
class ThrustModel:
    """T(x) = sum_k coefficients[k] * TERMS[terms[k]](u, v, r), N.

    terms : names from TERMS; coefficients : (len(terms),) in TERM_UNITS
    rms : N, residual rms over the fitting samples; loro_rms : N per run, each run predicted
    by the model fitted on the other runs (empty with one run); n_samples : fitting samples
    """

    terms: tuple
    coefficients: np.ndarray
    rms: float = float('nan')
    loro_rms: list = field(default_factory=list)
    n_samples: int = 0

    def __call__(self, x: np.ndarray) -> Any:
        x = np.asarray(x, dtype=float)
        return regressors(x, self.terms) @ self.coefficients

    def formula(self) -> str:
        """The model as text, e.g. 'T = 56.0 - 4.47 u - 4.95 u^2 [N]'."""
        sym = {'1': '', 'u': ' u', 'uu': ' u^2', 'v': ' v', 'r': ' r', 'vv': ' v^2',
               'rr': ' r^2', 'vr': ' v r'}
        parts = []
        for k, (name, c) in enumerate(zip(self.terms, self.coefficients)):
            s = f'{abs(c):.4g}{sym[name]}'
            parts.append(('-' if c < 0 else '') + s if k == 0 else
                         (' - ' if c < 0 else ' + ') + s)
        return 'T = ' + ''.join(parts) + ' [N] (u, v m/s, r rad/s)'

    def as_dict(self) -> dict[str, Any]:
        return {'terms': list(self.terms), 'coefficients': [float(c) for c in self.coefficients],
                'rms_N': self.rms, 'loro_rms_N': list(self.loro_rms),
                'n_samples': self.n_samples, 'formula': self.formula()}


def regressors(x: np.ndarray, terms: Sequence[str]) -> np.ndarray:
    """(N, len(terms)) (or (len(terms),) for one state) regressor matrix of the states x."""
    x = np.asarray(x, dtype=float)
    if x.shape[-1] != N_STATE:
        raise ConfigError(f'a thrust model takes states of {N_STATE} columns, got {x.shape}')
    u, v, r = x[..., State.U], x[..., State.V], x[..., State.R]
    return np.stack([TERMS[k](u, v, r) for k in terms], axis=-1)


def _run_data(run: Any) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(run, tuple) and len(run) == 2:
        x, thrust = (np.asarray(a, dtype=float) for a in run)
    else:
        try:
            x, thrust = np.asarray(run.x, dtype=float), np.asarray(run.inputs['thrust'], float)
        except (AttributeError, KeyError, TypeError) as err:
            raise DataError(f'{run!r:.80} is neither an (x, thrust) tuple nor a measured run '
                            'with x and inputs["thrust"]') from err
    if x.ndim != 2 or x.shape[1] != N_STATE or thrust.shape != (len(x),):
        raise DataError(f'thrust data: x must be (N, {N_STATE}) and thrust (N,), got '
                        f'{x.shape} and {thrust.shape}')
    ok = np.all(np.isfinite(x), axis=1) & np.isfinite(thrust)
    return x[ok], thrust[ok]


def _lstsq(A: np.ndarray, y: np.ndarray) -> np.ndarray:
    coef, _, rank, _ = np.linalg.lstsq(A, y, rcond=None)
    if rank < A.shape[1]:
        raise DataError(f'the thrust data cannot separate the terms (regressor rank {rank} of '
                        f'{A.shape[1]}): use fewer terms')
    return coef


def fit_thrust_model(runs: Sequence[Any], terms: Sequence[str] = DEFAULT_TERMS) -> ThrustModel:
    """Least-squares thrust model (module docstring) over the runs' samples.

    Parameters
    ----------
    runs : sequence of measured runs or (x (N, 12), thrust (N,) N) tuples
    terms : names from TERMS (SPEED_TERMS: T(u) only; DEFAULT_TERMS: T(u, v, r))

    Returns
    -------
    ThrustModel with its residual rms and leave-one-run-out rms (N)
    """
    terms = tuple(terms)
    bad = [k for k in terms if k not in TERMS]
    if bad or not terms or len(set(terms)) != len(terms):
        raise ConfigError(f'thrust model terms {terms}: each once, from {", ".join(TERMS)}')
    data = [_run_data(r) for r in runs]
    if not data or sum(len(y) for _, y in data) < 2 * len(terms):
        raise DataError(f'too few thrust samples for {len(terms)} terms')
    A = [regressors(x, terms) for x, _ in data]
    y = [t for _, t in data]
    coef = _lstsq(np.vstack(A), np.concatenate(y))
    res = np.concatenate(y) - np.vstack(A) @ coef
    loro = []
    if len(data) > 1:
        for j in range(len(data)):
            c = _lstsq(np.vstack(A[:j] + A[j + 1:]), np.concatenate(y[:j] + y[j + 1:]))
            loro.append(float(np.sqrt(np.mean((y[j] - A[j] @ c) ** 2))))
    return ThrustModel(terms=terms, coefficients=coef, rms=float(np.sqrt(np.mean(res ** 2))),
                       loro_rms=loro, n_samples=int(len(res)))
