"""gliderflight as a peer (issue #31, docs/glider.md): Merckelbach's own SteadyStateCalibrate and
DynamicCalibrate, run as his example runs them, on the same split by time as
tools/glider_campaign.py, judged with the same scores and printed in the same table columns.

    PYTHONPATH=. .venv/bin/python tools/gliderflight_peer.py /tmp/comet \\
        --gliderflight-path /tmp/gfvenv/lib/python3.11/site-packages [--json OUT.json] \\
        [--free Cd0 mg Vg] [--vehicle slocum_comet]

gliderflight (MIT, PyPI) is not a dependency of auv_ident: install it into a scratch venv
(``python -m venv /tmp/gfvenv && /tmp/gfvenv/bin/pip install gliderflight``) and name its
site-packages with --gliderflight-path; the folder is appended to sys.path, so the packages
both have (numpy, scipy) stay this venv's. Without gliderflight the tool says so and exits with
77 (skipped), having run nothing.

As gliderflight's examples/my_first_example.py: one density rho0 = 1004 kg/m^3 for the depth
rate, a_h 3.8, C_D1 10.5, the samples between 10 and 35 dbar, start Cd0 0.15, mg 70 kg,
Vg 70/1004 m^3; Cd0 and mg calibrated as the example does (--free Cd0 mg Vg: the issue's
baseline, Vg too) by its Nelder-Mead on the depth rate, with its own tolerances; the dynamic
model with k1 0.2, k2 0.92 (as ours; the example's k2 is 0.98), dt 1 s, on one process
(max_CPUs=1: the same integration on any machine). gliderflight 1.2.1 from PyPI runs
unchanged with numpy 2.4 and scipy 1.17 (both calibrations complete with no error): the
numpy fix the issue mentions is not needed with it, and none is applied.

The calibrated model then flies the other half (a fresh SteadyStateGliderModel /
DynamicGliderModel with the calibrated values) and is judged as ours
(auv_ident.analysis.glider.judge): its U against the DVL over every sample and over the dives
that pass the instruments' consistency check, its depth rate (-w) against the pressure's; and
its RMS against ours (the campaign's dynamic model, calibrated on the same half from the glider
file's prior, --vehicle) on the same DVL samples, paired dive by dive with the difference's
1-sigma over the dives (auv_ident.analysis.glider.versus).
"""
import argparse
from dataclasses import replace
import json
from pathlib import Path
import sys
import time

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from auv_ident.analysis.glider import (  # noqa: E402
    format_flagged,
    judge,
    OURS,
    SCORE_HEADER,
    score_row,
    versus,
    VERSUS_HEADER,
    versus_row,
)
from auv_ident.core.errors import AuvIdentError  # noqa: E402
from auv_ident.core.glider.calibration import calibrate as calibrate_ours  # noqa: E402
from auv_ident.core.glider.flight import Flight, FLIGHT_MODELS  # noqa: E402
from auv_ident.core.glider.validation import consistent_dvl  # noqa: E402
from auv_ident.core.glider.vehicle import glider_from_file  # noqa: E402
from auv_ident.offline.glider_import import read_glider_bag  # noqa: E402
from auv_ident.vehicles import resolve_vehicle_path  # noqa: E402

SKIPPED = 77        # the exit status of a skipped run (automake's convention)
RHO0 = 1004.0       # kg/m^3, gliderflight's example
EXAMPLE = {'ah': 3.8, 'Cd1': 10.5}
START = {'Cd0': 0.15, 'mg': 70.0, 'Vg': 70.0 / 1004.0}
FREE = ('Cd0', 'mg')            # the example's; --free names others (Cd0 mg Vg)
WINDOW_DBAR = (10.0, 35.0)
K1, K2, DT = 0.2, 0.92, 1.0


def import_gliderflight(path=None):
    """The gliderflight module, or (None, why) when it is not importable."""
    if path:
        sys.path.append(str(path))
    try:
        import gliderflight
    except ImportError as err:
        return None, f'{type(err).__name__}: {err}'
    return gliderflight, ''


def _data(record):
    """gliderflight's input dict of a GliderRecord (pressure bar, buoyancy drive cc)."""
    return dict(time=record.t, pressure=record.pressure / 1e5, pitch=record.pitch,
                buoyancy_change=record.pumped_volume * 1e6, density=record.density)


def _model(gf, kind, calibrate):
    if kind == 'steady':
        cls = gf.SteadyStateCalibrate if calibrate else gf.SteadyStateGliderModel
        return cls(rho0=RHO0)
    cls = gf.DynamicCalibrate if calibrate else gf.DynamicGliderModel
    return cls(rho0=RHO0, k1=K1, k2=K2, dt=DT, max_CPUs=1)


def calibrate(gf, kind, record, free=FREE, xtol=None):
    """(values, seconds): gliderflight's calibration of the ``free`` parameters on a record;
    xtol: its Nelder-Mead's tolerance on the parameters scaled by its REFERENCE_VALUES (None:
    its own, 1e-4 steady, 1e-2 dynamic)."""
    m = _model(gf, kind, calibrate=True)
    if xtol is not None:
        m.xtol = float(xtol)
    m.define(**EXAMPLE)
    m.set_input_data(**_data(record))
    dbar = record.pressure / 1e4
    m.OR(dbar < WINDOW_DBAR[0])
    m.OR(dbar > WINDOW_DBAR[1])
    m.define(**START)
    t0 = time.perf_counter()
    values = m.calibrate(*free)
    return {k: float(v) for k, v in values.items()}, time.perf_counter() - t0


def fly(gf, kind, values, record):
    """Our Flight of gliderflight's model with the calibrated values over a record."""
    m = _model(gf, kind, calibrate=False)
    m.define(**EXAMPLE, **{**START, **values})     # the parameters not calibrated: START
    r = m.solve(_data(record))
    U = np.asarray(r.U, dtype=float)
    gamma = record.pitch + np.asarray(r.alpha, dtype=float)
    return Flight(speed=U, angle_of_attack=-np.asarray(r.alpha, dtype=float), glide_angle=gamma,
                  depth_rate=-np.asarray(r.w, dtype=float),
                  horizontal_speed=np.asarray(r.u, dtype=float),
                  buoyancy=np.full(len(record), np.nan))


def ours_speeds(halves, prior):
    """{validated half: (N,) m/s}: our dynamic model (the campaign's, OURS) calibrated on the
    other half from the prior (GliderParameters), flown on this one; as in the campaign,
    without the water temperature (ours leaves the hull's thermal expansion out,
    docs/glider.md)."""
    model, free, density, _ = OURS
    halves = {name: replace(h, temperature=None) for name, h in halves.items()}
    out = {}
    for fit_name, val_name in (('first', 'second'), ('second', 'first')):
        cal = calibrate_ours(halves[fit_name], prior, model, free,
                             depth_rate_density=density)
        out[val_name] = FLIGHT_MODELS[model](cal.params, halves[val_name]).speed
    return out


def run_peer(gf, record, kinds=('steady', 'dynamic'), free=FREE, prior=None, xtol=None,
             fitted_on=('first', 'second'), calibrated=None):
    """The peer's runs on a GliderRecord split at its middle (as run_campaign): per model
    kind and direction (the halves fitted on) the calibrated values, wall time and scores
    (judge), and with a prior (GliderParameters) its RMS against ours on the same samples
    (versus_ours); xtol as :func:`calibrate`. calibrated: a previous run's result (its
    'models'), whose values and wall times are judged again without calibrating anew."""
    t_split = 0.5 * (record.t[0] + record.t[-1])
    halves = dict(zip(('first', 'second'), record.split(t_split)))
    check = consistent_dvl(record)
    kept_times = record.t[check.keep]
    ours = ours_speeds(halves, prior) if prior is not None else None
    out = {'split': t_split, 'gliderflight': getattr(gf, '__version__', '?'), 'free': free,
           'xtol': xtol, 'models': {}, 'dvl_check': check.as_dict()}
    for kind in kinds:
        runs = {}
        for fit_name in fitted_on:
            val_name = 'second' if fit_name == 'first' else 'first'
            if calibrated is None:
                values, seconds = calibrate(gf, kind, halves[fit_name], free, xtol)
            else:
                old = calibrated['models'][f'gliderflight {kind} (its own code)'][fit_name]
                values, seconds = old['values'], old['seconds']
            val = halves[val_name]
            flight = fly(gf, kind, values, val)
            runs[fit_name] = {'fitted_on': fit_name, 'validated_on': val_name,
                              'values': values, 'seconds': seconds,
                              'validation': judge(flight, val, kept_times)}
            if ours is not None:
                runs[fit_name]['versus_ours'] = versus(flight.speed, ours[val_name], val,
                                                       kept_times)
        out['models'][f'gliderflight {kind} (its own code)'] = runs
    return out


def format_peer(result):
    free = result['free']
    xtol = result.get('xtol')
    L = [*format_flagged(result['dvl_check'], result['split']), '',
         f"gliderflight {result['gliderflight']}, calibrating {' '.join(free)}"
         + (f', xtol {xtol:g}' if xtol is not None else ''), '', *SCORE_HEADER]
    for label, runs in result['models'].items():
        L += [score_row(label, run) for run in runs.values()]
    if all('versus_ours' in run for runs in result['models'].values() for run in runs.values()):
        L += ['', *VERSUS_HEADER]
        for label, runs in result['models'].items():
            L += [versus_row(label, run) for run in runs.values()]
    L += ['', '| model | fitted on | ' + ' | '.join(free) + ' |', '|---|---|' + '---|' * len(free)]
    for label, runs in result['models'].items():
        for run in runs.values():
            L.append(f"| {label} | {run['fitted_on']} half | "
                     + ' | '.join(f"{run['values'][k]:.6g}" for k in free) + ' |')
    return L


def previous_run(path):
    """A previous run's result (its --json), checked to hold what run_peer reads again."""
    try:
        result = json.loads(Path(path).read_text())
        for runs in result['models'].values():
            for run in runs.values():
                run['values'], run['seconds']
        result['free']
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        raise AuvIdentError(f'--judge-again {path}: not a run of this tool '
                            f'({type(err).__name__}: {err})') from None
    return result


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('bag', help='a glider bag written by import --format npy')
    ap.add_argument('--gliderflight-path', metavar='DIR',
                    help="a site-packages folder holding gliderflight (a scratch venv's)")
    ap.add_argument('--steady-only', action='store_true',
                    help='skip the dynamic calibration (minutes)')
    ap.add_argument('--free', nargs='+', default=list(FREE), choices=('Cd0', 'mg', 'Vg'),
                    help="the parameters gliderflight calibrates (default: its example's)")
    ap.add_argument('--dynamic-only', action='store_true',
                    help='skip the steady calibration')
    ap.add_argument('--xtol', type=float,
                    help="gliderflight's Nelder-Mead tolerance on its scaled parameters "
                         '(default: its own, 1e-4 steady, 1e-2 dynamic)')
    ap.add_argument('--fitted-on', nargs='+', default=['first', 'second'],
                    choices=('first', 'second'), help='the halves to calibrate on')
    ap.add_argument('--judge-again', metavar='OLD.json',
                    help="judge a previous run's calibrated values (its --json) again, "
                         'without calibrating (the dynamic calibration takes minutes)')
    ap.add_argument('--vehicle', default='slocum_comet',
                    help="the glider file of ours' prior (a name in config/ or a path)")
    ap.add_argument('--json', help='write the runs here')
    a = ap.parse_args(argv)
    gf, why = import_gliderflight(a.gliderflight_path)
    if gf is None:
        print(f'skipped: gliderflight is not importable ({why}); install it into a scratch '
              'venv (python -m venv /tmp/gfvenv && /tmp/gfvenv/bin/pip install gliderflight) '
              'and pass --gliderflight-path /tmp/gfvenv/lib/python3.X/site-packages')
        return SKIPPED
    try:
        prior = glider_from_file(resolve_vehicle_path(a.vehicle)).params
        record = read_glider_bag(a.bag)
        calibrated = previous_run(a.judge_again) if a.judge_again else None
    except AuvIdentError as err:
        print(f'error: {err}', file=sys.stderr)
        return 2
    if calibrated is not None:
        a.free = calibrated['free']
        a.xtol = calibrated.get('xtol')
    kinds = tuple(k for k, skip in (('steady', a.dynamic_only), ('dynamic', a.steady_only))
                  if not skip)
    result = run_peer(gf, record, kinds, tuple(a.free), prior, a.xtol, tuple(a.fitted_on),
                      calibrated)
    print('\n'.join(format_peer(result)))
    if a.json:
        Path(a.json).write_text(json.dumps(result, indent=1, default=float) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
