"""Screening of one message before it reaches the filter: pure functions of arrays and strings.

Rejection policy of :class:`auv_ident.session.session.IdentSession` (the message is dropped,
counted under ``'<topic>: <code>'`` in ``IdentSession.counters.reasons`` (session/status.py)
and reported with a reason naming the problem; the filter is untouched). Codes, in the order
they are checked:

- ``conversion``: the message could not be read (wrong message type, missing or duplicated
  joint, zero quaternion, array lengths that do not match the joint names, ...:
  :class:`auv_ident.session.messages.ConversionError`), or the arrays given to the array API
  have the wrong length or a stamp that is not an integer;
- ``wrong frame`` (odometry): header.frame_id / child_frame_id name the other convention
  (:func:`frame_problem`);
- ``frame changed`` (odometry): frame ids that differ from those of the first accepted
  odometry (the ~/reset service forgets them);
- ``non-finite``: NaN or Inf in a command, or in a *measured* odometry channel (unmeasured
  channels are set to NaN and ignored; the message covariances are not used);
- ``implausible``: a value no vehicle produces, i.e. wrong units or a wrong frame (the
  plausibility rule below);
- from StreamIdentifier (core/filter/stream.py, its docstring has the time rules): ``no command``,
  ``stale command`` (the command in force is older than max_command_age, when set), ``command
  unknown`` (a newer command in the interval was rejected: the input is unknown), ``zero stamp``,
  ``duplicate stamp``, ``out of order``, ``time jump backwards`` (until five consistent
  messages confirm it), ``outlier`` (innovation gate, session/guard.py). Accepted with a
  note: ``gap`` (more than max_bridge, 0.25 s, without odometry: vehicle states restarted),
  ``time jump``, ``repaired``.

Frame-id rule: a token ``ned`` or ``frd`` in a frame id names the NED convention, ``enu`` or
``flu`` the ENU one (tokens are the lower-case alphanumeric runs, so 'odom_ned' and
'base_link_FRD' count, 'friend' does not); ids without such a token, e.g. 'odom'/'base_link',
are not judged. Odometry whose ids name the other convention than the ``frame`` setting is
rejected, and so is odometry whose ids differ from those of the first accepted one. With the
``frame`` setting 'auto' (the default), the first odometry's ids decide the convention
(:func:`frame_of_ids`): a token names it; ids without one are REP-103 names (ENU/FLU).

Plausibility rule (wrong units or frames detectable by range; only measured channels):
|u|, |v|, |w| <= MAX_BODY_SPEED (10 m/s: cm/s or mm/s are caught); |p|, |q|, |r| <=
MAX_BODY_RATE (5 rad/s: deg/s are caught once a rate exceeds 5 deg/s); |phi|, |theta| <=
MAX_TILT (1.2 rad = 69 deg: a sensor frame mounted 90 deg off, e.g. an optical frame);
|z| <= MAX_DEPTH (11000 m: depth in cm/mm); |x|, |y| <= MAX_HORIZONTAL (2e7 m: position in
mm); commands: |fin| <= FIN_LIMIT_FACTOR (2) x the vehicle's fin limit (degrees given as
radians: caught once a deflection exceeds 2x the limit *in degrees*, i.e. 0.7 deg for +-20 deg
fins), |n| <= SHAFT_LIMIT_FACTOR (2) x the vehicle's shaft limit (rpm written into the rad/s
velocity field is caught above 2 x 1500 / 9.55 = 314 rpm). NOT detectable by range: rates in
deg/s below 5 deg/s, speeds in knots, shaft speed in rev/s, positions in km, an ENU/FLU stream
read as NED/FRD (every value stays in range: (phi, -theta, pi/2 - psi), flipped v, w, q, r);
these make the innovations inconsistent with the model instead, which the divergence guard
(session/guard.py) catches (outliers, then a reset, ERROR 'diverging' on /diagnostics).
Simulated runs of every vehicle and manoeuvre and the shipped bag are far inside the bounds
(|u| < 0.7 m/s, rates < 0.16 rad/s, tilt < 0.4 rad).

Message covariance rule (noise_source 'message'): a stated variance of a measured channel more
than PLAUSIBLE_VARIANCE_RATIO (1e16, a 1-sigma 1e8 times) above or below the variance of
noise_std (the documented sensor level) is no sensor's: a driver that scaled it twice or wrote
1e300 for "unknown" (:func:`implausible_variances`). The session uses noise_std for it and
says so once per channel, naming the covariance entry; real data span far less (the importer's
1e6 "unmeasured" variance is 1e12 x the default variance of p; the HSVA runs' r at 1.4e-8 x).

The functions take plain lists of floats (``ndarray.tolist()``): a message has a dozen values,
and Python arithmetic on them costs less than numpy's per-call overhead.
"""
from collections.abc import Sequence
from functools import lru_cache
import math
import re

import numpy as np

from auv_ident.core.model.state import Input, N_FINS, State, STATE_NAMES, STATE_UNITS
from auv_ident.session.messages import JOINT_NAMES

MAX_BODY_SPEED = 10.0       # m/s, |u| |v| |w|
MAX_BODY_RATE = 5.0         # rad/s, |p| |q| |r|
MAX_TILT = 1.2              # rad, |phi| |theta|
MAX_DEPTH = 11000.0         # m, |z|
MAX_HORIZONTAL = 2.0e7      # m, |x| |y|
FIN_LIMIT_FACTOR = 2.0      # x the vehicle's fin limit
SHAFT_LIMIT_FACTOR = 2.0    # x the vehicle's shaft-speed limit
PLAUSIBLE_VARIANCE_RATIO = 1e16   # a message variance / noise_std's variance, either way

_BOUNDS = {State.U: MAX_BODY_SPEED, State.V: MAX_BODY_SPEED, State.W: MAX_BODY_SPEED,
           State.P: MAX_BODY_RATE, State.Q: MAX_BODY_RATE, State.R: MAX_BODY_RATE,
           State.X: MAX_HORIZONTAL, State.Y: MAX_HORIZONTAL, State.Z: MAX_DEPTH,
           State.PHI: MAX_TILT, State.THETA: MAX_TILT, State.PSI: math.inf}
STATE_BOUNDS = tuple(_BOUNDS[s] for s in State)    # plausibility bound of each state

# frame-id tokens that name a convention
FRAME_TOKENS = {'ned': 'ned', 'frd': 'ned', 'enu': 'enu', 'flu': 'enu'}
_TOKEN_SPLIT = re.compile(r'[^a-z0-9]+')


@lru_cache(maxsize=64)
def named_conventions(frame_id: str, child_frame_id: str) -> tuple[str, ...]:
    """The conventions ('ned', 'enu') the two frame ids name by their tokens, sorted.

    Cached: a stream repeats the same ids in every message (and the cache is bounded, so a
    stream of ever-new ids costs only the recomputation)."""
    named = set()
    for text in (frame_id, child_frame_id):
        for token in _TOKEN_SPLIT.split(text.lower()):
            if token in FRAME_TOKENS:
                named.add(FRAME_TOKENS[token])
    return tuple(sorted(named))


def frame_of_ids(frame_id: str, child_frame_id: str) -> str:
    """The convention ('ned' or 'enu') an odometry's frame ids say, for the frame setting
    'auto': a ``ned``/``frd`` token NED, an ``enu``/``flu`` token ENU (both named: NED, and the
    frame-id rule then rejects the messages, naming both); ids without a token name REP-103
    frames ('odom', 'base_link', 'map': ENU/FLU, REP-103/105); no ids at all: NED, the
    package's own convention."""
    named = named_conventions(frame_id, child_frame_id)
    if named:
        return 'ned' if 'ned' in named else 'enu'
    return 'enu' if (frame_id or child_frame_id) else 'ned'


def frame_problem(frame_id: str, child_frame_id: str, frame: str,
                  first_ids: tuple[str, str] | None = None) -> tuple[str, str] | None:
    """(code, text) if odometry frame ids break the frame-id rule, else None.

    frame : the expected convention ('ned' or 'enu')
    first_ids : (frame_id, child_frame_id) of the first accepted odometry, or None
    """
    named = named_conventions(frame_id, child_frame_id)
    if named and named != (frame,):
        return 'wrong frame', (f'frame ids {frame_id!r} / {child_frame_id!r} name the '
                               f'{"/".join(n.upper() for n in named)} convention, but the '
                               f'frame parameter is {frame!r}')
    if first_ids is not None and (frame_id, child_frame_id) != first_ids:
        return 'frame changed', (f'frame ids {frame_id!r} / {child_frame_id!r} differ from '
                                 f'{first_ids[0]!r} / {first_ids[1]!r} of the first accepted '
                                 'odometry')
    return None


def implausible_variances(variances: np.ndarray, documented: np.ndarray) -> np.ndarray:
    """(12,) bool: the message variances more than PLAUSIBLE_VARIANCE_RATIO away from the
    documented ones (noise_std squared) either way (module docstring). NaN, 0 and -1 ('not
    stated') are not judged here (False)."""
    with np.errstate(invalid='ignore', divide='ignore', over='ignore'):
        ratio = np.asarray(variances, dtype=float) / np.asarray(documented, dtype=float)
        return (ratio > PLAUSIBLE_VARIANCE_RATIO) | (ratio < 1.0 / PLAUSIBLE_VARIANCE_RATIO) \
            & (ratio > 0.0)


def nonfinite_states(x12: Sequence[float], channels: Sequence[int]) -> list[str]:
    """Names of the states among `channels` (State indices) whose value in x12 is NaN/Inf."""
    isfinite = math.isfinite
    return [STATE_NAMES[i] for i in channels if not isfinite(x12[i])]


def implausible_states(x12: Sequence[float], channels: Sequence[int]) -> str:
    """Text naming the states among `channels` beyond the plausibility bounds, or ''.

    x12 : (12,) finite on `channels` (checked before, see :func:`nonfinite_states`)."""
    bad = [i for i in channels if abs(x12[i]) > STATE_BOUNDS[i]]
    if not bad:
        return ''
    return 'implausible ' + ', '.join(
        f'{STATE_NAMES[i]} = {x12[i]:.6g} {STATE_UNITS[i]} (|{STATE_NAMES[i]}| <= '
        f'{STATE_BOUNDS[i]:g})' for i in bad) + ' (wrong units or frame?)'


def odometry_problem(x12: Sequence[float], t: float, frame_id: str, child_frame_id: str,
                     frame: str, first_ids: tuple[str, str] | None,
                     channels: Sequence[int]) -> tuple[str, str] | None:
    """(code, text) if odometry breaks a rule, else None: the frame-id rule
    (:func:`frame_problem`), then non-finite and implausible values (:func:`nonfinite_states`,
    :func:`implausible_states`).

    x12 : list of 12 floats (NED/FRD); t : its stamp (s), for the text
    frame_id, child_frame_id, frame, first_ids : as :func:`frame_problem`
    channels : the measured states (State indices), the only ones judged
    """
    problem = frame_problem(frame_id, child_frame_id, frame, first_ids)
    if problem is not None:
        return problem[0], f'{problem[1]} at {t:.9f} s'
    bad = nonfinite_states(x12, channels)
    if bad:
        return 'non-finite', f'non-finite field(s) {", ".join(bad)} at {t:.9f} s'
    text = implausible_states(x12, channels)
    if text:
        return 'implausible', f'{text} at {t:.9f} s'
    return None


def command_problem(u7: Sequence[float], t: float, fin_limit: float,
                    shaft_limit: float) -> tuple[str, str] | None:
    """(code, text) if an actuator command breaks the rules, else None.

    u7 : list of 7 floats, fins (rad), shaft speed (rpm), thrust (N); t : its stamp (s), for
        the text (a non-finite thrust is a non-finite command too)
    fin_limit (rad), shaft_limit (rpm) : the vehicle's limits
    """
    if not all(map(math.isfinite, u7)):
        return 'non-finite', f'non-finite command {[float(v) for v in u7]} at {t:.9f} s'
    fin_bound = FIN_LIMIT_FACTOR * fin_limit
    fins = [k for k in range(N_FINS) if abs(u7[k]) > fin_bound]
    if fins:
        bad = ', '.join(f'{JOINT_NAMES[k]} = {u7[k]:.6g} rad' for k in fins)
        return 'implausible', (f'implausible fin angle(s) {bad} at {t:.9f} s: beyond '
                               f'{FIN_LIMIT_FACTOR:g}x the {fin_limit:.4g} rad limit (degrees '
                               'given as radians?)')
    n_rpm = u7[Input.N_RPM]
    if abs(n_rpm) > SHAFT_LIMIT_FACTOR * shaft_limit:
        return 'implausible', (f'implausible shaft speed {n_rpm:.6g} rpm at {t:.9f} s: beyond '
                               f'{SHAFT_LIMIT_FACTOR:g}x the {shaft_limit:.6g} rpm limit (rpm '
                               'written into the rad/s velocity field?)')
    return None
