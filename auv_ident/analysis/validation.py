"""Validation of an identified model against the MEASUREMENTS of a held-out run.

A model is judged on a run it was not identified on (another bag of the same vehicle, or the
final part of the identification bag held out from identification): from the run's measured
initial state and with its measured commands (zero-order hold on the run's own stamps), the
identified model and the prior model (the vehicle file's values) fly freely; their channels are
compared with the measured ones by fit % (MATLAB ``compare``), RMSE and Theil's inequality
coefficient (core/simulation/prediction.py). Positions and heading drift in any free run (an error
in speed integrates), so they are also scored by K-step-ahead prediction: the model restarts from
the measured state every K measurements and predicts the next K.

The identified water current (if any) flies with the identified model; the prior model flies
in still water, as a model from the vehicle file alone would. In simulation the true model (the
vehicle file, in the run's true current) flies too.

Initial state: the free run starts at the first sample whose measured channels are all present
(channels that the run measures somewhere), from each channel's straight-line least-squares fit
over the first second of the run evaluated there (a single sample would carry the whole sensor
noise, 0.5 m in x and y, which a free run keeps for ever in positions and heading). A channel
the run never measures starts at the prior model's trim (u at the trim speed of the run's
median shaft speed, rates and angles 0, positions 0): x, y and z do not enter the dynamics, and
such a channel is not scored.

ROS-free; matplotlib only inside :func:`fig_measured` (report_format.pyplot).
"""
from dataclasses import dataclass, field, replace
import os

import numpy as np

from auv_ident.analysis.report_format import finite_cell, markdown_table, pyplot, save_figure
from auv_ident.core.angles import wrap_angle
from auv_ident.core.errors import ConfigError
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import (
    EULER,
    Input,
    N_STATE,
    NU_NAMES,
    State,
    STATE_NAMES,
    STATE_UNITS,
)
from auv_ident.core.model.thruster_lag import derivative
from auv_ident.core.model.trim import initial_state
from auv_ident.core.simulation.prediction import (
    angle_channels,
    DEFAULT_MAX_STEP,
    fit_percent,
    free_run,
    rmse,
    theil,
)
from auv_ident.session.settings import IdentifierSettings

DEFAULT_HOLDOUT = 0.25          # fraction of the identification run held out (its final part)
HORIZONS = (1, 10, 100)         # K of the K-step-ahead prediction (measurement samples)
SHARED_LIMIT = 0.5              # a run sharing more of its samples with the identification run
                                # than this is (a copy or a cut of) the identification run
MODELS = ('identified', 'prior', 'truth')
SUFFIX = {'identified': '', 'prior': '_prior', 'truth': '_truth'}
SAME_VALUE_TOL = 1e-9           # two samples closer than this in every channel are one sample
X0_WINDOW = 1.0                 # s, start of the run the initial state is fitted on
MIN_SAMPLES = 10                # measured samples a validation run needs at least


# --------------------------------------------------------------------------- the held-out run

def split_held_out(src, fraction=DEFAULT_HOLDOUT):
    """(identification part, held-out part) of a Source: the rows with t before / from the
    time that leaves `fraction` of the run's duration at its end.

    Returns two analysis.results.Source (arrays sliced, descriptions saying which part)."""
    fraction = float(fraction)
    if not 0.0 < fraction <= 0.9:
        raise ConfigError(f'held-out fraction must be in (0, 0.9], got {fraction:g}')
    t = np.asarray(src.t, dtype=float)
    t_split = t[0] + (1.0 - fraction) * (t[-1] - t[0])
    first = t < t_split
    parts = []
    for keep, what in ((first, f'first {100 * (1 - fraction):g} %'),
                       (~first, f'final {100 * fraction:g} % (held out)')):
        n_meas = int(np.sum(np.any(np.isfinite(src.Y[keep]), axis=1)))
        if n_meas < MIN_SAMPLES:
            raise ConfigError(f'{src.description}: the {what} part has {n_meas} measured '
                              f'samples; a held-out split needs at least {MIN_SAMPLES} in each '
                              'part (a longer run, another --holdout, or --validate BAG)')
        parts.append(replace(
            src, t=t[keep], Y=src.Y[keep], U=src.U[keep],
            X_true=None if src.X_true is None else np.asarray(src.X_true)[keep],
            description=f'{what} of {src.description} (t {t[keep][0]:.1f}..{t[keep][-1]:.1f} s)'))
    return parts[0], parts[1]


def _stamps_us(src, absolute=True):
    """Stamps (int microseconds; absolute, or from the run's time origin) of a Source's measured
    samples, and those samples."""
    meas = np.any(np.isfinite(src.Y), axis=1)
    origin = int(getattr(src, 'time_origin_ns', 0) or 0) if absolute else 0
    stamps = (origin // 1000 + np.round(np.asarray(src.t)[meas] * 1e6)).astype(np.int64)
    return stamps, np.asarray(src.Y)[meas]


def refuse_same_bag(ident_path, val_path):
    """Raise ConfigError if the validation bag is the identification bag (same path)."""
    if ident_path and val_path and os.path.exists(ident_path) and os.path.exists(val_path):
        if os.path.samefile(ident_path, val_path):
            raise ConfigError(f'--validate {val_path} is the identification bag itself: '
                              'validation needs another run of the vehicle')


def refuse_identification_run(ident_src, val_src, ident_path=None, val_path=None):
    """Raise ConfigError if the validation run is the identification run itself: the same bag
    path, or the same content (more than SHARED_LIMIT of the validation run's measured samples
    found in the identification run at the same absolute stamp (to 1 us) with the same 12
    values (to SAME_VALUE_TOL), i.e. a copy or a cut of it, or a bag of the same simulation)."""
    refuse_same_bag(ident_path, val_path)
    # a run simulated in memory has no absolute time (origin 0): compare from the origins
    absolute = bool(getattr(ident_src, 'time_origin_ns', 0)) and bool(
        getattr(val_src, 'time_origin_ns', 0))
    s_val, y_val = _stamps_us(val_src, absolute)
    s_id, y_id = _stamps_us(ident_src, absolute)
    common, i_val, i_id = np.intersect1d(s_val, s_id, return_indices=True)
    if not len(s_val) or not len(common):
        return
    diff = y_val[i_val] - y_id[i_id]
    diff[:, EULER] = wrap_angle(diff[:, EULER])
    # equal to rounding: a bag stores attitudes as quaternions (1e-16 rad), and two runs differ
    # by their sensor noise (>= 1e-3 in every channel)
    same = np.all((np.abs(diff) <= SAME_VALUE_TOL)
                  | (np.isnan(y_val[i_val]) & np.isnan(y_id[i_id])), axis=1)
    shared = float(np.sum(same)) / len(s_val)
    if shared > SHARED_LIMIT:
        raise ConfigError(f'validation run {val_src.description} is the identification run '
                          f'({100 * shared:.0f} % of its samples are identification samples, '
                          'same stamps and values): validation needs another run of the '
                          'vehicle')


# ----------------------------------------------------------------------------- predictions

def _initial_state(t, Y, prior_model, rpm, window):
    """(first row k0, x0 (12,), {channel: how it was filled}) of a run (module docstring)."""
    measured = np.any(np.isfinite(Y), axis=0)
    complete = np.all(np.isfinite(Y[:, measured]), axis=1) & np.any(np.isfinite(Y), axis=1)
    if not complete.any():
        raise ConfigError('the validation run has no sample with all its measured channels '
                          'present: no initial state to start the models from')
    k0 = int(np.argmax(complete))
    x0 = np.array(Y[k0], dtype=float)
    filled = {}
    if window > 0:
        # one sample carries the whole sensor noise (0.5 m in x, y), which a free run keeps
        # for ever in positions and heading: a straight line through the first `window`
        # seconds, evaluated at t0, has about 2 / sqrt(samples) of it
        near = t - t[k0] <= window
        Yu = angle_channels(Y, Y)[0]
        for i in np.flatnonzero(measured):
            ok = near & np.isfinite(Yu[:, i])
            ok[:k0] = False
            if np.sum(ok) >= 3:
                x0[i] = np.polyfit(t[ok] - t[k0], Yu[ok, i], 1)[1]     # value at t0
        x0[EULER] = wrap_angle(x0[EULER])
    if not measured.all():
        trim = initial_state(prior_model, rpm, depth=0.0)
        for i in np.flatnonzero(~measured):
            x0[i] = trim[i]
            filled[STATE_NAMES[i]] = f'not measured: trim value {trim[i]:g}'
    return k0, x0, filled


def k_step_on_measurements(f, t, U, Y, K, x0, max_step=DEFAULT_MAX_STEP):
    """K-step-ahead prediction counted in measurements: restart at the measured state every K
    measured samples and predict up to the K-th next one.

    Unlike core.simulation.prediction.k_step_prediction (K rows), rows without a measurement (the
    command changes between samples, which carry the exact zero-order hold) are not restart points
    and do not count toward K. A restart takes the measured channels and, for channels missing
    there, the prediction that arrives at that row. Row 0 holds x0; a restart row holds the
    prediction that arrives at it (not the measurement). (N, 12), NaN where a segment failed.
    """
    t = np.asarray(t, dtype=float)
    Y = np.asarray(Y, dtype=float)
    X = np.full((len(t), N_STATE), np.nan)
    X[0] = x0
    rows = np.flatnonzero(np.any(np.isfinite(Y), axis=1))
    starts = [0] + [int(r) for r in rows[K::K] if r > 0]
    ends = starts[1:] + [len(t) - 1]
    for a, b in zip(starts, ends):
        if b <= a:
            continue
        xs = np.where(np.isfinite(Y[a]), Y[a], X[a]) if a else np.asarray(x0, dtype=float)
        if not np.all(np.isfinite(xs)):
            continue
        X[a + 1:b + 1] = free_run(f, t[a:b + 1], U[a:b + 1], xs, max_step)[1:]
    return X


def _scores(Y, X, idx):
    """fit %, RMSE and Theil of prediction X against Y on the channels idx (SI units)."""
    Ym, Xp = angle_channels(Y, X)
    out = {}
    for i in idx:
        out[STATE_NAMES[i]] = {'fit_percent': fit_percent(Ym[:, i], Xp[:, i]),
                               'rmse': rmse(Ym[:, i], Xp[:, i]),
                               'theil': theil(Ym[:, i], Xp[:, i])}
    return out


def speed_series(X):
    """(N,) m/s, the total speed U = sqrt(u^2 + v^2) of states X (N, 12) (NaN where u or v
    is): the speed a ship's log and its prime system use."""
    X = np.asarray(X, dtype=float)
    return np.hypot(X[:, State.U], X[:, State.V])


def _speed_scores(Y, X):
    """fit %, RMSE (m/s) and Theil of the total speed U of prediction X against Y."""
    y, y_hat = speed_series(Y), speed_series(X)
    return {'fit_percent': fit_percent(y, y_hat), 'rmse': rmse(y, y_hat),
            'theil': theil(y, y_hat)}


def _failed_at(t, Y, X):
    """Time (s) of the first measured sample the prediction does not reach, or None."""
    lost = np.any(np.isfinite(Y), axis=1) & ~np.all(np.isfinite(X), axis=1)
    return float(t[np.argmax(lost)]) if lost.any() else None


@dataclass
class RunValidation:
    """The models' predictions of a measured run and their scores.

    t, Y, U : (N,), (N, 12), (N, 6) the run from its initial sample on (s; SI, rad; rad, rpm)
    x0 : (12,) the initial state, filled : {channel: how it was filled} (module docstring);
        x0_window : s, the start of the run x0 was fitted on (0: the first sample)
    free : {model: (N, 12) free-run prediction}; models 'identified', 'prior' and, when the
        truth is known, 'truth'
    k_step : {K: {model: (N, 12)}}
    channels : {channel: {'fit_percent', 'fit_percent_prior', 'rmse', 'rmse_prior', 'theil',
        'theil_prior' (and *_truth)}}, free run, SI units (STATE_UNITS)
    prediction : {'K1': {'horizon_samples', 'horizon_s', 'channels': {channel: {'fit_percent',
        'rmse', ... with the same suffixes}}}, ...}
    failed_at : {model: s or None}, where a free run left the model's domain
    derived : {'U': {'fit_percent', ... as channels}}: the total speed U = sqrt(u^2 + v^2)
        (m/s) of the free runs, when the run measures u and v (a ship's speed, which its prime
        system scales by; :func:`speed_series`)
    """

    source: str
    t: np.ndarray
    Y: np.ndarray
    U: np.ndarray
    x0: np.ndarray
    filled: dict
    free: dict
    k_step: dict
    channels: dict
    prediction: dict
    failed_at: dict
    current: object = None
    velocity_reference: str = 'ground'
    x0_window: float = 0.0
    derived: dict = field(default_factory=dict)

    def mean_fit(self, model='identified', names=NU_NAMES):
        """Mean fit % over the channels `names` (u v w p q r by default); NaN channels (not
        measured, or a constant measurement) left out."""
        # a planar vehicle's run does not measure w, p, q: not channels here
        vals = [self.channels[n]['fit_percent' + SUFFIX[model]] for n in names
                if n in self.channels]
        vals = [v for v in vals if v is not None and np.isfinite(v)]
        return float(np.mean(vals)) if vals else float('nan')

    def document(self):
        """The `validation` entry of result.json (docs/report.md)."""
        def clean(d):
            if isinstance(d, dict):
                return {k: clean(v) for k, v in d.items()}
            if isinstance(d, float) and not np.isfinite(d):
                return None
            return d
        models = [m for m in MODELS if m in self.free]
        doc = {'source': self.source, 't0_s': float(self.t[0]),
               'duration_s': float(self.t[-1] - self.t[0]),
               'samples': int(np.sum(np.any(np.isfinite(self.Y), axis=1))),
               'models': models,
               'initial_state': {'x0': [float(v) for v in self.x0], 'filled': self.filled,
                                 'fit_window_s': self.x0_window},
               'current_identified': (None if self.current is None
                                      else [float(v) for v in self.current]),
               'velocity_reference': self.velocity_reference,
               'units': dict(zip(STATE_NAMES, STATE_UNITS)),
               'mean_fit_percent_nu': {m: self.mean_fit(m) for m in models},
               'failed_at_s': dict(self.failed_at),
               'channels': self.channels, 'derived_channels': self.derived,
               'prediction': self.prediction}
        return clean(doc)


def _model_with(vehicle, coefficient_values, current, velocity_reference):
    return Model(vehicle, coefficient_values=coefficient_values, current=current,
                 velocity_reference=velocity_reference)


def validate_on_run(vehicle, names, estimate, current, run_t, run_Y, run_U, source='run',
                    velocity_reference='ground', truth_current=None, include_truth=False,
                    horizons=HORIZONS, max_step=DEFAULT_MAX_STEP, x0_window=X0_WINDOW):
    """Fly the identified and the prior model (and the true one) through a measured run.

    Parameters
    ----------
    vehicle : core.model.vehicle.Vehicle; its file's values are the prior model (and the truth of a
        simulated run)
    names, estimate : the identified coefficients and their values (vehicle-file units)
    current : (3,) m/s NED, the identified (or given) water current the identified model flies
        in; None: still water
    run_t, run_Y, run_U : (N,) s, (N, 12) measured states (NaN: not measured; rows without any
        measurement are command changes), (N, 6) commands in force over [t_k, t_k+1)
    source : what the run is (quoted in the report)
    velocity_reference : what the run's u v w are ('ground' or 'water')
    include_truth, truth_current : fly the vehicle file's model in truth_current (3,) too (a
        simulated run, whose truth is the file)
    horizons : K of the K-step prediction, in measurement samples
    max_step : s, the longest RK4 step of the predictions
    x0_window : s, the initial state is each measured channel's straight-line fit over this
        long a start of the run, at its first sample (0: that sample as measured)

    Returns
    -------
    RunValidation
    """
    t = np.asarray(run_t, dtype=float)
    Y = np.asarray(run_Y, dtype=float)
    U = np.asarray(run_U, dtype=float)
    _check_run(t, Y, U, source)
    prior = Model(vehicle, velocity_reference=velocity_reference)
    identified = _model_with(vehicle, Model(vehicle, names).coefficients_with(estimate),
                             current, velocity_reference)
    models = {'identified': identified, 'prior': prior}
    if include_truth:
        models['truth'] = _model_with(vehicle, None, truth_current, velocity_reference)
    rpm = float(np.median(U[:, Input.N_RPM]))
    k0, x0, filled = _initial_state(t, Y, prior, rpm, x0_window)
    t, Y, U = t[k0:], Y[k0:], U[k0:]
    measured_idx = [i for i in range(N_STATE) if np.any(np.isfinite(Y[:, i]))]

    free, k_step, failed = {}, {K: {} for K in horizons}, {}
    for name, m in models.items():
        f = derivative(m)           # m.f, or its lagged thrust's stepper
        free[name] = free_run(f, t, U, x0, max_step)
        failed[name] = _failed_at(t, Y, free[name])
        for K in horizons:
            k_step[K][name] = k_step_on_measurements(f, t, U, Y, K, x0, max_step)

    dt = float(np.median(np.diff(t[np.any(np.isfinite(Y), axis=1)])))
    prediction = {f'K{K}': {'horizon_samples': K, 'horizon_s': K * dt,
                            'channels': _merged_scores(Y, k_step[K], measured_idx)}
                  for K in horizons}
    return RunValidation(source=source, t=t, Y=Y, U=U, x0=x0, filled=filled, free=free,
                         k_step=k_step,
                         channels=_free_run_scores(Y, free, failed, measured_idx),
                         prediction=prediction, failed_at=failed,
                         current=None if current is None else np.asarray(current, float),
                         velocity_reference=velocity_reference, x0_window=float(x0_window),
                         derived=_derived_scores(Y, free, failed, measured_idx))


def _check_run(t, Y, U, source):
    """ConfigError naming the run if its arrays do not fit together, it has too few measured
    samples or commands are missing."""
    if Y.ndim != 2 or Y.shape[1] != N_STATE or len(Y) != len(t) or len(U) != len(t):
        raise ConfigError(f'validation run: t, Y, U must have N rows and Y 12 columns, got '
                          f'{t.shape}, {Y.shape}, {U.shape}')
    if int(np.sum(np.any(np.isfinite(Y), axis=1))) < MIN_SAMPLES:
        raise ConfigError(f'validation run {source}: fewer than {MIN_SAMPLES} measured samples')
    if not np.all(np.isfinite(U)):
        raise ConfigError(f'validation run {source}: commands missing (NaN) on some rows')


def _merged_scores(Y, preds, measured_idx):
    """{channel: {'fit_percent', 'rmse', 'theil' with each model's SUFFIX}} of the predictions
    {model: (N, 12)} against the measurements Y on the measured channels."""
    out = {STATE_NAMES[i]: {} for i in measured_idx}
    for name, X in preds.items():
        for ch, sc in _scores(Y, X, measured_idx).items():
            out[ch].update({k + SUFFIX[name]: v for k, v in sc.items()})
    return out


def _free_run_scores(Y, free, failed, measured_idx):
    """_merged_scores of the free runs; a model that stopped early (failed {model: s or None})
    is not scored on a part: NaN."""
    channels = _merged_scores(Y, free, measured_idx)
    for name, at in failed.items():
        if at is not None:
            for ch in channels.values():
                for key in ('fit_percent', 'rmse', 'theil'):
                    ch[key + SUFFIX[name]] = float('nan')
    return channels


def _derived_scores(Y, free, failed, measured_idx):
    """{'U': scores with each model's SUFFIX} of the total speed of the free runs when the run
    measures u and v (NaN for a model that stopped early), else {}."""
    if State.U not in measured_idx or State.V not in measured_idx:
        return {}
    speed = {}
    for name, X in free.items():
        sc = ({'fit_percent': float('nan'), 'rmse': float('nan'), 'theil': float('nan')}
              if failed[name] is not None else _speed_scores(Y, X))
        speed.update({k + SUFFIX[name]: v for k, v in sc.items()})
    return {'U': speed}


def validate_on_bag(vehicle, names, estimate, current, bag, velocity_reference=None,
                    input_map=None, **kwargs):
    """validate_on_run on a bag's measurements as the data are: every well-formed odometry
    message paired with the command in force at its stamp, none judged by a filter's
    innovation gate (bag_identify.bag_source with filtering False: a model under test that
    disagrees with a sample must be scored on it, not drop it; the Source's `screening` says
    what the screening of malformed messages dropped). The truth flies too when the bag is our
    simulator's (its truth is the vehicle file). velocity_reference: None for what the bag
    says (else 'ground'); input_map: the bag's topics and fields (session/input_map.py; None:
    the one its metadata names, else the default); kwargs: validate_on_run's horizons,
    max_step, x0_window. Returns (RunValidation, Source)."""
    from auv_ident.analysis.bag_identify import bag_source
    run = bag_source(bag, IdentifierSettings.from_values(
        vehicle=vehicle.path, coefficients=names, velocity_reference=velocity_reference,
        input_map=input_map), filtering=False)
    val = validate_on_run(vehicle, names, estimate, current, run.t, run.Y, run.U,
                          source=run.description, velocity_reference=run.velocity_reference,
                          include_truth=run.truth is not None, truth_current=run.current_truth,
                          **kwargs)
    return val, run


# ------------------------------------------------------------------------------- the report

DEG = 180.0 / np.pi
# display scale and unit per channel (angles in degrees: readable numbers)
DISPLAY_SCALE = np.array([1, 1, 1, DEG, DEG, DEG, 1, 1, 1, DEG, DEG, DEG], dtype=float)
DISPLAY_UNITS = ('m/s',) * 3 + ('deg/s',) * 3 + ('m',) * 3 + ('deg',) * 3
MODEL_LABELS = {'identified': 'identified', 'prior': 'prior (vehicle file)', 'truth': 'true'}


def markdown_lines(vd, held_out_fraction=None):
    """The report's section on the validation against measurements (lines), from the
    `validation` document (RunValidation.document)."""
    models = vd['models']
    L = ['', '## Validation against measurements', '',
         f'Run: {vd["source"]}, {vd["samples"]} measured samples over {vd["duration_s"]:.1f} s.']
    if held_out_fraction:
        L[-1] += (f' The final {100 * held_out_fraction:g} % of the run was held out: the '
                  f'identification used only the first {100 * (1 - held_out_fraction):g} %.')
    cur = vd['current_identified']
    win = vd['initial_state']['fit_window_s']
    start = (f'the straight-line fit of each channel over the first {win:g} s of measurements'
             if win else 'the first complete measured sample')
    L += ['', f"From the initial state at the first complete sample ({start}), with the run's "
              'measured commands held between their stamps, the identified model'
          + (' (in the identified current ' + ', '.join(f'{c:.3g}' for c in cur)
             + ' m/s N, E, D)' if cur else '')
          + " and the prior model (the vehicle file's values, still water)"
          + (' and the true model' if 'truth' in models else '')
          + ' fly freely; per channel: fit % = 100 (1 - ||y - y_hat|| / ||y - mean y||) '
            "(100 perfect, 0 no better than the mean), RMSE, and Theil's inequality "
            'coefficient (0 perfect, below ~0.3 adequate).']
    if vd['initial_state']['filled']:
        L += ['', 'Initial state channels not measured: '
              + '; '.join(f'{k} ({v})' for k, v in vd['initial_state']['filled'].items())]
    for m, at in vd['failed_at_s'].items():
        if at is not None:
            L += ['', f'**The {MODEL_LABELS[m]} model left its domain at t = {at:.1f} s: its '
                      'free-run scores are not given.**']
    mean = vd['mean_fit_percent_nu']
    L += ['', 'Mean fit over the measured ones of u v w p q r: '
          + ', '.join(f'{MODEL_LABELS[m]} {finite_cell(mean[m], ".1f")} %' for m in models)
          + '.', '']
    header = ['channel'] + [f'fit % {MODEL_LABELS[m]}' for m in models] \
        + [f'RMSE {MODEL_LABELS[m]}' for m in models] \
        + [f'Theil {MODEL_LABELS[m]}' for m in models] + ['RMSE unit']
    rows = []
    for ch, d in vd['channels'].items():
        i = STATE_NAMES.index(ch)
        rows.append([ch] + [finite_cell(d['fit_percent' + SUFFIX[m]], '.2f') for m in models]
                    + [finite_cell(None if d['rmse' + SUFFIX[m]] is None
                             else d['rmse' + SUFFIX[m]] * DISPLAY_SCALE[i]) for m in models]
                    + [finite_cell(d['theil' + SUFFIX[m]], '.3f') for m in models]
                    + [DISPLAY_UNITS[i]])
    for ch, d in (vd.get('derived_channels') or {}).items():     # U = sqrt(u^2 + v^2)
        rows.append([f'{ch} (derived)'] + [finite_cell(d['fit_percent' + SUFFIX[m]], '.2f')
                                           for m in models]
                    + [finite_cell(d['rmse' + SUFFIX[m]]) for m in models]
                    + [finite_cell(d['theil' + SUFFIX[m]], '.3f') for m in models] + ['m/s'])
    L += markdown_table(header, rows).split('\n')
    keys = list(vd['prediction'])
    L += ['', '### K-step-ahead prediction', '',
          'Positions and heading drift in any free run, so the models also restart from the '
          'measured state every K measured samples and predict the next K (RMSE of the '
          'predictions; ' + ', '.join(f'K = {vd["prediction"][k]["horizon_samples"]} is '
                                      f'{vd["prediction"][k]["horizon_s"]:.3g} s'
                                      for k in keys) + ').', '']
    header = ['channel'] + [f'K={vd["prediction"][k]["horizon_samples"]} {MODEL_LABELS[m]}'
                            for k in keys for m in models] + ['unit']
    rows = []
    for ch in vd['channels']:
        i = STATE_NAMES.index(ch)
        row = [ch]
        for k in keys:
            d = vd['prediction'][k]['channels'][ch]
            for m in models:
                v = d['rmse' + SUFFIX[m]]
                row.append(finite_cell(None if v is None else v * DISPLAY_SCALE[i]))
        rows.append(row + [DISPLAY_UNITS[i]])
    return L + markdown_table(header, rows).split('\n')


def fig_measured(path, val, channels, title):
    """Measured vs the models' free runs, one panel per channel (a 3 x 2 grid for 6)."""
    plt = pyplot()
    ncol = 2 if len(channels) > 3 else 1
    nrow = -(-len(channels) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(6.0 * ncol, 2.3 * nrow + 1.0), sharex=True,
                             squeeze=False, layout='constrained')
    style = {'identified': dict(color='C3', lw=1.3), 'prior': dict(color='C0', lw=1.1, ls='--'),
             'truth': dict(color='k', lw=0.9, ls=':')}
    t = val.t
    for k, i in enumerate(channels):
        ax = axes[k % nrow, k // nrow]
        ch = STATE_NAMES[i]
        Ym = val.Y
        ok = np.isfinite(Ym[:, i])
        for name, X in val.free.items():
            Yu, Xu = angle_channels(Ym, X)
            ax.plot(t, DISPLAY_SCALE[i] * Xu[:, i], label=f'{MODEL_LABELS[name]} model',
                    **style[name])
        Yu = angle_channels(Ym, Ym)[0]
        ax.plot(t[ok], DISPLAY_SCALE[i] * Yu[ok, i], '.', color='0.45', ms=1.5, zorder=0,
                label='measured')
        d = val.channels.get(ch, {})
        fits = ', '.join(
            f'{MODEL_LABELS[m]} {finite_cell(d.get("fit_percent" + SUFFIX[m]), ".1f")}'
            for m in val.free)
        ax.set_title(f'{ch}: fit % {fits}', fontsize=8)
        ax.set_ylabel(f'{ch} ({DISPLAY_UNITS[i]})')
        ax.grid(alpha=0.3)
        if ch == 'z':
            ax.invert_yaxis()      # depth grows downwards
    for ax in axes[-1]:
        ax.set_xlabel('time (s)')
    axes[0, 0].legend(fontsize=7, loc='best', markerscale=4)
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)
