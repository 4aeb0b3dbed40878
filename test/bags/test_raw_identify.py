"""identify --bag with a raw-sensor input map (analysis/raw_identify.py) on a run of the
independent generator (offline/independent_data.py generate_raw) written as a bag."""
import json

import numpy as np
import pytest
import yaml

from auv_ident.analysis.raw_comparison import sensors_of
from auv_ident.cli import main
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.identification.raw import identify_raw
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.offline.independent_data import DataConfig, generate_raw, RawConfig

# the example bag's message writer (python -m auv_ident.offline.raw_example)
from auv_ident.offline.raw_example import record_message as _message
from auv_ident.offline.sim_bag import write_message_bag
from auv_ident.vehicles import load_vehicle

NAMES = ['Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v']
EPOCH = 1_700_000_000 * 10**9
TOPICS = {'/imu': 'sensor_msgs/msg/Imu', '/dvl': 'geometry_msgs/msg/TwistWithCovarianceStamped',
          '/pressure': 'sensor_msgs/msg/FluidPressure', '/actuators': 'sensor_msgs/msg/JointState'}


def _map(cfg, drop=()):
    actuators = yaml.safe_load(open('config/inputs/odom_actuators.yaml'))['inputs']['actuators']
    inputs = {
        'imu': {'topic': '/imu', 'type': TOPICS['/imu'], 'frame': 'ned',
                'fields': ['orientation', 'angular_velocity']},
        'dvl': {'topic': '/dvl', 'type': TOPICS['/dvl'], 'frame': 'ned', 'reference': 'ground',
                'mounting': {'lever_arm': list(cfg.dvl_lever_arm),
                             'rotation': [0, 0, cfg.dvl_yaw_deg], 'unit': 'deg'}},
        'pressure': {'topic': '/pressure', 'type': TOPICS['/pressure'],
                     'mounting': {'lever_arm': list(cfg.pressure_lever_arm)}},
        'actuators': dict(actuators, topic='/actuators')}
    for k in drop:
        inputs[k]['topic'] = '/not_recorded'
    return {'version': 1, 'body_frame': 'frd', 'inputs': inputs}


@pytest.fixture(scope='module')
def raw_bag(tmp_path_factory):
    cfg = RawConfig(data=DataConfig(duration=20.0, seed=5, integrator='rk4', rk4_dt=0.005),
                    noise_level=(0.01, 0.01), noise_tau=(0.0, 0.0))
    run = generate_raw(cfg)
    d = tmp_path_factory.mktemp('raw')
    bag = write_message_bag(d / 'bag', TOPICS, {}, (_message(r) for r in run.records), None)
    maps = {}
    for key, drop in (('good', ()), ('no_dvl', ('dvl',))):
        maps[key] = d / f'{key}.yaml'
        maps[key].write_text(yaml.safe_dump(_map(cfg, drop)))
    return cfg, run, bag, maps


@pytest.mark.slow
def test_identify_bag_with_a_raw_map_is_identify_raw_on_the_records(raw_bag, tmp_path, capsys):
    cfg, run, bag, maps = raw_bag
    out = tmp_path / 'r.json'
    code = main(['identify', '--bag', str(bag), '--input-map', str(maps['good']),
                 '--coefficients', ','.join(NAMES), '--json', str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert 'dvl_misalignment (sensor)' in text
    doc = json.loads(out.read_text())
    est = np.array([doc['coefficients'][n]['estimate'] for n in NAMES])
    std = np.array([doc['coefficients'][n]['std'] for n in NAMES])
    truth = np.array([run.truth['coefficients'][n] for n in NAMES])
    assert np.all(np.abs(est - truth) < 3 * std), (est, truth, std)
    ref = identify_raw(Model(load_vehicle('nps_auv2'), NAMES), FilterConfig(), run.records,
                       sensors_of(cfg), passes=2)
    np.testing.assert_allclose(est, ref.estimate, rtol=1e-6)
    assert doc['fused']['dvl'] == run.truth['counts']['dvl']


def test_a_raw_map_topic_the_bag_lacks_is_exit_2(raw_bag, capsys):
    _, _, bag, maps = raw_bag
    code = main(['identify', '--bag', str(bag), '--input-map', str(maps['no_dvl'])])
    assert code == 2
    assert '/not_recorded' in capsys.readouterr().err
