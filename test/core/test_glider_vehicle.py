"""A glider's vehicle file (config/slocum_comet.yaml, core/glider/vehicle.py): the published
prior read to the bit, every bad key named in one error, and the 6-DOF loader and `vehicle
check` telling a glider file for what it is."""
from pathlib import Path

import pytest
import yaml

from auv_ident.cli import main
from auv_ident.core.errors import ConfigError
from auv_ident.core.glider.vehicle import glider_from_file, NUMBERS
from auv_ident.core.model.vehicle import vehicle_from_file, VehicleFileProblems

COMET = Path(__file__).resolve().parents[2] / 'config' / 'slocum_comet.yaml'


def _write(tmp_path, raw):
    path = tmp_path / 'glider.yaml'
    path.write_text(yaml.safe_dump(raw, sort_keys=False), encoding='utf-8')
    return str(path)


def test_the_comet_file_holds_the_published_prior():
    glider = glider_from_file(str(COMET))
    p = glider.params
    assert glider.name == 'slocum_comet' and glider.pitch_source == 'measured'
    assert 'Merckelbach et al. 2019' in glider.prior
    assert p.hull_volume == 60.0 / 1005.0 and p.mass == 60.0
    assert (p.drag_zero_lift, p.induced_drag, p.wing_area) == (0.15, 10.5, 0.1)
    assert p.lift_slope == pytest.approx(3.8 + 3.73, abs=1e-12)
    assert (p.compressibility, p.added_mass_axial, p.added_mass_normal) == (5e-10, 0.2, 0.92)


def test_every_bad_key_is_named_in_one_error(tmp_path):
    raw = yaml.safe_load(COMET.read_text(encoding='utf-8'))
    raw['mass'] = 'heavy'
    del raw['hull_volume']
    raw['drag_zero_lift'] = -0.1
    raw['induced_drag'] = -1.0
    raw['wing_aera'] = raw.pop('wing_area')
    raw['pitch_source'] = 'battery'
    del raw['prior']
    with pytest.raises(VehicleFileProblems) as err:
        glider_from_file(_write(tmp_path, raw))
    problems = err.value.problems
    for key in ("mass = 'heavy'", "'hull_volume'", 'drag_zero_lift = -0.1', 'induced_drag = -1.0',
                "'wing_area'", "'wing_aera'", 'battery', "'prior'"):
        assert sum(key in p for p in problems) == 1, (key, problems)
    assert len(problems) == 8


def test_an_empty_glider_file_lists_every_number(tmp_path):
    with pytest.raises(VehicleFileProblems) as err:
        glider_from_file(_write(tmp_path, {'kind': 'glider'}))
    assert len(err.value.problems) == len(NUMBERS) + 3       # name, prior, pitch_source
    with pytest.raises(ConfigError, match='not a glider file'):
        glider_from_file(_write(tmp_path, {'name': 'x'}))
    with pytest.raises(ConfigError, match='no glider file'):
        glider_from_file(str(tmp_path / 'absent.yaml'))


def test_the_6dof_loader_and_vehicle_check_tell_a_glider_file(capsys):
    with pytest.raises(ConfigError, match='a glider file'):
        vehicle_from_file(str(COMET))
    assert main(['vehicle', 'check', str(COMET)]) == 0
    out = capsys.readouterr().out
    assert "vehicle 'slocum_comet' loads: ready" in out
    assert 'a glider file (kind: glider)' in out and '1005.0 kg/m^3' in out
    assert 'best glide: glide angle 18.4 deg' in out


def test_vehicle_check_names_a_glider_in_the_wrong_units(tmp_path, capsys):
    raw = yaml.safe_load(COMET.read_text(encoding='utf-8'))
    raw['hull_volume'] = 59.7          # litres
    assert main(['vehicle', 'check', _write(tmp_path, raw)]) == 1      # a warning
    assert 'units of mass (kg) and hull_volume (m^3)' in capsys.readouterr().out
