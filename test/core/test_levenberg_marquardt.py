"""The Levenberg-Marquardt on chunked normal equations
(core/identification/levenberg_marquardt.py): MINPACK lmder's iteration on J^T J and J^T r,
checked against scipy's least_squares(method='lm') (lmder itself) on known problems, and its
forward differences built a chunk at a time, never the whole Jacobian."""
import tracemalloc

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.optimize._numdiff import approx_derivative

from auv_ident.core.identification.levenberg_marquardt import (
    ChunkedForwardDifferences,
    levenberg_marquardt,
)

T = np.linspace(0.0, 4.0, 200)
Y = (2.5 * np.exp(-1.3 * T) + 0.5 * np.sin(3.0 * T)
     + 0.01 * np.random.default_rng(0).standard_normal(T.size))


def exp_sine(x):
    """Residuals (200,) of a decaying exponential plus a sine fitted to noisy data."""
    return x[0] * np.exp(-x[1] * T) + x[2] * np.sin(x[3] * T) - Y


def exp_sine_jac(x):
    e = np.exp(-x[1] * T)
    return np.column_stack([e, -x[0] * T * e, np.sin(x[3] * T), x[2] * T * np.cos(x[3] * T)])


def rosenbrock(x):
    return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])


def rosenbrock_jac(x):
    return np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])


def meyer(x):
    """MINPACK's test problem 10 (Meyer's thermistor): badly scaled, 16 residuals, 3 unknowns."""
    t = 45.0 + 5.0 * np.arange(1, 17)
    y = np.array([34780, 28610, 23650, 19630, 16370, 13720, 11540, 9744, 8261, 7030, 6005, 5147,
                  4427, 3820, 3307, 2872], dtype=float)
    return x[0] * np.exp(x[1] / (t + x[2])) - y


def meyer_jac(x):
    t = 45.0 + 5.0 * np.arange(1, 17)
    e = np.exp(x[1] / (t + x[2]))
    return np.column_stack([e, x[0] * e / (t + x[2]), -x[0] * x[1] * e / (t + x[2]) ** 2])


def normal(fun, jac):
    def equations(x):
        J = jac(x)
        return J.T @ J, J.T @ fun(x)
    return equations


# (residuals, Jacobian, start, whether the path is lmder's to the end: Rosenbrock's residuals
# reach 0, where the last steps are decided by the rounding of J^T J against that of a QR)
PROBLEMS = [(exp_sine, exp_sine_jac, [1.0, 1.0, 1.0, 2.8], True),
            (rosenbrock, rosenbrock_jac, [-1.2, 1.0], False),
            (meyer, meyer_jac, [0.02, 4000.0, 250.0], True)]


@pytest.mark.parametrize('scaling', ['marquardt', 'fixed'])
@pytest.mark.parametrize('fun,jac,x0,exact', PROBLEMS, ids=['exp_sine', 'rosenbrock', 'meyer'])
def test_it_takes_minpacks_steps(fun, jac, x0, exact, scaling):
    """The same iterates as lmder: the solution, the evaluations, the Jacobians and the status
    of least_squares(method='lm') with the exact Jacobian (Marquardt's scaling: x_scale='jac';
    fixed: x_scale=1); on a zero-residual problem the same solution."""
    x0 = np.array(x0)
    ref = least_squares(fun, x0, jac=jac, method='lm', max_nfev=2000,
                        x_scale='jac' if scaling == 'marquardt' else 1.0)
    ours = levenberg_marquardt(lambda x: float(np.linalg.norm(fun(x))), normal(fun, jac), x0,
                               2000, diag=None if scaling == 'marquardt' else np.ones(x0.size))
    assert ref.status > 0 and ours.status > 0
    assert np.allclose(ours.x, ref.x, rtol=1e-8, atol=0)
    if not exact:
        assert ours.cost < 1e-20 and ref.cost < 1e-20
        return
    assert ours.cost == pytest.approx(ref.cost, rel=1e-10)
    # the status may differ where both ftol and xtol are met within rounding of one of them
    assert (ours.nfev, ours.njev) == (ref.nfev, ref.njev)


def test_the_evaluation_limit_ends_the_fit():
    ours = levenberg_marquardt(lambda x: float(np.linalg.norm(meyer(x))),
                               normal(meyer, meyer_jac), np.array([0.02, 4000.0, 250.0]), 5)
    ref = least_squares(meyer, [0.02, 4000.0, 250.0], jac=meyer_jac, method='lm', max_nfev=5,
                        x_scale='jac')
    assert ours.status == ref.status == 0 and ours.nfev == ref.nfev == 5
    assert np.allclose(ours.x, ref.x, rtol=1e-8, atol=0)


def test_a_zero_residual_ends_at_the_start():
    """r = 0 at x0: the gradient test stops it at once, as lmder does (status 1)."""
    fun = lambda x: np.array([x[0] - 1.0, 2.0 * (x[1] + 3.0)])      # noqa: E731
    jac = lambda x: np.array([[1.0, 0.0], [0.0, 2.0]])              # noqa: E731
    ours = levenberg_marquardt(lambda x: float(np.linalg.norm(fun(x))), normal(fun, jac),
                               np.array([1.0, -3.0]), 100)
    assert ours.status == 1 and ours.cost == 0.0 and ours.nfev == 1


def test_a_bad_fixed_scaling_is_refused():
    with pytest.raises(ValueError, match='positive'):
        levenberg_marquardt(lambda x: 1.0, normal(rosenbrock, rosenbrock_jac),
                            np.zeros(2), 10, diag=np.array([1.0, 0.0]))


M_GROUPS, GROUP = 20_000, 12          # 240 000 residuals in groups of 12 rows


X_TRUE = np.array([0.7, -1.3, 0.5, 2.0])


def _linear_problem(p=4):
    rng = np.random.default_rng(2)
    B = 0.3 * rng.standard_normal((GROUP, p))
    phase = rng.uniform(0, 2 * np.pi, M_GROUPS * GROUP)
    noise = 0.1 * rng.standard_normal(M_GROUPS * GROUP)

    def rows(x, a, b):
        """Residuals a..b of sin(phase + B x) - sin(phase + B x_true) + noise (B repeated
        over the groups of 12 rows)."""
        n = (b - a) // GROUP
        return (np.sin(phase[a:b] + np.tile(B @ x, n))
                - np.sin(phase[a:b] + np.tile(B @ X_TRUE, n)) + noise[a:b])

    return rows, p


def _chunked(rows, chunk_groups, calls=None):
    n = M_GROUPS * GROUP

    def stream(x):
        for a in range(0, n, chunk_groups * GROUP):
            if calls is not None:
                calls.append(a)
            yield rows(x, a, min(n, a + chunk_groups * GROUP))

    return ChunkedForwardDifferences(lambda x: rows(x, 0, n), stream, GROUP, 1e-5)


def test_chunked_sums_are_the_forward_difference_jacobians():
    """J^T J, J^T r and the per-group scores J_k^T r_k built chunk by chunk are those of
    scipy's 2-point Jacobian (the same steps: approx_derivative's rel_step rule, a zero
    parameter getting sqrt(eps))."""
    rows, p = _linear_problem()
    n = M_GROUPS * GROUP
    x = np.array([0.7, -1.3, 0.0, 2.0])
    J = approx_derivative(lambda z: rows(z, 0, n), x, method='2-point', rel_step=1e-5)
    r = rows(x, 0, n)
    fd = _chunked(rows, 999)                # chunks that do not divide the groups evenly
    A, g = fd.normal_equations(x)
    assert np.allclose(A, J.T @ J, rtol=1e-12, atol=0)
    assert np.allclose(g, J.T @ r, rtol=1e-10, atol=1e-10 * np.abs(J.T @ r).max())
    scores = np.einsum('kmp,km->kp', J.reshape(-1, GROUP, p), r.reshape(-1, GROUP))
    assert np.allclose(fd.scores, scores, rtol=1e-12, atol=1e-15)
    assert fd.base is not None and np.array_equal(fd.base[1], r)


def test_the_chunk_bounds_the_memory():
    """The largest arrays of a chunked Jacobian are a chunk's (tracemalloc): 240 000 residuals,
    p = 4 (a whole Jacobian is 7.7 MB) in chunks of 100 groups: the peak is the scores
    (N / 12, p: a twelfth of the Jacobian) and chunk-sized pieces, 0.11 of the Jacobian
    measured; with one chunk of everything it is above a Jacobian."""
    rows, p = _linear_problem()
    x = np.array([0.7, -1.3, 0.5, 2.0])
    jacobian_bytes = M_GROUPS * GROUP * p * 8
    for chunk, most in ((100, 0.15), (M_GROUPS, None)):
        fd = _chunked(rows, chunk)
        fd.norm(x)
        tracemalloc.start()
        try:
            fd.normal_equations(x)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        if most is not None:
            assert peak < most * jacobian_bytes, peak / jacobian_bytes
        else:       # the check can see a whole Jacobian
            assert peak > jacobian_bytes, peak / jacobian_bytes


def test_a_failed_column_counts_as_the_failure_value():
    """A perturbed point whose stream fails part-way (None) is a column of (fail - r) / h
    throughout, as a failed whole evaluation filled with `fail` would give."""
    rows, p = _linear_problem()
    n = M_GROUPS * GROUP
    x = np.array([0.7, -1.3, 0.5, 2.0])

    def stream(z):
        for a in range(0, n, 1200):
            if z[2] != x[2] and a >= 6000:
                yield None          # the model fails in the 6th chunk at this column's step
                return
            yield rows(z, a, min(n, a + 1200))

    fd = ChunkedForwardDifferences(lambda z: rows(z, 0, n), stream, GROUP, 1e-5, fail=1e3)
    A, g = fd.normal_equations(x)
    J = approx_derivative(lambda z: rows(z, 0, n), x, method='2-point', rel_step=1e-5)
    h = (x[2] + 1e-5 * x[2]) - x[2]
    J[:, 2] = (1e3 - rows(x, 0, n)) / h
    assert np.allclose(A, J.T @ J, rtol=1e-12, atol=0)


def test_it_fits_from_chunks():
    """The solver on chunked forward differences finds least_squares' solution."""
    rows, p = _linear_problem()
    n = M_GROUPS * GROUP
    fd = _chunked(rows, 1000)
    x0 = X_TRUE + np.array([0.3, -0.2, 0.4, 0.3])
    ours = levenberg_marquardt(fd.norm, fd.normal_equations, x0, 100, diag=np.ones(p))
    ref = least_squares(lambda z: rows(z, 0, n), x0, method='lm', diff_step=1e-5,
                        x_scale=1.0)
    assert ours.status > 0 and ref.status > 0
    assert np.allclose(ours.x, ref.x, rtol=1e-7, atol=0)
    assert np.allclose(ours.x, X_TRUE, atol=0.01)
