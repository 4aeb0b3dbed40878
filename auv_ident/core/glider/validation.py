"""Judging a calibrated flight model on dives it never saw: its speed through water against a
DVL's, its depth rate against the pressure's.

The DVL is another instrument than the one the model is fitted to (pressure), so it is an
honest judge, but it is judged too, without any model: on a dive, the depth rate (pressure),
the pitch (inclinometer) and the DVL's speed fix the angle of attack,
``alpha = asin(|dz/dt| / U_DVL) - |theta|``. A Slocum flies at 2-5 deg (Merckelbach et al.
2019); a dive whose median implied angle is above :data:`MAX_IMPLIED_AOA_DEG` is one where the
three instruments disagree (the comet record's last dive: 17.5 deg, the DVL speed 0.2 m/s where
the depth rate alone needs 0.3 m/s at the measured pitch), and it is scored apart: every model
is given both figures, with and without such dives.
"""
from dataclasses import dataclass

import numpy as np

from auv_ident.core.glider.calibration import fit_window
from auv_ident.core.simulation.prediction import fit_percent

MAX_IMPLIED_AOA_DEG = 10.0
DIVE_GAP = 5        # samples: valid DVL samples further apart belong to different dives


def dvl_dives(record, gap=DIVE_GAP):
    """Index arrays of the runs of valid DVL samples (one per dive)."""
    idx = np.flatnonzero(np.isfinite(record.speed_through_water))
    if not len(idx):
        return []
    return np.split(idx, np.flatnonzero(np.diff(idx) > gap) + 1)


def implied_angle_of_attack(record):
    """(N,) rad: asin(|dz/dt| / U_DVL) - |theta| (module docstring); NaN without a DVL speed."""
    with np.errstate(invalid='ignore', divide='ignore'):
        ratio = np.clip(np.abs(record.depth_rate()) / record.speed_through_water, -1.0, 1.0)
    return np.arcsin(ratio) - np.abs(record.pitch)


def consistent_dvl(record, max_aoa_deg=MAX_IMPLIED_AOA_DEG):
    """(keep, dives): keep (N,) bool, the DVL samples on dives whose median implied angle of
    attack is at most max_aoa_deg; dives: list of (start time s, samples, median implied
    angle deg, kept) per dive."""
    aoa = np.degrees(implied_angle_of_attack(record))
    keep = np.zeros(len(record), dtype=bool)
    dives = []
    for idx in dvl_dives(record):
        med = float(np.median(aoa[idx]))
        ok = med <= max_aoa_deg
        keep[idx] = ok
        dives.append((float(record.t[idx[0]]), len(idx), med, ok))
    return keep, dives


@dataclass
class Scores:
    """Speed through water against the DVL (bias = mean(model - DVL), rms, fit %, m/s and %)
    over the DVL samples kept, and the depth rate against the pressure's over the fit
    window (bias, rms m/s)."""

    speed_bias: float
    speed_rms: float
    speed_fit: float
    speed_samples: int
    depth_rate_bias: float
    depth_rate_rms: float


def score(flight, record, dvl_mask, window):
    """:class:`Scores` of a Flight over a record; dvl_mask (N,) bool selects the DVL samples
    judged (finite ones only)."""
    dvl = record.speed_through_water
    use = dvl_mask & np.isfinite(dvl)
    e = flight.speed[use] - dvl[use]
    fit = fit_window(record, window)
    ez = flight.depth_rate[fit] - record.depth_rate()[fit]
    return Scores(speed_bias=float(np.mean(e)) if len(e) else np.nan,
                  speed_rms=float(np.sqrt(np.mean(e ** 2))) if len(e) else np.nan,
                  speed_fit=fit_percent(dvl[use], flight.speed[use]),
                  speed_samples=int(use.sum()),
                  depth_rate_bias=float(np.mean(ez)),
                  depth_rate_rms=float(np.sqrt(np.mean(ez ** 2))))
