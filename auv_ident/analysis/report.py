"""Report of one identification: figures, a Markdown summary and the result JSON.

The evidence of the paper's Section 4 for one run: convergence of the coefficients (Figs. 2-3),
the coefficient table (Tables 1-2) and the identified model against the true one on a manoeuvre
held out from identification (Figs. 4-5), plus the filter's consistency (NIS) and its adapted
noise covariances. ROS-free; matplotlib is imported inside the plotting code (Agg backend), so
importing this module never touches a display.
"""
from dataclasses import replace
import os

import numpy as np

from auv_ident.analysis import experiments as ex, results, validation as mv
from auv_ident.analysis.report_format import (
    cell as _num,
    finite_cell,
    markdown_table as _table,
    package_versions,
    pyplot as _plt,
    save_figure as _save,
)
from auv_ident.analysis.report_html import write_html
from auv_ident.analysis.report_noise import (
    diagnosis_lines,
    fig_innovation_autocorrelation,
    identifiability_markdown,
    noise_model_markdown,
)
from auv_ident.core.angles import wrap_angle
from auv_ident.core.errors import ConfigError
from auv_ident.core.identification.pipeline import identify_with_diagnosis
from auv_ident.core.identification.results import (
    confidence_words,
    percent,
    Record,
    SelectionRequest,
    times,
)
from auv_ident.core.identification.selection import AUTO
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.sensors import DEFAULT_PROCESS_STD, DEFAULT_T
from auv_ident.core.model.state import EULER, Input, N_STATE, State, STATE_NAMES
from auv_ident.core.model.trim import initial_state
from auv_ident.core.simulation.simulate import simulate
from auv_ident.session.settings import coefficient_request, IdentifierSettings
from auv_ident.vehicles import load_vehicle

HIST_POINTS = 1500       # history points kept for the time plots (enough to look continuous)
NIS_WINDOW_S = 10.0      # s, moving-average window of the NIS plot
DEG = 180.0 / np.pi

# Display scale and unit of each state channel (angles and rates in degrees: readable numbers)
SCALE = np.array([1, 1, 1, DEG, DEG, DEG, 1, 1, 1, DEG, DEG, DEG], dtype=float)
UNITS = ('m/s',) * 3 + ('deg/s',) * 3 + ('m',) * 3 + ('deg',) * 3
GROUPS = (('linear speeds', (State.U, State.V, State.W)),
          ('angular rates', (State.P, State.Q, State.R)),
          ('positions', (State.X, State.Y, State.Z)),
          ('attitudes', (State.PHI, State.THETA, State.PSI)))
LABELS = {'u': 'u (surge)', 'v': 'v (sway)', 'w': 'w (heave)', 'p': 'p (roll rate)',
          'q': 'q (pitch rate)', 'r': 'r (yaw rate)', 'x': 'x (north)', 'y': 'y (east)',
          'z': 'z (depth)', 'phi': 'phi (roll)', 'theta': 'theta (pitch)', 'psi': 'psi (yaw)'}


class Validation(tuple):
    """(t, X_true, X_ident, rms), plus the held-out manoeuvre's name, seed, rpm and inputs U.

    X_* are (N, 12) states in SI units (rad); rms maps each state name to the RMS difference
    X_ident - X_true in UNITS (angles wrapped before squaring)."""

    def __new__(cls, t, X_true, X_ident, rms, maneuver, seed, rpm, U):
        self = super().__new__(cls, (t, X_true, X_ident, rms))
        self.maneuver, self.seed, self.rpm, self.U = maneuver, seed, rpm, U
        return self

    t = property(lambda self: self[0])
    X_true = property(lambda self: self[1])
    X_ident = property(lambda self: self[2])
    rms = property(lambda self: self[3])


def _same_maneuver(a, b):
    if not a or not b:
        return False
    if os.path.isfile(a) and os.path.isfile(b):
        return os.path.samefile(a, b)
    return str(a) == str(b)


def validate(vehicle, names, estimate, maneuver='steps', duration=200.0, seed=1000, T=DEFAULT_T,
             rpm=None, identification_maneuver=None, process_std=DEFAULT_PROCESS_STD):
    """Simulate the true and the identified model on a held-out manoeuvre, same everything else.

    Both runs share the inputs, the initial state (the TRUE model's trim) and the process-noise
    realisation (same seed), so any difference comes from the coefficients alone.

    Parameters
    ----------
    vehicle : Vehicle or str
        Its file's values are the "true" model.
    names, estimate : identified coefficients and their values (vehicle-file units)
    maneuver : str, the validation manoeuvre (name or CSV)
    duration, T : s
    seed : int, seed of the process noise (and of seeded manoeuvres)
    rpm : shaft speed (the vehicle's cruise rpm if None)
    identification_maneuver : str, optional
        The manoeuvre identified on; validating on it raises ConfigError (not held out).
    process_std : (6,) white acceleration 1-sigma on nu_dot, None for none

    Returns
    -------
    Validation, a tuple (t, X_true, X_ident, rms) with .maneuver, .seed, .rpm, .U
    """
    if _same_maneuver(maneuver, identification_maneuver):
        raise ConfigError(f'validation manoeuvre {maneuver!r} is the identification manoeuvre: '
                          'validation must use a held-out manoeuvre (e.g. steps)')
    v = load_vehicle(vehicle) if isinstance(vehicle, str) else vehicle
    truth = Model(v)
    ident = Model(v, coefficient_values=Model(v, names).coefficients_with(estimate))
    rpm = v.cruise_rpm if rpm is None else float(rpm)
    x0 = initial_state(truth, rpm)
    runs = [simulate(m, maneuver, duration=duration, T=T, seed=seed, rpm=rpm,
                     noise_std=np.zeros(N_STATE), process_std=process_std, x0=x0)
            for m in (truth, ident)]
    err = runs[1].x - runs[0].x
    err[:, EULER] = wrap_angle(err[:, EULER])
    rms = {n: float(np.sqrt(np.mean((SCALE[i] * err[:, i]) ** 2)))
           for i, n in enumerate(STATE_NAMES)}
    return Validation(runs[0].t, runs[0].x, runs[1].x, rms, runs[0].maneuver, seed, rpm,
                      runs[0].u)


# ----------------------------------------------------------------------------------- figures

def _log_axis(ax, values=None):
    """Log y axis labelled 0.01, 0.02, 0.05, ... (not 2x10^-2), limits around `values`."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
    if values is not None:
        # limits first: flat, equal lines (fixed noise) would give the log scale a zero range
        v = np.asarray(values, dtype=float)
        v = v[np.isfinite(v) & (v > 0)]
        if v.size:
            ax.set_ylim(v.min() / 2.5, v.max() * 2.5)
    ax.set_yscale('log')
    ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda y, _: f'{y:g}'))
    ax.yaxis.set_minor_formatter(NullFormatter())


def _coef_unit(vehicle):
    return ('prime, nondim.' if vehicle.raw.get('scaling') != 'dimensional'
            else 'SI, vehicle-file units')


def fig_convergence(path, vehicle, res, noise_mode):
    """EKF estimate with its +-3-sigma band per coefficient, truth, initial and refined."""
    p = len(res.names)
    if p == 0:          # 'auto' alone chose no coefficient (the current alone): no panel
        return None
    plt = _plt()
    h = res.history
    ncol = 1 if p <= 3 else 2
    nrow = -(-p // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(6.5 * ncol, 2.6 * nrow + 0.8), sharex=True,
                             squeeze=False, layout='constrained')
    t = h['t']
    for i, n in enumerate(res.names):
        ax = axes.flat[i]
        th, sd = h['theta'][:, i], h['std'][:, i]
        ax.fill_between(t, th - 3 * sd, th + 3 * sd, color='C0', alpha=0.2, lw=0,
                        label='EKF $\\pm3\\sigma$')
        ax.plot(t, th, color='C0', lw=1.2, label='EKF estimate')
        ax.axhline(res.initial[i], color='0.5', ls=':', lw=1.2, label='initial guess')
        ref = [res.initial[i], res.estimate[i], res.ekf_estimate[i]]
        if res.truth is not None:
            ax.axhline(res.truth[i], color='k', ls='--', lw=1.2, label='true value')
            ref.append(res.truth[i])
        if res.refined:
            ax.errorbar([t[-1]], [res.estimate[i]], yerr=[3 * res.std[i]], fmt='o', color='C3',
                        ms=5, capsize=3, zorder=5, label='refined $\\pm3\\sigma$')
        # limits from the values that matter: the initial 3-sigma band would flatten the plot
        lo, hi = min(ref), max(ref)
        pad = max(0.3 * (hi - lo), 0.05 * max(abs(lo), abs(hi)), 1e-12)
        ax.set_ylim(lo - pad, hi + pad)
        title = f'{n}: refined {res.estimate[i]:.4g}'
        if res.truth is not None:
            title += f', true {res.truth[i]:.4g} (error {res.error_pct()[i]:+.2f} %)'
        ax.set_title(title, fontsize=9)
        ax.set_ylabel(f'{n} ({_coef_unit(vehicle)})', fontsize=8)
        ax.grid(alpha=0.3)
    for k in range(p, nrow * ncol):        # empty slot: the panel above keeps its time axis
        axes.flat[k].set_visible(False)
        axes.flat[k - ncol].xaxis.set_tick_params(labelbottom=True)
        axes.flat[k - ncol].set_xlabel('time (s)')
    for ax in axes[-1]:
        ax.set_xlabel('time (s)')
    axes.flat[0].legend(fontsize=7, loc='best')
    fig.suptitle(f'{vehicle.title}: coefficient convergence (noise mode {noise_mode!r})')
    return _save(fig, path)


def _overlay(path, val, rows, title, reference):
    """Grid of true-vs-identified channels; rows is a list of rows of state indices."""
    plt = _plt()
    ncol = len(rows[0])
    fig, axes = plt.subplots(len(rows), ncol, figsize=(max(9.0, 6.0 * ncol),
                                                       2.2 * len(rows) + 1.0),
                             sharex=True, squeeze=False, layout='constrained')
    t, Xt, Xi, rms = val
    for r, row in enumerate(rows):
        for c, i in enumerate(row):
            ax = axes[r, c]
            a, b = Xt[:, i], Xi[:, i]
            if i == State.PSI:   # heading: unwrap, or a +-180 deg jump hides the comparison
                a, b = np.unwrap(a), np.unwrap(b)
            n = STATE_NAMES[i]
            ax.plot(t, SCALE[i] * a, color='k', lw=1.4, label=reference)
            ax.plot(t, SCALE[i] * b, color='C3', lw=1.2, ls='--', label='identified model')
            ax.set_ylabel(f'{n} ({UNITS[i]})')
            ax.set_title(f'{LABELS[n]}: RMS difference {rms[n]:.3g} {UNITS[i]}', fontsize=9)
            ax.grid(alpha=0.3)
            if i == State.Z:
                ax.invert_yaxis()    # depth grows downwards
    for ax in axes[-1]:
        ax.set_xlabel('time (s)')
    axes[0, 0].legend(fontsize=8, loc='best')
    fig.suptitle(title)
    return _save(fig, path)


def fig_nis(path, res, T, hist_every):
    """Per-step NIS and its moving average against their chi-square 95 % bands."""
    from scipy.stats import chi2
    plt = _plt()
    h = res.history
    t, nis, dof = h['t'], h['nis'], h['dof']
    ok = np.isfinite(nis) & (dof > 0)
    ok[:1] = False     # the first update sets the state from y0 itself: NIS ~ 0, no evidence
    dofs = np.where(ok, dof, np.nan)
    w = max(1, int(round(NIS_WINDOW_S / (hist_every * T))))
    num = np.convolve(np.where(ok, nis, 0.0), np.ones(w))[:len(nis)]
    cnt = np.convolve(ok.astype(float), np.ones(w))[:len(nis)]
    dsum = np.convolve(np.where(ok, dof, 0.0), np.ones(w))[:len(nis)]
    with np.errstate(invalid='ignore', divide='ignore'):
        ma = num / cnt
        # the mean of n independent chi2(d) NIS is chi2(sum d) / n
        ma_lo = chi2.ppf(0.025, dsum) / cnt
        ma_hi = chi2.ppf(0.975, dsum) / cnt
    fig, ax = plt.subplots(figsize=(10, 5.0), layout='constrained')
    ax.plot(t[ok], nis[ok], '.', color='0.55', ms=2, label='NIS per step')
    ax.plot(t, chi2.ppf(0.025, dofs), color='C2', ls='--', lw=1,
            label='95 % band per step')
    ax.plot(t, chi2.ppf(0.975, dofs), color='C2', ls='--', lw=1)
    ax.fill_between(t, ma_lo, ma_hi, color='C0', alpha=0.2, lw=0,
                    label=f'95 % band of the {NIS_WINDOW_S:.0f} s mean')
    ax.plot(t, ma, color='C0', lw=1.6, label=f'{NIS_WINDOW_S:.0f} s moving mean')
    d = int(np.nanmedian(dofs)) if ok.any() else 0
    # limits from the bands: the first update (state set from y0) has NIS ~ 0
    _log_axis(ax, [chi2.ppf(0.005, max(d, 1)), np.nanmax(nis[ok]) if ok.any() else 1.0])
    ax.set_xlabel('time (s)')
    ax.set_ylabel('NIS $\\nu^T S^{-1} \\nu$ (dimensionless)')
    ax.set_title(f'Normalised innovation squared ({d} degrees of freedom; mean NIS/dof '
                 f'{res.mean_nis_per_dof:.3f}, expected 1)', fontsize=10)
    ax.grid(alpha=0.3, which='both')
    fig.legend(fontsize=8, loc='outside lower center', ncol=4)
    return _save(fig, path)


def fig_noise(path, res, noise_mode):
    """Adapted R diagonal as 1-sigma per channel group, and Q_theta diagonal per coefficient."""
    plt = _plt()
    h = res.history
    t = h['t']
    fig, axes = plt.subplots(5, 1, figsize=(10, 12.5), sharex=True, layout='constrained')
    # equal channels (u, v, w share a sensor) would hide each other: vary the line style
    styles = ('-', '--', ':', '-.', (0, (5, 1, 1, 1, 1, 1)))
    sd = np.sqrt(h['R_diag'])
    for ax, (group, idx) in zip(axes, GROUPS):
        for k, i in enumerate(idx):
            ax.plot(t, SCALE[i] * sd[:, i], lw=2.4 - 0.5 * k, ls=styles[k],
                    label=STATE_NAMES[i])
        ax.set_ylabel(f'R 1-sigma ({UNITS[idx[0]]})')
        ax.set_title(f'measurement noise 1-sigma, {group}', fontsize=9)
        _log_axis(ax, SCALE[list(idx)] * sd[:, idx])
    p = len(res.names)       # the coefficients (any current components follow them)
    qrel = np.sqrt(h['Q_theta_diag'][:, :p]) / np.abs(res.initial)[None, :]
    for i, n in enumerate(res.names):
        axes[4].plot(t, qrel[:, i], lw=2.4 - 0.3 * (i % 5), ls=styles[i % 5], label=n)
    axes[4].set_ylabel('Q 1-sigma / |initial guess|')
    axes[4].set_title('coefficient random walk 1-sigma per step, relative to the initial guess',
                      fontsize=9)
    _log_axis(axes[4], qrel)
    axes[4].set_xlabel('time (s)')
    for ax in axes:
        ax.grid(alpha=0.3, which='both')
        if ax.get_legend_handles_labels()[0]:       # no coefficient: nothing to label
            ax.legend(fontsize=8, loc='center left', bbox_to_anchor=(1.01, 0.5))
    note = ('\nmode fixed: Q and R are not adapted and stay at their configured values'
            if noise_mode == 'fixed' else '')
    fig.suptitle(f'Noise covariances used by the EKF, adaptation mode {noise_mode!r}{note}',
                 fontsize=11)
    return _save(fig, path)


# ---------------------------------------------------------------------------------- markdown

def _markdown(doc, src, cfg, val_error, figures, command, holdout=None):
    v = src.vehicle
    co = doc['coefficients']
    known = src.truth is not None
    L = [f'# Identification report: {v.title}', ''] + diagnosis_lines(doc) + [
         f'Command: `{command or "(not given)"}`', '',
         'Versions: ' + ', '.join(f'{k} {s}' for k, s in doc['versions'].items()), '',
         f'- source: {src.description}',
         f'- seed: {doc["seed"] if doc["seed"] is not None else "- (recorded data)"}',
         f'- coefficients ({doc["units"]}): {", ".join(co)}',
         f'- water current: {doc["current_option"]}; velocities over '
         f'{doc["velocity_reference"]}',
         f'- mass inverse: {doc["mass_inverse"]} (every model of this report)',
         f'- noise adaptation: {doc["noise_mode"]}; EKF pass + batch refinement '
         '(filter-error maximum likelihood)',
         '- configured sensor noise 1-sigma (u v w m/s, p q r rad/s, x y z m, phi theta psi '
         'rad): '
         + ' '.join(f'{s:g}' for s in doc['noise_std']),
         '- EKF state process noise 1-sigma per step (same units): '
         + ' '.join(f'{s:g}' for s in cfg.q_state),
         f'- coefficient random walk 1-sigma per step: {cfg.q_theta_rel:g} x |initial guess|; '
         f'initial 1-sigma {cfg.p0_rel:g} x |initial guess|',
         f'- {doc["steps"]} EKF steps, mean NIS/dof '
         f'{finite_cell(doc["mean_nis_per_dof"], ".3f")} '
         f'(expected 1), wall {doc["wall_s"]:.1f} s', '',
         '## Coefficients', '',
         'Refined (batch filter-error) estimates; the same numbers are in `result.json`.'
         + ('' if known else ' Truth unknown for this source: no errors are given.'), '']
    L.append(_table(['coefficient', 'truth', 'estimate', '1-sigma', 'error %', 'paper estimate',
                     'paper error %'],
                    [[n, _num(c['truth']), _num(c['estimate']), _num(c['std']),
                      _num(c['error_pct']), _num(c['paper_estimate']),
                      _num(c['paper_error_pct'])] for n, c in co.items()]))
    L += ['', '### EKF pass alone vs refined', '']
    L.append(_table(['coefficient', 'initial', 'EKF estimate', 'EKF 1-sigma', 'EKF error %',
                     'refined estimate', 'refined error %'],
                    [[n, _num(c['initial']), _num(c['ekf_estimate']), _num(c['ekf_std']),
                      _num(c['ekf_error_pct']), _num(c['estimate']), _num(c['error_pct'])]
                     for n, c in co.items()]))
    L += _selection_markdown(doc)
    L += _current_markdown(doc)
    L += noise_model_markdown(doc)
    L += identifiability_markdown(doc)
    L += mv.markdown_lines(doc['validation'], holdout)
    L += _true_model_markdown(doc, src, val_error)
    L += ['', '## Figures', '']
    captions = {
        'convergence': 'EKF estimates with their 3-sigma bands, the true values, the initial '
                       'guesses and the refined estimates (cf. the paper, Figs. 2-3)',
        'measured_speeds': 'validation run: measured speeds and rates vs the free runs of the '
                           'identified and the prior model',
        'measured_pose': 'validation run: measured positions and attitudes vs the free runs of '
                         'the identified and the prior model',
        'validation_positions': 'positions, true vs identified model (cf. Fig. 4)',
        'validation_attitudes': 'attitudes, true vs identified model (cf. Fig. 4)',
        'validation_speeds': 'linear and angular speeds, true vs identified model (cf. Fig. 5)',
        'nis': 'normalised innovation squared against its chi-square 95 % bands',
        'adapted_noise': 'measurement and coefficient noise covariances over time',
        'innovation_autocorrelation': 'autocorrelation of the whitened innovations per '
                                      'channel, against the band of white noise'}
    for key, p in figures.items():
        L += [f'![{captions[key]}]({os.path.basename(p)})', '', f'*{captions[key]}*', '']
    return '\n'.join(L)


def _true_model_markdown(doc, src, val_error):
    """The section on the simulated held-out manoeuvre, true vs identified model (lines),
    when the truth is known."""
    vd = doc.get('validation_true_model')
    if not vd:
        return []
    L = ['', '## Validation on a held-out manoeuvre, against the true model', '',
         f'Manoeuvre {vd["maneuver"]!r} (not used for identification, which used '
         f'{src.maneuver or "the bag"!r}), {vd["duration_s"]:g} s at {vd["rpm"]:g} rpm, '
         f'process noise 1-sigma {" ".join(f"{s:g}" for s in vd["process_std"])} '
         f'(m/s^2, rad/s^2) with seed {vd["seed"]}. The reference and the identified model '
         'share the inputs, the initial state and the process-noise realisation, so the '
         'differences come from the coefficients alone.', '']
    if val_error:
        L += [f'The identified model could not be simulated: {val_error}']
    else:
        L.append(_table(['channel', 'RMS difference', 'unit'],
                        [[n, _num(vd['rms'][n]), vd['rms_units'][n]] for n in STATE_NAMES]))
    return L


def _selection_markdown(doc):
    """The report's section on the automatic choice of coefficients (lines), empty when the
    coefficients were named (`--coefficients auto[,NAME,...]`,
    core/identification/selection.py)."""
    sel = doc.get('selection')
    if not sel:
        return []
    L = ['', '## Automatic selection', '',
         f'{len(sel["chosen"])} of {sel["candidates"]} candidate coefficients chosen from the '
         'identification data (' + sel['criteria']['method'] + '): '
         + ', '.join(sel['chosen'])
         + (f'; always included (named): {", ".join(sel["named"])}' if sel['named'] else '')
         + ". The others keep the vehicle file's values; the error bars include their "
         'errors as far as the residuals allow them (consider analysis'
         + (f': {percent(sel["consider_scale"])} of their values, 1-sigma, '
            + confidence_words(sel['criteria']['consider_confidence'])
            if sel.get('consider_scale') is not None else '') + ').', '']
    widened = {n: r for n, r in sel.get('consider_inflation', {}).items() if r >= 1.005}
    if widened:
        sources = sel.get('consider_sources') or {}
        L.append(_table(['coefficient', 'error bar / statistical one', 'widening from (share)'],
                        [[n, times(r), ', '.join(f'{k} {100 * f:.0f} %' for k, f in
                                                 sources.get(n, {}).items()) or '-']
                         for n, r in widened.items()]))
        L.append('')
    groups = {}     # by the reason's kind, as Selection.summary (figures in result.json)
    for name, why in sel['left_out'].items():
        groups.setdefault(why.split(':')[0].split(' (')[0], []).append(name)
    L.append(_table(['left out (file values kept)', 'reason (per coefficient in result.json '
                     '`selection`)'], [[', '.join(names), why] for why, names in groups.items()]))
    return L


def _current_markdown(doc):
    """The report's water-current section (lines), empty when no current was identified or
    given."""
    cur = doc.get('current')
    if not cur:
        return []
    L = ['', '## Water current', '',
         'Estimated with the coefficients (m/s, NED: where the water goes); components not '
         'estimated are held at the value shown. Velocities measured over '
         f'{cur["velocity_reference"]}.', '']
    rows = []
    for i, key in enumerate(('north', 'east', 'down')):
        est = f'current_{key[0]}' in cur['estimated']
        rows.append([key, _num(cur['truth'][i]) if cur.get('truth') else '-', _num(cur[key]),
                     _num(cur['std'][i]) if est else 'given',
                     _num(cur['ekf'][key]) if est else '-'])
    L.append(_table(['component', 'truth', 'estimate', '1-sigma', 'EKF pass'], rows))
    L += ['', f'Speed {cur["speed"]:.4g} m/s towards {cur["direction_deg"]:.1f} deg (clockwise '
              'from north).']
    ident = cur.get('identifiability')
    if ident:
        L += ['', f'Headings covered: {ident["heading_span_deg"]:.0f} deg; '
                  + (f'largest correlation of a current component with a coefficient: '
                     f'{ident["max_correlation"]:.2f} ({ident["correlated_with"]}).'
                     if ident['correlated_with'] else 'no coefficient identified with it.')]
    for w in doc.get('warnings') or []:
        L += ['', f'**{w}**']
    return L


# ------------------------------------------------------------------------------------ driver

# what make_report takes of its settings (the command line's report options)
REPORT_SETTINGS = ('vehicle', 'coefficients', 'noise_mode', 'current', 'current_down',
                   'velocity_reference', 'mass_inverse', 'input_map')


def _sources(settings, simulate_maneuver, bag, seed, duration, sim_current, validate_bag,
             holdout, validation_maneuver):
    """(identification Source, validation Source, holdout or None, named or None) of
    make_report: named is the list of coefficients ['auto', NAME, ...] always includes (a bag;
    the source is then paired for the named, or the default, set, and the set to identify is
    chosen from the identification data)."""
    from auv_ident.analysis.bag_identify import bag_source
    coefficients = settings.coefficients
    auto = bool(bag) and bool(coefficients) and coefficients[0].lower() == AUTO
    paired = settings.with_values(coefficients=coefficients[1:]) if auto else settings
    full = ex.load_source(paired, simulate_maneuver=simulate_maneuver, bag=bag, seed=seed,
                          duration=duration, sim_current=sim_current)
    named = coefficient_request(full.vehicle, coefficients)[1] if auto else None
    # fail before the long identification if the validation would not be held out
    if _same_maneuver(validation_maneuver, full.maneuver):
        raise ConfigError(f'validation manoeuvre {validation_maneuver!r} is the identification '
                          'manoeuvre: validation must use a held-out manoeuvre')
    if not validate_bag:
        src, run = mv.split_held_out(full, holdout)
        return src, run, holdout, named
    v = full.vehicle
    # the validation run as the data are: no filter's gate drops samples the model disagrees
    # with (bag_source filtering False)
    run = bag_source(validate_bag, IdentifierSettings.from_values(
        vehicle=v.path, coefficients=full.names, mass_inverse=v.mass_inverse,
        velocity_reference=(settings.velocity_reference if 'velocity_reference'
                            in settings.given else full.velocity_reference),
        input_map=settings.input_map if 'input_map' in settings.given else None),
        filtering=False)
    mv.refuse_identification_run(full, run)
    return full, run, None, named


def _identify(src, cfg, opt, named, hist_every, progress):
    """(Identification, the Source of the identified set) of make_report: the set chosen from
    the data when `named` is a list (coefficients ['auto', ...]; res.selection says how), else
    src's."""
    from auv_ident.analysis.progress import Progress
    v = src.vehicle
    bar = Progress(40 * len(src.names), 'batch refinement') if progress else None

    def make_model(names):
        return Model(v, list(names) + opt.names, current=opt.fixed,
                     velocity_reference=src.velocity_reference)
    auto = named is not None
    res = identify_with_diagnosis(None if auto else make_model(src.names), cfg,
                                  [Record(src.t, src.Y, src.U)], T=src.T, refine_pass=True,
                                  hist_every=hist_every, truth=None if auto else src.truth,
                                  progress=bar.update if bar else None,
                                  auto=SelectionRequest(make_model, tuple(named)) if auto
                                  else None)
    if auto:
        # the truth of the chosen set (known for a simulated source: the vehicle file); from
        # here on the source identifies the chosen set (validation, methods, report)
        truth = (None if src.truth is None
                 else Model(v, list(res.names)).theta_true[:len(res.names)])
        res = replace(res, truth=truth)
        src = replace(src, names=list(res.names), truth=res.truth)
    if bar:
        bar.close()
    return res, src


def make_report(out_dir, settings=None, simulate_maneuver=None, bag=None, seed=0,
                duration=600.0, command='', validation_maneuver='steps',
                validation_duration=200.0, progress=True, sim_current=None, validate_bag=None,
                holdout=mv.DEFAULT_HOLDOUT, methods=None):
    """Identify (noise model from the data, EKF + batch refinement, diagnosis), validate
    against the measurements of a held-out run (and, when the truth is known, against the true
    model on a held-out manoeuvre), write the report: report.md, report.html (self-contained),
    result.json and PNG figures.

    Parameters
    ----------
    out_dir : str, created if missing
    settings : IdentifierSettings (None: the defaults), of which REPORT_SETTINGS apply: the
        vehicle and coefficients (as experiments.load_source; with a bag, coefficients may also
        be ['auto', NAME, ...]: the set is chosen from the identification data,
        core/identification/selection.py, and validated, result.json gets `selection`), the
        noise_mode (Q/R adaptation), the water current (current, current_down), the
        velocity_reference (not given: 'ground', or what a bag of our simulator says) and
        mass_inverse (M^-1 of every model of the report, identified, prior and true; 'exact'
        lets the added-mass coefficients be identified and chosen by auto)
    simulate_maneuver, bag, seed, duration : as experiments.load_source
    command : the command line that produced the report (quoted in report.md)
    validation_maneuver, validation_duration : held-out manoeuvre and its length (s) of the
        true-model validation (known truth only); its seed is seed + 1000 (the bag's recorded
        seed + 1000 when it has one) and its process noise is DEFAULT_PROCESS_STD
    progress : show progress bars (only when stderr is a terminal)
    sim_current : (3,) m/s NED, the current a simulated run flies in (None: still water)
    validate_bag : another bag of the vehicle to validate on (analysis/validation.py); None:
        the final `holdout` fraction of the identification run is held out (identification
        uses the rest)
    holdout : fraction (0, 0.9] held out when no validate_bag is given

    methods : method names of analysis/compare_methods.py (e.g. ['ekf', 'ukf']) to run on the
        same identification data and validate on the same held-out run: result.json gets
        `methods` and report.md a section "Methods side by side" (None: not run)

    Returns
    -------
    dict with 'report', 'html', 'json' and 'figures' (name -> path) paths and 'result' (the JSON
    doc)
    """
    mv.refuse_same_bag(bag, validate_bag)        # before anything is loaded or written
    settings = settings or IdentifierSettings()
    opt = settings.current_option
    src, run, holdout, named = _sources(settings, simulate_maneuver, bag, seed, duration,
                                        sim_current, validate_bag, holdout, validation_maneuver)
    v = src.vehicle
    os.makedirs(out_dir, exist_ok=True)
    noise_mode = settings.noise_mode
    cfg = results.make_config(src.names, noise_mode=noise_mode,
                              noise_std=np.asarray(src.noise_std, dtype=float).copy())
    # a bag may lack whole channels (e.g. no position fixes): leave them out of the update
    cfg.measured = np.any(np.isfinite(src.Y), axis=0)
    hist_every = max(1, int(round(len(src.Y) / HIST_POINTS)))
    res, src = _identify(src, cfg, opt, named, hist_every, progress)

    run_val = mv.validate_on_run(
        v, src.names, res.estimate, None if res.current is None else res.current.estimate,
        run.t, run.Y, run.U, source=run.description, velocity_reference=run.velocity_reference,
        include_truth=run.truth is not None, truth_current=run.current_truth)
    val_doc = run_val.document()
    val_doc['holdout_fraction'] = holdout
    val_doc['identification_run'] = src.description
    # a --validate bag is read without the filter: what its screening dropped (one line)
    val_doc['screening'] = (None if run.screening is None
                            else dict(run.screening[0], line=run.screening[1]))

    try:        # the run's own seed when the source knows it (a bag's metadata: text)
        val_seed = int(src.seed) + 1000
    except (TypeError, ValueError):
        val_seed = seed + 1000
    rpm = float(np.median(src.U[:, Input.N_RPM]))
    val, val_error, true_doc = None, None, None
    if src.truth is not None:
        try:
            val = validate(v, src.names, res.estimate, validation_maneuver, validation_duration,
                           val_seed, src.T, rpm=rpm, identification_maneuver=src.maneuver)
        except ArithmeticError as err:    # the identified model leaves the model's domain
            val_error = str(err)
        true_doc = {'maneuver': validation_maneuver, 'seed': val_seed,
                    'duration_s': validation_duration, 'rpm': rpm,
                    'process_std': DEFAULT_PROCESS_STD.tolist(),
                    'reference': 'truth (vehicle file)',
                    'rms': None if val is None else val.rms,
                    'rms_units': dict(zip(STATE_NAMES, UNITS)), 'error': val_error}
    methods_doc = None
    if methods:
        from auv_ident.analysis.compare_methods import compare_methods
        methods_doc = compare_methods(src, run, methods=methods)
    extra = {'maneuver': src.maneuver, 'seed': src.seed,
             'duration_s': float(src.t[-1] - src.t[0]),
             'noise_mode': noise_mode, 'source': src.description,
             'mass_inverse': v.mass_inverse,
             'current_option': opt.describe(), 'velocity_reference': src.velocity_reference,
             'noise_std': np.asarray(src.noise_std, dtype=float).tolist(),
             'versions': package_versions(), 'command': command,
             'validation': val_doc, 'validation_true_model': true_doc,
             'selection': None if res.selection is None else res.selection.document()}
    if methods_doc is not None:
        extra['methods'] = methods_doc['methods']
        extra['methods_reference_fit_percent'] = methods_doc.get('reference_fit_percent')
    doc = results.result_dict(v, res, extra, current_truth=src.current_truth)
    json_path = os.path.join(out_dir, 'result.json')
    results.write_json(json_path, doc)

    def j(name):
        return os.path.join(out_dir, name + '.png')

    figures = {}
    convergence = fig_convergence(j('convergence'), v, res, noise_mode)
    if convergence:
        figures['convergence'] = convergence
    what = f'{v.title}, validation run: {run.description}'
    figures['measured_speeds'] = mv.fig_measured(
        j('measured_speeds'), run_val, [State.U, State.V, State.W, State.P, State.Q, State.R],
        f'{what}\nspeeds and rates, measured vs free run')
    figures['measured_pose'] = mv.fig_measured(
        j('measured_pose'), run_val, [State.X, State.Y, State.Z, State.PHI, State.THETA,
                                      State.PSI],
        f'{what}\npositions and attitudes, measured vs free run')
    if val is not None:
        what = (f'{v.title}\nheld-out {val.maneuver!r} manoeuvre, seed {val_seed}, '
                'process noise on')
        figures['validation_positions'] = _overlay(
            j('validation_positions'), val, [[State.X], [State.Y], [State.Z]],
            f'{what}: positions', 'true model')
        figures['validation_attitudes'] = _overlay(
            j('validation_attitudes'), val, [[State.PHI], [State.THETA], [State.PSI]],
            f'{what}: attitudes', 'true model')
        figures['validation_speeds'] = _overlay(
            j('validation_speeds'), val, [[State.U, State.P], [State.V, State.Q],
                                          [State.W, State.R]], f'{what}: speeds', 'true model')
    figures['nis'] = fig_nis(j('nis'), res, src.T, hist_every)
    figures['adapted_noise'] = fig_noise(j('adapted_noise'), res, noise_mode)
    acf = fig_innovation_autocorrelation(j('innovation_autocorrelation'), doc, src.T)
    if acf:
        figures['innovation_autocorrelation'] = acf

    md_path = os.path.join(out_dir, 'report.md')
    md = _markdown(doc, src, cfg, val_error, figures, command, holdout)
    if methods_doc is not None:
        from auv_ident.analysis.compare_methods import methods_markdown
        head, sep, tail = md.partition('\n## Figures')
        md = (head + '\n## Methods side by side\n\nThe same identification data through '
              'the standard methods (docs/methods.md), each validated on the same held-out '
              'run.\n\n' + methods_markdown(methods_doc) + '\n' + sep + tail)
    with open(md_path, 'w', encoding='utf-8') as fh:
        fh.write(md + '\n')
    html_path = write_html(md, out_dir, os.path.join(out_dir, 'report.html'))
    return {'report': md_path, 'html': html_path, 'json': json_path, 'figures': figures,
            'result': doc}
