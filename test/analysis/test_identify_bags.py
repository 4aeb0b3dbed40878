"""One model from several bags (`identify --bag A --bag B`): two simulated bags of the planar
ship, identified together, recover the truth within their error bars; and a vehicle given as a
YAML path is that file for the bag paths."""
import json

import numpy as np
import pytest
import yaml

from auv_ident.analysis.bag_identify import identify_bags
from auv_ident.bags.reader import BagError
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import N_STATE, State
from auv_ident.core.simulation.simulate import simulate
from auv_ident.offline.sim_bag import write_run_bag
from auv_ident.session.settings import IdentifierSettings
from auv_ident.vehicles import load_vehicle

NAMES = 'Y_v,N_r,Y_dr,N_dr'


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    d = tmp_path_factory.mktemp('planar_bags')
    m = Model(load_vehicle('kvlcc2_hsva'))
    noise = np.full(N_STATE, 1e-3)
    noise[[State.U, State.V]] = 0.003
    noise[State.R] = 5e-4
    noise[[State.X, State.Y]] = 0.01
    paths = []
    for seed in (4, 5):
        run = simulate(m, 'zigzag', duration=60.0, T=0.1, seed=seed, noise_std=noise)
        paths.append(write_run_bag(run, str(d / f'run{seed}')))
    return paths


def test_two_simulated_bags_give_one_model_within_its_error_bars(bags):
    doc, table = identify_bags(bags, IdentifierSettings.from_values(coefficients=NAMES,
                                                                    initial_offset=0.2))
    assert 'from 2 bags together' in table
    co = doc['coefficients']
    assert sorted(co) == sorted(NAMES.split(','))
    for name, c in co.items():
        assert abs(c['estimate'] - c['truth']) < 4.0 * c['std'], (name, c)
        assert abs(c['estimate'] - c['truth']) < 0.03 * abs(c['truth']), (name, c)
    # (that the error bars use both runs: test/core/test_planar.py, on arrays)


def test_bags_of_two_vehicles_are_refused(bags, tmp_path):
    run = simulate(Model(load_vehicle('nps_auv2')), 'zigzag', duration=5.0, seed=1)
    other = write_run_bag(run, str(tmp_path / 'auv'))
    with pytest.raises(BagError, match='one model needs one vehicle'):
        identify_bags([bags[0], other], IdentifierSettings.from_values(coefficients=''))


def test_identify_command_takes_several_bags(bags, capsys):
    from auv_ident.cli import main
    assert main(['identify', '--bag', bags[0], '--bag', bags[1], '--coefficients', 'N_r',
                 '--initial-offset', '0.1', '--no-refine']) == 0
    out = capsys.readouterr().out
    assert 'from 2 bags together' in out and 'N_r' in out
    # the start the output names is the one taken: guesses given are not "+10 % from the
    # vehicle file" (what both bag paths printed whatever --initial said)
    for argv in ([bags[0]], [bags[0], '--bag', bags[1]]):
        assert main(['identify', '--bag', *argv, '--coefficients', 'N_r', '--initial=-0.004',
                     '--no-refine']) in (0, 3)
        out = capsys.readouterr().out
        assert 'initial guesses as given (--initial)' in out and '% from the vehicle' not in out
    # what applies to one bag only is one clear error (exit status 2)
    assert main(['identify', '--bag', bags[0], '--bag', bags[1], '--noise-mode', 'paper']) == 2
    assert '--noise-mode applies to one bag' in capsys.readouterr().err


def test_one_planar_bag_with_the_noise_model_and_the_diagnosis(bags):
    """identify --bag on a planar vehicle: the noise model from the data and the diagnosis see
    the held channels as unmeasured (no model for them, no verdict on them), the rest as usual."""
    from auv_ident.analysis.bag_identify import identify_bag
    doc, table = identify_bag(bags[0], IdentifierSettings.from_values(coefficients=NAMES,
                                                                      initial_offset=0.2,
                                                                      current='none'))
    assert table.startswith('consistent'), table
    for name, c in doc['coefficients'].items():
        assert abs(c['estimate'] - c['truth']) < 4.0 * c['std'], (name, c)
    modelled = {n for n, d in doc['noise_model']['channels'].items() if d is not None}
    assert {'u', 'v', 'r', 'x', 'y', 'psi'} <= modelled
    assert not modelled & {'w', 'p', 'q', 'z', 'phi', 'theta'}


def test_noise_and_process_noise_options_are_checked(bags, capsys):
    from auv_ident.cli import main
    assert main(['identify', '--bag', bags[0], '--bag', bags[1], '--noise-std', '0.01,0.01']) == 2
    assert '--noise-std' in capsys.readouterr().err


def test_one_bag_takes_the_noise_and_process_noise_given(bags, tmp_path, capsys):
    """identify --bag with one bag and --noise-std/--q-state: the configured noise starts
    there (noise_source parameter), as with several bags. They were refused for one bag, so a
    run whose EKF diverged with the advice 'check noise_std and q_state' had no way to follow
    it."""
    from auv_ident.cli import main
    noise = [0.004, 0.004, 0.001, 0.001, 0.001, 0.0007, 0.02, 0.02, 0.001, 0.001, 0.001, 0.002]
    q = [3e-6] * 12
    out = tmp_path / 'one.json'
    assert main(['identify', '--bag', bags[0], '--coefficients', 'N_r', '--initial-offset',
                 '0.1', '--no-refine', '--current', 'none', '--json', str(out),
                 '--noise-std', ','.join(map(str, noise)),
                 '--q-state', ','.join(map(str, q))]) in (0, 3)
    capsys.readouterr()
    doc = json.loads(out.read_text())
    assert doc['noise_source'] == 'parameter'
    assert np.allclose(doc['noise_std'], noise)
    assert np.allclose(doc['noise_model']['configured_q_state'], q)


def test_a_vehicle_given_as_a_yaml_path_is_that_file(bags, tmp_path):
    """--vehicle PATH with bags: the file at PATH is the model (its name need not be a shipped
    vehicle's, and a shipped vehicle of the same name does not replace it), for one bag, for
    several and for the arrays of report/compare-methods (bag_source); the bags record
    kvlcc2_hsva, so the renamed file needs other_vehicle."""
    from auv_ident.analysis.bag_identify import bag_source, identify_bag
    from auv_ident.vehicles import resolve_vehicle_path
    raw = yaml.safe_load(open(resolve_vehicle_path('kvlcc2_hsva'), encoding='utf-8'))
    file_n_r = float(raw['coefficients']['N_r'][0])
    raw['name'] = 'my_ship'
    raw['coefficients']['N_r'][0] = 2.0 * file_n_r
    path = tmp_path / 'my_ship.yaml'
    path.write_text(yaml.safe_dump(raw, sort_keys=False), encoding='utf-8')
    doc, _ = identify_bag(bags[0], IdentifierSettings.from_values(
        vehicle=str(path), other_vehicle=True, coefficients='N_r', initial_offset=0.1,
        current='none'),
        refine_pass=False)
    assert doc['vehicle'] == 'my_ship'
    assert doc['coefficients']['N_r']['initial'] == pytest.approx(2.2 * file_n_r)
    doc, _ = identify_bags(bags, IdentifierSettings.from_values(
        vehicle=str(path), other_vehicle=True, coefficients='N_r', initial_offset=0.1),
        refine_pass=False)
    assert doc['vehicle'] == 'my_ship'
    src = bag_source(bags[0], IdentifierSettings.from_values(vehicle=str(path),
                                                             other_vehicle=True,
                                                             coefficients='N_r'))
    assert src.vehicle.name == 'my_ship' and src.truth[0] == pytest.approx(2.0 * file_n_r)


def test_several_bags_choose_the_coefficients_from_all_runs(bags):
    """`--coefficients auto,NAME` with several bags: one selection over the runs together
    (core.identification.selection on all their residuals), every coefficient chosen or left
    out with its reason, in the JSON and the table as for one bag."""
    doc, table = identify_bags(bags, IdentifierSettings.from_values(coefficients='auto,N_r',
                                                                    initial_offset=0.2),
                               refine_pass=False)
    sel = doc['selection']
    v = load_vehicle('kvlcc2_hsva')
    assert sel['named'] == ['N_r'] and sel['chosen'][0] == 'N_r'
    assert list(doc['coefficients']) == sel['chosen']
    assert set(sel['chosen']).isdisjoint(sel['left_out'])
    assert set(sel['chosen']) | set(sel['left_out']) == set(v.names)
    assert 'from 2 bags together' in table and 'automatic selection:' in table
