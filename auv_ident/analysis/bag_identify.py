"""Bags as identification sources: ``identify --bag`` and the arrays the batch methods take."""
import time

import numpy as np

from auv_ident.analysis import results as ex
from auv_ident.analysis.identification import diagnosed, identify_records
from auv_ident.analysis.results import coefficient_list, Source
from auv_ident.bags.reader import BagError
from auv_ident.core.identification.batch import Result
from auv_ident.core.identification.noise_fit import fit_noise_runs
from auv_ident.core.identification.selection import identify_auto, parse_request
from auv_ident.core.model.current import DEFAULT_CURRENT, parse_current
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.sensors import DEFAULT_NOISE_STD
from auv_ident.core.model.state import N_CURRENT, N_STATE
from auv_ident.offline.replay import bag_custom_data, replay_bag
from auv_ident.session.record import exact_hold
from auv_ident.vehicles import load_vehicle


def _meta_noise(meta):
    """(12,) the sensor noise 1-sigma a bag's custom data (bag_custom_data) stores (bags our
    simulator wrote), else the default sensor suite's."""
    try:
        vals = np.array([float(v) for v in meta.get('auv_ident.noise_std', '').split()])
    except ValueError:
        vals = np.zeros(0)
    return vals if vals.shape == (N_STATE,) and np.all(vals > 0) else DEFAULT_NOISE_STD.copy()


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


def identify_bag(path, vehicle=None, coefficients='', noise_mode='fixed', initial_offset=0.5,
                 refine_pass=True, progress=None, noise_source='message', max_command_age=None,
                 current=DEFAULT_CURRENT, current_down=False, velocity_reference=None,
                 mass_inverse='default'):
    """`identify --bag`: the live identifier's EKF pass over the bag (replay_bag, made again
    with the noise from the data if it rejected more than REPLAY_REJECT_LIMIT), then the noise
    model, the batch refinement on the paired arrays at their stamps, identifiability and the
    diagnosis; with coefficients 'auto[,NAME,...]' the set is chosen from the data
    (core/identification/selection.py). Returns (JSON document, printable table).

    noise_source, max_command_age : as IdentSession (the message covariances are the noise
    where they are usable; a held command stays in force however old)
    current, current_down : the water current (IdentSession's settings of the same names:
    'estimate' by default, 'none', or a known 'N,E[,D]' in m/s)
    velocity_reference : 'ground' or 'water' (None: what a bag of our simulator says, else
    'ground')
    mass_inverse : 'default' (the vehicle file's), 'exact' or 'mss_literal'
    (core.model.hydrodynamics.Model;
    with 'exact' the added-mass coefficients can be identified, and `auto` may choose them)"""
    t0 = time.perf_counter()
    meta = bag_custom_data(path)
    auto, names = parse_request(load_vehicle(vehicle or meta.get('auv_ident.vehicle')
                                             or 'nps_auv2'), coefficients)
    meta_noise = _meta_noise(meta)
    if velocity_reference is None:
        velocity_reference = meta.get('auv_ident.velocity_reference', 'ground')

    def replay(p, noise, q, source):
        return replay_bag(p, vehicle=vehicle, coefficients=names, noise_mode=noise_mode,
                          initial_offset=initial_offset,
                          noise_std=meta_noise if noise is None else noise,
                          noise_source=source or noise_source, q_state=q,
                          max_command_age=max_command_age, current=current,
                          current_down=current_down, velocity_reference=velocity_reference,
                          mass_inverse=mass_inverse)

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
             f'adaptation: {noise_mode}; ' + ('EKF pass + batch refinement (filter-error ML)'
                                              if refine_pass else 'EKF pass only'))
    over = ('ground (DVL bottom lock)' if velocity_reference == 'ground'
            else 'water (water-track DVL)')
    head += (f'\nwater current: {parse_current(current, current_down).describe()}; velocity '
             f'over {over}')
    doc = ex.result_dict(v, res, {'bag': str(path), 'rejected': rr.rejected,
                                  'noise_mode': noise_mode, 'noise_source': noise_source,
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


def bag_source(path, vehicle=None, coefficients='', velocity_reference=None, noise_std=None,
               q_state=None, mass_inverse='default'):
    """experiments.Source of a bag: the paired arrays (U[k] = command in force from t_k on, the
    command changes between samples inserted as rows without a measurement). The replay that
    pairs them estimates the current (so that its innovation gate judges samples with it); the
    caller's model says what to do with the current. noise_std, q_state : (12,) the
    measurement and per-step state process noise 1-sigma the replay's gate judges samples with
    (None: the messages' and the default; a real run needs the noise its identification used,
    docs/kvlcc2.md, or the gate rejects its samples). mass_inverse : the replay model's M^-1
    ('default': the vehicle file's; core.model.hydrodynamics.Model), which the Source's vehicle
    then says
    (Vehicle.with_mass_inverse), so that every Model made of it forms M^-1 so."""
    names = [n.strip() for n in (coefficients or '').split(',') if n.strip()]
    meta = bag_custom_data(path)
    vr = velocity_reference or meta.get('auv_ident.velocity_reference', 'ground')
    given = {} if noise_std is None else {'noise_source': 'parameter'}
    if q_state is not None:
        given['q_state'] = np.asarray(q_state, dtype=float)
    rr = replay_bag(path, vehicle=vehicle, coefficients=names,
                    noise_std=(_meta_noise(meta) if noise_std is None
                               else np.asarray(noise_std, dtype=float)),
                    velocity_reference=vr, mass_inverse=mass_inverse, **given)
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


def identify_bags(paths, vehicle=None, coefficients='', initial_offset=0.5, refine_pass=True,
                  progress=None, noise_source='message', max_command_age=None,
                  velocity_reference=None, noise_std=None, q_state=None, current='none',
                  current_down=False, mass_inverse='default'):
    """`identify --bag A --bag B ...`: one coefficient set from several bags of one vehicle,
    by identify_bag's steps over all of them: each bag replayed as the identifier would have
    read it (its accepted measurements, its commands held, the noise of its messages; made
    again with the noise from the data if it rejected more than REPLAY_REJECT_LIMIT, see
    _replays), then the noise model from all runs' innovations, the EKF pass over the runs in
    turn and the refinement on all of them with it (core.identification.noise_fit.
    identify_runs_with_noise_model), the sandwich covariance within each run,
    identifiability and the diagnosis (printed first, and in the JSON as identify_bag's).

    noise_std, q_state : (12,) the measurement and per-step state process noise 1-sigma (the
        states' units) to start from instead of the messages' (median over the bags) and the
        default; the noise model from the data still applies
    current, current_down : 'none' (still water, default) or a known current 'N,E[,D]' in m/s
        that all runs flew in; one current per run is not estimated
    mass_inverse : as identify_bag
    Returns (JSON document, printable table)."""
    t0 = time.perf_counter()
    names = [n.strip() for n in (coefficients or '').split(',') if n.strip()]
    if str(current).strip().lower() == 'estimate':
        raise BagError('several bags: give the current as none or a known N,E[,D] (m/s); one '
                       'current per run is not estimated')
    metas = {p: bag_custom_data(p) for p in paths}
    vrefs = {velocity_reference or metas[p].get('auv_ident.velocity_reference', 'ground')
             for p in paths}
    if len(vrefs) > 1:
        raise BagError(f'the bags measure their velocity over {" and ".join(sorted(vrefs))}: '
                       'give --velocity-reference')
    vref = vrefs.pop()

    def replay(path, noise, q, source):
        given = noise_std if noise is None else noise
        return replay_bag(path, vehicle=vehicle, coefficients=names, noise_mode='fixed',
                          initial_offset=initial_offset,
                          noise_std=_meta_noise(metas[path]) if given is None else given,
                          noise_source=source or (noise_source if noise_std is None
                                                  else 'parameter'),
                          q_state=q_state if q is None else q,
                          max_command_age=max_command_age, current=current,
                          current_down=current_down, velocity_reference=vref,
                          mass_inverse=mass_inverse)

    def cfg_of(model, noise):
        cfg = ex.make_config(model.theta_names[:model.p_coef], noise_mode='fixed',
                             noise_std=noise, initial_offset=initial_offset)
        if q_state is not None:
            cfg.q_state = np.asarray(q_state, dtype=float)
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
                                  'noise_mode': 'fixed', 'noise_source': noise_source,
                                  'mass_inverse': model.mass_inverse,
                                  'noise_std': [float(x) for x in noise],
                                  'q_state': [float(x) for x in cfg.q_state],
                                  'replayed_with_noise_model': again,
                                  'rejection_reasons': _reasons(rrs)},
                         current_truth=_common([_bag_current_truth(metas[p]) for p in paths]))
    head = (f'{v.title}: identified {", ".join(res.names)} from {len(paths)} bags together '
            f'({", ".join(str(p) for p in paths)}; {steps} samples, {rejected} rejected)'
            f'\ninitial guesses {100 * initial_offset:+.0f} % from the vehicle file; '
            'configured noise ' + ("the messages' (median over the bags)" if noise_std is None
                                   else 'as given')
            + ('' if q_state is None else ', state process noise as given')
            + ', then the noise model from the data; '
            + ('EKF pass over the runs in turn + batch refinement on all of them'
               if refine_pass else 'EKF pass over the runs in turn')
            + f'\nwater current: {parse_current(current, current_down).describe()}')
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
