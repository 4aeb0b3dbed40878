"""Walking the records of an MCAP file in file order, for files without a usable index.

A recorder killed with SIGKILL leaves a file with no summary, no footer and possibly a torn
last record (usually the chunk being written). :class:`McapScan` walks the top-level records
from the start, checks each record's declared length against the file size before reading it,
opens complete chunks (CRC checked, all or nothing) and stops at the first record that is torn
or corrupt, describing it in :attr:`McapScan.stop` so that callers can say what was lost.

The record layout is that of the MCAP specification (https://mcap.dev/spec): every record is
``opcode (uint8) + length (uint64) + body``; records are parsed with ``mcap.records``.
"""
from collections import Counter
from dataclasses import dataclass
import io
import struct

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    Channel,
    Chunk,
    DataEnd,
    Footer,
    Header,
    Message,
    MessageIndex,
    Metadata,
    Schema,
)
from mcap.stream_reader import breakup_chunk

from auv_ident.bags.schema import MCAP_MAGIC

_HEAD = struct.Struct('<BQ')  # opcode, record length
# Chunk body start: message_start_time, message_end_time, uncompressed_size, uncompressed_crc,
# compression string length.
_CHUNK_HEAD = struct.Struct('<QQQII')

_TOP_LEVEL = {
    Opcode.HEADER: Header, Opcode.FOOTER: Footer, Opcode.SCHEMA: Schema,
    Opcode.CHANNEL: Channel, Opcode.MESSAGE_INDEX: MessageIndex, Opcode.METADATA: Metadata,
    Opcode.ATTACHMENT: Attachment, Opcode.DATA_END: DataEnd,
}


@dataclass
class ScanStop:
    """Where and why a scan stopped before the footer.

    offset : byte offset of the first record not read; lost_bytes : bytes from there to the end
    of the file; reason : text; opcode : the record's opcode (None if its head is torn);
    chunk_times : (message_start_time, message_end_time) ns of a chunk whose head survived,
    else None; messages_seen : complete message records inside a torn uncompressed chunk (a
    lower bound of the messages it held), else None.
    """

    offset: int
    lost_bytes: int
    reason: str
    opcode: object = None
    chunk_times: object = None
    messages_seen: object = None

    def describe(self):
        """One line saying what was lost."""
        if not self.lost_bytes:
            return f'nothing that reached the file ({self.reason})'
        what = {Opcode.CHUNK: 'chunk', Opcode.MESSAGE_INDEX: 'message index',
                Opcode.MESSAGE: 'message'}.get(self.opcode, 'record')
        text = f'{self.lost_bytes} bytes from byte {self.offset} ({what}: {self.reason})'
        if self.chunk_times is not None:
            text += (f'; that chunk held the messages logged {stamp_text(self.chunk_times[0])}'
                     f' .. {stamp_text(self.chunk_times[1])} s')
            if self.messages_seen:
                text += f', at least {self.messages_seen} of them'
        return text


def stamp_text(t_ns):
    """Integer ns as exact seconds text, '1704067200.050000000'."""
    sec, nsec = divmod(int(t_ns), 1_000_000_000)
    return f'{sec}.{nsec:09d}'


def _torn_chunk_details(body):
    """(times, complete messages seen) of the readable part of a torn chunk record."""
    if len(body) < _CHUNK_HEAD.size:
        return None, None
    start, end, _, _, comp_len = _CHUNK_HEAD.unpack_from(body)
    times = (start, end)
    pos = _CHUNK_HEAD.size
    compression = body[pos:pos + comp_len]
    pos += comp_len + 8  # compression name, records length
    if compression != b'' or pos > len(body):
        return times, None  # compressed data cannot be read in part
    seen = 0
    while pos + _HEAD.size <= len(body):
        opcode, length = _HEAD.unpack_from(body, pos)
        pos += _HEAD.size + length
        if pos > len(body):
            break
        seen += opcode == Opcode.MESSAGE
    return times, seen


class McapScan:
    """Records of one MCAP file in file order (see the module docstring).

    After :meth:`records` is exhausted: ``stop`` is None if the footer was reached, else a
    :class:`ScanStop`; ``end_offset`` is the end of the last complete record; ``chunks`` counts
    the complete chunks and ``compressions`` their compression names.
    """

    def __init__(self, fh, size):
        self.fh = fh
        self.size = size
        self.stop = None
        self.end_offset = 0
        self.chunks = 0
        self.compressions = Counter()
        self.header = None

    def _stop(self, offset, reason, opcode=None, body=b''):
        times, seen = (None, None)
        if opcode == Opcode.CHUNK:
            times, seen = _torn_chunk_details(body)
        self.stop = ScanStop(offset, self.size - offset, reason, opcode, times, seen)

    def records(self):
        """Yield the records in file order; a chunk's records (Schema, Channel, Message) are
        yielded in its place once the whole chunk has been read and checked."""
        self.fh.seek(0)
        if self.fh.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            self._stop(0, 'no MCAP magic')
            return
        offset = self.end_offset = len(MCAP_MAGIC)
        while True:
            if offset == self.size:
                self._stop(offset, 'the file ends after a complete record, without footer')
                return
            if offset + _HEAD.size > self.size:
                self._stop(offset, 'file ends inside a record head')
                return
            self.fh.seek(offset)
            opcode, length = _HEAD.unpack(self.fh.read(_HEAD.size))
            body_start = offset + _HEAD.size
            if length > self.size - body_start:
                self.fh.seek(body_start)
                self._stop(offset, f'record of {length} bytes, only '
                                   f'{self.size - body_start} present', opcode,
                           self.fh.read(min(self.size - body_start, 1 << 26)))
                return
            body = self.fh.read(length)
            try:
                parsed = self._parse(opcode, body)
            except Exception as exc:  # a corrupt record can break the parser in any way
                self._stop(offset, f'unreadable ({type(exc).__name__}: {exc})', opcode)
                return
            if self.header is None:
                if not isinstance(parsed, Header):
                    self._stop(offset, 'the first record is not a Header', opcode)
                    return
                self.header = parsed
            offset = self.end_offset = body_start + length
            if isinstance(parsed, list):
                yield from parsed
            elif parsed is not None:
                yield parsed
            if isinstance(parsed, Footer):
                return

    def _parse(self, opcode, body):
        stream = ReadDataStream(io.BytesIO(body))
        if opcode == Opcode.CHUNK:
            chunk = Chunk.read(stream)
            # Without a CRC (it may be 0) an uncompressed chunk's size is the only check left.
            if not chunk.compression and len(chunk.data) != chunk.uncompressed_size:
                raise ValueError('chunk data size differs from its uncompressed_size')
            inner = breakup_chunk(chunk, validate_crc=True)  # all or nothing
            self.chunks += 1
            self.compressions[chunk.compression] += 1
            return inner
        if opcode == Opcode.MESSAGE:
            return Message.read(stream, len(body))
        cls = _TOP_LEVEL.get(opcode)
        return cls.read(stream) if cls is not None else None  # the summary section is skipped


def message_index_counts(fh, start, length):
    """Return {channel_id: entries} of the MessageIndex records in fh[start:start+length]."""
    fh.seek(start)
    data = fh.read(length)
    counts = Counter()
    pos = 0
    while pos + _HEAD.size <= len(data):
        opcode, rec_len = _HEAD.unpack_from(data, pos)
        body = data[pos + _HEAD.size:pos + _HEAD.size + rec_len]
        pos += _HEAD.size + rec_len
        if opcode == Opcode.MESSAGE_INDEX and len(body) == rec_len:
            index = MessageIndex.read(ReadDataStream(io.BytesIO(body)))
            counts[index.channel_id] += len(index.records)
    return counts


def first_chunk_compression(fh, size):
    """Compression name of the first complete chunk record ('' = none), None if there is none.

    Walks the record heads only (no bodies are read)."""
    offset = len(MCAP_MAGIC)
    while offset + _HEAD.size <= size:
        fh.seek(offset)
        opcode, length = _HEAD.unpack(fh.read(_HEAD.size))
        if length > size - offset - _HEAD.size:
            return None
        if opcode == Opcode.CHUNK and length >= _CHUNK_HEAD.size:
            head = fh.read(_CHUNK_HEAD.size)
            comp_len = _CHUNK_HEAD.unpack(head)[4]
            return fh.read(comp_len).decode('utf-8', 'replace')
        if opcode == Opcode.FOOTER:
            return None
        offset += _HEAD.size + length
    return None
