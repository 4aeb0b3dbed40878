"""A result that should not be trusted says so on its first line, in result.json and in the
exit status (EXIT_UNTRUSTED = 3): here another vehicle's file fitted to the shipped bag, whose
identification is NOT plausible (a self-damping term identified positive); the right file's
result is trusted, exit 0."""
import json
from pathlib import Path

import helpers

from auv_ident.cli import EXIT_UNTRUSTED, main

BAG = str(Path(helpers.REPO) / 'bags' / 'nps_auv2_ident')


def test_another_vehicles_file_is_not_plausible_and_exits_3(tmp_path, capsys):
    out = tmp_path / 'wrong.json'
    rc = main(['identify', '--bag', BAG, '--vehicle', 'remus100', '--current', 'none',
               '--no-refine', '--json', str(out)])
    first = capsys.readouterr().out.splitlines()[0]
    assert rc == EXIT_UNTRUSTED == 3
    assert first.startswith('NOT plausible: ') and 'Y_v' in first and 'vehicle file' in first
    diagnosis = json.loads(out.read_text())['diagnosis']
    assert diagnosis['plausible'] is False and diagnosis['trusted'] is False
    assert diagnosis['messages'][0] == first and diagnosis['implausible']


def test_the_right_vehicle_file_is_trusted_and_exits_0(tmp_path, capsys):
    out = tmp_path / 'right.json'
    rc = main(['identify', '--bag', BAG, '--current', 'none', '--no-refine',
               '--json', str(out)])
    first = capsys.readouterr().out.splitlines()[0]
    assert rc == 0 and first.startswith('consistent: ')
    diagnosis = json.loads(out.read_text())['diagnosis']
    assert diagnosis['plausible'] is True and diagnosis['trusted'] is True
    assert diagnosis['implausible'] == []
