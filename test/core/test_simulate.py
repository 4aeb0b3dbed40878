"""Tier 1: simulator core (RK4, manoeuvres, noise, trim) and the simulate/derivatives CLIs."""
import csv
import subprocess
import sys

import numpy as np
import pytest

from auv_ident.core.errors import ConfigError
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.integrators import rk4_step
from auv_ident.core.model.sensors import DEFAULT_NOISE_STD
from auv_ident.core.model.trim import trim_speed
from auv_ident.core.simulation import maneuvers
from auv_ident.core.simulation.simulate import simulate
from auv_ident.vehicles import available_vehicles, load_vehicle


def test_rk4_is_fourth_order_on_a_linear_system():
    a = -0.7

    def f(x, u):
        return a * x
    errs = []
    for h in (0.1, 0.05):
        x = np.array([1.0])
        for _ in range(int(round(1.0 / h))):
            x = rk4_step(f, x, None, h)
        errs.append(abs(x[0] - np.exp(a)))
    assert 12 < errs[0] / errs[1] < 20   # 2^4 = 16


def test_nps_trims_to_about_0p6_m_s_at_500_rpm_from_a_long_run():
    m = Model(load_vehicle('nps_auv2'))
    x0 = np.zeros(12)
    x0[0], x0[8] = 0.3, 10.0
    run = simulate(m, 'steps', duration=900.0, T=0.1, rpm=500.0, x0=x0,
                   noise_std=np.zeros(12))
    # 'steps' returns all fins to zero after 160 s; the run then settles on the trim speed
    assert np.all(np.isfinite(run.x))
    assert 0.58 < run.x[-1, 0] < 0.64
    assert abs(run.x[-1, 0] - trim_speed(m, 500.0)) < 0.01


@pytest.mark.parametrize('name', [n for n in available_vehicles()
                                  if load_vehicle(n).free_states.all()
                                  and not load_vehicle(n).hovers])
def test_long_zigzag_stays_finite_and_bounded(name):
    # (the AUVs: a ship at constant thrust in 20 s rudder holds slows far more, test_planar)
    m = Model(load_vehicle(name))
    run = simulate(m, 'zigzag', duration=600.0, seed=3)
    assert np.all(np.isfinite(run.x))
    u0 = trim_speed(m, m.vehicle.cruise_rpm)
    assert 0.5 * u0 < run.x[:, 0].mean() < 1.1 * u0
    assert np.abs(run.x[:, 9]).max() < np.deg2rad(30)


def test_measurement_noise_is_seeded_and_has_the_documented_std():
    m = Model(load_vehicle('nps_auv2'))
    a = simulate(m, 'zigzag', duration=300.0, seed=5)
    b = simulate(m, 'zigzag', duration=300.0, seed=5)
    c = simulate(m, 'zigzag', duration=300.0, seed=6)
    assert np.array_equal(a.y, b.y) and not np.array_equal(a.y, c.y)
    e = a.y - a.x
    e[:, 9:] = (e[:, 9:] + np.pi) % (2 * np.pi) - np.pi
    assert np.allclose(e.std(axis=0), DEFAULT_NOISE_STD, rtol=0.1)


def test_process_noise_changes_the_trajectory():
    m = Model(load_vehicle('nps_auv2'))
    a = simulate(m, 'zigzag', duration=60.0, seed=1)
    b = simulate(m, 'zigzag', duration=60.0, seed=1, process_std=[1e-3] * 3 + [1e-4] * 3)
    assert not np.allclose(a.x, b.x)


def test_maneuvers_respect_fin_limits_and_rpm():
    t = np.arange(0, 300, 0.05)
    for name in maneuvers.MANEUVERS:
        u = maneuvers.commands(name, t, rpm=500.0, seed=2)
        assert np.abs(u[:, :5]).max() <= np.deg2rad(20) + 1e-12
        assert np.all(u[:, 5] == 500.0)
        assert np.abs(u[:, 0]).max() > 0.05     # the rudder moves


def test_prbs_is_rate_limited():
    t = np.arange(0, 200, 0.05)
    u = maneuvers.commands('prbs', t, seed=4)
    assert np.abs(np.diff(u[:, :5], axis=0)).max() <= maneuvers.FIN_RATE * 0.05 + 1e-12


def test_maneuver_from_file(tmp_path):
    p = tmp_path / 'm.csv'
    p.write_text('t,delta_r,delta_s,delta_b,delta_bp,delta_bs,n_rpm\n'
                 '0,0.1,0,0,0,0,500\n10,-0.1,0.05,0,0,0,600\n')
    u = maneuvers.commands(str(p), np.array([0.0, 9.99, 10.0, 20.0]))
    assert u[1, 0] == 0.1 and u[2, 0] == -0.1 and u[3, 5] == 600
    p.write_text('t,delta_r\n0,1\n')
    with pytest.raises(ConfigError, match='lacks column'):
        maneuvers.commands(str(p), np.array([0.0]))


def test_unknown_maneuver_is_a_clear_error():
    with pytest.raises(ConfigError, match="unknown manoeuvre 'zagzig'"):
        maneuvers.commands('zagzig', np.arange(3.0))


def _cli(*args):
    return subprocess.run([sys.executable, '-m', 'auv_ident', *args], capture_output=True,
                          text=True)


def test_simulate_cli_prints_a_summary(tmp_path):
    out = tmp_path / 'run.csv'
    r = _cli('simulate', '--vehicle', 'nps_auv2', '--maneuver', 'zigzag', '--duration', '20',
             '--seed', '1', '--out', str(out))
    assert r.returncode == 0, r.stderr
    assert 'final state' in r.stdout and 'depth' in r.stdout
    rows = list(csv.reader(out.open()))
    assert rows[0][:2] == ['t', 'u'] and len(rows) == 402


def test_simulate_cli_bad_vehicle_is_one_clear_line():
    r = _cli('simulate', '--vehicle', 'titanic')
    assert r.returncode == 2
    assert "unknown vehicle 'titanic'" in r.stderr and 'Traceback' not in r.stderr


def test_derivatives_cli_matches_reference_and_reports_bad_rows(tmp_path):
    src = tmp_path / 'in.csv'
    dst = tmp_path / 'out.csv'
    hdr = 'u,v,w,p,q,r,x,y,z,phi,theta,psi,delta_r,delta_s,delta_b,delta_bp,delta_bs,n_rpm'
    src.write_text(hdr + '\n'
                   '2,0,0,0,0,0,0,0,10,0,0,0,0,0,0,0,0,1000\n'
                   '0,0,0,0,0,0,0,0,10,0,0,0,0,0,0,0,0,1000\n'
                   '2,nan,0,0,0,0,0,0,10,0,0,0,0,0,0,0,0,1000\n'
                   '2,0.1,0.05,0.01,0.02,0.03,0,0,10,0.05,0.1,0.2,0.1,-0.05,0,0.02,0.02,1000\n')
    r = _cli('derivatives', '--vehicle', 'nps_auv2', str(src), str(dst))
    assert r.returncode == 1
    assert 'row 3' in r.stderr and 'propeller ratio' in r.stderr
    assert 'row 4' in r.stderr and 'NaN' in r.stderr
    rows = list(csv.reader(dst.open()))
    assert rows[0][0] == 'u_dot' and len(rows) == 5
    assert float(rows[1][0]) == pytest.approx(-0.021756235860269393, rel=1e-12)
    assert rows[2] == [''] * 12 and rows[3] == [''] * 12
    assert float(rows[4][2]) == pytest.approx(-0.019599861875375876, rel=1e-12)


@pytest.mark.parametrize('name,rpm,lo,hi', [
    ('nps_auv2', 500.0, 0.62, 0.64),     # eta = 1: u = 0.012 n[rad/s] = 0.628 m/s
    ('remus100', 1500.0, 1.50, 1.58),    # Prestero's sea trials: 1.51-1.54 m/s at 1500 rpm
    ('isimi', 1500.0, 1.03, 1.6),        # ISIMI's design goal: > 2 kn = 1.03 m/s
])
def test_vehicles_trim_to_a_sensible_cruise_speed(name, rpm, lo, hi):
    assert lo < trim_speed(Model(load_vehicle(name)), rpm) < hi
