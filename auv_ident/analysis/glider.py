"""The glider campaign (issue #31): calibrate the flight model on one half of a glider's record
and judge it on the other, both ways, beside a steady-state calibration in gliderflight's
style on the same split; :func:`format_campaign` prints the table (tools/glider_campaign.py,
docs/glider.md).

Models (:mod:`auv_ident.core.glider`):

- ``dynamic``: ours, the dynamic flight model with V_g and C_D0 identified from the depth rate
  (with the local density), the other parameters at the published values;
- ``steady (gliderflight style)``: the steady glide with C_D0, m and V_g fitted to the depth
  rate computed with one density (1004 kg/m^3), as gliderflight's example calibrates
  (``SteadyStateCalibrate(rho0=1004)``, a_h 3.8, C_D1 10.5, the 10-35 m window); written here
  with our code, least squares in place of Nelder-Mead (the same minimum);
- ``dynamic (gliderflight style)``: the same three parameters and density, the dynamic model;
- ``dynamic (gliderflight's example)``: the problem gliderflight's own dynamic calibration
  solves as its example sets it (tools/gliderflight_peer.py): C_D0 and m from m = 70 kg,
  V_g = 70/1004 m^3 held, the depth rate with 1004 kg/m^3; solved by our least squares to
  its minimum, where gliderflight's Nelder-Mead stops within its tolerance of it;
- ``dynamic + mass (inertia)``: ours with the mass freed too. Only rho V_g - m enters the
  buoyancy, so the mass is seen only through the inertia m (1 + k) of the transients: what
  the depth rate says of it, and what it changes in the prediction (docs/glider.md);
- with the water temperature in the record (``import --format npy`` given the raw logs too):
  ours with the hull's thermal expansion at its prior, and with it fitted. Ours leaves it out
  (docs/glider.md says why).

Every model starts from the glider file's prior (config/slocum_comet.yaml,
:func:`auv_ident.core.glider.vehicle.glider_from_file`).

Scores on the half not fitted: speed through water against the DVL (bias with its 1-sigma over
the dives, RMS, fit %) over
the dives that pass the instruments' consistency check (run once over the whole record before
the split, :func:`auv_ident.core.glider.validation.consistent_dvl`; reported dive by dive)
and over every DVL sample, and the depth rate (RMS over the fit window); and every other
model's RMS against ours on the same DVL samples, paired dive by dive, with the difference's
1-sigma over the dives (:func:`auv_ident.core.glider.validation.compare_speeds`). Agreement
of the halves: per parameter |a - b| / sqrt(s_a^2 + s_b^2).
"""
from dataclasses import asdict, replace

import numpy as np

from auv_ident.core.glider.calibration import calibrate, DEPTH_WINDOW, identifiability
from auv_ident.core.glider.flight import FLIGHT_MODELS, GliderParameters
from auv_ident.core.glider.record import GliderRecord
from auv_ident.core.glider.validation import compare_speeds, consistent_dvl, dvl_dives, score

# label: (model, free parameters, depth-rate density (None: local), water temperature used[,
# values replacing the prior's: a peer's own start])
OURS = ('dynamic', ('hull_volume', 'drag_zero_lift'), None, False)
GLIDERFLIGHT_FREE = ('drag_zero_lift', 'mass', 'hull_volume')
MODELS = {'dynamic': OURS,
          'steady (gliderflight style)': ('steady', GLIDERFLIGHT_FREE, 1004.0, False),
          'dynamic (gliderflight style)': ('dynamic', GLIDERFLIGHT_FREE, 1004.0, False),
          "dynamic (gliderflight's example)": ('dynamic', ('drag_zero_lift', 'mass'), 1004.0,
                                               False, {'mass': 70.0,
                                                       'hull_volume': 70.0 / 1004.0}),
          'dynamic + mass (inertia)': ('dynamic', ('hull_volume', 'drag_zero_lift', 'mass'),
                                       None, False)}
# with the water temperature (the raw logs'): the hull's thermal expansion at the prior, and
# freed
THERMAL_MODELS = {
    'dynamic + thermal expansion (prior)': ('dynamic', ('hull_volume', 'drag_zero_lift'),
                                            None, True),
    'dynamic + thermal expansion (fitted)': ('dynamic', ('hull_volume', 'drag_zero_lift',
                                                         'thermal_expansion'), None, True)}
# what the dives are asked about beyond what ours identifies
EXTRA = ('compressibility', 'lift_slope', 'induced_drag', 'mass')
BIAS_GOAL = 0.005       # m/s: issue #31's goal for the speed-through-water bias


def _flight(cal, record):
    return FLIGHT_MODELS[cal.model](cal.params, record)


def _scores(cal, record, kept_times):
    return judge(_flight(cal, record), record, kept_times, cal.window)


def versus(speed, ours_speed, record, kept_times):
    """The Comparison dict (validation.compare_speeds) of a model's speed (N,) m/s against
    ours on a record's DVL samples at kept_times (the consistent dives): rms_a is the
    model's, rms_b ours, difference = rms_a - rms_b (positive: ours closer to the DVL)."""
    return compare_speeds(speed, ours_speed, record, np.isin(record.t, kept_times)).__dict__


def judge(flight, record, kept_times, window=DEPTH_WINDOW):
    """{'all': Scores dict over every DVL sample, 'consistent': over the samples at
    kept_times (s since 1970; the dives that passed the consistency check)} of a Flight."""
    keep = np.isin(record.t, kept_times)
    every = np.isfinite(record.speed_through_water)
    return {'all': score(flight, record, every, window).__dict__,
            'consistent': score(flight, record, keep, window).__dict__}


def run_campaign(record: GliderRecord, prior: GliderParameters, split=None,
                 window=DEPTH_WINDOW):
    """The campaign on a GliderRecord from the prior (a glider file's params), split at time
    ``split`` (s since 1970; default the middle of the record). Returns a dict (JSON-ready):
    per model and direction the estimates, 1-sigma, fit seconds, scores on both halves; per
    model the halves' agreement; the identifiability of the extra parameters; the
    instruments' consistency check, dive by dive."""
    t_split = 0.5 * (record.t[0] + record.t[-1]) if split is None else float(split)
    with_temperature = dict(zip(('first', 'second'), record.split(t_split)))
    halves = {name: replace(h, temperature=None) for name, h in with_temperature.items()}
    out = {'split': t_split, 'window': list(window), 'models': {}}
    # the instruments' check, on every dive of the record (more dives, a firmer spread), before
    # any model: its verdict is the same whichever half a model was fitted on
    check = consistent_dvl(record)
    kept_times = record.t[check.keep]
    models = dict(MODELS)
    if record.temperature is not None:
        models.update(THERMAL_MODELS)
    ours_speed = {}
    for label, (model, free, density, thermal, *start) in models.items():
        runs = {}
        data = with_temperature if thermal else halves
        start_params = replace(prior, **start[0]) if start else prior
        for fit_name, val_name in (('first', 'second'), ('second', 'first')):
            cal = calibrate(data[fit_name], start_params, model, free, window=window,
                            depth_rate_density=density)
            speed = _flight(cal, data[val_name]).speed
            ours_speed.setdefault(val_name, speed)     # the first model is ours
            runs[fit_name] = {
                'fitted_on': fit_name, 'validated_on': val_name,
                'estimates': {n: list(v) for n, v in cal.estimates().items()},
                'verdicts': {n: v['verdict'] for n, v in cal.verdicts.items()},
                'seconds': cal.seconds, 'lags': cal.lags, 'depth_rate_rms_fit': cal.rms,
                'validation': _scores(cal, data[val_name], kept_times),
                'versus_ours': versus(speed, ours_speed[val_name], data[val_name], kept_times),
                'fit': _scores(cal, data[fit_name], kept_times),
                'params': asdict(cal.params), 'calibration': cal}
        a, b = runs['first']['estimates'], runs['second']['estimates']
        agreement = {n: abs(a[n][0] - b[n][0]) / np.hypot(a[n][1], b[n][1]) for n in free}
        out['models'][label] = {'runs': runs, 'agreement': agreement}
    ours = out['models']['dynamic']['runs']
    # each extra parameter freed alone beside ours, at the solution
    out['identifiability'] = {
        fit: {name: identifiability(halves[fit], ours[fit]['calibration'], (name,))[name]
              for name in EXTRA}
        for fit in ('first', 'second')}
    out['dvl_check'] = check.as_dict()
    for model in out['models'].values():
        for run in model['runs'].values():
            run.pop('calibration')
    return out


def _delayed(x, t, lag):
    """(N,) x read lag s later than logged (x at t - lag; negative: earlier), held at the ends."""
    return np.interp(t - lag, t, x)


def hull_temperature(record: GliderRecord, tau: float) -> np.ndarray:
    """(N,) degC: the hull's temperature lagging the water's with time constant tau (s), a
    first-order lag integrated exactly on the sample steps from the water's first value."""
    water = record.temperature
    out = np.empty(len(water))
    out[0] = water[0]
    decay = np.exp(-np.diff(record.t) / tau)
    for k in range(1, len(water)):
        out[k] = decay[k - 1] * out[k - 1] + (1.0 - decay[k - 1]) * water[k]
    return out


HULL_LAG = 400.0    # s: the hull's temperature lag tried (a dive is ~600 s; tried 60-3200 s)
# terms ours leaves out, each added alone to ours (V_g, C_D0 from the depth rate) and judged
# on the half not fitted: label -> (the record as this variant reads it, parameters freed
# beyond ours, values replacing the prior's, fit window m); the hull temperature only when
# the record holds the water's (the variant freeing thermal_expansion)
VARIANTS = {
    'pitch delayed 4 s': (lambda r: replace(r, pitch=_delayed(r.pitch, r.t, 4.0)), (), {},
                          DEPTH_WINDOW),
    'pitch advanced 4 s': (lambda r: replace(r, pitch=_delayed(r.pitch, r.t, -4.0)), (), {},
                           DEPTH_WINDOW),
    'pump delayed 5 s': (lambda r: replace(
        r, pumped_volume=_delayed(r.pumped_volume, r.t, 5.0)), (), {}, DEPTH_WINDOW),
    'pump advanced 5 s': (lambda r: replace(
        r, pumped_volume=_delayed(r.pumped_volume, r.t, -5.0)), (), {}, DEPTH_WINDOW),
    # the CTD's density read late through the pycnocline (its sensors' lag): the glider's
    # water is the one measured a few seconds on
    'density advanced 8 s': (lambda r: replace(r, density=_delayed(r.density, r.t, -8.0)),
                             (), {}, DEPTH_WINDOW),
    'compressibility freed': (lambda r: r, ('compressibility',), {}, DEPTH_WINDOW),
    "mass 70 kg (gliderflight's)": (lambda r: r, (), {'mass': 70.0}, DEPTH_WINDOW),
    'fit window 5-40 m': (lambda r: r, (), {}, (5.0, 40.0)),
    f'hull temperature lagging the water by {HULL_LAG:.0f} s, alpha_T fitted': (
        lambda r: replace(r, temperature=hull_temperature(r, HULL_LAG)),
        ('thermal_expansion',), {}, DEPTH_WINDOW)}


def run_variants(record: GliderRecord, prior: GliderParameters, split=None):
    """Each of :data:`VARIANTS` calibrated on one half of a record and judged on the other,
    both ways, beside ours (run_campaign's split): per variant and half fitted on, the
    depth-rate RMS the fit reached (m/s; ours' beside it: what the fit itself can prefer),
    the estimates, the scores with the flagged dives out, and its RMS against ours on the same
    samples, paired dive by dive (JSON-ready dict)."""
    t_split = 0.5 * (record.t[0] + record.t[-1]) if split is None else float(split)
    kept_times = record.t[consistent_dvl(record).keep]
    model, free, density, _ = OURS
    out = {'split': t_split, 'variants': {}}
    ours = {}
    for label, (read, extra, start, window) in VARIANTS.items():
        thermal = 'thermal_expansion' in extra
        if thermal and record.temperature is None:
            continue
        rec = read(record)
        if not thermal:
            rec = replace(rec, temperature=None)
        halves = dict(zip(('first', 'second'), rec.split(t_split)))
        params = prior
        if 'mass' in start:         # neutral with nothing pumped, as the prior
            params = replace(prior, hull_volume=prior.hull_volume * start['mass'] / prior.mass)
        params = replace(params, **start)
        runs = {}
        for fit_name, val_name in (('first', 'second'), ('second', 'first')):
            if fit_name not in ours:
                base = replace(record, temperature=None).split(t_split)
                base_halves = dict(zip(('first', 'second'), base))
                cal0 = calibrate(base_halves[fit_name], prior, model, free,
                                 depth_rate_density=density)
                ours[fit_name] = (cal0.rms, FLIGHT_MODELS[model](cal0.params,
                                                                 base_halves[val_name]).speed)
            cal = calibrate(halves[fit_name], params, model, free + tuple(extra),
                            window=window, depth_rate_density=density)
            val = halves[val_name]
            speed = FLIGHT_MODELS[model](cal.params, val).speed
            runs[fit_name] = {
                'fitted_on': fit_name, 'validated_on': val_name,
                'depth_rate_rms_fit': cal.rms, 'ours_depth_rate_rms_fit': ours[fit_name][0],
                'estimates': {n: list(v) for n, v in cal.estimates().items()},
                'validation': judge(FLIGHT_MODELS[model](cal.params, val), val, kept_times,
                                    cal.window)['consistent'],
                'versus_ours': versus(speed, ours[fit_name][1], val, kept_times),
                'seconds': cal.seconds}
        out['variants'][label] = runs
    return out


def format_variants(result):
    """Markdown lines of :func:`run_variants`."""
    L = ['| variant | fitted on | dz/dt RMS on the fit half cm/s (ours) | U bias cm/s, '
         'flagged out (1-sigma) | U RMS, flagged out | its - ours (1-sigma over the dives) | '
         'estimates (1-sigma) |', '|---|---|---|---|---|---|---|']
    for label, runs in result['variants'].items():
        for run in runs.values():
            v, c = run['validation'], run['versus_ours']
            est = ', '.join(f'{n} {x:.4g} ({sd:.2g})' for n, (x, sd) in run['estimates'].items()
                            if n not in OURS[1])
            L.append(f"| {label} | {run['fitted_on']} half | "
                     f"{100 * run['depth_rate_rms_fit']:.3f} "
                     f"({100 * run['ours_depth_rate_rms_fit']:.3f}) | "
                     f"{_cm_std(v['speed_bias'], v['speed_bias_std'])} | "
                     f"{100 * v['speed_rms']:.2f} | "
                     f"{_cm_std(c['difference'], c['difference_std'])} | {est} |")
    return L


def _cm(v):
    return f'{100.0 * v:+.2f}' if np.isfinite(v) else 'n/a'


def _cm_std(v, std):
    """'+0.32 (0.10)': a value and its 1-sigma, cm/s."""
    return f'{_cm(v)} ({100.0 * std:.2f})' if np.isfinite(std) else _cm(v)


SCORE_HEADER = ['| model | fitted on | validated on | U bias cm/s, all dives (1-sigma) | '
                'U RMS cm/s, all dives | U fit %, all dives | U bias, flagged dives out | '
                'U RMS, flagged out | U fit %, flagged out | dz/dt RMS cm/s | fit s (wall) |',
                '|---|---|---|---|---|---|---|---|---|---|---|']


def score_row(label, run):
    """The table line of one calibration judged on the half it did not see: ``run`` holds
    fitted_on, validated_on, seconds and validation = {'all': Scores dict, 'consistent': ...}
    (run_campaign's runs; tools/gliderflight_peer.py's)."""
    v = run['validation']
    a, c = v['all'], v['consistent']
    return (f"| {label} | {run['fitted_on']} half | {run['validated_on']} half | "
            f"{_cm_std(a['speed_bias'], a.get('speed_bias_std', np.nan))} | "
            f"{100 * a['speed_rms']:.2f} | {a['speed_fit']:.1f} | "
            f"{_cm_std(c['speed_bias'], c.get('speed_bias_std', np.nan))} | "
            f"{100 * v['consistent']['speed_rms']:.2f} | "
            f"{v['consistent']['speed_fit']:.1f} | "
            f"{100 * v['all']['depth_rate_rms']:.2f} | {run['seconds']:.2f} |")


VERSUS_HEADER = ['| model | fitted on | validated on | its U RMS cm/s | ours | '
                 'its - ours (1-sigma over the dives) | dives |', '|---|---|---|---|---|---|---|']


def versus_row(label, run):
    """The table line of one model's RMS against ours on the consistent dives of the half it
    did not see (run['versus_ours'], a Comparison dict)."""
    c = run['versus_ours']
    return (f"| {label} | {run['fitted_on']} half | {run['validated_on']} half | "
            f"{100 * c['rms_a']:.2f} | {100 * c['rms_b']:.2f} | "
            f"{_cm_std(c['difference'], c['difference_std'])} | {c['dives']} |")


def format_campaign(result):
    """Markdown lines of the campaign (module docstring): first the dives the data-quality
    check flagged (:func:`format_flagged`) and the goals (:func:`format_goals`), then the
    tables."""
    L = format_flagged(result['dvl_check'], result['split'])
    L += ['', *format_goals(result), '', *SCORE_HEADER]
    for label, model in result['models'].items():
        for run in model['runs'].values():
            L.append(score_row(label, run))
    L += ['', 'Each model against ours on the same DVL samples (flagged dives out), paired '
          'dive by dive:', '', *VERSUS_HEADER]
    for label, model in result['models'].items():
        if label != 'dynamic':
            L += [versus_row(label, run) for run in model['runs'].values()]
    L += ['', '| model | parameter | first half (1-sigma) | second half (1-sigma) | '
          'difference / combined sigma |', '|---|---|---|---|---|']
    for label, model in result['models'].items():
        a, b = model['runs']['first']['estimates'], model['runs']['second']['estimates']
        for name, z in model['agreement'].items():
            L.append(f'| {label} | {name} | {a[name][0]:.6g} ({a[name][1]:.2g}) | '
                     f'{b[name][0]:.6g} ({b[name][1]:.2g}) | {z:.2f} |')
    L += ['', 'What the dives cannot identify (our dynamic model; each parameter freed alone '
          'beside V_g and C_D0 at the solution, sandwich covariance):', '',
          '| fitted on | parameter | 1-sigma | max correlation (with) | verdict |',
          '|---|---|---|---|---|']
    for fit, verdicts in result['identifiability'].items():
        for name, v in verdicts.items():
            L.append(f"| {fit} half | {name} | {v['crb_std']:.3g} | "
                     f"{v['max_correlation']:.3f} ({v['correlated_with']}) | {v['verdict']} |")
    return L + format_dvl_check(result['dvl_check'])


def utc_text(t):
    """s since 1970 -> '2016-06-23T19:55:00' (UTC)."""
    return str(np.datetime64(int(t), 's'))


def format_flagged(check, split=None, dive_table='the last table of tools/glider_campaign.py'):
    """The first lines of a glider run's output: the dives the data-quality check
    (core/glider/validation.py consistent_dvl, its as_dict) flagged, each named by its start
    (UTC) and, given the split (s since 1970), its half, with the evidence: its DVL speed
    against the speed its depth rate and pitch imply at the other dives' angle of attack, and
    how far the other dives' DVL speeds are from theirs."""
    dives = check['dives']
    if not np.isfinite(check['z_limit']):
        return [f'data quality: {len(dives)} DVL dives, too few to judge the DVL against the '
                'pressure and the pitch: none flagged; every figure is over every dive']
    flagged = [d for d in dives if not d['kept']]
    ratios = [d['dvl_speed'] / d['implied_speed'] - 1.0 for d in dives if d['kept']]
    L = [f'data quality: {len(flagged)} of {len(dives)} DVL dives flagged'
         + (': ' + ', '.join(utc_text(d['start']) for d in flagged) if flagged else '')
         + " (the DVL's speed against the speed the depth rate and the pitch imply, beyond "
         f"the other dives' spread: |z| > {check['z_limit']:.2f}, at which any of "
         f"{len(dives)} consistent dives is flagged with {100 * check['false_rejection']:g} % "
         "chance)"]
    for d in flagged:
        half = ''
        if split is not None:
            half = ' (first half)' if d['start'] < split else ' (second half)'
        L.append(f"  flagged: the dive from {utc_text(d['start'])}{half}: DVL "
                 f"{d['dvl_speed']:.3f} m/s where its depth rate {d['depth_rate']:.3f} m/s "
                 f"and pitch {d['pitch_deg']:.1f} deg imply {d['implied_speed']:.3f} m/s at "
                 f"the dives' angle of attack {check['centre_deg']:.2f} deg "
                 f"({100 * (d['dvl_speed'] / d['implied_speed'] - 1.0):+.0f} %; the other "
                 f"dives {100 * min(ratios):+.0f}..{100 * max(ratios):+.0f} %); its implied "
                 f"angle of attack {d['median_aoa_deg']:.2f} deg, z = {d['z']:+.1f}")
    L.append("  the figures 'all dives' count every DVL sample, the flagged dives' too; "
             f"'flagged out' leave the flagged dives out (dive by dive: {dive_table})")
    return L


def _met(ok):
    return 'met' if ok else 'not met'


def format_goals(result):
    """Lines saying, for ours on each half it did not see, which figure meets issue #31's
    goals: the speed bias within :data:`BIAS_GOAL` over every dive and with the flagged dives
    out, and the speed RMS (flagged dives out) against the steady calibration and
    gliderflight's example problem solved to its minimum, paired on the same samples."""
    ours = result['models']['dynamic']['runs']
    L = ['goals (issue #31), ours (dynamic) on the half it did not see:']
    for run in ours.values():
        a, c = run['validation']['all'], run['validation']['consistent']
        where = f"  fitted on the {run['fitted_on']} half, validated on the {run['validated_on']}"
        L.append(f"{where}: speed bias within {100 * BIAS_GOAL:.1f} cm/s: flagged dives out "
                 f"{_cm_std(c['speed_bias'], c['speed_bias_std'])} cm/s: "
                 f"{_met(abs(c['speed_bias']) <= BIAS_GOAL)}; all dives "
                 f"{_cm_std(a['speed_bias'], a['speed_bias_std'])} cm/s: "
                 f"{_met(abs(a['speed_bias']) <= BIAS_GOAL)}")
        for label in ('steady (gliderflight style)', "dynamic (gliderflight's example)"):
            other = result['models'].get(label)
            if other is None:
                continue
            v = other['runs'][run['fitted_on']]['versus_ours']
            below = v['difference'] > 0.0
            told = abs(v['difference']) > 2.0 * v['difference_std']
            L.append(f"{where}: speed RMS (flagged out) {100 * v['rms_b']:.2f} cm/s against "
                     f"{label} {100 * v['rms_a']:.2f}: {'below' if below else 'not below'}, "
                     f"by {_cm_std(v['difference'], v['difference_std'])} cm/s paired over "
                     f"{v['dives']} dives ({'more' if told else 'less'} than twice its 1-sigma)")
    return L


def format_dvl_check(check):
    """Markdown lines of the instruments' consistency check (core/glider/validation.py)."""
    dives = check['dives']
    failed = [d for d in dives if not d['kept']]
    L = ['', 'The data-quality check, the DVL against the pressure and the pitch, dive by dive: '
         f"{len(dives)} dives, "
         f"median implied angle of attack {check['centre_deg']:.2f} deg, dive-to-dive spread "
         f"(1.4826 MAD) {check['spread_deg']:.2f} deg; a dive fails at |z| > "
         f"{check['z_limit']:.2f} ({100 * check['false_rejection']:g} % chance of failing any "
         f"of {len(dives)} consistent dives); failed: {len(failed)}", '',
         '| dive start (UTC) | DVL samples | pumped cc | pitch deg | depth rate m/s | '
         'DVL speed m/s | implied speed m/s | median implied angle of attack deg (s.e.) | z | '
         'flagged |', '|---|---|---|---|---|---|---|---|---|---|']
    for d in dives:
        L.append(f"| {utc_text(d['start'])} | {d['samples']} | "
                 f"{d['pumped_cc']:.0f} | {d['pitch_deg']:.1f} | {d['depth_rate']:.3f} | "
                 f"{d['dvl_speed']:.3f} | {d['implied_speed']:.3f} | "
                 f"{d['median_aoa_deg']:.2f} ({d['stderr_deg']:.2f}) | {d['z']:+.1f} | "
                 f"{'no' if d['kept'] else 'FLAGGED'} |")
    return L


def plot_campaign(record, result, path):
    """A figure of the campaign (PNG at path): top, three dives of the second half, the DVL's
    speed and the speeds the models fitted on the first half predict; bottom, per DVL dive of
    the whole record, the mean speed error (model - DVL) of each model on the half it did not
    see, the inconsistent dive marked."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    first, second = record.split(result['split'])
    halves = {'first': replace(first, temperature=None),
              'second': replace(second, temperature=None)}
    labels = ('dynamic', 'steady (gliderflight style)')
    colours = {'dynamic': 'C0', 'steady (gliderflight style)': 'C3'}
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 6.5))
    val = halves['second']
    t0 = val.t[0]
    window = (val.t - t0 > 1200) & (val.t - t0 < 3200)
    top.plot((val.t[window] - t0) / 60, val.speed_through_water[window], 'k.', ms=2,
             label='DVL')
    for label in labels:
        run = result['models'][label]['runs']['first']
        model, *_ = MODELS[label]
        flight = FLIGHT_MODELS[model](GliderParameters(**run['params']), val)
        top.plot((val.t[window] - t0) / 60, flight.speed[window], color=colours[label],
                 lw=1, label=f'{label}, fitted on the first half')
    top.set_xlabel('minutes into the second half')
    top.set_ylabel('speed through water (m/s)')
    top.set_ylim(0.0, 0.5)
    top.legend(fontsize=8, loc='upper right')
    for label in labels:
        xs, ys = [], []
        for fit_name, val_name in (('first', 'second'), ('second', 'first')):
            rec = halves[val_name]
            model, *_ = MODELS[label]
            params = GliderParameters(**result['models'][label]['runs'][fit_name]['params'])
            flight = FLIGHT_MODELS[model](params, rec)
            for idx in dvl_dives(rec):
                xs.append((rec.t[idx[0]] - record.t[0]) / 3600)
                ys.append(100 * np.mean(flight.speed[idx] - rec.speed_through_water[idx]))
        bottom.plot(xs, ys, 'o', color=colours[label], ms=4, label=label)
    for d in result['dvl_check']['dives']:
        if not d['kept']:
            bottom.axvspan((d['start'] - record.t[0]) / 3600 - 0.03,
                           (d['start'] - record.t[0]) / 3600 + 0.08, color='0.85',
                           label='DVL inconsistent with pressure and pitch')
    bottom.axhline(0.0, color='k', lw=0.5)
    bottom.axvline((result['split'] - record.t[0]) / 3600, color='k', ls='--', lw=0.8)
    bottom.set_xlabel('hours from the start (dashed: the split)')
    bottom.set_ylabel('dive mean of model - DVL (cm/s)')
    bottom.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
