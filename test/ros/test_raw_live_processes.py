"""The live identifier node with a raw-sensor input map as a process over DDS, fed a raw bag by
the player (ros/play_node.py with the same map): its final estimate (the estimate file written
at shutdown) is identify --bag's first EKF pass over that bag with that map."""
import json

from conftest import play_into_identifier
import numpy as np
import pytest

from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.identification.raw import identify_raw
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.offline.raw_bag import raw_bag_records, raw_sensor_config
from auv_ident.offline.raw_example import write_raw_example
from auv_ident.ros.raw_loadtest import _cmd as _node_cmd
from auv_ident.session.input_map import load_input_map
from auv_ident.vehicles import load_vehicle

# not marked slow: about 11 s on the 2-core machine (identifier + player over DDS)
NAMES = ['Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v']


def test_player_fed_raw_node_publishes_the_offline_pass(tmp_path, ros_env):
    bag, map_path = write_raw_example(tmp_path / 'ex', duration=10.0, seed=5)
    imap = load_input_map(str(map_path))
    v = load_vehicle('nps_auv2')
    records, _ = raw_bag_records(bag, imap, v)
    ref = identify_raw(Model(v, NAMES), FilterConfig(), records, raw_sensor_config(imap),
                       passes=1)
    out = tmp_path / 'estimate.json'
    topics = ','.join(e.bag_topic for e in imap.inputs)
    play_into_identifier(
        _node_cmd('identifier', f'input_map:={map_path}', f'coefficients:=[{",".join(NAMES)}]',
                  f'save_path:={out}'),
        _node_cmd('play', f'bag:={bag}', f'input_map:={map_path}', 'rate:=2.0',
                  f'wait_for_subscribers:=[{topics}]', 'wait_for_subscribers_s:=60.0'),
        ros_env)
    doc = json.loads(out.read_text())
    assert doc['input_mode'] == 'raw sensors' and doc['coefficients'] == NAMES
    # every sensor message fused, as offline
    assert doc['fused'] == {k: n for k, n in ref.fused.items() if k != 'command'}
    assert doc['not_fused'] == {}
    np.testing.assert_allclose(doc['estimate'], ref.estimate, rtol=1e-9, atol=0)
    np.testing.assert_allclose(doc['covariance'], ref.filter_covariance, rtol=1e-6, atol=1e-18)


@pytest.mark.slow     # a 30 s bag played in real time, plus start-up: about 45 s
def test_raw_load_400_hz_imu_every_message_processed(tmp_path, ros_env):
    from auv_ident.ros.raw_loadtest import run_raw_loadtest
    # 30 s: seed 5's 10 s run at 400 Hz stops the offline reference pass itself (a propeller
    # domain error at 0.06 s, before the filter has a speed), the 30 s run does not
    d = run_raw_loadtest(seconds=30.0, imu_rate=400.0, rate=1.0, folder=tmp_path)
    assert d['fused']['imu'] == 12000 and d['every_message_processed'], d
    assert d['cpu_ms_per_message'] > 0
