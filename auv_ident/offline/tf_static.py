"""Sensor mountings from a bag's /tf_static (tf2_msgs/msg/TFMessage).

A sensor message's header frame_id names the sensor's frame; /tf_static chains it to the
body frame (the map's ``tf_body_frame``, default base_link). Each TransformStamped gives the
child frame's origin in its parent (translation, m) and the rotation child -> parent
(quaternion): composed along the chain they give the sensor's lever arm and its rotation
sensor -> body, in the axes of the map's ``body_frame`` (flu: REP-103, as tf trees are; then
held in FRD like a map's mounting: session/input_map.py mounting_in_frd).

Precedence (raw_sensor_config): a sensor whose map entry has no ``mounting`` takes the tf one;
one whose entry has a ``mounting`` keeps it, and if /tf_static says otherwise (lever arms more
than LEVER_TOL apart, or rotations more than ROTATION_TOL_DEG apart) that is an InputMapError
naming both: two descriptions of one vehicle that disagree are a mistake in one of them, and
silently picking one would bias the DVL's velocity (a 1 deg mounting error turns 1 % of the
forward speed into sway). A sensor frame /tf_static does not reach keeps the map's mounting.
"""
import math

import numpy as np

from auv_ident.bags.reader import bag_topics, read_bag
from auv_ident.core.model.raw_sensors import rotation_of_quaternion
from auv_ident.session.input_map import InputMapError, mounting_in_frd

TF_STATIC = '/tf_static'
TF_TYPE = 'tf2_msgs/msg/TFMessage'
LEVER_TOL = 0.01           # m
ROTATION_TOL_DEG = 0.5     # deg


def _frame(name):
    return str(name).strip().lstrip('/')


def static_transforms(path, allow_truncated=False):
    """child frame -> (parent frame, translation (3,) m, rotation (3, 3) child -> parent) of
    every transform on the bag's /tf_static ({} when it has none)."""
    if TF_STATIC not in bag_topics(path, allow_truncated=allow_truncated):
        return {}
    out = {}
    for _, _, msg in read_bag(path, {TF_STATIC: TF_TYPE}, allow_truncated=allow_truncated):
        for ts in msg.transforms:
            tr, q = ts.transform.translation, ts.transform.rotation
            out[_frame(ts.child_frame_id)] = (
                _frame(ts.header.frame_id), np.array([tr.x, tr.y, tr.z], dtype=float),
                rotation_of_quaternion(np.array([q.x, q.y, q.z, q.w], dtype=float)))
    return out


def chain_to(transforms, frame, body):
    """(translation (3,) m, rotation (3, 3)) of ``frame`` in ``body`` composed along the tf
    chain, or None if the chain does not reach it (or loops)."""
    t, R = np.zeros(3), np.eye(3)
    seen = set()
    while frame != body:
        if frame in seen or frame not in transforms:
            return None
        seen.add(frame)
        parent, t_p, R_p = transforms[frame]
        # x_parent = R_p x_child + t_p
        t, R = R_p @ t + t_p, R_p @ R
        frame = parent
    return t, R


def sensor_frames(path, input_map, allow_truncated=False):
    """input name -> the header frame_id of its first message (sensors with one)."""
    by_topic = {e.bag_topic: e for e in input_map.sensors}
    out = {}
    if not by_topic:
        return out
    types = {t: e.type for t, e in by_topic.items()}
    for topic, _, msg in read_bag(path, types, allow_truncated=allow_truncated):
        e = by_topic[topic]
        if e.name not in out:
            fid = _frame(getattr(getattr(msg, 'header', None), 'frame_id', ''))
            out[e.name] = fid
            if len(out) == len(by_topic):
                break
    return {k: v for k, v in out.items() if v}


def tf_mountings(path, input_map, allow_truncated=False):
    """input name -> Mounting (FRD) of each sensor /tf_static chains to the body frame."""
    transforms = static_transforms(path, allow_truncated)
    if not transforms:
        return {}
    out = {}
    for name, fid in sensor_frames(path, input_map, allow_truncated).items():
        found = chain_to(transforms, fid, input_map.tf_body_frame)
        if found is not None:
            out[name] = mounting_in_frd(found[0], found[1], input_map.body_frame)
    return out


def merged_mountings(input_map, from_tf):
    """input name -> Mounting of every sensor: the module docstring's precedence (the map's
    given mounting, checked against the tf one; the tf one where the map gives none)."""
    out = {}
    for e in input_map.sensors:
        m = from_tf.get(e.name)
        if m is None:
            out[e.name] = e.mounting
        elif not e.mounting_given:
            out[e.name] = m
        else:
            _check_agree(input_map, e, m)
            out[e.name] = e.mounting
    return out


def _check_agree(input_map, entry, tf):
    """InputMapError naming both mountings if they disagree (module docstring)."""
    d_arm = float(np.linalg.norm(np.subtract(entry.mounting.lever_arm, tf.lever_arm)))
    dR = entry.mounting.matrix.T @ tf.matrix
    angle = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(dR) - 1.0) / 2.0))))
    if d_arm > LEVER_TOL or angle > ROTATION_TOL_DEG:
        raise InputMapError(
            f'input {entry.name!r} of {input_map.where}: its mounting (lever arm '
            f"{_v(entry.mounting.lever_arm)} m FRD) and the bag's /tf_static (lever arm "
            f'{_v(tf.lever_arm)} m FRD, rotation {angle:.2f} deg apart) disagree by more than '
            f"{LEVER_TOL} m / {ROTATION_TOL_DEG} deg; correct one of them, or drop the map's "
            'mounting to use /tf_static')


def _v(x):
    return '[' + ', '.join(f'{v:.3f}' for v in x) + ']'
