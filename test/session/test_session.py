"""Tests of the session layer on its own: the array API against the message API, the screening
functions, the guard and health windows, and parameter validation (no ROS graph)."""
from collections import deque
import math
import random
from types import SimpleNamespace

import numpy as np
import pytest

from auv_ident.core.filter.ekf import MODES
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import Input, State, STATE_NAMES
from auv_ident.core.model.vehicle import P_FIN, P_NMAX
from auv_ident.core.simulation.simulate import simulate
from auv_ident.ros.sim_messages import ACTUATOR_TOPIC, sample_messages
from auv_ident.session import screening
from auv_ident.session.guard import (
    GUARD_FACTOR,
    GUARD_SECONDS,
    GUARD_WINDOW,
    GuardWindow,
    nis_band,
    NIS_WINDOW,
    NisWindow,
)
from auv_ident.session.guarded_filter import GuardedFilter
from auv_ident.session.messages import (
    ConversionError,
    joint_state_to_actuators,
    odometry_state,
    odometry_to_state,
    PublishGate,
    stamp_to_ns,
)
from auv_ident.session.session import IdentSession
from auv_ident.session.settings import (
    FRAMES,
    IdentifierSettings,
    MASS_INVERSES,
    NOISE_MODES,
    ParameterError,
)
from auv_ident.session.status import diagnostic_values, StampGaps
from auv_ident.vehicles import load_vehicle

T = 0.05
N = 300                     # samples of the short run (15 s)


@pytest.fixture(scope='module')
def run():
    return simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=N * T + 1.0, T=T,
                    seed=5)


def _messages(run, frame='ned'):
    return [(topic, msg) for k in range(N)
            for topic, _, msg in sample_messages(run, k, frame, with_truth=False)]


def _feed_messages(session, messages):
    return [session.on_actuators(m) if topic == ACTUATOR_TOPIC else session.on_odom(m)
            for topic, m in messages]


def _feed_arrays(session, messages, frame='ned'):
    """The same messages read by the caller and given to the array API."""
    events = []
    for topic, m in messages:
        stamp_ns = stamp_to_ns(m.header.stamp)
        if topic == ACTUATOR_TOPIC:
            events.append(session.add_command(stamp_ns, joint_state_to_actuators(m)[1]))
        else:
            _, x12, _, _ = odometry_to_state(m, frame)
            events.append(session.add_odometry(stamp_ns, x12, m.header.frame_id,
                                               m.child_frame_id))
    return events


def _assert_same_events(a, b):
    assert len(a) == len(b)
    for i, (x, y) in enumerate(zip(a, b)):
        assert (x.kind, x.reason, x.code, x.good, x.stamp_ns, x.dof) == \
            (y.kind, y.reason, y.code, y.good, y.stamp_ns, y.dof), i
        assert x.nis == y.nis or (math.isnan(x.nis) and math.isnan(y.nis)), i
        for field in ('estimate', 'std', 'cov'):
            u, v = getattr(x, field), getattr(y, field)
            assert (u is None and v is None) or np.array_equal(u, v), (i, field)


def _corrupted(run):
    """A clean run with a NaN, an implausible speed, a duplicate, a wrong frame id, degrees
    on the fins and an absurd burst (outliers, then a guard reset) in it."""
    msgs = _messages(run)
    odom = [i for i, (topic, _) in enumerate(msgs) if topic != ACTUATOR_TOPIC]
    msgs[odom[50]][1].twist.twist.linear.y = math.nan
    msgs[odom[60]][1].twist.twist.linear.x = 150.0
    msgs[odom[70]][1].header.frame_id = 'odom_enu'
    cmd = msgs[odom[80] - 1][1]
    cmd.position = [math.degrees(v) for v in cmd.position]
    msgs.insert(odom[90] + 1, msgs[odom[90]])                  # duplicate stamp
    for i in odom[150:190]:                                    # 2 s absurd burst
        msgs[i + 1][1].pose.pose.position.z += 50.0
    return msgs


@pytest.mark.parametrize('case', ['clean', 'corrupted'])
def test_array_api_gives_the_events_of_the_message_api(run, case):
    messages = _messages(run) if case == 'clean' else _corrupted(run)
    by_message, by_array = IdentSession(), IdentSession()
    a = _feed_messages(by_message, messages)
    b = _feed_arrays(by_array, messages)
    _assert_same_events(a, b)
    assert by_message.counters.reasons == by_array.counters.reasons
    if case == 'clean':
        assert not by_message.counters.reasons and all(e.accepted for e in a)
    else:
        assert {'odom: non-finite', 'odom: implausible', 'odom: wrong frame',
                'actuators: implausible', 'odom: duplicate stamp',
                'odom: outlier'} <= set(by_message.counters.reasons)
        assert by_message.counters.guard_resets >= 1
    assert by_message.document() == by_array.document()
    h1, h2 = by_message.health(), by_array.health()
    assert (h1.level, h1.message, h1.window) == (h2.level, h2.message, h2.window)


def test_array_api_takes_ned_arrays_whatever_the_frame_setting(run):
    """An 'enu' session reads ENU/FLU messages; its array API takes the NED/FRD state that
    odometry_to_state(msg, 'enu') returns, and gives the same events."""
    messages = _messages(run, 'enu')
    a = _feed_messages(IdentSession(IdentifierSettings.from_values(frame='enu')), messages)
    b = _feed_arrays(IdentSession(IdentifierSettings.from_values(frame='enu')), messages, 'enu')
    _assert_same_events(a, b)
    assert all(e.accepted for e in a)


def test_array_api_rejects_unreadable_arrays_by_name(run):
    s = IdentSession()
    ev = s.add_odometry(1.5, run.y[0])
    assert ev.kind == 'rejected' and ev.code == 'conversion' and ev.stamp_ns is None
    assert 'stamp_ns must be an integer' in ev.reason
    ev = s.add_odometry(10, run.y[0][:11])
    assert ev.code == 'conversion' and 'x12 must have shape (12,)' in ev.reason
    assert ev.stamp_ns == 10
    ev = s.add_command(np.int64(10), ['a'] * 6)
    assert ev.code == 'conversion' and 'u7 is not numeric' in ev.reason
    assert s.counters.reasons == {'odom: conversion': 2, 'actuators: conversion': 1}
    # numpy integer stamps and plain lists are taken
    assert s.add_command(np.int64(0), list(run.u[0])).kind == 'command'
    assert s.add_odometry(np.int64(0), list(run.y[0])).kind == 'update'


def test_array_api_copies_the_callers_arrays(run):
    """A caller may reuse its buffers: what the session keeps is its own copy."""
    reused, fresh = IdentSession(keep_arrays=True), IdentSession(keep_arrays=True)
    u, x = np.empty(7), np.empty(12)
    for k in range(40):
        stamp_ns = round(run.t[k] * 1e9)
        u[:] = run.u[k]
        x[:] = run.y[k]
        reused.add_command(stamp_ns, u)
        reused.add_odometry(stamp_ns, x)
        fresh.add_command(stamp_ns, run.u[k].copy())
        fresh.add_odometry(stamp_ns, run.y[k].copy())
    u[:] = math.nan
    x[:] = math.nan
    assert np.array_equal(reused.last_good.estimate, fresh.last_good.estimate)
    assert len(reused.commands) == len(fresh.commands) == 40
    assert np.array_equal(reused.commands.array, fresh.commands.array)
    assert np.array_equal(reused.measurements.array, fresh.measurements.array, equal_nan=True)


def test_session_odometry_reading_refuses_what_the_full_reader_refuses(run):
    """on_odom skips transforming the (unused) covariances but refuses the same messages."""
    msg = _messages(run)[1][1]
    for frame in FRAMES:
        t1, x1, _, _ = odometry_to_state(msg, frame)
        t2, x2 = odometry_state(msg, frame)
        assert t1 == t2 and np.array_equal(x1, x2)
    no_twist_cov = SimpleNamespace(header=msg.header, pose=msg.pose,
                                   twist=SimpleNamespace(twist=msg.twist.twist))
    short_pose_cov = SimpleNamespace(header=msg.header, twist=msg.twist,
                                     pose=SimpleNamespace(pose=msg.pose.pose,
                                                          covariance=[0.0] * 35))
    for reader in (odometry_to_state, odometry_state):
        with pytest.raises(ConversionError, match="no field 'twist.covariance'"):
            reader(no_twist_cov)
        with pytest.raises(ConversionError, match='pose.covariance must be 6x6 or 36 long'):
            reader(short_pose_cov, 'enu')
    s = IdentSession()
    ev = s.on_odom(short_pose_cov)
    assert ev.kind == 'rejected' and ev.code == 'conversion' and 'pose.covariance' in ev.reason


# --- screening, on its own ----------------------------------------------------------------


def test_frame_id_rule():
    assert screening.frame_problem('odom_ned', 'base_link_frd', 'ned') is None
    assert screening.frame_problem('odom', 'base_link', 'enu') is None
    assert screening.frame_problem('friend', 'menu_flux', 'ned') is None     # not tokens
    code, text = screening.frame_problem('odom_enu', 'base_link_FLU', 'ned')
    assert code == 'wrong frame' and 'name the ENU convention' in text
    assert "frame parameter is 'ned'" in text
    code, text = screening.frame_problem('odom_ned', 'base_link_flu', 'ned')
    assert code == 'wrong frame' and 'ENU/NED' in text
    code, text = screening.frame_problem('map', 'base_link', 'ned', ('odom', 'base_link'))
    assert code == 'frame changed' and "'odom' / 'base_link' of the first" in text
    assert screening.frame_problem('odom', 'base_link', 'ned', ('odom', 'base_link')) is None


def test_nonfinite_and_implausible_states_look_only_at_the_given_channels():
    x = [0.5, 0.0, 0.1, 0.01, 0.02, 0.03, 100.0, -50.0, 10.0, 0.1, -0.1, 3.0]
    everything = tuple(State)
    assert screening.nonfinite_states(x, everything) == []
    assert screening.implausible_states(x, everything) == ''
    y = list(x)
    y[State.V], y[State.PSI] = math.nan, math.inf
    assert screening.nonfinite_states(y, everything) == ['v', 'psi']
    assert screening.nonfinite_states(y, (State.U, State.W)) == []
    bounds = dict(zip(STATE_NAMES, screening.STATE_BOUNDS))
    for s in State:
        if math.isinf(bounds[s.name.lower()]):
            continue
        y = list(x)
        y[s] = -1.01 * bounds[s.name.lower()]
        text = screening.implausible_states(y, everything)
        assert text.startswith(f'implausible {s.name.lower()} = ') and 'wrong units' in text
        assert screening.implausible_states(y, tuple(c for c in State if c != s)) == ''
    y = list(x)
    y[State.PSI] = 1e9                     # yaw is not bounded (any number of turns)
    assert screening.implausible_states(y, everything) == ''
    y[State.U], y[State.Q] = 70.0, math.radians(20.0) * 57.3
    text = screening.implausible_states(y, everything)
    assert 'u = 70 m/s (|u| <= 10)' in text and 'q = ' in text and 'rad/s' in text


def test_command_problem_names_the_fin_or_the_shaft():
    v = load_vehicle('nps_auv2')
    fin, shaft = float(v.par[P_FIN]), float(v.par[P_NMAX])
    u = [0.1, -0.1, 0.0, 0.05, -0.05, 0.8 * shaft]
    assert screening.command_problem(u, 1.0, fin, shaft) is None
    bad = list(u)
    bad[Input.N_RPM] = math.nan
    code, text = screening.command_problem(bad, 1.0, fin, shaft)
    assert code == 'non-finite' and 'nan' in text and 'at 1.000000000 s' in text
    bad = list(u)
    bad[Input.DELTA_S] = math.degrees(0.3)
    code, text = screening.command_problem(bad, 1.0, fin, shaft)
    assert code == 'implausible' and 'stern_planes = 17.18' in text and 'rudder' not in text
    bad = list(u)
    bad[Input.DELTA_R] = 2.0 * fin           # at the bound: still plausible
    assert screening.command_problem(bad, 1.0, fin, shaft) is None
    bad[Input.N_RPM] = 2.01 * shaft
    code, text = screening.command_problem(bad, 1.0, fin, shaft)
    assert code == 'implausible' and 'shaft speed' in text and 'rpm' in text


# --- guard and health windows ---------------------------------------------------------------


def test_guard_window_median_is_numpy_median_of_the_window():
    rng = random.Random(1)
    w, ref = GuardWindow(), deque(maxlen=GUARD_WINDOW)
    assert math.isnan(w.median())
    for k in range(300):
        nis = rng.choice([rng.expovariate(1 / 12), 1e6 * rng.random(), math.inf, 12.0])
        dof = rng.choice([12, 9, 1])
        w.add(k * T, nis, dof)
        ref.append((nis if math.isfinite(nis) else 1e300) / dof)
        assert w.median() == float(np.median(list(ref)))
        assert len(w) == len(ref)
        assert w.inconsistent() == (len(ref) == GUARD_WINDOW
                                    and np.median(list(ref)) > GUARD_FACTOR)


def test_guard_window_reports_a_sustained_inconsistency_after_guard_seconds():
    w = GuardWindow()
    for k in range(GUARD_WINDOW):
        assert not w.add(k * T, 12.0, 12)
    steps = []
    for k in range(GUARD_WINDOW, 200):
        steps.append(w.add(k * T, 1e6, 12))
    first = GUARD_WINDOW + steps.index(True)
    # inconsistent once half the window is large (the median moved), sustained from
    # GUARD_SECONDS of stamps later on
    assert w.since == (GUARD_WINDOW + GUARD_WINDOW // 2 - 1) * T
    assert first * T - w.since >= GUARD_SECONDS > (first - 1) * T - w.since
    assert all(steps[first - GUARD_WINDOW:])
    w.clear()
    assert len(w) == 0 and w.since is None and math.isnan(w.median())


def test_nis_window_mean_is_the_correctly_rounded_sum_over_the_window():
    rng = random.Random(2)
    w, ref = NisWindow(), deque(maxlen=NIS_WINDOW)
    assert math.isnan(w.mean()) and math.isnan(w.band()[0])
    for k in range(1000):
        nis = rng.choice([rng.expovariate(1 / 12), 1e-300 * rng.random(), 5e-324,
                          1e12 * rng.random(), 0.0, 12.0])
        dof = rng.choice([12, 11, 3])
        w.add(nis, dof)
        ref.append((nis, dof))
        total, dof_sum = math.fsum(n for n, _ in ref), sum(d for _, d in ref)
        assert w.mean() == total / dof_sum and w.dof == dof_sum
        assert w.total() == total
    assert len(w) == NIS_WINDOW
    assert w.band() == nis_band(w.dof)
    w.clear()
    assert len(w) == 0 and w.dof == 0 and not w.gross()


def test_nis_band_brackets_one_and_narrows_with_dof():
    lo1, hi1 = nis_band(12)
    lo2, hi2 = nis_band(2400)
    assert lo1 < lo2 < 1.0 < hi2 < hi1


# --- the parts: one filter's update rule, the status ---------------------------------------


def test_the_session_updates_through_one_guarded_filter(run):
    """The session's per-odometry update is GuardedFilter.update (the rule the 'auto'
    choice's chosen filter follows too): a GuardedFilter of its own, fed the same samples
    after the session's screening, gives the same updates, last good estimate and windows."""
    s = IdentSession()
    g = GuardedFilter(s._new_stream(), s.guard_on)
    for k in range(120):
        stamp_ns = round(run.t[k] * 1e9)
        t = stamp_ns / 1e9                      # the session's time line: origin 0
        s.add_command(stamp_ns, run.u[k])
        g.stream.add_command(t, run.u[k].copy())
        ev = s.add_odometry(stamp_ns, run.y[k])
        step = g.update(t, stamp_ns, run.y[k].copy())
        assert (ev.kind == 'update') == step.accepted and ev.good == step.good, k
        assert np.array_equal(ev.estimate, step.estimate) and ev.nis == step.nis, k
    assert s.filter is not g and np.array_equal(s.last_good.cov, g.last_good.cov)
    assert s.filter.mean_nis_per_dof() == g.mean_nis_per_dof()
    assert s.filter.guard_median() == g.guard_median()


def test_without_filtering_every_wellformed_sample_is_kept_by_stamp(run):
    """filtering False (a validation's measured run): samples a filter's gate would reject as
    outliers are kept as the data are, in stamp order; malformed ones (non-finite) and a
    repeated stamp are still rejected, and counted."""
    def feed(s, y_of, order):
        events = []
        for k in order:
            stamp_ns = round(run.t[k] * 1e9)
            s.add_command(stamp_ns, run.u[k])
            events.append(s.add_odometry(stamp_ns, y_of(k)))
        return events

    def wild(k):
        y = run.y[k].copy()
        if k % 10 == 5:
            y[State.R] += 1.0           # rad/s: hundreds of noise sigmas, within plausibility
        if k == 33:
            y[State.U] = math.nan
        return y

    order = list(range(60))
    order[40], order[41] = order[41], order[40]      # two samples out of order
    gated = IdentSession(keep_arrays=True)
    feed(gated, wild, order)
    assert gated.counters.reasons['odom: outlier'] >= 3     # what the gate drops
    s = IdentSession(filtering=False)
    events = feed(s, wild, order)
    events.append(s.add_odometry(round(run.t[59] * 1e9), run.y[59]))     # stamp repeated
    assert {e.kind for e in events} == {'kept', 'rejected'}
    assert dict(s.counters.reasons) == {'odom: non-finite': 1, 'odom: duplicate stamp': 1}
    assert s.counters.odom_accepted == 59 and s.auto is None
    from auv_ident.session.record import paired
    t, Y, U, _, _ = paired(s.commands, s.measurements)
    assert np.all(np.diff(t) > 0) and len(t) == 59
    kept = [k for k in range(60) if k != 33]
    assert np.allclose(t, run.t[kept], atol=1e-9) and np.allclose(Y[:, State.R], [wild(k)[State.R]
                                                                          for k in kept])
    assert np.array_equal(U, run.u[kept])


def test_status_values_are_the_diagnostics_without_ros(run):
    s = IdentSession()
    _feed_messages(s, _corrupted(run))
    h = s.health()
    values = diagnostic_values(s, h, [('internal_errors', '0')])
    keys = [k for k, _ in values]
    assert keys[:10] == ['accepted', 'rejected', 'commands', 'commands_rejected', 'errors',
                         'guard_resets', 'outliers', 'repairs', 'time_jumps', 'internal_errors']
    kv = dict(values)
    c = s.counters
    assert kv['accepted'] == str(c.odom_accepted) and kv['errors'] == str(c.errors) != '0'
    assert kv['rejected'] == str(sum(n for key, n in c.reasons.items()
                                     if key.startswith('odom: ')))
    assert kv['last_error'] == c.last_error and kv['nis_window'] == str(h.window)
    assert kv['Z_ds'] == repr(float(s.best()[0][s.names.index('Z_ds')]))
    assert {'R_u', 'R_psi', 'Q_Z_ds', 'Z_ds_std', 'Z_ds_verdict', 'diagnosis'} <= set(kv)


# --- parameters -------------------------------------------------------------------------------


def test_choice_lists_are_defined_once():
    """The session's choice lists are the core's, and every choice takes effect."""
    assert NOISE_MODES == tuple(MODES)
    for mode in NOISE_MODES:
        assert IdentSession(IdentifierSettings.from_values(noise_mode=mode)).cfg.mode == mode
    for frame in FRAMES:
        assert IdentSession(IdentifierSettings.from_values(frame=frame)).frame == frame
    file_choice = load_vehicle('nps_auv2').mass_inverse     # what 'default' means for it
    assert file_choice in MASS_INVERSES and file_choice != 'default'
    for mi in MASS_INVERSES:
        model = IdentSession(IdentifierSettings.from_values(mass_inverse=mi)).model
        assert model.mass_inverse == (file_choice if mi == 'default' else mi)
        assert model.mass_inverse == Model(load_vehicle('nps_auv2'), mass_inverse=mi).mass_inverse


BAD_SETTINGS = [
    ('tau', 'abc', 'not a number'),
    ('lam', None, 'not a number'),
    ('lam', 0.0, 'positive'),
    ('p0_rel', math.inf, 'positive'),
    ('noise_mode', None, 'use one of fixed'),
    ('noise_mode', 'Fixed', 'use one of fixed'),
    ('frame', 3, 'use one of auto, ned, enu'),
    ('mass_inverse', 'inverse', 'use one of default, exact, mss_literal'),
    ('max_bridge', -0.1, 'positive'),
    ('max_gap', 'long', 'not a number'),
    ('initial_offset', math.nan, 'not -1'),
    ('initial_offset', 'x', 'not a number'),
    ('q_state', [math.nan] * 12, 'finite and >= 0'),
    ('noise_std', [0.01] * 12 + [0.01], 'expected 12 numbers, got 13'),
    ('noise_std', [0.01] * 6 + [0.0] + [0.01] * 5, 'zero for x'),
    ('measured', np.ones(11, dtype=bool), 'a mask must have 12 entries'),
    ('measured', ['u', 'u'], "'u' listed twice"),
    ('initial', [1.0, 0.0, 1.0, 1.0, 1.0], 'finite and non-zero'),
    ('initial', ['a'] * 5, 'expected 5 numbers'),
    ('coefficients', ['Z_w', 'nope'], 'nope'),
    ('coefficients', ['Z_w', 'current_n'], 'is the water current'),
    ('current', 'fast', 'use estimate, none, or N,E[,D]'),
    ('current', '0.1', 'use estimate, none, or N,E[,D]'),
    ('current', 3, 'use estimate, none, or N,E[,D]'),
    ('velocity_reference', 'bottom', 'use one of ground, water'),
    ('current_sd0', 0.0, 'positive'),
    ('current_walk', -1e-3, 'non-negative'),
]


@pytest.mark.parametrize('name, value, needle', BAD_SETTINGS,
                         ids=[f'{n}={v!r}'[:40] for n, v, _ in BAD_SETTINGS])
def test_bad_setting_is_a_parameter_error_naming_it(name, value, needle):
    with pytest.raises(ParameterError) as info:
        IdentSession(IdentifierSettings(**{name: value}))
    assert info.value.name == name
    assert str(info.value).startswith(f'parameter {name!r}: ') and needle in str(info.value)


def test_current_down_without_estimating_the_current_is_a_parameter_error():
    with pytest.raises(ParameterError, match="parameter 'current_down': current-down needs"):
        IdentSession(IdentifierSettings.from_values(current='none', current_down=True))


def test_current_settings_reach_the_model_and_the_names():
    s = IdentSession(IdentifierSettings.from_values(current='estimate', current_down=True,
                                                    velocity_reference='water', current_walk=1e-3))
    assert s.names[-3:] == ['current_n', 'current_e', 'current_d']
    assert s.model.velocity_reference == 'water' and s.model.p_coef == len(s.names) - 3
    assert s.stream.ekf.Q0[-1, -1] == pytest.approx(1e-6 * s.T)
    given = IdentSession(IdentifierSettings.from_values(current='0.1, -0.2'))
    assert given.names == given.coefficient_names and list(given.model.current) == [0.1, -0.2,
                                                                                    0.0]
    assert IdentSession(IdentifierSettings.from_values(current='none')).model.current_mode == 0


def test_warm_start_takes_the_coefficients_not_the_current(tmp_path):
    """A previous run's current is not this run's: a warm start restarts it from its prior."""
    from auv_ident.session.estimate_file import write_estimate_json
    s = IdentSession()
    doc = s.document()
    doc['estimate'][-2:] = [0.3, -0.2]        # a current in the file
    write_estimate_json(tmp_path / 'est.json', doc)
    warm = IdentSession(IdentifierSettings.from_values(warm_start=str(tmp_path / 'est.json')))
    assert warm.names == s.names
    assert np.array_equal(warm.theta0[:-2], doc['estimate'][:-2])
    assert list(warm.theta0[-2:]) == [0.0, 0.0]
    assert np.allclose(warm.estimate_now()[1][-2:, -2:], np.eye(2) * 0.5 ** 2)


def test_warm_start_and_initial_together_is_a_parameter_error(tmp_path):
    from auv_ident.session.estimate_file import write_estimate_json
    doc = IdentSession().document()
    write_estimate_json(tmp_path / 'est.json', doc)
    with pytest.raises(ParameterError, match="parameter 'initial': give either"):
        IdentSession(IdentifierSettings.from_values(warm_start=str(tmp_path / 'est.json'),
                                                    initial=[1.0] * 5))
    with pytest.raises(ParameterError, match="parameter 'warm_start': .* for vehicle"):
        IdentSession(IdentifierSettings.from_values(vehicle='remus100',
                                                    warm_start=str(tmp_path / 'est.json')))
    with pytest.raises(ParameterError, match="parameter 'warm_start': .* holds"):
        IdentSession(IdentifierSettings.from_values(coefficients=['Z_w'],
                                                    warm_start=str(tmp_path / 'est.json')))


def test_a_planar_vehicle_neither_reads_nor_screens_its_held_states():
    """A ship's odometry may carry anything where it does not move (an importer's NaN for
    heave, a measured roll): the session reads u v r x y psi and leaves the rest held."""
    v = load_vehicle('kvlcc2_hsva')
    run = simulate(Model(v), 'zigzag', duration=10.0, T=0.1, seed=1)
    s = IdentSession(IdentifierSettings.from_values(vehicle='kvlcc2_hsva', coefficients=['N_r'],
                                                    sample_time=0.1))
    assert list(np.flatnonzero(s.measured)) == [State.U, State.V, State.R, State.X, State.Y,
                                                State.PSI]
    held = [State.W, State.P, State.Q, State.Z, State.PHI, State.THETA]
    for k in range(20):
        stamp_ns = round(run.t[k] * 1e9)
        assert s.add_command(stamp_ns, run.u[k]).kind != 'rejected'
        y = run.y[k].copy()
        y[[State.W, State.P, State.Q]] = math.nan
        y[State.PHI] = 0.2
        assert s.add_odometry(stamp_ns, y).kind == 'update'
        assert np.all(s.stream.ekf.xa[held] == 0.0)


# --- odometry lost before the session saw it --------------------------------------------------

def test_stamp_gaps_count_what_a_2khz_stream_lost():
    """A 2 kHz stream (stamps with 5 % jitter) of which 37 % never arrive, in runs of 1-3 as
    an overflowing queue drops them: every lost message counted from the stamps, and the
    rate found."""
    rng = np.random.default_rng(1)
    dt_ns = 500_000
    n = 20000
    stamps = np.arange(n) * dt_ns + rng.normal(0.0, 0.05 * dt_ns, n).astype(np.int64)
    keep = np.ones(n, dtype=bool)
    k = 100
    while k < n - 4:
        if rng.random() < 0.25:
            run_len = int(rng.integers(1, 4))
            keep[k:k + run_len] = False
            k += run_len
        k += 1
    gaps = StampGaps(max_gap_s=1.0)
    for s in stamps[keep]:
        gaps.see(int(s))
    dropped = int(np.count_nonzero(~keep))
    assert 0.3 < dropped / n < 0.45
    assert gaps.lost == dropped and gaps.expected == n
    assert gaps.interval_s == pytest.approx(dt_ns * 1e-9, rel=0.1)


def test_stamp_gaps_count_nothing_in_a_complete_or_paused_stream():
    """Jitter (20 %), duplicate and out-of-order stamps and a pause longer than max_gap are
    not losses."""
    rng = np.random.default_rng(2)
    gaps = StampGaps(max_gap_s=1.0)
    stamps = list(np.arange(2000) * 50_000_000 + rng.uniform(-1e7, 1e7, 2000).astype(np.int64))
    stamps.insert(500, stamps[499])             # a duplicate
    stamps[700], stamps[701] = stamps[701], stamps[700]    # out of order
    stamps += [stamps[-1] + 5_000_000_000 + k * 50_000_000 for k in range(1, 50)]   # pause
    for s in stamps:
        gaps.see(int(s))
    assert gaps.lost == 0 and gaps.seen == len(stamps)


def test_lost_odometry_is_on_the_diagnostics(run):
    """A session fed a stream with every third odometry message missing counts them in
    /diagnostics odom_lost, with the rate the stamps show."""
    s = IdentSession()
    messages = _messages(run)
    odom = [i for i, (topic, _) in enumerate(messages) if topic != ACTUATOR_TOPIC]
    missing = set(odom[50:-1:3])      # not the last: a later stamp shows a gap
    _feed_messages(s, [m for i, m in enumerate(messages) if i not in missing])
    kv = dict(diagnostic_values(s, s.health()))
    assert kv['odom_lost'] == str(len(missing))
    assert float(kv['odom_rate_hz']) == pytest.approx(1.0 / T, rel=0.01)
    s2 = IdentSession()
    _feed_messages(s2, messages)
    assert dict(diagnostic_values(s2, s2.health()))['odom_lost'] == '0'


def test_publish_gate_publishes_the_first_update_of_each_interval():
    """publish_rate_hz: the first update in each 1/rate interval of stamps; 0 = every one; a
    stamp back in an earlier interval (a time jump) is published and starts over."""
    every = PublishGate(0.0)
    assert all(every.due(ns) for ns in (5, 5, 6))
    gate = PublishGate(10.0)                    # 100 ms intervals
    ms = 1_000_000
    stamps = [0, 40 * ms, 99 * ms, 100 * ms, 150 * ms, 310 * ms, 320 * ms, 120 * ms, 130 * ms]
    assert [gate.due(ns) for ns in stamps] == [True, False, False, True, False, True, False,
                                               True, False]


def test_a_repeated_message_covariance_gives_the_same_variances_and_notices():
    """The variances of a message whose covariance repeats the last message's are taken
    again without the checks: every R and every notice is that of checking each message."""
    cached, checked = IdentSession(), IdentSession()
    good = cached.noise_default * 2.0
    absurd = good.copy()
    absurd[2] = good[2] * 1e-20     # beyond PLAUSIBLE_VARIANCE_RATIO
    unstated = good.copy()
    unstated[[0, 7]] = [np.nan, -1.0]
    unmeasured = good.copy()
    unmeasured[9] = 1e9
    for v in (good, good, good, absurd, absurd, good, unstated, unstated, absurd, unmeasured,
              unmeasured, good):
        r = cached._measurement_variances(v.copy())
        np.testing.assert_array_equal(r, checked._checked_variances(v.copy()))
        assert cached.notices == checked.notices
        r[:] = -5.0                 # the caller's to change: the next message's R is not
    assert len(cached.notices) == 3
