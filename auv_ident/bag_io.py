"""Rosbag2 (Jazzy) MCAP bags without rosbag2: writer and reader.

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

Reading decodes with rosbags (fast) using the definitions stored in the bag, and falls back to
rclpy for payloads rosbags rejects: rclpy/Fast-CDR pads messages that end with an empty float64
sequence (JointState with empty effort) by up to 8 bytes, which rosbags calls a size mismatch.
Every message is yielded as a rosbags message object (attribute access like rclpy messages;
arrays are numpy arrays), or as raw CDR bytes with ``raw=True``.

All bad input raises :class:`BagError` naming the path (and topic where it applies).
"""
import atexit
from collections.abc import Mapping
import functools
import heapq
import importlib
import json
import numbers
import os
from pathlib import Path
import re
import struct
import sys
import threading
import warnings
import weakref
import zlib

from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import breakup_chunk, StreamReader
from mcap.writer import CompressionType
# Why mcap.writer.Writer and not rosbags.rosbag2.Writer: rosbags writes its own comment-less
# message definitions, no 'topic_type_hash' channel metadata and a fixed 1 MiB chunk held in
# memory; mcap's Writer takes our rosbag2-exact schema text and channel metadata verbatim, a
# chunk size of our choosing, and has a public flush() that closes the chunk in progress.
from mcap.writer import Writer as McapWriter
import numpy as np
from rosbags.typesys import get_typestore, get_types_from_msg, Stores
from rosbags.typesys.base import Nodetype
import yaml

from auv_ident import __version__
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
        except (KeyError, TypeError, ValueError):
            raise BagError(f'QoS {key} must be {{sec, nsec}}, got {value!r}') from None
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
        except AttributeError:
            raise BagError(
                f'QoS must be None, a dict or an rclpy QoSProfile, got {qos!r}') from None
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


def qos_yaml(profiles):
    """Return the channel-metadata YAML of a list of v9 QoS dicts, as yaml-cpp dumps it."""
    return yaml.safe_dump(list(profiles), sort_keys=False, default_flow_style=False).rstrip('\n')


# ---------------------------------------------------------------------------------------------
# writer


def _close_if_alive(ref):
    writer = ref()
    if writer is not None:
        writer.close()


class _Topic:
    __slots__ = ('name', 'msgtype', 'channel_id', 'qos', 'hash', 'count')

    def __init__(self, name, msgtype, channel_id, qos, hash_string):
        self.name = name
        self.msgtype = msgtype
        self.channel_id = channel_id
        self.qos = qos
        self.hash = hash_string
        self.count = 0


def _rclpy_msgtype(msg):
    """Return 'pkg/msg/Type' of an rclpy message instance."""
    parts = type(msg).__module__.split('.')
    if len(parts) < 2 or not hasattr(type(msg), 'get_fields_and_field_types'):
        raise BagError(f'{type(msg).__name__} is not an rclpy ROS message')
    return f'{parts[0]}/{parts[1]}/{type(msg).__name__}'


class BagWriter:
    """Write a rosbag2 (Jazzy, MCAP, metadata v9) bag directory.

    Parameters
    ----------
    path : str or Path
        Bag directory to create; must not exist. The data file is ``<path>/<name>_0.mcap``.
    compression : {None, 'zstd'}
        Chunk compression (rosbag2's storage-level compression; metadata.yaml then says
        ``compression_format: ''`` as rosbag2 does for it).
    chunk_size : int
        Uncompressed bytes per chunk, see :data:`DEFAULT_CHUNK_SIZE`.

    Crash behaviour: every completed chunk is handed to the OS at once, so a killed process
    (even SIGKILL) leaves a file whose complete chunks ``read_bag(..., allow_truncated=True)``
    recovers; only ``close()`` writes the summary and metadata.yaml. :meth:`flush` closes the
    chunk in progress early (call it periodically to bound the loss in time, not only size).
    ``close()`` is idempotent, thread-safe, runs on leaving a ``with`` block (also on an
    exception) and at interpreter exit; SIGINT/SIGTERM handlers must let a ``finally:`` call it
    (rclpy turns both into exceptions, see shared/ros_stack.md section 2).
    """

    def __init__(self, path, compression=None, chunk_size=DEFAULT_CHUNK_SIZE):
        self.path = Path(path)
        if compression not in (None, 'zstd'):
            raise BagError(f'{self.path}: compression must be None or \'zstd\', '
                           f'got {compression!r}')
        if self.path.exists():
            raise BagError(f'{self.path}: bag path exists already, not overwriting')
        self.compression = compression
        self._lock = threading.Lock()
        self._closed = True
        self._topics = {}
        self._schema_ids = {}
        self._custom_data = {}
        self._t_min = None
        self._t_max = None
        self._count = 0
        try:
            self.path.mkdir(parents=True)
            self.mcap_path = self.path / f'{self.path.absolute().name}_0.mcap'
            self._fh = open(self.mcap_path, 'xb')
        except OSError as exc:
            raise BagError(f'{self.path}: cannot create bag: {exc}') from None
        self._writer = McapWriter(
            self._fh, chunk_size=int(chunk_size),
            compression=CompressionType.ZSTD if compression else CompressionType.NONE)
        self._writer.start(profile='ros2', library=f'auv_ident {__version__}; mcap-python')
        self._fh.flush()
        self._closed = False
        self._atexit = functools.partial(_close_if_alive, weakref.ref(self))
        atexit.register(self._atexit)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        self.close()
        return False

    @property
    def message_count(self):
        """Messages written so far."""
        return self._count

    @property
    def closed(self):
        """True once close() has run."""
        return self._closed

    def _check_open(self):
        if self._closed:
            raise BagError(f'{self.path}: bag writer is closed')

    def set_custom_data(self, key, value):
        """Store a string pair in metadata.yaml's custom_data (rosbag2 v6+)."""
        if not isinstance(key, str) or not isinstance(value, str):
            raise BagError(f'{self.path}: custom_data key and value must be str, '
                           f'got {key!r}: {value!r}')
        self._custom_data[key] = value

    def add_topic(self, topic, msgtype, qos=None):
        """Register ``topic`` with type ``msgtype`` ('pkg/msg/Type').

        ``qos``: the publishers' offered QoS: None (:data:`DEFAULT_QOS`), a dict, an rclpy
        QoSProfile, or a list of those (one per publisher, as rosbag2 records them). Adding a
        topic again with the same type does nothing; with another type raises BagError.
        """
        if not isinstance(topic, str) or not topic.startswith('/') or topic.endswith('/'):
            raise BagError(f'{self.path}: topic name must be absolute, e.g. /odom; '
                           f'got {topic!r}')
        try:
            full = normalize_msgtype(msgtype)
        except BagError as exc:
            raise BagError(f'{self.path}: topic {topic}: {exc}') from None
        with self._lock:
            self._check_open()
            known = self._topics.get(topic)
            if known is not None:
                if known.msgtype != full:
                    raise BagError(f'{self.path}: topic {topic} already has type '
                                   f'{known.msgtype}, cannot add it as {full}')
                return
            try:
                profiles = _qos_list(qos)
                definition = message_definition(full)
            except BagError as exc:
                raise BagError(f'{self.path}: topic {topic}: {exc}') from None
            schema_id = self._schema_ids.get(full)
            if schema_id is None:
                schema_id = self._writer.register_schema(
                    name=full, encoding='ros2msg', data=definition.encode('utf-8'))
                self._schema_ids[full] = schema_id
            hash_string = type_hash(full)
            channel_id = self._writer.register_channel(
                topic=topic, message_encoding='cdr', schema_id=schema_id,
                metadata={'offered_qos_profiles': qos_yaml(profiles),
                          'topic_type_hash': hash_string})
            self._topics[topic] = _Topic(topic, full, channel_id, profiles, hash_string)

    def write(self, topic, t_ns, payload):
        """Write one CDR payload (bytes as rclpy serialize_message or DDS give them).

        ``t_ns`` (int ns) is both the MCAP log time (rosbag2: receive time) and publish time.
        """
        if isinstance(t_ns, bool) or not isinstance(t_ns, numbers.Integral) or t_ns < 0:
            raise BagError(f'{self.path}: topic {topic}: time must be a non-negative int of '
                           f'nanoseconds, got {t_ns!r}')
        if not isinstance(payload, (bytes, bytearray, memoryview)):
            raise BagError(f'{self.path}: topic {topic}: payload must be CDR bytes, '
                           f'got {type(payload).__name__}')
        data = bytes(payload)
        # CDR encapsulation header: 00 00 (big endian) or 00 01 (little endian), 2 option bytes.
        if len(data) < 4 or data[0] != 0 or data[1] > 1:
            start = data[:4].hex() or 'empty'
            raise BagError(f'{self.path}: topic {topic}: payload is not CDR (starts {start})')
        t_ns = int(t_ns)
        with self._lock:
            self._check_open()
            info = self._topics.get(topic)
            if info is None:
                raise BagError(f'{self.path}: topic {topic} was not added; added topics: '
                               f'{sorted(self._topics)}')
            self._writer.add_message(channel_id=info.channel_id, log_time=t_ns,
                                     publish_time=t_ns, sequence=info.count, data=data)
            info.count += 1
            self._count += 1
            self._t_min = t_ns if self._t_min is None else min(self._t_min, t_ns)
            self._t_max = t_ns if self._t_max is None else max(self._t_max, t_ns)
            # Hands a just-completed chunk to the OS, so that a kill cannot lose it; a no-op
            # (cheap) while the chunk is still being filled in memory.
            self._fh.flush()

    def write_msg(self, topic, t_ns, msg):
        """Serialize an rclpy message and write it; adds the topic (default QoS) if new."""
        from rclpy.serialization import serialize_message
        try:
            msgtype = _rclpy_msgtype(msg)
        except BagError as exc:
            raise BagError(f'{self.path}: topic {topic}: {exc}') from None
        known = self._topics.get(topic)
        if known is None:
            self.add_topic(topic, msgtype)
        elif known.msgtype != msgtype:
            raise BagError(f'{self.path}: topic {topic} has type {known.msgtype}, '
                           f'got a {msgtype} message')
        self.write(topic, t_ns, serialize_message(msg))

    def flush(self):
        """Close the chunk in progress and hand everything written so far to the OS.

        A no-op once closed, so a periodic flush timer may race with close().
        """
        with self._lock:
            if not self._closed:
                self._writer.flush()

    def _metadata(self):
        start = self._t_min if self._t_min is not None else 0
        duration = (self._t_max - self._t_min) if self._t_min is not None else 0
        name = self.mcap_path.name
        return {
            'version': METADATA_VERSION,
            'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': self._count,
            'topics_with_message_count': [
                {'topic_metadata': {'name': t.name,
                                    'type': t.msgtype,
                                    'serialization_format': 'cdr',
                                    'offered_qos_profiles': t.qos,
                                    'type_description_hash': t.hash},
                 'message_count': t.count}
                for t in self._topics.values()],
            # Chunk compression is storage-internal: rosbag2 leaves these empty for it too.
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [name],
            'files': [{'path': name,
                       'starting_time': {'nanoseconds_since_epoch': start},
                       'duration': {'nanoseconds': duration},
                       'message_count': self._count}],
            'custom_data': dict(self._custom_data) or None,
            'ros_distro': ROS_DISTRO,
        }

    def close(self):
        """Finish the MCAP file (summary, statistics) and write metadata.yaml; idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            atexit.unregister(self._atexit)
            info = self._metadata()
            dump = functools.partial(yaml.safe_dump, sort_keys=False, default_flow_style=False)
            try:
                self._writer.add_metadata('rosbag2', {'serialized_metadata': dump(info)})
                self._writer.finish()
                self._fh.close()
                meta = self.path / 'metadata.yaml'
                tmp = self.path / 'metadata.yaml.tmp'
                tmp.write_text(dump({'rosbag2_bagfile_information': info}), encoding='utf-8')
                os.replace(tmp, meta)  # a reader never sees a half-written metadata.yaml
            except OSError as exc:
                raise BagError(f'{self.path}: cannot finish bag: {exc}') from None
            finally:
                if not self._fh.closed:
                    self._fh.close()


# ---------------------------------------------------------------------------------------------
# reader


def _bag_files(path):
    """Return the .mcap files of a bag directory or a bare .mcap file."""
    p = Path(path)
    if not p.exists():
        raise BagError(f'{p}: no such bag (path does not exist)')
    if p.is_file():
        return [p]
    meta = p / 'metadata.yaml'
    if meta.is_file():
        try:
            doc = yaml.safe_load(meta.read_text(encoding='utf-8'))
            info = doc['rosbag2_bagfile_information']
            storage = info.get('storage_identifier')
            names = list(info['relative_file_paths'])
            compression_mode = info.get('compression_mode') or ''
        except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError,
                AttributeError) as exc:
            raise BagError(f'{meta}: not a readable rosbag2 metadata.yaml '
                           f'({type(exc).__name__}: {exc})') from None
        if storage != 'mcap':
            raise BagError(f'{p}: storage {storage!r} not supported, only mcap')
        if compression_mode:
            raise BagError(f'{p}: compression_mode {compression_mode!r} not supported '
                           '(only chunk compression inside the MCAP file)')
        files = [p / Path(n).name for n in names]
        missing = [str(f) for f in files if not f.is_file()]
        if missing:
            raise BagError(f'{p}: metadata.yaml lists missing file(s) {missing}')
        if not files:
            raise BagError(f'{p}: metadata.yaml lists no data files')
        return files
    mcaps = sorted(p.glob('*.mcap'))
    if mcaps:
        return mcaps  # no metadata.yaml: e.g. a recorder that was killed before close()
    if not any(p.iterdir()):
        raise BagError(f'{p}: empty directory, not a bag')
    raise BagError(f'{p}: not a bag (no metadata.yaml and no .mcap file)')


def _check_summary_crc(fh, size, path):
    """Check the end magic and the summary CRC that the footer holds (if it holds one)."""
    fh.seek(size - len(MCAP_MAGIC))
    if fh.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
        raise BagError(f'{path}: truncated or corrupted MCAP file (no end magic: the writer '
                       'did not finish it; read_bag(..., allow_truncated=True) recovers '
                       'its complete chunks)')
    fh.seek(size - len(MCAP_MAGIC) - _FOOTER_LEN)
    footer = fh.read(_FOOTER_LEN)
    opcode, length, summary_start, summary_offset, crc = struct.unpack('<BQQQI', footer)
    if opcode != 0x02 or length != 20 or summary_start > size:
        raise BagError(f'{path}: corrupted MCAP file (bad footer)')
    if crc == 0 or summary_start == 0:
        return
    fh.seek(summary_start)
    covered = fh.read(size - len(MCAP_MAGIC) - 4 - summary_start)
    if zlib.crc32(covered) != crc:
        raise BagError(f'{path}: corrupted MCAP file (summary CRC mismatch)')


class _McapFile:
    """One MCAP file: summary, topics, per-type decoders and a message iterator."""

    def __init__(self, path):
        self.path = Path(path)
        try:
            size = self.path.stat().st_size
        except OSError as exc:
            raise BagError(f'{self.path}: cannot read: {exc}') from None
        if size == 0:
            raise BagError(f'{self.path}: empty file (0 bytes), not an MCAP bag')
        self.size = size
        try:
            self.fh = open(self.path, 'rb')
        except OSError as exc:
            raise BagError(f'{self.path}: cannot read: {exc}') from None
        self.summary = None
        self.recovered = None
        self.is_mcap = False

    def close(self):
        self.fh.close()

    def open_indexed(self):
        """Read and check the summary; raise BagError if the file is not complete and sound."""
        head = self.fh.read(len(MCAP_MAGIC))
        if head != MCAP_MAGIC:
            raise BagError(f'{self.path}: not an MCAP file (bad magic {head[:8]!r})')
        self.is_mcap = True
        if self.size < 2 * len(MCAP_MAGIC) + _FOOTER_LEN:
            raise BagError(f'{self.path}: truncated MCAP file ({self.size} bytes)')
        _check_summary_crc(self.fh, self.size, self.path)
        try:
            self.fh.seek(0)
            self.reader = SeekingReader(self.fh, validate_crcs=True)
            self.reader.get_header()
            summary = self.reader.get_summary()
        except Exception as exc:  # a corrupt file can break the parser in any way
            raise BagError(f'{self.path}: corrupted MCAP file ({type(exc).__name__}: '
                           f'{exc})') from None
        if summary is None or summary.statistics is None:
            raise BagError(f'{self.path}: MCAP file has no summary/statistics (not written '
                           'by rosbag2 or this writer; read_bag(..., allow_truncated=True) '
                           'scans it linearly)')
        self.summary = summary
        self.schemas = dict(summary.schemas)
        self.channels = dict(summary.channels)

    def recover_linear(self):
        """Scan records in file order and keep messages of complete, CRC-valid chunks."""
        self.fh.seek(0)
        schemas, channels, messages = {}, {}, []
        error = None

        def keep(record):
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                messages.append(record)

        try:
            for record in StreamReader(self.fh, emit_chunks=True, validate_crcs=True).records:
                if not isinstance(record, Chunk):
                    keep(record)
                    continue
                # A short read does not raise in mcap; without a CRC only the size tells.
                if not record.compression and len(record.data) != record.uncompressed_size:
                    raise BagError('incomplete chunk')
                for inner in breakup_chunk(record, validate_crc=True):  # all or nothing
                    keep(inner)
        except Exception as exc:  # the broken tail may fail in any way; keep what came before
            error = exc
        self.schemas, self.channels = schemas, channels
        messages = [m for m in messages if m.channel_id in channels]
        messages.sort(key=lambda m: m.log_time)  # stable: file order within equal times
        self.recovered = messages
        if error is not None:
            warnings.warn(f'{self.path}: truncated or corrupted ({type(error).__name__}); '
                          f'recovered {len(messages)} messages from complete chunks',
                          stacklevel=4)

    def topics(self):
        out = {}
        for channel in self.channels.values():
            schema = self.schemas.get(channel.schema_id)
            out[channel.topic] = schema.name if schema is not None else ''
        return out

    def counts(self):
        if self.recovered is not None:
            counts = {c.topic: 0 for c in self.channels.values()}
            for m in self.recovered:
                counts[self.channels[m.channel_id].topic] += 1
            return counts
        per_channel = self.summary.statistics.channel_message_counts
        return {c.topic: int(per_channel.get(cid, 0)) for cid, c in self.channels.items()}

    def iter_raw(self, topics):
        """Yield (t_ns, topic, msgtype, payload bytes) in log-time order."""
        if self.recovered is not None:
            for m in self.recovered:
                channel = self.channels[m.channel_id]
                if topics is None or channel.topic in topics:
                    schema = self.schemas.get(channel.schema_id)
                    yield m.log_time, channel.topic, schema.name if schema else '', m.data
            return
        it = self.reader.iter_messages(topics=None if topics is None else list(topics),
                                       log_time_order=True)
        while True:
            try:
                schema, channel, message = next(it)
            except StopIteration:
                return
            except Exception as exc:  # CRC mismatch, bad compression, short read, ...
                raise BagError(f'{self.path}: corrupted MCAP chunk ({type(exc).__name__}: '
                               f'{exc})') from None
            yield message.log_time, channel.topic, schema.name if schema else '', message.data


def _open_files(path, allow_truncated):
    files = []
    try:
        for f in _bag_files(path):
            mf = _McapFile(f)
            files.append(mf)
            try:
                mf.open_indexed()
            except BagError:
                if not (allow_truncated and mf.is_mcap):
                    raise
                mf.recover_linear()
    except BaseException:
        for mf in files:
            mf.close()
        raise
    return files


def _merged_topics(files):
    out = {}
    for mf in files:
        out.update(mf.topics())
    return out


def bag_topics(path, allow_truncated=False):
    """Return ``{topic: 'pkg/msg/Type'}`` of a bag directory or .mcap file."""
    files = _open_files(path, allow_truncated)
    try:
        return _merged_topics(files)
    finally:
        for mf in files:
            mf.close()


def message_counts(path, allow_truncated=False):
    """Return ``{topic: number of messages}`` of a bag directory or .mcap file."""
    files = _open_files(path, allow_truncated)
    try:
        counts = {}
        for mf in files:
            for topic, n in mf.counts().items():
                counts[topic] = counts.get(topic, 0) + n
        return counts
    finally:
        for mf in files:
            mf.close()


# --- decoding ---

_JAZZY = None
_NUMPY_DTYPES = {
    'bool': np.bool_, 'byte': np.uint8, 'char': np.uint8, 'int8': np.int8, 'uint8': np.uint8,
    'int16': np.int16, 'uint16': np.uint16, 'int32': np.int32, 'uint32': np.uint32,
    'int64': np.int64, 'uint64': np.uint64, 'float32': np.float32, 'float64': np.float64,
}


def _jazzy_store():
    global _JAZZY
    if _JAZZY is None:
        _JAZZY = get_typestore(Stores.ROS2_JAZZY)
    return _JAZZY


def _rclpy_class(msgtype):
    pkg, ns, name = _split_type(msgtype)
    try:
        return getattr(importlib.import_module(f'{pkg}.{ns}'), name)
    except (ImportError, AttributeError):
        return None


def _from_rclpy(value, msgtype, store):
    """Return the rosbags message object equal to an rclpy message."""
    cls = store.types[msgtype]
    kwargs = {}
    for name, (node, spec) in store.fielddefs[msgtype][1]:
        if name == 'structure_needs_at_least_one_member':
            kwargs[name] = 0  # rosbags' placeholder in empty messages; rclpy has no such field
            continue
        kwargs[name] = _field_from_rclpy(getattr(value, name), node, spec, store)
    return cls(**kwargs)


def _field_from_rclpy(value, node, spec, store):
    if node == Nodetype.NAME:
        return _from_rclpy(value, spec, store)
    if node == Nodetype.BASE:
        return value
    (sub_node, sub_spec), _ = spec  # ARRAY or SEQUENCE
    if sub_node == Nodetype.BASE and sub_spec[0] in _NUMPY_DTYPES:
        if isinstance(value, (bytes, bytearray)):
            return np.frombuffer(value, dtype=np.uint8).copy()
        return np.asarray(value, dtype=_NUMPY_DTYPES[sub_spec[0]])
    return [_field_from_rclpy(v, sub_node, sub_spec, store) for v in value]


class _Decoder:
    """Decode CDR of the types in one bag: rosbags first, rclpy where rosbags refuses."""

    def __init__(self, schemas, path):
        self.path = path
        self.stores = {}
        store = get_typestore(Stores.EMPTY)
        for schema in schemas:
            name = schema.name
            if name in self.stores:
                continue
            try:
                if schema.encoding != 'ros2msg':
                    raise ValueError(f'schema encoding {schema.encoding!r}')
                store.register(get_types_from_msg(schema.data.decode('utf-8'), name))
                self.stores[name] = store
            except Exception:  # any parse/registration failure: try Jazzy's
                jazzy = _jazzy_store()
                self.stores[name] = jazzy if name in jazzy.types else None
        self.rclpy_classes = {}

    def __call__(self, msgtype, data, topic, t_ns):
        store = self.stores.get(msgtype)
        if store is not None:
            try:
                return store.deserialize_cdr(data, msgtype)
            except Exception:  # rosbags rejects it: let rclpy decide
                pass
        if msgtype not in self.rclpy_classes:
            self.rclpy_classes[msgtype] = _rclpy_class(msgtype)
        cls = self.rclpy_classes[msgtype]
        if cls is None:
            raise BagError(f'{self.path}: topic {topic}: cannot decode {msgtype!r} at '
                           f'{t_ns} ns (no usable definition in the bag, no rclpy type)')
        from rclpy.serialization import deserialize_message
        try:
            msg = deserialize_message(bytes(data), cls)
        except Exception as exc:  # rclpy raises assorted errors on bad CDR
            raise BagError(f'{self.path}: topic {topic}: undecodable {msgtype} payload at '
                           f'{t_ns} ns ({type(exc).__name__}: {exc})') from None
        if store is None:
            return msg
        return _from_rclpy(msg, msgtype, store)


def _select_topics(topics, present, path):
    """Return the set of topics to read (None: all) after checking names and types."""
    if topics is None:
        return None
    if isinstance(topics, str):
        topics = [topics]
    if isinstance(topics, Mapping):
        expected = dict(topics)
    else:
        expected = {t: None for t in topics}
    absent = [t for t in expected if t not in present]
    if absent:
        listing = ', '.join(f'{t} ({present[t]})' for t in sorted(present)) or 'none'
        raise BagError(f'{path}: topic(s) {absent} not in bag; present: {listing}')
    for topic, msgtype in expected.items():
        if msgtype is not None and normalize_msgtype(msgtype) != present[topic]:
            raise BagError(f'{path}: topic {topic} has type {present[topic]}, '
                           f'expected {normalize_msgtype(msgtype)}')
    return set(expected)


def read_bag(path, topics=None, *, raw=False, allow_truncated=False):
    """Return an iterator of ``(topic, t_ns, msg)`` of a bag in log-time order.

    The path, the files' integrity (end magic, summary CRC) and ``topics`` are checked at call
    time; chunk CRCs as the chunks are read.

    Parameters
    ----------
    path : str or Path
        Bag directory (metadata.yaml + .mcap) or a bare .mcap file.
    topics : list of str or dict, optional
        Topics to read (default all). A dict ``{topic: 'pkg/msg/Type'}`` also checks types.
        An absent topic or another type raises BagError.
    raw : bool
        Yield the CDR payload bytes instead of decoded messages.
    allow_truncated : bool
        For a file whose writer died before close() (no footer/summary), scan it and read the
        complete, CRC-valid chunks (warns) instead of raising BagError.

    Returns
    -------
    iterator of (topic, t_ns, msg)
    topic : str
    t_ns : int
        Log (receive) time (ns).
    msg : rosbags message object, or bytes if ``raw``
        (an rclpy message only for a type whose definition rosbags can neither parse from
        the bag nor knows itself).
    """
    files = _open_files(path, allow_truncated)
    try:
        selected = _select_topics(topics, _merged_topics(files), path)
        decoder = None
        if not raw:
            decoder = _Decoder([s for mf in files for s in mf.schemas.values()], path)
    except BaseException:
        for mf in files:
            mf.close()
        raise
    # Checks above run at call time; messages are read lazily.
    return _iterate(files, selected, decoder)


def _iterate(files, selected, decoder):
    try:
        streams = [mf.iter_raw(selected) for mf in files]
        if len(streams) == 1:
            merged = streams[0]
        else:
            merged = heapq.merge(*streams, key=lambda r: r[0])
        for t_ns, topic, msgtype, data in merged:
            if decoder is None:
                yield topic, t_ns, bytes(data)
            else:
                yield topic, t_ns, decoder(msgtype, data, topic, t_ns)
    finally:
        for mf in files:
            mf.close()
