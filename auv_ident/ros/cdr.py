"""Reading nav_msgs/Odometry and sensor_msgs/Imu straight from their CDR bytes (raw
subscriptions).

rclpy turns every received Odometry into a tree of Python message objects (measured 39 us per
message: deserialize_message(bytes, Odometry)); the identifier needs 13 numbers, two strings
and the covariances. :class:`OdometryView` reads them from the serialized payload with
struct (about 2 us) into one preallocated object tree that has the attribute paths of
nav_msgs/Odometry, so the session reads it like a message.

Layout (XCDR1, what Fast DDS sends for ROS 2 messages): 4-byte encapsulation header
(00 01 = little endian, 00 00 = big endian), then, aligned relative to the byte after it:
header.stamp.sec int32, nanosec uint32, header.frame_id (uint32 length incl. NUL, bytes),
child_frame_id (align 4, same), pose.pose.position x y z, orientation x y z w, pose.covariance
36 (align 8, float64), twist.twist.linear x y z, angular x y z, twist.covariance 36. Other
encapsulations (XCDR2) and malformed payloads are left to rclpy's deserialize_message (the
identifier's on_odom_payload); bytes that neither reads become an :class:`UndecodableMessage`,
which the session rejects as a conversion error like any message without Odometry fields.

sensor_msgs/Imu (:class:`ImuView`, the raw-sensor path's 400 Hz stream; rclpy's conversion
measured ~30 us): the same header, then (align 8) orientation x y z w, orientation_covariance 9,
angular_velocity x y z, angular_velocity_covariance 9, linear_acceleration x y z,
linear_acceleration_covariance 9, all float64.
"""
import copy
import struct

import numpy as np

_LE = (struct.Struct('<iiI'), struct.Struct('<I'), struct.Struct('<7d'), struct.Struct('<6d'),
       np.dtype('<f8'))
_BE = (struct.Struct('>iiI'), struct.Struct('>I'), struct.Struct('>7d'), struct.Struct('>6d'),
       np.dtype('>f8'))
_SIZE = 4 + 8 + 4 + 4 + 56 + 288 + 48 + 288   # without the strings' bytes and padding


class _Fields:
    __slots__ = ('x', 'y', 'z', 'w', 'sec', 'nanosec', 'frame_id', 'stamp', 'position',
                 'orientation', 'linear', 'angular', 'pose', 'twist', 'covariance')


class OdometryView:
    """One nav_msgs/Odometry's fields, refilled by :meth:`read` for every message."""
    __slots__ = ('header', 'child_frame_id', 'pose', 'twist')

    def __init__(self):
        self.header = _Fields()
        self.header.stamp = _Fields()
        self.header.frame_id = ''
        self.child_frame_id = ''
        self.pose = _Fields()
        self.pose.pose = _Fields()
        self.pose.pose.position = _Fields()
        self.pose.pose.orientation = _Fields()
        self.twist = _Fields()
        self.twist.twist = _Fields()
        self.twist.twist.linear = _Fields()
        self.twist.twist.angular = _Fields()

    def read(self, payload):
        """Fill the view from CDR bytes; False if they are not XCDR1 or too short."""
        got = _header(payload, _SIZE)
        if got is None:
            return False
        fmt, frame_id, o = got
        head, length, pose7, twist6, f8 = fmt
        (n,) = length.unpack_from(payload, o)
        o += 4
        child = payload[o:o + n - 1]
        o += n
        o += -(o - 4) % 8
        if n == 0 or o + 680 > len(payload):
            return False
        stamp = self.header.stamp
        stamp.sec, stamp.nanosec = head.unpack_from(payload, 4)[:2]
        self.header.frame_id = frame_id.decode('utf-8', 'replace')
        self.child_frame_id = child.decode('utf-8', 'replace')
        p, q = self.pose.pose.position, self.pose.pose.orientation
        p.x, p.y, p.z, q.x, q.y, q.z, q.w = pose7.unpack_from(payload, o)
        self.pose.covariance = np.frombuffer(payload, f8, 36, o + 56)
        lin, ang = self.twist.twist.linear, self.twist.twist.angular
        lin.x, lin.y, lin.z, ang.x, ang.y, ang.z = twist6.unpack_from(payload, o + 344)
        self.twist.covariance = np.frombuffer(payload, f8, 36, o + 392)
        return True


def _header(payload, size):
    """(formats, frame_id bytes, offset after it aligned to 4) of a std_msgs/Header at the
    start of XCDR1 ``payload`` of at least ``size`` bytes; None if it is not that."""
    if len(payload) < size or payload[0] != 0 or payload[1] not in (0, 1):
        return None
    fmt = _LE if payload[1] == 1 else _BE
    n = fmt[0].unpack_from(payload, 4)[2]
    o = 16 + n
    frame_id = payload[16:o - 1]
    o += -(o - 4) % 4
    if n == 0 or o + 4 > len(payload):
        return None
    return fmt, frame_id, o


_IMU_SIZE = 4 + 8 + 4 + 296     # without frame_id's bytes and padding


class ImuView:
    """One sensor_msgs/Imu's fields, refilled by :meth:`read` for every message (the
    attribute paths of the message; the covariances are float64 arrays over the payload)."""
    __slots__ = ('header', 'orientation', 'orientation_covariance', 'angular_velocity',
                 'angular_velocity_covariance', 'linear_acceleration',
                 'linear_acceleration_covariance')

    def __init__(self):
        self.header = _Fields()
        self.header.stamp = _Fields()
        self.header.frame_id = ''
        self.orientation = _Fields()
        self.angular_velocity = _Fields()
        self.linear_acceleration = _Fields()

    def read(self, payload):
        """Fill the view from CDR bytes; False if they are not XCDR1 or too short."""
        got = _header(payload, _IMU_SIZE)
        if got is None:
            return False
        (head, _, pose7, twist6, f8), frame_id, o = got
        o += -(o - 4) % 8
        if o + 296 > len(payload):
            return False
        stamp = self.header.stamp
        stamp.sec, stamp.nanosec = head.unpack_from(payload, 4)[:2]
        self.header.frame_id = frame_id.decode('utf-8', 'replace')
        q, w, a = self.orientation, self.angular_velocity, self.linear_acceleration
        q.x, q.y, q.z, q.w = pose7.unpack_from(payload, o)[:4]
        self.orientation_covariance = np.frombuffer(payload, f8, 9, o + 32)
        w.x, w.y, w.z = twist6.unpack_from(payload, o + 104)[:3]
        self.angular_velocity_covariance = np.frombuffer(payload, f8, 9, o + 128)
        a.x, a.y, a.z = twist6.unpack_from(payload, o + 200)[:3]
        self.linear_acceleration_covariance = np.frombuffer(payload, f8, 9, o + 224)
        return True


class UndecodableMessage:
    """Stands for a payload no reader could decode (``reason``): it has none of the fields of a
    message, so IdentSession rejects it as a conversion error naming this class."""
    __slots__ = ('reason',)

    def __init__(self, reason):
        self.reason = reason


_STAMP = struct.Struct('<iI')
_SENTINEL_STAMP = (0x1A2B3C4D, 0x0E5F6A7B)


class PayloadTemplate:
    """A message's serialized bytes, refilled in place: the header stamp and fixed-size
    float64 arrays, so a publish sends bytes (``publish(bytes)``) instead of rclpy converting
    the Python message to C and serializing it (the identifier's estimate, covariance and current:
    80 -> 41 us of CPU per update for the three, tools/node_cost.py; the bytes path costs a copy).

    ``msg``: the message with every other field as it will be published (``stamped``: its
    first field is a std_msgs/Header, whose stamp is refilled too); ``arrays``: (setter,
    length) pairs, setter(msg, values) putting `length` float64 values into the message. The
    template serializes the message once with random values in each array and the sentinel
    stamp, and finds each one's bytes (little-endian XCDR1, what rclpy writes on this host);
    :meth:`build` returns None if a place is not found exactly once (the caller then
    publishes the message itself)."""
    __slots__ = ('buffer', 'view', 'offsets', 'stamped')

    def __init__(self, buffer, offsets, stamped):
        self.buffer = buffer
        self.stamped = stamped
        # writes go through a view: one of another length raises instead of resizing
        self.view = memoryview(buffer)
        self.offsets = offsets

    @classmethod
    def build(cls, msg, arrays, serialize, stamped=True):
        if stamped and not hasattr(msg, 'header'):
            return None
        rng = np.random.default_rng(0x5EED)
        marks = []
        for setter, length in arrays:
            values = rng.uniform(1.0, 2.0, length)
            setter(msg, values)
            marks.append(values.astype('<f8').tobytes())
        if stamped:
            msg.header.stamp.sec, msg.header.stamp.nanosec = _SENTINEL_STAMP
        payload = serialize(msg)
        if payload[:2] != b'\x00\x01' or (
                stamped and payload[4:12] != _STAMP.pack(*_SENTINEL_STAMP)):
            return None
        offsets = []
        for mark in marks:
            at = payload.find(mark)
            if at < 0 or (mark and payload.find(mark, at + 1) >= 0):
                return None
            offsets.append((at, at + len(mark)))
        return cls(bytearray(payload), offsets, stamped)

    def fill(self, sec, nanosec, *arrays):
        """The payload with this stamp (ignored if not stamped) and arrays (float64 arrays of
        the template's lengths, in its order) as bytes for ``Publisher.publish``."""
        if self.stamped:
            _STAMP.pack_into(self.buffer, 4, sec, nanosec)
        view = self.view
        for (a, b), values in zip(self.offsets, arrays):
            view[a:b] = np.ascontiguousarray(values, dtype='<f8').data.cast('B')
        return bytes(self.buffer)


def _setter(name):
    """setter(msg, values) of a float64 array field of a message (PayloadTemplate.build)."""
    return lambda m, v: setattr(m, name, v.tolist())


def estimate_templates(estimate, covariance, p, serialize):
    """(~/estimate, ~/covariance) PayloadTemplates of a p-coefficient estimate: a JointState
    whose position and velocity hold p values, and a Float64MultiArray of p*p, each laid out
    (names, dimensions) as the messages given (copied); None for one that cannot be built."""
    return (PayloadTemplate.build(copy.deepcopy(estimate), [(_setter('position'), p),
                                                            (_setter('velocity'), p)], serialize),
            PayloadTemplate.build(copy.deepcopy(covariance), [(_setter('data'), p * p)],
                                  serialize, stamped=False))
