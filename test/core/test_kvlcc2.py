"""The KVLCC2 free-running model tests (HSVA, SIMMAN 2008; not in the repository, skipped when
absent): the captive-test prior of config/kvlcc2_hsva.yaml and the identification from the two
starboard zig-zags together (tools/kvlcc2_identify.py), validated by free runs on the port
zig-zags against the goals of issue #20."""
import importlib.util
from pathlib import Path
import time

from kvlcc2_data import load_run, require_runs, RUNS
import numpy as np
import pytest

from auv_ident.core.identification.batch import identify
from auv_ident.core.identification.results import Record
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import Input
from auv_ident.session.settings import IdentifierSettings
from auv_ident.vehicles import load_vehicle

TOOL = Path(__file__).resolve().parents[2] / 'tools' / 'kvlcc2_identify.py'


def _tool():
    spec = importlib.util.spec_from_file_location('kvlcc2_identify', TOOL)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_data_are_read_in_our_signs():
    """A zig-zag 'starting to starboard' first puts the rudder to starboard (negative: the HSVA
    delta and our delta_r are positive to port) and then yaws to starboard (r > 0, psi grows)."""
    require_runs(('Z_20_10_S', 'Z_20_10_P'))
    for run, sign in (('Z_20_10_S', 1.0), ('Z_20_10_P', -1.0)):
        t, Y, U = load_run(run)
        k = np.argmax(np.abs(U[:, Input.DELTA_R]) > np.deg2rad(5.0))
        assert np.sign(U[k, Input.DELTA_R]) == -sign
        first = np.argmax(np.abs(Y[:, 11]) > np.deg2rad(5.0))
        assert np.sign(Y[first, 11]) == sign and np.sign(Y[first, 5]) == sign
        assert 1.17 < Y[0, 0] < 1.19 and abs(Y[0, 1]) < 0.01 and np.all(U[:, Input.THRUST] > 30)


def test_identified_from_both_starboard_runs_predicts_the_port_runs():
    require_runs(RUNS)
    tool = _tool()
    v = load_vehicle(tool.VEHICLE)
    names = v.identify_default
    model = Model(v, names)
    runs = {r: load_run(r) for r in RUNS}
    noise = tool.measurement_noise(runs['Z_10_10_S'][1], runs['Z_10_10_S'][0])
    t0 = time.perf_counter()
    res = identify(model, [Record(*runs[r]) for r in tool.TRAIN], tool.config(v, names, noise))
    wall = time.perf_counter() - t0
    assert wall < 60.0
    fits = tool.validate(model, res.estimate, {r: runs[r] for r in tool.GOALS})
    for run, (goal_r, goal_u) in tool.GOALS.items():
        assert fits[run][0] >= goal_r and fits[run][1] >= goal_u, (run, fits[run])
    # and far better than the prior from the captive tests
    prior = tool.validate(model, model.theta_file, {'Z_20_10_P': runs['Z_20_10_P']})
    assert fits['Z_20_10_P'][0] > prior['Z_20_10_P'][0] + 20.0
    assert np.all(np.isfinite(res.std)) and np.all(res.std > 0)


@pytest.mark.slow
def test_identify_from_the_imported_bags_equals_the_arrays(tmp_path):
    """`import --format hsva` then `identify --bag A --bag B` with the real-data noise gives
    the coefficients of the same steps on the arrays of test/kvlcc2_data.py (the noise model
    from the data, core.identification.noise_fit.identify_with_noise_model; same samples, same
    filter
    settings: the bags keep every value in float64)."""
    require_runs(('Z_10_10_S', 'Z_20_10_S'))
    from kvlcc2_data import run_path

    from auv_ident.analysis.bag_identify import identify_bags
    from auv_ident.cli import main
    tool = _tool()
    bags = []
    for run in tool.TRAIN:
        out = str(tmp_path / run)
        assert main(['import', '--format', 'hsva', str(run_path(run)), '--out', out]) == 0
        bags.append(out)
    v = load_vehicle(tool.VEHICLE)
    runs = [load_run(r) for r in tool.TRAIN]
    cfg = tool.config(v, v.identify_default, tool.measurement_noise(runs[0][1], runs[0][0]))
    from auv_ident.analysis.results import make_config
    from auv_ident.core.identification.noise_fit import identify_with_noise_model
    # the filter settings of the bag path (its prior: the vehicle file's values, p0_rel 1;
    # every channel fused, the unmeasured ones as the zeros the bags hold at 1-sigma 1): the
    # noise model is read off the EKF pass, so that pass must be the same
    bag_cfg = make_config(v.identify_default, noise_mode='fixed', initial_offset=0.0,
                          noise_std=cfg.noise_std)
    bag_cfg.q_state = cfg.q_state
    want = identify_with_noise_model(Model(v, v.identify_default), bag_cfg,
                                     [Record(t, np.nan_to_num(Y), U)
                                      for t, Y, U in runs]).estimate
    doc, _ = identify_bags(bags, IdentifierSettings.from_values(initial_offset=0.0,
                                                                noise_std=cfg.noise_std,
                                                                q_state=cfg.q_state))
    assert doc['rejected'] == 0
    got = np.array([doc['coefficients'][n]['estimate'] for n in v.identify_default])
    np.testing.assert_allclose(got, want, rtol=1e-3)
