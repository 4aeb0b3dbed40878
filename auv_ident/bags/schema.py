"""Rosbag2 (Jazzy) conventions shared by the bag writer and reader: message type names,
message definitions and type hashes from the installed interface packages, QoS profiles,
and :class:`BagError`.


Layout written (that of Jazzy's rosbag2 with the MCAP storage plugin, which ``ros2 bag play``
expects)::

    <bag>/metadata.yaml       rosbag2_bagfile_information, version 9
    <bag>/<bag>_0.mcap        profile 'ros2'; one Schema per type: name 'pkg/msg/Type',
                              encoding 'ros2msg', data = rosbag2's full message definition
                              text; one Channel per topic: message_encoding 'cdr', metadata
                              'offered_qos_profiles' (YAML) and 'topic_type_hash' (RIHS01_...);
                              a 'rosbag2' Metadata record (serialized_metadata); Statistics.

Message definitions and type hashes come from the installed interface packages
(``<prefix>/share/<pkg>/msg/<Type>.msg`` and ``.json``), exactly as rosbag2 reads them.
"""
import functools
import json
import numbers
import os
from pathlib import Path
import re
import sys

import yaml

from auv_ident.core.errors import AuvIdentError

METADATA_VERSION = 9
ROS_DISTRO = 'jazzy'
MCAP_MAGIC = b'\x89MCAP0\r\n'
DEFAULT_CHUNK_SIZE = 64 * 1024
"""Bytes of uncompressed records per chunk (rosbag2 uses 768 KiB). A killed writer loses at
most the chunk in progress: 64 KiB is ~0.3 s of 200 Hz Odometry + JointState + Clock."""

_INFINITE = {'sec': 9223372036, 'nsec': 854775807}  # RMW_DURATION_INFINITE, as rosbag2 writes it
DEFAULT_QOS = {
    'history': 'keep_last',
    'depth': 10,
    'reliability': 'reliable',
    'durability': 'volatile',
    'deadline': dict(_INFINITE),
    'lifespan': dict(_INFINITE),
    'liveliness': 'automatic',
    'liveliness_lease_duration': dict(_INFINITE),
    'avoid_ros_namespace_conventions': False,
}
_QOS_ENUMS = {
    'history': ('system_default', 'keep_last', 'keep_all', 'unknown'),
    'reliability': ('system_default', 'reliable', 'best_effort', 'best_available', 'unknown'),
    'durability': ('system_default', 'transient_local', 'volatile', 'best_available', 'unknown'),
    'liveliness': ('system_default', 'automatic', 'manual_by_topic', 'best_available',
                   'unknown'),
}
_QOS_DURATIONS = ('deadline', 'lifespan', 'liveliness_lease_duration')

# rosbag2's dependency scan of .msg text (local_message_definition_source.cpp).
_MSG_FIELD_TYPE_RE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
_PRIMITIVES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
    'uint32', 'int64', 'uint64', 'string'))
_SEPARATOR = '=' * 80
_NAME_RE = re.compile(r'^([a-zA-Z][a-zA-Z0-9_]*)/(?:([a-zA-Z][a-zA-Z0-9_]*)/)?'
                      r'([a-zA-Z][a-zA-Z0-9_]*)$')

_FOOTER_LEN = 1 + 8 + 8 + 8 + 4  # opcode, record length, summary_start, summary_offset, crc


class BagError(AuvIdentError, ValueError):
    """A bag cannot be written or read; the message names the path and, if any, the topic."""


# ---------------------------------------------------------------------------------------------
# message definitions, type hashes, QoS


def _split_type(msgtype):
    """Return (package, namespace, name) of 'pkg/msg/Type' or 'pkg/Type'."""
    m = _NAME_RE.match(msgtype) if isinstance(msgtype, str) else None
    if not m:
        raise BagError(f'invalid message type {msgtype!r}; expected e.g. nav_msgs/msg/Odometry')
    return m.group(1), m.group(2) or 'msg', m.group(3)


def normalize_msgtype(msgtype):
    """Return 'pkg/msg/Type' for 'pkg/Type' or 'pkg/msg/Type'."""
    return '/'.join(_split_type(msgtype))


def _share_dirs():
    dirs = [Path(sys.prefix) / 'share']
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / 'share')
    return dirs


def _interface_file(msgtype, suffix):
    pkg, ns, name = _split_type(msgtype)
    for share in _share_dirs():
        candidate = share / pkg / ns / f'{name}{suffix}'
        if candidate.is_file():
            return candidate
    return None


@functools.lru_cache(maxsize=None)
def _msg_text(msgtype):
    path = _interface_file(msgtype, '.msg')
    if path is None:
        raise BagError(f'no .msg definition for {msgtype!r} under '
                       f'{[str(d) for d in _share_dirs()]}')
    # Bytes as they are on disk (no newline translation), as rosbag2 reads them.
    return path.read_bytes().decode('utf-8')


def _msg_dependencies(text, package):
    deps = set()
    for m in _MSG_FIELD_TYPE_RE.finditer(text):
        name = m.group(1)
        if name in _PRIMITIVES:
            continue
        deps.add(name if '/' in name else f'{package}/{name}')
    return sorted(deps)  # std::set order


@functools.lru_cache(maxsize=None)
def message_definition(msgtype):
    """Return rosbag2's full 'ros2msg' definition text of ``msgtype``.

    The root .msg text, then for each dependency not yet written (sorted, depth first)
    ``'\\n' + '=' * 80 + '\\nMSG: pkg/Type\\n' + its text``.
    """
    seen = set()

    def append_recursive(name, depth):
        if depth <= 0:
            raise BagError(f'message definition of {msgtype!r} nests too deeply')
        text = _msg_text(name)
        result = text
        for dep in _msg_dependencies(text, _split_type(name)[0]):
            if dep not in seen:
                seen.add(dep)
                result += f'\n{_SEPARATOR}\nMSG: {dep}\n' + append_recursive(dep, depth - 1)
        return result

    return append_recursive(normalize_msgtype(msgtype), 50)


@functools.lru_cache(maxsize=None)
def type_hash(msgtype):
    """Return the RIHS01 type hash of ``msgtype`` from its installed .json, or '' if unknown."""
    full = normalize_msgtype(msgtype)
    path = _interface_file(full, '.json')
    if path is None:
        return ''
    try:
        for entry in json.loads(path.read_text())['type_hashes']:
            if entry['type_name'] == full:
                return entry['hash_string']
    except (ValueError, KeyError, TypeError):
        return ''
    return ''


def _duration_dict(value, key):
    if isinstance(value, dict):
        try:
            return {'sec': int(value['sec']), 'nsec': int(value['nsec'])}
        except (KeyError, TypeError, ValueError) as err:
            raise BagError(f'QoS {key} must be {{sec, nsec}}, got {value!r}') from err
    ns = getattr(value, 'nanoseconds', value)  # rclpy Duration or integer ns
    if not isinstance(ns, numbers.Integral):
        raise BagError(f'QoS {key} must be a Duration, int ns or {{sec, nsec}}, got {value!r}')
    sec, nsec = divmod(int(ns), 1_000_000_000)
    return {'sec': sec, 'nsec': nsec}


def qos_to_dict(qos=None):
    """Return the rosbag2 v9 dict of one QoS profile.

    ``qos`` is None (:data:`DEFAULT_QOS`), an rclpy ``QoSProfile`` (e.g. from
    ``get_publishers_info_by_topic``) or a dict with some of DEFAULT_QOS's keys.
    """
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in DEFAULT_QOS.items()}
    if qos is None:
        return out
    if isinstance(qos, dict):
        unknown = set(qos) - set(DEFAULT_QOS)
        if unknown:
            raise BagError(f'unknown QoS keys {sorted(unknown)}; known: {list(DEFAULT_QOS)}')
        items = qos.items()
    else:
        try:
            items = [(k, getattr(qos, k)) for k in DEFAULT_QOS]
        except AttributeError as err:
            raise BagError(
                f'QoS must be None, a dict or an rclpy QoSProfile, got {qos!r}') from err
    for key, value in items:
        if key in _QOS_ENUMS:
            name = getattr(value, 'name', value)  # rclpy policy enums: KEEP_LAST -> keep_last
            name = str(name).lower()
            if name not in _QOS_ENUMS[key]:
                raise BagError(f'QoS {key} {value!r} not one of {_QOS_ENUMS[key]}')
            out[key] = name
        elif key in _QOS_DURATIONS:
            out[key] = _duration_dict(value, key)
        elif key == 'depth':
            out[key] = int(value)
        else:
            out[key] = bool(value)
    return out


def _qos_list(qos):
    if isinstance(qos, (list, tuple)):
        return [qos_to_dict(q) for q in qos]
    return [qos_to_dict(qos)]


# rmw's integer values of the policies, as rosbag2 before Jazzy (metadata version < 9) wrote them.
_RMW_POLICY_NAMES = {
    'history': {0: 'system_default', 1: 'keep_last', 2: 'keep_all', 3: 'unknown'},
    'reliability': {0: 'system_default', 1: 'reliable', 2: 'best_effort', 3: 'unknown',
                    4: 'best_available'},
    'durability': {0: 'system_default', 1: 'transient_local', 2: 'volatile', 3: 'unknown',
                   4: 'best_available'},
    'liveliness': {0: 'system_default', 1: 'automatic', 3: 'manual_by_topic', 4: 'unknown',
                   5: 'best_available'},
}


# metadata.yaml and the channels' QoS YAML come from whoever made the bag. A real rosbag2 file is
# kilobytes and has no YAML anchors; aliases let 1 KB expand to gigabytes once the values are
# turned into strings ("billion laughs"), so they are refused, and so is a file over this size.
MAX_METADATA_BYTES = 4 * 1024 * 1024


class _NoAliasLoader(yaml.SafeLoader):
    """yaml.SafeLoader that refuses aliases (``*name``): rosbag2 never writes them."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.events.AliasEvent):
            event = self.peek_event()
            raise yaml.composer.ComposerError(
                None, None, f'YAML alias *{event.anchor} (rosbag2 writes none; aliases can '
                'expand a small file without bound)', event.start_mark)
        return super().compose_node(parent, index)


def bounded_yaml(text, what, kind='YAML for a bag'):
    """Parse untrusted YAML text (at most MAX_METADATA_BYTES, no aliases); otherwise BagError
    '<what>: not a readable <kind> (<the problem and where>)'."""
    if len(text) > MAX_METADATA_BYTES:
        raise BagError(f'{what}: {len(text)} characters of YAML, more than a rosbag2 file '
                       f'holds (limit {MAX_METADATA_BYTES})')
    try:
        return yaml.load(text, Loader=_NoAliasLoader)   # a SafeLoader that refuses aliases
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = '' if mark is None else f' at line {mark.line + 1}, column {mark.column + 1}'
        problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
        raise BagError(f'{what}: not a readable {kind} ({problem}{where})') from exc


def read_metadata(bag_dir):
    """rosbag2_bagfile_information of ``bag_dir/metadata.yaml`` (dict), None when the bag has no
    metadata.yaml; BagError naming the file when it is unreadable, too large, aliased or not a
    rosbag2 metadata file."""
    meta = Path(bag_dir) / 'metadata.yaml'
    if not meta.is_file():
        return None
    try:
        size = meta.stat().st_size
        if size > MAX_METADATA_BYTES:
            raise BagError(f'{meta}: {size} bytes, more than a rosbag2 metadata.yaml holds '
                           f'(limit {MAX_METADATA_BYTES})')
        text = meta.read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as exc:
        raise BagError(f'{meta}: not a readable rosbag2 metadata.yaml '
                       f'({type(exc).__name__}: {exc})') from exc
    doc = bounded_yaml(text, str(meta), 'rosbag2 metadata.yaml')
    info = doc.get('rosbag2_bagfile_information') if isinstance(doc, dict) else None
    if not isinstance(info, dict):
        raise BagError(f'{meta}: not a rosbag2 metadata.yaml (no rosbag2_bagfile_information '
                       'mapping)')
    return info


def custom_data_of(info, where='metadata.yaml'):
    """custom_data of a rosbag2_bagfile_information dict as {str: str} (rosbag2 stores a map of
    strings); BagError naming the key whose value is a list or a mapping."""
    data = info.get('custom_data') or {}
    if not isinstance(data, dict):
        raise BagError(f'{where}: custom_data is a {type(data).__name__}, not a mapping')
    bad = [str(k) for k, v in data.items() if isinstance(v, (dict, list))]
    if bad:
        raise BagError(f'{where}: custom_data value of {bad[0]!r} is not a string '
                       '(rosbag2 custom_data maps strings to strings)')
    return {str(k): '' if v is None else str(v) for k, v in data.items()}


def qos_from_yaml(text):
    """Return the v9 QoS dicts of a rosbag2 ``offered_qos_profiles`` YAML (a channel's metadata
    or an older metadata.yaml's string): v9 names, or the integer policies of versions < 9."""
    profiles = bounded_yaml(text, 'offered_qos_profiles', 'QoS profile list') if text else []
    if profiles is None:
        return []
    if not isinstance(profiles, list) or not all(isinstance(p, dict) for p in profiles):
        raise BagError(f'offered_qos_profiles is not a list of profiles: {text!r}')
    out = []
    for profile in profiles:
        named = {}
        for key, value in profile.items():
            if key in _RMW_POLICY_NAMES and isinstance(value, int):
                value = _RMW_POLICY_NAMES[key].get(value, 'unknown')
            named[key] = value
        out.append(qos_to_dict({k: v for k, v in named.items() if k in DEFAULT_QOS}))
    return out


def qos_yaml(profiles):
    """Return the channel-metadata YAML of a list of v9 QoS dicts, as yaml-cpp dumps it."""
    return yaml.safe_dump(list(profiles), sort_keys=False, default_flow_style=False).rstrip('\n')


_dump = functools.partial(yaml.safe_dump, sort_keys=False, default_flow_style=False)


def bagfile_information(files, topics, custom_data=None):
    """Return rosbag2's v9 ``rosbag2_bagfile_information`` dict.

    Parameters
    ----------
    files : list of (name, span, message_count)
        One entry per data file in bag order; span = (first, last) log time (ns), or None for
        a file without messages.
    topics : list of dict
        Keys name, type ('pkg/msg/Type'), qos (list of v9 QoS dicts), hash (RIHS01_... or '')
        and count.
    custom_data : dict of str, optional
    """
    spans = [span for _, span, _ in files if span is not None]
    start = min(s[0] for s in spans) if spans else 0
    duration = (max(s[1] for s in spans) - start) if spans else 0
    total = sum(n for _, _, n in files)
    return {
        'version': METADATA_VERSION,
        'storage_identifier': 'mcap',
        'duration': {'nanoseconds': duration},
        'starting_time': {'nanoseconds_since_epoch': start},
        'message_count': total,
        'topics_with_message_count': [
            {'topic_metadata': {'name': t['name'],
                                'type': t['type'],
                                'serialization_format': 'cdr',
                                'offered_qos_profiles': t['qos'],
                                'type_description_hash': t['hash']},
             'message_count': t['count']}
            for t in topics],
        # Chunk compression is storage-internal: rosbag2 leaves these empty for it too.
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [name for name, _, _ in files],
        'files': [{'path': name,
                   'starting_time': {'nanoseconds_since_epoch': span[0] if span else 0},
                   'duration': {'nanoseconds': (span[1] - span[0]) if span else 0},
                   'message_count': n}
                  for name, span, n in files],
        'custom_data': dict(custom_data or {}) or None,
        'ros_distro': ROS_DISTRO,
    }


def write_metadata_yaml(bag_dir, info):
    """Write ``bag_dir/metadata.yaml`` of a bagfile_information dict, atomically."""
    meta = Path(bag_dir) / 'metadata.yaml'
    tmp = Path(bag_dir) / 'metadata.yaml.tmp'
    tmp.write_text(_dump({'rosbag2_bagfile_information': info}), encoding='utf-8')
    os.replace(tmp, meta)  # a reader never sees a half-written metadata.yaml
