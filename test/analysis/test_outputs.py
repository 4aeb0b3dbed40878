"""Outputs of the commands (#27 items 8, 10): an existing output is never overwritten silently
(refused before any work unless --force), and a path that cannot be written is said at once,
not after the computation."""
import time

import pytest

from auv_ident.cli import main

BAG = 'bags/nps_auv2_ident'

# every command writing a result, with a fast input: the refusal must come before any work
CASES = [
    (['identify', '--bag', BAG, '--json'], '--json'),
    (['identify', '--bag', BAG, '--estimate-out'], '--estimate-out'),
    (['simulate', '--duration', '600', '--out'], '--out'),
    (['report', '--simulate', 'ident', '--out'], '--out'),
    (['compare-methods', '--simulate', 'ident', '--json'], '--json'),
    (['montecarlo', '--seeds', '50', '--json'], '--json'),
    (['bench', '--json'], '--json'),
]


@pytest.mark.parametrize('argv, option', CASES, ids=[' '.join(c[0][:2]) for c in CASES])
def test_an_existing_output_is_refused_before_any_work(argv, option, tmp_path, capsys):
    out = tmp_path / ('report' if argv[0] == 'report' else 'out.csv')
    if argv[0] == 'report':
        out.mkdir()
        (out / 'report.md').write_text('earlier report\n')
    else:
        out.write_text('earlier result\n')
    t0 = time.monotonic()
    assert main(argv + [str(out)]) == 2
    assert time.monotonic() - t0 < 10.0                      # no identification was run
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f'error: {option} {out}: exists already; give --force to overwrite it']
    kept = out / 'report.md' if argv[0] == 'report' else out
    assert kept.read_text() == 'earlier report\n' if argv[0] == 'report' \
        else kept.read_text() == 'earlier result\n'


@pytest.mark.parametrize('argv, option', CASES[:3], ids=[' '.join(c[0][:2]) for c in CASES[:3]])
def test_an_output_folder_that_does_not_exist_is_said_at_once(argv, option, tmp_path, capsys):
    out = tmp_path / 'no_such_folder' / 'out.csv'
    assert main(argv + [str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f'error: {option} {out}: its folder {out.parent} does not exist']


def test_force_overwrites(tmp_path, capsys):
    out = tmp_path / 'run.csv'
    out.write_text('earlier result\n')
    assert main(['simulate', '--duration', '2', '--out', str(out), '--force']) == 0
    assert out.read_text().startswith('t,')
    assert f'wrote {out}' in capsys.readouterr().out


def test_an_estimate_file_asked_of_several_bags_is_refused_at_once(tmp_path, capsys):
    """identify --bag A --bag B --estimate-out FILE identified both and wrote nothing, silently:
    an option that is not honoured is refused before the work, naming it."""
    out = tmp_path / 'e.json'
    t0 = time.monotonic()
    assert main(['identify', '--bag', BAG, '--bag', BAG, '--estimate-out', str(out)]) == 2
    assert time.monotonic() - t0 < 10.0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('error: --estimate-out: one --bag only')
    assert not out.exists()
