"""The stuck-sensor rule (session/stuck.py) in the session: exact repeats of a measured channel
group are not fed, a stuck sensor raises ERROR and freezes the last good estimate; quantised
single components and a slow sensor republished at a faster rate are not faults."""
import numpy as np
import pytest

from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import State
from auv_ident.core.simulation.simulate import simulate
from auv_ident.session.session import IdentSession
from auv_ident.session.settings import IdentifierSettings
from auv_ident.session.status import diagnostic_values
from auv_ident.session.stuck import STUCK_SAMPLES, STUCK_SECONDS, StuckDetector
from auv_ident.vehicles import load_vehicle

T = 0.05
STUCK = (200, 300)      # samples 200..299 (t = 10.0 .. 14.95 s) repeat sample 199
TWIST = list(range(State.U, State.R + 1))
ATTITUDE = [State.PHI, State.THETA, State.PSI]


@pytest.fixture(scope='module')
def run():
    return simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=30.0, T=T, seed=3)


def _ns(t):
    return int(round(t * 1e9))


def _feed(session, run, y, watch=None):
    """Feed commands and odometry y (N, 12) at the run's stamps through the array API;
    watch(k, event) after each odometry. Returns the odometry events."""
    events = []
    for k, t in enumerate(run.t[:len(y)]):
        session.add_command(_ns(t), run.u[k])
        ev = session.add_odometry(_ns(t), y[k])
        events.append(ev)
        if watch is not None:
            watch(k, ev)
    return events


def _stuck(y, channels=slice(None), span=STUCK):
    y = y.copy()
    y[span[0]:span[1], channels] = y[span[0] - 1, channels]
    return y


def test_repeated_odometry_is_not_fed_and_is_a_stuck_sensor(run):
    """The issue's case: the whole odometry message repeated with fresh stamps for 5 s at
    20 Hz. Nothing of it reaches the filter, the health is ERROR 'stuck sensor' while it lasts
    (not before 10 samples and 2 s), the last good estimate stays the one from before it, the
    start and the end are each said once; afterwards the estimate is the one that perfect
    rejection of those samples gives."""
    s = IdentSession(keep_arrays=True)
    t_before = _ns(run.t[STUCK[0] - 1])
    seen = {}

    def watch(k, ev):
        seen[k] = (ev.kind, ev.code, s.health().level, s.health().message,
                   None if s.last_good is None else s.last_good.stamp_ns, list(s.notices))
        s.notices.clear()
    _feed(s, run, _stuck(run.y), watch)
    assert dict(s.counters.reasons) == {'odom: repeated': STUCK[1] - STUCK[0]}
    # not a fault before STUCK_SAMPLES samples spanning STUCK_SECONDS
    first_error = min(k for k, v in seen.items() if v[2] == 'ERROR')
    assert first_error == STUCK[0] - 1 + round(STUCK_SECONDS / T)
    assert first_error - (STUCK[0] - 1) + 1 >= STUCK_SAMPLES
    for k in range(first_error, STUCK[1]):
        kind, code, level, message, good, _ = seen[k]
        assert (kind, code, level) == ('rejected', 'repeated', 'ERROR'), k
        assert message.startswith('stuck sensor: position, attitude, linear velocity, '
                                  'angular velocity repeated exactly for')
        assert good == t_before, k
    assert seen[STUCK[1]][0] == 'update' and seen[STUCK[1]][2] != 'ERROR'
    notices = [n for v in seen.values() for n in v[5]]
    assert len(notices) == 2, notices
    assert 'from t = 9.950 s' in notices[0] and 'a stuck sensor?' in notices[0]
    assert notices[1].startswith('odom: changes again at t = 15.000 s after')
    assert 'repeated exactly for 5.0 s from t = 9.950 s (100 samples not fed)' in notices[1]
    span_ts = {round(t, 6) for t in s.measurements.array[:, 0]}
    assert not span_ts & {round(t, 6) for t in run.t[STUCK[0]:STUCK[1]]}
    kv = dict(diagnostic_values(s, s.health()))
    assert kv['repeated'] == str(4 * (STUCK[1] - STUCK[0])) and kv['stuck_sensor'] == 'none'

    # what perfect rejection gives: the same run without the span's odometry
    ref = IdentSession()
    for k, t in enumerate(run.t):
        ref.add_command(_ns(t), run.u[k])
        if not STUCK[0] <= k < STUCK[1]:
            ref.add_odometry(_ns(t), run.y[k])
    assert np.array_equal(s.last_good.estimate, ref.last_good.estimate)


def test_a_stuck_twist_is_left_out_and_nothing_is_good_meanwhile(run):
    """Only the twist freezes (the pose goes on): the messages are fed without u ... r, no
    update is good while the fault is active, the /diagnostics values name it."""
    s = IdentSession(keep_arrays=True)
    good_during, values = [], {}

    def watch(k, ev):
        if STUCK[0] + 39 <= k < STUCK[1]:     # the fault from 2 s after sample 199
            assert ev.kind == 'update' and not ev.good and 'stuck sensor' in ev.reason
            good_during.append(s.last_good.stamp_ns)
        if k == STUCK[1] - 1:
            values.update(diagnostic_values(s, s.health()))
    events = _feed(s, run, _stuck(run.y, TWIST), watch)
    assert not s.counters.reasons and s.counters.odom_accepted == len(run.t)
    assert set(good_during) == {_ns(run.t[STUCK[0] + 38])}
    assert values['stuck_sensor'].startswith('linear velocity, angular velocity repeated '
                                             'exactly for 5.0 s from t = 9.950 s')
    assert values['consistent'] == 'false' and 'stuck sensor' in values['diagnosis']
    Y = s.measurements.array[:, 1:]
    assert np.all(np.isnan(Y[STUCK[0]:STUCK[1], TWIST]))
    assert np.all(np.isfinite(Y[STUCK[0]:STUCK[1], State.X:]))
    assert np.all(np.isfinite(Y[STUCK[1]:]))
    assert events[-1].good and s.health().level != 'ERROR'


def test_legitimate_repeats_are_not_faults(run):
    """Depth quantised at 1 cm repeats one component for long stretches (the position group
    changes); a 1 Hz velocity sensor republished at 20 Hz repeats its group 19 times within
    0.95 s (not fed, but never 2 s: no fault). Neither rejects a message or raises ERROR."""
    y = run.y.copy()
    y[:, State.Z] = np.round(y[:, State.Z], 2)
    held = np.repeat(np.arange(0, len(run.t), 20), 20)[:len(run.t)]
    y[:, TWIST] = run.y[held][:, TWIST]
    levels = set()
    s = IdentSession()
    _feed(s, run, y, lambda k, ev: levels.add(s.health().level))
    assert 'ERROR' not in levels and not s.counters.reasons and not s.stuck.spans
    assert s.stuck.repeats == 2 * sum(held[1:] == held[:-1])    # linear and angular
    assert s.counters.odom_accepted == len(run.t)


def test_a_field_never_filled_is_a_stuck_sensor_for_the_whole_run(run):
    """Orientation left at the identity quaternion (a driver that fills only the twist): the
    attitude is fed once, then never; ERROR from 2 s on, to the end; the saved estimate is
    the last good one from before that (formed without the repeats)."""
    y = run.y.copy()
    y[:, ATTITUDE] = 0.0
    s = IdentSession(IdentifierSettings.from_values(initial_offset=0.5))
    _feed(s, run, y)
    assert s.health().level == 'ERROR' and s.health().message.startswith(
        'stuck sensor: attitude repeated exactly for 30.0 s from t = 0.000 s')
    assert [sp.group for sp in s.stuck.spans] == ['attitude']
    good = s.last_good
    assert good is not None and good.stamp_ns < _ns(STUCK_SECONDS)
    assert s.document()['stamp_ns'] == good.stamp_ns


def test_no_good_estimate_during_a_fault_saves_the_prior(run):
    """A stuck sensor before any update was good (the guard on probation, say): the estimate
    file holds the start-up prior, not the faulted filter's estimate."""
    s = IdentSession()
    y = _stuck(run.y, span=(1, 100))
    s.filter.probation = True           # nothing becomes good before the fault
    _feed(s, run, y[:100])
    assert s.last_good is None and s.stuck.active()
    doc = s.document()
    assert doc['stamp'] is None and doc['estimate'] == list(s.theta0)
    assert not np.array_equal(s.estimate_now()[0], s.theta0)


def test_lone_measured_channels_are_judged_together():
    """A planar vehicle measures u v r x y psi: psi and r are each the only measured member of
    their group, and one channel may repeat legitimately (a quantised heading on a straight
    course); they are judged together."""
    planar = [State.U, State.V, State.R, State.X, State.Y, State.PSI]
    d = StuckDetector(planar)
    assert [(g.name, g.channels) for g in d.groups] == [
        ('position', (State.X, State.Y)), ('linear velocity', (State.U, State.V)),
        ('psi, r', (State.PSI, State.R))]
    x = np.arange(12.0)
    d.renew(0.0, x.tolist(), [])
    moved = x + 1e-6
    moved[State.PSI] = x[State.PSI]     # the heading repeats, nothing else does
    assert d.held(moved.tolist()) == []
    moved[State.R] = x[State.R]         # heading and yaw rate repeat
    moved[State.X:State.Z] = x[State.X:State.Z]     # so does the position
    assert [g.name for g in d.held(moved.tolist())] == ['position', 'psi, r']
    assert [g.name for g in StuckDetector([State.Z, State.U, State.V]).groups] == [
        'linear velocity']      # a lone z is not judged


def test_a_field_the_message_says_it_does_not_measure_is_not_stuck(run):
    """The same identity quaternion, but the message states the attitude's variance as 'not
    measured' (>= NOT_MEASURED_VARIANCE): skipped by that rule, so nothing repeats; no fault."""
    from auv_ident.session.messages import NOT_MEASURED_VARIANCE
    s = IdentSession(IdentifierSettings.from_values(noise_source='message'))
    variances = s.noise_default.copy()
    variances[ATTITUDE] = 10 * NOT_MEASURED_VARIANCE
    y = run.y.copy()
    y[:, ATTITUDE] = 0.0
    for k, t in enumerate(run.t):
        s.add_command(_ns(t), run.u[k])
        s.add_odometry(_ns(t), y[k], variances=variances)
    assert not s.stuck.spans and s.stuck.repeats == 0 and s.health().level != 'ERROR'
