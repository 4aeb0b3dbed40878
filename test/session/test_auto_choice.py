"""The live `coefficients: [auto, NAME, ...]` (session/auto_choice.py) on an independent record:
the session publishes the named set while it keeps the first auto_window s, chooses, switches
without losing a sample, and ends where an offline identify of the chosen set ends; messages
that arrive while a worker chooses are kept and fed; a failed choice keeps the running set and
says why; bad settings are one-line errors."""
import math
import re
import threading

import numpy as np
import pytest

from auv_ident.analysis.bag_identify import identify_bag
from auv_ident.bags.reader import read_bag
from auv_ident.core.errors import DomainError
from auv_ident.offline.independent_data import ACTUATOR_TOPIC, DataConfig, generate, ODOM_TOPIC
from auv_ident.offline.replay import replay_bag
from auv_ident.session import auto_choice
from auv_ident.session.auto_choice import run_in_thread
from auv_ident.session.session import IdentSession
from auv_ident.session.settings import IdentifierSettings, ParameterError
from auv_ident.vehicles import load_vehicle

WINDOW_S = 30.0
CURRENT = ['current_n', 'current_e']


@pytest.fixture(scope='module')
def record(tmp_path_factory):
    """60 s at 20 Hz of a vehicle whose every coefficient is 0.8-1.2x the file's (so the data
    ask for more than the named one), and its messages in log-time order."""
    out = tmp_path_factory.mktemp('live_auto') / 'run'
    data = generate(DataConfig(duration=60.0, seed=5, odom_rate=20.0, commands='periodic',
                               perturb=0.2), out)
    messages = list(read_bag(data.bag, {ODOM_TOPIC: 'nav_msgs/msg/Odometry',
                                        ACTUATOR_TOPIC: 'sensor_msgs/msg/JointState'}))
    return data, messages


def _feed(session, messages):
    """Feed (topic, t_ns, msg) in order; return the events of the odometry."""
    events = []
    for topic, _, msg in messages:
        if topic == ACTUATOR_TOPIC:
            session.on_actuators(msg)
        else:
            events.append(session.on_odom(msg))
    return events


def test_publishes_while_choosing_then_switches_without_losing_a_sample(record):
    data, messages = record
    n_odom = len(data.odom_stamp_ns)
    s = IdentSession(IdentifierSettings.from_values(coefficients=['auto', 'Z_ds'],
                                                    auto_window=WINDOW_S))
    assert s.names == ['Z_ds'] + CURRENT and s.auto.state == 'choosing'
    events, lines = [], []
    for topic, _, msg in messages:
        if topic == ACTUATOR_TOPIC:
            s.on_actuators(msg)
            continue
        events.append(s.on_odom(msg))
        # names, last good estimate and estimate file agree after every message
        assert s.last_good is None or len(s.last_good.estimate) == len(s.names)
        if s.auto.state == 'choosing' and len(events) == 200:
            lines.append(s.diagnosis()[1]['messages'][0])
    # before the switch the named coefficient (and the current) is published, from the start
    lengths = [len(ev.estimate) for ev in events if ev.good]
    assert lengths[0] == 3 and events[0].kind == 'update'
    assert lines and re.fullmatch(r'choosing coefficients from the data \((9\.9|10\.0) of '
                                  f'{WINDOW_S:g}' r' s\); identifying Z_ds meanwhile', lines[0])
    # the choice: the named one first, more than it (a wrong prior), every other one left out
    # with its reason
    auto = s.auto
    assert auto.state == 'chosen', auto.reason
    sel = auto.selection
    v = load_vehicle('nps_auv2')
    assert sel.chosen[0] == 'Z_ds' and len(sel.chosen) > 1 and sel.named == ['Z_ds']
    assert set(sel.chosen).isdisjoint(sel.left_out)
    assert set(sel.chosen) | set(sel.left_out) == set(v.names)
    assert all(isinstance(why, str) and why for why in sel.left_out.values())
    assert s.names == sel.chosen + CURRENT and s.coefficient_names == sel.chosen
    # once switched, the estimate has the chosen set's length, and keeps it
    switch = next(i for i, ev in enumerate(events) if len(ev.estimate) != 3)
    assert all(len(ev.estimate) == len(s.names) for ev in events[switch:])
    assert auto.window_data_s == pytest.approx(WINDOW_S, abs=0.05)
    # no sample lost: every odometry sample reached the chosen set's filter once and was taken
    assert s.odom_accepted == n_odom and s.odom_rejected == 0
    assert s.stream.accepted == n_odom and s.stream.rejected == 0
    assert auto.samples == switch         # the ones kept up to the switch were fed to it
    assert s.last_good is not None and len(s.last_good.estimate) == len(s.names)
    # what the user sees: the news, the diagnosis, /diagnostics' values, the estimate file
    assert [lvl for lvl, _ in auto.news].count('error') == 0
    assert any(text.startswith('switched to the chosen set') for _, text in auto.news)
    messages_now = s.diagnosis()[1]['messages']
    assert messages_now[1].startswith(f'coefficients chosen from {auto.window_data_s:.1f} s')
    kv = dict(auto.diagnostic_values())
    assert kv['auto_state'] == 'chosen' and kv['auto_chosen'] == ','.join(sel.chosen)
    assert int(kv['auto_left_out_count']) == len(sel.left_out) and kv['auto_error'] == ''
    assert all(kv[f'auto_left_out_{n}'] == why for n, why in sel.left_out.items())
    doc = s.document()
    assert doc['coefficients'] == s.names
    block = doc['selection']
    assert block['state'] == 'chosen' and block['chosen'] == sel.chosen
    assert block['left_out'] == sel.left_out and block['window_s'] == WINDOW_S
    assert block['criteria']['method'].endswith('(no re-assessment)')
    assert block['samples'] == switch


def test_the_chosen_set_ends_where_an_offline_identify_of_it_ends(record):
    """The live estimate of the chosen set over the whole record against `identify --bag` of
    the same bag with the same coefficients given (EKF pass and refinement): within the live
    estimate's error bars (3 sigma)."""
    data, messages = record
    s = IdentSession(IdentifierSettings.from_values(coefficients=['auto', 'Z_ds'],
                                                    auto_window=WINDOW_S))
    _feed(s, messages)
    assert s.auto.state == 'chosen', s.auto.reason
    doc, _ = identify_bag(data.bag,
                          IdentifierSettings.from_values(coefficients=s.coefficient_names))
    assert list(doc['coefficients']) == s.coefficient_names
    offline = np.array([doc['coefficients'][n]['estimate'] for n in s.coefficient_names])
    live, cov = s.best()
    p = len(s.coefficient_names)
    live_std = np.sqrt(np.diag(cov))[:p]
    z = np.abs(live[:p] - offline) / live_std
    assert np.all(z < 3.0), dict(zip(s.coefficient_names, np.round(z, 2)))


def test_a_bag_replays_with_the_choice_as_the_node_makes_it(record):
    """replay_bag (identify --bag's EKF pass, the node's logic offline) takes the same
    coefficients [auto, NAME] and ends on the chosen set, as the session fed by hand."""
    data, messages = record
    res = replay_bag(data.bag, IdentifierSettings.from_values(coefficients=['auto', 'Z_ds'],
                                                              auto_window=WINDOW_S))
    s = IdentSession(IdentifierSettings.from_values(coefficients=['auto', 'Z_ds'],
                                                    auto_window=WINDOW_S))
    _feed(s, messages)
    assert res.names == s.names and len(res.names) > 3
    assert res.accepted == len(data.odom_stamp_ns) and res.rejected == 0
    assert np.array_equal(res.estimate, s.last_good.estimate)


def test_auto_alone_identifies_the_default_set_while_choosing():
    s = IdentSession(IdentifierSettings.from_values(coefficients=['AUTO']))
    v = load_vehicle('nps_auv2')
    assert s.auto.named == () and s.names == list(v.identify_default) + CURRENT
    assert s.auto.window_s == 120.0
    assert s.document()['selection'] == {'state': 'choosing', 'window_s': 120.0, 'named': [],
                                         'data_s': 0.0}
    assert IdentSession(IdentifierSettings.from_values(coefficients=['Z_ds'])).auto is None


def test_messages_arriving_while_a_worker_chooses_are_kept_and_fed(record, monkeypatch):
    """With the choice in a worker thread (the node's runner) held until released: the running
    filter goes on publishing its set, the messages are kept, and the switch at the next
    message feeds them to the chosen filter: it has taken every sample."""
    data, messages = record
    release = threading.Event()
    real_choice = auto_choice.choose_coefficients

    def held_choice(*args, **kwargs):
        assert release.wait(30.0)
        return real_choice(*args, **kwargs)

    monkeypatch.setattr(auto_choice, 'choose_coefficients', held_choice)
    s = IdentSession(IdentifierSettings.from_values(coefficients=['auto', 'Z_ds'],
                                                    auto_window=WINDOW_S),
                     auto_runner=run_in_thread)
    odom = [i for i, (topic, _, _) in enumerate(messages) if topic == ODOM_TOPIC]
    split = odom[900]                # 15 s after the window filled
    events = _feed(s, messages[:split])
    assert s.auto.state == 'choosing' and s.auto.running
    assert 'the selection runs' in s.diagnosis()[1]['messages'][0]
    assert all(len(ev.estimate) == 3 for ev in events)
    kept = len(s.auto.kept)
    assert kept > s.auto.taken
    release.set()
    assert s.auto.job.exception(timeout=30.0) is None
    events += _feed(s, messages[split:])
    assert s.auto.state == 'chosen', s.auto.reason
    assert s.auto.samples == 900    # the window's and the 15 s kept while it chose
    assert s.stream.accepted == len(odom) == s.odom_accepted
    assert len(events[-1].estimate) == len(s.names) > 3


def test_a_failed_choice_keeps_the_running_set_and_says_why(record, monkeypatch):
    data, messages = record

    def out_of_domain(*args, **kwargs):
        raise DomainError("the filter-error residuals cannot be computed at the vehicle file's "
                          'values (the model leaves its domain on this record)')

    monkeypatch.setattr(auto_choice, 'choose_coefficients', out_of_domain)
    s = IdentSession(IdentifierSettings.from_values(coefficients=['auto', 'Z_ds'],
                                                    auto_window=WINDOW_S))
    events = _feed(s, messages)
    auto = s.auto
    assert auto.state == 'failed' and 'leaves its domain' in auto.reason
    assert s.names == ['Z_ds'] + CURRENT and all(len(ev.estimate) == 3 for ev in events)
    assert s.stream.accepted == len(data.odom_stamp_ns) and auto.kept is None
    assert [lvl for lvl, _ in auto.news] == ['info', 'error']     # started; failed, once
    first = s.diagnosis()[1]['messages'][0]
    assert first.startswith('automatic choice of coefficients failed: the filter-error')
    assert first.endswith('identifying Z_ds (the running set) instead')
    kv = dict(auto.diagnostic_values())
    assert kv['auto_state'] == 'failed' and kv['auto_error'] == auto.reason
    assert s.document()['selection']['error'] == auto.reason


def test_a_choice_of_no_coefficient_keeps_the_default_set_with_the_reasons(record):
    """'auto' alone on 20 s that determine no coefficient: nothing to switch to (a filter of
    the current alone would say less than the default set); every coefficient's reason stays
    visible."""
    data, messages = record
    s = IdentSession(IdentifierSettings.from_values(coefficients=['auto'], auto_window=20.0))
    _feed(s, messages)
    auto = s.auto
    assert auto.state == 'failed' and auto.reason.startswith('the data chose no coefficient')
    assert s.names == list(load_vehicle('nps_auv2').identify_default) + CURRENT
    kv = dict(auto.diagnostic_values())
    assert kv['auto_chosen'] == '' and int(kv['auto_left_out_count']) == len(
        load_vehicle('nps_auv2').names)
    assert s.document()['selection']['left_out'] == auto.selection.left_out


BAD = [
    ('auto_window', 0.0, "parameter 'auto_window': 0.0 must be a positive finite number"),
    ('auto_window', -5.0, 'must be a positive finite number'),
    ('auto_window', math.nan, 'must be a positive finite number'),
    ('auto_window', 'long', "'long' is not a number"),
    ('coefficients', ['Z_ds', 'auto'], "'auto' must come first"),
    ('coefficients', ['auto', 'Z_ds', 'Q_xyz'], "unknown coefficient 'Q_xyz'"),
    ('coefficients', ['auto', 'Z_ds', 'z_ds'], 'Z_ds is listed twice'),
    ('coefficients', ['auto', 'current_n'], 'is the water current'),
]


@pytest.mark.parametrize('name, value, needle', BAD, ids=[f'{n}={v!r}' for n, v, _ in BAD])
def test_bad_auto_settings_are_one_line_errors_naming_the_parameter(name, value, needle):
    kwargs = {'coefficients': ['auto'], name: value}
    with pytest.raises(ParameterError) as info:
        IdentSession(IdentifierSettings.from_values(**kwargs))
    text = str(info.value)
    assert info.value.name == name and needle in text and '\n' not in text
    assert text.startswith(f'parameter {name!r}: ')


def test_auto_and_a_warm_start_together_is_a_parameter_error(tmp_path):
    from auv_ident.session.estimate_file import write_estimate_json
    write_estimate_json(tmp_path / 'est.json', IdentSession().document())
    with pytest.raises(ParameterError, match="parameter 'warm_start': .*give one or the other"):
        IdentSession(IdentifierSettings.from_values(coefficients=['auto'],
                                                    warm_start=str(tmp_path / 'est.json')))
