"""
``ros2 bag info``'s text, laid out as rosbag2 (Jazzy) prints it (pure, no rclpy).

rosbag2_py's ``format_bag_meta_data``: a blank line, then fields padded to 19 columns
(Files, Bag size, Storage id, ROS Distro, Duration, Start, End, Messages, Topic
information, Service, Service information), one topic per line as ``Topic: NAME | Type:
TYPE | Count: N | Serialization Format: FMT``, continuation lines indented by 19
spaces. Service event topics (``.../_service_event`` of a ``.../srv/..._Event`` type) are
counted under Service, not under Topic information or Messages. Times are shown in local
time as ``Mon DD YYYY HH:MM:SS.nnnnnnnnn (seconds.nnnnnnnnn)``; sizes in B, KiB, MiB,
GiB or TiB (powers of 1024, one decimal except for bytes).
"""

import time
from typing import Callable, List, Tuple

from ros2bag_mcap.bag import BagMetadata, TopicInformation

#: Width of the field names ("Topic information: ").
INDENT = 19
SERVICE_EVENT_SUFFIX = '/_service_event'


def format_file_size(size_bytes: int) -> str:
    """Return a size as rosbag2 shows it: '512 B', '44.5 KiB', '2.5 MiB'."""
    size = float(size_bytes)
    units = ('B', 'KiB', 'MiB', 'GiB', 'TiB')
    index = 0
    while size >= 1024 and index < len(units) - 1:
        size /= 1024
        index += 1
    return f'{size:.0f} {units[0]}' if index == 0 else f'{size:.1f} {units[index]}'


def _split_ns(nanoseconds: int) -> Tuple[int, int]:
    """Return (whole seconds, nanoseconds 0..999999999) of a time in ns (floor)."""
    return divmod(int(nanoseconds), 1_000_000_000)


def format_duration(nanoseconds: int) -> str:
    """Return seconds with nine decimals, as rosbag2's "time_in_sec": '6.680000000'."""
    seconds, fraction = _split_ns(nanoseconds)
    return f'{seconds}.{fraction:09d}'


def format_time_point(nanoseconds: int,
                      localtime: Callable[[float], time.struct_time] = time.localtime) -> str:
    """Return 'Nov 28 2026 12:18:34.020000000 (1795864714.020000000)' (local time)."""
    seconds, fraction = _split_ns(nanoseconds)
    moment = localtime(seconds)
    date = f'{time.strftime("%b", moment)} {moment.tm_mday:2d} {moment.tm_year}'
    return (f'{date} {time.strftime("%H:%M:%S", moment)}.{fraction:09d} '
            f'({format_duration(nanoseconds)})')


def is_service_event_topic(name: str, type_name: str) -> bool:
    """Tell whether a topic carries service events (rosbag2's is_service_event_topic)."""
    return ('/srv/' in type_name and type_name.endswith('_Event')
            and name.endswith(SERVICE_EVENT_SUFFIX))


def _topic_line(topic: TopicInformation) -> str:
    return (f'Topic: {topic.name} | Type: {topic.type_name} | Count: {topic.message_count} | '
            f'Serialization Format: {topic.serialization_format}')


def _service_line(topic: TopicInformation) -> str:
    service = topic.name[:-len(SERVICE_EVENT_SUFFIX)]
    service_type = topic.type_name[:-len('_Event')]
    return (f'Service: {service} | Type: {service_type} | Event Count: {topic.message_count}'
            f' | Serialization Format: {topic.serialization_format}')


def _lines(first: str, items: List[str], indent: int) -> str:
    """Return the first item after a field name, the others indented on their own lines."""
    if not items:
        return first + '\n'
    return first + items[0] + '\n' + ''.join(' ' * indent + item + '\n' for item in items[1:])


def format_info(metadata: BagMetadata, only_topics: bool = False,
                localtime: Callable[[float], time.struct_time] = time.localtime) -> str:
    """
    Return ``ros2 bag info``'s text (what rosbag2 prints, but for print's last newline).

    only_topics leaves out the Service lines (rosbag2's ``-v`` output starts this way).
    """
    services = [t for t in metadata.topics if is_service_event_topic(t.name, t.type_name)]
    topics = [t for t in metadata.topics if not is_service_event_topic(t.name, t.type_name)]
    end_ns = metadata.starting_time_ns + metadata.duration_ns
    text = '\n'
    text += _lines('Files:             ', metadata.relative_file_paths, INDENT)
    text += f'Bag size:          {format_file_size(metadata.bag_size)}\n'
    text += f'Storage id:        {metadata.storage_identifier}\n'
    text += f'ROS Distro:        {metadata.ros_distro or "unknown"}\n'
    text += f'Duration:          {format_duration(metadata.duration_ns)}s\n'
    text += f'Start:             {format_time_point(metadata.starting_time_ns, localtime)}\n'
    text += f'End:               {format_time_point(end_ns, localtime)}\n'
    text += (f'Messages:          '
             f'{metadata.message_count - sum(s.message_count for s in services)}\n')
    text += _lines('Topic information: ', [_topic_line(t) for t in topics], INDENT)
    if not only_topics:
        text += f'Service:           {len(services)}\n'
        text += 'Service information: '
        if services:
            text += _lines('', [_service_line(s) for s in services], INDENT + 2)
    return text


def topic_names(metadata: BagMetadata) -> List[str]:
    """Return the names of the bag's topics, service event topics left out (``info -t``)."""
    return [t.name for t in metadata.topics if not is_service_event_topic(t.name, t.type_name)]
