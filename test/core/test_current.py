"""The water current: the model in a current against its equations (Fossen 2021 sec. 10.3) and
finite differences, the option and the identifiability verdict, and our simulator's current
against the independent generator's (offline/independent_data.py). Identification on
independent bags with a current: test_current_identification.py."""
import math

import numpy as np
import pytest

from auv_ident.core.errors import ConfigError
from auv_ident.core.model.current import (
    ADVICE,
    body_current,
    current_identifiability,
    heading_span_deg,
    parse_current,
)
from auv_ident.core.model.hydrodynamics import CURRENT_GROUND, CURRENT_NONE, CURRENT_WATER, Model
from auv_ident.core.model.state import CURRENT_NAMES, LINEAR, State
from auv_ident.core.simulation.simulate import simulate
from auv_ident.offline import independent_data as gen
from auv_ident.offline.independent_data import DataConfig, generate
from auv_ident.vehicles import load_vehicle

VEHICLES = ('nps_auv2', 'remus100')


def _states(rng, n):
    for _ in range(n):
        x = np.concatenate([[rng.uniform(0.5, 2.0)], rng.normal(0, 0.1, 2),
                            rng.normal(0, 0.05, 3), rng.normal(0, 10, 3),
                            rng.uniform(-0.5, 0.5, 2), rng.uniform(-3, 3, 1)])
        ui = np.concatenate([rng.uniform(-0.3, 0.3, 5), [rng.uniform(300, 1400)], [0.0]])
        yield x, ui, rng.normal(0.0, 0.2, 3)


@pytest.mark.parametrize('name', VEHICLES)
@pytest.mark.parametrize('ref', ('ground', 'water'))
def test_jacobians_with_a_current_match_finite_differences(name, ref):
    v = load_vehicle(name)
    m = Model(v, list(v.identify_default) + list(CURRENT_NAMES), mass_inverse='exact',
              velocity_reference=ref)
    assert m.current_mode == (CURRENT_GROUND if ref == 'ground' else CURRENT_WATER)
    rng = np.random.default_rng(11)
    for x, ui, vc in _states(rng, 4):
        th = m.theta_file
        th[m.p_coef:] = vc
        _, A, Bt = m.jacobians(x, ui, th)
        for j in range(12):
            h = 1e-6 * max(1.0, abs(x[j]))
            e = np.zeros(12)
            e[j] = h
            fd = (m.f(x + e, ui, th) - m.f(x - e, ui, th)) / (2 * h)
            assert np.allclose(A[:, j], fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max() + 1e-9), \
                (name, ref, 'x', j)
        for j in range(m.p):
            h = 1e-6 * max(1e-2, abs(th[j]))
            e = np.zeros(m.p)
            e[j] = h
            fd = (m.f(x, ui, th + e) - m.f(x, ui, th - e)) / (2 * h)
            assert np.allclose(Bt[:, j], fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max() + 1e-12), \
                (name, ref, m.theta_names[j])
        # the current's columns are not zero (it does enter f)
        assert np.all(np.abs(Bt[:, m.p_coef:]).max(axis=0) > 0)


@pytest.mark.parametrize('name', VEHICLES)
def test_model_in_a_current_is_the_still_water_model_in_nu_r(name):
    """Ground reference: nu_dot = f_still(nu_r, eta)[nu] + v_cb x omega, eta_dot = J nu; water
    reference: nu_r_dot = f_still(nu_r, eta)[nu], position rate = R nu_r + v_c. R from the
    generator's own rotation (independent of core/model/hydrodynamics.py)."""
    v = load_vehicle(name)
    still = Model(v)
    rng = np.random.default_rng(5)
    for x, ui, vc in _states(rng, 5):
        R = gen.rotation(*x[9:12])
        vcb = R.T @ vc
        xr = x.copy()
        xr[LINEAR] -= vcb
        ground = Model(v, current=vc).f(x, ui)
        ref = still.f(xr, ui)
        np.testing.assert_allclose(ground[:3], ref[:3] + np.cross(vcb, x[3:6]), rtol=1e-12,
                                   atol=1e-14)
        np.testing.assert_allclose(ground[3:6], ref[3:6], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(ground[6:9], R @ x[:3], rtol=1e-12, atol=1e-14)
        np.testing.assert_array_equal(ground[9:], still.f(x, ui)[9:])
        water = Model(v, current=vc, velocity_reference='water').f(x, ui)
        np.testing.assert_array_equal(water[:6], still.f(x, ui)[:6])
        np.testing.assert_allclose(water[6:9], R @ x[:3] + vc, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(body_current(vc, *x[9:12]), vcb, rtol=1e-12, atol=1e-15)


def test_still_water_costs_nothing_and_a_zero_current_changes_no_bit():
    v = load_vehicle('nps_auv2')
    assert Model(v, v.identify_default).current_mode == CURRENT_NONE
    assert Model(v, current=np.zeros(3), velocity_reference='water').current_mode == \
        CURRENT_NONE
    still = Model(v, v.identify_default)
    with_current = Model(v, list(v.identify_default) + ['current_n', 'current_e'])
    rng = np.random.default_rng(2)
    for x, ui, _ in _states(rng, 3):
        th = with_current.theta_file          # current components at 0
        a = still.jacobians(x, ui)
        b = with_current.jacobians(x, ui, th)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[2], b[2][:, :still.p])


@pytest.mark.parametrize('text,estimate,fixed', [
    ('estimate', True, (0, 0, 0)), ('none', False, (0, 0, 0)), ('0.1,-0.2', False, (0.1, -0.2, 0)),
    (' 0.1, 0.2, 0.05 ', False, (0.1, 0.2, 0.05))])
def test_current_option(text, estimate, fixed):
    opt = parse_current(text)
    assert opt.estimate == estimate
    np.testing.assert_array_equal(opt.fixed, fixed)
    assert opt.names == (['current_n', 'current_e'] if estimate else [])
    assert parse_current('estimate', estimate_down=True).names == list(CURRENT_NAMES)


@pytest.mark.parametrize('text', ['fast', '0.1', '0.1,0.2,0.3,0.4', 'nan,0', '0.1,x'])
def test_bad_current_option_is_one_clear_error(text):
    with pytest.raises(ConfigError, match='current'):
        parse_current(text)
    with pytest.raises(ConfigError, match='current-down needs'):
        parse_current('none', estimate_down=True)


def test_model_rejects_bad_current_settings():
    v = load_vehicle('nps_auv2')
    with pytest.raises(ConfigError, match='velocity_reference'):
        Model(v, velocity_reference='bottom')
    with pytest.raises(ConfigError, match='current must be 3'):
        Model(v, current=[0.1, np.nan, 0.0])
    with pytest.raises(ConfigError, match='listed twice'):
        Model(v, ['Z_w', 'current_n', 'current_n'])


def test_heading_span():
    assert heading_span_deg(np.zeros(10)) == 0.0
    assert heading_span_deg(np.radians([170, -170])) == pytest.approx(20.0)
    assert heading_span_deg(np.radians(np.arange(0, 360, 10))) == pytest.approx(350.0)
    assert heading_span_deg(np.radians([-30.0, 50.0, np.nan])) == pytest.approx(80.0)


def test_identifiability_names_the_reason_and_what_to_fly():
    names = ['Z_w', 'current_n', 'current_e']
    cov = np.diag([1e-6, 1e-6, 1e-6])
    ok = current_identifiability(np.radians(np.linspace(-60, 60, 50)), names, cov,
                                 np.sqrt(np.diag(cov)), ['Z_w'])
    assert ok['separable'] and not ok['reasons'] and ok['advice'] == ''
    straight = current_identifiability(np.radians(np.linspace(10, 30, 50)), names, cov,
                                       np.sqrt(np.diag(cov)), ['Z_w'])
    assert not straight['separable'] and 'straight run' in straight['reasons'][0]
    assert straight['advice'] == ADVICE and ADVICE.startswith('turns: the current is separable')
    cov = np.array([[1e-6, 0.99e-6, 0], [0.99e-6, 1e-6, 0], [0, 0, 1e-6]])
    corr = current_identifiability(np.radians(np.linspace(-60, 60, 50)), names, cov,
                                   np.sqrt(np.diag(cov)), ['Z_w'])
    assert not corr['separable'] and corr['correlated_with'] == 'Z_w'


@pytest.mark.parametrize('dvl', ('ground', 'water'))
def test_simulator_current_agrees_with_the_independent_generator(tmp_path, dvl):
    """Our simulator (core RK4 at T) and the generator (its own DOP853 in nu_r and its own
    kinematics) fly the same commands in the same current: the trajectories agree to
    integration accuracy, in what the sensor measures too."""
    vc = (0.12, -0.2, 0.0)
    cfg = DataConfig(duration=60.0, seed=4, odom_rate=20.0, commands='periodic',
                     command_rate=20.0, noise='none', current_ned=vc, dvl=dvl, heading0_deg=0.0)
    data = generate(cfg, tmp_path / 'gen')
    # the generator's commands as a manoeuvre table (switching a hair before each stamp: the
    # grid k T and the stamps agree to a nanosecond, not to the bit)
    table = tmp_path / 'commands.csv'
    rows = [[max(0.0, (s - data.t0_ns) / gen.NS - 1e-6)] + list(u)
            for s, u in zip(data.cmd_stamp_ns, data.cmd_values)]
    np.savetxt(table, rows, delimiter=',', comments='',
               header='t,delta_r,delta_s,delta_b,delta_bp,delta_bs,n_rpm')
    v = load_vehicle('nps_auv2')
    run = simulate(Model(v), str(table), duration=60.0, T=0.05, noise_std=np.zeros(12),
                   current=vc, velocity_reference=dvl, substeps=2)
    assert run.current is not None and run.velocity_reference == dvl
    k = np.round(data.t_odom / 0.05).astype(int)
    x_ours, y_ours = run.x[k], run.y[k]
    assert np.abs(data.t_odom - run.t[k]).max() < 1e-6
    d = x_ours - data.x_true
    d[:, 9:] = (d[:, 9:] + np.pi) % (2 * np.pi) - np.pi
    scale = np.array([1e-4] * 3 + [1e-4] * 3 + [2e-3] * 3 + [1e-4] * 3)
    assert np.all(np.abs(d).max(axis=0) < scale), np.abs(d).max(axis=0)
    dy = y_ours[:, :3] - data.y[:, :3]
    assert np.abs(dy).max() < 1e-4
    # the current matters at this scale: a still-water run is far off
    still = simulate(Model(v), str(table), duration=60.0, T=0.05, noise_std=np.zeros(12))
    assert np.abs(still.x[k][:, State.X] - data.x_true[:, State.X]).max() > 1.0
    assert math.isclose(np.abs(np.asarray(vc)).sum(), np.abs(run.current).sum())
