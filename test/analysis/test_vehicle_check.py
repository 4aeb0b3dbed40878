"""`vehicle check FILE`: every missing key of a new file in one run, then the trim, the
stability and the unusual values of a file that loads (analysis/vehicle_check.py)."""
from pathlib import Path

import pytest
import yaml

from auv_ident.analysis.vehicle_check import check_vehicle
from auv_ident.cli import main
from auv_ident.core.errors import ConfigError
from auv_ident.core.model.vehicle import vehicle_from_file, VehicleFileProblems
from auv_ident.vehicles import resolve_vehicle_path

REQUIRED = ('coefficients', "'rho'", "'L'", "'mass'", "'W'", "'B'", "'Ix'", "'Iy'", "'Iz'",
            "'fin_rad'", "'n_rpm'")


def test_an_empty_file_lists_every_missing_key_in_one_run(tmp_path, capsys):
    empty = tmp_path / 'mine.yaml'
    empty.write_text('# my vehicle\n', encoding='utf-8')
    assert main(['vehicle', 'check', str(empty)]) == 2
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f'{empty}: does not load: {len(REQUIRED)} error(s)'
    errors = [ln for ln in out if ln.startswith('  error: ')]
    assert len(errors) == len(REQUIRED)
    for key in REQUIRED:
        assert sum(key in e for e in errors) >= 1, key
    # the loader of every other command says all of them at once too, with their units
    with pytest.raises(VehicleFileProblems) as err:
        vehicle_from_file(str(empty))
    assert len(err.value.problems) == len(REQUIRED) and 'kg/m^3' in str(err.value)


def test_some_keys_wrong_some_missing_all_named(tmp_path):
    raw = yaml.safe_load(Path(resolve_vehicle_path('nps_auv2')).read_text(encoding='utf-8'))
    raw['rho'] = 'seawater'
    del raw['B']
    raw['inertia'].pop('Iy')
    path = tmp_path / 'v.yaml'
    path.write_text(yaml.safe_dump(raw, sort_keys=False), encoding='utf-8')
    check = check_vehicle(str(path))
    assert not check.ok and len(check.errors) == 3
    assert any("rho = 'seawater'" in e for e in check.errors)
    assert any("'B'" in e for e in check.errors) and any("'Iy'" in e for e in check.errors)


@pytest.mark.parametrize('vehicle', ['nps_auv2', 'remus100', 'isimi', 'kvlcc2_hsva'])
def test_every_shipped_file_loads_trims_and_says_its_modes(vehicle):
    check = check_vehicle(vehicle)
    assert check.ok and check.name == vehicle
    assert any(f.startswith('straight run at cruise_rpm') for f in check.facts)
    assert any(f.startswith('eigenvalues of the velocity dynamics') for f in check.facts)
    # no warning but the slender hulls' known sway/yaw instability
    assert all('unstable mode' in w for w in check.warnings), check.warnings


def test_unusual_values_are_warnings(tmp_path, capsys):
    raw = yaml.safe_load(Path(resolve_vehicle_path('nps_auv2')).read_text(encoding='utf-8'))
    raw['B'] = raw['W'] * 1.3
    raw['r_G'] = [0.0, 0.0, -0.05]                # above the centre of buoyancy
    raw['mass_inverse'] = 'exact'                 # MSS's literal inverse is of the old r_G
    raw['coefficients']['Y_v'][0] = abs(raw['coefficients']['Y_v'][0])
    path = tmp_path / 'odd.yaml'
    path.write_text(yaml.safe_dump(raw, sort_keys=False), encoding='utf-8')
    assert main(['vehicle', 'check', str(path)]) == 1
    out = capsys.readouterr().out
    assert '+30.0% of W' in out and 'not below the centre of buoyancy' in out
    assert 'positive value' in out and 'Y_v' in out


def test_a_missing_path_is_one_error(tmp_path, capsys):
    assert main(['vehicle', 'check', str(tmp_path / 'nope.yaml')]) == 2
    assert capsys.readouterr().err.startswith('error: ')
    with pytest.raises(ConfigError):
        check_vehicle(str(tmp_path / 'nope.yaml'))
