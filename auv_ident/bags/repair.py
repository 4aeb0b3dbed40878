"""Making a bag complete again: :func:`repair_bag` (``python -m auv_ident bag repair``).

A recorder killed with SIGKILL (or a power cut) leaves MCAP files without summary, footer,
chunk indexes and Statistics, perhaps ending in a torn chunk, and no metadata.yaml. Such a file
can only be scanned in file order: libmcap (which rosbag2 uses), rosbags and mcap's
SeekingReader cannot read it in time order. Like ``ros2 bag reindex`` for rosbag2, the repair
makes the bag readable by all of them again:

- each data file that is not complete and indexed (no summary, no Statistics, a chunk without
  message indexes) is rewritten: every message of its complete, CRC-valid chunks (and any
  message outside chunks), with its log time, publish time and sequence, the file's schemas,
  channels (metadata kept: QoS, type hash), metadata and attachment records, then the summary:
  chunk indexes, message indexes, Statistics, and a 'rosbag2' metadata record;
- metadata.yaml (rosbag2 version 9) is written from the files (custom_data of an existing
  metadata.yaml is kept).

What cannot be recovered is the torn tail: at most the chunk being written when the writer
died (and index records after it); :class:`RepairReport` says how many bytes, and the time
range of that chunk when its head survived. Files that are already complete are kept as they
are.

In place (no ``out``) each rewritten file replaces the original atomically; the original is
kept next to it as ``<file>.orig`` (not read as part of the bag). With ``out`` a new bag
directory is written and the source is left untouched.
"""
from collections import Counter
from dataclasses import dataclass, field
import itertools
import os
from pathlib import Path
import shutil

from mcap.reader import SeekingReader
from mcap.records import Attachment, Channel, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer as McapWriter

from auv_ident import __version__
from auv_ident.bags.mcap_scan import first_chunk_compression, McapScan
from auv_ident.bags.reader import _bag_files, _normalized, _summary_start
from auv_ident.bags.schema import (
    _dump,
    BagError,
    bagfile_information,
    custom_data_of,
    MCAP_MAGIC,
    qos_from_yaml,
    read_metadata,
    write_metadata_yaml,
)

REPAIR_CHUNK_SIZE = 768 * 1024
"""Uncompressed bytes per chunk of a rewritten file: rosbag2's own default (a repaired file is
not written live, so the small chunks of BagWriter, which bound a crash's loss, buy nothing)."""

_COMPRESSION = {'': CompressionType.NONE, 'zstd': CompressionType.ZSTD,
                'lz4': CompressionType.LZ4}


@dataclass
class FileRepair:
    """What happened to one data file.

    name : file name; rewritten : False if kept as it was; why : why it was rewritten;
    messages : messages in the (new) file; chunks : complete chunks read from the original;
    lost : ScanStop of the unreadable tail (None: nothing lost); unknown_channel : messages
    dropped because their channel record was lost; span : (first, last) log time or None;
    channels : {channel_id: (Channel, type name, count)} of the new file.
    """

    name: str
    rewritten: bool
    why: str = ''
    messages: int = 0
    chunks: int = 0
    lost: object = None
    unknown_channel: int = 0
    span: object = None
    channels: dict = field(default_factory=dict)


@dataclass
class RepairReport:
    """Result of :func:`repair_bag`; :meth:`lines` is the command's output."""

    source: Path
    out: Path
    in_place: bool
    files: list
    metadata_written: bool
    counts: dict

    @property
    def changed(self):
        return self.metadata_written or any(f.rewritten for f in self.files)

    def lines(self):
        out = []
        where = 'in place' if self.in_place else f'into {self.out}'
        if not self.changed:
            out.append(f'{self.source}: complete and indexed, nothing to repair')
        else:
            out.append(f'repaired {self.source} {where}')
        for f in self.files:
            if not f.rewritten:
                out.append(f'  {f.name}: complete and indexed, kept as it is '
                           f'({f.messages} messages)')
                continue
            text = (f'  {f.name}: rewritten ({f.why}): {f.messages} messages from '
                    f'{f.chunks} complete chunk{"s" if f.chunks != 1 else ""}')
            if self.in_place:
                text += f'; the original is kept as {f.name}.orig'
            out.append(text)
            if f.lost is None:
                out.append('    lost: nothing')
            else:
                out.append(f'    lost: {f.lost.describe()}')
                if not f.lost.lost_bytes:
                    out.append('    (what a killed writer still held in memory, at most its '
                               'chunk in progress, never reached the file)')
            if f.unknown_channel:
                out.append(f'    lost: {f.unknown_channel} messages whose channel record was '
                           'in the lost part')
        if self.metadata_written:
            total = sum(self.counts.values())
            out.append(f'  metadata.yaml written (rosbag2 version 9): {total} messages; '
                       + ', '.join(f'{t} {n}' for t, n in sorted(self.counts.items())))
        return out


def _complete_and_indexed(fh, size, path):
    """'' if the file is complete with a full index, else why it needs rewriting."""
    summary_start = _summary_start(fh, size, path)
    if summary_start is None:
        return 'no summary: its writer did not finish'
    if summary_start == 0:
        return 'no summary section'
    try:
        fh.seek(0)
        summary = SeekingReader(fh, validate_crcs=True).get_summary()
    except Exception as exc:  # a corrupt summary can break the parser in any way
        return f'unreadable summary ({type(exc).__name__})'
    if summary is None:
        return 'no summary section'
    if summary.statistics is None:
        return 'no Statistics record'
    if summary.statistics.message_count and not summary.chunk_indexes:
        return 'no chunk indexes'
    if any(not i.message_index_offsets for i in summary.chunk_indexes):
        return 'chunks without message indexes'
    return ''


def _indexed_channels(fh):
    """{channel_id: (Channel, type, count)} and span of a complete, indexed file."""
    fh.seek(0)
    summary = SeekingReader(fh).get_summary()
    stats = summary.statistics
    channels = {}
    for cid, channel in summary.channels.items():
        schema = summary.schemas.get(channel.schema_id)
        name = _normalized(schema.name) if schema is not None else ''
        channels[cid] = (channel, name, int(stats.channel_message_counts.get(cid, 0)))
    span = ((stats.message_start_time, stats.message_end_time) if stats.message_count
            else None)
    return channels, span, stats.message_count


def rewrite_complete(src, dst, why):
    """Rewrite src (an MCAP file) as a complete, indexed file dst. Returns a FileRepair."""
    size = src.stat().st_size
    result = FileRepair(name=dst.name, rewritten=True, why=why)
    with open(src, 'rb') as fin:
        if fin.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise BagError(f'{src}: not an MCAP file (bad magic), cannot repair it')
        compression = first_chunk_compression(fin, size) or ''
        scan = McapScan(fin, size)
        records = scan.records()
        first = next(records, None)
        if scan.header is None:
            raise BagError(f'{src}: no readable MCAP header ({scan.stop.reason}), '
                           'cannot repair it')
        with open(dst, 'xb') as fout:
            writer = McapWriter(fout, chunk_size=REPAIR_CHUNK_SIZE,
                                compression=_COMPRESSION.get(compression,
                                                             CompressionType.ZSTD))
            library = scan.header.library or 'unknown writer'
            writer.start(profile=scan.header.profile,
                         library=f'{library}; repaired by auv_ident {__version__}')
            schema_ids, channel_ids, counts = {}, {}, Counter()
            names = {}
            span = None
            for record in itertools.chain([first], records):
                if isinstance(record, Schema):
                    if record.id not in schema_ids:
                        schema_ids[record.id] = writer.register_schema(
                            record.name, record.encoding, record.data)
                        names[record.id] = _normalized(record.name)
                elif isinstance(record, Channel):
                    if record.id not in channel_ids:
                        channel_ids[record.id] = (writer.register_channel(
                            record.topic, record.message_encoding,
                            schema_ids.get(record.schema_id, 0), record.metadata), record)
                elif isinstance(record, Message):
                    known = channel_ids.get(record.channel_id)
                    if known is None:
                        result.unknown_channel += 1
                        continue
                    writer.add_message(known[0], record.log_time, record.data,
                                       record.publish_time, record.sequence)
                    counts[record.channel_id] += 1
                    t = record.log_time
                    span = (t, t) if span is None else (min(span[0], t), max(span[1], t))
                elif isinstance(record, Metadata) and record.name != 'rosbag2':
                    writer.add_metadata(record.name, record.metadata)
                elif isinstance(record, Attachment):
                    writer.add_attachment(record.create_time, record.log_time, record.name,
                                          record.media_type, record.data)
            result.channels = {
                new_id: (channel, names.get(channel.schema_id, ''), counts[old_id])
                for old_id, (new_id, channel) in channel_ids.items()}
            result.messages = sum(counts.values())
            result.span = span
            result.chunks = scan.chunks
            result.lost = scan.stop
            info = bagfile_information([(dst.name, span, result.messages)],
                                       topic_entries([result.channels]))
            writer.add_metadata('rosbag2', {'serialized_metadata': _dump(info)})
            writer.finish()
            fout.flush()
            os.fsync(fout.fileno())
    return result


def topic_entries(channel_maps):
    """metadata.yaml topic entries of the channels of all files (merged by topic name)."""
    topics = {}
    for channels in channel_maps:
        for channel, msgtype, count in channels.values():
            entry = topics.get(channel.topic)
            if entry is None:
                try:
                    qos = qos_from_yaml(channel.metadata.get('offered_qos_profiles', ''))
                except BagError:
                    qos = []  # unreadable QoS metadata: rosbag2 then uses its defaults
                entry = topics[channel.topic] = {
                    'name': channel.topic, 'type': msgtype, 'qos': qos,
                    'hash': channel.metadata.get('topic_type_hash', ''), 'count': 0}
            entry['count'] += count
    return list(topics.values())


def _custom_data(bag_dir):
    try:
        info = read_metadata(bag_dir)
        return None if info is None else custom_data_of(info)
    except BagError:
        return None  # unreadable, aliased or oversized: it is being replaced anyway


def _replace_keeping_original(new, original):
    """Atomically put ``new`` in place of ``original``, keeping ``original`` as .orig."""
    backup = original.with_name(original.name + '.orig')
    if backup.exists():
        raise BagError(f'{backup} exists already (an earlier repair?); move it away first')
    try:
        os.link(original, backup)  # the original stays readable under both names meanwhile
    except OSError:
        shutil.copy2(original, backup)
    os.replace(new, original)


def _repair_file(f, dest, out):
    """Check one data file and rewrite it (or copy / keep it). Returns a FileRepair."""
    size = f.stat().st_size
    if size == 0:
        raise BagError(f'{f}: empty file (0 bytes), nothing to repair')
    with open(f, 'rb') as fh:
        if fh.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise BagError(f'{f}: not an MCAP file (bad magic), cannot repair it')
        why = _complete_and_indexed(fh, size, f)
        if not why:
            channels, span, n = _indexed_channels(fh)
    if not why:
        if out is not None:
            shutil.copy2(f, dest / f.name)
        return FileRepair(name=f.name, rewritten=False, messages=n, span=span,
                          channels=channels)
    target = dest / f.name if out is not None else f.with_name(f.name + '.repairing')
    try:
        result = rewrite_complete(f, target, why)
    except BaseException:
        if target.exists() and out is None:
            target.unlink()
        raise
    if out is None:
        _replace_keeping_original(target, f)
        result.name = f.name
    return result


def repair_bag(path, out=None):
    """Make a bag whose recorder died complete and indexed again (see the module docstring).

    Parameters
    ----------
    path : str or Path
        Bag directory (with or without metadata.yaml) or a bare .mcap file.
    out : str or Path, optional
        New bag directory to write (must not exist); default: repair in place.

    Returns a :class:`RepairReport`. Raises BagError for a path that is not a bag, a file that
    is not MCAP or has no readable header, or an existing ``out``.
    """
    src = Path(path)
    files = _bag_files(src)
    bare = src.is_file()
    if out is not None:
        dest = Path(out)
        if dest.exists():
            raise BagError(f'{dest}: output path exists already, not overwriting')
        try:
            dest.mkdir(parents=True)
        except OSError as exc:
            raise BagError(f'{dest}: cannot create the output bag: {exc}') from None
    else:
        dest = src.parent if bare else src
    results = []
    try:
        for f in files:
            try:
                results.append(_repair_file(f, dest, out))
            except OSError as exc:
                raise BagError(f'{f}: repair failed: {exc}') from exc
    except BaseException:
        if out is not None:
            shutil.rmtree(dest, ignore_errors=True)  # no half-written output bag
        raise
    if bare and out is None:
        write_meta = False  # a bare file has no metadata.yaml
    else:
        # in place, a complete bag whose metadata.yaml exists is left alone
        write_meta = (out is not None or any(r.rewritten for r in results)
                      or not (dest / 'metadata.yaml').is_file())
    counts = {}
    for entry in topic_entries([r.channels for r in results]):
        counts[entry['name']] = entry['count']
    if write_meta:
        custom = _custom_data(src) if not bare else None
        info = bagfile_information([(r.name, r.span, r.messages) for r in results],
                                   topic_entries([r.channels for r in results]), custom)
        try:
            write_metadata_yaml(dest, info)
        except OSError as exc:
            raise BagError(f'{dest}: cannot write metadata.yaml: {exc}') from None
    return RepairReport(source=src, out=dest, in_place=out is None, files=results,
                        metadata_written=write_meta, counts=counts)
