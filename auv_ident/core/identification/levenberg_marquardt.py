"""Levenberg-Marquardt on normal equations built chunk by chunk: MINPACK's lmder (Moré 1978)
without the Jacobian.

MINPACK's lmder (scipy's leastsq and least_squares(method='lm')) keeps the whole (M, p)
Jacobian, and scipy's wrapper a second copy of it: 70 MB for the filter-error refinement of an
hour of 20 Hz data (M = 12 N = 720 000 residuals, p = 6; docs/reliability.md, bounded memory).
Every quantity lmder takes from the Jacobian is a function of the normal equations
A = J^T J (p, p) and g = J^T r (p,) alone: the Gauss-Newton step, the trust-region parameter
(lmpar: ||R^-T v||^2 = v^T A^-1 v for the QR factor R of J), the predicted reduction
(||J s||^2 = s^T A s), the column norms of the scaling (sqrt(A_jj)) and the gradient test
(|g_j| / (||J_j|| ||r||)). So this is lmder's iteration, step for step (the same trust-region
updates, Marquardt scaling or a fixed one, the same ftol/xtol/gtol tests and status), on A
and g; a problem supplies them however it likes. :class:`ChunkedForwardDifferences` builds
them by forward differences over chunks of the residual vector, so no more than a chunk of
the Jacobian exists at once.

The numbers differ from MINPACK's at the rounding level (A squares J's condition number: fine
for the few well-scaled parameters of a refinement, where it is far below 1/eps); the
converged point agrees within the tolerances (test/core/test_levenberg_marquardt.py).
"""
from dataclasses import dataclass
import math
from typing import Any, Callable, Iterable, Iterator, Optional

import numpy as np

EPS = float(np.finfo(float).eps)
DWARF = float(np.finfo(float).tiny)

# least_squares(method='lm')'s status and messages (its numbering of MINPACK's info)
MESSAGES = {
    0: 'The maximum number of function evaluations is exceeded.',
    1: '`gtol` termination condition is satisfied.',
    2: '`ftol` termination condition is satisfied.',
    3: '`xtol` termination condition is satisfied.',
    4: 'Both `ftol` and `xtol` termination conditions are satisfied.'}


@dataclass
class Solution:
    """What :func:`levenberg_marquardt` found.

    x : (p,) the parameters; cost : 0.5 ||r(x)||^2; status : 0 evaluations exhausted, 1 gtol,
    2 ftol, 3 xtol, 4 ftol and xtol (least_squares' numbering; MINPACK's "tolerance too small"
    cases count as the test they refine); message : its text; nfev : residual evaluations at
    trial points (MINPACK's count: the Jacobian's are not included); njev : normal equations
    built; information : (p, p) J^T J and gradient : (p,) J^T r at x, when they were built at
    x (None if the last accepted step ended the fit: the problem is then asked again by the
    caller that needs them)."""

    x: np.ndarray
    cost: float
    status: int
    message: str
    nfev: int
    njev: int
    information: Optional[np.ndarray] = None
    gradient: Optional[np.ndarray] = None


def _solve(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, bool]:
    """(x, full rank) with A x = b for the symmetric positive semi-definite A (p, p): Cholesky,
    or the least-norm solution when A is singular (MINPACK's rank-deficient Gauss-Newton step
    uses the leading columns of a pivoted QR; on a singular A either is a step within the
    null space's complement)."""
    try:
        L = np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(A, b, rcond=None)[0], False
    return np.linalg.solve(L.T, np.linalg.solve(L, b)), True


def _inverse_norm2(A: np.ndarray, v: np.ndarray) -> float:
    """v^T A^-1 v for a positive definite A: ||R^-T v||^2 of lmpar with R^T R = A."""
    L = np.linalg.cholesky(A)
    w = np.linalg.solve(L, v)
    return float(w @ w)


def lmpar(A: np.ndarray, g: np.ndarray, diag: np.ndarray, delta: float,
          par: float) -> tuple[float, np.ndarray]:
    """MINPACK's lmpar on the normal equations: the Levenberg-Marquardt parameter par >= 0 and
    the step s = -(A + par D^2)^-1 g with ||D s|| within 10 % of delta (or par = 0 and the
    Gauss-Newton step when that is shorter).

    A : (p, p) J^T J; g : (p,) J^T r; diag : (p,) the scaling D (positive); delta : trust
    radius (the units of D s); par : the previous parameter (the start of the search).
    Returns (par, s (p,))."""
    x, full = _solve(A, g)
    dx = diag * x
    dxnorm = float(np.linalg.norm(dx))
    fp = dxnorm - delta
    if fp <= 0.1 * delta:
        return 0.0, -x
    # lower bound from the Newton step at par = 0 (only with a full-rank A)
    parl = 0.0
    if full:
        parl = fp / delta / _inverse_norm2(A, diag * dx / dxnorm)
    gnorm = float(np.linalg.norm(g / diag))
    paru = gnorm / delta
    if paru == 0.0:
        paru = DWARF / min(delta, 0.1)
    par = min(max(par, parl), paru)
    if par == 0.0:
        par = gnorm / dxnorm
    D2 = np.diag(diag * diag)
    for it in range(1, 11):
        if par == 0.0:
            par = max(DWARF, 0.001 * paru)
        Ap = A + par * D2
        x = _solve(Ap, g)[0]
        dx = diag * x
        dxnorm = float(np.linalg.norm(dx))
        temp = fp
        fp = dxnorm - delta
        if (abs(fp) <= 0.1 * delta or (parl == 0.0 and fp <= temp < 0.0) or it == 10):
            break
        parc = fp / delta / _inverse_norm2(Ap, diag * dx / dxnorm)
        if fp > 0.0:
            parl = max(parl, par)
        elif fp < 0.0:
            paru = min(paru, par)
        par = max(parl, par + parc)
    return par, -x


def _gradient_norm(g: np.ndarray, acnorm: np.ndarray, fnorm: float) -> float:
    """lmder's gnorm: the largest |cos| between r and a column of J (|g_j| / (||J_j|| ||r||)),
    0 for r = 0; acnorm (p,) the column norms of J."""
    used = acnorm != 0.0
    if fnorm == 0.0 or not np.any(used):
        return 0.0
    return float(np.max(np.abs(g[used]) / (acnorm[used] * fnorm)))


def _reductions(A: np.ndarray, step: np.ndarray, par: float, pnorm: float, fnorm: float,
                fnorm1: float) -> tuple[float, float, float]:
    """lmder's (actual, predicted relative reduction of ||r||^2, directional derivative) of a
    step (p,) of parameter par and scaled length pnorm from ||r|| = fnorm to fnorm1; the
    predicted one from ||J s||^2 = s^T A s."""
    actred = 1.0 - (fnorm1 / fnorm) ** 2 if 0.1 * fnorm1 < fnorm else -1.0
    temp1 = math.sqrt(max(0.0, float(step @ A @ step))) / fnorm
    temp2 = math.sqrt(par) * pnorm / fnorm
    return (actred, temp1 * temp1 + temp2 * temp2 / 0.5, -(temp1 * temp1 + temp2 * temp2))


def _new_radius(ratio: float, actred: float, dirder: float, fnorm: float, fnorm1: float,
                delta: float, pnorm: float, par: float) -> tuple[float, float]:
    """lmder's update of the trust radius and the parameter after a step: (delta, par)."""
    if ratio <= 0.25:
        temp = 0.5 if actred >= 0.0 else 0.5 * dirder / (dirder + 0.5 * actred)
        if 0.1 * fnorm1 >= fnorm or temp < 0.1:
            temp = 0.1
        return temp * min(delta, pnorm / 0.1), par / temp
    if par == 0.0 or ratio >= 0.75:
        return pnorm / 0.5, 0.5 * par
    return delta, par


def _stop(actred: float, prered: float, ratio: float, delta: float, xnorm: float, gnorm: float,
          ftol: float, xtol: float, nfev: int, max_nfev: int) -> int:
    """lmder's info after a step: 1 ftol, 2 xtol, 3 both, 5 evaluations exhausted, 6/7/8 ftol,
    xtol, gtol below the machine precision; 0 to go on."""
    small = abs(actred) <= ftol and prered <= ftol and 0.5 * ratio <= 1.0
    info = (1 if small else 0) + (2 if delta <= xtol * xnorm else 0)
    if info != 0:
        return info
    if nfev >= max_nfev:
        return 5
    if abs(actred) <= EPS and prered <= EPS and 0.5 * ratio <= 1.0:
        return 6
    if delta <= EPS * xnorm:
        return 7
    return 8 if gnorm <= EPS else 0


def levenberg_marquardt(residual_norm: Callable[[np.ndarray], float],
                        normal_equations: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                        x0: np.ndarray, max_nfev: int, ftol: float = 1e-8, xtol: float = 1e-8,
                        gtol: float = 1e-8, factor: float = 100.0,
                        diag: Optional[np.ndarray] = None) -> Solution:
    """Minimise 0.5 ||r(x)||^2 by MINPACK lmder's trust-region Levenberg-Marquardt.

    residual_norm : x (p,) -> ||r(x)|| (a finite float; a failed evaluation should return a
        large one, it is then a rejected step); normal_equations : x -> (J^T J (p, p),
        J^T r (p,)) at a point x that residual_norm was last called with (an accepted point);
    x0 : (p,) start; max_nfev : residual evaluations allowed (lmder's maxfev);
    ftol, xtol, gtol, factor : as lmder's (relative reduction of the sum of squares, relative
    step in D x, cosine between r and J's columns, initial trust radius factor x ||D x0||);
    diag : None for Marquardt's scaling (lmder's mode 1: D_j the largest norm of column j of J
    seen so far), or (p,) fixed positive scales (mode 2; least_squares(x_scale=s) is 1 / s).
    Returns a :class:`Solution`."""
    x = np.array(x0, dtype=float)
    p = x.size
    fixed = diag is not None
    D = np.array(diag, dtype=float) if fixed else np.zeros(p)
    if fixed and (D.shape != (p,) or not np.all(D > 0)):
        raise ValueError(f'diag must be {p} positive scales, got {diag!r}')
    fnorm = float(residual_norm(x))
    nfev, njev, it, info = 1, 0, 1, 0
    delta = xnorm = par = 0.0
    at_x = False        # whether A, g are those of x (not after an accepted last step)
    while info == 0:
        A, g = normal_equations(x)
        njev += 1
        at_x = True
        acnorm = np.sqrt(np.clip(np.diag(A), 0.0, None))
        if it == 1:
            if not fixed:
                D = np.where(acnorm == 0.0, 1.0, acnorm)
            xnorm = float(np.linalg.norm(D * x))
            delta = factor * xnorm if xnorm != 0.0 else factor
        gnorm = _gradient_norm(g, acnorm, fnorm)
        if gnorm <= gtol:
            info = 4
            break
        if not fixed:
            D = np.maximum(D, acnorm)
        ratio = 0.0
        while ratio < 1e-4 and info == 0:
            par, step = lmpar(A, g, D, delta, par)
            x_new = x + step
            pnorm = float(np.linalg.norm(D * step))
            if it == 1:
                delta = min(delta, pnorm)
            fnorm1 = float(residual_norm(x_new))
            nfev += 1
            actred, prered, dirder = _reductions(A, step, par, pnorm, fnorm, fnorm1)
            ratio = actred / prered if prered != 0.0 else 0.0
            delta, par = _new_radius(ratio, actred, dirder, fnorm, fnorm1, delta, pnorm, par)
            if ratio >= 1e-4:       # accepted
                x = x_new
                xnorm = float(np.linalg.norm(D * x))
                fnorm = fnorm1
                it += 1
                at_x = False
            info = _stop(actred, prered, ratio, delta, xnorm, gnorm, ftol, xtol, nfev, max_nfev)
    status = {1: 2, 2: 3, 3: 4, 4: 1, 5: 0, 6: 2, 7: 3, 8: 1}[info]
    return Solution(x=x, cost=0.5 * fnorm * fnorm, status=status, message=MESSAGES[status],
                    nfev=nfev, njev=njev, information=A if at_x else None,
                    gradient=g if at_x else None)


def forward_steps(z: np.ndarray, rel_step: float) -> np.ndarray:
    """Forward-difference steps h (p,) at z (p,), scipy 1.17's 2-point rule:
    h_i = rel_step * sign(z_i) * |z_i|, or sqrt(eps) * sign(z_i) * max(1, |z_i|) where that
    adds nothing to z_i; the column divides by (z_i + h_i) - z_i (the step as represented)."""
    sign = (z >= 0).astype(float) * 2 - 1
    h = rel_step * sign * np.abs(z)
    return np.where(((z + h) - z) == 0, math.sqrt(EPS) * sign * np.maximum(1.0, np.abs(z)), h)


# A stream of the residual vector at a point: its consecutive pieces in order, each (rows,)
# with rows a multiple of the group size, or None once the evaluation failed (the residual
# vector is then taken as the failure value everywhere, as a failed full evaluation is).
Stream = Callable[[np.ndarray], Iterator[Optional[np.ndarray]]]


class ChunkedForwardDifferences:
    """J^T J, J^T r and the per-group scores of a residual vector's forward-difference
    Jacobian, built a chunk of rows at a time: the largest array is (chunk, p), never (M, p).

    residuals : x (p,) -> (M,) the whole residual vector (a new array; the failure value where
        a model fails, see `fail`); stream : a :data:`Stream` of the same numbers in pieces
        (the p perturbed points of a Jacobian are streamed side by side, a piece each at a
        time); m : the rows of one group (a sample's channels: the scores are per group);
        rel_step : the relative forward step (:func:`forward_steps`); mapper : map-like that
        advances the p streams (a thread pool's map; the streams are independent); fail :
        the residual value standing for a failed evaluation.

    :meth:`norm` and :meth:`normal_equations` are the two callables of
    :func:`levenberg_marquardt`; the residual vector of the last point given to norm is kept
    (the base of the next Jacobian, (M,) floats), as lmder keeps its fvec."""

    def __init__(self, residuals: Callable[[np.ndarray], np.ndarray], stream: Stream,
                 m: int, rel_step: float, mapper: Callable[..., Iterable[Any]] = map,
                 fail: float = 1e3):
        self.residuals = residuals
        self.stream = stream
        self.m = int(m)
        self.rel_step = rel_step
        self.mapper = mapper
        self.fail = fail
        self.at: Optional[np.ndarray] = None    # the last point evaluated
        self.r: Optional[np.ndarray] = None     # (M,) its residuals
        # of the last normal equations built: (x, r(x)), J^T J, J^T r, scores (M / m, p)
        self.base: Optional[tuple[np.ndarray, np.ndarray]] = None
        self.information: Optional[np.ndarray] = None
        self.gradient: Optional[np.ndarray] = None
        self.scores: Optional[np.ndarray] = None

    def norm(self, x: np.ndarray) -> float:
        """||r(x)||, keeping r(x)."""
        self.at = np.array(x, dtype=float)
        self.r = self.residuals(self.at)
        return float(np.linalg.norm(self.r))

    def normal_equations(self, x: np.ndarray,
                         observer: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """(A = J^T J (p, p), g = J^T r (p,)) at x, J by forward differences; they are also
        kept (self.information, self.gradient) with self.base = (x, r(x)) and self.scores
        (M / m, p): row k = J_k^T r_k over group k's m rows (the per-sample scores of a sandwich
        covariance). observer: None, or an object whose start() is called at each pass over
        the chunks and add(group, J, r) with each chunk (its first group's index, its rows of
        J and of r): other sums of the same Jacobian, a chunk at a time."""
        x = np.array(x, dtype=float)
        if self.at is None or not np.array_equal(self.at, x):
            self.norm(x)
        failed: set[int] = set()
        while True:
            out = self._sweep(x, failed, observer)
            if isinstance(out, tuple):
                return out
            failed.add(out)     # a column's model failed part-way: again, with it constant

    def _sweep(self, x: np.ndarray, failed: set[int], observer: Any = None) -> Any:
        """One pass over the chunks: (A, g), or the index of a column whose stream failed."""
        if observer is not None:
            observer.start()
        r0 = self.r
        assert r0 is not None
        p, m = x.size, self.m
        h = forward_steps(x, self.rel_step)
        dh = (x + h) - x

        def start(i: int) -> Iterator[Optional[np.ndarray]]:
            x1 = x.copy()
            x1[i] = x[i] + h[i]
            return self.stream(x1)

        live = [i for i in range(p) if i not in failed]
        streams = dict(zip(live, self.mapper(start, live)))
        A = np.zeros((p, p))
        g = np.zeros(p)
        scores = np.empty((r0.size // m, p))
        Jc: Optional[np.ndarray] = None
        at = 0
        while at < r0.size:
            pieces = dict(zip(live, self.mapper(lambda i: next(streams[i], None), live)))
            for i, piece in pieces.items():
                if piece is None:
                    return i
            rows = next(iter(pieces.values())).size if pieces else min(r0.size - at, 4096 * m)
            if rows % m or at + rows > r0.size or any(q.size != rows for q in pieces.values()):
                raise ValueError(f'the streams gave pieces of {[q.size for q in pieces.values()]}'
                                 f' rows at row {at} of {r0.size}: they must be equal multiples'
                                 f' of {m} within the residual vector')
            if Jc is None or Jc.shape[0] < rows:
                Jc = np.empty((rows, p))
            J = Jc[:rows]
            base = r0[at:at + rows]
            for i in range(p):
                piece = pieces[i] if i in pieces else self.fail
                np.subtract(piece, base, out=J[:, i])
                J[:, i] /= dh[i]
            A += J.T @ J
            g += J.T @ base
            scores[at // m:(at + rows) // m] = np.einsum(
                'kmp,km->kp', J.reshape(-1, m, p), base.reshape(-1, m))
            if observer is not None:
                observer.add(at // m, J, base)
            at += rows
        self.base, self.information, self.gradient, self.scores = (x, r0), A, g, scores
        return A, g
