"""core.simulation.zigzag, core.simulation.steering, core.identification.thrust_fit,
core.simulation.zigzag_sim, core.simulation.nomoto against hand
computations and independent integrations: IMO overshoots of a heading with known extremes, a
steering gear recovered from a rudder made by a fine Euler integration of the servo, a thrust
model recovered from exact data, the closed-loop zig-zag of a first-order Nomoto model against
its closed-form solution and against scipy's DOP853 with events, and a Nomoto model recovered
from its own simulated zig-zags."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from auv_ident.core.errors import ConfigError, DataError, DomainError
from auv_ident.core.identification.thrust_fit import fit_thrust_model, SPEED_TERMS
from auv_ident.core.model.state import Input, State
from auv_ident.core.simulation.nomoto import fit_nomoto, NomotoModel
from auv_ident.core.simulation.steering import identify_steering_gear, SteeringGear
from auv_ident.core.simulation.zigzag import (
    MAX_REVERSAL_LAG_S,
    zigzag_measures,
    zigzag_problem,
)
from auv_ident.core.simulation.zigzag_sim import simulate_zigzag

DEG = np.pi / 180.0
DT = 0.05                   # s, the 20 Hz of the basin's files
OMEGA = 2 * np.pi / 60.0    # rad/s: a 60 s heading cycle
AMPS = [14.0, 17.5, 16.0, 15.2]   # deg, the heading's extreme in each half-cycle
T_EXEC = 2.0                # s, first execute (the heading starts turning there)


def synthetic_heading(t):
    """psi (deg): half-sines of amplitude AMPS[k] and alternating sign from T_EXEC, 0 before.
    Extremes: +-AMPS[k] at T_EXEC + (k + 1/2) pi / OMEGA; passes +-10 deg at
    T_EXEC + (k pi + asin(10 / A_k)) / OMEGA."""
    s = np.clip(t - T_EXEC, 0.0, None)
    k = np.floor(s * OMEGA / np.pi).astype(int)
    a = np.array(AMPS)[np.minimum(k, len(AMPS) - 1)]
    return a * np.sin(OMEGA * s)   # the sign alternates with the sine itself


def ramp_rudder(t, orders, rate_deg_s, delay):
    """delta (deg): 0, then to each ordered angle at rate_deg_s after its order + delay."""
    d = np.zeros_like(t)
    for t_o, angle in orders:
        t_s = t_o + delay
        for i in np.flatnonzero(t > t_s):
            prev = d[i - 1] if i else 0.0
            step = rate_deg_s * min(t[i] - t_s, t[i] - t[i - 1])
            d[i] = prev + np.clip(angle - prev, -step, step)
    return d


def test_overshoots_of_a_known_heading():
    t = np.arange(0.0, 125.0, DT)
    psi = synthetic_heading(t)
    checks = [T_EXEC + (k * np.pi + np.arcsin(10.0 / a)) / OMEGA for k, a in enumerate(AMPS)]
    orders = [(T_EXEC, -20.0)] + [(tc, 20.0 * (-1) ** k) for k, tc in enumerate(checks)]
    delta = ramp_rudder(t, orders, 15.0, 0.2)
    m = zigzag_measures(t, psi * DEG, delta * DEG, execute_time=T_EXEC)
    assert m.label == '20/10' and m.first == 'starboard'
    assert m.rudder_deg == pytest.approx(20.0)
    assert m.check_times == pytest.approx(checks, abs=2e-3)
    # the last half-cycle ends with the run: its extreme is complete only if the heading came
    # back; here it does (125 s > 2 + 3.5 x 30 s)
    assert m.overshoots_deg == pytest.approx([a - 10.0 for a in AMPS], abs=2e-3)
    peaks = [T_EXEC + (k + 0.5) * np.pi / OMEGA for k in range(len(AMPS))]
    assert m.times_to_overshoot == pytest.approx(np.subtract(peaks, checks), abs=0.02)
    assert m.initial_turning_time == pytest.approx(checks[0] - T_EXEC, abs=2e-3)
    assert m.period == pytest.approx(np.mean(np.subtract(checks[2:], checks[:-2])), abs=2e-3)
    # the switch angle from the rudder onsets: the heading 0.2 s after the crossing, less
    # than one sample's heading change above the ordered 10 deg
    assert 10.0 < m.switch_deg < 10.0 + 0.25 * 2 * np.pi * 17.5 / 60 + 0.1
    # mirrored: port first, the same magnitudes
    p = zigzag_measures(t, -psi * DEG, -delta * DEG, execute_time=T_EXEC)
    assert p.first == 'port' and p.label == '20/10'
    assert p.overshoots_deg == pytest.approx(m.overshoots_deg, abs=1e-9)
    # without the execute time: the rudder's first motion, 0.2 s after the order
    d = zigzag_measures(t, psi * DEG, delta * DEG)
    assert d.execute_time == pytest.approx(T_EXEC + 0.2, abs=DT)


def test_noisy_records_give_the_same_test_and_gear():
    """Sensor noise (rudder 0.1 deg, heading 0.02 deg, white) must not make reversals of the
    noise about zero, nor hide the holds (the rudder rate is read over 0.5 s)."""
    t = np.arange(0.0, 125.0, DT)
    psi = synthetic_heading(t)
    checks = [T_EXEC + (k * np.pi + np.arcsin(10.0 / a)) / OMEGA for k, a in enumerate(AMPS)]
    orders = [(T_EXEC - 1.0, -20.0)] + [(tc, 20.0 * (-1) ** k) for k, tc in enumerate(checks)]
    delta = ramp_rudder(t, orders, 15.0, 0.2)
    rng = np.random.default_rng(11)
    for _ in range(3):
        run = (t, (psi + rng.normal(0.0, 0.02, len(t))) * DEG,
               (delta + rng.normal(0.0, 0.1, len(t))) * DEG)
        m = zigzag_measures(*run)
        assert m.label == '20/10' and len(m.rudder_onsets) == len(AMPS)
        assert m.overshoots_deg == pytest.approx([a - 10.0 for a in AMPS], abs=0.15)
        g = identify_steering_gear([run]).gear
        assert g.delay == pytest.approx(0.2, abs=0.03)
        assert g.rate_deg_s == pytest.approx(15.0, rel=0.01)


def test_an_overshoot_cut_by_the_end_of_the_run_is_not_reported():
    t = np.arange(0.0, T_EXEC + 1.5 * np.pi / OMEGA, DT)     # ends at the second extreme
    psi = synthetic_heading(t)
    checks = [T_EXEC + (k * np.pi + np.arcsin(10.0 / a)) / OMEGA for k, a in enumerate(AMPS)]
    orders = [(T_EXEC, -20.0)] + [(tc, 20.0 * (-1) ** k) for k, tc in enumerate(checks)
                                  if tc < t[-1]]
    m = zigzag_measures(t, psi * DEG, ramp_rudder(t, orders, 15.0, 0.2) * DEG)
    assert len(m.overshoots_deg) == 1 and np.isnan(m.second_overshoot_deg)
    assert np.isnan(m.period)


def test_measures_reject_bad_series():
    t = np.arange(0.0, 10.0, DT)
    with pytest.raises(DataError, match='never holds a deflection|never moves'):
        zigzag_measures(t, np.zeros_like(t), np.zeros_like(t))
    with pytest.raises(DataError, match='strictly increasing'):
        zigzag_measures(t[::-1], np.zeros_like(t), np.zeros_like(t))
    with pytest.raises(DataError, match='delta has shape'):
        zigzag_measures(t, np.zeros_like(t), np.zeros(3))
    bad = np.zeros_like(t)
    bad[4] = np.nan
    with pytest.raises(DataError, match='psi holds NaN/Inf at sample 4'):
        zigzag_measures(t, bad, np.zeros_like(t))


def euler_servo(t_fine, orders, delay, rate, tc):
    """Rudder (deg) of d(delta)/dt = sat((delta_c(t - delay) - delta) / tc, rate) by forward
    Euler on the fine grid t_fine, independently of SteeringGear.response."""
    d = np.zeros_like(t_fine)
    h = t_fine[1] - t_fine[0]
    for i in range(1, len(t_fine)):
        cmd = 0.0
        for t_o, angle in orders:
            if t_fine[i - 1] >= t_o + delay:
                cmd = angle
        d[i] = d[i - 1] + h * np.clip((cmd - d[i - 1]) / tc, -rate, rate)
    return d


def test_steering_gear_recovers_a_known_servo():
    delay, rate, tc = 0.30, 14.0, 0.20
    t_fine = np.arange(0.0, 125.0, 1e-3)
    checks = [T_EXEC + (k * np.pi + np.arcsin(10.0 / a)) / OMEGA for k, a in enumerate(AMPS)]
    # the first order before the heading moves (as on a ship, whose heading lags the rudder):
    # the execute detected from the rudder then finds the initial heading 0
    orders = [(T_EXEC - 1.5, -20.0)] + [(c, 20.0 * (-1) ** k) for k, c in enumerate(checks)]
    d_fine = euler_servo(t_fine, orders, delay, rate, tc)
    t = np.arange(0.0, 125.0, DT)
    delta = np.interp(t, t_fine, d_fine)
    delta = np.round(delta / 0.0122) * 0.0122          # the basin's rudder quantisation
    ident = identify_steering_gear([(t, synthetic_heading(t) * DEG, delta * DEG)])
    g = ident.gear
    assert len(ident.reversals) == len(AMPS)
    assert g.delay == pytest.approx(delay, abs=0.01)
    assert g.rate_deg_s == pytest.approx(rate, rel=0.02)
    assert g.time_constant == pytest.approx(tc, abs=0.02)
    assert ident.rms_deg < 0.05
    # the onset (the last sample the rudder holds its angle) lies within a sample before the
    # servo starts
    assert delay - DT - 0.005 <= ident.summary['onset_delay'][0] <= delay + 0.005
    # the closed form of the fitted gear matches the fine integration
    resp = g.response(t_fine - (checks[0] + g.delay), 20.0 * DEG, -20.0 * DEG)
    w = (t_fine > checks[0]) & (t_fine < checks[1])
    assert np.max(np.abs(-resp[w] / DEG - d_fine[w])) < 0.15


def test_steering_gear_rejects_bad_values():
    with pytest.raises(ConfigError, match='delay'):
        SteeringGear(delay=-0.1, rate=0.2)
    with pytest.raises(ConfigError, match='rate'):
        SteeringGear(delay=0.1, rate=0.0)
    with pytest.raises(DataError, match='no complete rudder reversal|never reversed'):
        t = np.arange(0, 20, DT)
        identify_steering_gear([(t, synthetic_heading(t) * DEG,
                                 ramp_rudder(t, [(1.0, -20.0)], 15, 0) * DEG)])


def test_thrust_model_recovers_known_coefficients():
    rng = np.random.default_rng(3)
    runs = []
    for _ in range(3):
        x = np.zeros((400, 12))
        x[:, State.U] = rng.uniform(0.8, 1.2, 400)
        x[:, State.V] = rng.uniform(-0.1, 0.1, 400)
        x[:, State.R] = rng.uniform(-0.05, 0.05, 400)
        thrust = 60 - 15 * x[:, 0] - 2 * x[:, 0] ** 2 + 30 * x[:, 1] + 40 * x[:, 5]
        runs.append((x, thrust))
    m = fit_thrust_model(runs)
    assert m.coefficients == pytest.approx([60, -15, -2, 30, 40], abs=1e-8)
    assert m.rms < 1e-9 and max(m.loro_rms) < 1e-9
    assert m(runs[0][0][0]) == pytest.approx(runs[0][1][0])
    only_u = fit_thrust_model(runs, SPEED_TERMS)
    assert only_u.rms > 0.5     # v and r carry part of it
    with pytest.raises(ConfigError, match='terms'):
        fit_thrust_model(runs, ('1', 'w'))
    x = runs[0][0].copy()
    x[:, State.V] = 0.0
    with pytest.raises(DataError, match='rank'):
        fit_thrust_model([(x, runs[0][1])])


# -- closed loop: a first-order Nomoto model, r_dot = (K delta - r) / T_N, psi_dot = r --------
K_N = -0.06     # 1/s: steady yaw rate per rad of rudder (delta > 0 to port turns to port)
T_N = 12.0      # s
U0 = 1.1        # m/s, held (the model holds every other state)


def nomoto(x, u):
    xd = np.zeros(12)
    xd[State.R] = (K_N * u[Input.DELTA_R] - x[State.R]) / T_N
    xd[State.PSI] = x[State.R]
    return xd


def nomoto_closed_form(rudder, switch, delay, t_exec, n_half):
    """Overshoots (deg) and check times (s) of the Nomoto model under an instant rudder with a
    dead time, from the exact solution of each constant-rudder segment:
    r(s) = K d + (r_a - K d) e^(-s/T), psi(s) = psi_a + K d s + (r_a - K d) T (1 - e^(-s/T))."""
    def seg(psi_a, r_a, d, s):
        e = np.exp(-s / T_N)
        return psi_a + K_N * d * s + (r_a - K_N * d) * T_N * (1 - e), K_N * d + (r_a - K_N * d) * e

    t_a, psi_a, r_a = t_exec + delay, 0.0, 0.0
    d = -rudder
    side, checks, overs = 1.0, [], []
    for _ in range(n_half):
        # heading passes side * switch: root of psi(s) - side * switch on this segment
        g = lambda s: side * seg(psi_a, r_a, d, s)[0] - switch     # noqa: E731
        s_c = brentq(g, 0.0, 200.0, xtol=1e-13)
        checks.append(t_a + s_c)
        s_new = s_c + delay           # the rudder reverses after the dead time
        psi_n, r_n = seg(psi_a, r_a, d, s_new)
        t_a, psi_a, r_a, d = t_a + s_new, psi_n, r_n, -d
        # the heading's extreme: r = 0 at s* = T ln((K d - r_a) / (K d))
        s_star = T_N * np.log((K_N * d - r_a) / (K_N * d))
        overs.append((side * seg(psi_a, r_a, d, s_star)[0] - switch) / DEG)
        side = -side
    return overs, checks


@pytest.mark.parametrize('delay', [0.0, 0.37])
def test_closed_loop_nomoto_matches_the_closed_form(delay):
    x0 = np.zeros(12)
    x0[State.U] = U0
    gear = SteeringGear(delay=delay, rate=np.inf)
    sim = simulate_zigzag(nomoto, x0, 20.0, 10.0, 150.0, gear, execute_time=1.0)
    overs, checks = nomoto_closed_form(20 * DEG, 10 * DEG, delay, 1.0, 4)
    m = sim.measures
    # the orders at the Hermite-interpolated crossings; the measures interpolate the 20 Hz
    # samples linearly
    assert [o[0] for o in sim.orders[1:5]] == pytest.approx(checks, abs=1e-6)
    assert m.check_times[:4] == pytest.approx(checks, abs=1e-4)
    assert m.overshoots_deg[:4] == pytest.approx(overs, abs=1e-4)
    assert np.all(sim.x[:, State.U] == U0)


def scipy_reference(gear, rudder, switch, t_exec, t_end):
    """Overshoots (deg) of the Nomoto model with a rate-limited servo from DOP853 with events:
    state [r, psi, delta], d(delta)/dt = sat((delta_c - delta) / T_s, R)."""
    R, Ts = gear.rate, gear.time_constant

    def rhs(t, y, cmd):
        return [(K_N * y[2] - y[0]) / T_N, y[0], np.clip((cmd - y[2]) / Ts, -R, R)]

    y, t, cmd, side, overs_side = np.zeros(3), 0.0, 0.0, 1.0, None
    changes = [(t_exec + gear.delay, -rudder)]
    overs = []
    while t < t_end:
        t_next = min([c[0] for c in changes] + [t_end])

        def cross(t, y, cmd):
            return side * y[1] - switch
        cross.terminal, cross.direction = True, 1

        def peak(t, y, cmd):     # the yaw rate through 0: a heading extreme
            return y[0]
        sol = solve_ivp(rhs, (t, t_next), y, method='DOP853', args=(cmd,), rtol=1e-11,
                        atol=1e-13, events=[cross, peak])
        for yp in sol.y_events[1]:
            # a heading extreme on the side of the last check: an overshoot
            if overs_side is not None:
                overs.append((overs_side * yp[1] - switch) / DEG)
        t, y = sol.t[-1], sol.y[:, -1]
        if sol.status == 1:          # the heading passed the switch angle
            changes.append((t + gear.delay, side * rudder))
            overs_side = side
            side = -side
            continue
        if changes and t >= changes[0][0] - 1e-12:
            cmd = changes.pop(0)[1]
    return overs


def test_closed_loop_with_a_rate_limited_gear_matches_dop853():
    gear = SteeringGear(delay=0.36, rate=15.7 * DEG, time_constant=0.15)
    x0 = np.zeros(12)
    x0[State.U] = U0
    sim = simulate_zigzag(nomoto, x0, 20.0, 10.0, 150.0, gear, execute_time=1.0)
    ref = scipy_reference(gear, 20 * DEG, 10 * DEG, 1.0, 150.0)
    n = min(len(ref), len(sim.measures.overshoots_deg))
    assert n >= 3
    assert sim.measures.overshoots_deg[:n] == pytest.approx(ref[:n], abs=2e-4)
    # the ideal helm turns back sooner: smaller overshoots than the real gear's
    ideal = simulate_zigzag(nomoto, x0, 20.0, 10.0, 150.0, SteeringGear.ideal(15.8),
                            execute_time=1.0)
    assert all(a < b for a, b in zip(ideal.measures.overshoots_deg,
                                     sim.measures.overshoots_deg))


def test_closed_loop_writes_the_thrust_and_checks_its_arguments():
    x0 = np.zeros(12)
    x0[State.U] = U0
    gear = SteeringGear.ideal(15.8)
    seen = []

    def f(x, u):
        seen.append(u[5])
        return nomoto(x, u)

    sim = simulate_zigzag(f, x0, 10.0, 10.0, 30.0, gear, thrust=lambda x: 40.0 + x[State.U],
                          thrust_index=5, first='port')
    assert np.all(np.array(seen) == 40.0 + U0) and np.all(sim.thrust == 40.0 + U0)
    assert sim.measures.first == 'port' and sim.rudder.max() == pytest.approx(10 * DEG)
    with pytest.raises(ConfigError, match='thrust_index'):
        simulate_zigzag(nomoto, x0, 10, 10, 30, gear, thrust=lambda x: 1.0)
    with pytest.raises(ConfigError, match='first'):
        simulate_zigzag(nomoto, x0, 10, 10, 30, gear, first='left')


def test_nomoto_fit_recovers_the_model_of_a_simulated_zigzag():
    truth = NomotoModel(K=-0.06, T=12.0, delta_0=0.01)
    x0 = np.zeros(12)
    x0[State.U] = U0
    runs = []
    for first in ('starboard', 'port'):
        sim = simulate_zigzag(truth.f, x0, 20.0, 10.0, 120.0, SteeringGear.ideal(15.8),
                              first=first, execute_time=1.0)
        runs.append((sim.t, sim.x[:, State.R], sim.rudder))
    fit = fit_nomoto(runs)
    # the fit holds the 20 Hz rudder samples (the simulation moves it in between): close, not
    # exact
    assert fit.K == pytest.approx(truth.K, rel=0.01)
    assert fit.T == pytest.approx(truth.T, rel=0.01)
    assert fit.delta_0 == pytest.approx(truth.delta_0, abs=2e-4)
    assert fit.rms_r < 1e-4
    with pytest.raises(DataError, match='Nomoto'):
        fit_nomoto([(np.arange(3.0), np.zeros(3), np.zeros(2))])


def test_a_model_leaving_its_domain_ends_the_run_early():
    def fragile(x, u):
        if x[State.PSI] < -12.0 * DEG:
            raise DomainError("heading beyond the model's data")
        return nomoto(x, u)

    x0 = np.zeros(12)
    x0[State.U] = U0
    sim = simulate_zigzag(fragile, x0, 20.0, 10.0, 150.0, SteeringGear.ideal(15.8))
    assert sim.stopped and 'beyond' in sim.stopped
    assert 20.0 < sim.t[-1] < 150.0 and len(sim.x) == len(sim.t) == len(sim.rudder)
    assert np.all(np.isfinite(sim.x)) and sim.x[-1, State.PSI] >= -12.0 * DEG
    # the overshoot after the first reversal was complete before the stop
    assert len(sim.measures.overshoots_deg) == 1
    # too short for the rudder to reach and hold its angle: series, no measures, and why
    short = simulate_zigzag(nomoto, x0, 20.0, 10.0, 1.0, SteeringGear.ideal(15.8))
    assert short.measures is None and 'no zig-zag measures' in short.stopped
    assert len(short.t) == 21


def helm_run(orders_by, duration=130.0, K=0.18, T=12.0, rate=15.0, dt=0.01, out_dt=0.05):
    """(t, psi, delta) at out_dt of a first-order Nomoto ship (T r' = -K delta - r, K 1/s,
    T s; delta positive to port turns it to port), its rudder moving at `rate` deg/s to the
    order, the first order -20 deg (to starboard) at T_EXEC. orders_by(k, t, dev_deg, side)
    -> True when the k-th reversal is ordered at time t, the heading deviation dev_deg from
    psi_0 and side (+1: the leg turns to starboard); the order then flips the rudder."""
    n = int(round(duration / dt))
    every = int(round(out_dt / dt))
    psi = r = delta = 0.0
    order, k, side = 0.0, 0, 1.0
    rec = []
    for i in range(n + 1):
        t = i * dt
        if i % every == 0:
            rec.append((t, psi, delta))
        if order == 0.0 and t >= T_EXEC:
            order = -20.0
        elif order != 0.0 and orders_by(k, t, np.rad2deg(psi), side):
            order, k, side = -order, k + 1, -side
        delta += float(np.clip(order - delta, -rate * dt, rate * dt))
        r += dt * (-K * np.deg2rad(delta) - r) / T
        psi += dt * r
    t, p, d = np.array(rec).T
    return t, p, np.deg2rad(d)


def test_a_helm_delay_is_a_lag_not_a_reason_to_refuse():
    """A helm that reverses the rudder 0.1-2.5 s after the heading passes 10 deg, at yaw rates
    of ~3 deg/s: reversals several degrees past the switch angle. Recognised as the 20/10
    zig-zag it is, each reversal's lag reported (deg and s); the old rule (reversal headings
    within 1 deg of their median) refused it."""
    delays = [0.1, 1.6, 0.4, 2.5, 1.0, 0.2]
    passed = {}

    def helm(k, t, dev, side):
        if k >= len(delays):
            return False
        if k not in passed and side * dev >= 10.0:
            passed[k] = t
        return k in passed and t >= passed[k] + delays[k]

    t, psi, delta = helm_run(helm, duration=190.0)
    m = zigzag_measures(t, psi, delta)
    assert zigzag_problem(m) is None
    assert m.label == '20/10' and m.first == 'starboard'
    assert len(m.rudder_onsets) == len(delays) and len(m.overshoots_deg) >= 5
    # the lag in time: the helm's delay, to the sample (the onset is the last 20 Hz sample
    # still at the held angle, up to one sample before the order)
    assert np.all(np.array(m.reversal_lag_s) >= np.array(delays) - 0.06)
    assert np.all(np.array(m.reversal_lag_s) <= np.array(delays) + 0.01)
    assert max(m.reversal_lag_s) < MAX_REVERSAL_LAG_S
    # in degrees: the yaw rate times the delay, several degrees at the slow reversals
    assert max(m.reversal_lag_deg) > 5.0 and min(m.reversal_lag_deg) < 0.6
    assert m.reversal_lag_deg == pytest.approx(np.array(m.onset_deviation_deg) - 10.0)
    # the measures use the ordered angle: the heading passes +-10 deg at the check times
    assert np.all(np.array(m.rudder_onsets) > np.array(m.check_times[:len(delays)]))
    spread = max(abs(np.array(m.onset_deviation_deg) - m.switch_deg))
    assert spread > 1.0      # what the previous rule refused


@pytest.mark.parametrize('times, why', [
    # legs of 16 s: the heading drifts to starboard, the second reversal comes with it still
    # there
    ([16.0 * (k + 1) for k in range(6)], 'towards the side it had turned to'),
    # a long first leg, then 24 s legs: the first reversal 6.6 s after the heading passed
    # the angle the others would make the switch angle
    ([12.0, 36.0, 60.0, 84.0, 108.0], 's after the heading deviation passed')])
def test_a_timed_rudder_sequence_is_told_apart(times, why):
    """Rudder reversals timed by a clock (at T_EXEC + times), not by the heading: refused,
    naming the reversal that came long after, or short of, the heading passing the switch
    angle."""
    def clock(k, t, dev, side):
        return k < len(times) and t >= T_EXEC + times[k]

    t, psi, delta = helm_run(clock, duration=130.0)
    m = zigzag_measures(t, psi, delta)
    problem = zigzag_problem(m)
    assert problem is not None and problem.endswith('a timed rudder sequence, not a zig-zag')
    assert why in problem and problem.startswith('reversal ')
