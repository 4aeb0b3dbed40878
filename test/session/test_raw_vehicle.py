"""The raw-sensor path and a thruster-driven vehicle (session/raw_session.py check_raw_vehicle):
its filter takes the fin vehicles' command vector, so a BlueROV2 Heavy with an IMU, a DVL and
its eight thruster commands would have waited for commands forever (each thruster channel was
read into the last one). It is refused by name, live and offline, before any message."""
import pytest

from auv_ident.cli import main as cli_main
from auv_ident.session.raw_session import RawSession
from auv_ident.session.settings import IdentifierSettings, ParameterError

MAP = """version: 1
inputs:
  imu: {topic: imu, type: sensor_msgs/msg/Imu, frame: ned}
  dvl: {topic: dvl, type: geometry_msgs/msg/TwistWithCovarianceStamped, frame: ned}
  thrusters:
    topic: thrusters
    type: std_msgs/msg/Float64MultiArray
    channels:
""" + ''.join(f'      - {{index: {i}, actuator: t{i + 1}, unit: us}}\n' for i in range(8))


@pytest.fixture
def rov_raw_map(tmp_path):
    p = tmp_path / 'rov_raw.yaml'
    p.write_text(MAP)
    return str(p)


def test_a_thruster_vehicle_is_refused_by_the_live_raw_session(rov_raw_map):
    settings = IdentifierSettings.from_values(vehicle='bluerov2_heavy', input_map=rov_raw_map,
                                              coefficients=['X_u'])
    with pytest.raises(ParameterError) as err:
        RawSession(settings)
    assert err.value.name == 'vehicle'
    assert 'thruster-driven vehicle (8 thrusters)' in err.value.message


def test_a_thruster_vehicle_is_refused_by_identify_on_a_raw_map(rov_raw_map, tmp_path, capsys):
    bag = tmp_path / 'no_bag'        # refused before the bag is read
    assert cli_main(['identify', '--vehicle', 'bluerov2_heavy', '--bag', str(bag),
                     '--input-map', rov_raw_map, '--coefficients', 'X_u']) == 2
    err = capsys.readouterr().err
    assert 'thruster-driven vehicle' in err and len(err.splitlines()) == 1, err
