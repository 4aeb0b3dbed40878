"""Identifier settings checked once, in one style: a bad value raises :class:`ParameterError`
naming the setting (= the identifier node's parameter and the keyword of IdentSession).

The choice lists are defined once and imported from here by whoever needs them (IdentSession,
the identifier node's parameter descriptions, the command line):

- :data:`NOISE_MODES`: the filter's noise adaptation modes (core.filter.ekf.MODES);
- :data:`MASS_INVERSES`: how M^-1 is formed (core.model.hydrodynamics.Model's ``mass_inverse``);
- :data:`FRAMES`: conventions of the incoming Odometry (session.messages, the frame algebra).
"""
import math

import numpy as np

from auv_ident.core.errors import ConfigError
from auv_ident.core.filter.ekf import MODES
from auv_ident.core.identification.selection import AUTO, parse_request
from auv_ident.core.model.state import CURRENT_NAMES, N_STATE, STATE_NAMES
from auv_ident.session.messages import FRAMES
from auv_ident.vehicles import load_vehicle

NOISE_MODES = tuple(MODES)
MASS_INVERSES = ('default', 'exact', 'mss_literal')
NOISE_SOURCES = ('message', 'parameter')   # where R comes from (IdentSession noise_source)

MAX_SAMPLE_TIME = 1.0   # s: one RK4 step of the model over a longer one is not faithful
MAX_SUBSTEPS = 20000    # max_gap / sample_time: the longest bridge of one gap
MAX_BRIDGE_S = 0.25     # s, default max_bridge: longest gap bridged by time updates

__all__ = ['choice', 'coefficient_list', 'coefficient_request', 'FRAMES', 'MASS_INVERSES',
           'MAX_BRIDGE_S', 'MAX_SAMPLE_TIME', 'MAX_SUBSTEPS', 'max_command_age',
           'measured_mask', 'noise_model', 'NOISE_MODES', 'NOISE_SOURCES', 'number',
           'ParameterError', 'positive', 'relative_offset', 'sigmas', 'timing', 'vector',
           'vehicle_named']


class ParameterError(ConfigError):
    """A bad identifier setting; ``name`` is the node parameter (= keyword argument) at fault."""

    def __init__(self, name, message):
        self.name = name
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
        return parse_request(vehicle, ','.join(names))
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
