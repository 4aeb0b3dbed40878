"""A bag read through an input map with raw-sensor inputs (session/input_map.py: IMU, DVL,
pressure, pose) as the time-sorted RawMeasurement records and the RawSensorConfig that
core/identification/raw.py identify_raw takes.

Sensor messages are stamped with their header stamp, headerless commands with the bag's log
time (as the live node does); commands go through session/inputs.py CommandHolder (held on
change) and become one 'command' record each once every fed actuator has been heard. Times are
s from the earliest stamp read (``time_origin_ns``), so the filter's float times keep their
resolution. A NavSatFix input without a datum in the map is measured from its first fix
(session/raw_messages.py navsat_ned).
"""
from auv_ident.bags.reader import bag_topics, read_bag
from auv_ident.core.filter.raw import RawMeasurement
from auv_ident.offline.tf_static import merged_mountings
from auv_ident.session import raw_messages
from auv_ident.session.input_map import InputMapError, NAVSAT
from auv_ident.session.inputs import CommandHolder
from auv_ident.session.messages import header_stamp_ns
from auv_ident.session.raw_messages import navsat_origin, raw_record, RAW_TYPES


def raw_sensor_config(input_map, tf=None):
    """RawSensorConfig of the map's sensors (session/raw_messages.py raw_sensor_config), with
    ``tf`` (input name -> Mounting read from a bag's /tf_static) merged into the map's
    mountings by offline/tf_static.py's precedence."""
    return raw_messages.raw_sensor_config(input_map, merged_mountings(input_map, tf or {}))


def raw_bag_records(path, input_map, vehicle, allow_truncated=False):
    """(records, time_origin_ns) of bag ``path`` read through ``input_map`` (module docstring).

    BagError for an unreadable bag; InputMapError naming the input whose topic the bag lacks
    or records with another type, or a sensor type this reader does not convert."""
    input_map.check_topics(bag_topics(path, allow_truncated=allow_truncated), path)
    by_topic = {e.bag_topic: e for e in input_map.inputs}
    for e in input_map.sensors:
        if e.type not in RAW_TYPES:
            raise InputMapError(f'input {e.name!r} ({e.type}): not read from a bag yet; '
                                'raw sensors read: ' + ', '.join(RAW_TYPES))
    holder = CommandHolder.of(input_map, vehicle)
    raw = []                                       # (stamp_ns, order, entry, msg | u)
    for k, (topic, log_ns, msg) in enumerate(
            read_bag(path, input_map.topic_types, allow_truncated=allow_truncated)):
        e = by_topic[topic]
        stamp = header_stamp_ns(msg) if e.stamped else None
        stamp = log_ns if stamp is None else stamp
        if e.role == 'command':
            u = holder.update(e, msg, stamp)
            if u is not None:
                raw.append((stamp, k, None, u))
        elif e.role == 'sensor':
            raw.append((stamp, k, e, msg))
    if not raw:
        return [], 0
    raw.sort(key=lambda r: (r[0], r[1]))
    t0 = raw[0][0]
    origins = {}                                   # NavSatFix input -> its first fix
    records = []
    for s, _, e, m in raw:
        if e is None:
            records.append(RawMeasurement('command', (s - t0) * 1e-9, m))
            continue
        if e.type == NAVSAT and e.name not in origins:
            origin = navsat_origin(e, m)
            if origin is not None:
                origins[e.name] = origin
        records.append(raw_record(e, m, (s - t0) * 1e-9, origins.get(e.name)))
    return records, t0
