"""Synthetic glider dives with known parameters, flown by the dynamic flight model itself
(white pressure noise, a coloured vertical water velocity), for the glider tests
(test/core/test_glider.py, test/analysis/test_glider_file.py)."""
from dataclasses import replace
import math
from pathlib import Path

import numpy as np

from auv_ident.core.glider.flight import dynamic_flight
from auv_ident.core.glider.record import G, GliderRecord
from auv_ident.core.glider.vehicle import glider_from_file

# the published prior, the glider file's
PRIOR = glider_from_file(str(Path(__file__).resolve().parents[1] / 'config'
                             / 'slocum_comet.yaml')).params
TRUE = replace(PRIOR, hull_volume=0.05966, drag_zero_lift=0.17, compressibility=5e-10)


def _density(depth):
    """kg/m^3, a Baltic summer profile: 1004.5 above, 1007 below a pycnocline at 20 m."""
    return 1004.5 + 1.25 * (1.0 + np.tanh((depth - 20.0) / 4.0))


def synthetic_dives(params, seed, n_cycles=6, half_period=300.0, dt=1.0, heave_std=0.5,
                    pressure_noise=50.0):
    """A GliderRecord of yo-yos from 10 m to ~45 m and back flown by the dynamic model with params:
    pump +-230 cc and pitch -+0.38 rad switched (20 s ramps) every half_period s; the water
    heaves the glider (AR(1) displacement, heave_std m, 120 s: coloured depth-rate errors of
    ~0.6 cm/s); the pressure read with white noise (Pa). The pressure the model needs
    (density, compressibility) is found by iterating flight and depth to a fixed point."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 2 * n_cycles * half_period, dt)
    # +1 diving, -1 climbing, ~20 s ramps between
    phase = np.clip(10.0 * np.sin(np.pi * t / half_period), -1.0, 1.0)
    pumped = -230e-6 * phase
    pitch = -0.38 * phase
    rho_w = math.exp(-dt / 120.0)
    heave = np.zeros(len(t))          # m, the water's vertical displacement (internal waves)
    for k in range(1, len(t)):
        heave[k] = rho_w * heave[k - 1] + heave_std * math.sqrt(1 - rho_w ** 2) * rng.normal()
    depth = np.full(len(t), 10.0)
    for _ in range(8):
        rec = GliderRecord(t=t, pressure=_density(depth) * G * depth, pitch=pitch,
                           pumped_volume=pumped, density=_density(depth))
        rate = dynamic_flight(params, rec).depth_rate
        depth = 10.0 + heave + np.concatenate(([0.0],
                                               np.cumsum(0.5 * (rate[1:] + rate[:-1]) * dt)))
    assert depth.min() > 1.0 and 30.0 < depth.max() < 60.0      # yo-yos under the surface
    pressure = _density(depth) * G * depth + rng.normal(0.0, pressure_noise, len(t))
    speed = dynamic_flight(params, rec).speed
    return GliderRecord(t=t + 1.5e9, pressure=pressure, pitch=pitch, pumped_volume=pumped,
                        density=_density(depth), speed_through_water=speed)


def dvl_on_descents(rec):
    """The record with its DVL speed only where a glider's DVL is valid: descending, deeper
    than 12 m (the comet's processed file)."""
    valid = (rec.pitch < -0.3) & (rec.depth > 12.0)
    return replace(rec, speed_through_water=np.where(valid, rec.speed_through_water, np.nan))
