"""Is an identified coefficient physically plausible for the vehicle file it was identified with?

Consistent error bars say the data agree with the model; they do not say the model is the right
vehicle, or that the data were read in the right frame. An ENU bag read as NED, or another
vehicle's file, still fits, with coefficients whose signs or sizes no hull has. Two checks, each
against what the vehicle file says:

- **Signs the physics forbids.** A self-damping term takes energy out of its own degree of
  freedom, so its coefficient is negative in SNAME/Fossen signs: a term of equation X Y Z K M N
  whose multiplier is that equation's own velocity u v w p q r, alone, times its absolute value
  (``v*|v|``) or times the forward speed (``u*v``, ``|u|*v``, ``U*v``: the prime-system linear
  damping of a vehicle moving forward), and the diagonal added mass (``X_udot`` ... ``N_rdot``,
  multiplier ``udot`` in X, ...). Such a coefficient identified positive by more than
  ``z`` of its 1-sigma is not plausible: dissipation does not feed the motion.
- **Control derivatives keep the file's sign.** A term with a fin angle in its multiplier
  (``dr ds db dbp dbs db2``) gets its sign from the fin's place and the file's sign convention
  for the deflection, not from the data: identified with the opposite sign by more than ``z``
  of its 1-sigma, it says the fins' sign convention or the frames (an ENU/FLU run read as
  NED/FRD flips Z_ds, M_ds, Y_dr, N_dr) differ from the file's.
- **The prior.** The vehicle file's value is a prior with a 1-sigma of ``relative_sd`` times
  its magnitude (default :data:`DEFAULT_RELATIVE_SD` = 1.0, i.e. the file may be off by its own
  size), or what the file's ``prior:`` block says per coefficient::

      prior:
        relative_sd: 0.5          # every coefficient: 1-sigma = 0.5 |file value|
        coefficients:
          M_w: {relative_sd: 2.0} # this one is poorly known
          Y_dr: {sd: 0.003}       # or an absolute 1-sigma, in the file's units

  An estimate farther than ``z`` combined sigma (prior and estimate) from the file value is not
  plausible: the vehicle file, the frame or the data are wrong. A coefficient whose file value
  is 0 and that has no absolute ``sd`` is judged by its sign alone.

The water current's components are not vehicle coefficients and are not judged here.
"""
from collections.abc import Sequence
from dataclasses import dataclass
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.errors import ConfigError
from auv_ident.core.model.state import CURRENT_NAMES
from auv_ident.core.model.vehicle import Coefficient, EQUATIONS, FACTOR_INDEX, Vehicle

DEFAULT_RELATIVE_SD = 1.0   # prior 1-sigma of a file value, relative to its magnitude
DEFAULT_Z = 3.0             # how many combined sigma make an estimate implausible


@dataclass(frozen=True)
class Implausible:
    """One coefficient that is not plausible, and why (a sentence for the user)."""

    name: str
    estimate: float
    std: float
    file_value: float
    reason: str


def _speed_factors() -> set[int]:
    return {FACTOR_INDEX['u'], FACTOR_INDEX['|u|'], FACTOR_INDEX['U']}


def is_self_damping(coefficient: Coefficient) -> bool:
    """True if the coefficient (core.model.vehicle.Coefficient) is a self-damping or diagonal
    added-mass term (module docstring): its value must not be positive."""
    e = coefficient.equation
    if coefficient.is_added_mass:
        return coefficient.added_mass_col == e
    own, own_abs = e, FACTOR_INDEX['|' + 'uvwpqr'[e] + '|']
    f = sorted(coefficient.factors)
    if f in ([own], sorted([own, own_abs])):
        return True
    if len(f) == 2 and own in f:
        other = f[1] if f[0] == own else f[0]
        if other in _speed_factors() and not (e == 0 and other == FACTOR_INDEX['U']):
            return True
    return e == 0 and f == [own, own]          # X_uu u*u: drag of a vehicle moving forward


FIN_FACTORS = frozenset(FACTOR_INDEX[f] for f in ('dr', 'ds', 'db', 'dbp', 'dbs', 'db2'))


def is_control_derivative(coefficient: Coefficient) -> bool:
    """True for a term with a fin angle in its multiplier (its sign is the file's)."""
    return (not coefficient.is_added_mass
            and any(f in FIN_FACTORS for f in coefficient.factors))


def prior_sd(vehicle: Vehicle, name: str) -> float:
    """1-sigma of the vehicle file's value of `name` as a prior, in the file's units (NaN when
    the file value is 0 and no absolute sd is given: no prior check)."""
    block: dict[str, Any] = vehicle.raw.get('prior') or {}
    if not isinstance(block, dict):
        raise ConfigError(f'vehicle {vehicle.name!r}: prior must be a mapping, got {block!r}')
    per: dict[str, Any] = (block.get('coefficients') or {}).get(name) or {}
    value = vehicle.values[vehicle.index(name)]
    if 'sd' in per:
        sd = float(per['sd'])
    else:
        rel_given = (per['relative_sd'] if 'relative_sd' in per
                     else block.get('relative_sd', DEFAULT_RELATIVE_SD))
        rel = float(rel_given)
        sd = rel * abs(value) if value != 0.0 else math.nan
    if not (math.isnan(sd) or (math.isfinite(sd) and sd > 0.0)):
        raise ConfigError(f'vehicle {vehicle.name!r}: prior of {name} gives 1-sigma {sd!r}; '
                          'it must be a positive number')
    return sd


def implausible_coefficients(vehicle: Vehicle, names: Sequence[str],
                             estimate: Sequence[float] | np.ndarray,
                             std: Sequence[float] | np.ndarray,
                             z: float = DEFAULT_Z) -> list[Implausible]:
    """The identified coefficients that are not plausible for `vehicle` (module docstring):
    a list of :class:`Implausible`, empty when every one is. names, estimate, std: the
    identified parameters (current components are skipped) with their 1-sigma."""
    out = []
    for name, est, sd in zip(names, np.asarray(estimate, float), np.asarray(std, float)):
        if name in CURRENT_NAMES:
            continue
        c = vehicle.coefficients[vehicle.index(name)]
        sd = float(sd) if np.isfinite(sd) else 0.0
        if is_self_damping(c) and est > z * sd:
            out.append(Implausible(
                name, float(est), sd, c.value,
                f'{name} = {est:.4g} +- {sd:.2g} is positive: a {_kind(c)} of equation '
                f'{EQUATIONS[c.equation]} takes energy out of the motion, so it is negative '
                f'(file value {c.value:.4g})'))
            continue
        if (is_control_derivative(c) and c.value != 0.0 and est * c.value < 0.0
                and abs(est) > z * sd):
            out.append(Implausible(
                name, float(est), sd, c.value,
                f"{name} = {est:.4g} +- {sd:.2g} has the opposite sign of the vehicle file's "
                f"{c.value:.4g}: a control derivative's sign is set by the fin and its sign "
                "convention, so the fins' convention or the frames differ from the file's"))
            continue
        prior = prior_sd(vehicle, name)
        if math.isnan(prior):
            continue
        dev = (est - c.value) / math.hypot(prior, sd)
        if abs(dev) > z:
            out.append(Implausible(
                name, float(est), sd, c.value,
                f'{name} = {est:.4g} +- {sd:.2g} is {abs(dev):.1f} sigma from the vehicle '
                f"file's {c.value:.4g} (prior 1-sigma {prior:.2g}); beyond {z:g} sigma"))
    return out


def _kind(c: Coefficient) -> str:
    return 'diagonal added mass' if c.is_added_mass else 'self-damping term'


def what_to_check(findings: Sequence[Implausible], frame_hint: str = '') -> str:
    """One sentence for the user: what to check when findings are not plausible."""
    if not findings:
        return ''
    names = ', '.join(f.name for f in findings)
    return (f'NOT plausible: {names} ({findings[0].reason}). Check that the vehicle file is this '
            "vehicle's, that the data's frames are what the bag says (ENU/FLU vs NED/FRD)"
            + (f' ({frame_hint})' if frame_hint else '')
            + ' and the units of every channel')


ABOVE_SURFACE_M = 1.0   # m: a submerged run's median depth this far above the surface is no depth


def depth_contradicts_down(z: ArrayLike, heave_free: bool = True) -> str:
    """A sentence when the run's NED depths z (m, down positive; NaN: not measured) put a
    submerged vehicle above the water (median z < -ABOVE_SURFACE_M): the data's 'down' is up,
    e.g. an ENU (REP-103) run read as NED; '' otherwise, or for a vehicle without heave."""
    depths = np.asarray(z, dtype=float)
    depths = depths[np.isfinite(depths)]
    if not heave_free or depths.size == 0:
        return ''
    median = float(np.median(depths))
    if median >= -ABOVE_SURFACE_M:
        return ''
    return (f'the depth z (NED, down positive) has a median of {median:.3g} m: the vehicle '
            f"would run {-median:.3g} m above the water surface, so the data's z axis points "
            'up (an ENU/FLU run, REP-103, read as NED/FRD?)')
