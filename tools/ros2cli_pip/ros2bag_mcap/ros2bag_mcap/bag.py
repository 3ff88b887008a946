"""
Reading rosbag2 bags in MCAP storage: their metadata and their messages (pure, no rclpy).

A bag is what ``ros2 bag record -s mcap`` (Jazzy) and this project's bag_recorder write:
a folder holding ``metadata.yaml`` and the ``.mcap`` files it lists
(``relative_file_paths``), or a single ``.mcap`` file. The metadata is metadata.yaml's
when the folder has one (as rosbag2: the MCAP files are then not opened by ``info``);
otherwise it is read from the MCAP summary (statistics, channels, schemas) of the
folder's ``.mcap`` files, or of the one file, as rosbag2's MCAP plugin does. The ROS
distribution comes from rosbag2's 'rosbag2' metadata record when there is one.

Times are integers in nanoseconds since the epoch (or since the start of simulated
time, for bags recorded on it); sizes in bytes. Every failure to read a bag is a
:class:`BagError` with a one-line message naming the path.
"""

from dataclasses import dataclass, field
import heapq
import os
import struct
from typing import Dict, Iterable, Iterator, List, Mapping, Optional, Sequence

from mcap.exceptions import InvalidMagic, McapError
from mcap.reader import make_reader
from mcap.records import Channel, Footer, Message, Metadata, Schema, Statistics
from mcap.stream_reader import StreamReader
import yaml

METADATA_FILE = 'metadata.yaml'
#: What a corrupt file can make the mcap library raise (besides McapError).
_READ_ERRORS = (McapError, struct.error, ValueError, EOFError, KeyError, IndexError,
                UnicodeDecodeError, MemoryError, OSError, RuntimeError)


class BagError(Exception):
    """A bag that cannot be read; the message is one line, naming the path."""


@dataclass
class TopicInformation:
    """One topic of a bag and its message count (rosbag2's TopicInformation)."""

    name: str
    type_name: str
    serialization_format: str = 'cdr'
    offered_qos_profiles: List[dict] = field(default_factory=list)
    type_description_hash: str = ''
    message_count: int = 0


@dataclass
class BagMetadata:
    """What ``ros2 bag info`` shows of a bag (rosbag2's BagMetadata)."""

    relative_file_paths: List[str]
    bag_size: int
    storage_identifier: str
    ros_distro: str
    starting_time_ns: int
    duration_ns: int
    message_count: int
    topics: List[TopicInformation]
    version: int = 9


@dataclass
class Bag:
    """A bag opened for reading: its metadata and the MCAP files holding its messages."""

    path: str
    metadata: BagMetadata
    mcap_paths: List[str]


@dataclass(frozen=True)
class BagMessage:
    """One recorded message: topic, log and publish times (ns), CDR bytes."""

    topic: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes


def directory_size(directory: str) -> int:
    """Sum of the sizes of the files directly in a folder (rosbag2's bag size), bytes."""
    total = 0
    with os.scandir(directory) as entries:
        for entry in entries:
            if entry.is_file():
                total += entry.stat().st_size
    return total


def open_bag(path: str) -> Bag:
    """Open a bag folder or a single .mcap file; BagError when it is not a readable bag."""
    if not os.path.exists(path):
        raise BagError(f"Bag path '{path}' does not exist")
    if os.path.isdir(path):
        try:
            if os.path.isfile(os.path.join(path, METADATA_FILE)):
                metadata = read_metadata_yaml(path)
                mcap_paths = [os.path.join(path, f) for f in metadata.relative_file_paths]
                return Bag(path, metadata, mcap_paths)
            names = sorted(n for n in os.listdir(path) if n.endswith('.mcap')
                           and os.path.isfile(os.path.join(path, n)))
            if not names:
                raise BagError(f"'{path}' is not a bag: it has neither {METADATA_FILE} "
                               'nor .mcap files')
            mcap_paths = [os.path.join(path, n) for n in names]
            parts = [read_mcap_metadata(p, n) for p, n in zip(mcap_paths, names)]
            metadata = merge_metadata(parts, directory_size(path))
            return Bag(path, metadata, mcap_paths)
        except OSError as error:
            raise BagError(f"cannot read bag '{path}': {error.strerror or error}") from None
    metadata = read_mcap_metadata(path, path)
    return Bag(path, metadata, [path])


def _field(data, *keys, kind=None, where: str = ''):
    """Return data[keys[0]][keys[1]]...; BagError naming the missing or mistyped field."""
    value = data
    for index, key in enumerate(keys):
        if not isinstance(value, Mapping) or key not in value:
            name = '.'.join(keys[:index + 1])
            raise BagError(f'{where}: missing field {name}')
        value = value[key]
    if kind is not None and (not isinstance(value, kind) or isinstance(value, bool)
                             and kind is not bool):
        raise BagError(f'{where}: field {".".join(keys)} is not {kind.__name__}: {value!r}')
    return value


def qos_profiles(value, where: str) -> List[dict]:
    """Return offered_qos_profiles as a list of dicts (a YAML string before version 9)."""
    if value in (None, ''):
        return []
    if isinstance(value, str):
        try:
            value = yaml.safe_load(value)
        except yaml.YAMLError as error:
            raise BagError(f'{where}: offered_qos_profiles is not YAML '
                           f'({str(error).splitlines()[0]})') from None
        if value is None:
            return []
    if not isinstance(value, list) or not all(isinstance(p, Mapping) for p in value):
        raise BagError(f'{where}: offered_qos_profiles is not a list of QoS profiles')
    return [dict(p) for p in value]


def parse_metadata(document, where: str, bag_size: int) -> BagMetadata:
    """Return the BagMetadata of a metadata.yaml document (rosbag2 versions 4 to 9)."""
    info = _field(document, 'rosbag2_bagfile_information', kind=dict, where=where)
    topics = []
    entries = _field(info, 'topics_with_message_count', kind=list, where=where)
    for number, entry in enumerate(entries):
        at = f'{where}: topics_with_message_count[{number}]'
        meta = _field(entry, 'topic_metadata', kind=dict, where=at)
        topics.append(TopicInformation(
            name=_field(meta, 'name', kind=str, where=at),
            type_name=_field(meta, 'type', kind=str, where=at),
            serialization_format=_field(meta, 'serialization_format', kind=str, where=at),
            offered_qos_profiles=qos_profiles(meta.get('offered_qos_profiles'), at),
            type_description_hash=str(meta.get('type_description_hash') or ''),
            message_count=_field(entry, 'message_count', kind=int, where=at)))
    files = _field(info, 'relative_file_paths', kind=list, where=where)
    if not all(isinstance(f, str) for f in files):
        raise BagError(f'{where}: relative_file_paths must be a list of file names')
    return BagMetadata(
        relative_file_paths=list(files),
        bag_size=bag_size,
        storage_identifier=_field(info, 'storage_identifier', kind=str, where=where),
        ros_distro=str(info.get('ros_distro') or ''),
        starting_time_ns=_field(info, 'starting_time', 'nanoseconds_since_epoch', kind=int,
                                where=where),
        duration_ns=_field(info, 'duration', 'nanoseconds', kind=int, where=where),
        message_count=_field(info, 'message_count', kind=int, where=where),
        topics=topics,
        version=info.get('version', 9) if isinstance(info.get('version'), int) else 9)


def read_metadata_yaml(directory: str) -> BagMetadata:
    """Read a bag folder's metadata.yaml; BagError if it is not rosbag2 metadata."""
    path = os.path.join(directory, METADATA_FILE)
    try:
        with open(path, encoding='utf-8') as file:
            document = yaml.safe_load(file)
    except yaml.YAMLError as error:
        raise BagError(f"'{path}' is not valid YAML "
                       f'({" ".join(str(error).split())})') from None
    except UnicodeDecodeError:
        raise BagError(f"'{path}' is not a text file") from None
    return parse_metadata(document, f"malformed '{path}'", directory_size(directory))


@dataclass
class _Scan:
    """The parts of an MCAP file that make its metadata."""

    schemas: Dict[int, Schema] = field(default_factory=dict)
    channels: Dict[int, Channel] = field(default_factory=dict)
    statistics: Optional[Statistics] = None
    metadata: List[Metadata] = field(default_factory=list)


def _scan_records(stream) -> _Scan:
    """Read a whole MCAP file record by record (a file written without summary)."""
    scan = _Scan()
    counts: Dict[int, int] = {}
    start, end = None, None
    for record in StreamReader(stream, skip_magic=False).records:
        if isinstance(record, Schema):
            scan.schemas[record.id] = record
        elif isinstance(record, Channel):
            scan.channels[record.id] = record
        elif isinstance(record, Metadata):
            scan.metadata.append(record)
        elif isinstance(record, Message):
            counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
            start = record.log_time if start is None else min(start, record.log_time)
            end = record.log_time if end is None else max(end, record.log_time)
        elif isinstance(record, Footer):
            break
    scan.statistics = Statistics(
        message_count=sum(counts.values()), schema_count=len(scan.schemas),
        channel_count=len(scan.channels), attachment_count=0,
        metadata_count=len(scan.metadata), chunk_count=0,
        message_start_time=start or 0, message_end_time=end or 0,
        channel_message_counts=counts)
    return scan


def _read_mcap(stream) -> _Scan:
    """Return the schemas, channels, statistics and metadata records of an MCAP file."""
    reader = make_reader(stream)
    summary = reader.get_summary()
    if summary is None or summary.statistics is None:
        stream.seek(0)
        return _scan_records(stream)
    scan = _Scan(dict(summary.schemas), dict(summary.channels), summary.statistics)
    scan.metadata = [m for m in reader.iter_metadata() if m.name == 'rosbag2']
    return scan


def read_mcap_metadata(path: str, relative_path: str) -> BagMetadata:
    """
    Return the metadata of one MCAP file, from its summary (rosbag2's MCAP plugin's way).

    relative_path is the name shown under "Files". BagError for a file that is not MCAP,
    truncated (no footer: a recording that was not finished) or corrupt.
    """
    try:
        stream = open(path, 'rb')
    except OSError as error:
        raise BagError(f"cannot read '{path}': {error.strerror or error}") from None
    try:
        with stream:
            scan = _read_mcap(stream)
    except InvalidMagic:
        raise BagError(f"'{path}' is not an MCAP file (no MCAP magic bytes)") from None
    except _READ_ERRORS as error:
        detail = ' '.join(str(error).split()) or type(error).__name__
        raise BagError(f"'{path}' is truncated or corrupt, not a complete MCAP file "
                       f'({detail})') from None
    ros_distro = ''
    for record in scan.metadata:
        if record.name != 'rosbag2':
            continue
        ros_distro = record.metadata.get('ROS_DISTRO', ros_distro)
        try:
            serialized = yaml.safe_load(record.metadata.get('serialized_metadata') or '')
        except yaml.YAMLError:
            serialized = None
        if isinstance(serialized, Mapping) and serialized.get('ros_distro'):
            ros_distro = str(serialized['ros_distro'])
    stats = scan.statistics
    topics = []
    for channel_id in sorted(scan.channels):
        channel = scan.channels[channel_id]
        schema = scan.schemas.get(channel.schema_id)
        if schema is None:
            raise BagError(f"'{path}' is corrupt: no schema for topic {channel.topic}")
        topics.append(TopicInformation(
            name=channel.topic, type_name=schema.name,
            serialization_format=channel.message_encoding,
            offered_qos_profiles=qos_profiles(channel.metadata.get('offered_qos_profiles'),
                                              f"'{path}': topic {channel.topic}"),
            type_description_hash=channel.metadata.get('topic_type_hash', ''),
            message_count=stats.channel_message_counts.get(channel_id, 0)))
    start = stats.message_start_time if stats.message_count else 0
    duration = stats.message_end_time - start if stats.message_count else 0
    return BagMetadata(
        relative_file_paths=[relative_path], bag_size=os.path.getsize(path),
        storage_identifier='mcap', ros_distro=ros_distro, starting_time_ns=start,
        duration_ns=duration, message_count=stats.message_count, topics=topics)


def merge_metadata(parts: Sequence[BagMetadata], bag_size: int) -> BagMetadata:
    """Return the metadata of a bag split in several files (counts summed, times spanned)."""
    topics: Dict[str, TopicInformation] = {}
    for part in parts:
        for topic in part.topics:
            if topic.name in topics:
                topics[topic.name].message_count += topic.message_count
            else:
                topics[topic.name] = TopicInformation(**vars(topic))
    with_messages = [p for p in parts if p.message_count]
    start = min((p.starting_time_ns for p in with_messages), default=0)
    end = max((p.starting_time_ns + p.duration_ns for p in with_messages), default=0)
    return BagMetadata(
        relative_file_paths=[f for p in parts for f in p.relative_file_paths],
        bag_size=bag_size, storage_identifier='mcap',
        ros_distro=next((p.ros_distro for p in parts if p.ros_distro), ''),
        starting_time_ns=start, duration_ns=end - start,
        message_count=sum(p.message_count for p in parts), topics=list(topics.values()))


def check_playable(bag: Bag) -> None:
    """Raise BagError unless the bag's messages can be read here (MCAP, files present)."""
    storage = bag.metadata.storage_identifier
    if storage != 'mcap':
        raise BagError(f"'{bag.path}' has storage '{storage}': this ros2 bag (ros2bag_mcap) "
                       'reads MCAP bags only')
    for path in bag.mcap_paths:
        if not os.path.isfile(path):
            raise BagError(f"'{bag.path}': the bag's file '{path}' is missing")


def _file_messages(path: str, topics: Optional[Iterable[str]],
                   start_ns: Optional[int]) -> Iterator[BagMessage]:
    """Yield one MCAP file's messages in log time order; BagError if it is corrupt."""
    try:
        stream = open(path, 'rb')
    except OSError as error:
        raise BagError(f"cannot read '{path}': {error.strerror or error}") from None
    try:
        with stream:
            reader = make_reader(stream)
            for _, channel, message in reader.iter_messages(
                    topics=None if topics is None else list(topics),
                    starting_at=start_ns, log_time_order=True):
                yield BagMessage(channel.topic, message.log_time, message.publish_time,
                                 bytes(message.data))
    except InvalidMagic:
        raise BagError(f"'{path}' is not an MCAP file (no MCAP magic bytes)") from None
    except _READ_ERRORS as error:
        detail = ' '.join(str(error).split()) or type(error).__name__
        raise BagError(f"'{path}' is truncated or corrupt ({detail})") from None


def iter_messages(bag: Bag, topics: Optional[Iterable[str]] = None,
                  start_ns: Optional[int] = None) -> Iterator[BagMessage]:
    """
    Yield the bag's messages in log time order (all files merged), read as they are needed.

    topics: only these (None: all); start_ns: only those logged at or after it.
    """
    topics = None if topics is None else sorted(set(topics))
    streams = [_file_messages(path, topics, start_ns) for path in bag.mcap_paths]
    if len(streams) == 1:
        yield from streams[0]
    else:
        yield from heapq.merge(*streams, key=lambda m: m.log_time_ns)
