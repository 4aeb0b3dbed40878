"""Experiments over the core: identify a simulated run, tables, JSON, Monte Carlo statistics.

ROS-free (bags come in through analysis/bag_identify.py). Every figure printed here can be
reproduced with the command shown next to it in docs/.
"""
import contextlib
from dataclasses import dataclass
import time

import numpy as np

from auv_ident.analysis.bag_identify import bag_source
from auv_ident.analysis.results import coefficient_list, DEFAULT_NOISE_MODE, make_config, Source
from auv_ident.core.errors import ConfigError
from auv_ident.core.identification.pipeline import identify_with_diagnosis
from auv_ident.core.identification.results import Identification, Record
from auv_ident.core.model.current import parse_current
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.sensors import ar1_noise, DEFAULT_NOISE_STD, perturbed_values
from auv_ident.core.model.state import Input
from auv_ident.core.simulation.simulate import Run, simulate
from auv_ident.session.settings import IdentifierSettings
from auv_ident.vehicles import load_vehicle

DEFAULT_DURATION = 600.0     # s of the identification run
DEFAULT_MANEUVER = 'ident'


@dataclass
class SimulatedIdentification:
    """identify_simulated's outcome: the Identification (core.identification.results; its
    model the one identified) and the simulated run (core.simulation.simulate.Run)."""

    result: Identification
    run: Run


def identify_simulated(vehicle, names, cfg, maneuver=DEFAULT_MANEUVER, seed=0,
                       duration=DEFAULT_DURATION, rpm=None, refine_pass=True, hist_every=0,
                       mass_inverse='default', progress=None, process_std=None, current='none',
                       sim_current=None, velocity_reference='ground', noise_level=1.0,
                       noise_tau=0.0, perturb=0.0):
    """Simulate the truth (vehicle file values, in the water current sim_current (3,) m/s NED
    if given), then identify with the current option `current` ('estimate', 'none' or 'N,E[,D]',
    core/model/current.py) and the velocity reference of the simulated sensor, with the noise model
    from the data and a diagnosis (core/identification/pipeline.py). vehicle : a Vehicle, or its
    name or YAML path. Returns a SimulatedIdentification.

    Data the identifier's assumptions do not hold for (issue #14), neither told to it:
    noise_level, noise_tau : the measurement noise is noise_level x cfg.noise_std, first-order
        correlated with time constant noise_tau (s; core.model.sensors.ar1_noise), drawn from
        default_rng([seed, 1]); 1.0 and 0 are the white noise the filter assumes
    perturb : every coefficient but the identified ones (and added mass) is scaled by
        U(1 - perturb, 1 + perturb) in the truth (default_rng([seed, 2]),
        core.model.sensors.perturbed_values), the identifier keeps the file's values: a wrong
        prior"""
    v = load_vehicle(vehicle)
    values = (perturbed_values(v, perturb, np.random.default_rng([seed, 2]), keep=names)
              if perturb else None)
    truth = Model(v, mass_inverse=mass_inverse, coefficient_values=values)
    white = noise_level == 1.0 and noise_tau == 0.0
    run = simulate(truth, maneuver, duration=duration, seed=seed, rpm=rpm,
                   noise_std=cfg.noise_std if white else np.zeros(len(cfg.noise_std)),
                   process_std=process_std, current=sim_current,
                   velocity_reference=velocity_reference)
    if not white:
        run.noise_std = noise_level * np.asarray(cfg.noise_std, dtype=float)
        run.y = run.y + ar1_noise(np.random.default_rng([seed, 1]), len(run.t), run.noise_std,
                                  noise_tau, run.T)
    opt = parse_current(current)
    m = Model(v, list(names) + opt.names, mass_inverse=mass_inverse, current=opt.fixed,
              velocity_reference=velocity_reference)
    res = identify_with_diagnosis(m, cfg, [Record(run.t, run.y, run.u)], T=run.T,
                                  refine_pass=refine_pass, hist_every=hist_every,
                                  truth=m.theta_true[:m.p_coef], progress=progress)
    return SimulatedIdentification(res, run)


def load_source(settings=None, simulate_maneuver=None, bag=None, seed=0,
                duration=DEFAULT_DURATION, rpm=None, process_std=None, sim_current=None):
    """A Source from --simulate MANEUVER (in memory, in the water current sim_current (3,) m/s
    NED if given) or --bag PATH (bag_identify.bag_source). settings: IdentifierSettings (None:
    the defaults) of which the vehicle, coefficients, velocity_reference (what the velocities
    are; not given: what a bag of our simulator says, else 'ground') and mass_inverse (M^-1 of
    the model that simulates or pairs the run; the Source's vehicle then says it, so that every
    Model made of it uses it) apply."""
    if bool(simulate_maneuver) == bool(bag):
        raise ConfigError('give exactly one of --simulate MANEUVER or --bag PATH')
    settings = settings or IdentifierSettings()
    if bag:
        return bag_source(bag, settings)
    v = load_vehicle(settings.vehicle).with_mass_inverse(settings.mass_inverse)
    names = coefficient_list(v, settings.coefficients)
    vr = settings.velocity_reference
    run = simulate(Model(v), simulate_maneuver, duration=duration, seed=seed, rpm=rpm,
                   process_std=process_std, current=sim_current, velocity_reference=vr)
    m = Model(v, names)
    where = ('' if run.current is None else ', in a current of '
             + ', '.join(f'{c:g}' for c in run.current) + ' m/s (N, E, D)')
    return Source(vehicle=v, names=names, t=run.t, Y=run.y, U=run.u, T=run.T,
                  noise_std=run.noise_std, X_true=run.x, truth=m.theta_true, seed=seed,
                  maneuver=run.maneuver,
                  current_truth=np.zeros(3) if run.current is None else run.current,
                  velocity_reference=vr,
                  description=f'simulated {run.maneuver!r} run of {run.t[-1]:.0f} s at '
                              f'T = {run.T} s, seed {seed}, {run.u[0, Input.N_RPM]:.0f} rpm'
                              + where)


MC_WARM_UP_DURATION_S = 20.0   # s of the run each Dask worker identifies before its cases


def _mc_case(args):
    """One Monte Carlo case (runs on a Dask worker, or in this process): its row of
    stats['runs']. The vehicle comes as its file's content (engine.VehicleText)."""
    (vehicle, names, noise_mode, offset, seed, maneuver, duration, rpm, refine_pass,
     tau, noise_level, noise_tau, perturb) = args
    cfg = make_config(names, noise_mode=noise_mode, initial_offset=offset, tau=tau)
    try:
        res = identify_simulated(vehicle.local_path(), names, cfg, maneuver=maneuver,
                                 seed=seed, duration=duration, rpm=rpm,
                                 refine_pass=refine_pass, noise_level=noise_level,
                                 noise_tau=noise_tau, perturb=perturb).result
    except ArithmeticError as err:      # DomainError / DivergenceError: a diverged run
        return {'seed': seed, 'offset': offset, 'diverged': str(err)}
    e = res.estimate - res.truth
    try:
        nees = float(e @ np.linalg.solve(res.cov, e))
    except np.linalg.LinAlgError:
        nees = float('nan')
    return {'seed': seed, 'offset': offset, 'error_pct': res.error_pct().tolist(),
            'z': (e / res.std).tolist(), 'nees': nees,
            'ekf_error_pct': res.error_pct('ekf_estimate').tolist(),
            'ekf_z': ((res.ekf_estimate - res.truth) / res.ekf_std).tolist(),
            'mean_nis_per_dof': res.mean_nis_per_dof, 'wall_s': res.wall_s,
            'consistent': res.diagnosis.consistent,
            'plausible': res.diagnosis.plausible,
            'noise_model_used': bool(res.noise.used)}


def _mc_warm_up(case):
    """A short run of the campaign's first case: compiles what its cases use (engine.WarmUp)."""
    _mc_case(case[:6] + (MC_WARM_UP_DURATION_S,) + case[7:])


def montecarlo(vehicle, names, seeds=20, offsets=(0.5, -0.5), noise_mode=DEFAULT_NOISE_MODE,
               maneuver=DEFAULT_MANEUVER, duration=DEFAULT_DURATION, rpm=None, refine_pass=True,
               jobs=2, progress=None, tau=10.0, scheduler=None, noise_level=1.0, noise_tau=0.0,
               perturb=0.0):
    """Seeds x initial offsets; statistics of |error| %, 3-sigma coverage, NEES and NIS, the
    median |error|/sigma and how many results the diagnosis called consistent.

    noise_level, noise_tau, perturb : data that contradict the filter's assumptions, not told
    to it (identify_simulated): coloured noise of another level, a truth vehicle whose other
    coefficients differ from the file's.

    The cases run as tasks on the Dask engine (analysis/engine.py): on the cluster at
    `scheduler` if given, else on a local cluster of `jobs` worker processes, or one after the
    other in this process for jobs <= 1. Each case is a function of its seed and offset only,
    and the statistics are taken in case order, so every way gives the same numbers.

    vehicle : a Vehicle, or its name or YAML path (its file's content goes to the workers)."""
    from auv_ident.analysis import engine  # distributed is imported only when used
    v = load_vehicle(vehicle)
    vehicle = engine.VehicleText.read(v.path)
    cases = [(vehicle, names, noise_mode, off, s, maneuver, duration, rpm, refine_pass,
              tau, noise_level, noise_tau, perturb) for s in range(seeds) for off in offsets]
    t0 = time.perf_counter()
    out = [None] * len(cases)
    serial = scheduler is None and jobs <= 1
    with (contextlib.nullcontext() if serial else engine.dask_client(scheduler, jobs)) as client:
        if client is not None:
            name = f'auv_ident-warm-up-montecarlo-{vehicle.name}-{vehicle.digest}'
            client.register_plugin(engine.WarmUp(_mc_warm_up, (cases[0],), name=name))
        for i, outcome in engine.run_tasks(client, _mc_case, cases):
            if isinstance(outcome, Exception):
                seed, off = cases[i][4], cases[i][3]
                raise engine.EngineError(f'montecarlo case seed {seed}, offset {off:+g}: '
                                         f'{engine.one_line(outcome)}')
            out[i] = outcome
            if progress:
                progress()
    ok = [r for r in out if 'diverged' not in r]
    p = len(names)
    stats = {'vehicle': v.name, 'coefficients': names, 'maneuver': maneuver,
             'duration_s': duration, 'seeds': seeds, 'offsets': list(offsets),
             'noise_mode': noise_mode, 'tau_s': tau, 'refined': refine_pass,
             'noise_level': noise_level, 'noise_tau_s': noise_tau, 'perturb': perturb,
             'cases': len(out),
             'diverged': len(out) - len(ok), 'wall_s': time.perf_counter() - t0,
             'noise_std': DEFAULT_NOISE_STD.tolist(), 'per_coefficient': {}}
    if ok:
        E = np.abs(np.array([r['error_pct'] for r in ok]))
        Z = np.abs(np.array([r['z'] for r in ok]))
        EE = np.abs(np.array([r['ekf_error_pct'] for r in ok]))
        EZ = np.abs(np.array([r['ekf_z'] for r in ok]))
        for i, n in enumerate(names):
            stats['per_coefficient'][n] = {
                'median_abs_error_pct': float(np.median(E[:, i])),
                'max_abs_error_pct': float(E[:, i].max()),
                'within_3sigma': float(np.mean(Z[:, i] <= 3.0)),
                'ekf_median_abs_error_pct': float(np.median(EE[:, i])),
                'ekf_within_3sigma': float(np.mean(EZ[:, i] <= 3.0))}
        stats['within_3sigma_all'] = float(np.mean(Z <= 3.0))
        stats['median_abs_z'] = float(np.median(Z))
        stats['ekf_median_abs_z'] = float(np.median(EZ))
        stats['consistent'] = int(sum(1 for r in ok if r['consistent']))
        # a false alarm with the correct vehicle file: NOT plausible (#26 done-when)
        stats['not_plausible'] = int(sum(1 for r in ok if not r.get('plausible', True)))
        stats['ekf_within_3sigma_all'] = float(np.mean(EZ <= 3.0))
        nees = np.array([r['nees'] for r in ok])
        stats['mean_nees'] = float(np.nanmean(nees))
        stats['nees_expected'] = p
        stats['mean_nis_per_dof'] = float(np.mean([r['mean_nis_per_dof'] for r in ok]))
    stats['runs'] = sorted(out, key=lambda r: (r['seed'], -r['offset']))
    return stats


def montecarlo_table(stats):
    lines = [f'{"coefficient":<12}{"median|err|%":>14}{"max|err|%":>11}{"in 3-sigma":>12}'
             f'{"EKF-only med%":>15}{"EKF in 3s":>11}']
    for n, s in stats['per_coefficient'].items():
        lines.append(f'{n:<12}{s["median_abs_error_pct"]:>14.3f}{s["max_abs_error_pct"]:>11.3f}'
                     f'{100 * s["within_3sigma"]:>11.0f}%{s["ekf_median_abs_error_pct"]:>15.3f}'
                     f'{100 * s["ekf_within_3sigma"]:>10.0f}%')
    if stats['diverged']:
        first = next(r['diverged'] for r in stats['runs'] if 'diverged' in r)
        lines.append(f'{stats["diverged"]} of {stats["cases"]} runs diverged (first: {first})')
    if 'mean_nees' in stats:
        lines.append(f'cases {stats["cases"]} (diverged {stats["diverged"]}); truth within '
                     f'3-sigma in {100 * stats["within_3sigma_all"]:.1f} % of seed x coefficient '
                     f'cases; mean NEES {stats["mean_nees"]:.2f} (expected '
                     f'{stats["nees_expected"]}); mean NIS/dof {stats["mean_nis_per_dof"]:.3f} '
                     '(expected 1)')
        lines.append(f'median |error|/sigma {stats["median_abs_z"]:.2f} refined, '
                     f'{stats["ekf_median_abs_z"]:.2f} EKF pass (an honest sigma gives ~0.67); '
                     f'EKF pass within 3-sigma in {100 * stats["ekf_within_3sigma_all"]:.1f} %; '
                     f'diagnosis consistent in {stats["consistent"]} of '
                     f'{len(stats["runs"]) - stats["diverged"]}')
        n_ok = len(stats['runs']) - stats['diverged']
        lines.append(f'NOT plausible in {stats["not_plausible"]} of {n_ok} runs; '
                     f'NOT consistent in {n_ok - stats["consistent"]} of {n_ok}')
    return '\n'.join(lines)


