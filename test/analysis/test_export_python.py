"""`export --format python`: the exported module, imported from a folder of its own with no
auv_ident on its import path's use, reproduces our model along held-out manoeuvres of every
shipped vehicle (< 1e-6 relative; the terms are written out, not fitted), and a thruster
vehicle's thrust curves and wrench."""
import ast
import importlib.util
import json

import numpy as np
import pytest

from auv_ident.analysis.export import export_model
from auv_ident.analysis.export_python import identified_model
from auv_ident.analysis.model_report import load_model
from auv_ident.cli import main
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.integrators import rk4_step
from auv_ident.core.model.thrusters import wrench
from auv_ident.core.simulation.simulate import simulate
from auv_ident.vehicles import load_vehicle


def _model_json(path, vehicle, estimates):
    doc = {'vehicle': str(vehicle), 'source': 'test',
           'coefficients': {n: {'estimate': e, 'std': abs(e) * 0.01 + 1e-9}
                            for n, e in estimates.items()}}
    path.write_text(json.dumps(doc), encoding='utf-8')
    return path


def _import(path, name):
    """The exported file as a module, imported by path (its folder is not a package)."""
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _imports(source):
    tree = ast.parse(source)
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name.split('.')[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            out.add((node.module or '').split('.')[0])
    return out


def _wrapped_diff(a, b):
    d = a - b
    d[:, 9:] = (d[:, 9:] + np.pi) % (2.0 * np.pi) - np.pi
    return d


# held-out manoeuvres per vehicle: a hovering thruster vehicle flies a pilot's (no rudder)
MANOEUVRES = {'bluerov2_heavy': ('steps', 'tank')}


@pytest.mark.parametrize('vehicle', ['nps_auv2', 'remus100', 'isimi', 'kvlcc2_hsva',
                                     'bluerov2_heavy'])
def test_the_python_export_is_our_model(tmp_path, vehicle):
    """The BlueROV2 Heavy with its added mass identified: the added-mass Coriolis terms its
    file computes from the added mass (added_mass_coriolis: fossen) are written out too."""
    v = load_vehicle(vehicle)
    # identified values off the file's, and not short decimals (the BlueROV2: its thrust
    # gains and the added mass, X_udot .. Z_wdot)
    names = (v.identify_default[:5] if vehicle == 'bluerov2_heavy'
             else v.identify_default[:3])
    est = {n: v.values[v.index(n)] * 1.1 + 1e-17 for n in names}
    model_path = _model_json(tmp_path / 'm.json', vehicle, est)
    out = tmp_path / 'exported' / f'{vehicle}_model.py'
    out.parent.mkdir()
    assert main(['export', str(model_path), '--format', 'python', '--out', str(out)]) == 0
    source = out.read_text(encoding='utf-8')
    assert _imports(source) == {'math', 'numpy'}
    assert 'Units SI' in source and 'body FRD' in source and 'SNAME' in source
    mod = _import(out, f'exported_{vehicle}')
    ours = identified_model(load_model(model_path))
    for n, e in est.items():
        assert mod.COEFFICIENTS[n] == e      # to the last bit
    # held out: the export samples nothing, and neither manoeuvre is the identification's
    for manoeuvre in MANOEUVRES.get(vehicle, ('zigzag', 'prbs')):
        run = simulate(ours, manoeuvre, duration=60.0, noise_std=np.zeros(12))
        x = mod.simulate(run.x[0], run.u[:-1], run.T)
        rel = (np.abs(_wrapped_diff(x, run.x)).max(axis=0)
               / np.maximum(np.abs(run.x).max(axis=0), 1e-9))
        assert rel.max() < 1e-6, (manoeuvre, rel)
        for xk, uk in zip(run.x[::40], run.u[::40]):
            want = ours.f(xk, uk)
            got = mod.f(xk, uk)
            assert np.abs(got - want).max() <= 1e-9 * np.abs(want).max()


def test_the_python_export_refuses_what_our_model_refuses(tmp_path):
    model_path = _model_json(tmp_path / 'm.json', 'nps_auv2', {'Z_w': -0.31})
    out = export_model(model_path, tmp_path / 'nps.py', fmt='python')
    mod = _import(out, 'exported_refusals')
    x = np.zeros(12)
    with pytest.raises(ValueError, match='u ~ 0'):       # Healey-Lienard at u = 0
        mod.f(x, np.zeros(7))
    x[0], x[10] = 1.0, np.pi / 2
    with pytest.raises(ValueError, match='90 deg'):
        mod.f(x, np.zeros(7))
    with pytest.raises(ValueError, match='7 entries'):
        mod.f(np.zeros(12), np.zeros(6))


THRUSTER_VEHICLE = """\
name: thruster_test
title: a test vehicle with four thrusters
scaling: dimensional
rho: 1025.0
L: 0.45
mass: 11.5
W: 112.8
B: 114.8
r_G: [0.0, 0.0, 0.02]
r_B: [0.0, 0.0, -0.01]
inertia: {Ix: 0.16, Iy: 0.16, Iz: 0.16, Ixy: 0.0, Iyz: 0.0, Ixz: 0.0}
limits: {fin_rad: 0.1, n_rpm: 1000.0}
cruise_rpm: 1000.0
mass_inverse: exact
# a main propeller besides the thrusters, so that the fitted exports' simulated envelope
# (no bag) can cruise
propulsion: {model: quadratic_thrust, X_prop: 20.0, K_prop: 0.0, n_nominal_rpm: 1000.0}
coefficients:
  X_udot: [-5.5, X, 3, udot]
  Y_vdot: [-12.7, Y, 3, vdot]
  Z_wdot: [-14.57, Z, 3, wdot]
  K_pdot: [-0.12, K, 3, pdot]
  M_qdot: [-0.12, M, 3, qdot]
  N_rdot: [-0.12, N, 3, rdot]
  X_u: [-4.03, X, 2, u]
  X_uu: [-18.18, X, 2, u*|u|]
  Y_v: [-6.22, Y, 2, v]
  Y_vv: [-21.66, Y, 2, v*|v|]
  Z_w: [-5.18, Z, 2, w]
  Z_ww: [-36.99, Z, 2, w*|w|]
  K_p: [-0.07, K, 2, p]
  K_pp: [-1.55, K, 2, p*|p|]
  M_q: [-0.07, M, 2, q]
  M_qq: [-1.55, M, 2, q*|q|]
  N_r: [-0.07, N, 2, r]
  N_rr: [-1.55, N, 2, r*|r|]
thrusters:
  - {name: t1, r: [0.156, 0.111, 0.085], d: [0.7071, -0.7071, 0.0], command: pwm_us,
     dead_band: 25.0, forward: [0.06, 0.00009], reverse: [0.05, 0.00006],
     thrust_max_forward: 51.5, thrust_max_reverse: 40.0}
  - {name: t2, r: [0.156, -0.111, 0.085], d: [0.7071, 0.7071, 0.0], command: pwm_us,
     table: {unit: kgf, command: [1100, 1300, 1472, 1528, 1700, 1900],
             thrust: [-4.07, -1.44, 0.0, 0.0, 1.82, 5.25]}}
  - {name: t3, r: [0.0, 0.218, 0.0], d: [0.0, 0.0, 1.0], command: setpoint,
     forward: [40.0, 10.0], reverse: [30.0, 8.0]}
  - {name: t4, r: [-0.1, 0.0, 0.0], d: [0.0, 0.0, 1.0], command: force}
identify_default: [X_u]
"""


def test_a_thruster_vehicles_thrusters_are_written_out(tmp_path):
    path = tmp_path / 'thruster_test.yaml'
    path.write_text(THRUSTER_VEHICLE, encoding='utf-8')
    model_path = _model_json(tmp_path / 'm.json', path, {'X_u': -4.4})
    out = export_model(model_path, tmp_path / 'rov.py', fmt='python')
    mod = _import(out, 'exported_rov')
    saved = load_model(model_path)
    v = saved.vehicle
    ours = identified_model(saved)
    assert mod.INPUT_NAMES[7:] == ('t1', 't2', 't3', 't4') and mod.N_INPUTS == 11
    rng = np.random.default_rng(1)
    for command in ([1500.0, 1500.0, 0.0, 0.0], [1520.0, 1480.0, 0.0, 3.0],
                    [1900.0, 1100.0, 1.0, -5.0], [2100.0, 1000.0, -2.0, 0.5],
                    [1700.0, 1300.0, 0.4, 12.0]):
        for i, t in enumerate(v.thrusters):
            assert mod.thruster_force(i, command[i]) == pytest.approx(t.thrust(command[i]),
                                                              rel=1e-15, abs=1e-15)
        x = np.concatenate([rng.normal(0.0, 0.3, 6), rng.normal(0.0, 1.0, 3),
                            rng.normal(0.0, 0.2, 3)])
        u_in = np.concatenate([np.zeros(7), command])
        if getattr(ours, 'n_inputs', 7) == len(u_in):     # a model that holds the thrusters
            want = ours.f(x, u_in)
        else:   # our model's f with the thrusters' wrench (core/model/thrusters.py) in F
            want = ours.f(x, u_in[:7])
            want[:6] += ours.Minv @ wrench(v.thrusters, command)
        got = mod.f(x, u_in)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())


@pytest.mark.parametrize('reference', ['ground', 'water'])
def test_the_python_export_flies_in_a_current_as_our_model(tmp_path, reference):
    """A model that estimated a current: IDENTIFIED_CURRENT, and f / simulate with it equal
    our model with that current (velocities over ground or through the water)."""
    doc = {'vehicle': 'remus100', 'current': {'north': 0.2, 'east': -0.15, 'down': 0.01},
           'coefficients': {'Z_w': {'estimate': -70.0, 'std': 1.0}}}
    model_path = tmp_path / 'm.json'
    model_path.write_text(json.dumps(doc), encoding='utf-8')
    out = export_model(model_path, tmp_path / f'remus_{reference}.py', fmt='python')
    mod = _import(out, f'exported_current_{reference}')
    vc = np.array([0.2, -0.15, 0.01])
    assert mod.IDENTIFIED_CURRENT == tuple(vc)
    saved = load_model(model_path)
    still = identified_model(saved)
    ours = Model(saved.vehicle, (), coefficient_values=still.c, current=vc,
                 velocity_reference=reference)
    # our model's own RK4 run with the current (the simulator's truth is over ground, so
    # the run is integrated here for either reference)
    u = simulate(still, 'zigzag', duration=40.0, noise_std=np.zeros(12)).u
    want = np.empty((len(u), 12))
    want[0] = simulate(still, 'zigzag', duration=0.05, noise_std=np.zeros(12)).x[0]
    for k in range(len(u) - 1):
        want[k + 1] = rk4_step(ours.f, want[k], u[k], 0.05)
    x = mod.simulate(want[0], u[:-1], 0.05, current=mod.IDENTIFIED_CURRENT,
                     velocity_reference=reference)
    rel = (np.abs(_wrapped_diff(x, want)).max(axis=0)
           / np.maximum(np.abs(want).max(axis=0), 1e-9))
    assert rel.max() < 1e-6, rel
    # and the current matters: still water is another trajectory
    assert np.abs(mod.simulate(want[0], u[:-1], 0.05) - x).max() > 0.1
