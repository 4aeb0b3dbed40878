"""Rosbag2 MCAP bag reader without rosbag2 and without ROS: :func:`read_bag`,
:func:`bag_topics`, :func:`message_counts`.

Reads any rosbag2 MCAP bag (directory or bare .mcap): files with or without Statistics or
summary, schema names ``pkg/msg/Type`` or ``pkg/Type``. Decoding uses rosbags with the
definitions stored in the bag; payloads rosbags rejects only for trailing padding (rclpy /
Fast-CDR pads a message holding an empty float64 sequence, e.g. a JointState with an empty
effort, by up to 8 bytes: shared/ros_stack.md section 3) are decoded by rosbags again with
that padding allowed, and a type rosbags cannot build is decoded by mcap_ros2. Every message is
yielded as a rosbags message object (attribute access like rclpy messages; arrays are numpy
arrays), or as raw CDR bytes with ``raw=True``.

All bad input raises :class:`BagError` naming the path (and topic where it applies), except
that a topic that cannot be decoded is skipped with one warning when all topics are read.
"""
from collections import Counter
from collections.abc import Mapping
import contextlib
import heapq
import io
import logging
from pathlib import Path
import struct
import warnings
import zlib

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import breakup_chunk
from rosbags.typesys import get_types_from_msg, get_typestore, Stores

from auv_ident.bags.mcap_scan import McapScan, message_index_counts
from auv_ident.bags.schema import (
    _FOOTER_LEN,
    BagError,
    MCAP_MAGIC,
    normalize_msgtype,
    read_metadata,
)

log = logging.getLogger('auv_ident.bags')

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
    info = read_metadata(p)
    if info is not None:
        storage = info.get('storage_identifier')
        names = info.get('relative_file_paths')
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise BagError(f'{meta}: relative_file_paths is not a list of file names')
        compression_mode = info.get('compression_mode') or ''
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


def _summary_start(fh, size, path):
    """Return the footer's summary_start (0: no summary) of a finished file, None if the file
    has no end magic (its writer did not finish); BagError for a bad footer or summary CRC."""
    if size < 2 * len(MCAP_MAGIC) + _FOOTER_LEN:
        return None
    fh.seek(size - len(MCAP_MAGIC))
    if fh.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
        return None
    fh.seek(size - len(MCAP_MAGIC) - _FOOTER_LEN)
    footer = fh.read(_FOOTER_LEN)
    opcode, length, summary_start, summary_offset, crc = struct.unpack('<BQQQI', footer)
    if opcode != 0x02 or length != 20 or summary_start > size:
        raise BagError(f'{path}: corrupted MCAP file (bad footer)')
    if crc == 0 or summary_start == 0:
        return summary_start
    fh.seek(summary_start)
    covered = fh.read(size - len(MCAP_MAGIC) - 4 - summary_start)
    if zlib.crc32(covered) != crc:
        raise BagError(f'{path}: corrupted MCAP file (summary CRC mismatch)')
    return summary_start


_TRUNCATED_HINT = ('`python -m auv_ident bag repair` rewrites it as a complete bag; '
                   'read_bag(..., allow_truncated=True) reads its complete chunks')


class _McapFile:
    """One MCAP file: topics, counts, time range and a raw message iterator.

    A complete file with chunk indexes is read through its index (mcap's SeekingReader, in
    log-time order); a complete file without one (no summary, or no chunk indexes) and, on
    request, a truncated file are scanned in file order (:class:`McapScan`).
    """

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
        self.complete = False
        self.header = None
        self.stop = None
        self.schemas = {}
        self.channels = {}

    def close(self):
        self.fh.close()

    def open(self, allow_truncated=False):
        """Read the index (or scan); BagError if the file is not sound (see read_bag)."""
        head = self.fh.read(len(MCAP_MAGIC))
        if head != MCAP_MAGIC:
            raise BagError(f'{self.path}: not an MCAP file (bad magic {head[:8]!r})')
        self.is_mcap = True
        summary_start = _summary_start(self.fh, self.size, self.path)
        if summary_start is None:
            if not allow_truncated:
                what = (f'truncated MCAP file ({self.size} bytes)'
                        if self.size < 2 * len(MCAP_MAGIC) + _FOOTER_LEN else
                        'truncated or corrupted MCAP file (no end magic: the writer did not '
                        'finish it)')
                raise BagError(f'{self.path}: {what}; {_TRUNCATED_HINT}')
            self._scan(truncated=True)
            return
        self.complete = True
        if summary_start:
            try:
                self.fh.seek(0)
                self.reader = SeekingReader(self.fh, validate_crcs=True)
                self.header = self.reader.get_header()
                summary = self.reader.get_summary()
            except Exception as exc:  # a corrupt file can break the parser in any way
                raise BagError(f'{self.path}: corrupted MCAP file ({type(exc).__name__}: '
                               f'{exc})') from exc
            stats = summary.statistics if summary is not None else None
            if summary is not None and (summary.chunk_indexes or (
                    stats is not None and stats.message_count == 0)):
                self.summary = summary
                self.schemas = dict(summary.schemas)
                self.channels = dict(summary.channels)
                return
        # Finished, but without an index to read in log-time order: scan it.
        self._scan(truncated=False, allow_truncated=allow_truncated)

    def _scan(self, truncated, allow_truncated=True):
        scan = McapScan(self.fh, self.size)
        schemas, channels, messages = {}, {}, []
        for record in scan.records():
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                messages.append(record)
        self.header, self.stop = scan.header, scan.stop
        if scan.stop is not None and not truncated and not allow_truncated:
            raise BagError(f'{self.path}: corrupted MCAP file (unreadable after byte '
                           f'{scan.stop.offset}: {scan.stop.reason})')
        self.schemas, self.channels = schemas, channels
        messages = [m for m in messages if m.channel_id in channels]
        messages.sort(key=lambda m: m.log_time)  # stable: file order within equal times
        self.recovered = messages
        if scan.stop is not None:
            warnings.warn(f'{self.path}: truncated or corrupted ({scan.stop.describe()}); '
                          f'recovered {len(messages)} messages from complete chunks',
                          stacklevel=5)

    def msgtype(self, channel):
        """'pkg/msg/Type' of a channel's schema ('' without one; an odd name as it is)."""
        schema = self.schemas.get(channel.schema_id)
        return _normalized(schema.name) if schema is not None else ''

    def topics(self):
        return {c.topic: self.msgtype(c) for c in self.channels.values()}

    def _channel_counts(self):
        """{channel_id: messages}: statistics, else the message indexes, else a count."""
        if self.recovered is not None:
            return Counter(m.channel_id for m in self.recovered)
        stats = self.summary.statistics
        if stats is not None:
            return Counter(stats.channel_message_counts)
        counts = Counter()
        for index in self.summary.chunk_indexes:
            if index.message_index_offsets:
                counts += message_index_counts(
                    self.fh, index.chunk_start_offset + index.chunk_length,
                    index.message_index_length)
                continue
            counts += self._count_chunk(index)  # a chunk without message indexes
        return counts

    def counts(self):
        per_channel = self._channel_counts()
        counts = {c.topic: 0 for c in self.channels.values()}
        for cid, channel in self.channels.items():
            counts[channel.topic] += int(per_channel.get(cid, 0))
        return counts

    def time_range(self):
        """(first, last) log time (ns) of the file's messages, or None if it has none."""
        if self.recovered is not None:
            if not self.recovered:
                return None
            return self.recovered[0].log_time, max(m.log_time for m in self.recovered)
        stats = self.summary.statistics
        if stats is not None:
            if stats.message_count == 0:
                return None
            return stats.message_start_time, stats.message_end_time
        if not self.summary.chunk_indexes:
            return None
        return (min(i.message_start_time for i in self.summary.chunk_indexes),
                max(i.message_end_time for i in self.summary.chunk_indexes))

    def compressions(self):
        """Chunk compression names ('' = none) of an indexed file (empty set otherwise)."""
        if self.summary is None:
            return set()
        return {i.compression for i in self.summary.chunk_indexes}

    def _chunk_messages(self, index):
        """The Message records of one chunk, its CRC checked (BagError if it fails)."""
        chunk = _read_chunk(self.fh, index, self.path)
        try:
            records = breakup_chunk(chunk, validate_crc=True)
        except Exception as exc:  # CRC mismatch, bad compression, ...
            raise BagError(f'{self.path}: corrupted MCAP chunk ({type(exc).__name__}: '
                           f'{exc})') from exc
        return [r for r in records if isinstance(r, Message)]

    def _count_chunk(self, index):
        """{channel_id: messages} of one chunk, counted by reading it."""
        return Counter(r.channel_id for r in self._chunk_messages(index))

    def _iter_indexed(self, topics):
        """Yield (channel, message) through the index in log-time order (ties: the file's
        order, as mcap's reader orders them)."""
        chunks = _chunks_in_time_order(self.summary.chunk_indexes)
        if chunks is not None:
            yield from self._iter_chunks(chunks, topics)
            return
        for _, channel, message in self._iter_merged(topics):
            yield channel, message

    def _iter_chunks(self, chunks, topics):
        """The chunks one after another, each one's messages stably sorted by log time: the
        same order as mcap's merge of every message (log time, chunk offset, offset in the
        chunk) when no chunk's time range overlaps the next one's, at a fraction of its
        cost (its heap compares message pairs in Python: 40 % of reading a 100 Hz IMU bag)."""
        wanted = {cid for cid, c in self.channels.items()
                  if topics is None or c.topic in topics}
        for index in chunks:
            messages = [r for r in self._chunk_messages(index) if r.channel_id in wanted]
            messages.sort(key=lambda m: m.log_time)
            for m in messages:
                yield self.channels[m.channel_id], m

    def _iter_merged(self, topics):
        """Yield (schema, channel, message) through mcap's log-time-ordered merge."""
        it = self.reader.iter_messages(topics=None if topics is None else list(topics),
                                       log_time_order=True)
        while True:
            try:
                item = next(it)
            except StopIteration:
                return
            except Exception as exc:  # CRC mismatch, bad compression, short read, ...
                raise BagError(f'{self.path}: corrupted MCAP chunk ({type(exc).__name__}: '
                               f'{exc})') from exc
            yield item

    def iter_raw(self, topics):
        """Yield (t_ns, topic, msgtype, payload bytes) in log-time order."""
        if self.recovered is not None:
            for m in self.recovered:
                channel = self.channels[m.channel_id]
                if topics is None or channel.topic in topics:
                    yield m.log_time, channel.topic, self.msgtype(channel), m.data
            return
        for channel, message in self._iter_indexed(topics):
            yield message.log_time, channel.topic, self.msgtype(channel), message.data


def _chunks_in_time_order(indexes):
    """The chunk indexes in reading order if reading them one after another, each sorted in
    itself, gives log-time order: each chunk starts after the one before ends (at the same
    nanosecond only when it also lies later in the file); else None (then mcap merges)."""
    if not indexes or any(i.message_start_time > i.message_end_time for i in indexes):
        return None
    ordered = sorted(indexes, key=lambda i: (i.message_start_time, i.chunk_start_offset))
    for a, b in zip(ordered, ordered[1:]):
        if a.message_end_time > b.message_start_time or (
                a.message_end_time == b.message_start_time
                and a.chunk_start_offset > b.chunk_start_offset):
            return None
    return ordered


def _read_chunk(fh, index, path):
    """The Chunk record a ChunkIndex points at."""
    fh.seek(index.chunk_start_offset)
    data = fh.read(index.chunk_length)
    try:
        stream = ReadDataStream(io.BytesIO(data))
        if stream.read1() != Opcode.CHUNK:
            raise ValueError('no chunk at the indexed offset')
        stream.read8()
        return Chunk.read(stream)
    except Exception as exc:  # a corrupt index or chunk can fail in any way
        raise BagError(f'{path}: corrupted MCAP chunk ({type(exc).__name__}: {exc})') from exc


def _normalized(name):
    """'pkg/msg/Type' for 'pkg/Type' (as some writers name schemas); other names as they are."""
    try:
        return normalize_msgtype(name)
    except BagError:
        return name


def _open_files(path, allow_truncated):
    files = []
    try:
        for f in _bag_files(path):
            mf = _McapFile(f)
            files.append(mf)
            mf.open(allow_truncated)
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
    """Return ``{topic: number of messages}`` of a bag directory or .mcap file.

    From the files' Statistics records; for a file without one (optional in MCAP), from its
    message indexes, else by counting.
    """
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
# rosbags accepts up to 3 bytes after the last field (CDR's final alignment to 4). rclpy
# (Fast-CDR) ends a message that holds an empty float64 sequence, e.g. a JointState with an
# empty effort, with up to 8 more bytes of alignment (shared/ros_stack.md section 3): measured
# 4 or 8. More left over than that is not padding but a payload of another layout.
_MAX_TRAILING = 3 + 8


def _jazzy_store():
    global _JAZZY
    if _JAZZY is None:
        _JAZZY = get_typestore(Stores.ROS2_JAZZY)
    return _JAZZY


class _Undecodable(Exception):
    """A payload (or a whole type) cannot be decoded; str() is the reason."""


def _first_line(exc):
    text = str(exc).strip().splitlines()
    return f'{type(exc).__name__}: {text[0] if text else ""}'.rstrip(': ')


def _rosbags_store(schema, name, shared):
    """A rosbags typestore that knows ``name``, from the bag's definition text, else Jazzy's
    own; raises _Undecodable with the reason if neither has it."""
    try:
        types = get_types_from_msg(schema.data.decode('utf-8'), name)
    except Exception as exc:  # any parse failure: maybe rosbags knows the type itself
        reason = f'definition not parsed ({_first_line(exc)})'
    else:
        for store in (shared, get_typestore(Stores.EMPTY)):
            try:
                store.register(types)
                return store
            except Exception as exc:  # e.g. a dependency defined differently by another schema
                reason = f'definition not registered ({_first_line(exc)})'
    jazzy = _jazzy_store()
    if name in jazzy.types:
        return jazzy
    raise _Undecodable(reason)


def _mcap_ros2_decoder(schema):
    """mcap_ros2's decoding function of a schema, or raise _Undecodable."""
    # Imported here: only bags with types rosbags cannot build need it (and its parser).
    from mcap_ros2.decoder import DecoderFactory
    try:
        # its vendored .msg parser prints each failure to stderr on top of raising
        with contextlib.redirect_stderr(io.StringIO()):
            return DecoderFactory().decoder_for('cdr', schema)
    except Exception as exc:
        raise _Undecodable(f'definition not parsed ({_first_line(exc)})') from exc


class _Decoder:
    """Decode the CDR payloads of one bag's types, without ROS.

    rosbags first (fast; numpy arrays), with the bag's own definitions (else rosbags' Jazzy
    types); for a payload rosbags rejects only for what follows the last field, rosbags again
    accepting up to :data:`_MAX_TRAILING` bytes of trailing alignment (the Fast-CDR padding
    pitfall). A type rosbags cannot build at all is decoded with mcap_ros2 (its own objects,
    attribute access alike). :meth:`problem` says why a type cannot be decoded at all.
    """

    def __init__(self, schemas, path):
        self.path = path
        self.stores = {}
        self.fallbacks = {}
        self.problems = {}
        shared = get_typestore(Stores.EMPTY)
        for schema in schemas:
            name = _normalized(schema.name)
            if name in self.stores or name in self.fallbacks or name in self.problems:
                continue
            if schema.encoding != 'ros2msg':
                self.problems[name] = f'schema encoding {schema.encoding!r} (not ros2msg)'
                continue
            try:
                self.stores[name] = _rosbags_store(schema, name, shared)
                continue
            except _Undecodable as exc:
                reason = str(exc)
            try:
                self.fallbacks[name] = _mcap_ros2_decoder(schema)
            except _Undecodable as exc:
                self.problems[name] = f'{reason}; mcap_ros2: {exc}'

    def problem(self, msgtype, encoding='cdr'):
        """Why messages of msgtype cannot be decoded at all ('' if they can)."""
        if encoding != 'cdr':
            return f'message encoding {encoding!r} (only cdr is decoded)'
        if msgtype in self.stores or msgtype in self.fallbacks:
            return ''
        return self.problems.get(msgtype, 'no schema')

    def __call__(self, msgtype, data):
        store = self.stores.get(msgtype)
        if store is None:
            try:
                return self.fallbacks[msgtype](data)
            except KeyError:
                raise _Undecodable(self.problem(msgtype)) from None
            except Exception as exc:  # mcap_ros2 fails in assorted ways on bad CDR
                raise _Undecodable(_first_line(exc)) from exc
        try:
            return store.deserialize_cdr(data, msgtype)
        except Exception as exc:  # rosbags' SerdeError, or a KeyError for a broken type
            strict_error = exc
        # Again, but accepting what a Fast-CDR writer pads at the end.
        try:
            msgdef = store.get_msgdef(msgtype)
            decode = msgdef.deserialize_cdr_le if data[1] else msgdef.deserialize_cdr_be
            msg, pos = decode(memoryview(data)[4:], 0, msgdef.cls, store)
        except Exception:  # the payload itself is bad: report rosbags' own reason
            raise _Undecodable(_first_line(strict_error)) from strict_error
        left = len(data) - 4 - pos
        if left > _MAX_TRAILING:
            raise _Undecodable(f'{left} bytes left over after the message, more than '
                               'alignment padding') from None
        return msg


def _select_topics(topics, present, path):
    """Return the dict {topic: expected type or None} asked for (None: all), names checked."""
    if topics is None:
        return None
    if isinstance(topics, str):
        topics = [topics]
    if isinstance(topics, Mapping):
        expected = dict(topics)
    else:
        expected = dict.fromkeys(topics)
    absent = [t for t in expected if t not in present]
    if absent:
        listing = ', '.join(f'{t} ({present[t]})' for t in sorted(present)) or 'none'
        raise BagError(f'{path}: topic(s) {absent} not in bag; present: {listing}')
    for topic, msgtype in expected.items():
        if msgtype is not None and normalize_msgtype(msgtype) != present[topic]:
            raise BagError(f'{path}: topic {topic} has type {present[topic]}, '
                           f'expected {normalize_msgtype(msgtype)}')
    return expected


def _encodings(files):
    out = {}
    for mf in files:
        for channel in mf.channels.values():
            out[channel.topic] = channel.message_encoding
    return out


def read_bag(path, topics=None, *, raw=False, allow_truncated=False):
    """Return an iterator of ``(topic, t_ns, msg)`` of a bag in log-time order.

    The path, the files' integrity (end magic, summary CRC), ``topics`` and whether their
    types can be decoded are checked at call time; chunk CRCs as the chunks are read.

    Parameters
    ----------
    path : str or Path
        Bag directory (metadata.yaml + .mcap) or a bare .mcap file. Schema names ``pkg/Type``
        are read as ``pkg/msg/Type``; a file without Statistics or summary is read too.
    topics : list of str or dict, optional
        Topics to read (default all). A dict ``{topic: 'pkg/msg/Type'}`` also checks types.
        An absent topic, another type, or (unless ``raw``) a type that cannot be decoded at
        all raises BagError; so does an undecodable payload of a topic asked for here.
    raw : bool
        Yield the CDR payload bytes instead of decoded messages.
    allow_truncated : bool
        For a file whose writer died before close() (no footer/summary), scan it and read the
        complete, CRC-valid chunks (warns) instead of raising BagError.

    With ``topics=None``, a topic that cannot be decoded (its type at all, or a payload) is
    skipped with ONE warning (logger ``auv_ident.bags``) naming the topic and the reason; the
    other topics keep coming.

    Returns
    -------
    iterator of (topic, t_ns, msg)
    topic : str
    t_ns : int
        Log (receive) time (ns).
    msg : rosbags message object, or bytes if ``raw``
        (an mcap_ros2 object for a type whose definition rosbags cannot build but mcap_ros2
        can; attribute access alike).
    """
    files = _open_files(path, allow_truncated)
    try:
        present = _merged_topics(files)
        expected = _select_topics(topics, present, path)
        decoder = None
        selected = None if expected is None else set(expected)
        if not raw:
            decoder = _Decoder([s for mf in files for s in mf.schemas.values()], path)
            encodings = _encodings(files)
            wanted = present if expected is None else expected
            bad = {t: decoder.problem(present[t], encodings[t]) for t in wanted}
            bad = {t: why for t, why in bad.items() if why}
            if bad and expected is not None:
                topic = sorted(bad)[0]
                raise BagError(f'{path}: topic {topic}: cannot decode {present[topic]!r} at all '
                               f'({bad[topic]})')
            for topic in sorted(bad):
                log.warning('%s: skipping topic %s (%s): cannot decode it (%s)', path, topic,
                            present[topic], bad[topic])
            if bad:
                selected = set(present) - set(bad)
    except BaseException:
        for mf in files:
            mf.close()
        raise
    # Checks above run at call time; messages are read lazily.
    return _iterate(files, selected, decoder, path, strict=expected is not None)


def _iterate(files, selected, decoder, path, strict):
    warned = set()
    try:
        streams = [mf.iter_raw(selected) for mf in files]
        if len(streams) == 1:
            merged = streams[0]
        else:
            merged = heapq.merge(*streams, key=lambda r: r[0])
        for t_ns, topic, msgtype, data in merged:
            if decoder is None:
                yield topic, t_ns, bytes(data)
                continue
            try:
                msg = decoder(msgtype, data)
            except _Undecodable as exc:
                if strict:
                    raise BagError(f'{path}: topic {topic}: undecodable {msgtype} payload at '
                                   f'{t_ns} ns ({exc})') from exc
                if topic not in warned:
                    warned.add(topic)
                    log.warning('%s: topic %s: undecodable %s payload at %d ns (%s); skipping '
                                'the undecodable messages of this topic, others keep coming',
                                path, topic, msgtype, t_ns, exc)
                continue
            yield topic, t_ns, msg
    finally:
        for mf in files:
            mf.close()
