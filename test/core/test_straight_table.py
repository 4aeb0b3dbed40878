"""tools/straight_table.py (docs/vehicles.md, "The table's truth"): a copy of the BlueROV2 file
whose T200 tables state straight lines between their points in the intervals named. Its
thrust, read by the package's loader and kernel, is the straight line between the published
points at every integer PWM inside those intervals (where the file's own cubic is not: 0.054 N
against 0.098 N at 1529 us) and the file's curve elsewhere, but for a few mN in the table's
intervals next to them."""
import sys

from helpers import load_tool
import numpy as np
import pytest

from auv_ident.core.model.thrusters import steady_thrusts
from auv_ident.core.model.vehicle import vehicle_from_file
from auv_ident.vehicles import resolve_vehicle_path


@pytest.fixture
def tool(monkeypatch):
    monkeypatch.setattr(sys, 'path', list(sys.path))       # the tool inserts the package root
    return load_tool('straight_table')


def _thrust(vehicle, pwm):
    """(len(pwm),) N: thruster t1's thrust at each PWM (us)."""
    return np.array([steady_thrusts(vehicle.thrusters, [c] * 8)[0] for c in pwm])


def test_straight_lines_inside_the_intervals_the_files_curve_outside(tool, tmp_path, capsys):
    src = resolve_vehicle_path('bluerov2_heavy')
    out = tmp_path / 'lines.yaml'
    assert tool.main([str(src), str(out), '--between', '1468:1472,1528:1532']) == 0
    assert 'wrote' in capsys.readouterr().out
    file_v, lines_v = vehicle_from_file(str(src)), vehicle_from_file(str(out))
    table = file_v.thrusters[0].table          # (3, K): command, thrust N, slope
    inside = np.array([1469, 1470, 1471, 1529, 1530, 1531], float)
    straight = np.interp(inside, table[0], table[1])
    np.testing.assert_allclose(_thrust(lines_v, inside), straight, rtol=1e-12, atol=1e-12)
    # the file's cubic leaves the dead band with slope 0: 0.054 N, not the line's 0.098 N
    assert _thrust(file_v, [1529.0])[0] < 0.6 * straight[3]
    outside = np.array([1100, 1350, 1463, 1500, 1537, 1650.5, 1900], float)
    np.testing.assert_allclose(_thrust(lines_v, outside), _thrust(file_v, outside),
                               rtol=1e-12, atol=1e-12)
    # the table's intervals next to them: the slope at the shared point moves with the
    # spacing (PCHIP's weights), by a few mN on the T200 (3.0 mN at 1467 us)
    nextdoor = np.array([1465, 1466, 1467, 1533, 1534, 1535], float)
    moved = np.abs(_thrust(lines_v, nextdoor) - _thrust(file_v, nextdoor))
    assert 1e-4 < moved.max() < 0.005, moved


def test_a_file_without_tables_is_one_clear_error(tool, tmp_path):
    with pytest.raises(SystemExit, match='no thruster has a table'):
        tool.main([str(resolve_vehicle_path('remus100')), str(tmp_path / 'x.yaml')])
