"""A thruster vehicle's bag (#29): our simulator writes its PWM commands as
std_msgs/Float64MultiArray on /thrusters when they change, its metadata names the input map
that reads them, and a replay pairs every odometry sample with the commands in force."""
import numpy as np

from auv_ident.bags.reader import read_bag
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.simulation.simulate import simulate
from auv_ident.offline.replay import bag_settings, read_bag_run
from auv_ident.offline.sim_bag import THRUSTER_TOPIC, write_run_bag
from auv_ident.vehicles import load_vehicle


def test_thruster_commands_on_change_replay_to_the_run(tmp_path):
    run = simulate(Model(load_vehicle('bluerov2_heavy')), 'surge', duration=60.0, seed=4)
    bag = write_run_bag(run, str(tmp_path / 'bag'))
    assert bag_settings(bag)['input_map'] == 'bluerov2_heavy'
    msgs = [m for m in read_bag(bag, {THRUSTER_TOPIC: 'std_msgs/msg/Float64MultiArray'})]
    changes = 1 + int(np.any(np.diff(run.u, axis=0) != 0, axis=1).sum())
    assert 1 < len(msgs) == changes < len(run.t)
    rr = read_bag_run(bag)
    assert rr.U.shape == run.u.shape
    assert np.array_equal(rr.U, run.u)
    np.testing.assert_allclose(rr.Y, run.y, rtol=0, atol=1e-12)   # via quaternions
