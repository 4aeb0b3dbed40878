"""Zig-zag measures, steering gear and thrust model of measured runs, as tables.

Glue over :mod:`auv_ident.core.simulation.zigzag`, :mod:`~auv_ident.core.simulation.steering`,
:mod:`~auv_ident.core.identification.thrust_fit` for files read with
:mod:`auv_ident.offline.importers` (tools/zigzag_measures.py prints these tables; docs/zigzag.md
shows them):

- :func:`load_hsva_runs` reads the four HSVA KVLCC2 zig-zags (SIMMAN 2008) from a directory;
- :func:`measured_measures` gives the measures of a run with its first execute at the order
  time the gear implies (rudder onset minus the mean onset delay), so measured and simulated
  measures share the definition of the execute;
- :func:`closed_loop` simulates a run's zig-zag with a model (identified gear and ideal helm);
- :func:`measures_table`, :func:`gear_table`, :func:`thrust_table`, :func:`closed_loop_table`
  format Markdown tables.
"""
from pathlib import Path

import numpy as np

from auv_ident.core.errors import DataError
from auv_ident.core.model.state import State
from auv_ident.core.simulation.zigzag import zigzag_measures
from auv_ident.core.simulation.zigzag_sim import simulate_zigzag
from auv_ident.offline.importers import read_hsva

HSVA_RUNS = ('Z_10_10_S', 'Z_10_10_P', 'Z_20_10_S', 'Z_20_10_P')
HSVA_PATTERN = 'HSVA_CPMC_KVLCC2_{}.dat'


def load_hsva_runs(directory, names=HSVA_RUNS):
    """{name: MeasuredRun} of the HSVA zig-zag files in directory; DataError naming a missing
    file."""
    directory = Path(directory)
    out = {}
    for name in names:
        path = directory / HSVA_PATTERN.format(name)
        if not path.is_file():
            raise DataError(f'{path}: no such file (the HSVA KVLCC2 runs are read from a '
                            'directory holding HSVA_CPMC_KVLCC2_Z_*.dat)')
        out[name] = read_hsva(path)
    return out


def measured_measures(run, ident=None):
    """ZigzagMeasures of a measured run; with a GearIdentification, the first execute is the
    estimated order time (the rudder onset minus the mean onset delay)."""
    t, psi, delta = run.t, run.x[:, State.PSI], run.inputs['rudder']
    m = zigzag_measures(t, psi, delta)
    if ident is None:
        return m
    return zigzag_measures(t, psi, delta, execute_time=ident.execute_order_time(m))


def _f(v, fmt='.2f'):
    return '-' if v is None or (isinstance(v, float) and np.isnan(v)) else format(v, fmt)


def measures_table(measures):
    """Markdown table of {name: ZigzagMeasures}: angles deg, times s; the overshoots after the
    second in one cell."""
    head = ['run', 'test', 'first', 'rudder (deg)', 'switch at onset (deg)', 'execute (s)',
            'initial turning (s)', '1st overshoot (deg)', '2nd overshoot (deg)',
            'time to 1st (s)', 'time to 2nd (s)', 'period (s)', 'further overshoots (deg)']
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    for name, m in measures.items():
        tt = m.times_to_overshoot + [float('nan')] * 2
        row = [name, m.label, m.first, _f(m.rudder_deg), _f(m.switch_deg),
               _f(m.execute_time), _f(m.initial_turning_time), _f(m.first_overshoot_deg),
               _f(m.second_overshoot_deg), _f(tt[0]), _f(tt[1]), _f(m.period),
               ', '.join(_f(v) for v in m.overshoots_deg[2:]) or '-']
        lines.append('| ' + ' | '.join(row) + ' |')
    return '\n'.join(lines)


def gear_table(ident, names):
    """Markdown tables of a GearIdentification: per reversal, then mean +- sd and the joint
    fit. names: the run names in the order the runs were given."""
    head = ['run', 'reversal', 'check time (s)', 'swing (deg)', 'onset delay (s)',
            'mean rate (deg/s)', 'fit delay (s)', 'fit rate (deg/s)', 'fit T_s (s)',
            'fit rms (deg)']
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    for r in ident.reversals:
        lines.append('| ' + ' | '.join([
            names[r['run']], str(r['k']), _f(r['check_time']), _f(r['swing_deg']),
            _f(r['onset_delay'], '.3f'), _f(r['mean_rate']), _f(r['delay'], '.3f'),
            _f(r['rate']), _f(r['time_constant'], '.3f'), _f(r['rms_deg'], '.3f')]) + ' |')
    s = ident.summary
    lines.append('| mean +- sd | ' + str(len(ident.reversals)) + ' | | | ' + ' | '.join(
        f'{s[k][0]:{p}} +- {s[k][1]:{p}}' for k, p in
        (('onset_delay', '.3f'), ('mean_rate', '.2f'), ('delay', '.3f'), ('rate', '.2f'),
         ('time_constant', '.3f'), ('rms_deg', '.3f'))) + ' |')
    g = ident.gear
    lines.append(f'| joint fit | {len(ident.reversals)} | | | | | {g.delay:.3f} | '
                 f'{g.rate_deg_s:.2f} | {g.time_constant:.3f} | {ident.rms_deg:.3f} |')
    return '\n'.join(lines)


def thrust_table(models, names):
    """Markdown table of {label: ThrustModel}: formula, rms and leave-one-run-out rms (N)."""
    head = ['model', 'formula', 'rms (N)'] + [f'{n} left out (N)' for n in names]
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    for label, m in models.items():
        lines.append('| ' + ' | '.join([label, m.formula(), _f(m.rms)]
                                       + [_f(v) for v in m.loro_rms]) + ' |')
    return '\n'.join(lines)


def closed_loop(run, f, ident, ideal, step=0.05, x0=None, **sim):
    """Measured and simulated measures of a run: the model f (x, u) -> x_dot from the run's
    first measured state (or x0 (12,) at t = 0), with the run's test, side and order time of
    the first execute, once through the identified gear and once with the ideal helm (None:
    not simulated). sim: simulate_zigzag's thrust, thrust_index, inputs, n_inputs. Returns
    (measured, with gear, ideal) ZigzagMeasures and the two ZigzagSimulations."""
    m = measured_measures(run, ident)
    kw = dict(rudder_deg=m.nominal[0], switch_deg=m.nominal[1], duration=float(run.t[-1]),
              first=m.first, execute_time=m.execute_time, step=step, **sim)
    x0 = run.x[0] if x0 is None else x0
    sim_g = simulate_zigzag(f, x0, gear=ident.gear, **kw)
    sim_i = None if ideal is None else simulate_zigzag(f, x0, gear=ideal, **kw)
    return m, sim_g, sim_i


def closed_loop_table(rows):
    """Markdown table of {name: (measured, sim with gear, sim ideal, heading fit %)}: first
    and second overshoots (deg) and the time to the first (s)."""
    head = ['run', 'measured 1st / 2nd (deg)', 'model + identified gear', 'model + ideal helm',
            'helm effect on 1st (deg)', 'time to 1st: measured / gear / ideal (s)',
            'heading fit % (gear)']
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    for name, (m, g, i, fit) in rows.items():
        def pair(x):
            return f'{_f(x.first_overshoot_deg)} / {_f(x.second_overshoot_deg)}'
        lines.append('| ' + ' | '.join([
            name, pair(m), pair(g), pair(i),
            _f(g.first_overshoot_deg - i.first_overshoot_deg, '+.2f'),
            ' / '.join(_f(x.times_to_overshoot[0] if x.times_to_overshoot else None)
                       for x in (m, g, i)), _f(fit, '.1f')]) + ' |')
    return '\n'.join(lines)
