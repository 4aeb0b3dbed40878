"""Bags as identification sources: ``identify --bag`` and the arrays the batch methods take."""
import time

import numpy as np

from auv_ident.analysis import results as ex
from auv_ident.analysis.identification import diagnosed, identify_records
from auv_ident.analysis.results import coefficient_list, Source
from auv_ident.bags.reader import BagError
from auv_ident.core.errors import ConfigError
from auv_ident.core.identification.batch import Result
from auv_ident.core.identification.noise_fit import fit_noise_runs
from auv_ident.core.identification.selection import identify_auto
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import N_CURRENT
from auv_ident.offline.replay import bag_custom_data, bag_settings, replay_bag
from auv_ident.session.record import exact_hold
from auv_ident.session.settings import coefficient_request, IdentifierSettings
from auv_ident.vehicles import load_vehicle


def _meta_truth(meta, model):
    """The model's coefficients as the truth (the vehicle file's values) for a bag our
    simulator wrote (its custom data says so), else None: another program's bag has no
    known truth."""
    return model.theta_true[:model.p_coef] if meta.get('auv_ident.simulated') == 'true' else None


def _bag_current_truth(meta):
    """(3,) the current a simulated bag flew in (zeros: still water), or None if not ours."""
    if meta.get('auv_ident.simulated') != 'true':
        return None
    try:
        vals = np.array([float(v) for v in meta.get('auv_ident.current', '0 0 0').split()])
    except ValueError:
        return None
    return vals if vals.shape == (N_CURRENT,) else None


def _exact_hold(rr):
    """(t, Y, U) of a replay for the batch methods: the samples with a command, and the
    command changes between them as samples without a measurement (timing.with_command_changes:
    the exact zero-order hold the EKF pass followed)."""
    return exact_hold(rr.t, rr.Y, rr.U, rr.t_cmd, rr.U_cmd)


def identify_bag(path, settings=None, refine_pass=True, progress=None):
    """`identify --bag`: the live identifier's EKF pass over the bag (replay_bag, made again
    with the noise from the data if it rejected more than REPLAY_REJECT_LIMIT), then the noise
    model, the batch refinement on the paired arrays at their stamps, identifiability and the
    diagnosis; with coefficients ['auto', NAME, ...] the set is chosen from the data
    (core/identification/selection.py). Returns (JSON document, printable table).

    settings : IdentifierSettings (None: the defaults), the identifier node's: every one
        applies to the replay (a setting not given comes from the bag's metadata where that
        says it: offline/replay.py bag_settings); the noise model and the refinement that
        follow take the coefficients, initial_offset, the current, velocity_reference and
        mass_inverse from them (with mass_inverse 'exact' the added-mass coefficients can be
        identified, and auto may choose them)"""
    t0 = time.perf_counter()
    meta = bag_custom_data(path)
    settings = (settings or IdentifierSettings()).over(bag_settings(path))
    auto, names = coefficient_request(load_vehicle(settings.vehicle), settings.coefficients)
    initial_offset = settings.initial_offset

    def replay(p, noise, q, source):
        changes = {'coefficients': names}
        for name, value in (('noise_std', noise), ('q_state', q), ('noise_source', source)):
            if value is not None:
                changes[name] = value
        return replay_bag(p, settings.with_values(**changes))

    def cfg_of(model, noise):
        return ex.make_config(model.theta_names[:model.p_coef], noise_mode='fixed',
                              noise_std=noise, initial_offset=initial_offset)

    (rr,), noise, again = _replays([path], replay, cfg_of)
    v = rr.model.vehicle      # the replay's (a YAML path stays that file)
    model = rr.model
    truth = _meta_truth(meta, model)
    rec = _exact_hold(rr)
    selection = None
    initial = rr.initial[:model.p_coef]
    mean_nis = rr.mean_nis_per_dof
    if auto:
        # the replay only paired the samples (its EKF pass identified the named or default
        # set); the coefficients come from the data (core/identification/selection.py), started at
        # the file
        def make_model(coefs):
            return Model(v, list(coefs) + list(rr.model.current_names),
                         mass_inverse=rr.model.mass_inverse, current=rr.model.current,
                         velocity_reference=rr.model.velocity_reference)
        t, Y, U = rec
        model, ekf_est, ekf_cov, est, cov, fit, selection = identify_auto(
            make_model, cfg_of(model, noise), t, Y, U, named=names, T=rr.T,
            refine_pass=refine_pass, progress=progress)
        truth = (model.theta_true[:model.p_coef]
                 if meta.get('auv_ident.simulated') == 'true' else None)
        initial = np.array([v.values[v.index(n)] for n in selection.chosen])
        mean_nis = float('nan')     # the replay's filter identified another set
        est_c, cov_c, ekf_c, ekf_cov_c, cur, verdicts, diagnosis = diagnosed(
            model, [rec], rr.T, fit, ekf_est, ekf_cov, est, cov, mean_nis, refine_pass)
    else:
        # the noise model from the data (core/identification/noise_fit.py): with the configured
        # noise right, the EKF pass is the replay's (the live node's) and the refinement starts
        # from it
        est_c, cov_c, ekf_c, ekf_cov_c, cur, verdicts, diagnosis, fit = identify_records(
            model, cfg_of(model, noise), [rec], rr.T, refine_pass, progress,
            ekf_pass=None if again else (rr.estimate, rr.cov))
    res = Result(names=model.theta_names[:model.p_coef], estimate=est_c,
                 std=np.sqrt(np.diag(cov_c)), cov=cov_c, ekf_estimate=ekf_c,
                 ekf_std=np.sqrt(np.diag(ekf_cov_c)), initial=initial,
                 truth=truth, steps=rr.accepted, wall_s=time.perf_counter() - t0,
                 mean_nis_per_dof=mean_nis, refined=refine_pass, current=cur)
    if again is not None:
        diagnosis['messages'].append(_replayed_note(again, rr.rejected))
    head = (f'{v.title}: identified {", ".join(res.names)} from bag {path} '
            f'({rr.accepted} odometry samples used, {rr.rejected} rejected, {rr.commands} '
            f'actuator commands; frame {rr.frame})')
    if meta.get('auv_ident.simulated') == 'true':
        head += (f'\nsimulated by auv_ident: manoeuvre {meta.get("auv_ident.maneuver")!r}, seed '
                 f'{meta.get("auv_ident.seed")}; truth = the vehicle file values')
    start = ('automatic selection, initial guesses at the vehicle file' if auto else
             f'initial guesses {100 * initial_offset:+.0f} % from the vehicle file')
    head += (f'\n{start}; noise '
             f'adaptation: {settings.noise_mode}; '
             + ('EKF pass + batch refinement (filter-error ML)' if refine_pass
                else 'EKF pass only'))
    over = ('ground (DVL bottom lock)' if settings.velocity_reference == 'ground'
            else 'water (water-track DVL)')
    head += (f'\nwater current: {settings.current_option.describe()}; velocity '
             f'over {over}')
    doc = ex.result_dict(v, res, {'bag': str(path), 'rejected': rr.rejected,
                                  'noise_mode': settings.noise_mode,
                                  'noise_source': settings.noise_source,
                                  'mass_inverse': model.mass_inverse,
                                  'noise_std': [float(x) for x in noise],
                                  'time_origin_ns': rr.time_origin_ns,
                                  'noise_model': fit.document(),
                                  'diagnosis': diagnosis, 'identifiability': verdicts,
                                  'rejection_reasons': dict(rr.reasons),
                                  'replayed_with_noise_model': again,
                                  'selection': None if selection is None
                                  else selection.document()},
                         current_truth=_bag_current_truth(meta))
    head = diagnosis['messages'][0] + '\n' + head
    table = (head + '\n' + ex.result_table(v, res, doc) + f'\n{res.steps} EKF steps, mean '
             f'NIS/dof {res.mean_nis_per_dof:.3f}, wall {res.wall_s:.2f} s'
             + ''.join('\n- ' + m for m in diagnosis['messages'][1:])
             + ('' if selection is None else '\n' + '\n'.join(selection.summary())))
    return doc, table


# what the replay that pairs a bag's arrays for the batch methods takes (bag_source)
PAIRING_SETTINGS = frozenset({'vehicle', 'coefficients', 'noise_std', 'q_state',
                              'velocity_reference', 'mass_inverse'})


def bag_source(path, settings=None):
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
    of it forms M^-1 so."""
    settings = settings or IdentifierSettings()
    given = {n: getattr(settings, n) for n in settings.given & PAIRING_SETTINGS}
    if 'noise_std' in given:
        given['noise_source'] = 'parameter'
    meta = bag_custom_data(path)
    rr = replay_bag(path, IdentifierSettings.from_values(**given))
    vr = rr.model.velocity_reference
    # the replay's vehicle (a YAML path stays that file), forming M^-1 as the replay did
    v = rr.model.vehicle.with_mass_inverse(rr.model.mass_inverse)
    names = coefficient_list(v, ','.join(rr.model.theta_names[:rr.model.p_coef]))
    truth = _meta_truth(meta, Model(v, names))
    noise = rr.noise_std
    t, Y, U = _exact_hold(rr)
    return Source(vehicle=v, names=names, t=t, Y=Y, U=U, T=rr.T,
                  noise_std=noise, description=f'bag {path} ({rr.accepted} samples)',
                  truth=truth, seed=meta.get('auv_ident.seed'),
                  maneuver=meta.get('auv_ident.maneuver', ''),
                  current_truth=_bag_current_truth(meta), velocity_reference=vr,
                  time_origin_ns=rr.time_origin_ns)


REPLAY_REJECT_LIMIT = 0.02     # a replay rejecting more than this fraction is made again


def _replays(paths, replay, cfg_of):
    """Replay every bag (replay(path, noise_std, q_state, noise_source) -> ReplayResult); if
    they reject more than REPLAY_REJECT_LIMIT of their odometry (a first pass whose configured
    noise is far too small for the data throws away good samples as outliers), replay them
    again with the noise model read off the accepted samples (core/identification/noise_fit.py: the
    effective measurement noise and, for model error, the matched process noise).

    cfg_of(model, noise) -> FilterConfig of the configured noise. Returns (replays, the
    configured noise (12,) (the first replays' median), note: None or {'first_rejected',
    'first_samples', 'noise_std', 'q_state'} of the replay made again)."""
    rrs = [replay(p, None, None, None) for p in paths]
    for p, rr in zip(paths, rrs):
        if rr.accepted < 2:
            raise BagError(f'{p}: only {rr.accepted} odometry samples could be used '
                           f'(rejected: {dict(rr.reasons)})')
        if rr.vehicle != rrs[0].vehicle:
            raise BagError(f"{p}: vehicle {rr.vehicle!r}, the other bags' is "
                           f'{rrs[0].vehicle!r}: one model needs one vehicle')
    rejected = sum(rr.rejected for rr in rrs)
    total = rejected + sum(rr.accepted for rr in rrs)
    noise = np.median(np.array([rr.noise_std for rr in rrs]), axis=0)
    if rejected <= REPLAY_REJECT_LIMIT * total:
        return rrs, noise, None
    model = rrs[0].model
    cfg = cfg_of(model, noise)
    pre = fit_noise_runs(model, cfg, [_exact_hold(rr) for rr in rrs], T=rrs[0].T)
    again = [replay(p, pre.effective_std, pre.effective_q, 'parameter') for p in paths]
    note = {'first_rejected': int(rejected), 'first_samples': int(total),
            'noise_std': [float(x) for x in pre.effective_std],
            'q_state': [float(x) for x in pre.effective_q]}
    return again, noise, note


def identify_bags(paths, settings=None, refine_pass=True, progress=None):
    """`identify --bag A --bag B ...`: one coefficient set from several bags of one vehicle,
    by identify_bag's steps over all of them: each bag replayed as the identifier would have
    read it (its accepted measurements, its commands held, the noise of its messages; made
    again with the noise from the data if it rejected more than REPLAY_REJECT_LIMIT, see
    _replays), then the noise model from all runs' innovations, the EKF pass over the runs in
    turn and the refinement on all of them with it (core.identification.noise_fit.
    identify_runs_with_noise_model), the sandwich covariance within each run,
    identifiability and the diagnosis (printed first, and in the JSON as identify_bag's).

    settings : IdentifierSettings (None: the defaults), as identify_bag's, except:
    noise_std, q_state given: the measurement and per-step state process noise 1-sigma (the
        states' units) to start from instead of the messages' (median over the bags) and the
        default; the noise model from the data still applies
    current : not given: 'none' (still water); else a known current 'N,E[,D]' in m/s that all
        runs flew in (one current per run is not estimated)
    noise_mode : 'fixed' (the noise model comes from the data)
    Returns (JSON document, printable table)."""
    t0 = time.perf_counter()
    settings = settings or IdentifierSettings()
    if settings.noise_mode != 'fixed':
        raise ConfigError('several bags are identified with the fixed noise of their messages '
                          'and the noise model from the data: --noise-mode applies to one bag')
    if 'current' not in settings.given:
        settings = settings.with_values(current='none')
    if settings.current_option.estimate:
        raise BagError('several bags: give the current as none or a known N,E[,D] (m/s); one '
                       'current per run is not estimated')
    noise_given, q_given = ('noise_std' in settings.given), ('q_state' in settings.given)
    names = list(settings.coefficients)
    initial_offset = settings.initial_offset
    metas = {p: bag_custom_data(p) for p in paths}
    vrefs = {settings.velocity_reference if 'velocity_reference' in settings.given
             else bag_settings(p).get('velocity_reference', 'ground') for p in paths}
    if len(vrefs) > 1:
        raise BagError(f'the bags measure their velocity over {" and ".join(sorted(vrefs))}: '
                       'give --velocity-reference')
    vref = vrefs.pop()

    def replay(path, noise, q, source):
        changes = {'coefficients': names, 'velocity_reference': vref,
                   'noise_source': source or ('parameter' if noise_given
                                              else settings.noise_source)}
        for name, value in (('noise_std', noise), ('q_state', q)):
            if value is not None:
                changes[name] = value
        return replay_bag(path, settings.over(bag_settings(path)).with_values(**changes))

    def cfg_of(model, noise):
        cfg = ex.make_config(model.theta_names[:model.p_coef], noise_mode='fixed',
                             noise_std=noise, initial_offset=initial_offset)
        if q_given:
            cfg.q_state = np.asarray(settings.q_state, dtype=float)
        return cfg

    rrs, noise, again = _replays(paths, replay, cfg_of)
    model = rrs[0].model
    v = model.vehicle
    rejected = sum(rr.rejected for rr in rrs)
    cfg = cfg_of(model, noise)
    records = [_exact_hold(rr) for rr in rrs]
    est, cov, ekf_est, ekf_cov, cur, verdicts, diagnosis, fit = identify_records(
        model, cfg, records, rrs[0].T, refine_pass, progress)
    truths = [_meta_truth(metas[p], model) for p in paths]
    truth = truths[0] if all(tr is not None for tr in truths) else None
    steps = sum(len(r[0]) for r in records)
    run = fit.ekf_run
    res = Result(names=model.theta_names[:model.p_coef], estimate=est,
                 std=np.sqrt(np.diag(cov)), cov=cov, ekf_estimate=ekf_est,
                 ekf_std=np.sqrt(np.diag(ekf_cov)), initial=rrs[0].initial[:model.p_coef],
                 truth=truth, steps=steps, wall_s=time.perf_counter() - t0,
                 mean_nis_per_dof=run['mean_nis_per_dof'], refined=refine_pass, current=cur,
                 noise_model=fit.document(), identifiability=verdicts, diagnosis=diagnosis)
    if again is not None:
        diagnosis['messages'].append(_replayed_note(again, rejected))
    doc = ex.result_dict(v, res, {'bags': [str(p) for p in paths], 'rejected': rejected,
                                  'noise_mode': 'fixed',
                                  'noise_source': settings.noise_source,
                                  'mass_inverse': model.mass_inverse,
                                  'noise_std': [float(x) for x in noise],
                                  'q_state': [float(x) for x in cfg.q_state],
                                  'replayed_with_noise_model': again,
                                  'rejection_reasons': _reasons(rrs)},
                         current_truth=_common([_bag_current_truth(metas[p]) for p in paths]))
    head = (f'{v.title}: identified {", ".join(res.names)} from {len(paths)} bags together '
            f'({", ".join(str(p) for p in paths)}; {steps} samples, {rejected} rejected)'
            f'\ninitial guesses {100 * initial_offset:+.0f} % from the vehicle file; '
            'configured noise ' + ('as given' if noise_given
                                   else "the messages' (median over the bags)")
            + (', state process noise as given' if q_given else '')
            + ', then the noise model from the data; '
            + ('EKF pass over the runs in turn + batch refinement on all of them'
               if refine_pass else 'EKF pass over the runs in turn')
            + f'\nwater current: {settings.current_option.describe()}')
    head = diagnosis['messages'][0] + '\n' + head
    table = (head + '\n' + ex.result_table(v, res, doc) + f'\n{res.steps} EKF steps, mean '
             f'NIS/dof {res.mean_nis_per_dof:.3f} (the reported EKF pass; with the configured '
             f'noise {fit.configured_pass["mean_nis_per_dof"]:.4g})'
             + (f', refined cost per residual {fit.refine_cost:.3f}' if refine_pass else '')
             + f', wall {res.wall_s:.2f} s'
             + ''.join('\n- ' + m for m in diagnosis['messages'][1:]))
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
