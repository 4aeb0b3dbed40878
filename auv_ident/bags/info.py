"""What ``ros2 bag info`` prints, for any rosbag2 MCAP bag, without rosbag2:
:func:`bag_info` and :func:`format_bag_info` (``python -m auv_ident bag info PATH``).

The figures come from the MCAP files themselves (Statistics, else the message indexes, else a
count), not from metadata.yaml, which a killed recorder never wrote and another tool may have
left stale; metadata.yaml gives only the ROS distro and custom_data. A file whose writer did not
finish is described from its complete chunks and flagged, with what is lost. Times are printed
in UTC (``ros2 bag info`` uses the local time zone), so the output does not depend on where it
runs.
"""
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
import warnings

from auv_ident.bags.mcap_scan import stamp_text
from auv_ident.bags.reader import _bag_files, _McapFile
from auv_ident.bags.schema import custom_data_of, read_metadata

_LABEL_WIDTH = 19  # 'Topic information: ' as rosbag2 aligns its continuation lines


@dataclass
class TopicInfo:
    """One topic: name, type ('pkg/msg/Type'), message count, serialization format."""

    name: str
    msgtype: str
    count: int
    serialization_format: str


@dataclass
class BagInfo:
    """Summary of a bag; see :func:`bag_info`. Times are log times (ns); None: no messages."""

    path: Path
    files: list
    size: int
    storage_id: str
    ros_distro: str
    start_ns: object
    end_ns: object
    message_count: int
    topics: list
    compression: str = ''
    custom_data: dict = field(default_factory=dict)
    incomplete: list = field(default_factory=list)

    @property
    def duration_ns(self):
        return 0 if self.start_ns is None else self.end_ns - self.start_ns


def _metadata_yaml(path):
    """rosbag2_bagfile_information of a bag directory's metadata.yaml ({} if none)."""
    if not Path(path).is_dir():
        return {}
    return read_metadata(path) or {}


def bag_info(path):
    """Return the :class:`BagInfo` of a bag directory or a bare .mcap file.

    Raises BagError for what is not a readable bag (as read_bag); a truncated file is read up
    to its last complete chunk and listed in ``incomplete``.
    """
    path = Path(path)
    files = _bag_files(path)
    meta = _metadata_yaml(path) if path.is_dir() else {}
    topics = {}
    spans = []
    compressions = set()
    incomplete = []
    size = 0
    for f in files:
        mf = _McapFile(f)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter('ignore')  # the truncation is reported below instead
                mf.open(allow_truncated=True)
            size += mf.size
            counts = mf.counts()
            for channel in mf.channels.values():
                entry = topics.get(channel.topic)
                if entry is None:
                    entry = topics[channel.topic] = TopicInfo(
                        channel.topic, mf.msgtype(channel), 0, channel.message_encoding)
            for topic, n in counts.items():
                topics[topic].count += n
            span = mf.time_range()
            if span is not None:
                spans.append(span)
            compressions |= mf.compressions()
            if not mf.complete:
                lost = mf.stop.describe() if mf.stop is not None else 'nothing'
                incomplete.append(f'{f.name}: its writer did not finish (no summary); '
                                  f'counted from its complete chunks; lost: {lost}')
            elif mf.stop is not None:  # finished, unindexed, and unreadable part way
                incomplete.append(f'{f.name}: corrupted; counted up to the damage; '
                                  f'unreadable: {mf.stop.describe()}')
        finally:
            mf.close()
    custom = custom_data_of(meta, f'{path}/metadata.yaml')
    return BagInfo(
        path=path, files=[f.name for f in files], size=size, storage_id='mcap',
        ros_distro=str(meta.get('ros_distro') or 'unknown'),
        start_ns=min(s[0] for s in spans) if spans else None,
        end_ns=max(s[1] for s in spans) if spans else None,
        message_count=sum(t.count for t in topics.values()),
        topics=sorted(topics.values(), key=lambda t: t.name),
        compression=', '.join(sorted(c or 'none' for c in compressions)),
        custom_data=custom,
        incomplete=incomplete)


def _size_text(n_bytes):
    """Bytes as rosbag2 prints them: '812 B', '12.6 KiB', '3.4 MiB'."""
    size = float(n_bytes)
    units = ('B', 'KiB', 'MiB', 'GiB', 'TiB')
    index = 0
    while size >= 1024 and index < len(units) - 1:
        size /= 1024
        index += 1
    return f'{size:.0f} {units[index]}' if index == 0 else f'{size:.1f} {units[index]}'


def _time_text(t_ns):
    """'Jan  1 2024 00:00:00.050000000 UTC (1704067200.050000000)'."""
    sec, nsec = divmod(int(t_ns), 1_000_000_000)
    d = datetime.fromtimestamp(sec, tz=timezone.utc)
    return (f'{d:%b} {d.day:2d} {d.year} {d:%H:%M:%S}.{nsec:09d} UTC '
            f'({stamp_text(t_ns)})')


def _block(label, lines):
    """Label + first line, continuation lines aligned under it."""
    if not lines:
        return [f'{label:<{_LABEL_WIDTH}}']
    out = [f'{label:<{_LABEL_WIDTH}}{lines[0]}']
    out += [' ' * _LABEL_WIDTH + line for line in lines[1:]]
    return out


def format_bag_info(info):
    """The text ``ros2 bag info`` prints for it (plus chunk compression, custom_data and a
    warning for incomplete files), as a list of lines."""
    out = _block('Files:', info.files)
    out += _block('Bag size:', [_size_text(info.size)])
    out += _block('Storage id:', [info.storage_id
                                  + (f' (chunks: {info.compression})' if info.compression
                                     else '')])
    out += _block('ROS Distro:', [info.ros_distro])
    out += _block('Duration:', [f'{stamp_text(info.duration_ns)}s'])
    if info.start_ns is None:
        out += _block('Start:', ['- (no messages)'])
        out += _block('End:', ['- (no messages)'])
    else:
        out += _block('Start:', [_time_text(info.start_ns)])
        out += _block('End:', [_time_text(info.end_ns)])
    out += _block('Messages:', [str(info.message_count)])
    out += _block('Topic information:', [
        f'Topic: {t.name} | Type: {t.msgtype} | Count: {t.count} | '
        f'Serialization Format: {t.serialization_format}' for t in info.topics])
    if info.custom_data:
        out += _block('Custom data:', [f'{k}: {v}' for k, v in info.custom_data.items()])
    if info.incomplete:
        out += _block('INCOMPLETE:', info.incomplete + [
            f'`python -m auv_ident bag repair {info.path}` rewrites it complete'])
    return out
