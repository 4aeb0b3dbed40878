"""Tier 1: the augmented EKF, noise adaptation, batch refinement and streaming pairing."""
import ast
import os
import pathlib
import shutil
import subprocess
import sys

import numba
import numpy as np
import pytest

import auv_ident.core as core
from auv_ident.core import compiled_cache, safe_files
from auv_ident.core.angles import wrap_angle
from auv_ident.core.errors import ConfigError, DimensionError
from auv_ident.core.filter import ekf
from auv_ident.core.filter.augmented import AugmentedEKF, FilterConfig
from auv_ident.core.filter.stream import StreamIdentifier
from auv_ident.core.identification.batch import identify, run_ekf
from auv_ident.core.identification.results import Record
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import COEFFICIENTS, EULER, NU, POSITION, State, VEHICLE
from auv_ident.core.simulation.simulate import simulate
from auv_ident.vehicles import available_vehicles, load_vehicle

NPS = load_vehicle('nps_auv2')
NAMES = list(NPS.identify_default)


@pytest.fixture(scope='module')
def short_run():
    return simulate(Model(NPS), 'ident', duration=120.0, seed=11)


def _spd(n, rng):
    a = rng.normal(size=(n, n))
    return a @ a.T + n * np.eye(n)


@pytest.mark.parametrize('full_R', [False, True])
def test_update_equals_closed_form_kalman_update_with_missing_channels(full_R):
    rng = np.random.default_rng(0)
    n = 15
    P = _spd(n, rng) * 1e-2
    # diagonal R: sequential scalar Joseph updates; full R: the batch path
    R = _spd(12, rng) * 1e-3 if full_R else np.diag(rng.uniform(0.01, 0.1, 12))
    xa = rng.normal(size=n)
    xa[9:12] = 0.1
    y = xa[:12] + rng.normal(0, 0.1, 12)
    y[4] = np.nan                      # a missing sample
    measured = np.ones(12, dtype=bool)
    measured[7] = False                # a channel the suite does not have
    out_x, out_P = np.empty(n), np.empty((n, n))
    innov, S_diag, white = np.empty(12), np.empty(12), np.empty(12)
    st, nis, m = ekf.update(xa, P, y, measured, R, out_x, out_P, innov, S_diag, white,
                          ekf.new_workspace(len(xa), 1))
    assert st == ekf.OK and m == 10
    idx = [j for j in range(12) if j not in (4, 7)]
    H = np.zeros((len(idx), n))
    H[np.arange(len(idx)), idx] = 1.0
    Rm = R[np.ix_(idx, idx)]
    S = H @ P @ H.T + Rm
    Kg = P @ H.T @ np.linalg.inv(S)
    nu = y[idx] - xa[idx]
    x_ref = xa + Kg @ nu
    P_ref = (np.eye(n) - Kg @ H) @ P
    assert np.allclose(out_x[:11], x_ref[:11], atol=1e-12)
    assert np.allclose(out_P, P_ref, atol=1e-12)
    assert nis == pytest.approx(nu @ np.linalg.solve(S, nu), rel=1e-10)
    w = white[idx]
    assert w @ w == pytest.approx(nis, rel=1e-10)
    assert np.isnan(innov[4]) and np.isnan(innov[7])


def test_angle_innovation_is_wrapped():
    n = 12
    P = np.eye(n) * 0.01
    R = np.eye(12) * 0.01
    xa = np.zeros(n)
    xa[11] = np.pi - 0.01
    y = np.full(12, np.nan)
    y[11] = -np.pi + 0.01              # 0.02 rad away across the +-pi cut
    out_x, out_P = np.empty(n), np.empty((n, n))
    innov, S_diag, white = np.empty(12), np.empty(12), np.empty(12)
    st, _, _ = ekf.update(xa, P, y, np.ones(12, bool), R, out_x, out_P, innov, S_diag, white,
                        ekf.new_workspace(len(xa), 1))
    assert st == ekf.OK and innov[11] == pytest.approx(0.02)
    assert abs(abs(out_x[11]) - np.pi) < 0.02


@pytest.mark.parametrize('name', available_vehicles())
def test_rk4_transition_jacobian_matches_finite_differences(name):
    """Also checks, for every vehicle and at random states, the sparsity the chain through the
    stages relies on (rk4_step_into: f depends on neither the position nor, in the rows of the
    body-velocity and Euler-angle rates, psi)."""
    v = load_vehicle(name)
    m = Model(v, list(v.identify_default))
    rng = np.random.default_rng(3)
    xa = np.concatenate([[1.2, 0.05, -0.03, 0.01, 0.02, -0.01, 3, 4, 10, 0.05, -0.1, 0.4],
                         m.theta_file * 1.2])
    ui = np.array([0.1, -0.2, 0.0, 0.1, 0.05, 800.0, 30.0])
    # a thruster vehicle's PWM commands (us): both sides of the dead band, one saturated
    ui = np.r_[ui, np.resize([1700.0, 1350.0, 1560.0, 1950.0, 1200.0], len(v.thrusters))]
    n = len(xa)
    x1, Fa = np.empty(n), np.empty((n, n))
    assert ekf.rk4_jacobian_step(xa, ui, m.compiled, 0.05, True, x1, Fa) == ekf.OK
    for j in range(n):
        h = 1e-6 * max(1.0, abs(xa[j])) if j < 12 else 1e-4 * abs(xa[j])
        e = np.zeros(n)
        e[j] = h
        a, b = np.empty(n), np.empty(n)
        ekf.rk4_jacobian_step(xa + e, ui, m.compiled, 0.05, False, a, Fa.copy())
        ekf.rk4_jacobian_step(xa - e, ui, m.compiled, 0.05, False, b, Fa.copy())
        fd = (a - b) / (2 * h)
        assert np.allclose(Fa[:, j], fd, rtol=1e-6, atol=1e-9 * max(1, np.abs(fd).max())), j
    spread = np.array([0.1] * 3 + [0.02] * 3 + [50.0] * 3 + [0.1] * 3)
    for _ in range(5):
        x = xa[VEHICLE] + rng.normal(0.0, spread)
        _, A, _ = m.jacobians(x, ui, xa[COEFFICIENTS])
        assert not np.any(A[:, POSITION]), (name, A[:, POSITION])
        assert not np.any(A[NU, State.PSI]) and not np.any(A[EULER, State.PSI]), name
        assert np.any(A[POSITION, State.PSI])          # the position rates do depend on psi


def test_the_compiled_angle_wrap_agrees_with_core_angles():
    """ekf.wrap (the filter's, compiled) and angles.wrap_angle (Python callers') wrap to
    (-pi, pi] alike: equal outside it; inside it wrap_angle returns the angle itself and the
    compiled one at most an ulp of pi away (it reduces every angle)."""
    rng = np.random.default_rng(9)
    a = np.concatenate([rng.uniform(-20.0, 20.0, 2000), [np.pi, -np.pi, 3 * np.pi, 0.0, 1e-300,
                                                          -np.pi + 1e-15, 7 * np.pi / 2]])
    w = wrap_angle(a)
    assert np.all((w > -np.pi) & (w <= np.pi)) and wrap_angle(-np.pi) == np.pi
    assert np.array_equal(w, [wrap_angle(float(v)) for v in a])      # arrays as numbers
    inside = (a > -np.pi) & (a <= np.pi)
    assert np.array_equal(w[inside], a[inside])
    c = np.array([ekf.wrap(float(v)) for v in a])
    assert np.array_equal(c[~inside], w[~inside])
    assert np.all(np.abs(c[inside] - a[inside]) <= np.spacing(np.pi))


def test_predict_is_F_P_Ft_plus_Q():
    m = Model(NPS, NAMES)
    rng = np.random.default_rng(4)
    n = 17
    xa = np.concatenate([[1.0, 0, 0, 0, 0, 0, 0, 0, 10, 0, 0, 0], m.theta_file])
    P = _spd(n, rng) * 1e-4
    Q = np.diag(rng.uniform(1e-8, 1e-6, n))
    ui = np.array([0.1, 0.1, 0, 0, 0, 500.0, 0.0])
    x1, Fa = np.empty(n), np.empty((n, n))
    ekf.rk4_jacobian_step(xa, ui, m.compiled, 0.05, True, x1, Fa)
    xo, Po = np.empty(n), np.empty((n, n))
    ws = ekf.new_workspace(n, len(m.c))
    assert ekf.predict(xa, P, ui, Q, m.compiled, 0.05, xo, Po, ws) == ekf.OK
    assert np.allclose(xo, x1) and np.allclose(Po, Fa @ P @ Fa.T + Q, rtol=1e-12, atol=1e-18)


def test_paper_adaptation_formulas_by_hand():
    n = 14                               # 12 states + 2 coefficients
    Q = np.diag(np.arange(1.0, n + 1) * 1e-6)
    R = np.eye(12) * 0.01
    Q0, R0 = Q.copy(), R.copy()
    theta_prev = np.array([1.0, 2.0])
    xa_post = np.zeros(n)
    xa_post[12:] = [1.1, 1.8]
    innov = np.full(12, np.nan)
    innov[0], innov[3] = 0.2, -0.1
    gamma, lam, T = 0.1, 2e-3, 0.05
    Qp, Rp = Q.copy(), R.copy()
    ekf.adapt(ekf.MODE_PAPER, gamma, lam, T, 4.0, 1e-4, theta_prev, xa_post, innov, np.ones(12),
            np.eye(n), Qp, Rp, Q0, R0)
    w = (xa_post[12:] - theta_prev) / T                        # Eq. 18
    Qth = (1 - gamma) * Q[12:, 12:] + gamma * lam ** 2 * np.outer(w, w)   # Eq. 16
    assert np.allclose(Qp[12:, 12:], Qth, rtol=1e-12)
    assert np.array_equal(Qp[:12, :12], Q[:12, :12])
    v = innov[[0, 3]]
    Rref = R.copy()
    Rref[np.ix_([0, 3], [0, 3])] = (1 - gamma) * R[np.ix_([0, 3], [0, 3])] \
        + gamma * lam ** 2 * np.outer(v, v)                    # Eq. 17
    assert np.allclose(Rp, Rref, rtol=1e-12)
    # matching: R_jj moves towards nu^2 - (H P H^T)_jj and is clipped to [R0/4, 4 R0]
    Qm, Rm = Q.copy(), R.copy()
    P_prior = np.eye(n) * 1e-3
    ekf.adapt(ekf.MODE_MATCHING, gamma, lam, T, 4.0, 1e-4, theta_prev, xa_post, innov,
            np.ones(12), P_prior, Qm, Rm, Q0, R0)
    assert Rm[0, 0] == pytest.approx((1 - gamma) * 0.01 + gamma * (0.04 - 1e-3))
    assert Rm[3, 3] == pytest.approx((1 - gamma) * 0.01 + gamma * (0.01 - 1e-3))
    assert Rm[1, 1] == 0.01                                    # no innovation: unchanged
    d2 = (xa_post[12:] - theta_prev) ** 2
    q = np.minimum((1 - gamma) * np.diag(Q)[12:] + gamma * d2, np.diag(Q0)[12:])
    assert np.allclose(np.diag(Qm)[12:], q)


def test_covariance_stays_symmetric_positive_definite_over_a_long_run():
    m = Model(NPS, NAMES)
    run = simulate(Model(NPS), 'ident', duration=900.0, seed=2)
    f = AugmentedEKF(m, FilterConfig(coefficients=NAMES), run.T)
    hist = run_ekf(f, [Record(run.t, run.y, run.u)], hist_every=100).history
    assert np.array_equal(f.P, f.P.T)
    assert np.linalg.eigvalsh(f.P).min() > 0
    assert np.all(np.isfinite(hist['std'])) and np.all(hist['std'] > 0)


def test_short_run_converges_within_a_few_percent(short_run):
    m = Model(NPS, NAMES)
    for offset in (0.5, -0.5):
        cfg = FilterConfig(coefficients=NAMES, initial_offset=offset)
        res = identify(m, [Record(short_run.t, short_run.y, short_run.u)], cfg,
                       refine_pass=False, truth=m.theta_file)
        err = np.abs(res.error_pct())
        assert err.max() < 5.0, dict(zip(NAMES, err))


def test_refinement_is_consistent_and_independent_of_the_start(short_run):
    m = Model(NPS, NAMES)
    ests = []
    for offset in (0.5, -0.5):
        res = identify(m, [Record(short_run.t, short_run.y, short_run.u)],
                       FilterConfig(coefficients=NAMES, initial_offset=offset),
                       truth=m.theta_file)
        assert np.all(np.abs(res.estimate - res.truth) < 4 * res.std)
        ests.append(res.estimate)
    assert np.allclose(ests[0], ests[1], rtol=1e-4)


def test_subset_of_channels_and_missing_samples_still_identify(short_run):
    m = Model(NPS, NAMES)
    y = short_run.y.copy()
    y[::7, 0:3] = np.nan                       # DVL drop-outs
    measured = np.ones(12, dtype=bool)
    measured[6:8] = False                      # no USBL x, y
    cfg = FilterConfig(coefficients=NAMES, measured=measured)
    res = identify(m, [Record(short_run.t, y, short_run.u)], cfg, refine_pass=False,
                   truth=m.theta_file)
    assert np.abs(res.error_pct()).max() < 5.0


def test_stream_identifier_equals_the_compiled_loop(short_run):
    m = Model(NPS, NAMES)
    cfg = FilterConfig(coefficients=NAMES)
    res = identify(m, [Record(short_run.t, short_run.y, short_run.u)], cfg, refine_pass=False)
    s = StreamIdentifier(m, cfg, short_run.T)
    # actuator commands arrive with the odometry of the same stamp; order must not matter
    for k, t in enumerate(short_run.t):
        if k % 2:
            s.add_measurement(t, short_run.y[k])
            s.add_command(t, short_run.u[k])
        else:
            s.add_command(t, short_run.u[k])
            s.add_measurement(t, short_run.y[k])
    assert s.accepted == len(short_run.t) and s.rejected == 0
    assert np.allclose(s.ekf.theta, res.ekf_estimate, rtol=1e-9, atol=0)


def test_stream_rejects_duplicates_and_out_of_order_and_bridges_gaps(short_run):
    m = Model(NPS, NAMES)
    s = StreamIdentifier(m, FilterConfig(coefficients=NAMES), short_run.T, max_gap=5.0,
                         max_bridge=1.0)
    r = s.add_measurement(0.0, short_run.y[0])
    assert not r.accepted and 'no actuator command' in r.reason
    s.add_command(0.0, short_run.u[0])
    assert s.add_measurement(0.0, short_run.y[0]).accepted
    assert 'duplicate or out of order' in s.add_measurement(0.0, short_run.y[0]).reason
    s.add_command(0.05, short_run.u[1])
    assert s.add_measurement(0.05, short_run.y[1]).accepted
    out = s.add_measurement(0.5, short_run.y[10])                 # 9 samples missing: bridged
    assert out.accepted and out.code == ''
    out = s.add_measurement(2.0, short_run.y[40])                 # 1.5 s > max_bridge: restart
    assert out.accepted and out.code == 'gap' and 'restarted' in out.reason
    out = s.add_measurement(20.0, short_run.y[400])               # beyond max_gap too
    assert out.accepted and out.code == 'gap' and 'restarted' in out.reason
    assert np.all(np.isfinite(s.ekf.theta))


@pytest.mark.parametrize('kwargs,exc,needle', [
    ({'noise_std': np.ones(11)}, DimensionError, 'noise_std must have shape'),
    ({'noise_std': -np.ones(12)}, ConfigError, 'non-negative'),
    ({'q_state': np.full(12, np.nan)}, ConfigError, 'q_state'),
    ({'mode': 'arma'}, ConfigError, "mode 'arma'"),
    ({'initial': [1.0, 2.0]}, DimensionError, 'expected 5 values'),
    ({'p0_rel': -1.0}, ConfigError, 'p0_rel'),
    ({'theta_cov0': np.eye(4)}, DimensionError, r'theta_cov0 must have shape \(5, 5\)'),
    ({'theta_cov0': np.triu(np.ones((5, 5)))}, ConfigError, 'theta_cov0 is not symmetric'),
    ({'theta_cov0': -np.eye(5)}, ConfigError, 'theta_cov0 is not positive definite'),
])
def test_bad_configuration_is_a_clear_error(kwargs, exc, needle):
    m = Model(NPS, NAMES)
    with pytest.raises(exc, match=needle):
        AugmentedEKF(m, FilterConfig(coefficients=NAMES, **kwargs), 0.05)


def test_initial_coefficient_covariance_is_the_prior_of_start_and_of_the_compiled_loop(
        short_run):
    """FilterConfig.theta_cov0 (a full covariance, e.g. a warm start) is the coefficient block
    of P0 in both paths; set_prior replaces estimate and covariance for the next start."""
    m = Model(NPS, NAMES)
    rng = np.random.default_rng(8)
    th0 = m.theta_file * 1.1
    C = _spd(5, rng) * np.outer(th0, th0) * 1e-3
    cfg = FilterConfig(coefficients=NAMES, initial=th0, theta_cov0=C)
    f = AugmentedEKF(m, cfg, short_run.T)
    xa0, P0 = f.initial_estimate(short_run.y[0], short_run.u[0, 5])
    assert np.array_equal(P0[12:, 12:], C) and not np.any(P0[:12, 12:])
    assert np.array_equal(xa0[12:], th0)
    # the per-message start and the compiled loop start from the same prior
    g = AugmentedEKF(m, cfg, short_run.T)
    g.start(short_run.y[0], short_run.u[0, 5])
    for k in range(1, 50):
        g.step(short_run.u[k - 1], short_run.y[k])
    run_ekf(f, [Record(short_run.t[:50], short_run.y[:50], short_run.u[:50])])
    np.testing.assert_allclose(g.xa, f.xa, rtol=1e-12)
    # the default prior differs (diagonal), so the prior did matter
    d = AugmentedEKF(m, FilterConfig(coefficients=NAMES, initial=th0), short_run.T)
    run_ekf(d, [Record(short_run.t[:50], short_run.y[:50], short_run.u[:50])])
    assert not np.allclose(d.xa[12:], f.xa[12:], rtol=1e-6)
    h = AugmentedEKF(m, FilterConfig(coefficients=NAMES), short_run.T)
    h.set_prior(th0, C)
    h.start(short_run.y[0], short_run.u[0, 5])
    g.reset()
    g.start(short_run.y[0], short_run.u[0, 5])
    assert np.array_equal(h.P, g.P) and np.array_equal(h.xa, g.xa)
    with pytest.raises(ConfigError, match='prior coefficients must be 5 finite values'):
        h.set_prior(th0[:3], C)


def test_zero_sample_time_and_unknown_coefficient_are_clear_errors():
    with pytest.raises(ConfigError, match='sample time'):
        AugmentedEKF(Model(NPS, NAMES), FilterConfig(coefficients=NAMES), 0.0)
    with pytest.raises(ConfigError, match="unknown coefficient 'Z_wx'"):
        Model(NPS, ['Z_wx'])


def _compiled_core_closure(core):
    """Core modules with numba code, and every core module they import (transitively)."""
    compiled, imports = set(), {}
    for path in core.rglob('*.py'):
        if '__pycache__' in path.parts:
            continue        # numba caches of older versions, not sources
        name = path.relative_to(core).as_posix()
        tree = ast.parse(path.read_text())
        names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
        names |= {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)}
        if names & {'njit', 'cached_njit', 'jit', 'cfunc', 'intrinsic', 'kernel'}:
            compiled.add(name)
        imports[name] = set()
        for n in ast.walk(tree):
            if isinstance(n, ast.ImportFrom) and (n.module or '').startswith('auv_ident.core.'):
                mod = n.module[len('auv_ident.core.'):].replace('.', '/')
                imports[name] |= {f'{mod}.py'} | {f'{mod}/{a.name}.py' for a in n.names}
    # the cache's and the files' mechanism, no compiled code
    mechanism = {'__init__.py', 'compiled_cache.py', 'safe_files.py'}
    todo = list(compiled - mechanism)
    seen = set()
    while todo:
        name = todo.pop()
        if name not in seen | mechanism:
            seen.add(name)
            todo.extend(i for i in imports.get(name, ()) if (core / i).is_file())
    return seen


def test_numba_cache_of_the_core_is_keyed_on_every_compiled_source(short_run):
    """Every function the core caches has its cache in the folder named after the digest of
    all compiled core sources, outside the package (numba writes the loop's index there), and
    that list holds every module with numba code and everything such code imports; nothing
    in the core asks numba for a cache but through compiled_cache.cached_njit."""
    folder = pathlib.Path(core.__file__).parent
    assert _compiled_core_closure(folder) == set(core.COMPILED_SOURCES)
    for path in folder.rglob('*.py'):
        if path.name != 'compiled_cache.py' and '__pycache__' not in path.parts:
            for n in ast.walk(ast.parse(path.read_text())):
                assert not (isinstance(n, ast.keyword) and n.arg == 'cache'), path
    group = compiled_cache.cache_folder_of(ekf.__file__)
    base = os.environ.get('NUMBA_CACHE_DIR') or safe_files.private_folder('numba')
    assert group == compiled_cache.group_folder(base, str(folder), core.COMPILED_SOURCES)
    assert not pathlib.Path(group).is_relative_to(folder.parent)
    for name in core.COMPILED_SOURCES:
        assert compiled_cache.cache_folder_of(str(folder / name)) == group
    r = short_run
    run_ekf(AugmentedEKF(Model(NPS, NAMES), FilterConfig(coefficients=NAMES), r.T),
            [Record(r.t[:50], r.y[:50], r.u[:50])])
    assert list(pathlib.Path(group).rglob('ekf.run_filter-*.nbi'))


def test_editing_the_model_makes_the_cached_ekf_loop_stale(tmp_path, monkeypatch):
    """The cache folder of ekf.py's functions changes when model/hydrodynamics.py (which they
    inline) changes, and not when a file outside the compiled sources does."""
    monkeypatch.setattr(numba.config, 'CACHE_DIR', str(tmp_path / 'numba'))  # as NUMBA_CACHE_DIR
    folder = tmp_path / 'core'
    shutil.copytree(pathlib.Path(core.__file__).parent, folder,
                    ignore=shutil.ignore_patterns('__pycache__'))
    compiled_cache.register(str(folder), core.COMPILED_SOURCES)
    ekf_py = str(folder / 'filter/ekf.py')
    before = compiled_cache.cache_folder_of(ekf_py)
    assert os.path.dirname(before) == str(tmp_path / 'numba')

    def fresh():
        compiled_cache.register(str(folder), core.COMPILED_SOURCES)   # forget the folder
        return compiled_cache.cache_folder_of(ekf_py)
    with open(folder / 'filter/stream.py', 'a') as fh:
        fh.write('# an edit outside the compiled sources\n')
    assert fresh() == before
    with open(folder / 'model/hydrodynamics.py', 'a') as fh:
        fh.write('# an edit of the model\n')
    after = fresh()
    assert after != before and os.path.dirname(after) == os.path.dirname(before)


_CALLEE = '{head}\n\n@{deco}\ndef g(x):\n    return x + {increment}\n'
_CALLER = '{head}\n\nfrom .callee import g\n\n\n@{deco}\ndef f(x):\n    return g(x)\n'
_HEADS = {'numba': ('from numba import njit\n', 'njit(cache=True)'),
          'group': ('from auv_ident.core.compiled_cache import cached_njit\n', 'cached_njit()')}
_RUN = ('import sys\n'
        'from auv_ident.core import compiled_cache\n'
        'if sys.argv[1] == "group":\n'
        '    compiled_cache.register(sys.argv[2], ("callee.py", "caller.py"))\n'
        'from pkg.caller import f\n'
        'print(f(1), sum(f.stats.cache_hits.values()))\n')


@pytest.mark.slow      # six fresh processes, each compiling with numba
def test_a_cached_caller_is_recompiled_when_only_its_callee_file_changes(tmp_path):
    """End to end in fresh processes: numba alone keeps running a cached caller with its old
    callee after an edit of the callee's file (the problem); with the file pair registered as a
    group and compiled by cached_njit, the edit is seen, unchanged code still loads from the
    cache, and nothing is written beside the sources."""
    pkg = tmp_path / 'pkg'
    pkg.mkdir()
    (pkg / '__init__.py').write_text('')
    repo = pathlib.Path(core.__file__).parents[2]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), str(repo)]),
               XDG_CACHE_HOME=str(tmp_path / 'cache'), PYTHONDONTWRITEBYTECODE='1')
    env.pop('NUMBA_CACHE_DIR', None)

    def run(mode, increment):
        head, deco = _HEADS[mode]
        (pkg / 'caller.py').write_text(_CALLER.format(head=head, deco=deco))
        (pkg / 'callee.py').write_text(_CALLEE.format(head=head, deco=deco,
                                                      increment=increment))
        r = subprocess.run([sys.executable, '-c', _RUN, mode, str(pkg)], capture_output=True,
                           text=True, env=env, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        value, hits = r.stdout.split()
        return int(value), int(hits)
    assert run('numba', 1) == (2, 0)
    assert run('numba', 2)[0] == 2                 # stale: the old callee still runs
    shutil.rmtree(pkg / '__pycache__')
    assert run('group', 1) == (2, 0)               # compiled and cached
    assert run('group', 1) == (2, 1)               # unchanged: from the cache
    assert run('group', 2) == (3, 0)               # callee edited: recompiled
    assert run('group', 2) == (3, 1)
    assert sorted(p.name for p in pkg.iterdir()) == ['__init__.py', 'callee.py', 'caller.py']
    groups = list((tmp_path / 'cache' / 'auv_ident' / 'numba').iterdir())
    assert len(groups) == 2 and all(list(g.rglob('caller.f-*.nbi')) for g in groups)


def per_message_and_loop(m, run):
    """(g, f): the filter of model m over a simulated run stepped message by message
    (AugmentedEKF.step, the live node's way) and run by the compiled loop (run_ekf), both from
    the file's values +50 %."""
    cfg = FilterConfig(coefficients=m.theta_names, initial_offset=0.5)
    f = AugmentedEKF(m, cfg, run.T)
    run_ekf(f, [Record(run.t, run.y, run.u)])
    g = AugmentedEKF(m, cfg, run.T)
    g.start(run.y[0], run.u[0, 5])
    for k in range(1, len(run.t)):
        g.step(run.u[k - 1], run.y[k])
    return g, f


def test_workspace_reuse_gives_the_same_filter_as_fresh_scratch():
    """The per-message API (one Workspace reused by every step) and the compiled loop (its own
    Workspace) run the same filter: same estimates to rounding."""
    v = load_vehicle('nps_auv2')
    names = list(v.identify_default)
    truth = Model(v)
    run = simulate(truth, 'ident', duration=20.0, seed=5)
    g, f = per_message_and_loop(Model(v, names), run)
    np.testing.assert_allclose(g.xa, f.xa, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(g.P, f.P, rtol=1e-7, atol=1e-15)
