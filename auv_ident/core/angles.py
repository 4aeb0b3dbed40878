"""Angle wrapping for Python callers (the simulator, message conversion, reports).

The filter's compiled loop has its own (ekf.wrap, inlined into the measurement update, which
reduces every angle it is given); test_ekf checks the two agree.
"""
import math
from typing import Any

import numpy as np


def wrap_angle(a: Any) -> Any:
    """Angle(s) a (rad, a number or an array) wrapped to (-pi, pi].

    Angles already in (-pi, pi] come back unchanged, bit for bit (a conversion round trip
    does not move them); others are reduced modulo 2 pi. A number gives a float, an array an
    array.
    """
    if isinstance(a, float) or np.ndim(a) == 0:    # a float first: np.ndim costs ~1 us
        a = float(a)
        if -math.pi < a <= math.pi:
            return a
        return math.pi - ((math.pi - a) % (2.0 * math.pi))
    a = np.asarray(a, dtype=float)
    return np.where((a > -np.pi) & (a <= np.pi), a, np.pi - np.mod(np.pi - a, 2.0 * np.pi))
