"""Bag replay: a recorded bag through the identifier's per-message logic, offline.

The identifier node and :func:`replay_bag` both drive one
:class:`auv_ident.session.session.IdentSession` with the messages in arrival (log-time) order,
so the same message sequence gives identical estimates online and offline.
"""
from collections import Counter
from dataclasses import dataclass, field
import logging
import os
from pathlib import Path

import numpy as np

from auv_ident.bags.reader import bag_topics, BagError, read_bag
from auv_ident.bags.schema import custom_data_of, read_metadata
from auv_ident.core.model.state import N_STATE
from auv_ident.session.estimate_file import estimate_document
from auv_ident.session.input_map import input_maps_dir, InputMapError
from auv_ident.session.record import median_noise_std, paired, UpdateLog
from auv_ident.session.session import Health, IdentSession
from auv_ident.session.settings import IdentifierSettings, ParameterError, vehicle_named

log = logging.getLogger('auv_ident.replay')

@dataclass
class ReplayResult:
    """Identification over a bag.

    names : parameter names (coefficients, then any estimated current components);
        vehicle, frame : what was used
    updates : session.record.UpdateLog of (stamp_ns, estimate (p,), std (p,)), one per
        accepted odometry update
    estimate, std, cov : final (last good) estimate, 1-sigma, covariance (p,), (p,), (p, p)
    initial : the initial guesses; truth : the vehicle file's values (the truth of a simulated
        bag)
    accepted, rejected : odometry messages fused / dropped; commands : actuator messages
        buffered; errors : core errors (each restarted the filter); reasons : Counter of
        rejection reasons
    t, Y, U : (N,), (N, 12), (N, 7) of the accepted measurements (NaN: unmeasured channel) and
        U[k] = the command in force at t[k] (latest stamp <= t[k]), for identify.refine
    mean_nis_per_dof : over the last NIS window; health : the node's health verdict at the end
    noise_std : (12,) the measurement 1-sigma the EKF pass used, per channel (the median over
        the accepted updates: the message covariances with noise_source 'message')
    time_origin_ns : t = 0 of t and of the session's time line (int ns; 0 for stamps that
        start near 0)
    t_cmd, U_cmd : (M,), (M, 7) the accepted commands by stamp (a later message with the same
        stamp wins), on the same time line
    """

    names: list
    vehicle: str
    frame: str
    updates: UpdateLog
    estimate: np.ndarray
    std: np.ndarray
    cov: np.ndarray
    initial: np.ndarray
    truth: np.ndarray
    accepted: int
    rejected: int
    commands: int
    errors: int
    reasons: Counter
    t: np.ndarray
    Y: np.ndarray
    U: np.ndarray
    mean_nis_per_dof: float
    health: Health
    T: float = 0.05
    settings: dict = field(default_factory=dict)
    noise_std: np.ndarray = None
    time_origin_ns: int = 0
    t_cmd: np.ndarray = None
    U_cmd: np.ndarray = None
    # the session's core.model.hydrodynamics.Model (coefficients, then current)
    model: object = None
    # the stuck-sensor faults of the replay (session/stuck.py StuckSpan; their samples were
    # not fed)
    stuck: list = field(default_factory=list)
    # (p_coef, p_coef) the warm start's coefficient covariance, None without one
    theta_cov0: np.ndarray | None = None

    def document(self, stamp_ns=None):
        """The estimate file's dict of the final estimate."""
        if stamp_ns is None and self.updates:
            stamp_ns = self.updates[-1][0]
        return estimate_document(self.vehicle, self.names, self.estimate, self.cov, stamp_ns,
                                 self.accepted)

def bag_custom_data(path):
    """metadata.yaml's custom_data of a bag directory ({} if absent or unreadable)."""
    if not Path(path).is_dir():
        return {}
    try:
        info = read_metadata(path)
        return {} if info is None else custom_data_of(info)
    except BagError:
        return {}   # reading the bag's messages says what is wrong with it

class ReplayWarnings:
    """Offline counterpart of WarningLimiter: logs (logger 'auv_ident.replay', WARNING) the
    first `first` rejections/errors of each key (topic, code), then only counts them;
    :meth:`summary` logs one line per key with more."""

    def __init__(self, first=3, logger=None):
        self.first = first
        self.log = logger or log
        self.counts = Counter()

    def __call__(self, ev):
        key = (ev.reason.split(':', 1)[0], ev.code)
        self.counts[key] += 1
        n = self.counts[key]
        if n <= self.first:
            self.log.warning('%s %s' % ('rejected' if ev.kind == 'rejected' else 'filter reset:',
                                        ev.reason)
                             + (f' [first {self.first} of this kind logged]'
                                if n == self.first else ''))

    def summary(self):
        for (topic, code), n in sorted(self.counts.items()):
            if n > self.first:
                self.log.warning(f'{topic}: {n} messages in all with problem {code!r} '
                                 f'({n - self.first} not logged)')

def replay_messages(messages, session, warn=None):
    """Drive an IdentSession with (topic, t_ns, msg) in the given order: each topic of the
    session's input map (session/input_map.py; a relative map topic is the bag's '/' + it) to
    its input, the log time t_ns the stamp of a message without a header; other topics
    ignored.

    warn : None or a callable taking every 'rejected' / 'error' Event (e.g. ReplayWarnings)
    Returns the UpdateLog (session/record.py) of (stamp_ns, estimate, std) of the accepted
    updates (with coefficients ['auto', ...] their length changes once, at the switch). The
    session's one-time notices (e.g. message covariances not usable) are logged as warnings,
    what an 'auto' choice says as info (an error if it failed)."""
    updates = UpdateLog()
    names = {e.bag_topic: e.name for e in session.input_map.inputs}
    for topic, t_ns, msg in messages:
        name = names.get(topic)
        if name is None:
            continue
        ev = session.on_input(name, msg, t_ns)
        if ev.kind == 'update':
            updates.append(ev.stamp_ns, ev.estimate, ev.std)
        if warn is not None and ev.kind in ('rejected', 'error'):
            warn(ev)
        if session.notices:
            for text in session.notices:
                log.warning(text)
            session.notices.clear()
        if session.noise.news:      # what the noise learning found
            for text in session.noise.news:
                log.info(text)
            session.noise.news.clear()
        if session.auto is not None and session.auto.news:   # coefficients ['auto', ...]
            _log_choice_news(session.auto)
    return updates


def _log_choice_news(auto):
    for level, text in auto.news:
        (log.error if level == 'error' else log.info)(text)
    auto.news.clear()

def session_result(session, updates, settings=None):
    """Pack a finished session into a ReplayResult (arrays aligned by the pairing rule)."""
    t, Y, U, t_cmd, U_cmd = paired(session.commands.array, session.measurements.array)
    est, cov = session.best()
    counters = session.counters
    return ReplayResult(
        names=list(session.names), vehicle=session.vehicle.name, frame=session.frame,
        updates=updates, estimate=est, std=np.sqrt(np.diag(cov)), cov=cov,
        initial=session.theta0.copy(), truth=session.model.theta_file,
        accepted=counters.odom_accepted, rejected=counters.odom_rejected,
        commands=counters.cmd_accepted, errors=counters.errors, reasons=counters.reasons,
        t=t, Y=Y, U=U, mean_nis_per_dof=session.filter.mean_nis_per_dof(),
        health=session.health(),
        T=session.T, settings=dict(settings or {}),
        noise_std=median_noise_std(session.variances.array, session.noise_default),
        time_origin_ns=int(session.time_origin_ns or 0),
        t_cmd=t_cmd, U_cmd=U_cmd, model=session.model, stuck=list(session.stuck.spans),
        theta_cov0=None if session.warm_cov is None else np.array(session.warm_cov))

def bag_settings(path):
    """Raw identifier settings a bag's metadata custom_data carries (bag_custom_data): the
    vehicle, frame and input map ('auv_ident.vehicle', 'auv_ident.frame',
    'auv_ident.input_map' when it names a map of config/inputs/: a thruster vehicle's), the
    velocity reference and the
    sensor noise 1-sigma of a bag our simulator wrote ('auv_ident.velocity_reference',
    'auv_ident.noise_std': 12 positive numbers, else not taken). The defaults under what a
    caller gives (IdentifierSettings.over)."""
    return metadata_settings(bag_custom_data(path))


def metadata_settings(meta):
    """bag_settings of custom data already read (bag_custom_data)."""
    raw = {name: meta[key] for name, key in (('vehicle', 'auv_ident.vehicle'),
                                             ('frame', 'auv_ident.frame'),
                                             ('velocity_reference',
                                              'auv_ident.velocity_reference'))
           if meta.get(key)}
    try:
        noise = np.array([float(v) for v in meta.get('auv_ident.noise_std', '').split()])
    except ValueError:
        noise = np.zeros(0)
    if noise.shape == (N_STATE,) and np.all(noise > 0):
        raw['noise_std'] = noise
    shipped = meta.get('auv_ident.input_map', '')
    if shipped and os.path.sep not in shipped and not shipped.endswith(('.yaml', '.yml')) \
            and os.path.isfile(os.path.join(input_maps_dir(), shipped + '.yaml')):
        # a map shipped in config/inputs/ (a thruster vehicle's bag of our simulator); a
        # path an import recorded may not exist here: the user gives it
        raw['input_map'] = shipped
    return raw


def settings_for_bag(settings, path, meta=None):
    """`settings` with what the bag's metadata records (:func:`bag_settings`) for what they
    were not given. A bag that records its vehicle and is given another one is a BagError
    naming both, unless ``settings.other_vehicle`` (a renamed or corrected file of the same
    vehicle): a wrong vehicle file otherwise fits confidently wrong coefficients."""
    recorded = metadata_settings(bag_custom_data(path) if meta is None else meta)
    bag_vehicle = recorded.get('vehicle')
    if (bag_vehicle and 'vehicle' in settings.given and not settings.other_vehicle
            and not _same_vehicle(settings.vehicle, bag_vehicle)):
        given = vehicle_named(settings.vehicle)
        raise BagError(f'{path}: the bag records vehicle {bag_vehicle!r}, the identification '
                       f'was given vehicle {given.name!r} ({given.path}); leave the vehicle '
                       "out to use the bag's, or say --other-vehicle if this file is meant "
                       'for it')
    return settings.over(recorded)


def _same_vehicle(given, recorded):
    """Whether a vehicle setting (name or YAML path) names the vehicle a bag records (a name,
    or the path of the file the bag was made with), compared by the files' vehicle names."""
    if given == recorded:
        return True
    try:
        return vehicle_named(given).name == vehicle_named(recorded).name
    except ParameterError:
        # the recorded file is not on this machine: its file name stands for its vehicle
        return Path(str(recorded)).stem == vehicle_named(given).name


class BagInputError(BagError, InputMapError):
    """The bag does not hold what the input map names (a topic, or its type)."""


def replay_bag(path, settings=None, allow_truncated=False, warn=True, filtering=True):
    """Identify from a bag exactly as the identifier node would have live.

    The input map's topics (the ``input_map`` setting, session/input_map.py; default: the
    Odometry on /odom and the JointState on /actuators) are read in log-time order (as
    recorded) and fed to an IdentSession in that order.

    Parameters
    ----------
    path : bag directory or .mcap file
    settings : IdentifierSettings (None: the defaults); a setting it was not given
        (IdentifierSettings.given) comes from the bag's metadata where that says it
        (:func:`bag_settings`: vehicle, frame, velocity_reference, noise_std)
    allow_truncated : read the complete chunks of a bag whose writer died (bags.reader.read_bag);
        default: such a bag is a BagError naming the option
    warn : log rejected messages and filter resets (ReplayWarnings: the first 3 of each kind,
        then a count), or False
    filtering : False: the messages screened and paired by stamp without the filter (no
        innovation gate, no resets: IdentSession's filtering), nothing logged per message;
        :func:`read_bag_run`

    Returns a ReplayResult (its `settings`: the settings used, as a dict). Raises BagError for
    an unreadable bag (empty, truncated, corrupted, not an MCAP bag), BagInputError (a
    BagError and an InputMapError) for a topic of the map the bag lacks or records with
    another type, ParameterError for a bad setting, InputMapError for a bad map; nothing else
    for bad input.
    """
    present = bag_topics(path, allow_truncated=allow_truncated)
    settings = settings_for_bag(settings or IdentifierSettings(), path)
    session = IdentSession(settings, keep_arrays=True, filtering=filtering)
    try:
        session.input_map.check_topics(present, path)
    except InputMapError as err:
        raise BagInputError(str(err)) from None
    msgs = read_bag(path, session.input_map.topic_types, allow_truncated=allow_truncated)
    warner = ReplayWarnings() if warn and filtering else None
    try:
        updates = replay_messages(msgs, session, warn=warner)
        if session.poll_choice():   # an 'auto' window that filled with the last message
            _log_choice_news(session.auto)
    finally:
        if warner is not None:
            warner.summary()
    return session_result(session, updates, settings.as_dict())


def read_bag_run(path, settings=None, **kwargs):
    """A bag's measured run as the data are, for a validation: :func:`replay_bag` with
    filtering False. Every odometry message that passes the screening of malformed messages
    (session/screening.py: unreadable, wrong or changed frame ids, non-finite, implausible;
    and a repeated stamp) is kept and paired with the command in force at its stamp
    (session/record.py paired); no innovation gate judges the samples against a model, so a
    model under test cannot thin out the run it is judged on (the topics: the settings'
    input_map). kwargs: replay_bag's allow_truncated. Returns a ReplayResult (its estimate
    the prior: nothing was filtered; :func:`rejections` says what was dropped)."""
    return replay_bag(path, settings, warn=False, filtering=False, **kwargs)


def rejections(rr):
    """What a replay dropped, as a dict (JSON-ready) and one line: {'odometry': messages read,
    'rejected': of them dropped, 'without_command': kept but before the first command (not
    paired), 'commands': read, 'commands_rejected', 'reasons': {'<topic>: <code>': n}} and
    e.g. '0 of 3601 odometry messages and 0 of 3601 commands rejected' or '... (odom:
    duplicate stamp 1, odom: non-finite 2)'."""
    n_odom = int(rr.accepted + rr.rejected)
    n_cmd_bad = int(sum(n for k, n in rr.reasons.items() if k.startswith('actuators:')))
    no_cmd = int(np.sum(~np.all(np.isfinite(rr.U), axis=1))) if len(rr.t) else 0
    doc = {'odometry': n_odom, 'rejected': int(rr.rejected), 'without_command': no_cmd,
           'commands': int(rr.commands + n_cmd_bad), 'commands_rejected': n_cmd_bad,
           'reasons': {k: int(n) for k, n in sorted(rr.reasons.items())}}
    why = ', '.join(f'{k} {n}' for k, n in doc['reasons'].items())
    line = (f'{doc["rejected"]} of {n_odom} odometry messages and {n_cmd_bad} of '
            f'{doc["commands"]} commands rejected' + (f' ({why})' if why else '')
            + (f'; {no_cmd} samples before the first command not paired' if no_cmd else ''))
    return doc, line
