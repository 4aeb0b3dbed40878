"""`--coefficients auto[,NAME,...]` end to end: identify --bag on an independent bag whose truth
differs from the vehicle file, the JSON `selection` block, the estimate file for the live
node, and the errors (an unknown name; 'auto' where only a fixed set is possible). The live
node's own [auto] is test/session/test_auto_choice.py."""
import json
from pathlib import Path
import re
import sys

import pytest

from auv_ident.cli import main
from auv_ident.session.session import IdentSession
from auv_ident.session.settings import IdentifierSettings
from auv_ident.vehicles import load_vehicle

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from auv_ident.offline.independent_data import DataConfig, generate  # noqa: E402


@pytest.fixture(scope='module')
def perturbed_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp('auto') / 'run'
    return generate(DataConfig(duration=120.0, seed=5, odom_rate=20.0, commands='periodic',
                               perturb=0.2), out)


@pytest.mark.slow
def test_auto_with_a_name_lists_every_coefficient_as_chosen_or_left_out(perturbed_bag, tmp_path,
                                                                        capsys):
    out, est = tmp_path / 'auto.json', tmp_path / 'estimate.json'
    rc = main(['identify', '--vehicle', 'nps_auv2', '--bag', str(perturbed_bag.bag),
               '--coefficients', 'auto,K_v', '--json', str(out), '--estimate-out', str(est)])
    text = capsys.readouterr().out
    assert rc == 0
    doc = json.loads(out.read_text())
    sel = doc['selection']
    v = load_vehicle('nps_auv2')
    assert sel['named'] == ['K_v'] and sel['chosen'][0] == 'K_v'
    assert len(sel['chosen']) > 1                  # a wrong prior: the data ask for more
    assert list(doc['coefficients']) == sel['chosen']
    assert set(sel['chosen']).isdisjoint(sel['left_out'])
    assert set(sel['chosen']) | set(sel['left_out']) == set(v.names)
    assert all(isinstance(r, str) and r for r in sel['left_out'].values())
    assert sel['criteria']['rel_std_max'] == 0.05 and sel['criteria']['correlation_max'] == 0.95
    assert 'automatic selection:' in text and 'left out (vehicle file values kept' in text
    # every left-out coefficient is named in the printed text, none silently valued
    for name in sel['left_out']:
        assert name in text
    # the widening is what the residuals allow, said with its sources; sentences for people
    # carry no nan, None or exponent
    assert 0.0 <= sel['consider_scale'] <= 1.0
    assert ("error bars include the errors of the coefficients left at the file's values "
            '(the residuals ') in text
    widened = [n for n, r in sel['consider_inflation'].items() if r >= 1.005]
    assert all(sel['consider_sources'][n] for n in widened)
    machine = re.compile(r'\bnan\b|\bNone\b|\binf\b|\d[eE][+-]?\d')
    sentences = (doc['diagnosis']['messages'] + list(sel['left_out'].values())
                 + [line for line in text.splitlines() if line.startswith(('- ', 'error bars'))])
    assert not [s for s in sentences if machine.search(s)]
    assert 'mean NIS/dof nan' not in text
    # a coefficient's verdict is judged by the run's information, not by the widened bar
    for name in widened:
        if name in doc['coefficients']:
            assert doc['identifiability'][name]['crb_std'] < doc['coefficients'][name]['std']
    warm = json.loads(est.read_text())
    assert warm['vehicle'] == 'nps_auv2' and warm['coefficients'] == sel['chosen']
    session = IdentSession(IdentifierSettings.from_values(vehicle='nps_auv2', warm_start=str(est)))
    assert session.names[:len(sel['chosen'])] == sel['chosen']


def test_an_unknown_name_after_auto_is_one_clear_error(perturbed_bag, capsys):
    rc = main(['identify', '--vehicle', 'nps_auv2', '--bag', str(perturbed_bag.bag),
               '--coefficients', 'auto,Z_ds,Q_xyz'])
    err = capsys.readouterr().err
    assert rc == 2
    assert "unknown coefficient 'Q_xyz'" in err and 'Traceback' not in err


def test_auto_where_the_set_is_fixed_says_how_to_get_it(capsys):
    rc = main(['identify', '--vehicle', 'nps_auv2', '--simulate', 'ident', '--duration', '10',
               '--coefficients', 'auto'])
    assert rc == 2 and 'identify --bag' in capsys.readouterr().err


def test_mass_inverse_option_reaches_the_bag_identification(perturbed_bag, tmp_path, capsys):
    """identify --bag --mass-inverse exact: the replay and the identification form M^-1
    exactly, so an added-mass coefficient can be identified (with the vehicle file's literal
    inverse it is one clear error naming the option)."""
    out = tmp_path / 'am.json'
    rc = main(['identify', '--vehicle', 'nps_auv2', '--bag', str(perturbed_bag.bag),
               '--coefficients', 'Z_w,Z_wdot', '--mass-inverse', 'exact', '--no-refine',
               '--json', str(out)])
    assert rc == 0, capsys.readouterr().err
    doc = json.loads(out.read_text())
    assert doc['mass_inverse'] == 'exact' and list(doc['coefficients']) == ['Z_w', 'Z_wdot']
    capsys.readouterr()
    rc = main(['identify', '--vehicle', 'nps_auv2', '--bag', str(perturbed_bag.bag),
               '--coefficients', 'Z_w,Z_wdot', '--no-refine'])
    assert rc == 2 and '--mass-inverse exact' in capsys.readouterr().err
