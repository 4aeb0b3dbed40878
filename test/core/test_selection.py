"""The automatic choice of coefficients (core/identification/selection.py): the request's syntax,
the
stepwise pass on a linear problem whose answer is known, and a short simulated run whose truth
differs from the vehicle file in a few coefficients."""
import numpy as np
import pytest
from rov_munk import fixed_munk_file

from auv_ident.core.errors import ConfigError
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.identification.diagnosis import inadequacy_remedy
from auv_ident.core.identification.results import (
    Linearisation,
    percent,
    readable,
    Record,
    Selection,
    times,
)
from auv_ident.core.identification.selection import (
    candidate_coefficients,
    consider_bias,
    consider_sources,
    forward_stepwise,
    HOVER_CROSS_TERM,
    identify_auto,
    left_out_deviation,
    parse_request,
    tank_groups,
)
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.vehicle import vehicle_from_file
from auv_ident.core.simulation.simulate import simulate
from auv_ident.vehicles import load_vehicle


def test_request_syntax_and_errors_name_the_culprit():
    v = load_vehicle('nps_auv2')
    assert parse_request(v, ['auto']) == (True, [])
    assert parse_request(v, [' AUTO ', ' z_ds', 'Y_v']) == (True, ['Z_ds', 'Y_v'])
    assert parse_request(v, ('Z_ds', 'K_v')) == (False, ['Z_ds', 'K_v'])
    assert parse_request(v, []) == (False, [])
    with pytest.raises(ConfigError, match="unknown coefficient 'Q_xyz'"):
        parse_request(v, ['auto', 'Q_xyz'])
    with pytest.raises(ConfigError, match='must come first'):
        parse_request(v, ['Z_ds', 'auto'])
    with pytest.raises(ConfigError, match='Z_ds is listed twice'):
        parse_request(v, ['auto', 'Z_ds', 'z_ds'])
    with pytest.raises(ConfigError, match='water current'):
        parse_request(v, ['auto', 'current_n'])


def test_stepwise_takes_what_reduces_the_residual_and_leaves_out_the_rest_with_reasons():
    """Residual = 2 columns' effect + white noise: those two enter, largest reduction first; a
    column that also acts but correlates 0.96 with a forced one, a column with no effect and one
    with no sensitivity stay out, each with its reason; the forced columns stay first."""
    rng = np.random.default_rng(4)
    n = 400
    J = rng.normal(size=(n * 12, 7))
    J[:, 4] = J[:, 3] + 0.3 * rng.normal(size=n * 12)      # correlation 0.96 with column 3
    J[:, 6] = 0.0                                           # no sensitivity
    r = J[:, 1] * 0.3 + J[:, 2] * -0.2 + J[:, 4] * 0.5 + rng.normal(size=n * 12)
    names = ['F', 'A', 'B', 'G', 'G_copy', 'none', 'zero']
    members, steps, reasons = forward_stepwise(J, r.reshape(n, 12), np.full(7, 2.0), names, [0, 3],
                                               [1, 2, 4, 5, 6])
    assert members[:2] == [0, 3] and sorted(members) == [0, 1, 2, 3]
    assert [s['name'] for s in steps] == ['A', 'B']
    assert all(s['partial_f'] >= 9.0 for s in steps)
    assert set(reasons) == {'G_copy', 'none', 'zero'}
    assert reasons['zero'].startswith('no sensitivity')
    assert reasons['G_copy'].startswith('correlated 0.95') and 'with G' in reasons['G_copy']
    assert reasons['none'].startswith('residual reduction too small')


def test_auto_on_a_short_simulated_run_picks_the_wrong_excited_coefficients():
    """Truth = the file with Z_w, N_r and M_uq off by 25-30 %: the selection frees them, keeps
    a named coefficient the run does not excite, and lists every other coefficient as left out
    with a reason (never both, never neither)."""
    v = load_vehicle('nps_auv2')
    c = v.values.copy()
    for name, factor in (('Z_w', 1.3), ('N_r', 0.75), ('M_uq', 1.25)):
        c[v.index(name)] *= factor
    run = simulate(Model(v, coefficient_values=c), 'ident', duration=150.0, seed=2)
    cfg = FilterConfig(coefficients=[], noise_std=run.noise_std, mode='fixed')
    out = identify_auto(lambda names: Model(v, list(names)), cfg,
                        [Record(run.t, run.y, run.u)], named=['X_pp'], T=run.T)
    model, est, cov, sel = out.model, out.estimate, out.cov, out.selection
    assert sel.chosen[0] == 'X_pp' and sel.named == ['X_pp']
    for name in ('Z_w', 'N_r', 'M_uq'):
        assert name in sel.chosen, (name, sel.left_out.get(name))
    assert set(sel.chosen).isdisjoint(sel.left_out)
    assert set(sel.chosen) | set(sel.left_out) == set(v.names)
    assert all(isinstance(w, str) and w for w in sel.left_out.values())
    assert model.theta_names == sel.chosen
    for name, factor in (('Z_w', 1.3), ('N_r', 0.75), ('M_uq', 1.25)):
        i = sel.chosen.index(name)
        truth = c[v.index(name)]
        assert abs(est[i] - truth) < 3.0 * np.sqrt(cov[i, i]), (name, est[i], truth)
    doc = sel.document()
    assert doc['chosen'] == sel.chosen and doc['left_out'] == sel.left_out
    # every other coefficient is at the file's value: the residuals allow the left-out ones
    # little deviation, and the bars stay near the statistical ones (a blanket 20 % widened
    # them several times)
    assert sel.consider_scale < 0.05
    assert max(sel.consider_inflation.values()) < 2.0
    assert np.all(np.diag(out.statistical_cov) <= np.diag(cov) * (1 + 1e-12))


def test_stepwise_with_nothing_forced():
    """`auto` alone with the water current given: the set starts empty."""
    rng = np.random.default_rng(7)
    n = 300
    J = rng.normal(size=(n * 12, 3))
    r = J[:, 0] * 0.4 + J[:, 2] * 0.3 + rng.normal(size=n * 12)
    members, steps, reasons = forward_stepwise(J, r.reshape(n, 12), np.full(3, 2.0),
                                               ['A', 'none', 'B'], [], [0, 1, 2])
    assert members == [0, 2] and list(reasons) == ['none']


def _left_out_problem(rel_dev, seed=3, n=1500):
    """Linear problem: 2 members, 6 left-out terms off by rel_dev x N(0, 1) of their prior
    values; returns the Linearisation and the members' residuals (whitened, unit noise)."""
    rng = np.random.default_rng(seed)
    p = 8
    J = rng.normal(size=(n * 12, p))
    J[:, 2] += 0.6 * J[:, 0]                    # a left-out term that biases member 0
    prior = np.array([1.0, -2.0, 0.5, 1.5, -1.0, 2.0, 0.8, -0.3])
    d = rel_dev * np.abs(prior) * rng.normal(size=p)
    d[:2] = [0.2, -0.1]                         # the members' own errors: fitted away
    r = J @ d + rng.normal(size=n * 12)
    members, left = [0, 1], list(range(2, p))
    coef = np.linalg.lstsq(J[:, members], r, rcond=None)[0]
    white = (r - J[:, members] @ coef).reshape(n, 12)
    lin = Linearisation(G=J.T @ J, names=[f'c{i}' for i in range(p)], prior=prior,
                        left_candidates=left, jacobian=J.astype(np.float32),
                        white=r.reshape(n, 12))
    return lin, members, left, white


def test_left_out_deviation_is_what_the_residuals_allow():
    """The left-out terms' 1-sigma is read off the members' residuals: ~0 when they are at
    their prior (no blanket widening), of the size of their real deviation when they are off,
    and larger for a larger deviation; the suspects are the terms the residuals point at."""
    lin, members, left, white = _left_out_problem(0.0)
    tau0, info0 = left_out_deviation(lin, members, left, white)
    assert tau0 < 0.03 and info0['suspects'] == []     # the old blanket: 0.2
    lin, members, left, white = _left_out_problem(0.1)
    tau1, info1 = left_out_deviation(lin, members, left, white)
    assert 0.03 < info1['point'] < 0.3 and info1['point'] <= tau1 < 0.4
    lin, members, left, white = _left_out_problem(0.4)
    tau2, _ = left_out_deviation(lin, members, left, white)
    assert tau2 > 2 * tau1
    assert left_out_deviation(lin, members, [], white)[0] == 0.0


def test_consider_sources_name_the_term_a_widening_comes_from():
    lin, members, left, _ = _left_out_problem(0.1)
    sigma = 0.1 * np.abs(lin.prior)
    src = consider_sources(lin.G, members, left, sigma, lin.names, ['c0', 'c1'])
    assert next(iter(src['c0'])) == 'c2' and src['c0']['c2'] > 0.9
    bias = consider_bias(lin.G, members, left, sigma)
    assert bias[0, 0] > 10 * bias[1, 1]


def test_inadequacy_advice_after_auto_names_what_was_left_out_not_auto_again():
    v = load_vehicle('nps_auv2')
    sel = Selection(chosen=['K_v', 'Z_w'], named=['K_v'],
                    left_out={'N_r': 'correlated 0.970 with Z_w (limit 0.95)',
                              'M_qdot': "added mass: the vehicle's fixed (literal) mass inverse "
                                        'does not change with it', 'Y_v': 'not reached'},
                    suspects=['N_r', 'M_qdot'])
    text = inadequacy_remedy(v, sel)
    assert '(--coefficients auto)' not in text and 'used here' in text
    assert '--coefficients auto,K_v,N_r,M_qdot --mass-inverse exact' in text
    assert 'rudder zig-zags' in text and 'quick fin reversals' in text
    assert 'identify more coefficients (--coefficients auto)' in inadequacy_remedy(v, None)
    none = inadequacy_remedy(v, Selection(chosen=['K_v'], named=['K_v'], left_out={}))
    assert 'no left-out coefficient the residuals point at' in none


def test_numbers_for_people_have_no_exponent_and_no_nan():
    assert readable(7.63e-06) == '< 0.001' and readable(12345.6) == '12300'
    assert readable(0.041345) == '0.0413' and readable(float('nan')) == '-'
    assert readable(float('inf')) == 'unbounded' and readable(0.0) == '0'
    assert percent(122.0) == '12200 %' and percent(0.0041) == '0.41 %' and percent(0.13) == '13 %'
    assert times(822.4) == '822x' and times(1.523) == '1.52x' and times(2.345, 2) == '2.3x'
    for text in (readable(1e-9), readable(3e7), percent(2.65e1), times(1e6)):
        assert 'e+' not in text and 'e-' not in text and 'nan' not in text


def test_a_group_that_is_determined_together_enters_together():
    """Three columns correlated 0.8 pairwise, each with its prior 20 % off in the residual:
    one at a time each absorbs the other two's prior errors (consider analysis) and none
    lowers the expected error, so the plain stepwise leaves all three out; as a group (a
    hovering vehicle's added mass, linear and quadratic damping of one equation) they enter
    together, with the group named in their steps."""
    rng = np.random.default_rng(11)
    n = 400
    common = rng.normal(size=n * 12)
    J = np.column_stack([2.0 * common + rng.normal(size=n * 12) for _ in range(3)]
                        + [rng.normal(size=n * 12)])
    assert np.all(np.corrcoef(J[:, :3].T)[np.triu_indices(3, 1)] > 0.75)
    r = J[:, :3] @ np.array([0.2, -0.2, 0.2]) + rng.normal(size=n * 12)
    names = ['A_udot', 'A_u', 'A_uu', 'none']
    args = (J, r.reshape(n, 12), np.ones(4), names, [], [0, 1, 2, 3])
    members, steps, reasons = forward_stepwise(*args)
    assert members == [] and all('would not lower the expected error' in reasons[m]
                                 for m in names[:3]), reasons
    members, steps, reasons = forward_stepwise(*args, groups=[[0, 1, 2]])
    assert sorted(members) == [0, 1, 2] and list(reasons) == ['none']
    assert {s['group'] for s in steps} == {'A_udot,A_u,A_uu'}


def test_a_hovering_vehicle_chooses_among_its_diagonal_terms_and_thrust_gains(tmp_path):
    """BlueROV2 Heavy: the candidates are the thrust gains and the diagonal added mass and
    damping (cross terms, such as the Coriolis of the added mass written as fixed coefficients,
    left out with the reason), in groups per degree of freedom; a fin vehicle's candidates and
    groups are as before."""
    v = load_vehicle('bluerov2_heavy')
    cands, left = candidate_coefficients(v, 'exact')
    assert set(v.identify_default) <= set(cands)
    assert set(cands) | set(left) == set(v.names) and not set(cands) & set(left)
    # the shipped file's added-mass Coriolis follows its added mass (no coefficients of its
    # own); the file that writes it as fixed cross terms gets those left out
    assert HOVER_CROSS_TERM not in left.values()
    fixed = vehicle_from_file(str(fixed_munk_file(tmp_path / 'fixed.yaml')))
    f_cands, f_left = candidate_coefficients(fixed, 'exact')
    assert f_cands == cands
    assert {f_left[n] for n in ('X_vr', 'Y_ur', 'N_uv', 'K_vw', 'M_uw')} == {HOVER_CROSS_TERM}
    idx = list(range(len(cands)))
    groups = [[cands[i] for i in g] for g in tank_groups(cands, v, idx)]
    assert ['thrust_gain_fwd', 'thrust_gain_rev'] in groups
    assert ['X_udot', 'X_u', 'X_uu'] in groups and ['N_rdot', 'N_rr'] in groups
    fin = load_vehicle('nps_auv2')
    f_cands, f_left = candidate_coefficients(fin, 'exact')
    assert HOVER_CROSS_TERM not in f_left.values() and len(f_cands) > 20
    assert tank_groups(f_cands, fin, list(range(len(f_cands)))) == []
