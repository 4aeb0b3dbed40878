"""Rosbag2 (Jazzy) MCAP bag writer without rosbag2: :class:`BagWriter`.

It writes the layout of Jazzy's rosbag2 with the MCAP storage plugin, which ``ros2 bag play``
expects (metadata.yaml version 9, schemas, channels with their QoS and type hashes, the
'rosbag2' metadata record, statistics): :mod:`auv_ident.bags.schema` describes it.
"""
import atexit
import contextlib
import functools
import numbers
import os
from pathlib import Path
import threading
import weakref

# Why mcap.writer.Writer and not rosbags.rosbag2.Writer: rosbags writes its own comment-less
# message definitions, no 'topic_type_hash' channel metadata and a fixed 1 MiB chunk held in
# memory; mcap's Writer takes our rosbag2-exact schema text and channel metadata verbatim, a
# chunk size of our choosing, and has a public flush() that closes the chunk in progress.
from mcap.writer import CompressionType, Writer as McapWriter

from auv_ident import __version__
from auv_ident.bags.repair import rewrite_complete, topic_entries
from auv_ident.bags.schema import (
    _dump,
    _qos_list,
    BagError,
    bagfile_information,
    DEFAULT_CHUNK_SIZE,
    message_definition,
    normalize_msgtype,
    qos_yaml,
    type_hash,
    write_metadata_yaml,
)

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
            raise BagError(f"{self.path}: compression must be None or 'zstd', "
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
        self._torn = False
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
        """Write one CDR payload (bytes as DDS delivers them, rclpy's serialize_message or
        rosbags' serialize_cdr gives them: the writer does not serialize messages itself, so
        that this layer needs no ROS).

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
            if self._torn:
                raise BagError(f'{self.path}: an earlier write was interrupted; close() the '
                               'bag (it keeps the complete chunks)')
            info = self._topics.get(topic)
            if info is None:
                raise BagError(f'{self.path}: topic {topic} was not added; added topics: '
                               f'{sorted(self._topics)}')
            with self._tearing():
                self._writer.add_message(channel_id=info.channel_id, log_time=t_ns,
                                         publish_time=t_ns, sequence=info.count, data=data)
            info.count += 1
            self._count += 1
            self._t_min = t_ns if self._t_min is None else min(self._t_min, t_ns)
            self._t_max = t_ns if self._t_max is None else max(self._t_max, t_ns)
            # Hands a just-completed chunk to the OS, so that a kill cannot lose it; a no-op
            # (cheap) while the chunk is still being filled in memory.
            self._fh.flush()

    def flush(self):
        """Close the chunk in progress and hand everything written so far to the OS.

        A no-op once closed, so a periodic flush timer may race with close().
        """
        with self._lock:
            if not self._closed:
                with self._tearing():
                    self._writer.flush()

    @contextlib.contextmanager
    def _tearing(self):
        """Mark the writer torn when what runs inside leaves by an exception.

        KeyboardInterrupt (SIGINT, and SIGTERM as rclpy raises it) can arrive between any two
        bytecodes of mcap's Writer, e.g. after it counted a chunk and before the chunk's bytes
        reached the file: its in-memory index then no longer describes the file, and a summary
        written from it makes a bag whose readers stop at a short read. close() of a torn
        writer therefore does not trust that state (see :meth:`close`).
        """
        try:
            yield
        except BaseException:
            self._torn = True
            raise

    def _metadata(self):
        span = None if self._t_min is None else (self._t_min, self._t_max)
        topics = [{'name': t.name, 'type': t.msgtype, 'qos': t.qos, 'hash': t.hash,
                   'count': t.count} for t in self._topics.values()]
        return bagfile_information([(self.mcap_path.name, span, self._count)], topics,
                                   self._custom_data)

    def close(self):
        """Finish the MCAP file (summary, statistics) and write metadata.yaml; idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            atexit.unregister(self._atexit)
            if self._torn:
                self._close_torn()
                return
            info = self._metadata()
            try:
                self._writer.add_metadata('rosbag2', {'serialized_metadata': _dump(info)})
                self._writer.finish()
                self._fh.close()
                write_metadata_yaml(self.path, info)
            except OSError as exc:
                raise BagError(f'{self.path}: cannot finish bag: {exc}') from None
            finally:
                if not self._fh.closed:
                    self._fh.close()

    def _close_torn(self):
        """Finish a bag whose writer was interrupted inside a write: as a killed recorder's.

        The file is closed without a summary, then rewritten from its complete chunks
        (:func:`auv_ident.bags.repair.rewrite_complete`, the ``bag repair`` path), so at most
        the chunk in progress is lost, and metadata.yaml counts what the file holds.
        """
        try:
            self._fh.close()
        except OSError:
            pass  # what did not reach the file is the chunk the rewrite drops anyway
        rewritten = self.mcap_path.with_name(self.mcap_path.name + '.rewriting')
        try:
            result = rewrite_complete(self.mcap_path, rewritten,
                                      'a write was interrupted')
            os.replace(rewritten, self.mcap_path)
            topics = {t['name']: t for t in topic_entries([result.channels])}
            for name, known in self._topics.items():  # topics without a surviving message
                topics.setdefault(name, {'name': name, 'type': known.msgtype,
                                         'qos': known.qos, 'hash': known.hash, 'count': 0})
            info = bagfile_information([(self.mcap_path.name, result.span, result.messages)],
                                       list(topics.values()), self._custom_data)
            write_metadata_yaml(self.path, info)
        except OSError as exc:
            raise BagError(f'{self.path}: cannot finish the interrupted bag: {exc}; '
                           f'`python -m auv_ident bag repair {self.path}` recovers its '
                           'complete chunks') from None
        finally:
            if rewritten.exists():
                rewritten.unlink()
