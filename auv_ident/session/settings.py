"""Identifier settings checked once, in one style: a bad value raises :class:`ParameterError`
naming the setting (= the identifier node's parameter and the keyword of IdentSession)."""
import math

import numpy as np

from auv_ident.core.errors import ConfigError
from auv_ident.core.state import STATE_NAMES

MASS_INVERSES = ('default', 'exact', 'mss_literal')

class ParameterError(ConfigError):
    """A bad identifier setting; ``name`` is the node parameter (= keyword argument) at fault."""

    def __init__(self, name, message):
        self.name = name
        super().__init__(f'parameter {name!r}: {message}')

def _vector(name, values, n, default):
    """Return a float (n,) array; None or empty gives the default (ROS maps [] to 'not set')."""
    if values is None or len(values) == 0:
        return np.array(default, dtype=float)
    try:
        a = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(name, f'expected {n} numbers, got {values!r}') from None
    if a.shape != (n,):
        raise ParameterError(name, f'expected {n} numbers, got {a.size}')
    return a

def _positive(name, value, allow_zero=False):
    v = float(value)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        what = 'non-negative' if allow_zero else 'positive'
        raise ParameterError(name, f'{value!r} must be a {what} finite number')
    return v

def measured_mask(names):
    """(12,) bool from state channel names (u v w p q r x y z phi theta psi); empty: all."""
    if names is None or len(names) == 0:
        return np.ones(12, dtype=bool)
    if isinstance(names, np.ndarray) and names.dtype == bool:
        if names.shape != (12,):
            raise ParameterError('measured', f'a mask must have 12 entries, got {names.shape}')
        return names.copy()
    mask = np.zeros(12, dtype=bool)
    for n in names:
        if n not in STATE_NAMES:
            raise ParameterError('measured', f'unknown channel {n!r}; use names from '
                                             + ' '.join(STATE_NAMES))
        if mask[STATE_NAMES.index(n)]:
            raise ParameterError('measured', f'channel {n!r} listed twice')
        mask[STATE_NAMES.index(n)] = True
    return mask
