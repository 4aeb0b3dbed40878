"""Vehicle-file values that are numbers but not a vehicle (#27 items 6 and 10): each one
ConfigError naming the file and the key, never a numba TypingError, a NaN later or a silently
kept duplicate."""
import re

import pytest

from auv_ident.core.errors import ConfigError
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.vehicle import vehicle_from_file
from auv_ident.vehicles import resolve_vehicle_path

NPS = open(resolve_vehicle_path('nps_auv2'), encoding='utf-8').read()


def _edited(tmp_path, pattern, repl, name='edited_auv.yaml'):
    text, n = re.subn(pattern, repl, NPS, count=1, flags=re.M)
    assert n == 1, pattern
    path = tmp_path / name
    path.write_text(text, encoding='utf-8')
    return str(path)


def test_the_shipped_file_passes_the_checks(tmp_path):
    v = vehicle_from_file(_edited(tmp_path, r'^rho: 1000\.0', 'rho: 1000.0'))
    Model(v, v.identify_default)


@pytest.mark.parametrize('pattern, repl, match', [
    # the term scale (rho/2) L^k overflows: numba's "name 'inf' is not defined" before
    (r'^rho: 1000\.0', 'rho: 1.0e308', r'coefficient X_udot: its scale .* not a finite number'),
    (r'^L: 5\.3', 'L: 1.0e200', 'not a finite number'),
    # a mass in other units (or mistyped) than the weight
    (r'^mass: 5454\.54', 'mass: 1.0e-300', r'W / mass = .* check the units of mass and W'),
    (r'^mass: 5454\.54', 'mass: 5.45454', 'W / mass'),
    (r'^cruise_rpm: 500\.0', 'cruise_rpm: .nan', r'cruise_rpm = nan must be a finite positive'),
    (r'^cruise_rpm: 500\.0', 'cruise_rpm: -500', 'cruise_rpm = -500.0 must be a finite positive'),
    (r'^  stations: 11', '  stations: 10.5', r'stations = 10\.5 must be a whole number'),
    (r'^  stations: 11', '  stations: 1000000000', 'must be a whole number from 2 to 1000'),
    (r'^  stations: 11', '  stations: 1', 'must be a whole number from 2 to 1000'),
    # a singular literal inverse (one row zero)
    (r'^  - \[0\.0001662, .*\]', '  - [0, 0, 0, 0, 0, 0]', 'mss_inverse is not the inverse'),
    (r'^  - \[0\.0001662, .*\]', '  - [0.01662, 1.846e-10, 1.303e-07, 3.726e-09, -1.132e-06, '
     '7.32e-10]', 'mss_inverse is not the inverse'),
    # a key written twice: PyYAML kept the last silently
    (r'^  stations: 11', '  stations: 11\n  Cy: 3.0', r"duplicate key 'Cy' \(first on line"),
    (r'^rho: 1000\.0', 'rho: 1000.0\nrho: 1025.0', r"duplicate key 'rho'"),
])
def test_a_bad_value_is_one_error_naming_file_and_key(tmp_path, pattern, repl, match):
    path = _edited(tmp_path, pattern, repl)
    with pytest.raises(ConfigError, match=match) as info:
        v = vehicle_from_file(path)
        Model(v, v.identify_default)        # without the check: the kernel's TypingError
    assert 'edited_auv.yaml' in str(info.value)


def test_a_duplicate_coefficient_is_refused(tmp_path):
    path = _edited(tmp_path, r'^  (Z_w: .*)$', r'  \1\n  \1')
    with pytest.raises(ConfigError, match=r"edited_auv.yaml: not valid YAML: .*duplicate key "
                                          r"'Z_w'"):
        vehicle_from_file(path)
