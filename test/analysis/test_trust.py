"""A result that should not be trusted says so on its first line, in result.json and in the
exit status (EXIT_UNTRUSTED = 3): here another vehicle's file fitted to the shipped bag, whose
identification is NOT plausible (a self-damping term identified positive); the right file's
result is trusted, exit 0."""
import json
from pathlib import Path

import helpers
import pytest

from auv_ident.cli import EXIT_UNTRUSTED, main

BAG = str(Path(helpers.REPO) / 'bags' / 'nps_auv2_ident')


def test_another_vehicles_file_is_not_plausible_and_exits_3(tmp_path, capsys):
    out = tmp_path / 'wrong.json'
    rc = main(['identify', '--bag', BAG, '--vehicle', 'remus100', '--other-vehicle',
               '--current', 'none', '--no-refine', '--json', str(out)])
    first = capsys.readouterr().out.splitlines()[0]
    assert rc == EXIT_UNTRUSTED == 3
    assert first.startswith('NOT plausible: ') and 'Y_v' in first and 'vehicle file' in first
    diagnosis = json.loads(out.read_text())['diagnosis']
    assert diagnosis['plausible'] is False and diagnosis['trusted'] is False
    assert diagnosis['messages'][0] == first and diagnosis['implausible']


def test_another_vehicle_than_the_bag_records_is_refused(tmp_path, capsys):
    out = tmp_path / 'refused.json'
    rc = main(['identify', '--bag', BAG, '--vehicle', 'remus100', '--json', str(out)])
    captured = capsys.readouterr()
    assert rc == 2 and not out.exists() and captured.out == ''
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "records vehicle 'nps_auv2'" in err[0]
    assert "'remus100'" in err[0] and '--other-vehicle' in err[0]


def test_the_right_vehicle_file_is_trusted_and_exits_0(tmp_path, capsys):
    out = tmp_path / 'right.json'
    rc = main(['identify', '--bag', BAG, '--current', 'none', '--no-refine',
               '--json', str(out)])
    first = capsys.readouterr().out.splitlines()[0]
    assert rc == 0 and first.startswith('consistent: ')
    diagnosis = json.loads(out.read_text())['diagnosis']
    assert diagnosis['plausible'] is True and diagnosis['trusted'] is True
    assert diagnosis['implausible'] == []


SHIPPED = ('nps_auv2', 'remus100', 'isimi', 'kvlcc2_hsva')


@pytest.mark.slow       # 16 identifications of 300 s bags
def test_every_shipped_file_on_another_vehicles_bag_is_refused_or_flagged(tmp_path_factory):
    """Each shipped vehicle's bag (300 s, seed 3; zig-zags for the ship) identified with every
    shipped vehicle file, insisting (--other-vehicle: without it each other file is refused at
    once, test_another_vehicle_than_the_bag_records_is_refused): the right file is trusted
    (exit 0), every other one is refused (exit 2, one line) or flagged NOT plausible / NOT
    consistent (exit 3); never a confident result."""
    import subprocess
    import sys
    root = tmp_path_factory.mktemp('pairs')
    for v in SHIPPED:
        subprocess.run([sys.executable, '-m', 'auv_ident', 'simulate', '--vehicle', v,
                        '--maneuver', 'zigzag' if v == 'kvlcc2_hsva' else 'ident',
                        '--duration', '300', '--seed', '3', '--out', str(root / v)],
                       check=True, capture_output=True, cwd=helpers.REPO, timeout=300)
    for bag in SHIPPED:
        for v in SHIPPED:
            r = subprocess.run([sys.executable, '-m', 'auv_ident', 'identify', '--bag',
                                str(root / bag), '--vehicle', v, '--other-vehicle'],
                               capture_output=True, text=True, cwd=helpers.REPO, timeout=600)
            first = r.stdout.splitlines()[0] if r.stdout else ''
            if bag == v:
                assert r.returncode == 0 and first.startswith('consistent'), (bag, v, first)
            else:
                assert r.returncode in (2, EXIT_UNTRUSTED), (bag, v, r.returncode, first)
                if r.returncode == EXIT_UNTRUSTED:
                    assert first.startswith('NOT '), (bag, v, first)
