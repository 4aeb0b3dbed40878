"""A BlueROV2 Heavy identified from a simulated 10-minute tank session (#29): the truth's T200
curves differ from the file's (forward side +10 %, reverse -5 %), the run is integrated with
a finer step than the filter's and the noise is coloured and twice the configured level; the
file's coefficient set (two thrust gains, diagonal added mass and damping in surge, sway,
heave, yaw) comes back within 5 %, and with the truth inside 3 sigma."""
import numpy as np
import yaml

from auv_ident.analysis import results
from auv_ident.core.identification.pipeline import identify_with_diagnosis
from auv_ident.core.identification.results import Record
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.sensors import ar1_noise, DEFAULT_NOISE_STD
from auv_ident.core.model.thrusters import scaled_curves
from auv_ident.core.model.vehicle import vehicle_from_file
from auv_ident.core.simulation.simulate import simulate
from auv_ident.core.vehicle_files import read_yaml_file
from auv_ident.vehicles import load_vehicle, resolve_vehicle_path

FWD, REV = 1.10, 0.95       # the truth's curves: forward side +10 %, reverse side -5 %


def _perturbed_vehicle(tmp_path):
    raw = read_yaml_file(resolve_vehicle_path('bluerov2_heavy'))
    raw['thrusters'] = scaled_curves(raw['thrusters'], FWD, REV)
    p = tmp_path / 'bluerov2_heavy.yaml'
    p.write_text(yaml.safe_dump(raw))
    return vehicle_from_file(str(p))


def test_bluerov2_heavy_from_a_tank_session_within_5_percent(tmp_path):
    truth = Model(_perturbed_vehicle(tmp_path))
    run = simulate(truth, 'tank', duration=600.0, seed=1, substeps=4, noise_std=np.zeros(12))
    y = run.y + ar1_noise(np.random.default_rng([1, 1]), len(run.t), 2 * DEFAULT_NOISE_STD,
                          0.5, run.T)
    v = load_vehicle('bluerov2_heavy')
    names = list(v.identify_default)
    m = Model(v, names)
    res = identify_with_diagnosis(m, results.make_config(names), [Record(run.t, y, run.u)],
                                  T=run.T)
    true = m.theta_file.copy()
    true[names.index('thrust_gain_fwd')] = FWD
    true[names.index('thrust_gain_rev')] = REV
    err = res.estimate / true - 1.0
    sd = np.sqrt(np.diag(res.cov))
    assert np.all(np.abs(err) < 0.05), dict(zip(names, np.round(100 * err, 2)))
    inside = np.abs(res.estimate - true) <= 3 * sd
    assert inside.mean() >= 0.9, dict(zip(names, np.round((res.estimate - true) / sd, 1)))
