"""Judging a calibrated flight model on dives it never saw: its speed through water against a
DVL's, its depth rate against the pressure's.

The DVL is another instrument than the one the model is fitted to (pressure), so it is an
honest judge, but it is judged too, without any model: on a dive, the depth rate (pressure),
the pitch (inclinometer) and the DVL's speed fix the angle of attack,
``alpha = asin(|dz/dt| / U_DVL) - |theta|``. A glider flies its dives at one angle of attack
to within the instruments' noise (a Slocum at 2-5 deg, Merckelbach et al. 2019), so a dive
whose median implied angle stands out from the other dives' by more than their spread and its
own sampling error explain is one where the three instruments disagree
(:func:`consistent_dvl`, a test with a stated false-rejection rate; the comet record's last
dive: 17.5 deg against 3.6 +- 0.7 deg, z = 9 for a limit of 3.45). In speed: at the dives'
centre angle the depth rate and the pitch imply a speed ``|dz/dt| / sin(|theta| + alpha_c)``
(:attr:`DiveCheck.implied_speed`), and a flagged dive is one whose DVL speed is off it by more
than the other dives' are (the comet's last: 0.196 m/s where 0.305 m/s is implied, -36 %; the
other 17 dives -7..+1 %). Such a dive cannot judge
a flight model: the validation scores the dives that pass, and gives every model the figures
over every DVL sample too.

Error bars of the scores (:func:`score`, :func:`compare_speeds`): the speed errors last a dive
(a current, internal waves, the DVL's own per-dive processing), so the dive, not the sample,
is the independent unit: the bias's 1-sigma and that of the difference between two models'
RMS errors on the same DVL samples are the cluster-robust ones over the dives
(``G / (G - 1) sum_i w_i^2 (x_i - x)^2``, w_i the dive's share of the samples, G dives). A
difference between two models smaller than twice its 1-sigma is one this record cannot tell.
"""
from dataclasses import asdict, dataclass
import math
from typing import Any

import numpy as np
from scipy.stats import norm

from auv_ident.core.glider.calibration import fit_window
from auv_ident.core.glider.flight import Flight
from auv_ident.core.glider.record import GliderRecord
from auv_ident.core.simulation.prediction import fit_percent

# the probability that the check wrongly rejects any of a record's dives (1 %), and the fewest
# dives with which the dive-to-dive spread means anything
FALSE_REJECTION = 0.01
MIN_DIVES = 5
DIVE_GAP = 5        # samples: valid DVL samples further apart belong to different dives


def dvl_dives(record: GliderRecord, gap: int = DIVE_GAP) -> list[np.ndarray]:
    """Index arrays of the runs of valid DVL samples (one per dive)."""
    idx = np.flatnonzero(np.isfinite(record.speed_through_water))
    if not len(idx):
        return []
    return np.split(idx, np.flatnonzero(np.diff(idx) > gap) + 1)


def implied_angle_of_attack(record: GliderRecord) -> np.ndarray:
    """(N,) rad: asin(|dz/dt| / U_DVL) - |theta| (module docstring); NaN without a DVL speed."""
    with np.errstate(invalid='ignore', divide='ignore'):
        ratio = np.clip(np.abs(record.depth_rate()) / record.speed_through_water, -1.0, 1.0)
    return np.arcsin(ratio) - np.abs(record.pitch)


@dataclass
class DiveCheck:
    """One DVL dive judged (:func:`consistent_dvl`): its start (s since 1970), DVL samples,
    median implied angle of attack and that median's standard error (deg), its distance from
    the dives' centre in combined sigma, and whether it passed."""

    start: float
    samples: int
    median_aoa_deg: float
    stderr_deg: float
    z: float
    kept: bool
    # what the three instruments and the pump read on the dive (medians over its DVL samples):
    # m/s, deg, cc, m/s; a dive flown as the others (same pump, pitch, depth rate) with a DVL
    # speed unlike theirs is the DVL's, not the flight's
    depth_rate: float = float('nan')
    pitch_deg: float = float('nan')
    pumped_cc: float = float('nan')
    dvl_speed: float = float('nan')
    # m/s: the speed the dive's (median) depth rate and pitch imply at the dives' centre
    # angle of attack, |dz/dt| / sin(|theta| + centre): what the DVL would read were the dive
    # flown at the others' angle of attack (the evidence printed beside the verdict)
    implied_speed: float = float('nan')


@dataclass
class DvlConsistency:
    """The instruments' consistency check over a record's DVL dives (:func:`consistent_dvl`).

    keep : (N,) bool, the DVL samples of the dives that passed; dives : a DiveCheck each;
    centre_deg, spread_deg : the dives' median implied angle of attack and its dive-to-dive
    robust standard deviation (1.4826 MAD); z_limit : the limit on |z| (NaN: too few dives to
    judge, every dive kept)."""

    keep: np.ndarray
    dives: list[DiveCheck]
    centre_deg: float
    spread_deg: float
    z_limit: float

    @property
    def flagged(self) -> list[DiveCheck]:
        """The dives that failed the check, in time order."""
        return [d for d in self.dives if not d.kept]

    def as_dict(self) -> dict[str, Any]:
        return {'centre_deg': self.centre_deg, 'spread_deg': self.spread_deg,
                'z_limit': self.z_limit, 'false_rejection': FALSE_REJECTION,
                'dives': [asdict(d) for d in self.dives]}


def _median_stderr(values: np.ndarray) -> float:
    """deg: the standard error of a median, 1.2533 sigma / sqrt(n), sigma from the IQR (robust
    to the stall-side tail). The samples of a dive are correlated over seconds, so this is a
    lower bound: a dive is, if anything, judged more strictly."""
    q25, q75 = np.percentile(values, [25.0, 75.0])
    return float(1.2533 * (q75 - q25) / 1.349 / np.sqrt(len(values)))


def consistent_dvl(record: GliderRecord,
                   false_rejection: float = FALSE_REJECTION) -> DvlConsistency:
    """The consistency check of the DVL with the pressure and the pitch, dive by dive (module
    docstring): a :class:`DvlConsistency`.

    Each dive's median implied angle of attack m_i (standard error s_i) is compared with the
    dives' centre c (the median of the m_i) and their robust spread d (1.4826 MAD):
    ``z_i = (m_i - c) / sqrt(d^2 + s_i^2)``, the dive-to-dive spread plus the dive's own
    sampling error. A dive fails when |z_i| is above the two-sided normal limit at which all
    n dives together are wrongly rejected with probability ``false_rejection`` (Bonferroni:
    Phi^-1(1 - false_rejection / 2n), 3.45 for 18 dives at 1 %). The limit comes from the
    dives themselves, not from the models: no flight model is used. With fewer than
    :data:`MIN_DIVES` dives there is no spread to judge by, and every dive is kept."""
    aoa = np.degrees(implied_angle_of_attack(record))
    runs = dvl_dives(record)
    medians = np.array([float(np.median(aoa[idx])) for idx in runs])
    errors = np.array([_median_stderr(aoa[idx]) for idx in runs])
    if len(runs) >= MIN_DIVES:
        centre = float(np.median(medians))
        spread = float(1.4826 * np.median(np.abs(medians - centre)))
        z_limit = float(norm.ppf(1.0 - false_rejection / (2.0 * len(runs))))
        with np.errstate(divide='ignore', invalid='ignore'):
            z = (medians - centre) / np.hypot(spread, errors)
    else:
        centre = float(np.median(medians)) if len(runs) else np.nan
        spread = z_limit = np.nan
        z = np.full(len(runs), np.nan)
    keep = np.zeros(len(record), dtype=bool)
    dives = []
    rate = record.depth_rate()
    for idx, med, err, zi in zip(runs, medians, errors, z):
        ok = not abs(zi) > z_limit          # NaN (too few dives): kept
        keep[idx] = ok
        w, pitch = float(np.median(rate[idx])), float(np.median(record.pitch[idx]))
        dives.append(DiveCheck(start=float(record.t[idx[0]]), samples=len(idx),
                               median_aoa_deg=float(med), stderr_deg=float(err), z=float(zi),
                               kept=bool(ok), depth_rate=w, pitch_deg=math.degrees(pitch),
                               pumped_cc=float(1e6 * np.median(record.pumped_volume[idx])),
                               dvl_speed=float(np.median(record.speed_through_water[idx])),
                               implied_speed=abs(w) / math.sin(abs(pitch)
                                                               + math.radians(centre))))
    return DvlConsistency(keep=keep, dives=dives, centre_deg=centre, spread_deg=spread,
                          z_limit=z_limit)


def dive_groups(record: GliderRecord, use: np.ndarray) -> list[np.ndarray]:
    """Index arrays of the samples where use (N,) bool, one per DVL dive that has any."""
    return [idx[use[idx]] for idx in dvl_dives(record) if use[idx].any()]


def clustered_mean(values: np.ndarray, groups: list[np.ndarray]) -> tuple[float, float]:
    """(mean, 1-sigma) of values (N,) over the samples of groups (index arrays, one per
    dive): the sample mean and its cluster-robust standard error over the groups (module
    docstring); NaN 1-sigma with fewer than 2 groups."""
    n = np.array([len(g) for g in groups], dtype=float)
    if not n.sum():
        return np.nan, np.nan
    w = n / n.sum()
    means = np.array([np.mean(values[g]) for g in groups])
    mean = float(np.sum(w * means))
    if len(groups) < 2:
        return mean, np.nan
    var = len(groups) / (len(groups) - 1.0) * np.sum(w ** 2 * (means - mean) ** 2)
    return mean, float(np.sqrt(var))


@dataclass
class Scores:
    """Speed through water against the DVL (bias = mean(model - DVL), rms, fit %, m/s and %)
    over the DVL samples kept, the bias's 1-sigma over the dives (module docstring) and
    their number, and the depth rate against the pressure's over the fit window (bias,
    rms m/s)."""

    speed_bias: float
    speed_rms: float
    speed_fit: float
    speed_samples: int
    depth_rate_bias: float
    depth_rate_rms: float
    speed_bias_std: float = float('nan')
    speed_dives: int = 0


def score(flight: Flight, record: GliderRecord, dvl_mask: np.ndarray,
          window: tuple[float, float]) -> Scores:
    """:class:`Scores` of a Flight over a record; dvl_mask (N,) bool selects the DVL samples
    judged (finite ones only)."""
    dvl = record.speed_through_water
    use = dvl_mask & np.isfinite(dvl)
    e = flight.speed[use] - dvl[use]
    fit = fit_window(record, window)
    ez = flight.depth_rate[fit] - record.depth_rate()[fit]
    groups = dive_groups(record, use)
    _, bias_std = clustered_mean(flight.speed - dvl, groups)
    return Scores(speed_bias=float(np.mean(e)) if len(e) else np.nan,
                  speed_rms=float(np.sqrt(np.mean(e ** 2))) if len(e) else np.nan,
                  speed_fit=fit_percent(dvl[use], flight.speed[use]),
                  speed_samples=int(use.sum()),
                  depth_rate_bias=float(np.mean(ez)),
                  depth_rate_rms=float(np.sqrt(np.mean(ez ** 2))),
                  speed_bias_std=bias_std, speed_dives=len(groups))


@dataclass
class Comparison:
    """Two models' speeds judged on the same DVL samples, paired dive by dive
    (:func:`compare_speeds`): their RMS errors (m/s), the difference rms_a - rms_b and its
    1-sigma over the dives (m/s), the dives and samples."""

    rms_a: float
    rms_b: float
    difference: float
    difference_std: float
    dives: int
    samples: int


def compare_speeds(speed_a: np.ndarray, speed_b: np.ndarray, record: GliderRecord,
                   use: np.ndarray) -> Comparison:
    """Is model a's speed (N,) m/s closer to the DVL than model b's on the samples where use
    (N,) bool (finite DVL ones)? rms_a^2 - rms_b^2 is the mean of e_a^2 - e_b^2, whose
    1-sigma is the cluster-robust one over the dives (module docstring): paired on the same
    samples, the DVL's own dive-to-dive errors, common to both, cancel."""
    dvl = record.speed_through_water
    use = use & np.isfinite(dvl)
    ea, eb = speed_a - dvl, speed_b - dvl
    groups = dive_groups(record, use)
    rms_a = float(np.sqrt(np.mean(ea[use] ** 2)))
    rms_b = float(np.sqrt(np.mean(eb[use] ** 2)))
    with np.errstate(invalid='ignore'):
        _, d_std = clustered_mean(ea ** 2 - eb ** 2, groups)
    # rms_a - rms_b = (rms_a^2 - rms_b^2) / (rms_a + rms_b), exactly
    return Comparison(rms_a=rms_a, rms_b=rms_b, difference=rms_a - rms_b,
                      difference_std=d_std / (rms_a + rms_b), dives=len(groups),
                      samples=int(use.sum()))


@dataclass
class AngleOfAttackAgreement:
    """A flight model's angle of attack against the one the DVL, the pressure and the pitch
    imply (:func:`angle_of_attack_agreement`): deg, the model's median |alpha| and glide angle
    over the consistent dives' DVL samples, the dives' centre and spread, z = (model - centre)
    / spread, the limit on |z| (the consistency check's), the speed error the difference
    implies (m/s, model - DVL) and whether it is beyond the limit."""

    model_deg: float
    implied_deg: float
    spread_deg: float
    glide_deg: float
    z: float
    z_limit: float
    speed_error: float
    disagrees: bool


def angle_of_attack_agreement(flight: Flight, record: GliderRecord, check: DvlConsistency,
                              kept_times: np.ndarray) -> AngleOfAttackAgreement | None:
    """Does the model fly at the angle of attack the instruments imply? Over the record's
    DVL samples at kept_times (s since 1970: the dives that passed ``check``, which may have
    run over a longer record). None without a spread to judge by (fewer than
    :data:`MIN_DIVES` dives) or without such samples.

    The depth-rate calibration fits the vertical speed |dz/dt| = U sin(|theta| + alpha); the
    split of it into U and the glide angle rests on the pitch and the model's angle of attack
    (its lift and drag). On the DVL's dives the three instruments fix alpha without a model
    (:func:`consistent_dvl`'s centre). A model whose alpha lies outside the dives' own scatter
    by more than the check's limit flies them at an angle no dive shows: for the same depth
    rate its speed is off by about ``-U cot(|gamma|) (alpha_model - alpha_c)``. The usual
    cause is an uncalibrated inclinometer (the comet's raw m_pitch reads 1/0.86 of its pitch:
    an implied alpha of 0.4 deg against the model's 3.9, a speed 3.8 cm/s low); else the lift
    slope or the induced drag."""
    use = np.isin(record.t, kept_times) & np.isfinite(record.speed_through_water)
    if not math.isfinite(check.z_limit) or not check.spread_deg > 0.0 or not use.any():
        return None
    alpha = float(np.degrees(np.median(np.abs(flight.angle_of_attack[use]))))
    gamma = float(np.degrees(np.median(np.abs(flight.glide_angle[use]))))
    speed = float(np.median(flight.speed[use]))
    z = (alpha - check.centre_deg) / check.spread_deg
    error = -speed * math.radians(alpha - check.centre_deg) / math.tan(math.radians(gamma))
    return AngleOfAttackAgreement(model_deg=alpha, implied_deg=check.centre_deg,
                                  spread_deg=check.spread_deg, glide_deg=gamma, z=z,
                                  z_limit=check.z_limit, speed_error=error,
                                  disagrees=bool(abs(z) > check.z_limit))
