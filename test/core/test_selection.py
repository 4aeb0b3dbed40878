"""The automatic choice of coefficients (core/identification/selection.py): the request's syntax,
the
stepwise pass on a linear problem whose answer is known, and a short simulated run whose truth
differs from the vehicle file in a few coefficients."""
import numpy as np
import pytest

from auv_ident.core.errors import ConfigError
from auv_ident.core.filter.augmented import FilterConfig
from auv_ident.core.identification.selection import forward_stepwise, identify_auto, parse_request
from auv_ident.core.model.hydrodynamics import Model
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
    model, _, _, est, cov, fit, sel = identify_auto(lambda names: Model(v, list(names)), cfg,
                                                    run.t, run.y, run.u, named=['X_pp'],
                                                    T=run.T)
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


def test_stepwise_with_nothing_forced():
    """`auto` alone with the water current given: the set starts empty."""
    rng = np.random.default_rng(7)
    n = 300
    J = rng.normal(size=(n * 12, 3))
    r = J[:, 0] * 0.4 + J[:, 2] * 0.3 + rng.normal(size=n * 12)
    members, steps, reasons = forward_stepwise(J, r.reshape(n, 12), np.full(3, 2.0),
                                               ['A', 'none', 'B'], [], [0, 1, 2])
    assert members == [0, 2] and list(reasons) == ['none']
