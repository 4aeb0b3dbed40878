"""Rosbag2 MCAP bag reader without rosbag2: :func:`read_bag`, :func:`bag_topics`,
:func:`message_counts`.

Reading decodes with rosbags (fast) using the definitions stored in the bag, and falls back to
rclpy for payloads rosbags rejects: rclpy/Fast-CDR pads messages that end with an empty float64
sequence (JointState with empty effort) by up to 8 bytes, which rosbags calls a size mismatch.
Every message is yielded as a rosbags message object (attribute access like rclpy messages;
arrays are numpy arrays), or as raw CDR bytes with ``raw=True``.

All bad input raises :class:`BagError` naming the path (and topic where it applies).
"""
from collections.abc import Mapping
import heapq
import importlib
from pathlib import Path
import struct
import warnings
import zlib

from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import breakup_chunk, StreamReader
# Why mcap.writer.Writer and not rosbags.rosbag2.Writer: rosbags writes its own comment-less
# message definitions, no 'topic_type_hash' channel metadata and a fixed 1 MiB chunk held in
# memory; mcap's Writer takes our rosbag2-exact schema text and channel metadata verbatim, a
# chunk size of our choosing, and has a public flush() that closes the chunk in progress.
import numpy as np
from rosbags.typesys import get_typestore, get_types_from_msg, Stores
from rosbags.typesys.base import Nodetype
import yaml


from auv_ident.bags.schema import BagError, _FOOTER_LEN, MCAP_MAGIC, normalize_msgtype, _split_type

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
