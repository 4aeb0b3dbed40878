"""The glider campaign (issue #31, docs/glider.md): calibrate the Slocum glider's flight model
on the first half of its record and validate it on the second, and the reverse, beside a
steady-state calibration in gliderflight's style on the same split; prints the markdown tables
(auv_ident/analysis/glider.py says what they hold).

    python -m auv_ident import --format npy \\
        ../shared/realdata/slocum_comet/gliderflight_data.npy --out /tmp/comet
    PYTHONPATH=. .venv/bin/python tools/glider_campaign.py /tmp/comet [--json OUT.json] \\
        [--plot PNG] [--vehicle slocum_comet] [--variants]

The prior is the glider file's (--vehicle, a name in config/ or a path; config/slocum_comet.yaml).
"""
import argparse
import json
from pathlib import Path
import sys

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from auv_ident.analysis.glider import (  # noqa: E402
    format_campaign,
    format_variants,
    plot_campaign,
    run_campaign,
    run_variants,
)
from auv_ident.core.errors import AuvIdentError  # noqa: E402
from auv_ident.core.glider.vehicle import glider_from_file  # noqa: E402
from auv_ident.offline.glider_import import read_glider_bag  # noqa: E402
from auv_ident.vehicles import resolve_vehicle_path  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('bag', help='a glider bag written by import --format npy')
    ap.add_argument('--json', help='write the campaign here')
    ap.add_argument('--plot', metavar='PNG', help='draw the campaign here')
    ap.add_argument('--variants', action='store_true',
                    help='also the terms ours leaves out, each added alone (analysis/glider.py '
                         'VARIANTS), judged as ours')
    ap.add_argument('--vehicle', default='slocum_comet',
                    help='the glider file of the prior (a name in config/ or a path)')
    a = ap.parse_args(argv)
    try:
        glider = glider_from_file(resolve_vehicle_path(a.vehicle))
        record = read_glider_bag(a.bag)
        result = run_campaign(record, glider.params)
        if a.variants:
            result['variants'] = run_variants(record, glider.params, result['split'])
    except AuvIdentError as err:
        print(f'error: {err}', file=sys.stderr)
        return 2
    print('\n'.join(format_campaign(result)))
    if a.variants:
        print('\nThe terms ours leaves out, each added alone, on the half not fitted:\n')
        print('\n'.join(format_variants(result['variants'])))
    if a.plot:
        plot_campaign(record, result, a.plot)
    if a.json:
        Path(a.json).write_text(json.dumps(result, indent=1, default=float) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
