"""Default sensor suite and sample time: what the simulator adds and the filter assumes
when the user gives nothing.

Sensor-noise defaults (1-sigma, per output channel y = x) describe a typical small-AUV suite:

======== ============================ =========== ============================================
channel  sensor                       sigma       why
======== ============================ =========== ============================================
u v w    DVL (bottom lock)            0.01 m/s    ~0.3-1 % of speed + 2-5 mm/s at 0.5-2 m/s
p q r    MEMS/FOG gyro                0.001 rad/s ~0.06 deg/s, tactical-grade MEMS
x y      USBL/LBL fix                 0.5 m       acoustic positioning, short range
z        pressure depth sensor        0.05 m      0.05-0.1 % full scale of a 50-100 m sensor
phi th   AHRS roll/pitch              0.002 rad   ~0.1 deg
psi      AHRS/compass heading         0.005 rad   ~0.3 deg
======== ============================ =========== ============================================

Process noise (off by default) adds white accelerations to nu_dot, sigma per DOF in m/s^2 and
rad/s^2, to stand for unmodelled forces (waves, tether, currents).
"""
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:
    from auv_ident.core.model.vehicle import Vehicle

DEFAULT_NOISE_STD = np.array([0.01, 0.01, 0.01, 0.001, 0.001, 0.001,
                              0.5, 0.5, 0.05, 0.002, 0.002, 0.005])
DEFAULT_PROCESS_STD = np.array([1e-3, 1e-3, 1e-3, 1e-4, 1e-4, 1e-4])
DEFAULT_T = 0.05        # s, sample time (the paper's T)


def ar1_noise(rng: np.random.Generator, n: int, std: ArrayLike, tau: float,
              T: float) -> np.ndarray:
    """Coloured (first-order, AR(1)) measurement noise: (n, len(std)) samples at interval T (s)
    with per-channel stationary 1-sigma std and correlation time tau (s; 0 gives white noise):
    e_k = a e_(k-1) + sqrt(1 - a^2) w_k, a = exp(-T / tau), started stationary. What a
    navigation solution or a DVL that averages over pings gives: consecutive samples share
    most of their error."""
    std = np.asarray(std, dtype=float)
    w = rng.standard_normal((n, len(std)))
    if tau <= 0.0:
        return w * std
    a = float(np.exp(-T / tau))
    b = float(np.sqrt(1.0 - a * a))
    e = np.empty_like(w)
    e[0] = w[0]
    for k in range(1, n):
        e[k] = a * e[k - 1] + b * w[k]
    return e * std


def perturbed_values(vehicle: 'Vehicle', factor: float, rng: np.random.Generator,
                     keep: Iterable[str] = ()) -> np.ndarray:
    """The vehicle's coefficient values with every one not in `keep` (names) and not an
    added-mass term scaled by U(1 - factor, 1 + factor): a truth vehicle that differs from the
    file, as a real one differs from its prior (empirical formulas are 10-50 % off). Added
    mass is left alone: it enters through M^-1, which some vehicles give literally."""
    values = np.array(vehicle.values, dtype=float)
    keep = {vehicle.names[vehicle.index(n)] for n in keep}
    scale = rng.uniform(1.0 - factor, 1.0 + factor, len(values))
    for i, c in enumerate(vehicle.coefficients):
        if vehicle.names[i] not in keep and not c.is_added_mass:
            values[i] *= scale[i]
    return values
