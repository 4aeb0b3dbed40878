"""`report --model MODEL.json --validate BAG`: a saved model judged on a run it never saw.

The way a naval architect validates a manoeuvring model (issue #20, item 5):

- **free run** (analysis/validation.py validate_on_run): from the run's measured initial state,
  with its measured inputs (rudder, thrust, shaft speed held between their stamps), the saved
  model and the prior model (the vehicle file's values) fly freely; per channel the fit %
  (MATLAB ``compare``) and, for a ship, the total speed U = sqrt(u^2 + v^2);
- **closed-loop zig-zag**, when the run is one (core/simulation/zigzag.py detects the test on its
measured
  heading and rudder): the run's ordered rudder and switch angles and first side executed by a
  helm through the steering gear identified from the IDENTIFICATION runs' measured rudder
  (core/simulation/steering.py), with the thrust from a thrust model fitted on the same runs
  (core/identification/thrust_fit.py, for a vehicle whose thrust is an input); the IMO overshoot
  angles of the measured run, of the saved model, of the prior model, and of the saved model with
  an ideal helm (no dead time; the difference is the helm's effect);
- a **rudder-neutral diagnosis** AFTER scoring: the constant rudder bias (deg) that makes the
  saved model's free run fit the yaw rate best. A basin's rudder zero is set by hand; a bias
  of a degree turns a 10/10 zig-zag visibly. It never enters the scores above.

Writes report.md, report.html, result.json, validation.csv (the scored series) and PNG figures
to the output folder. Units: SI in files (m/s, rad/s, rad), degrees in tables and figures.

ROS-free above bags; matplotlib only in the figure functions (report_format.pyplot).
"""
import csv
from dataclasses import dataclass
import json
import os
from types import SimpleNamespace

import numpy as np
from scipy.optimize import minimize_scalar

from auv_ident.analysis import validation as mv
from auv_ident.analysis.report_format import (
    finite_cell,
    markdown_table,
    package_versions,
    pyplot,
    save_figure,
)
from auv_ident.analysis.report_html import write_html
from auv_ident.analysis.results import write_json
from auv_ident.analysis.zigzag import closed_loop
from auv_ident.core.errors import ConfigError, DataError
from auv_ident.core.identification.thrust_fit import fit_thrust_model
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import Input, N_STATE, State
from auv_ident.core.simulation.prediction import angle_channels, fit_percent, free_run
from auv_ident.core.simulation.steering import identify_steering_gear, SteeringGear
from auv_ident.core.simulation.zigzag import zigzag_problem
from auv_ident.session.input_map import vehicle_actuators
from auv_ident.session.settings import IdentifierSettings
from auv_ident.vehicles import load_vehicle

DEG = 180.0 / np.pi
CSV_CHANNELS = ('u', 'v', 'r', 'U', 'psi')      # validation.csv, SI: m/s, m/s, rad/s, m/s, rad
BIAS_BOUND_DEG = 3.0        # the rudder-neutral diagnosis searches a bias within +-this
BIAS_TOL_DEG = 0.02


# ------------------------------------------------------------------------------ the model file

@dataclass
class SavedModel:
    """A model written by `identify --json` (docs/report.md), as the report uses it.

    vehicle : core.model.vehicle.Vehicle; names, estimate, std : the coefficients (vehicle-file
    units); current : (3,) m/s NED or None; bags : the identification bags (paths as written);
    noise_std, q_state : (12,) the noise the identification judged the data with, or None;
    source : what it was identified from, as the model file says it ('' if it does not);
    mass_inverse : how the identification formed M^-1 ('default': as the vehicle file says)
    """

    path: str
    vehicle: object
    names: list
    estimate: np.ndarray
    std: np.ndarray
    current: object
    bags: list
    noise_std: object
    q_state: object
    source: str = ''
    mass_inverse: str = 'default'
    input_map: str | None = None      # the map the bags were read through (None: their own)


def _twelve(doc, key, path):
    vals = doc.get(key)
    if vals is None:
        return None
    arr = np.asarray(vals, dtype=float)
    if arr.shape != (N_STATE,) or not np.all(np.isfinite(arr)):
        raise ConfigError(f'{path}: {key!r} must be {N_STATE} finite numbers')
    return arr


def load_model(path, vehicle=None):
    """SavedModel of a model JSON; ConfigError naming the culprit for a file that is not one
    (not JSON, no 'vehicle' or 'coefficients', a coefficient without 'estimate', another
    vehicle than `vehicle`, a coefficient the vehicle does not have)."""
    try:
        with open(path, encoding='utf-8') as fh:
            doc = json.load(fh)
    except json.JSONDecodeError as err:
        raise ConfigError(f'--model {path}: not JSON ({err.msg}, line {err.lineno})') from None
    doc = _from_estimate_file(doc)
    if not isinstance(doc, dict) or 'vehicle' not in doc or not isinstance(
            doc.get('coefficients'), dict) or not doc['coefficients']:
        raise ConfigError(f'--model {path}: not a model written by identify --json (needs '
                          '"vehicle" and "coefficients")')
    if vehicle:
        v = load_vehicle(vehicle)
        if v.name != doc['vehicle']:
            raise ConfigError(f'--model {path} is a model of {doc["vehicle"]!r}, not of '
                              f'--vehicle {v.name!r}')
    else:
        v = load_vehicle(doc['vehicle'])
    names, est, std = [], [], []
    for n, c in doc['coefficients'].items():
        if not isinstance(c, dict) or 'estimate' not in c:
            raise ConfigError(f'--model {path}: coefficient {n!r} has no "estimate"')
        if n not in v.names:
            raise ConfigError(f"--model {path}: coefficient {n!r} is not one of {v.name}'s")
        names.append(n)
        est.append(float(c['estimate']))
        std.append(float(c['std']) if c.get('std') is not None else float('nan'))
    cur = doc.get('current')
    current = (None if not cur else np.array([cur['north'], cur['east'], cur['down']], float))
    bags = list(doc.get('bags') or ([doc['bag']] if doc.get('bag') else []))
    # identify --json records the paths as given: relative ones may be the model file's
    here = os.path.dirname(os.path.abspath(path))
    bags = [b if os.path.isabs(b) or os.path.exists(b)
            or not os.path.exists(os.path.join(here, b)) else os.path.join(here, b)
            for b in map(str, bags)]
    return SavedModel(path=str(path), vehicle=v, names=names, estimate=np.array(est),
                      std=np.array(std), current=current, bags=[str(b) for b in bags],
                      noise_std=_twelve(doc, 'noise_std', path),
                      q_state=_twelve(doc, 'q_state', path),
                      source=str(doc.get('source') or ''),
                      mass_inverse=str(doc.get('mass_inverse') or 'default'),
                      input_map=doc.get('input_map') or None)


def _from_estimate_file(doc):
    """The identifier node's estimate file (session/estimate_file.py: 'coefficients' a list
    of names beside 'estimate' and 'std' lists) in identify --json's layout; other
    documents as they are."""
    if not (isinstance(doc, dict) and isinstance(doc.get('coefficients'), list)
            and isinstance(doc.get('estimate'), list)
            and len(doc['estimate']) == len(doc['coefficients'])):
        return doc
    std = doc.get('std') if isinstance(doc.get('std'), list) else []
    coefficients = {str(n): {'estimate': e, 'std': std[i] if i < len(std) else None}
                    for i, (n, e) in enumerate(zip(doc['coefficients'], doc['estimate']))}
    source = 'the identifier node' + (f" (stamp {doc['stamp']} s)" if doc.get('stamp') else '')
    return dict(doc, coefficients=coefficients, source=source)


def refuse_identification_bag(bags, validate_bag):
    """ConfigError if the validation bag is one of the identification bags (same file)."""
    for b in bags:
        try:
            mv.refuse_same_bag(b, validate_bag)
        except ConfigError:
            raise ConfigError(f"--validate {validate_bag} is one of the model's identification "
                              f'bags ({b}): validation needs a run the model never saw') from None


# ----------------------------------------------------------------------------- measured runs

def measured_run(src, t0=None):
    """A Source's measured rows from t0 on (default: the first) as a run for core.simulation.zigzag
    /
    steering / thrust_fit: ``t`` (s, from t0), ``x`` (N, 12; unmeasured channels 0),
    ``inputs`` rudder (rad, the command in force: what the bag logs as the rudder) and thrust
    (N), ``base`` the inputs (7,) of the first row."""
    t_all = np.asarray(src.t)
    t0 = t_all[0] if t0 is None else t0
    rows = np.any(np.isfinite(src.Y), axis=1) & (t_all >= t0)
    t = t_all[rows]
    return SimpleNamespace(t=t - t0, x=np.where(np.isfinite(src.Y[rows]), src.Y[rows], 0.0),
                           inputs={'rudder': src.U[rows, Input.DELTA_R],
                                   'thrust': src.U[rows, Input.THRUST]},
                           base=src.U[rows][0], name=src.description)


def uses_thrust(vehicle):
    """True for a vehicle whose measured thrust is an input (propulsion: measured_thrust)."""
    return (vehicle.raw.get('propulsion') or {}).get('model') == 'measured_thrust'


def helm_and_thrust(vehicle, runs, bags):
    """(GearIdentification, ThrustModel or None) from the identification runs; DataError
    naming the bags when their rudder or thrust cannot give them."""
    try:
        ident = identify_steering_gear(runs)
    except DataError as err:
        raise DataError(f'steering gear from the identification bags {", ".join(bags)}: '
                        f'{err}') from None
    thrust = None
    if uses_thrust(vehicle):
        for r, b in zip(runs, bags):
            if not np.any(np.abs(r.inputs['thrust']) > 0):
                raise DataError(f'identification bag {b} has no thrust (the thrust input of '
                                f'{vehicle.name} is 0 throughout): no thrust model for the '
                                'closed-loop zig-zag')
        thrust = fit_thrust_model([(r.x, r.inputs['thrust']) for r in runs])
    return ident, thrust


def detect_zigzag(run):
    """(ZigzagMeasures, None) if the run is a zig-zag, else (None, why): recognised by its
    rudder and heading pattern (core/simulation/zigzag.py zigzag_problem: the rudder switching
    sign between +-delta after the heading deviation passes +-psi, within a helm's lag; the
    lags are in the measures, not a reason to refuse)."""
    from auv_ident.analysis.zigzag import measured_measures
    try:
        m = measured_measures(run)
    except DataError as err:
        return None, str(err)
    why = zigzag_problem(m)
    return (None, why) if why else (m, None)


def screening_doc(validate_bag, src, ident_bags, ident_srcs):
    """{'how', 'bags': {bag: {'role', 'line', counts...}}}: what reading each bag without the
    filter dropped (offline/replay.py rejections: malformed messages only)."""
    bags = {str(validate_bag): dict(src.screening[0], role='validation',
                                    line=src.screening[1])}
    for b, s in zip(ident_bags, ident_srcs):
        bags[str(b)] = dict(s.screening[0], role='gear and thrust', line=s.screening[1])
    return {'how': 'every well-formed odometry message paired with the command in force at '
                   'its stamp; no innovation gate (a model under test cannot drop samples)',
            'bags': bags}


def screening_lines(doc):
    """One line per bag read: what its screening dropped."""
    return [f'{b} ({d["role"]}): {d["line"]}' for b, d in doc['bags'].items()]


# ------------------------------------------------------------------------------ the zig-zag

def _sim_doc(sim):
    if sim is None:
        return None
    m = sim.measures
    return {'overshoot_deg': [] if m is None else list(m.overshoots_deg),
            'time_to_overshoot_s': [] if m is None else list(m.times_to_overshoot),
            'stopped': sim.stopped}


def zigzag_validation(saved, run, x0, ident_runs, ident_bag_names):
    """The closed-loop zig-zag section: dict for result.json and the simulations, or a
    {'detected': False, 'reason'} dict."""
    m_meas, why = detect_zigzag(run)
    if m_meas is None:
        return {'detected': False, 'reason': why}, None
    v = saved.vehicle
    ident, thrust = helm_and_thrust(v, ident_runs, ident_bag_names)
    identified = Model(v, coefficient_values=Model(v, saved.names).coefficients_with(
        saved.estimate), current=saved.current)
    prior = Model(v)
    sim = dict(inputs=np.array(run.base, dtype=float))
    if thrust is not None:
        sim.update(thrust=thrust, thrust_index=Input.THRUST)
    ideal = SteeringGear.ideal(ident.gear.rate_deg_s, ident.gear.limit * DEG)
    m, sim_g, sim_i = closed_loop(run, lambda x, u: identified.f(x, u), ident, ideal, x0=x0,
                                  **sim)
    _, prior_g, _ = closed_loop(run, lambda x, u: prior.f(x, u), ident, None, x0=x0, **sim)
    doc = {'detected': True, 'test': m.label, 'first': m.first,
           'rudder_deg': m.nominal[0], 'switch_deg': m.nominal[1],
           'execute_time_s': m.execute_time,
           # the measured helm: how far past the switch angle each reversal came (deg, s)
           'reversal_lag_deg': list(m.reversal_lag_deg),
           'reversal_lag_s': list(m.reversal_lag_s),
           'overshoot_deg': {'measured': list(m.overshoots_deg),
                             'predicted': _sim_doc(sim_g)['overshoot_deg'],
                             'prior': _sim_doc(prior_g)['overshoot_deg'],
                             'predicted_ideal_helm': _sim_doc(sim_i)['overshoot_deg']},
           'time_to_overshoot_s': {'measured': list(m.times_to_overshoot),
                                   'predicted': _sim_doc(sim_g)['time_to_overshoot_s'],
                                   'prior': _sim_doc(prior_g)['time_to_overshoot_s'],
                                   'predicted_ideal_helm': _sim_doc(sim_i)['time_to_overshoot_s']},
           'stopped': {'predicted': sim_g.stopped, 'prior': prior_g.stopped,
                       'predicted_ideal_helm': sim_i.stopped},
           'gear': dict(ident.gear.as_dict(), rms_deg=ident.rms_deg,
                        reversals=len(ident.reversals), identified_from=list(ident_bag_names),
                        how='dead time + rate-limited first-order servo fitted to every rudder '
                            'reversal of the identification runs (core/simulation/steering.py)'),
           'ideal_helm': ideal.as_dict(),
           'thrust_model': None if thrust is None else dict(
               thrust.as_dict(), fitted_on=list(ident_bag_names))}
    return doc, {'measured': m, 'predicted': sim_g, 'prior': prior_g, 'ideal': sim_i}


# ------------------------------------------------------------------ rudder-neutral diagnosis

def rudder_bias(saved, val):
    """The constant rudder bias (deg, added to the measured rudder) whose free run of the
    saved model fits the run's yaw rate best, and the fits (%) with it: a diagnosis made after
    the scores, never part of them. None when the run does not measure r, or when the
    vehicle's model has no rudder (a thruster vehicle: no term multiplies the rudder angle, so
    every bias flies the same run and the search would report its bound)."""
    r = val.Y[:, State.R]
    v = saved.vehicle
    if not np.any(np.isfinite(r)) or Input.DELTA_R not in vehicle_actuators(v):
        return None
    model = Model(v, coefficient_values=Model(v, saved.names).coefficients_with(saved.estimate),
                  current=saved.current, velocity_reference=val.velocity_reference)

    def run_with(bias_deg):
        U = val.U.copy()
        U[:, Input.DELTA_R] += bias_deg / DEG
        return free_run(lambda x, u: model.f(x, u), val.t, U, val.x0)

    def cost(bias_deg):
        f = fit_percent(r, run_with(bias_deg)[:, State.R])
        return 1e3 if not np.isfinite(f) else -f

    best = minimize_scalar(cost, bounds=(-BIAS_BOUND_DEG, BIAS_BOUND_DEG), method='bounded',
                           options={'xatol': BIAS_TOL_DEG})
    X = run_with(best.x)
    return {'bias_deg': float(best.x), 'search_deg': [-BIAS_BOUND_DEG, BIAS_BOUND_DEG],
            'r_fit_percent_with_bias': -float(best.fun),
            'U_fit_percent_with_bias': fit_percent(mv.speed_series(val.Y), mv.speed_series(X)),
            'at_bound': bool(abs(abs(best.x) - BIAS_BOUND_DEG) < 2 * BIAS_TOL_DEG)}


# -------------------------------------------------------------------------------- the files

def _series(val, X, ch):
    """(N,) SI series of channel ch ('U' or a state name) of X (val.Y: the measurement), the
    angles as scored (angle_channels: the measurement unwrapped, a prediction moved by whole
    turns onto it)."""
    if ch == 'U':
        return mv.speed_series(X)
    i = mv.STATE_NAMES.index(ch)
    Ym, Xp = angle_channels(val.Y, X)
    return (Ym if X is val.Y else Xp)[:, i]


def write_csv(path, val):
    """validation.csv: the measured rows of the free run, t (s) then <ch>_measured,
    <ch>_predicted, <ch>_prior for u, v (m/s), r (rad/s), U (m/s), psi (rad: the measurement
    unwrapped, the predictions moved by whole turns onto it), empty where not measured."""
    rows = np.any(np.isfinite(val.Y), axis=1)
    cols = [('t', val.t)]
    for ch in CSV_CHANNELS:
        cols += [(f'{ch}_measured', _series(val, val.Y, ch)),
                 (f'{ch}_predicted', _series(val, val.free['identified'], ch)),
                 (f'{ch}_prior', _series(val, val.free['prior'], ch))]
    with open(path, 'w', newline='', encoding='utf-8') as fh:
        w = csv.writer(fh)
        w.writerow([c for c, _ in cols])
        for k in np.flatnonzero(rows):
            w.writerow(['' if not np.isfinite(s[k]) else repr(float(s[k])) for _, s in cols])
    return path


def fig_free_run(path, val, title):
    """Heading, yaw rate and speed U: measured vs the saved and the prior model's free runs."""
    plt = pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(8.0, 7.5), sharex=True, layout='constrained')
    meas = np.any(np.isfinite(val.Y), axis=1)
    fits = val.document()
    for ax, (ch, scale, unit) in zip(axes, (('psi', DEG, 'deg'), ('r', DEG, 'deg/s'),
                                            ('U', 1.0, 'm/s'))):
        d = (fits['derived_channels'] if ch == 'U' else fits['channels']).get(ch, {})
        ax.plot(val.t[meas], scale * _series(val, val.Y, ch)[meas], '.', color='0.45', ms=1.5,
                label='measured')
        for name, style in (('identified', dict(color='C3', lw=1.3)),
                            ('prior', dict(color='C0', lw=1.1, ls='--'))):
            ax.plot(val.t, scale * _series(val, val.free[name], ch), label=f'{name} model',
                    **style)
        ax.set_ylabel(f'{ch} ({unit})')
        ax.set_title(f'{ch}: fit % identified {finite_cell(d.get("fit_percent"), ".1f")}, prior '
                     f'{finite_cell(d.get("fit_percent_prior"), ".1f")}', fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel('time (s)')
    axes[0].legend(fontsize=7, markerscale=4)
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)


def fig_zigzag(path, run, sims, title):
    """Heading deviation and rudder of the measured run and the closed-loop zig-zags."""
    plt = pyplot()
    m = sims['measured']
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8.0, 6.0), sharex=True, layout='constrained')
    psi = np.unwrap(run.x[:, State.PSI]) * DEG
    a1.plot(run.t, psi - m.initial_heading_deg, color='0.3', lw=1.6, label='measured')
    a2.plot(run.t, run.inputs['rudder'] * DEG, color='0.3', lw=1.6, label='measured')
    for key, label, style in (('predicted', 'identified model + identified gear',
                               dict(color='C3', lw=1.2)),
                              ('ideal', 'identified model + ideal helm',
                               dict(color='C2', lw=1.0, ls=':')),
                              ('prior', 'prior model + identified gear',
                               dict(color='C0', lw=1.1, ls='--'))):
        s = sims[key]
        a1.plot(s.t, np.unwrap(s.x[:, State.PSI]) * DEG - m.initial_heading_deg, label=label,
                **style)
        a2.plot(s.t, s.rudder * DEG, label=label, **style)
    for a in (a1, a2):
        a.grid(alpha=0.3)
    sw = m.nominal[1]
    a1.axhline(sw, color='k', lw=0.5)
    a1.axhline(-sw, color='k', lw=0.5)
    a1.set_ylabel('heading deviation (deg, + starboard)')
    a2.set_ylabel('rudder delta_r (deg, + port)')
    a2.set_xlabel('time from the first sample (s)')
    a1.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)


def _clean(d):
    """JSON-ready: NaN and inf as null (strict JSON has neither)."""
    if isinstance(d, dict):
        return {k: _clean(x) for k, x in d.items()}
    if isinstance(d, (list, tuple)):
        return [_clean(x) for x in d]
    if isinstance(d, (float, np.floating)):
        return float(d) if np.isfinite(d) else None
    if isinstance(d, np.integer):
        return int(d)
    return d


def _f(v, fmt='.2f'):
    return finite_cell(None if v is None else float(v), fmt)


def zigzag_lines(zz):
    """The report's closed-loop zig-zag section (lines)."""
    L = ['', '## Closed-loop zig-zag', '']
    if not zz['detected']:
        return L + [f'Not a zig-zag run ({zz["reason"]}): no closed-loop comparison.']
    g = zz['gear']
    L += [f'The run is a {zz["test"]} zig-zag, first to {zz["first"]} (detected on the measured '
          'heading and rudder, core/simulation/zigzag.py). The helm orders the rudder '
          f'{zz["rudder_deg"]:g} deg at the estimated order time {zz["execute_time_s"]:.2f} s '
          f'and reverses it each time the heading deviation passes {zz["switch_deg"]:g} deg; '
          'the order goes through a **steering gear identified from the measured rudder of '
          f'the identification runs** ({", ".join(g["identified_from"])}; {g["reversals"]} '
          f'reversals): dead time {g["delay_s"]:.3f} s, rate {g["rate_deg_s"]:.2f} deg/s, '
          f'servo time constant {g["time_constant_s"]:.3f} s, rms {g["rms_deg"]:.3f} deg. '
          'The ideal helm has no dead time and no servo lag, the same rate.']
    lag_d, lag_s = zz['reversal_lag_deg'], zz['reversal_lag_s']
    L += ['', 'The measured helm reversed the rudder '
          + ', '.join(f'{d:.2f} deg / {t:.2f} s' for d, t in zip(lag_d, lag_s))
          + f' past the {zz["switch_deg"]:g} deg switch angle (reversal lag per reversal: '
          'heading deviation at the rudder onset minus the switch angle, and time since the '
          'heading passed it); the closed loops reverse through the identified gear at the '
          'switch angle itself.']
    th = zz['thrust_model']
    L += ['', 'Thrust: ' + ("not an input of this vehicle (the shaft speed of the run's first "
                            'sample is held).' if th is None else
                            f'{th["formula"]}, fitted on the identification runs '
                            f'({", ".join(th["fitted_on"])}; rms {th["rms_N"]:.2f} N).'), '']
    o, tt = zz['overshoot_deg'], zz['time_to_overshoot_s']
    n = max(len(v) for v in o.values())
    rows = []
    for k in range(n):
        def at(key, d=o):
            return _f(d[key][k]) if k < len(d[key]) else '-'
        err = (_f(o['predicted'][k] - o['measured'][k], '+.2f')
               if k < len(o['predicted']) and k < len(o['measured']) else '-')
        rows.append([str(k + 1), at('measured'), at('predicted'), err, at('prior'),
                     at('predicted_ideal_helm'), at('measured', tt), at('predicted', tt)])
    L += markdown_table(['overshoot', 'measured (deg)', 'identified + gear (deg)',
                         'identified - measured (deg)', 'prior + gear (deg)',
                         'identified + ideal helm (deg)', 'time to it, measured (s)',
                         'time to it, identified (s)'], rows).split('\n')
    for k, why in zz['stopped'].items():
        if why:
            L += ['', f'The {k} closed loop stopped early: {why}.']
    return L


def markdown(doc, figures):
    val = doc['validation']
    L = [f'# Model validation: {doc["vehicle_title"]}', '',
         f'Command: `{doc["command"] or "(not given)"}`', '',
         'Versions: ' + ', '.join(f'{k} {s}' for k, s in doc['versions'].items()), '',
         f'- model: {doc["model"]} ({len(doc["coefficients"])} coefficients, vehicle '
         f'{doc["vehicle"]})',
         f'- identified from: {", ".join(doc["identification_bags"]) or "(not recorded)"}',
         f'- validated on: {doc["validation_bag"]}, a run the identification never saw', '',
         '## Coefficients of the model', '']
    L += markdown_table(['coefficient', 'prior (vehicle file)', 'estimate', '1-sigma'],
                        [[n, _f(c['prior'], '.5g'), _f(c['estimate'], '.5g'),
                          _f(c['std'], '.3g')] for n, c in doc['coefficients'].items()]
                        ).split('\n')
    L += mv.markdown_lines(val)
    L += ['', 'The bags were read without the filter (' + val['screening']['how'] + '):', '']
    L += ['- ' + line for line in screening_lines(val['screening'])]
    L += zigzag_lines(val['zigzag'])
    b = val.get('rudder_bias_diagnosis')
    if b:
        L += ['', '## Diagnosis: rudder neutral', '',
              'After the scores above (which it does not change): the constant bias added to '
              "the measured rudder that makes the identified model's free run fit the yaw rate "
              f'best is {b["bias_deg"]:+.2f} deg (searched within +-{BIAS_BOUND_DEG:g} deg; yaw-'
              f'rate fit {b["r_fit_percent_with_bias"]:.1f} %, speed U fit '
              f'{b["U_fit_percent_with_bias"]:.1f} % with it). A value of a few tenths of a '
              "degree or more says the run's rudder zero differs from that of the "
              'identification runs (or the model has an asymmetry it does not know).'
              + (' The bias is at the edge of the search: the yaw rate is not explained by a '
                 'rudder offset.' if b['at_bound'] else '')]
    L += ['', '## Files', '',
          '- `validation.csv`: the scored series, the measured rows of the free run: t (s), '
          'then `<ch>_measured`, `<ch>_predicted` (identified model), `<ch>_prior` for u, v '
          '(m/s), r (rad/s), U = sqrt(u^2 + v^2) (m/s), psi (rad, unwrapped); fit % = 100 '
          '(1 - ||y - y_hat|| / ||y - mean y||) recomputed from it gives the table above.',
          '- `result.json`: everything in this report.', '', '## Figures', '']
    for name, p in figures.items():
        L += [f'![{name}]({os.path.basename(p)})', '']
    return '\n'.join(L)


# ----------------------------------------------------------------------------------- entry

def make_model_report(out_dir, model_path, validate_bag, vehicle=None, ident_bags=None,
                      command='', bias_diagnosis=True, input_map=None):
    """Judge the saved model on validate_bag and write the report (module docstring).

    Parameters
    ----------
    out_dir : folder, created; model_path : JSON of identify --json (single or several bags)
    validate_bag : bag of a run the model was not identified on
    vehicle : name or path; must be the model's (None: the model's)
    ident_bags : bags to identify the steering gear and the thrust model from (None: the
        model's identification bags)
    input_map : the bags' topics and fields (session/input_map.py; None: what each bag's
        metadata names, else the default /odom + /actuators)
    command : the command line (quoted in the report); bias_diagnosis : estimate the rudder
        bias after scoring

    Returns dict with 'report', 'html', 'json', 'csv', 'figures', 'result'.
    """
    from auv_ident.analysis.bag_identify import bag_source
    saved = load_model(model_path, vehicle)
    input_map = input_map or saved.input_map
    refuse_identification_bag(saved.bags, validate_bag)
    ident_bags = list(ident_bags) if ident_bags else saved.bags
    refuse_identification_bag(ident_bags, validate_bag)
    v = saved.vehicle
    if not os.path.exists(validate_bag):
        raise ConfigError(f'--validate {validate_bag}: no such bag')
    val, src = mv.validate_on_bag(v, saved.names, saved.estimate, saved.current, validate_bag,
                                  input_map=input_map)
    if src.vehicle.name != v.name:
        raise ConfigError(f'--validate {validate_bag} is a run of {src.vehicle.name!r}, the '
                          f'model one of {v.name!r}')
    run = measured_run(src, t0=val.t[0])
    vd = val.document()
    ident_runs, ident_srcs = [], []
    for b in ident_bags:
        if not os.path.exists(b):
            raise ConfigError(f'identification bag {b} (from the model, or --ident-bags) does '
                              'not exist: give --ident-bags A,B')
        # the measured rudder and thrust as the data are (no filter judges the samples)
        s = bag_source(b, IdentifierSettings.from_values(
            vehicle=v.path, coefficients=saved.names,
            input_map=input_map), filtering=False)
        mv.refuse_identification_run(s, src)
        ident_srcs.append(s)
        ident_runs.append(measured_run(s))
    if not ident_runs:
        raise ConfigError(f'--model {model_path} records no identification bag: give '
                          '--ident-bags A,B (the steering gear and thrust come from them)')
    zz, sims = zigzag_validation(saved, run, val.x0, ident_runs, ident_bags)
    vd['zigzag'] = zz
    vd['screening'] = screening_doc(validate_bag, src, ident_bags, ident_srcs)
    vd['rudder_bias_diagnosis'] = rudder_bias(saved, val) if bias_diagnosis else None
    os.makedirs(out_dir, exist_ok=True)
    prior = v.values
    doc = {'model': str(model_path), 'vehicle': v.name, 'vehicle_title': v.title,
           'identification_bags': saved.bags, 'gear_and_thrust_bags': ident_bags,
           'validation_bag': str(validate_bag), 'command': command, 'versions': package_versions(),
           'coefficients': {n: {'estimate': float(e), 'std': float(s),
                                'prior': float(prior[v.index(n)])}
                            for n, e, s in zip(saved.names, saved.estimate, saved.std)},
           'current': None if saved.current is None else [float(c) for c in saved.current],
           'validation': vd}
    json_path = os.path.join(out_dir, 'result.json')
    write_json(json_path, _clean(doc))
    csv_path = write_csv(os.path.join(out_dir, 'validation.csv'), val)
    figures = {'free_run': fig_free_run(os.path.join(out_dir, 'free_run.png'), val,
                                        f'{v.title}\nfree run on {src.description}')}
    if sims is not None:
        figures['zigzag'] = fig_zigzag(os.path.join(out_dir, 'zigzag.png'), run, sims,
                                       f'{v.title}: closed-loop {zz["test"]} zig-zag')
    md = markdown(doc, figures)
    md_path = os.path.join(out_dir, 'report.md')
    with open(md_path, 'w', encoding='utf-8') as fh:
        fh.write(md + '\n')
    html_path = write_html(md, out_dir, os.path.join(out_dir, 'report.html'))
    return {'report': md_path, 'html': html_path, 'json': json_path, 'csv': csv_path,
            'figures': figures, 'result': doc}

