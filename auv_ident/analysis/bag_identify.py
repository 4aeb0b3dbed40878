"""Bags as identification sources: ``identify --bag`` and the arrays the batch methods take."""
import time

import numpy as np

from auv_ident.analysis import results as ex
from auv_ident.analysis.results import coefficient_list, Source
from auv_ident.bags.reader import BagError
from auv_ident.bags.replay import bag_custom_data, replay_bag
from auv_ident.core.batch import Result, refine
from auv_ident.core.model import Model
from auv_ident.core.sensors import DEFAULT_NOISE_STD
from auv_ident.core.state import N_STATE
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
    return (model.theta_true if simulated else None), noise, meta

def identify_bag(path, vehicle=None, coefficients='', noise_mode='fixed', initial_offset=0.5,
                 refine_pass=True, progress=None):
    """`identify --bag`: the live identifier's EKF pass over the bag (replay_bag), then the
    batch refinement on the paired arrays. Returns (JSON document, printable table)."""
    t0 = time.perf_counter()
    names = [n.strip() for n in (coefficients or '').split(',') if n.strip()]
    rr = replay_bag(path, vehicle=vehicle, coefficients=names, noise_mode=noise_mode,
                    initial_offset=initial_offset)
    v = load_vehicle(rr.vehicle)
    model = Model(v, rr.names)
    truth, noise, meta = _bag_truth_and_noise(path, model)
    if rr.accepted < 2:
        raise BagError(f'{path}: only {rr.accepted} odometry samples could be used '
                       f'(rejected: {dict(rr.reasons)})')
    est, cov = rr.estimate, rr.cov
    if refine_pass:
        ok = np.all(np.isfinite(rr.U), axis=1)
        cfg = ex.make_config(rr.names, noise_mode='fixed', noise_std=noise)
        est, cov, _ = refine(model, cfg, rr.t[ok], rr.Y[ok], rr.U[ok], rr.estimate, T=rr.T,
                             progress=progress)
    res = Result(names=rr.names, estimate=est, std=np.sqrt(np.diag(cov)), cov=cov,
                 ekf_estimate=rr.estimate, ekf_std=rr.std, initial=rr.initial, truth=truth,
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
                                  'noise_mode': noise_mode,
                                  'rejection_reasons': dict(rr.reasons)})
    table = (head + '\n' + ex.result_table(v, res) + f'\n{res.steps} EKF steps, mean NIS/dof '
             f'{res.mean_nis_per_dof:.3f}, wall {res.wall_s:.2f} s')
    return doc, table

def bag_source(path, vehicle=None, coefficients=''):
    """experiments.Source of a bag: the paired arrays (U[k] = command in force at t_k)."""
    names = [n.strip() for n in (coefficients or '').split(',') if n.strip()]
    rr = replay_bag(path, vehicle=vehicle, coefficients=names)
    v = load_vehicle(rr.vehicle)
    names = coefficient_list(v, ','.join(rr.names))
    truth, noise, meta = _bag_truth_and_noise(path, Model(v, names))
    ok = np.all(np.isfinite(rr.U), axis=1)
    return Source(vehicle=v, names=names, t=rr.t[ok], Y=rr.Y[ok], U=rr.U[ok], T=rr.T,
                  noise_std=noise, description=f'bag {path} ({int(ok.sum())} samples)',
                  truth=truth, seed=meta.get('auv_ident.seed'),
                  maneuver=meta.get('auv_ident.maneuver', ''))
