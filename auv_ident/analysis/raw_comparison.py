"""Raw sensors against fused odometry on the same run (issue 28's measure): one run made by
offline/independent_data.py's raw generator (its own integrator, IMU / DVL / pressure at their
own rates, DVL dropouts, a gyro bias, a DVL misalignment and scale, coloured noise of a level
and correlation drawn per run and not told), identified

- from the raw records by core/identification/raw.py ``identify_raw`` (the sensors' mountings
  as a vehicle's input map would give them: the nominal DVL mounting and lever arms, nothing
  of the errors), and
- from a fused odometry of the same records made by the generator's plain navigation EKF
  (``fused_odometry``, 20 Hz) through the package's pipeline (``identify_with_diagnosis``: the
  noise model, the EKF pass, the refinement), as ``identify --bag`` would from an /odom bag.

:func:`compare_case` returns both results against the truth; tools/raw_sensor_campaign.py
prints the figures over seeds, test/analysis/test_raw_comparison.py runs a short case.
"""
from collections import Counter
from dataclasses import dataclass
import math
import time

import numpy as np

from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.filter.raw import RawSensorConfig
from auv_ident.core.filter.timing import commands_at, with_command_changes
from auv_ident.core.identification.pipeline import identify_with_diagnosis
from auv_ident.core.identification.raw import DEFAULT_PASSES, identify_raw
from auv_ident.core.identification.results import Record
from auv_ident.core.model import raw_sensors as rs
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.offline.independent_data import (
    DataConfig,
    fused_odometry,
    generate_raw,
    RawConfig,
)
from auv_ident.vehicles import load_vehicle

PAPER_FIVE = ('Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v')
FUSED_RATE = 20.0    # Hz, the navigation filter's odometry


@dataclass
class Case:
    """One run's comparison: per coefficient (names) the truth, and for 'raw' and 'fused' the
    estimate and 1-sigma; the raw pass's sensor errors (name -> (value, 1-sigma)) and the
    generator's; seconds of each identification; per record kind the records the generator
    made (records), those the raw pass fused (raw_fused; commands: taken) and per reason those
    it did not (raw_skipped: every record is a good message, so only 'waiting' for the start
    belongs there) and how many sensor records precede the raw filter's start (before_start)."""

    seed: int
    names: list[str]
    truth: np.ndarray
    raw: np.ndarray
    raw_std: np.ndarray
    fused: np.ndarray
    fused_std: np.ndarray
    raw_errors: dict
    true_errors: dict
    raw_s: float
    fused_s: float
    fused_dropped: dict
    records: dict
    raw_fused: dict
    raw_skipped: dict
    before_start: int

    def rel_error(self, which: str) -> np.ndarray:
        """|estimate - truth| / |truth| (per coefficient) of 'raw' or 'fused'."""
        return np.abs(getattr(self, which) - self.truth) / np.abs(self.truth)

    def z(self, which: str) -> np.ndarray:
        """(estimate - truth) / 1-sigma of 'raw' or 'fused'."""
        return (getattr(self, which) - self.truth) / getattr(self, which + '_std')


def sensors_of(cfg: RawConfig) -> RawSensorConfig:
    """What the vehicle's input map says of the generator's sensors: the DVL's nominal mounting
    (turned dvl_yaw_deg about body z, at its lever arm) and the pressure sensor's lever arm."""
    R_dvl = rs.rotation(0.0, 0.0, math.radians(cfg.dvl_yaw_deg))
    return RawSensorConfig(mountings={
        'dvl': rs.Mounting(np.asarray(cfg.dvl_lever_arm, dtype=float), R_dvl),
        'pressure': rs.Mounting(np.asarray(cfg.pressure_lever_arm, dtype=float))})


def fused_record(run, cfg: RawConfig) -> tuple[Record, int]:
    """The navigation filter's odometry as a Record with the commands in force (and their
    changes between samples); also the number of odometry samples before the first command
    (dropped: no input)."""
    t, Y = fused_odometry(run, cfg, FUSED_RATE)
    U = commands_at(run.cmd_t, run.cmd_values, t)
    ok = np.all(np.isfinite(U), axis=1)
    t2, Y2, U2, _ = with_command_changes(t[ok], Y[ok], U[ok], run.cmd_t, run.cmd_values)
    return Record(t2, Y2, U2), int(np.count_nonzero(~ok))


def before_start(records) -> int:
    """The sensor records (in time order) before the first IMU message after the first
    command: the raw filter starts at that IMU message (core/filter/raw.py), so these are the
    only good messages it may leave unfused ('waiting')."""
    commanded, n = False, 0
    for m in records:
        if m.kind == 'command':
            commanded = True
        elif commanded and m.kind == 'imu':
            return n
        else:
            n += 1
    return n


def compare_case(seed: int, duration: float, names: tuple[str, ...] = PAPER_FIVE,
                 vehicle: str = 'nps_auv2', passes: int = DEFAULT_PASSES) -> Case:
    """Generate one raw run (seed, duration s) and identify `names` from its raw records and
    from its fused odometry (module docstring); both start at the FilterConfig default (the
    file's values +50 %)."""
    cfg = RawConfig(data=DataConfig(vehicle=vehicle, duration=duration, seed=seed))
    run = generate_raw(cfg)
    model = Model(load_vehicle(vehicle), list(names))
    truth = np.array([run.truth['coefficients'][n] for n in model.theta_names])
    t0 = time.perf_counter()
    raw = identify_raw(model, FilterConfig(), run.records, sensors_of(cfg), passes=passes)
    raw_s = time.perf_counter() - t0
    record, dropped = fused_record(run, cfg)
    t0 = time.perf_counter()
    fused = identify_with_diagnosis(model, FilterConfig(), [record], T=1.0 / FUSED_RATE)
    fused_s = time.perf_counter() - t0
    kinds = Counter(m.kind for m in run.records)
    return Case(seed, list(model.theta_names), truth, raw.estimate, raw.std,
                np.asarray(fused.estimate), np.asarray(fused.std), raw.errors,
                run.truth['sensor_errors'], raw_s, fused_s, {'before_first_command': dropped},
                dict(kinds), dict(raw.fused), dict(raw.skipped), before_start(run.records))


def summary(cases: list[Case]) -> dict:
    """Over the cases: per coefficient the median |error| % of raw and fused; over all
    (case, coefficient) the share within 3 sigma and the median |error|/sigma of each."""
    out: dict = {'coefficients': {}}
    names = cases[0].names
    for j, n in enumerate(names):
        out['coefficients'][n] = {
            w: 100.0 * float(np.median([c.rel_error(w)[j] for c in cases]))
            for w in ('raw', 'fused')}
    for w in ('raw', 'fused'):
        z = np.abs(np.concatenate([c.z(w) for c in cases]))
        e = np.concatenate([c.rel_error(w) for c in cases])
        out[w] = {'within_3_sigma': float(np.mean(z <= 3.0)), 'median_abs_z': float(np.median(z)),
                  'median_error_pct': 100.0 * float(np.median(e)),
                  'mean_error_pct': 100.0 * float(np.mean(e))}
    return out
