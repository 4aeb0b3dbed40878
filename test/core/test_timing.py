"""Tier 1: time is what the stamps say (core/filter/timing.py), in the batch methods and the
stream.

The records here are simulated NPS AUV II runs integrated at a fine step (5 ms) and sampled at
stamps of our own: jitter of +-10 % of the 50 ms sample time, 5 % of the samples dropped and a
2 s gap. The commands change only at sample stamps (the table of a manoeuvre file), so that
what is tested is the time handling, not the loss of a command change between two samples.
"""
import numpy as np
import pytest

from auv_ident.core.angles import wrap_angle
from auv_ident.core.errors import ConfigError, DataError
from auv_ident.core.filter.augmented import AugmentedEKF, FilterConfig
from auv_ident.core.filter.stream import StreamIdentifier
from auv_ident.core.filter.timing import (
    check_times,
    commands_at,
    DEFAULT_MAX_BRIDGE,
    nominal_sample_time,
    time_steps,
)
from auv_ident.core.identification.batch import identify, refine, run_ekf
from auv_ident.core.identification.results import Record
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.sensors import DEFAULT_NOISE_STD
from auv_ident.core.model.state import EULER, Input
from auv_ident.core.simulation import maneuvers
from auv_ident.core.simulation.simulate import simulate
from auv_ident.vehicles import load_vehicle

NPS = load_vehicle('nps_auv2')
NAMES = list(NPS.identify_default)
FINE = 0.005        # s, integration step of the truth
T = 0.05            # s, nominal sample time
DURATION = 120.0    # s
GAP = (60.0, 2.0)   # s, start and length of the gap


def _record(path, seed, jitter=False, drop=0.0, gap=None):
    """(t (N,), Y (N, 12), U (N, 7), X (N, 12) true states) of a run sampled at stamps on the
    fine grid: nominally every T, moved by one fine step (+-10 % of T) with `jitter`, a fraction
    `drop` of the samples and those in the gap (start, length) left out."""
    rng = np.random.default_rng(seed)
    n = int(round(DURATION / T)) + 1
    per = int(round(T / FINE))
    n_fine = (n - 1) * per + 1
    k = np.arange(n) * per
    if jitter:
        k[1:] = np.minimum(k[1:] + rng.integers(-1, 2, n - 1), n_fine - 1)
    keep = np.ones(n, dtype=bool)
    keep[1:] = rng.random(n - 1) >= drop
    if gap is not None:
        keep &= ~((k * FINE >= gap[0]) & (k * FINE < gap[0] + gap[1]))
    # the 'ident' commands of the nominal grid, one per sample, changing at the stamps only
    cmd = maneuvers.commands('ident', np.arange(n) * T, rpm=NPS.cruise_rpm, seed=seed)
    k, U = k[keep], cmd[keep]
    grid = np.arange(n_fine) * FINE          # the simulator's own grid (same floats)
    np.savetxt(path, np.column_stack([grid[k], U]), delimiter=',', fmt='%.17g', comments='',
               header='t,delta_r,delta_s,delta_b,delta_bp,delta_bs,n_rpm')
    run = simulate(Model(NPS), str(path), duration=(n - 1) * T, T=FINE, seed=seed,
                   rpm=NPS.cruise_rpm, noise_std=np.zeros(12))
    assert np.array_equal(run.u[k], U)
    X = run.x[k]
    Y = X + rng.normal(0.0, 1.0, X.shape) * DEFAULT_NOISE_STD
    Y[:, EULER] = wrap_angle(Y[:, EULER])
    return grid[k], Y, U, X


@pytest.fixture(scope='module')
def records(tmp_path_factory):
    d = tmp_path_factory.mktemp('records')
    return {'uniform': _record(d / 'uniform.csv', 3),
            'irregular': _record(d / 'irregular.csv', 3, jitter=True, drop=0.05, gap=GAP)}


def test_the_irregular_record_has_what_it_claims(records):
    t = records['irregular'][0]
    dt = np.diff(t)
    assert dt.min() == pytest.approx(0.04) and dt.max() >= GAP[1]
    assert np.count_nonzero((dt > 0.04 + 1e-9) & (dt < 0.06 - 1e-9)) > 0.3 * dt.size
    n, h = time_steps(t, T, DEFAULT_MAX_BRIDGE)
    assert np.count_nonzero(n[1:] == 0) == 1               # the gap restarts, once
    assert np.count_nonzero(n > 1) > 50                    # dropouts: several RK4 steps
    assert np.all(h[n > 0] <= T + 1e-12)
    assert nominal_sample_time(t) == 0.05


def test_irregular_stamps_identify_as_well_as_a_uniform_grid_with_honest_sigmas(records):
    """Jitter +-10 %, 5 % dropouts and a 2 s gap: the EKF pass and the refinement recover the
    coefficients with errors like the uniform grid's, and the truth within 3 sigma; the same
    samples taken as uniformly spaced (what the T path did) are far off."""
    m = Model(NPS, NAMES)
    cfg = FilterConfig(coefficients=NAMES)
    res = {}
    for name, (t, Y, U, _) in records.items():
        res[name] = r = identify(m, [Record(t, Y, U)], cfg, T=T, truth=m.theta_file)
        assert np.all(np.abs(r.estimate - r.truth) < 3.0 * r.std), (name, r.error_pct())
    # as precise as the uniform grid (7 % fewer samples, a gap), as accurate in absolute terms
    assert np.all(res['irregular'].std < 1.5 * res['uniform'].std)
    for which in ('estimate', 'ekf_estimate'):      # refined, and the EKF pass alone
        worst = {k: np.abs(r.error_pct(which)).max() for k, r in res.items()}
        assert max(worst.values()) < 3.0, (which, worst)
    t, Y, U, _ = records['irregular']
    naive = identify(m, [Record(np.arange(len(t)) * T, Y, U)], cfg, T=T, truth=m.theta_file)
    assert np.abs(naive.error_pct()).max() > 20.0 * np.abs(res['irregular'].error_pct()).max()


def test_a_uniform_grid_takes_the_old_fixed_T_path_bit_for_bit(records):
    """Stamps k T, built as float seconds or from integer nanoseconds, at any offset, give time
    updates of exactly T; the compiled loop then equals the per-message filter stepped with its
    fixed T (AugmentedEKF.step without a time, the path of fixed T), bit for bit."""
    for t in (np.arange(2401) * T, np.arange(2401) * 50_000_000 / 1e9,
              (10**12 + np.arange(2401) * 50_000_000) / 1e9):
        n, h = time_steps(t, T, DEFAULT_MAX_BRIDGE)
        assert np.all(n[1:] == 1) and np.all(h[1:] == T)
    t, Y, U, _ = records['uniform']
    m = Model(NPS, NAMES)
    cfg = FilterConfig(coefficients=NAMES, mode='matching')
    f = AugmentedEKF(m, cfg, T)
    hist = run_ekf(f, [Record(t + 1000.0, Y, U)], hist_every=100).history
    assert np.allclose(hist['t'], t[::100], rtol=0.0, atol=1e-9)      # since the first sample
    g = AugmentedEKF(m, cfg, T)
    g.start(Y[0], U[0, Input.N_RPM])
    for k in range(1, len(t)):
        g.step(U[k - 1], Y[k])
    assert np.array_equal(f.xa, g.xa) and np.array_equal(f.P, g.P)
    assert np.array_equal(f.Q, g.Q) and np.array_equal(f.R, g.R)


def _stream(t, Y, U, order='command first', every_sample=True, max_command_age=None):
    """A StreamIdentifier fed the record; commands at every sample or only when they change,
    each before or after the odometry of its stamp."""
    s = StreamIdentifier(Model(NPS, NAMES), FilterConfig(coefficients=NAMES), T,
                         max_command_age=max_command_age)
    outs = []
    for k in range(len(t)):
        send = every_sample or k == 0 or not np.array_equal(U[k], U[k - 1])
        if send and (order == 'command first' or k == 0):
            s.add_command(t[k], U[k])
        outs.append(s.add_measurement(t[k], Y[k]))
        if send and order == 'odometry first' and k > 0:
            s.add_command(t[k], U[k])
    return s, outs


def test_the_stream_and_the_batch_pass_apply_one_time_rule(records):
    """On the irregular record (jitter, dropouts, a gap) the streaming identifier and the
    compiled loop give the same filter bit for bit; a command arriving after the odometry of
    its own stamp is paired by its stamp (same result)."""
    t, Y, U, _ = records['irregular']
    f = AugmentedEKF(Model(NPS, NAMES), FilterConfig(coefficients=NAMES), T)
    run_ekf(f, [Record(t, Y, U)])
    for order in ('command first', 'odometry first'):
        s, outs = _stream(t, Y, U, order)
        assert s.rejected == 0 and [o.code for o in outs].count('gap') == 1
        assert np.array_equal(s.ekf.xa, f.xa) and np.array_equal(s.ekf.P, f.P), order


def test_commands_sent_only_on_change_are_held(records):
    """A command published only when it changes (the rudder is held for 20-40 s) gives the
    estimate of commands at every sample, in the stream and, through commands_at, in the batch
    pass; with max_command_age set the held commands become 'stale command'."""
    t, Y, U, _ = records['irregular']
    every, _ = _stream(t, Y, U)
    on_change, outs = _stream(t, Y, U, every_sample=False)
    assert on_change.rejected == 0
    assert np.array_equal(on_change.ekf.xa, every.ekf.xa)
    sent = np.concatenate([[True], np.any(U[1:] != U[:-1], axis=1)])
    assert sent.sum() < 0.8 * len(t)
    U_held = commands_at(t[sent], U[sent], t)
    assert np.array_equal(U_held, U)
    _, outs = _stream(t, Y, U, every_sample=False, max_command_age=1.0)
    assert 'stale command' in {o.code for o in outs}
    with pytest.raises(ConfigError, match='max_command_age = -1'):
        _stream(t[:2], Y[:2], U[:2], max_command_age=-1.0)


def test_refine_uses_the_stamps(records):
    """The refinement alone, started 5 % off, on the irregular record: the truth within 3
    sigma and a cost per residual near 1 (white innovations of unit variance); with the samples
    taken as uniformly spaced it cannot fit (a cost several times larger)."""
    t, Y, U, _ = records['irregular']
    m = Model(NPS, NAMES)
    cfg = FilterConfig(coefficients=NAMES)
    start = m.theta_file * 1.05
    ref = refine(m, cfg, [Record(t, Y, U)], start, T=T)
    assert np.all(np.abs(ref.estimate - m.theta_file) < 3.0 * np.sqrt(np.diag(ref.cov)))
    assert ref.cost < 1.5
    naive = refine(m, cfg, [Record(np.arange(len(t)) * T, Y, U)], start, T=T, max_nfev=5)
    assert naive.cost > 3.0 * ref.cost


@pytest.mark.parametrize('t,needle', [
    (np.array([0.0, 0.05, 0.05, 0.1]), r't\[2\] = 0.05 s is not after t\[1\]'),
    (np.array([0.0, 0.1, 0.05, 0.15]), r't\[2\] = 0.05 s is not after t\[1\] = 0.1 s'),
    (np.array([0.0, 0.05, np.nan, 0.15]), r't\[2\] = nan is not finite'),
    (np.zeros((4, 1)), r'must have shape \(4,\)'),
    (np.arange(3) * 0.05, r'must have shape \(4,\)'),
])
def test_bad_sample_times_are_one_clear_error(t, needle):
    f = AugmentedEKF(Model(NPS, NAMES), FilterConfig(coefficients=NAMES), T)
    Y = np.tile(np.r_[0.6, np.zeros(7), 10.0, 0.0, 0.0, 0.0], (4, 1))
    U = np.tile(np.r_[np.zeros(5), 500.0, 0.0], (4, 1))
    with pytest.raises(DataError, match=needle):
        run_ekf(f, [Record(t, Y, U)])


def test_check_times_and_nominal_sample_time():
    t = [0, 0.05, 0.1, 0.2, 0.25, 3]
    assert check_times(t).dtype == np.float64 and nominal_sample_time(t) == 0.05
    with pytest.raises(DataError, match='at least 2 samples'):
        nominal_sample_time([1.0])
    with pytest.raises(DataError, match='command stamps must not decrease'):
        commands_at([1.0, 0.0], np.zeros((2, 6)), [0.5])
    U = commands_at([0.0, 1.0, 1.0], np.arange(18.0).reshape(3, 6), [-1.0, 0.0, 0.5, 1.0, 9.0])
    assert np.all(np.isnan(U[0])) and U[1, 0] == 0.0 and U[2, 0] == 0.0
    assert U[3, 0] == 12.0 and U[4, 0] == 12.0          # same stamp: the later row wins
