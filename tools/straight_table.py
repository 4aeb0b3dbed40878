#!/usr/bin/env python3
"""Write a copy of a vehicle file whose thrust tables state straight lines between their points
in chosen command intervals: what docs/vehicles.md ("The table's truth", BlueROV2 Heavy) uses to
find where the file's monotone cubic and the independent generator's straight lines differ in
effect.

Run from the package root:
    .venv/bin/python tools/straight_table.py config/bluerov2_heavy.yaml /tmp/lines.yaml \\
        --between 1468:1472,1528:1532

Every thruster's `table:` gets points every --step command units (default 1: a PWM in us)
strictly inside each interval LO:HI (or inside every interval of the table with --between
all), on the straight line between the table's neighbouring points. The file's interpolation
(PCHIP, core/model/thrusters.py) then passes through those points, so at every command on the
--step grid (the generator's integer PWMs) the curve is the straight line. Outside the
intervals it is the file's curve as before, but in the table interval next to each: the PCHIP
slope at the point they share moves with the spacing (its weights), by at most 3.2 mN on the
T200 of config/bluerov2_heavy.yaml. The rest of the file is copied as read (its comments are
not).
"""
import argparse
import os
import sys

import numpy as np
import yaml

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from auv_ident.core.vehicle_files import read_yaml_file  # noqa: E402


def _intervals(text):
    """'all' -> None; 'LO:HI,LO:HI' -> [(lo, hi), ...] (command units)."""
    if text == 'all':
        return None
    out = []
    for part in text.split(','):
        lo, hi = (float(v) for v in part.split(':'))
        if not hi > lo:
            raise SystemExit(f'--between {part}: HI must be above LO')
        out.append((lo, hi))
    return out


def straight_table(table, intervals, step):
    """The table dict with the straight-line points added (module docstring)."""
    x = np.asarray(table['command'], dtype=float)
    f = np.asarray(table['thrust'], dtype=float)
    grid = np.arange(x[0], x[-1] + 0.5 * step, step)
    inside = (np.ones(grid.shape, bool) if intervals is None else
              np.any([(grid > lo) & (grid < hi) for lo, hi in intervals], axis=0))
    new = np.union1d(x, grid[inside])
    return dict(table, command=[float(v) for v in new],
                thrust=[float(v) for v in np.interp(new, x, f)])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('vehicle', help='vehicle file (YAML) with thrust tables')
    ap.add_argument('out', help='the copy to write (YAML)')
    ap.add_argument('--between', default='all',
                    help="LO:HI[,LO:HI...] command intervals, or 'all' (default)")
    ap.add_argument('--step', type=float, default=1.0, help='command units between points')
    args = ap.parse_args(argv)
    if not args.step > 0:
        raise SystemExit('--step must be positive')
    doc = read_yaml_file(args.vehicle)
    intervals = _intervals(args.between)
    changed = 0
    for entry in doc.get('thrusters') or []:
        if isinstance(entry, dict) and isinstance(entry.get('table'), dict):
            entry['table'] = straight_table(entry['table'], intervals, args.step)
            changed += 1
    if not changed:
        raise SystemExit(f'{args.vehicle}: no thruster has a table')
    with open(args.out, 'w', encoding='utf-8') as fh:
        yaml.safe_dump(doc, fh, sort_keys=False)
    print(f'wrote {args.out}: {changed} tables, straight lines '
          f'{"everywhere" if intervals is None else "in " + args.between}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
