"""core/identification/plausibility.py: signs the physics forbids and the vehicle file's prior."""
import numpy as np
import pytest

from auv_ident.core.errors import ConfigError
from auv_ident.core.identification.plausibility import (
    depth_contradicts_down,
    implausible_coefficients,
    is_self_damping,
    prior_sd,
    what_to_check,
)
from auv_ident.vehicles import load_vehicle

SHIPPED = ('nps_auv2', 'remus100', 'isimi', 'kvlcc2_hsva')


def _self_damping(v):
    return {c.name for c in v.coefficients if is_self_damping(c)}


def test_the_self_damping_terms_are_found_by_their_multiplier():
    nps = _self_damping(load_vehicle('nps_auv2'))
    assert nps == {'X_udot', 'Y_vdot', 'Z_wdot', 'K_pdot', 'M_qdot', 'N_rdot',
                   'Y_v', 'Z_w', 'K_p', 'M_uq', 'N_r'}
    remus = _self_damping(load_vehicle('remus100'))
    assert {'X_uu', 'Y_vv', 'Z_ww', 'K_pp', 'M_qq', 'N_rr', 'Y_v', 'Z_w', 'M_q', 'N_r'} <= remus
    # a cross term, a control derivative and the Munk moment are not self-damping
    assert not {'K_v', 'Z_ds', 'M_w', 'Y_r'} & (nps | remus)


@pytest.mark.parametrize('name', SHIPPED)
def test_every_shipped_vehicle_file_is_plausible_for_itself(name):
    """No false alarm: the file's values, with small or no error bars, and 20 % off."""
    v = load_vehicle(name)
    for scale, rel_std in ((1.0, 0.0), (1.0, 0.01), (1.2, 0.0), (0.8, 0.02)):
        est = v.values * scale
        assert implausible_coefficients(v, v.names, est, np.abs(est) * rel_std) == []


def test_another_vehicles_values_are_not_plausible():
    """REMUS 100's file on NPS AUV II's run gave M_w -845 (file 24) and Y_v +211: both named."""
    remus = load_vehicle('remus100')
    names = ['M_w', 'Y_v', 'Z_w', 'Y_dr']
    i = [remus.index(n) for n in names]
    est = remus.values[i].copy()
    est[0], est[1] = -845.0, 211.0
    found = implausible_coefficients(remus, names, est, np.abs(est) * 0.01)
    assert [f.name for f in found] == ['M_w', 'Y_v']
    assert 'is positive: a self-damping term of equation Y' in found[1].reason
    assert 'sigma from the vehicle file' in found[0].reason
    assert what_to_check(found).startswith('NOT plausible: M_w, Y_v (')


def test_a_positive_damping_inside_its_error_bar_is_not_flagged():
    v = load_vehicle('nps_auv2')
    assert implausible_coefficients(v, ['Z_w'], [0.01], [0.02]) == []
    assert [f.name for f in implausible_coefficients(v, ['Z_w'], [0.1], [0.02])] == ['Z_w']


def test_the_prior_block_of_a_vehicle_file(tmp_path):
    text = open(load_vehicle('nps_auv2').path, encoding='utf-8').read()
    path = tmp_path / 'nps_prior.yaml'
    path.write_text(text.replace('cruise_rpm: 500.0', 'cruise_rpm: 500.0\nprior:\n'
                                 '  relative_sd: 0.1\n  coefficients:\n'
                                 '    K_v: {relative_sd: 3.0}\n    Z_ds: {sd: 0.5}', 1))
    v = load_vehicle(str(path))
    assert prior_sd(v, 'Z_q') == pytest.approx(0.014)
    assert prior_sd(v, 'K_v') == pytest.approx(3.0 * 0.0031)
    assert prior_sd(v, 'Z_ds') == 0.5
    # 50 % off: outside a 10 % prior, inside the default 100 %
    assert [f.name for f in implausible_coefficients(v, ['Z_q'], [-0.07], [0.0])] == ['Z_q']
    bad = tmp_path / 'bad.yaml'
    bad.write_text(text.replace('cruise_rpm: 500.0',
                                'cruise_rpm: 500.0\nprior: {relative_sd: -1}'))
    with pytest.raises(ConfigError, match='prior of Z_q gives 1-sigma'):
        prior_sd(load_vehicle(str(bad)), 'Z_q')


def test_control_derivatives_with_the_opposite_sign_are_named():
    """An ENU run read as NED flips Z_ds, M_ds (and K_v, a cross term the prior judges): the
    control derivatives are named whatever their size; within their error bar they are not."""
    v = load_vehicle('nps_auv2')
    names = ['Z_ds', 'Z_q', 'Z_w', 'M_ds', 'K_v']
    flipped = np.array([0.073, -0.14, -0.3, 0.041, -0.0031])
    found = implausible_coefficients(v, names, flipped, np.abs(flipped) * 0.01)
    assert [f.name for f in found] == ['Z_ds', 'M_ds']
    assert 'opposite sign' in found[0].reason
    assert implausible_coefficients(v, ['Z_ds'], [0.001], [0.01]) == []


def test_a_depth_above_the_surface_says_the_z_axis_points_up():
    assert depth_contradicts_down(np.full(100, 10.0)) == ''
    assert depth_contradicts_down(np.r_[np.full(50, -0.3), np.full(50, 0.4)]) == ''
    why = depth_contradicts_down(np.r_[np.full(100, -10.0), np.nan])
    assert 'above the water surface' in why and 'ENU/FLU' in why
    assert depth_contradicts_down(np.full(100, -10.0), heave_free=False) == ''
