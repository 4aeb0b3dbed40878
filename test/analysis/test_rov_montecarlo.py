"""`montecarlo --vehicle bluerov2_heavy` (#29 item 4): the tank session ('ident' is a hovering
vehicle's tank manoeuvre: surge, sway, heave and yaw sticks in turn, then in pairs) flown
through the eight thrusters' PWM, its twelve default coefficients (thrust gains, diagonal added
mass and damping) identified per seed and offset; the truth within 3 sigma. Measured figures
with the command in docs/vehicles.md (BlueROV2 Heavy, Monte Carlo)."""
import pytest

from auv_ident.analysis.experiments import montecarlo
from auv_ident.cli import main as cli_main
from auv_ident.vehicles import load_vehicle


@pytest.mark.slow       # one 600 s tank session identified: ~1-2 min on the 2-core machine
def test_montecarlo_covers_the_bluerov2_truth_on_the_tank_session():
    v = load_vehicle('bluerov2_heavy')
    st = montecarlo(v, list(v.identify_default), seeds=1, offsets=(0.5,), jobs=1)
    assert st['diverged'] == 0 and len(st['per_coefficient']) == 12
    assert st['within_3sigma_all'] >= 0.9, st['per_coefficient']
    for name, c in st['per_coefficient'].items():
        assert c['max_abs_error_pct'] < 5.0, (name, c)


def test_montecarlo_names_the_thruster_vehicle_and_its_coefficients(capsys):
    """The command runs a thruster vehicle's cases (here a short one: the table, not the
    figures) with its identify_default."""
    assert cli_main(['montecarlo', '--vehicle', 'bluerov2_heavy', '--seeds', '1',
                     '--offsets', '0.5', '--duration', '20', '--jobs', '1', '--no-refine']) \
        in (0, None)
    out = capsys.readouterr().out
    assert 'BlueROV2 Heavy' in out and 'thrust_gain_fwd' in out and 'N_rr' in out
