"""Identifier settings: one frozen, validated value, :class:`IdentifierSettings`, built once
where the settings enter (the identifier node's parameters, the command line, a bag's
metadata, Python callers) and passed whole down the stack.

Each setting is one dataclass field whose metadata holds its help text, unit, choices and
kind (:func:`setting`); the node's parameter declarations, the command-line options,
config/identifier.yaml and the docs/ros.md table are made from these fields
(:func:`settings_fields`; tools/settings_docs.py writes the last two as
session/settings_text.py says). A bad value raises :class:`ParameterError` naming the setting
(= the node parameter, the keyword of :meth:`IdentifierSettings.from_values` and, with '-' for
'_', the command-line option).

Adding a setting: a field here, its use where it acts (IdentSession reads the value), then
``python tools/settings_docs.py``; the node's parameter, the option of ``identify`` and the
checks of test/ros/test_settings_agree.py follow from the field.

The choice lists are defined once here:

- :data:`NOISE_MODES`: the filter's noise adaptation modes (core.filter.ekf.MODES);
- :data:`MASS_INVERSES`: how M^-1 is formed (core.model.hydrodynamics.Model's ``mass_inverse``);
- :data:`FRAMES`: conventions of the incoming Odometry (session.messages, the frame algebra);
  :data:`FRAME_SETTINGS`: those and 'auto' (from the odometry's frame ids, REP-103).
"""
from dataclasses import dataclass, field, fields
import math

import numpy as np

from auv_ident.core.errors import ConfigError
from auv_ident.core.filter.augmented import DEFAULT_CURRENT_SD0, DEFAULT_Q_STATE
from auv_ident.core.filter.ekf import MODES
from auv_ident.core.identification.selection import AUTO, parse_request
from auv_ident.core.model.current import DEFAULT_CURRENT, parse_current
from auv_ident.core.model.sensors import DEFAULT_NOISE_STD
from auv_ident.core.model.state import CURRENT_NAMES, N_STATE, STATE_NAMES, VELOCITY_REFERENCES
from auv_ident.session.auto_choice import AUTO_WINDOW_S
from auv_ident.session.messages import FRAMES
from auv_ident.vehicles import load_vehicle

FRAME_SETTINGS = ('auto',) + FRAMES   # 'auto': the frame ids say (session/screening.py)

NOISE_MODES = tuple(MODES)
MASS_INVERSES = ('default', 'exact', 'mss_literal')
NOISE_SOURCES = ('message', 'parameter')   # where R comes from (IdentSession noise_source)

MAX_SAMPLE_TIME = 1.0   # s: one RK4 step of the model over a longer one is not faithful
MAX_SUBSTEPS = 20000    # max_gap / sample_time: the longest bridge of one gap
MAX_BRIDGE_S = 0.25     # s, default max_bridge: longest gap bridged by time updates
# s: the live node's longest batch (intake_period_s): its subscriptions keep 1000 messages,
# 2.5 s of a 400 Hz IMU; a batch must leave room for a busy moment
MAX_INTAKE_PERIOD_S = 0.5
DEFAULT_INTAKE_PERIOD_S = 0.02    # s: 8 messages of a 400 Hz IMU per batch (ros/intake.py)

__all__ = ['choice', 'coefficient_list', 'coefficient_request', 'DEFAULT_INTAKE_PERIOD_S',
           'FRAME_SETTINGS', 'FRAMES',
           'help_text',
           'IdentifierSettings', 'MASS_INVERSES', 'MAX_BRIDGE_S', 'max_command_age',
           'MAX_SAMPLE_TIME', 'MAX_SUBSTEPS', 'measured_mask', 'names_of', 'noise_model',
           'NOISE_MODES', 'NOISE_SOURCES', 'number', 'ParameterError', 'positive',
           'relative_offset', 'setting', 'settings_fields', 'sigmas', 'timing', 'vector',
           'vehicle_named']


class ParameterError(ConfigError):
    """A bad identifier setting; ``name`` is the node parameter (= keyword argument) at fault."""

    def __init__(self, name, message):
        self.name = name
        self.message = message
        super().__init__(f'parameter {name!r}: {message}')


def choice(name, value, choices):
    """Return value if it is one of `choices`, else raise ParameterError listing them."""
    if not isinstance(value, str) or value not in choices:
        raise ParameterError(name, f'{value!r}; use one of {", ".join(choices)}')
    return value


def number(name, value):
    """Return value as a float (any finite or non-finite number; the caller judges)."""
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ParameterError(name, f'{value!r} is not a number') from None


def positive(name, value, allow_zero=False):
    """Return value as a positive (or, with allow_zero, non-negative) finite float."""
    v = number(name, value)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        what = 'non-negative' if allow_zero else 'positive'
        raise ParameterError(name, f'{value!r} must be a {what} finite number')
    return v


def vector(name, values, n, default):
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


def relative_offset(name, value):
    """Return a relative offset (-) as a float: finite and not -1 (which would make x (1 +
    offset) zero)."""
    v = number(name, value)
    if not math.isfinite(v) or v == -1.0:
        raise ParameterError(name, f'{value!r} must be finite and not -1 (that would start '
                                   'every guess at 0)')
    return v


def sigmas(name, values, default):
    """Return (12,) 1-sigmas of the state channels (state units), each finite and >= 0."""
    a = vector(name, values, N_STATE, default)
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        raise ParameterError(name, f'every 1-sigma must be finite and >= 0, got {a.tolist()}')
    return a


def timing(sample_time, max_gap, max_bridge):
    """Return (sample_time, max_gap, max_bridge) in s, checked against each other.

    max_bridge None or 0 means MAX_BRIDGE_S; it is then clipped to [sample_time, max_gap]."""
    T = positive('sample_time', sample_time)
    if T > MAX_SAMPLE_TIME:
        raise ParameterError('sample_time', f'{sample_time!r} s is longer than '
                                            f'{MAX_SAMPLE_TIME:g} s: one RK4 step of the model '
                                            'over it is not a faithful integration (use the '
                                            'sensor sample time)')
    gap = positive('max_gap', max_gap)
    if gap < T:
        raise ParameterError('max_gap', f'{max_gap!r} s is shorter than sample_time '
                                        f'({T!r} s): every sample would restart the states')
    if max_bridge is None or max_bridge == 0:
        max_bridge = MAX_BRIDGE_S
    bridge = positive('max_bridge', max_bridge)
    if gap / T > MAX_SUBSTEPS:
        raise ParameterError('max_gap', f'{max_gap!r} s is more than {MAX_SUBSTEPS} sample '
                                        f'times ({T!r} s): one gap would take that many time '
                                        'updates')
    return T, gap, min(max(bridge, T), gap)


def max_command_age(value, max_gap):
    """The command staleness limit in s, or None (no limit: a held command is in force however
    old it is). None, 0 or a negative value mean no limit; a positive one is at most max_gap."""
    if value is None:
        return None
    v = number('max_command_age', value)
    if not math.isfinite(v):
        raise ParameterError('max_command_age', f'{value!r} must be a finite number of s '
                                                '(0 or less: no limit)')
    return None if v <= 0.0 else min(v, max_gap)


def noise_model(noise_std, q_state, measured, noise_default, q_default):
    """Return (noise_std (12,), q_state (12,), measured (12,) bool): 1-sigmas finite and
    >= 0, and noise_std > 0 on every measured channel (a zero would make R singular)."""
    noise = sigmas('noise_std', noise_std, noise_default)
    q = sigmas('q_state', q_state, q_default)
    mask = measured_mask(measured)
    if np.any(noise[mask] <= 0):
        bad = [STATE_NAMES[i] for i in np.flatnonzero(mask & (noise <= 0))]
        raise ParameterError('noise_std', f'must be > 0 on every measured channel (zero for '
                                          f'{", ".join(bad)})')
    return noise, q, mask


def measured_mask(names):
    """(12,) bool from state channel names (u v w p q r x y z phi theta psi); empty: all."""
    if names is None or len(names) == 0:
        return np.ones(N_STATE, dtype=bool)
    if isinstance(names, np.ndarray) and names.dtype == bool:
        if names.shape != (N_STATE,):
            raise ParameterError('measured', f'a mask must have {N_STATE} entries, got '
                                             f'{names.shape}')
        return names.copy()
    mask = np.zeros(N_STATE, dtype=bool)
    for n in names:
        if n not in STATE_NAMES:
            raise ParameterError('measured', f'unknown channel {n!r}; use names from '
                                             + ' '.join(STATE_NAMES))
        if mask[STATE_NAMES.index(n)]:
            raise ParameterError('measured', f'channel {n!r} listed twice')
        mask[STATE_NAMES.index(n)] = True
    return mask


def vehicle_named(name):
    """Return the vehicle of a name or YAML path (vehicles.load_vehicle)."""
    try:
        return load_vehicle(name)
    except ConfigError as err:
        raise ParameterError('vehicle', str(err)) from None


def coefficient_request(vehicle, coefficients):
    """(auto, names) of the `coefficients` setting: ['auto'] or ['auto', NAME, ...] asks for
    the set to be chosen from the data, NAME always included (session/auto_choice.py), with
    the offline `--coefficients auto[,NAME,...]` semantics
    (core.identification.selection.parse_request: 'auto' first, names as the vehicle file spells
    them, none twice, no current component);
    any other list is returned as given (auto False) for :func:`coefficient_list`."""
    names = [str(n) for n in (coefficients or ())]
    if not any(n.strip().lower() == AUTO for n in names):
        return False, names
    try:
        return parse_request(vehicle, names)
    except ConfigError as err:
        raise ParameterError('coefficients', str(err)) from None


def coefficient_list(vehicle, coefficients, initial, warm_start='', warm=None):
    """Return (names, initial guesses or None, warm-start covariance or None).

    vehicle : core.model.vehicle.Vehicle
    coefficients : names to identify (empty: the warm-start file's, else the vehicle's
        identify_default); returned in the vehicle's spelling
    initial : guesses in the same order (empty: none)
    warm_start, warm : the warm-start path and its content (vehicle, names, estimate,
        covariance) as estimate_file.load_estimate_json reads it, or '' and None. Its vehicle
        and coefficient list must match; its estimate is then the guesses (not with
        `initial` too).
    """
    names = list(coefficients or ())
    if warm is not None:
        w_vehicle, w_names, w_est, w_cov = warm
        # the file's water current (a previous run's) is not taken: only its coefficients
        keep = [i for i, n in enumerate(w_names) if n not in CURRENT_NAMES]
        w_names = [w_names[i] for i in keep]
        w_est = np.asarray(w_est)[keep]
        w_cov = np.asarray(w_cov)[np.ix_(keep, keep)]
        if w_vehicle != vehicle.name:
            raise ParameterError('warm_start', f'{warm_start} is for vehicle {w_vehicle!r}, '
                                               f'not {vehicle.name!r}')
        if not names:
            names = w_names
    if not names:
        names = list(vehicle.identify_default)
    for n in names:
        if n in CURRENT_NAMES:
            raise ParameterError('coefficients', f'{n!r} is the water current: choose it with '
                                                 'the current setting, not as a coefficient')
        try:
            vehicle.index(n)
        except ConfigError as err:
            raise ParameterError('coefficients', str(err)) from None
    canon = [vehicle.names[vehicle.index(n)] for n in names]
    if len(set(canon)) != len(canon):
        raise ParameterError('coefficients', f'a coefficient is listed twice in {names}')
    init = None
    if initial is not None and len(initial) > 0:
        init = vector('initial', initial, len(canon), None)
        if not np.all(np.isfinite(init)) or np.any(init == 0):
            raise ParameterError('initial', f'guesses must be finite and non-zero (0 gives '
                                            f'no scale for the covariance): {init.tolist()}')
    if warm is None:
        return canon, init, None
    w_canon = [vehicle.names[vehicle.index(n)] if n in vehicle.names else n for n in w_names]
    if w_canon != canon:
        raise ParameterError('warm_start', f'{warm_start} holds {w_names}, but the '
                                           f'coefficients to identify are {canon}')
    if init is not None:
        raise ParameterError('initial', 'give either initial guesses or warm_start, not both')
    if np.any(w_est == 0):
        raise ParameterError('warm_start', f'{warm_start}: an estimate of exactly 0')
    return canon, w_est, w_cov


# --- the settings value ------------------------------------------------------------------------

KINDS = ('str', 'float', 'bool', 'strings', 'floats')   # what a setting's value is


def setting(default, text, unit='', choices=(), kind=None, check=None, note=''):
    """A field of :class:`IdentifierSettings`: its default and, in the metadata, everything the
    node, the command line and the docs say about it.

    text : one line, the help (the node's parameter description, the option's help, the docs table)
    unit : e.g. 's', 'm/s' ('' for none); choices : the allowed values of a text setting
    kind : one of KINDS (default: from the default's type)
    check : (name, value) -> normalised value, raising ParameterError (default: by kind)
    note : more for config/identifier.yaml's comment (optional)"""
    if kind is None:
        kind = {str: 'str', float: 'float', bool: 'bool'}[type(default)]
    if kind not in KINDS:
        raise ValueError(f'unknown kind {kind!r}')
    if check is None:
        check = _choice(choices) if choices else _CHECKS[kind]
    return field(default=default, metadata={'help': text, 'unit': unit,
                                            'choices': tuple(choices), 'kind': kind,
                                            'check': check, 'note': note})


def _text(name, value):
    if not isinstance(value, str) and not hasattr(value, '__fspath__'):
        raise ParameterError(name, f'{value!r} is not text')
    return str(value).strip()


def _current(name, value):
    return str(value).strip()     # parse_current names what is wrong with it


def _flag(name, value):
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise ParameterError(name, f'{value!r}: give true or false')


def names_of(name, value):
    """Names from 'A,B,C' (the command line) or a sequence (a node parameter, Python): the one
    parser of every list of names (coefficients, measured)."""
    items = value.split(',') if isinstance(value, str) else list(value)
    out = [str(n).strip() for n in items]
    if isinstance(value, str):
        out = [n for n in out if n]
    elif not all(out):
        raise ParameterError(name, f'empty entry in {items!r}')
    return tuple(out)


def _floats(name, value):
    """Numbers from 'a,b,c' (the command line) or a sequence (a node parameter, Python)."""
    items = ([v for v in value.split(',') if v.strip()] if isinstance(value, str)
             else list(np.ravel(np.asarray(value, dtype=object))))
    try:
        return tuple(float(v) for v in items)
    except (TypeError, ValueError):
        raise ParameterError(name, f'expected {len(items)} numbers, got {value!r}') from None


def _choice(choices):
    return lambda name, value: choice(name, value, choices)


def _sigmas(default):
    return lambda name, value: tuple(float(v) for v in sigmas(name, _floats(name, value),
                                                              default))


def _measured(name, value):
    if isinstance(value, np.ndarray) and value.dtype == bool:
        mask = measured_mask(value)
        return tuple(STATE_NAMES[i] for i in np.flatnonzero(mask))
    names = names_of(name, value)
    measured_mask(names)
    return names


def _positive(name, value):
    return positive(name, value)


def _non_negative(name, value):
    return positive(name, value, allow_zero=True)


def _intake_period(name, value):
    value = positive(name, value, allow_zero=True)
    if value > MAX_INTAKE_PERIOD_S:
        raise ParameterError(name, f'{value:g} s is longer than {MAX_INTAKE_PERIOD_S:g} s: the '
                                   'input subscriptions keep 1000 messages, which a 400 Hz IMU '
                                   'fills in 2.5 s; take them at least every 0.5 s')
    return value


def _age(name, value):
    return 0.0 if value is None else number(name, value)


_CHECKS = {'str': _text, 'float': number, 'bool': _flag, 'strings': names_of, 'floats': _floats}


@dataclass(frozen=True)
class IdentifierSettings:
    """Every identification setting of the identifier, checked (module docstring).

    Build one with :meth:`from_values` (raw values: text, numbers, lists, None for "unset";
    what was given is remembered in ``given``) or the constructor (every other field its
    default); either way each value is normalised (numbers to float, lists to tuples) and
    checked, a bad one raising ParameterError naming it. ``given`` (the names given to
    from_values, or set away from their default) says which settings a bag's metadata must
    not override (:meth:`over`). Checks that need the vehicle file
    (coefficient names, the warm-start file, the initial guesses' count) are made by
    :class:`~auv_ident.session.session.IdentSession`, which loads the vehicle."""

    vehicle: str = setting('nps_auv2', 'vehicle name (config/<name>.yaml) or vehicle YAML path',
                           note='Its file gives the model, the coefficient names and units, '
                                'and the true values.')
    other_vehicle: bool = setting(
        False, 'identify a bag that records another vehicle than `vehicle` (offline: without '
               'it that is an error naming both)',
        note='A bag our simulator, recorder or importer wrote records its vehicle; '
             '`identify --bag` uses it when `vehicle` is not given, and refuses a different '
             '`vehicle` unless this is set (a renamed or corrected file of the same vehicle). '
             'The live node has no recorded vehicle to compare with.')
    coefficients: tuple = setting(
        (), "coefficients to identify; empty = the vehicle file's identify_default (or the "
            "warm-start file's list); [auto] or [auto, NAME, ...] = chosen from the first "
            'auto_window s of data, NAME always included', kind='strings',
        note='With [auto] the node identifies the NAMEs (none: identify_default) while it '
             'keeps the first auto_window s of data, then chooses the set from them in a '
             'worker thread and switches to it; ~/estimate and ~/covariance then change their '
             'names and length, once (docs/ros.md, Coefficients chosen from the data). Not '
             'with warm_start.')
    auto_window: float = setting(AUTO_WINDOW_S, 'seconds of accepted odometry the coefficients '
                                                '[auto] choice is made from', unit='s',
                                 check=_positive,
                                 note='The choice costs one filter run over the window per '
                                      'candidate coefficient (docs/ros.md). Ignored without '
                                      '[auto].')
    initial: tuple = setting((), "initial guesses in the order of coefficients (vehicle file's "
                                 'units); empty = file value * (1 + initial_offset)',
                             kind='floats')
    initial_offset: float = setting(0.5, 'relative offset of the initial guesses from the file '
                                         'values when initial is empty', unit='-',
                                    check=relative_offset)
    noise_mode: str = setting('fixed', 'noise adaptation (docs/method.md)', choices=NOISE_MODES,
                              note="fixed: Q, R as given; paper: the paper's Eqs. 16-19; "
                                   'paper_q: Eq. 16 only; matching: innovation-based '
                                   'covariance matching.')
    learn_noise: bool = setting(True, "learn the measurement noise's level and AR(1) colour "
                                      'from the innovations and re-run the filter with it '
                                      "(noise_mode fixed; session/noise_learning.py)",
                                note='The live form of the offline noise model: the estimate '
                                     'is NOT consistent until a fit finds the noise model '
                                     'holding (docs/ros.md).')
    tau: float = setting(10.0, 'time constant of the forgetting factor of the adaptation',
                         unit='s', check=_positive)
    lam: float = setting(2e-3, "the paper's lambda of the adaptation", unit='-',
                         check=_positive)
    noise_std: tuple = setting(
        tuple(float(v) for v in DEFAULT_NOISE_STD),
        'measurement noise 1-sigma of u v w [m/s], p q r [rad/s], x y z [m], phi theta psi '
        '[rad]; > 0 on measured channels', kind='floats', check=_sigmas(DEFAULT_NOISE_STD))
    q_state: tuple = setting(
        tuple(float(v) for v in DEFAULT_Q_STATE),
        'per-step process noise 1-sigma of the 12 states (units as noise_std)', kind='floats',
        check=_sigmas(DEFAULT_Q_STATE),
        note='Small on purpose: the coefficients are learnt from how well the model predicts '
             'the motion; raise it for real vehicles with unmodelled forces.')
    p0_rel: float = setting(1.0, 'initial 1-sigma of each coefficient, fraction of |initial '
                                 'guess|', unit='-', check=_positive)
    q_theta_rel: float = setting(1e-5, 'per-step random-walk 1-sigma of each coefficient, '
                                       'fraction of |initial guess|', unit='-',
                                 check=_non_negative)
    measured: tuple = setting(tuple(STATE_NAMES), 'measured channels among '
                                                  + ' '.join(STATE_NAMES),
                              kind='strings', check=_measured,
                              note='Others are ignored, even if present in the message. Quote '
                                   'the names in YAML: a bare y is a boolean.')
    input_map: str = setting('odom_actuators', 'input map: which topics, message types, fields, '
                                               'units and actuators the identifier reads '
                                               '(config/inputs/NAME.yaml or a YAML path; '
                                               'docs/your_data.md)',
                             note='odom_actuators is the nav_msgs/Odometry on odom and the '
                                  'sensor_msgs/JointState on actuators with the six joint '
                                  'names rudder, stern_planes, bow_planes, bow_plane_port, '
                                  'bow_plane_starboard, propeller.')
    frame: str = setting('auto', 'convention of the incoming Odometry: auto = from its frame '
                                 'ids (a _ned/_frd token: NED/FRD; other names, e.g. odom and '
                                 'base_link: REP-103 ENU/FLU; none: NED), ned = NED/FRD, enu = '
                                 'REP-103 ENU/FLU', choices=FRAME_SETTINGS)
    sample_time: float = setting(0.05, 'nominal sample time and longest single prediction '
                                       'step', unit='s')
    max_gap: float = setting(5.0, 'a backward time jump larger than this is confirmed by 5 '
                                  'messages before the time line restarts; also the longest '
                                  'forward gap and command hold', unit='s')
    max_bridge: float = setting(0.0, 'longest gap between odometry stamps bridged by time '
                                     'updates; a longer one restarts the vehicle states '
                                     f'(coefficients kept); 0 = {MAX_BRIDGE_S:g} s', unit='s',
                                check=lambda name, v: 0.0 if v is None else number(name, v))
    mass_inverse: str = setting('default', "M^-1: default (the vehicle file's choice), exact or "
                                           "mss_literal (MSS's 4-digit literal inverse)",
                                choices=MASS_INVERSES)
    max_command_age: float = setting(0.0, 'odometry whose command in force is older than this is '
                                          "rejected as 'stale command'; 0 = no limit (a held "
                                          'command stays in force: drivers publish on change)',
                                     unit='s', check=_age)
    noise_source: str = setting('message', 'measurement noise: message (the Odometry covariance '
                                           'diagonals where finite and positive, noise_std '
                                           'elsewhere) or parameter (noise_std)',
                                choices=NOISE_SOURCES)
    current: str = setting(DEFAULT_CURRENT, 'the water current: estimate (with the coefficients, '
                                            'as current_n, current_e), none (still water) or '
                                            'N,E[,D] (a known current, NED, where the water '
                                            'goes; docs/current.md)', unit='m/s',
                           check=_current,
                           note='Estimated by default: every AUV runs in one, and 0.1 m/s left '
                                'out biases the coefficients beyond their error bars, while '
                                'estimating a zero current costs nothing measurable; none is '
                                'the still-water filter of before, bit for bit.')
    current_down: bool = setting(False, 'also estimate the down component of the current '
                                        '(with current estimate)')
    velocity_reference: str = setting('ground', 'what twist.linear is: over ground (DVL bottom '
                                                'lock) or through the water (water-track DVL)',
                                      choices=VELOCITY_REFERENCES)
    current_sd0: float = setting(DEFAULT_CURRENT_SD0, 'initial 1-sigma of each estimated '
                                                      'current component', unit='m/s',
                                 check=_positive)
    current_walk: float = setting(0.0, 'random walk of the estimated current; 0 = constant',
                                  unit='m/s/sqrt(s)', check=_non_negative)
    warm_start: str = setting('', 'estimate JSON to start from (its estimate and covariance '
                                  "replace initial and p0_rel; the coefficients only); '' = "
                                  'none')
    publish_rate_hz: float = setting(
        0.0, 'live node: publish ~/estimate, ~/covariance and ~/current at most this often, '
             'the first good update in each 1/rate interval of message stamps; 0 = after every '
             'good update', unit='Hz', check=_non_negative,
        note='Every message is still processed and the estimates are the same; only what is '
             'published thins out. An update published to a subscriber costs the node about '
             '0.3 ms of CPU (the three topics, measured at 200 Hz odometry, docs/latency.md), '
             'more than the update itself, so a fast IMU or odometry stream with a slower '
             'consumer wants e.g. 10. Offline passes keep every update.')
    intake_period_s: float = setting(
        DEFAULT_INTAKE_PERIOD_S,
        'live node: take the input messages in batches, every this many seconds, in the order '
        'they were published; 0 = each as it arrives', unit='s',
        check=_intake_period,
        note='Every message is processed and the estimates are the same either way. Batched, '
             'the node wakes at this rate instead of at every message, and the same work costs '
             'far less CPU (400 Hz IMU + DVL + depth: 0.51 -> 0.29 ms per message, '
             'docs/latency.md); each estimate comes up to this much later. 0 gives the lowest '
             'latency (200 Hz odometry: p50 about 1 ms) at the most CPU. At most '
             f'{MAX_INTAKE_PERIOD_S:g} s: the subscriptions keep 1000 messages.')
    # the settings given: to from_values, or away from their default (not a setting itself)
    given: frozenset = field(default=frozenset(), compare=False, repr=False)

    def __post_init__(self):
        for f in settings_fields():
            object.__setattr__(self, f.name, f.metadata['check'](f.name, getattr(self, f.name)))
        object.__setattr__(self, 'given', frozenset(self.given) | {
            f.name for f in settings_fields() if getattr(self, f.name) != f.default})
        # the checks between settings, in the order IdentSession made them
        timing(self.sample_time, self.max_gap, self.max_bridge)
        max_command_age(self.max_command_age, self.max_gap)
        noise_model(self.noise_std, self.q_state, self.measured, DEFAULT_NOISE_STD,
                    DEFAULT_Q_STATE)
        self.current_option     # noqa: B018 - parsed for its check

    @classmethod
    def from_values(cls, **raw):
        """The settings of these raw values (None: the default, as ROS reads an empty list);
        raises ParameterError naming an unknown or bad one."""
        known = {f.name: f for f in settings_fields()}
        for name in raw:
            if name not in known:
                raise ParameterError(name, 'not an identifier setting (one of '
                                           + ', '.join(known) + ')')
        # None is "not set" (ROS turns an empty list into that; a Python caller's default)
        given = {k: v for k, v in raw.items() if v is not None}
        return cls(**given, given=frozenset(given))

    def over(self, defaults):
        """These settings, with `defaults` (raw values, e.g. a bag's metadata:
        offline/replay.py bag_settings) for those not given to from_values."""
        raw = dict(defaults)
        raw.update({n: getattr(self, n) for n in self.given})
        return self.from_values(**raw)

    def with_values(self, **raw):
        """A copy with these values changed (checked as from_values; they count as given)."""
        out = self.from_values(**dict(self.as_dict(), **raw))
        object.__setattr__(out, 'given', self.given | frozenset(raw))
        return out

    def as_dict(self):
        """{name: value} of every setting (lists as lists: JSON-ready)."""
        return {f.name: list(v) if isinstance(v := getattr(self, f.name), tuple) else v
                for f in settings_fields()}

    @property
    def timing(self):
        """(sample_time, max_gap, max_bridge) in s, max_bridge resolved (settings.timing)."""
        return timing(self.sample_time, self.max_gap, self.max_bridge)

    @property
    def command_age_limit(self):
        """The command staleness limit in s, or None (no limit)."""
        return max_command_age(self.max_command_age, self.max_gap)

    @property
    def current_option(self):
        """The water current option (core.model.current.parse_current)."""
        try:
            return parse_current(self.current, self.current_down)
        except ConfigError as err:
            raise ParameterError('current_down' if self.current_down and self.current
                                 != 'estimate' else 'current', str(err)) from None


def settings_fields():
    """The fields of IdentifierSettings that are settings, in order (not `given`)."""
    return tuple(f for f in fields(IdentifierSettings) if 'help' in f.metadata)


def help_text(f):
    """A setting's help with its choices and unit: the node's parameter description, the
    option's help and the docs table say this."""
    m = f.metadata
    return (m['help'] + (f'; one of {", ".join(m["choices"])}' if m['choices'] else '')
            + (f' [{m["unit"]}]' if m['unit'] else ''))
