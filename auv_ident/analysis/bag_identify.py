"""Bags as identification sources: ``identify --bag`` and the arrays the batch methods take."""
import time

import numpy as np

from auv_ident.analysis import results as ex
from auv_ident.analysis.results import coefficient_list, Source
from auv_ident.bags.reader import BagError
from auv_ident.bags.replay import bag_custom_data, replay_bag
from auv_ident.core.batch import Result
from auv_ident.core.diagnosis import assess
from auv_ident.core.model import Model
from auv_ident.core.noise_fit import identify_with_noise_model
from auv_ident.core.sensors import DEFAULT_NOISE_STD
from auv_ident.core.state import N_STATE
from auv_ident.core.timing import with_command_changes
from auv_ident.vehicles import load_vehicle

def _bag_truth_and_noise(path, model):
    """Truth (the vehicle file's values) only for bags our simulator wrote; the noise 1-sigma
    stored with them, else the default sensor suite."""
    meta = bag_custom_data(path)
    simulated = meta.get('auv_ident.simulated') == 'true'
    noise = DEFAULT_NOISE_STD.copy()
    if 'auv_ident.noise_std' in meta:
        try:
            vals = np.array([float(v) for v in meta['auv_ident.noise_std'].split()])
            if vals.shape == (N_STATE,) and np.all(vals > 0):
                noise = vals
        except ValueError:
            pass
    truth = model.theta_true if simulated and model is not None else None
    return truth, noise, meta


def _exact_hold(rr):
    """(t, Y, U) of a replay for the batch methods: the samples with a command, and the
    command changes between them as samples without a measurement (timing.with_command_changes:
    the exact zero-order hold the EKF pass followed)."""
    ok = np.all(np.isfinite(rr.U), axis=1)
    t, Y, U, _ = with_command_changes(rr.t[ok], rr.Y[ok], rr.U[ok], rr.t_cmd, rr.U_cmd)
    return t, Y, U



def identify_bag(path, vehicle=None, coefficients='', noise_mode='fixed', initial_offset=0.5,
                 refine_pass=True, progress=None, noise_source='message', max_command_age=None):
    """`identify --bag`: the live identifier's EKF pass over the bag (replay_bag), then the
    batch refinement on the paired arrays at their stamps. Returns (JSON document, printable
    table).

    noise_source, max_command_age : as IdentSession (the message covariances are the noise
    where they are usable; a held command stays in force however old)"""
    t0 = time.perf_counter()
    names = [n.strip() for n in (coefficients or '').split(',') if n.strip()]
    meta_noise = _bag_truth_and_noise(path, None)[1]
    rr = replay_bag(path, vehicle=vehicle, coefficients=names, noise_mode=noise_mode,
                    initial_offset=initial_offset, noise_std=meta_noise,
                    noise_source=noise_source, max_command_age=max_command_age)
    v = load_vehicle(rr.vehicle)
    model = Model(v, rr.names)
    truth, _, meta = _bag_truth_and_noise(path, model)
    noise = rr.noise_std
    if rr.accepted < 2:
        raise BagError(f'{path}: only {rr.accepted} odometry samples could be used '
                       f'(rejected: {dict(rr.reasons)})')
    # the noise model from the data (core/noise_fit.py): with the configured noise right, the
    # EKF pass is the replay's (the live node's) and the refinement starts from it
    t, Y, U = _exact_hold(rr)
    cfg = ex.make_config(rr.names, noise_mode='fixed', noise_std=noise,
                         initial_offset=initial_offset)
    ekf_est, ekf_cov, est, cov, fit = identify_with_noise_model(
        model, cfg, t, Y, U, T=rr.T, refine_pass=refine_pass, progress=progress,
        ekf_pass=(rr.estimate, rr.cov))
    verdicts, diagnosis = assess(v, rr.names, est, cov, fit, U, rr.T, rr.mean_nis_per_dof,
                                 refined=refine_pass)
    res = Result(names=rr.names, estimate=est, std=np.sqrt(np.diag(cov)), cov=cov,
                 ekf_estimate=ekf_est, ekf_std=np.sqrt(np.diag(ekf_cov)), initial=rr.initial,
                 truth=truth,
                 steps=rr.accepted, wall_s=time.perf_counter() - t0,
                 mean_nis_per_dof=rr.mean_nis_per_dof, refined=refine_pass)
    head = (f'{v.title}: identified {", ".join(rr.names)} from bag {path} '
            f'({rr.accepted} odometry samples used, {rr.rejected} rejected, {rr.commands} '
            f'actuator commands; frame {rr.frame})')
    if meta.get('auv_ident.simulated') == 'true':
        head += (f'\nsimulated by auv_ident: manoeuvre {meta.get("auv_ident.maneuver")!r}, seed '
                 f'{meta.get("auv_ident.seed")}; truth = the vehicle file values')
    head += (f'\ninitial guesses {100 * initial_offset:+.0f} % from the vehicle file; noise '
             f'adaptation: {noise_mode}; ' + ('EKF pass + batch refinement (filter-error ML)'
                                              if refine_pass else 'EKF pass only'))
    doc = ex.result_dict(v, res, {'bag': str(path), 'rejected': rr.rejected,
                                  'noise_mode': noise_mode, 'noise_source': noise_source,
                                  'noise_std': [float(x) for x in noise],
                                  'time_origin_ns': rr.time_origin_ns,
                                  'noise_model': fit.document(),
                                  'diagnosis': diagnosis, 'identifiability': verdicts,
                                  'rejection_reasons': dict(rr.reasons)})
    head = diagnosis['messages'][0] + '\n' + head
    table = (head + '\n' + ex.result_table(v, res) + f'\n{res.steps} EKF steps, mean NIS/dof '
             f'{res.mean_nis_per_dof:.3f}, wall {res.wall_s:.2f} s'
             + ''.join('\n- ' + m for m in diagnosis['messages'][1:]))
    return doc, table


def bag_source(path, vehicle=None, coefficients=''):
    """experiments.Source of a bag: the paired arrays (U[k] = command in force from t_k on, the
    command changes between samples inserted as rows without a measurement)."""
    names = [n.strip() for n in (coefficients or '').split(',') if n.strip()]
    rr = replay_bag(path, vehicle=vehicle, coefficients=names,
                    noise_std=_bag_truth_and_noise(path, None)[1])
    v = load_vehicle(rr.vehicle)
    names = coefficient_list(v, ','.join(rr.names))
    truth, _, meta = _bag_truth_and_noise(path, Model(v, names))
    noise = rr.noise_std
    t, Y, U = _exact_hold(rr)
    return Source(vehicle=v, names=names, t=t, Y=Y, U=U, T=rr.T,
                  noise_std=noise, description=f'bag {path} ({rr.accepted} samples)',
                  truth=truth, seed=meta.get('auv_ident.seed'),
                  maneuver=meta.get('auv_ident.maneuver', ''))
