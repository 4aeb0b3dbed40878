"""A glider's record of dives as the flight model reads it: arrays on one time base."""
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from auv_ident.core.errors import DataError

G = 9.81            # m/s^2, gravity (as gliderflight; 9.814 at 54 N changes w by 0.03 %)
SURFACE_PRESSURE = 0.5e4    # Pa (0.5 dbar): shallower, the glider is at the surface


@dataclass
class GliderRecord:
    """Dives of one glider, sampled on one time base (the CTD's).

    t : (N,) s since 1970-01-01 UTC, strictly increasing
    pressure : (N,) Pa, gauge (0 at the surface)
    pitch : (N,) rad, positive nose up (the glider's m_pitch as calibrated)
    pumped_volume : (N,) m^3, the buoyancy drive's volume change (m_ballast_pumped), positive
        more buoyant
    density : (N,) kg/m^3, in-situ water density (a measured input)
    temperature : (N,) degC or None (then the hull's thermal expansion is left out)
    speed_through_water : (N,) m/s, measured by another instrument (a DVL), NaN where not
        valid; used only to judge the model, never to fit it
    """

    t: np.ndarray
    pressure: np.ndarray
    pitch: np.ndarray
    pumped_volume: np.ndarray
    density: np.ndarray
    temperature: np.ndarray | None = None
    speed_through_water: np.ndarray = field(default=None)  # type: ignore[arg-type]  # NaN after init

    def __post_init__(self) -> None:
        n = len(self.t)
        for name in ('t', 'pressure', 'pitch', 'pumped_volume', 'density', 'temperature',
                     'speed_through_water'):
            v = getattr(self, name)
            if v is None:
                if name == 'speed_through_water':
                    self.speed_through_water = np.full(n, np.nan)
                continue
            v = np.asarray(v, dtype=float)
            if v.shape != (n,):
                raise DataError(f'glider record: {name} has shape {v.shape}, t has ({n},)')
            if name != 'speed_through_water' and not np.all(np.isfinite(v)):
                i = int(np.flatnonzero(~np.isfinite(v))[0])
                raise DataError(f'glider record: {name}[{i}] is {v[i]} (at t = {self.t[i]!r})')
            setattr(self, name, v)
        if n < 3 or np.any(np.diff(self.t) <= 0):
            raise DataError('glider record: t must rise strictly over at least 3 samples')

    def __len__(self) -> int:
        return len(self.t)

    def depth_rate(self) -> np.ndarray:
        """(N,) m/s, the measured depth rate dz/dt (positive down): the centred difference of
        the pressure over the local density times g."""
        return np.gradient(self.pressure, self.t) / (self.density * G)

    @property
    def depth(self) -> np.ndarray:
        """(N,) m, pressure over the local density times g (hydrostatic)."""
        return self.pressure / (self.density * G)

    def at_surface(self) -> np.ndarray:
        return self.pressure < SURFACE_PRESSURE

    def select(self, keep: np.ndarray) -> 'GliderRecord':
        """The record of the samples where keep (N,) bool is True."""
        keep = np.asarray(keep, dtype=bool)
        columns: dict[str, Any] = {
            name: None if getattr(self, name) is None else getattr(self, name)[keep]
            for name in ('t', 'pressure', 'pitch', 'pumped_volume', 'density', 'temperature',
                         'speed_through_water')}
        return replace(self, **columns)

    def split(self, t_split: float) -> tuple['GliderRecord', 'GliderRecord']:
        """(first, second): the samples before and from t_split (s since 1970)."""
        return self.select(self.t < t_split), self.select(self.t >= t_split)
