"""Hostile warm-start files and invalid stamps: one clear rejection or ParameterError, never a
hang, a traceback or a silently accepted value (#27: a FIFO warm start hung, /dev/zero was read
without bound, nested JSON raised RecursionError, true was taken as 1.0, a stamp with
nanosec >= 10^9 was accepted)."""
import json
import os
from types import SimpleNamespace

import numpy as np
import pytest

from auv_ident.session.estimate_file import load_estimate_json
from auv_ident.session.messages import ConversionError, JOINT_NAMES, stamp_to_ns
from auv_ident.session.session import IdentSession
from auv_ident.session.settings import ParameterError

GOOD = {'vehicle': 'nps_auv2', 'coefficients': ['Z_w'], 'estimate': [-0.3],
        'covariance': [[1e-4]]}


def _write(tmp_path, text, name='est.json'):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_a_good_estimate_file_loads(tmp_path):
    vehicle, names, est, cov = load_estimate_json(_write(tmp_path, json.dumps(GOOD)))
    assert (vehicle, names) == ('nps_auv2', ['Z_w']) and est.tolist() == [-0.3]


@pytest.mark.parametrize('text, match', [
    ('[' * 100000 + ']' * 100000, 'nested too deeply'),
    (json.dumps(dict(GOOD, estimate=[True])), "true/false in 'estimate'"),
    (json.dumps(dict(GOOD, covariance=[[False]])), "true/false in 'covariance'"),
    ('[1, 2]', 'a JSON list, not an object'),
    ('{"vehicle": ', 'cannot read'),
])
def test_a_hostile_estimate_file_is_one_parameter_error(tmp_path, text, match):
    with pytest.raises(ParameterError, match=f"parameter 'warm_start': .*{match}"):
        load_estimate_json(_write(tmp_path, text))


def test_a_fifo_or_a_device_is_refused_without_reading_it(tmp_path):
    fifo = tmp_path / 'fifo.json'
    os.mkfifo(fifo)
    for path in (str(fifo), '/dev/zero', str(tmp_path)):
        with pytest.raises(ParameterError, match='not a regular file'):
            load_estimate_json(path)


def test_an_oversized_file_is_refused(tmp_path):
    path = tmp_path / 'big.json'
    with open(path, 'wb') as fh:
        fh.truncate(17 * 1024 * 1024)
    with pytest.raises(ParameterError, match='more than an estimate file holds'):
        load_estimate_json(str(path))


def _stamp(sec, nanosec):
    return SimpleNamespace(sec=sec, nanosec=nanosec)


def test_a_stamp_with_nanosec_of_a_second_or_more_is_invalid():
    assert stamp_to_ns(_stamp(3, 999_999_999)) == 3_999_999_999
    for nanosec in (1_000_000_000, 4_000_000_000):
        with pytest.raises(ConversionError, match='nanosec .* outside'):
            stamp_to_ns(_stamp(3, nanosec))


def test_the_session_rejects_messages_with_an_invalid_stamp():
    """The message is rejected as a conversion problem naming the field; the next valid one is
    taken as usual."""
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import JointState
    s = IdentSession()
    cmd = JointState()
    cmd.header.stamp.sec, cmd.header.stamp.nanosec = 1, 0
    cmd.name = list(JOINT_NAMES)
    cmd.position = [0.0] * 6
    cmd.velocity = [0.0] * 6
    assert s.on_actuators(cmd).kind == 'command'
    odom = Odometry()
    odom.header.stamp.sec = 1
    odom.header.stamp.nanosec = 2_000_000_000   # outside [0, 1e9): not a valid Time
    odom.pose.pose.orientation.w = 1.0
    odom.twist.twist.linear.x = 1.5
    ev = s.on_odom(odom)
    assert ev.kind == 'rejected' and ev.code == 'conversion' and 'nanosec' in ev.reason
    assert s.reasons['odom: conversion'] == 1
    assert np.isfinite(s.theta0).all()
