"""Bags as identification sources: ``identify --bag`` (one bag or several) and the arrays the
batch methods take.

`identify --bag A [--bag B ...]` is one path (:func:`identify_replayed`): the vehicle resolved
once (given, or named by the bags' metadata), every bag replayed through the live identifier's
logic (offline/replay.py), the replays paired into core.identification.results.Record, and the
records identified together by core.identification.pipeline.identify_with_diagnosis; one bag
is a list of one. :func:`identify_bag` and :func:`identify_bags` print and document it.
"""
from dataclasses import dataclass, replace
import time

import numpy as np

from auv_ident.analysis import results as ex
from auv_ident.analysis.report_format import finite_cell
from auv_ident.analysis.results import coefficient_list, Source
from auv_ident.bags.reader import BagError
from auv_ident.core.errors import ConfigError
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.identification.diagnosis import not_consistent
from auv_ident.core.identification.noise_fit import fit_noise
from auv_ident.core.identification.pipeline import identify_with_diagnosis
from auv_ident.core.identification.results import (
    Identification,
    PassEstimate,
    SelectionRequest,
    Start,
)
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import N_CURRENT
from auv_ident.offline.replay import (
    bag_custom_data,
    metadata_settings,
    read_bag_run,
    rejections,
    replay_bag,
)
from auv_ident.session.record import exact_hold
from auv_ident.session.settings import coefficient_request, IdentifierSettings
from auv_ident.session.stuck import describe_spans
from auv_ident.vehicles import load_vehicle

REPLAY_REJECT_LIMIT = 0.02     # a replay rejecting more than this fraction is made again


def _given_map(settings):
    """The input map the bags were read through when the user named one (the model file
    records it, so export and report --model read the same bags the same way), else None (the
    bag's metadata or the default decides again)."""
    return settings.input_map if 'input_map' in settings.given else None


def _simulated(meta):
    """Whether a bag is our simulator's (its custom data say so): its truth is the vehicle
    file's values."""
    return meta.get('auv_ident.simulated') == 'true'


def _meta_truth(meta, model):
    """The model's coefficients as the truth (the vehicle file's values) for a bag our
    simulator wrote (its custom data says so), else None: another program's bag has no
    known truth."""
    return model.theta_true[:model.p_coef] if _simulated(meta) else None


def _bag_current_truth(meta):
    """(3,) the current a simulated bag flew in (zeros: still water), or None if not ours."""
    if not _simulated(meta):
        return None
    try:
        vals = np.array([float(v) for v in meta.get('auv_ident.current', '0 0 0').split()])
    except ValueError:
        return None
    return vals if vals.shape == (N_CURRENT,) else None


def _exact_hold(rr):
    """The Record of a replay for the batch methods: the samples with a command, and the
    command changes between samples as samples without a measurement
    (timing.with_command_changes: the exact zero-order hold the EKF pass followed)."""
    return exact_hold(rr.t, rr.Y, rr.U, rr.t_cmd, rr.U_cmd)


def bags_vehicle(paths, metas, vehicle=None):
    """The vehicle of a bag identification, resolved once: `vehicle` (a Vehicle, a name or a
    YAML path) if given, else the one the bags' metadata name (NPS AUV II when they name none).
    Raises BagError naming the bag when the bags name different vehicles."""
    if vehicle is not None:
        return load_vehicle(vehicle)
    specs = [m.get('auv_ident.vehicle') or 'nps_auv2' for m in metas]
    found = {spec: load_vehicle(spec) for spec in dict.fromkeys(specs)}
    first = found[specs[0]]
    for p, spec in zip(paths, specs):
        if found[spec].name != first.name:
            raise BagError(f"{p}: vehicle {found[spec].name!r}, the other bags' is "
                           f'{first.name!r}: one model needs one vehicle')
    return first


@dataclass
class Replays:
    """The bags replayed as the identifier would have read them (:func:`replay_bags`).

    replays : the ReplayResult of each bag (the last made)
    noise_std : (12,) the configured noise of the identification (the first replays' median)
    again : None, or {'first_rejected', 'first_samples', 'noise_std', 'q_state'} when the
        replays were made again with the noise model from the data
    """

    replays: list
    noise_std: np.ndarray
    again: dict = None

    @property
    def rejected(self):
        return sum(rr.rejected for rr in self.replays)

    @property
    def accepted(self):
        return sum(rr.accepted for rr in self.replays)

    def records(self):
        """The replays as Records (their exact zero-order hold)."""
        return [_exact_hold(rr) for rr in self.replays]


def replay_bags(paths, replay, cfg_of):
    """Replay every bag (replay(path, noise_std, q_state, noise_source) -> ReplayResult); if
    they reject more than REPLAY_REJECT_LIMIT of their odometry (exact repeats, a stuck
    sensor's, not counted: no noise model takes them back; a first pass whose configured
    noise is far too small for the data throws away good samples as outliers), replay them
    again with the noise model read off the accepted samples (core/identification/noise_fit.py:
    the effective measurement noise and, for model error, the matched process noise).

    cfg_of(model, noise) -> FilterConfig of the configured noise. Returns Replays."""
    rrs = [replay(p, None, None, None) for p in paths]
    for p, rr in zip(paths, rrs):
        if rr.accepted < 2:
            raise BagError(f'{p}: only {rr.accepted} odometry samples could be used '
                           f'(rejected: {dict(rr.reasons)})')
    first = Replays(rrs, np.median(np.array([rr.noise_std for rr in rrs]), axis=0))
    total = first.rejected + first.accepted
    # exact repeats (a stuck sensor, session/stuck.py) are rejected whatever the noise
    repeats = sum(rr.reasons.get('odom: repeated', 0) for rr in rrs)
    if first.rejected - repeats <= REPLAY_REJECT_LIMIT * total:
        return first
    model = rrs[0].model
    pre = fit_noise(model, cfg_of(model, first.noise_std), first.records(), T=rrs[0].T)
    again = [replay(p, pre.effective_std, pre.effective_q, 'parameter') for p in paths]
    note = {'first_rejected': int(first.rejected), 'first_samples': int(total),
            'noise_std': [float(x) for x in pre.effective_std],
            'q_state': [float(x) for x in pre.effective_q]}
    return Replays(again, first.noise_std, note)


@dataclass
class BagIdentification:
    """`identify --bag` over one bag or several (:func:`identify_replayed`).

    paths, metas : the bags and their custom data (bag_custom_data)
    replays : Replays (the bags as the identifier read them)
    cfg : FilterConfig of the configured noise the identification started from
    result : the Identification (one coefficient set from all bags)
    auto : whether the coefficients were chosen from the data
    velocity_reference : what the bags' velocities are ('ground' or 'water')
    settings : the IdentifierSettings the replays started from (several bags: current 'none'
        when not given)
    """

    paths: list
    metas: list
    replays: Replays
    cfg: FilterConfig
    result: Identification
    auto: bool
    velocity_reference: str
    settings: IdentifierSettings = None

    @property
    def vehicle(self):
        return self.result.model.vehicle

    @property
    def noise_given(self):
        """Whether the configured noise started from a given noise_std (not the messages')."""
        return 'noise_std' in self.settings.given

    @property
    def q_given(self):
        """Whether the state process noise was given (q_state)."""
        return 'q_state' in self.settings.given


def identify_replayed(paths, settings=None, refine_pass=True, progress=None, together=None):
    """`identify --bag`'s path, for one bag or several (module docstring).

    Each bag is replayed as the identifier would have read it (its accepted measurements, its
    commands held, the noise of its messages; made again with the noise from the data if they
    rejected more than REPLAY_REJECT_LIMIT, see replay_bags); then the noise model from all
    runs' innovations, the EKF pass over the runs in turn, the refinement on all of them with
    the sandwich covariance within each run, identifiability and the diagnosis
    (core.identification.pipeline.identify_with_diagnosis). With one bag and the configured
    noise right, the EKF pass is the replay's (the live node's) and the refinement starts from
    it. Coefficients 'auto[,NAME,...]': the set is chosen from the data
    (core/identification/selection.py), started at the vehicle file.

    settings : IdentifierSettings (None: the defaults), the identifier node's; every one
    applies to the replays, a setting not given coming from each bag's metadata where that
    says it (offline/replay.py bag_settings); the noise model and the refinement take the
    coefficients, initial_offset, the current, velocity_reference and mass_inverse from them.
    Several bags: noise_mode must be 'fixed' (the noise model comes from the data); the
    current is 'none' unless a known one is given (one current per run is not estimated);
    noise_std and q_state, given, are where the configured noise starts instead of the
    messages' (median over the bags). together: the rules of several bags (identify_bags),
    also for one (None: for more than one). Returns a BagIdentification."""
    t0 = time.perf_counter()
    settings = settings or IdentifierSettings()
    several = len(paths) > 1 if together is None else together
    if several:
        settings = _several_bags(settings)
    if 'noise_std' in settings.given and 'noise_source' not in settings.given:
        # a noise_std given is the noise to start from (as for several bags), not a fallback
        # for the messages without covariances
        settings = settings.with_values(noise_source='parameter')
    metas = [bag_custom_data(p) for p in paths]
    v = bags_vehicle(paths, metas, settings.vehicle if 'vehicle' in settings.given else None)
    auto, names = coefficient_request(v, settings.coefficients)
    vrefs = {settings.velocity_reference if 'velocity_reference' in settings.given
             else metadata_settings(m).get('velocity_reference', 'ground') for m in metas}
    if len(vrefs) > 1:
        raise BagError(f'the bags measure their velocity over {" and ".join(sorted(vrefs))}: '
                       'give --velocity-reference')
    vref = vrefs.pop()
    noise_given, q_given = 'noise_std' in settings.given, 'q_state' in settings.given
    initial_offset = settings.initial_offset
    # replay_bag fills in what each bag's metadata says under these settings

    def replay(path, noise, q, source):
        # the vehicle resolved once, by its file (a YAML path stays that file)
        changes = {'vehicle': v.path, 'coefficients': names, 'velocity_reference': vref}
        if several:
            changes['noise_source'] = source or ('parameter' if noise_given
                                                 else settings.noise_source)
        elif source is not None:
            changes['noise_source'] = source
        for name, value in (('noise_std', noise), ('q_state', q)):
            if value is not None:
                changes[name] = value
        return replay_bag(path, settings.with_values(**changes))

    def cfg_of(model, noise):
        cfg = ex.make_config(model.theta_names[:model.p_coef], noise_mode='fixed',
                             noise_std=noise, initial_offset=initial_offset)
        if q_given:
            cfg.q_state = np.asarray(settings.q_state, dtype=float)
        return cfg

    replays = replay_bags(paths, replay, cfg_of)
    first = replays.replays[0]
    model = first.model         # the replay's (a YAML path stays that file)
    cfg = cfg_of(model, replays.noise_std)
    if auto:
        # the replays only paired the samples (their EKF passes identified the named or
        # default set); the coefficients come from the data, started at the file
        def make_model(coefs):
            return Model(model.vehicle, list(coefs) + list(model.current_names),
                         mass_inverse=model.mass_inverse, current=model.current,
                         velocity_reference=model.velocity_reference)
        res = identify_with_diagnosis(None, cfg, replays.records(), T=first.T,
                                      refine_pass=refine_pass, progress=progress,
                                      auto=SelectionRequest(make_model, tuple(names)),
                                      judge_nis=None)
    else:
        # one bag with the configured noise right: the replay's EKF pass (the live node's) is
        # kept; several bags were replayed each on its own, not in turn
        kept = (PassEstimate(first.estimate, first.cov)
                if len(paths) == 1 and replays.again is None else None)
        # the user's start (--initial, a warm start) is where the identification starts, as
        # the replay did; its noise model is read off a pass from the file's values + offset
        start = (Start(first.initial[:model.p_coef], first.theta_cov0)
                 if settings.initial or settings.warm_start else None)
        res = identify_with_diagnosis(model, cfg, replays.records(), T=first.T,
                                      refine_pass=refine_pass, progress=progress,
                                      ekf_pass=kept, judge_nis='reported', start=start)
    res = replace(res, truth=(res.model.theta_true[:res.model.p_coef]
                              if all(_simulated(m) for m in metas) else None),
                  initial=_initial(res, first), steps=replays.accepted,
                  mean_nis_per_dof=_mean_nis(res, replays, auto),
                  wall_s=time.perf_counter() - t0)
    if replays.again is not None:
        res.diagnosis.messages.append(_replayed_note(replays.again, replays.rejected))
    res = replace(res, diagnosis=not_consistent(res.diagnosis, stuck_problems(paths, replays),
                                                'stuck_sensor'))
    return BagIdentification(paths=list(paths), metas=metas, replays=replays, cfg=cfg,
                             result=res, auto=auto, velocity_reference=vref, settings=settings)


def stuck_problems(paths, replays):
    """One clause per bag whose replay found a stuck sensor (session/stuck.py): its channel
    groups and spans (the bag named when there are several). Such a result is NOT consistent
    (module docstring of session/stuck.py): the spans were not fed to the filter, but a sensor
    that froze, or that a driver never filled, is a fault of the data to look at before the
    estimate is used."""
    out = []
    for path, rr in zip(paths, replays.replays):
        if rr.stuck:
            where = f'{path}: ' if len(paths) > 1 else ''
            out.append(f'{where}odometry {describe_spans(rr.stuck)}: a stuck sensor, or a field '
                       'the driver never fills; those samples were not fed to the filter. Check '
                       'the sensor, or leave the channels out (--measured)')
    return out


def _several_bags(settings):
    """The settings of several bags identified together: the noise mode fixed (the noise
    model comes from the data), the current 'none' unless a known one is given (one current
    per run is not estimated); ConfigError/BagError naming the setting otherwise."""
    if settings.noise_mode != 'fixed':
        raise ConfigError('several bags are identified with the fixed noise of their messages '
                          'and the noise model from the data: --noise-mode applies to one bag')
    if 'current' not in settings.given:
        settings = settings.with_values(current='none')
    if settings.current_option.estimate:
        raise BagError('several bags: give the current as none or a known N,E[,D] (m/s); one '
                       'current per run is not estimated')
    return settings


def _initial(res, first):
    """The coefficients' start: the vehicle file's values of a chosen set, else the replay's
    initial guesses."""
    if res.selection is not None:
        v = res.model.vehicle
        return np.array([v.values[v.index(n)] for n in res.selection.chosen])
    return first.initial[:res.model.p_coef]


def _mean_nis(res, replays, auto):
    """The mean NIS/dof reported: with one bag the replay's (what the live node showed); with
    several, or for a chosen set (the replays' filters identified another set), the reported
    EKF pass's."""
    if len(replays.replays) == 1 and not auto:
        return replays.replays[0].mean_nis_per_dof
    return res.noise.reported_pass.mean_nis_per_dof


def _start_line(settings):
    """Where the coefficients start, as the settings say: the guesses given (--initial), a
    warm start's estimate, or the vehicle file's values offset by initial_offset."""
    if settings.initial:
        return 'initial guesses as given (--initial)'
    if settings.warm_start:
        return f'initial guesses from the warm start {settings.warm_start}'
    return f'initial guesses {100 * settings.initial_offset:+.0f} % from the vehicle file'


def identify_bag(path, settings=None, refine_pass=True, progress=None):
    """`identify --bag`: the live identifier's EKF pass over the bag (replay_bag, made again
    with the noise from the data if it rejected more than REPLAY_REJECT_LIMIT), then the noise
    model, the batch refinement on the paired arrays at their stamps, identifiability and the
    diagnosis; with coefficients ['auto', NAME, ...] the set is chosen from the data
    (core/identification/selection.py). :func:`identify_replayed` of one bag. Returns (JSON
    document, printable table).

    settings : IdentifierSettings (None: the defaults), the identifier node's: every one
        applies to the replay (a setting not given comes from the bag's metadata where that
        says it: offline/replay.py bag_settings); with mass_inverse 'exact' the added-mass
        coefficients can be identified, and auto may choose them"""
    b = identify_replayed([path], settings, refine_pass=refine_pass, progress=progress)
    settings = b.settings
    res, rr, meta = b.result, b.replays.replays[0], b.metas[0]
    v, diagnosis, selection = b.vehicle, res.diagnosis, res.selection
    head = (f'{v.title}: identified {", ".join(res.names)} from bag {path} '
            f'({rr.accepted} odometry samples used, {rr.rejected} rejected, {rr.commands} '
            f'actuator commands; frame {rr.frame})')
    if _simulated(meta):
        head += (f'\nsimulated by auv_ident: manoeuvre {meta.get("auv_ident.maneuver")!r}, seed '
                 f'{meta.get("auv_ident.seed")}; truth = the vehicle file values')
    start = ('automatic selection, initial guesses at the vehicle file' if b.auto else
             _start_line(settings))
    head += (f'\n{start}; noise '
             f'adaptation: {settings.noise_mode}; '
             + ('EKF pass + batch refinement (filter-error ML)' if refine_pass
                else 'EKF pass only'))
    over = ('ground (DVL bottom lock)' if b.velocity_reference == 'ground'
            else 'water (water-track DVL)')
    head += (f'\nwater current: {settings.current_option.describe()}; velocity '
             f'over {over}')
    doc = ex.result_dict(v, res, {'bag': str(path), 'rejected': rr.rejected,
                                  'input_map': _given_map(settings),
                                  'noise_mode': settings.noise_mode,
                                  'noise_source': settings.noise_source,
                                  'mass_inverse': res.model.mass_inverse,
                                  'noise_std': [float(x) for x in b.replays.noise_std],
                                  'time_origin_ns': rr.time_origin_ns,
                                  'noise_model': res.noise.document(),
                                  'diagnosis': diagnosis.document(),
                                  'identifiability': diagnosis.identifiability,
                                  'rejection_reasons': dict(rr.reasons),
                                  'replayed_with_noise_model': b.replays.again,
                                  # a fault still active when the bag ends: the final
                                  # estimate was formed while it was ('' for none)
                                  'stuck_at_end': describe_spans(
                                      [s for s in rr.stuck if s.active]),
                                  'selection': None if selection is None
                                  else selection.document()},
                         current_truth=_bag_current_truth(meta))
    head = diagnosis.messages[0] + '\n' + head
    table = (head + '\n' + ex.result_table(v, res, doc) + f'\n{res.steps} EKF steps, mean '
             f'NIS/dof {finite_cell(res.mean_nis_per_dof, ".3f")}, wall {res.wall_s:.2f} s'
             + ''.join('\n- ' + m for m in diagnosis.messages[1:])
             + ('' if selection is None else '\n' + '\n'.join(selection.summary())))
    return doc, table


# what the replay that pairs a bag's arrays for the batch methods takes (bag_source)
PAIRING_SETTINGS = frozenset({'vehicle', 'coefficients', 'noise_std', 'q_state',
                              'velocity_reference', 'mass_inverse', 'other_vehicle',
                              'input_map'})


def bag_source(path, settings=None, filtering=True):
    """experiments.Source of a bag: the paired arrays (U[k] = command in force from t_k on, the
    command changes between samples inserted as rows without a measurement). The replay that
    pairs them takes the PAIRING_SETTINGS of `settings` (IdentifierSettings; None: the
    defaults, and the bag's metadata: offline/replay.py bag_settings), the identifier's
    defaults for the rest: it estimates the current (so that its innovation gate judges samples
    with it); the caller's model says what to do with the current. noise_std, q_state given:
    the measurement and per-step state process noise 1-sigma the replay's gate judges samples
    with (noise_source then 'parameter'; a real run needs the noise its identification used,
    docs/kvlcc2.md, or the gate rejects its samples). mass_inverse: the replay model's M^-1,
    which the Source's vehicle then says (Vehicle.with_mass_inverse), so that every Model made
    of it forms M^-1 so. filtering False (a validation's measured run): the messages are
    screened and paired by stamp without the filter (offline/replay.py read_bag_run), every
    well-formed sample kept whatever a model says of it; the Source's `screening` then says
    what was dropped (replay.rejections), and the noise settings do not matter."""
    settings = settings or IdentifierSettings()
    given = {n: getattr(settings, n) for n in settings.given & PAIRING_SETTINGS}
    if 'noise_std' in given:
        given['noise_source'] = 'parameter'
    meta = bag_custom_data(path)
    rr = (replay_bag if filtering else read_bag_run)(path,
                                                     IdentifierSettings.from_values(**given))
    vr = rr.model.velocity_reference
    # the replay's vehicle (a YAML path stays that file), forming M^-1 as the replay did
    v = rr.model.vehicle.with_mass_inverse(rr.model.mass_inverse)
    names = coefficient_list(v, ','.join(rr.model.theta_names[:rr.model.p_coef]))
    truth = _meta_truth(meta, Model(v, names))
    rec = _exact_hold(rr)
    return Source(vehicle=v, names=names, t=rec.t, Y=rec.Y, U=rec.U, T=rr.T,
                  noise_std=rr.noise_std, description=f'bag {path} ({rr.accepted} samples)',
                  truth=truth, seed=meta.get('auv_ident.seed'),
                  maneuver=meta.get('auv_ident.maneuver', ''),
                  current_truth=_bag_current_truth(meta), velocity_reference=vr,
                  time_origin_ns=rr.time_origin_ns,
                  screening=None if filtering else rejections(rr))


def identify_bags(paths, settings=None, refine_pass=True, progress=None):
    """`identify --bag A --bag B ...`: one coefficient set from several bags of one vehicle,
    :func:`identify_replayed` over all of them (each bag from its own initial state, the noise
    model from all runs' innovations, the EKF pass over the runs in turn, the refinement on all
    of them with the sandwich covariance within each run; identifiability and the diagnosis
    printed first, and in the JSON as identify_bag's).

    settings : IdentifierSettings (None: the defaults), as identify_bag's, except: noise_std,
        q_state given: the measurement and per-step state process noise 1-sigma to start from
        instead of the messages' (median over the bags) and the default (the noise model from
        the data still applies); current not given: 'none' (still water), else a known current
        'N,E[,D]' in m/s that all runs flew in; noise_mode 'fixed'.
    Returns (JSON document, printable table)."""
    b = identify_replayed(paths, settings, refine_pass=refine_pass, progress=progress,
                          together=True)
    settings = b.settings
    res, v, fit = b.result, b.vehicle, b.result.noise
    rejected = b.replays.rejected
    doc = ex.result_dict(v, res, {'bags': [str(p) for p in paths], 'rejected': rejected,
                                  'input_map': _given_map(settings),
                                  'noise_mode': 'fixed',
                                  'noise_source': settings.noise_source,
                                  'mass_inverse': res.model.mass_inverse,
                                  'noise_std': [float(x) for x in b.replays.noise_std],
                                  'q_state': [float(x) for x in b.cfg.q_state],
                                  'replayed_with_noise_model': b.replays.again,
                                  'rejection_reasons': _reasons(b.replays.replays),
                                  **({} if res.selection is None
                                     else {'selection': res.selection.document()})},
                         current_truth=_common([_bag_current_truth(m) for m in b.metas]))
    head = (f'{v.title}: identified {", ".join(res.names)} from {len(paths)} bags together '
            f'({", ".join(str(p) for p in paths)}; {res.steps} samples, {rejected} rejected)'
            f'\n{_start_line(settings)}; '
            'configured noise ' + ('as given' if b.noise_given
                                   else "the messages' (median over the bags)")
            + (', state process noise as given' if b.q_given else '')
            + ', then the noise model from the data; '
            + ('EKF pass over the runs in turn + batch refinement on all of them'
               if refine_pass else 'EKF pass over the runs in turn')
            + f'\nwater current: {settings.current_option.describe()}')
    messages = res.diagnosis.messages
    head = messages[0] + '\n' + head
    table = (head + '\n' + ex.result_table(v, res, doc) + f'\n{res.steps} EKF steps, mean '
             f'NIS/dof {res.mean_nis_per_dof:.3f} (the reported EKF pass; with the configured '
             f'noise {fit.configured_pass.mean_nis_per_dof:.4g})'
             + (f', refined cost per residual {fit.refine_cost:.3f}' if refine_pass else '')
             + f', wall {res.wall_s:.2f} s'
             + ''.join('\n- ' + m for m in messages[1:])
             + ('' if res.selection is None else '\n' + '\n'.join(res.selection.summary())))
    return doc, table


def _replayed_note(again, rejected):
    return (f'the replay with the configured noise rejected {again["first_rejected"]} of '
            f'{again["first_samples"]} odometry samples as outliers (more than '
            f'{100 * REPLAY_REJECT_LIMIT:g} %): replayed with the noise model read off the '
            f'accepted samples; {rejected} rejected then')


def _common(values):
    """The value all bags agree on (arrays), else None."""
    if any(x is None for x in values) or any(not np.array_equal(x, values[0]) for x in values):
        return None
    return values[0]


def _reasons(rrs):
    """The rejection reasons of several replays, summed."""
    out = {}
    for rr in rrs:
        for k, n in rr.reasons.items():
            out[k] = out.get(k, 0) + int(n)
    return out
