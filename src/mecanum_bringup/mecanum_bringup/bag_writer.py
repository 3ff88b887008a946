"""
Writing rosbag2 bags in MCAP storage from serialized messages (pure, no rclpy).

A bag is a directory ``<name>/`` holding ``<name>_0.mcap`` and ``metadata.yaml``, as
``ros2 bag record -s mcap`` (Jazzy) writes it, so ``ros2 bag info``/``play``, the
Foxglove app and the ``mcap`` tools read it. The MCAP file has the profile 'ros2', one
schema per message type (encoding 'ros2msg', the complete definition from
:mod:`mecanum_bringup.message_definitions`; 'unknown' and empty when no definition
is found, as rosbag2 does), one channel per topic (message encoding 'cdr', metadata
``offered_qos_profiles`` and ``topic_type_hash``), messages with the CDR bytes as
received, and at the end rosbag2's 'rosbag2' metadata record and the summary and
indexes. ``metadata.yaml`` is version 9: QoS policies by name ('reliable'),
durations as ``{sec, nsec}``, times in nanoseconds.

Times are integers in nanoseconds: ``log_time`` is the receive time (it orders the
bag; starting_time and duration are taken from it), ``publish_time`` the send time.
Messages are buffered in a chunk until it exceeds ``max_cache_size`` bytes, then
written; :meth:`BagWriter.close` writes the rest, the summary and metadata.yaml.
"""

from dataclasses import dataclass, field
import importlib
import os
import re
from typing import Callable, Dict, List, Optional, Pattern, Sequence, Tuple

from mcap.writer import CompressionType, LIBRARY_IDENTIFIER, Writer
from mecanum_bringup.message_definitions import message_definition, MessageDefinitionError
import yaml

#: rmw's infinite duration (the offered deadline/lifespan/lease of most publishers), ns.
INFINITE_NS = 2 ** 63 - 1
#: rosbag2's MCAP chunk size, bytes.
DEFAULT_MAX_CACHE_SIZE = 768 * 1024
#: metadata.yaml version written (rosbag2 in Jazzy).
METADATA_VERSION = 9
COMPRESSIONS = {'none': CompressionType.NONE, 'zstd': CompressionType.ZSTD,
                'lz4': CompressionType.LZ4}
_POLICIES = {
    'history': ('system_default', 'keep_last', 'keep_all', 'unknown'),
    'reliability': ('system_default', 'reliable', 'best_effort', 'unknown', 'best_available'),
    'durability': ('system_default', 'transient_local', 'volatile', 'unknown',
                   'best_available'),
    'liveliness': ('system_default', 'automatic', 'manual_by_topic', 'unknown',
                   'best_available'),
}


@dataclass(frozen=True)
class OfferedQos:
    """The QoS one publisher offers; policies by rmw name, durations in ns (rmw defaults)."""

    history: str = 'keep_last'
    depth: int = 10
    reliability: str = 'reliable'
    durability: str = 'volatile'
    deadline_ns: int = 0
    lifespan_ns: int = 0
    liveliness: str = 'system_default'
    liveliness_lease_duration_ns: int = 0
    avoid_ros_namespace_conventions: bool = False

    def __post_init__(self):
        """Reject unknown policy names and negative depths or durations."""
        for policy, names in _POLICIES.items():
            if getattr(self, policy) not in names:
                raise ValueError(f'QoS {policy} must be one of {names}, '
                                 f'got {getattr(self, policy)!r}')
        for name in ('depth', 'deadline_ns', 'lifespan_ns', 'liveliness_lease_duration_ns'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f'QoS {name} must be an integer >= 0, got {value!r}')

    def as_yaml(self) -> dict:
        """Return the profile as rosbag2 (metadata version 9) writes it."""
        return {
            'history': self.history,
            'depth': self.depth,
            'reliability': self.reliability,
            'durability': self.durability,
            'deadline': duration_yaml(self.deadline_ns),
            'lifespan': duration_yaml(self.lifespan_ns),
            'liveliness': self.liveliness,
            'liveliness_lease_duration': duration_yaml(self.liveliness_lease_duration_ns),
            'avoid_ros_namespace_conventions': bool(self.avoid_ros_namespace_conventions),
        }


def duration_yaml(nanoseconds: int) -> dict:
    """Return an rmw duration as rosbag2 writes it: {sec, nsec}."""
    sec, nsec = divmod(int(nanoseconds), 10 ** 9)
    return {'sec': sec, 'nsec': nsec}


def adapted_request(offers: Sequence[OfferedQos]) -> Tuple[bool, bool]:
    """
    (reliable, transient_local) for a subscription that matches every offer (rosbag2's rule).

    Reliable only if every publisher is reliable, else best effort (matches all);
    transient local (latched messages are delivered) only if every publisher is, else
    volatile. No publisher: (True, False), the ROS default.
    """
    offers = list(offers)
    if not offers:
        return True, False
    return (all(o.reliability == 'reliable' for o in offers),
            all(o.durability == 'transient_local' for o in offers))


def is_hidden_topic(name: str) -> bool:
    """Tell whether a topic name has a hidden part ('/_action/...'), not recorded by default."""
    return any(part.startswith('_') for part in name.split('/'))


@dataclass
class TopicInfo:
    """One recorded topic: what metadata.yaml says about it."""

    name: str
    type_name: str
    offered_qos: List[OfferedQos] = field(default_factory=list)
    type_description_hash: str = ''
    serialization_format: str = 'cdr'
    message_count: int = 0

    def as_yaml(self) -> dict:
        """Return the topics_with_message_count entry of metadata.yaml."""
        return {
            'topic_metadata': {
                'name': self.name,
                'type': self.type_name,
                'serialization_format': self.serialization_format,
                'offered_qos_profiles': [q.as_yaml() for q in self.offered_qos],
                'type_description_hash': self.type_description_hash,
            },
            'message_count': self.message_count,
        }


def bag_metadata(file_name: str, topics: Sequence[TopicInfo], start_ns: Optional[int],
                 end_ns: Optional[int], ros_distro: str = '') -> dict:
    """
    Return the content of metadata.yaml's ``rosbag2_bagfile_information`` (version 9).

    start_ns/end_ns: first and last log times (None for an empty bag: starting time 0).
    compression_format/mode stay empty: they describe rosbag2's file or message
    compression; MCAP chunk compression is inside the file, invisible to rosbag2.
    """
    count = sum(t.message_count for t in topics)
    start = 0 if start_ns is None else int(start_ns)
    duration = 0 if start_ns is None else int(end_ns) - start
    return {
        'version': METADATA_VERSION,
        'storage_identifier': 'mcap',
        'duration': {'nanoseconds': duration},
        'starting_time': {'nanoseconds_since_epoch': start},
        'message_count': count,
        'topics_with_message_count': [t.as_yaml() for t in topics],
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [file_name],
        'files': [{
            'path': file_name,
            'starting_time': {'nanoseconds_since_epoch': start},
            'duration': {'nanoseconds': duration},
            'message_count': count,
        }],
        'custom_data': {},
        'ros_distro': ros_distro,
    }


def dump_yaml(data) -> str:
    """YAML text in block style, keys in the given order."""
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=False)


class BagWriter:
    """Writes one rosbag2 MCAP bag: add topics, write their serialized messages, close."""

    def __init__(self, directory: str, max_cache_size: int = DEFAULT_MAX_CACHE_SIZE,
                 compression: str = 'none', ros_distro: str = '',
                 definition: Callable[[str], str] = message_definition):
        """
        Create the bag directory (not an existing one) and start its MCAP file.

        Raises FileExistsError for an existing directory, ValueError for a bad
        max_cache_size (bytes, > 0) or compression ('none', 'zstd', 'lz4').
        """
        if isinstance(max_cache_size, bool) or not isinstance(max_cache_size, int) \
                or max_cache_size <= 0:
            raise ValueError(f'max_cache_size must be an integer > 0 (bytes), '
                             f'got {max_cache_size!r}')
        if compression not in COMPRESSIONS:
            raise ValueError(f'compression must be one of {sorted(COMPRESSIONS)}, '
                             f'got {compression!r}')
        if compression != 'none':
            module = {'zstd': 'zstandard', 'lz4': 'lz4.frame'}[compression]
            try:
                importlib.import_module(module)
            except ImportError:
                raise ValueError(f'compression {compression} needs the Python package '
                                 f'{module.split(".")[0]}') from None
        self.directory = os.path.normpath(str(directory))
        if os.path.lexists(self.directory):
            raise FileExistsError(
                f'{self.directory} already exists; choose a new directory '
                '(a bag is never overwritten or appended to)')
        os.makedirs(self.directory)
        self.file_name = os.path.basename(os.path.abspath(self.directory)) + '_0.mcap'
        self.mcap_path = os.path.join(self.directory, self.file_name)
        self.metadata_path = os.path.join(self.directory, 'metadata.yaml')
        self.ros_distro = ros_distro
        self.compression = compression
        self._definition = definition
        self._stream = open(self.mcap_path, 'wb')
        self._writer = Writer(self._stream, chunk_size=max_cache_size,
                              compression=COMPRESSIONS[compression])
        self._writer.start(profile='ros2',
                           library=f'mecanum_bringup.bag_writer; {LIBRARY_IDENTIFIER}')
        self._schemas: Dict[str, int] = {}
        self._channels: Dict[str, int] = {}
        self._topics: Dict[str, TopicInfo] = {}
        self._start_ns: Optional[int] = None
        self._end_ns: Optional[int] = None
        self._closed = False
        self.missing_definitions: Dict[str, str] = {}

    @property
    def closed(self) -> bool:
        """Tell whether the bag is finished."""
        return self._closed

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return sum(t.message_count for t in self._topics.values())

    @property
    def topics(self) -> List[TopicInfo]:
        """Return the topics added so far, in the order they were added."""
        return list(self._topics.values())

    def has_topic(self, name: str) -> bool:
        """Tell whether a topic was added."""
        return name in self._topics

    def add_topic(self, name: str, type_name: str, offered_qos: Sequence[OfferedQos] = (),
                  type_description_hash: str = '') -> bool:
        """
        Add a topic (its schema once per type, and its channel); False if already added.

        A type without a findable definition gets an 'unknown' schema (its messages are
        still recorded, as by rosbag2); the reason is kept in ``missing_definitions``.
        """
        self._check_open()
        if not isinstance(name, str) or not name.startswith('/'):
            raise ValueError(f'topic name must be absolute (start with /), got {name!r}')
        if name in self._topics:
            return False
        offered_qos = list(offered_qos)
        schema_id = self._schemas.get(type_name)
        if schema_id is None:
            try:
                encoding, data = 'ros2msg', self._definition(type_name).encode('utf-8')
            except MessageDefinitionError as error:
                encoding, data = 'unknown', b''
                self.missing_definitions[type_name] = str(error)
            schema_id = self._writer.register_schema(type_name, encoding, data)
            self._schemas[type_name] = schema_id
        self._channels[name] = self._writer.register_channel(
            name, 'cdr', schema_id, {
                'offered_qos_profiles': dump_yaml([q.as_yaml() for q in offered_qos]),
                'topic_type_hash': type_description_hash,
            })
        self._topics[name] = TopicInfo(name, type_name, offered_qos, type_description_hash)
        return True

    def write(self, topic: str, data: bytes, log_time_ns: int,
              publish_time_ns: Optional[int] = None) -> None:
        """Write one serialized message of an added topic (publish time defaults to log time)."""
        self._check_open()
        channel_id = self._channels.get(topic)
        if channel_id is None:
            raise ValueError(f'topic {topic!r} was not added to the bag')
        if publish_time_ns is None:
            publish_time_ns = log_time_ns
        for label, value in (('log_time_ns', log_time_ns), ('publish_time_ns', publish_time_ns)):
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2 ** 64:
                raise ValueError(f'{label} must be an integer >= 0, got {value!r}')
        self._writer.add_message(channel_id, log_time=log_time_ns, data=bytes(data),
                                 publish_time=publish_time_ns)
        self._topics[topic].message_count += 1
        if self._start_ns is None:
            self._start_ns = self._end_ns = log_time_ns
        else:
            self._start_ns = min(self._start_ns, log_time_ns)
            self._end_ns = max(self._end_ns, log_time_ns)

    def metadata(self) -> dict:
        """Return what metadata.yaml would hold now."""
        return bag_metadata(self.file_name, self.topics, self._start_ns, self._end_ns,
                            self.ros_distro)

    def flush(self) -> None:
        """Write the chunk in progress to the file (smaller chunks, less lost on a crash)."""
        self._check_open()
        self._writer.flush()

    def close(self) -> dict:
        """Finish the MCAP file (metadata record, summary, indexes), write metadata.yaml."""
        if self._closed:
            return self.metadata()
        self._closed = True
        metadata = self.metadata()
        try:
            self._writer.add_metadata('rosbag2', {'serialized_metadata': dump_yaml(metadata)})
            self._writer.finish()
        finally:
            self._stream.close()
        temporary = self.metadata_path + '.tmp'
        with open(temporary, 'w', encoding='utf-8') as file:
            file.write(dump_yaml({'rosbag2_bagfile_information': metadata}))
        os.replace(temporary, self.metadata_path)
        return metadata

    def __enter__(self) -> 'BagWriter':
        """Use as a context manager: the bag is closed on exit."""
        return self

    def __exit__(self, *exc_info) -> None:
        """Close the bag."""
        self.close()

    def _check_open(self):
        if self._closed:
            raise ValueError(f'bag {self.directory} is closed')


def compile_pattern(name: str, pattern: str) -> Optional[Pattern]:
    """Compile a regular expression parameter ('' means none); ValueError names it."""
    if not pattern:
        return None
    try:
        return re.compile(pattern)
    except re.error as error:
        raise ValueError(f'parameter {name} is not a valid regular expression '
                         f'({error}): {pattern!r}') from None
