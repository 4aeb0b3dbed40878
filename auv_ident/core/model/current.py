"""The water current as part of the identification: the option that says what to do with it,
its estimate as reported, and whether a run can separate it from the coefficients.

The model (core/model/hydrodynamics.py) takes the current v_c (m/s, NED, where the water goes) as
three more entries of its parameter vector after the coefficients, 'current_n', 'current_e' and
'current_d'; identified ones are estimated with the coefficients (EKF pass and batch
refinement, core/identification/batch.py), the others are held at a given value (zero: still
water).

Why a run can separate them (Fossen 2021, sec. 10.3): the forces act on nu_r = nu - R^T v_c
while the DVL in bottom lock and the position fixes see nu. On one heading, R^T v_c is a
constant offset of the body velocity that a wrong surge/sway balance (drag, propeller or
lift coefficients) can mimic; each change of heading turns the offset in the body frame
while the coefficients stay, and that is what tells the two apart. A run that keeps one
heading therefore leaves the current (and the coefficients it correlates with) weakly
determined: :func:`current_identifiability` says so, and what to fly instead.
"""
from collections.abc import Sequence
from dataclasses import dataclass, field
import math
from typing import Any, TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.errors import ConfigError
from auv_ident.core.model.state import CURRENT_NAMES, N_CURRENT

if TYPE_CHECKING:
    from auv_ident.core.model.hydrodynamics import Model

CURRENT_OPTIONS = ('estimate', 'none')     # or 'N,E[,D]': a known current (m/s)
DEFAULT_CURRENT = 'estimate'
# headings covered (deg, the arc the run's headings span) below which the current is called
# not separable (a zig-zag of +-20 deg rudder sweeps 70-80 deg of heading; on one heading only a
# model exact in every other coefficient holds the current apart, real ones are not)
MIN_HEADING_SPAN_DEG = 30.0
# an identified current component's 1-sigma above this (m/s) is reported as weak
MAX_CURRENT_STD = 0.05
# |correlation| of a current component with a coefficient above this is reported as weak
MAX_CURRENT_CORRELATION = 0.95
ADVICE = ('turns: the current is separable from the coefficients only through heading changes; '
          'fly legs on several headings (a rudder zig-zag that swings the heading by 30 deg or '
          'more, or a full circle)')


@dataclass
class CurrentOption:
    """What to do with the water current.

    estimate : bool, identify the north and east components (and down, with estimate_down)
    estimate_down : bool, identify the down component too (else it is held at fixed[2])
    fixed : (3,) m/s NED, the value of the components not identified
    """

    estimate: bool = True
    estimate_down: bool = False
    fixed: np.ndarray = field(default_factory=lambda: np.zeros(N_CURRENT))

    @property
    def names(self) -> list[str]:
        """The identified components' parameter names (core.model.state.CURRENT_NAMES)."""
        if not self.estimate:
            return []
        return list(CURRENT_NAMES[:3 if self.estimate_down else 2])

    def describe(self) -> str:
        if self.estimate:
            return ('estimated (north, east' + (', down' if self.estimate_down else '; down 0')
                    + ')')
        if np.any(self.fixed != 0.0):
            return 'given: ' + ', '.join(f'{v:g}' for v in self.fixed) + ' m/s (N, E, D)'
        return 'none (still water)'


def parse_current(text: 'str | CurrentOption', estimate_down: bool = False,
                  what: str = 'current') -> CurrentOption:
    """A :class:`CurrentOption` from the option's text: 'estimate', 'none' or 'N,E[,D]' (m/s,
    NED, where the water goes). Raises ConfigError naming `what` for anything else."""
    if isinstance(text, CurrentOption):
        return text
    t = str(text).strip().lower()
    if t == 'estimate':
        return CurrentOption(True, bool(estimate_down))
    if estimate_down:
        raise ConfigError(f'{what}-down needs {what} estimate (got {text!r})')
    if t == 'none' or t == '':
        return CurrentOption(False)
    parts = [s for s in t.replace(' ', '').split(',')]
    try:
        vals = [float(s) for s in parts]
    except ValueError:
        vals = []
    if len(vals) not in (2, 3) or not all(math.isfinite(v) for v in vals):
        raise ConfigError(f'{what} = {text!r}: use estimate, none, or N,E[,D] in m/s (the '
                          "water's velocity in NED, e.g. 0.1,-0.05)")
    fixed = np.zeros(N_CURRENT)
    fixed[:len(vals)] = vals
    return CurrentOption(False, False, fixed)


def body_current(current: Sequence[float] | np.ndarray, phi: ArrayLike, theta: ArrayLike,
                 psi: ArrayLike) -> np.ndarray:
    """R(Theta)^T v_c: the current (3,) m/s NED in the body frame, shape (..., 3) for angles of
    shape (...,) rad (Fossen 2021 eq. 2.18, ZYX)."""
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    cp, sp = np.cos(psi), np.sin(psi)
    n, e, d = (float(v) for v in current)
    a = cp * n + sp * e
    b = -sp * n + cp * e
    return np.stack([ct * a - st * d, cf * b + sf * (st * a + ct * d),
                     -sf * b + cf * (st * a + ct * d)], axis=-1)


def ned_current(v_body: ArrayLike, phi: float, theta: float, psi: float) -> np.ndarray:
    """R(Theta) v_b: a body-frame velocity (3,) in NED (the inverse of body_current)."""
    cf, sf = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    R = np.array([[cp * ct, -sp * cf + cp * st * sf, sp * sf + cp * cf * st],
                  [sp * ct, cp * cf + sf * st * sp, -cp * sf + st * sp * cf],
                  [-st, ct * sf, ct * cf]])
    return R @ np.asarray(v_body, dtype=float)


def heading_span_deg(psi: ArrayLike) -> float:
    """The arc of headings a run covers (deg, 0..360): 360 minus the largest gap between the
    sorted headings on the circle. psi (N,) rad, NaN skipped."""
    a = np.asarray(psi, dtype=float)
    a = np.sort(np.mod(a[np.isfinite(a)], 2.0 * np.pi))
    if a.size < 2:
        return 0.0
    gaps = np.diff(np.concatenate([a, [a[0] + 2.0 * np.pi]]))
    return float(np.degrees(2.0 * np.pi - gaps.max()))


@dataclass
class CurrentEstimate:
    """The water current as identified (or as given).

    names : identified components (subset of CURRENT_NAMES)
    estimate : (3,) m/s NED (north, east, down); components not identified hold their value
    std : (3,) 1-sigma (0 for components not identified)
    cov : (k, k) covariance of the identified components
    ekf_estimate, ekf_std : (3,) the EKF pass's
    velocity_reference : 'ground' or 'water' (what the velocity sensor measured)
    identifiability : dict, see :func:`current_identifiability`
    """

    names: list
    estimate: np.ndarray
    std: np.ndarray
    cov: np.ndarray
    ekf_estimate: np.ndarray
    ekf_std: np.ndarray
    velocity_reference: str = 'ground'
    identifiability: dict = field(default_factory=dict)

    @property
    def speed(self) -> float:
        """Horizontal speed of the current (m/s)."""
        return float(math.hypot(self.estimate[0], self.estimate[1]))

    @property
    def direction_deg(self) -> float:
        """Where the water goes, deg clockwise from north (0..360)."""
        return float(np.degrees(math.atan2(self.estimate[1], self.estimate[0])) % 360.0)


def current_identifiability(psi: ArrayLike, names: Sequence[str], cov: ArrayLike, std: ArrayLike,
                            coefficient_names: Sequence[str] = ()) -> dict[str, Any]:
    """Whether the run separates the identified current from the coefficients.

    Parameters
    ----------
    psi : (N,) measured headings (rad; NaN = missing)
    names : all parameter names in the order of cov (coefficients, then current components)
    cov : (p, p) their covariance (the batch refinement's, or the EKF pass's)
    std : (p,) their 1-sigma
    coefficient_names : the coefficients among names

    Returns
    -------
    dict: 'separable' (bool), 'heading_span_deg', 'reasons' (list of str, empty when
    separable), 'advice' (what to fly instead, or ''), 'max_correlation' and
    'correlated_with' (the coefficient a current component correlates with most).
    """
    span = heading_span_deg(psi)
    reasons = []
    if span < MIN_HEADING_SPAN_DEG:
        reasons.append(f'straight run: headings span only {span:.0f} deg (less than '
                       f'{MIN_HEADING_SPAN_DEG:.0f} deg)')
    names = list(names)
    cov = np.asarray(cov, dtype=float)
    std = np.asarray(std, dtype=float)
    cur = [i for i, n in enumerate(names) if n in CURRENT_NAMES]
    coef = [i for i, n in enumerate(names) if n in set(coefficient_names)]
    c_max, partner = 0.0, None
    for i in cur:
        if std[i] > MAX_CURRENT_STD:
            reasons.append(f'{names[i]} 1-sigma {std[i]:.3g} m/s (more than '
                           f'{MAX_CURRENT_STD:g} m/s)')
        for j in coef:
            d = std[i] * std[j]
            r = abs(cov[i, j] / d) if d > 0 else 0.0
            if r > c_max:
                c_max, partner = float(r), names[j]
    if c_max > MAX_CURRENT_CORRELATION:
        reasons.append(f'the current correlates with {partner} ({c_max:.3f})')
    ok = not reasons
    return {'separable': ok, 'heading_span_deg': span, 'reasons': reasons,
            'advice': '' if ok else ADVICE, 'max_correlation': c_max,
            'correlated_with': partner}


def current_estimate(model: 'Model', estimate: ArrayLike, cov: ArrayLike,
                     ekf_estimate: ArrayLike, ekf_cov: ArrayLike,
                     psi: ArrayLike) -> CurrentEstimate | None:
    """The water current of a parameter vector of `model` (coefficients, then current
    components), as a :class:`CurrentEstimate` (None if the model identifies no current and
    has none given). estimate, cov, ekf_estimate, ekf_cov : the final and the EKF pass's
    parameters and covariances; psi : the headings of the record (its identifiability)."""
    pc = model.p_coef
    est = np.asarray(estimate, dtype=float)
    cov = np.asarray(cov, dtype=float)
    ekf_est = np.asarray(ekf_estimate, dtype=float)
    ekf_cov = np.asarray(ekf_cov, dtype=float)
    if not model.current_names and not np.any(model.current != 0.0):
        return None
    idx = [CURRENT_NAMES.index(n) for n in model.current_names]
    vc = model.current.copy()
    vc_ekf = model.current.copy()
    sd = np.zeros(N_CURRENT)
    sd_ekf = np.zeros(N_CURRENT)
    vc[idx] = est[pc:]
    vc_ekf[idx] = ekf_est[pc:]
    sd[idx] = np.sqrt(np.diag(cov)[pc:])
    sd_ekf[idx] = np.sqrt(np.diag(ekf_cov)[pc:])
    ident = (current_identifiability(psi, model.theta_names, cov, np.sqrt(np.diag(cov)),
                                     model.theta_names[:pc]) if idx else {})
    return CurrentEstimate(list(model.current_names), vc, sd, cov[pc:, pc:].copy(), vc_ekf,
                           sd_ekf, model.velocity_reference, ident)
