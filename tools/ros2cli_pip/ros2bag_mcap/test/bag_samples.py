"""Bags for the tests: std_msgs/String messages written with the mcap writer alone."""

import struct

from mcap.writer import Writer
import yaml

S = 10 ** 9
#: Start of the test bags: 2023-11-14 22:13:20.5 UTC, in ns.
START_NS = 1_700_000_000 * S + S // 2
STRING_DEFINITION = 'string data\n'


def cdr_string(text: str) -> bytes:
    """Return std_msgs/msg/String serialized as CDR (little endian), as rmw does."""
    data = text.encode() + b'\0'
    return b'\x00\x01\x00\x00' + struct.pack('<I', len(data)) + data


#: The test bag: (topic, log time ns, text), 0.1 s apart, /chatter and /latched.
MESSAGES = [('/chatter' if i % 2 == 0 else '/latched', START_NS + i * S // 10, f'message {i}')
            for i in range(6)]


def write_mcap(path, messages, summary: bool = True, rosbag2_record: dict = None) -> None:
    """Write an MCAP file of std_msgs/String messages with the mcap writer alone."""
    with open(path, 'wb') as stream:
        writer = Writer(stream, use_summary_offsets=summary, use_statistics=summary,
                        use_chunking=summary, repeat_channels=summary,
                        repeat_schemas=summary)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema('std_msgs/msg/String', 'ros2msg',
                                        STRING_DEFINITION.encode())
        channels = {}
        for topic, log_time, text in messages:
            if topic not in channels:
                qos = yaml.safe_dump([{'history': 'keep_last', 'depth': 10,
                                       'reliability': 'reliable',
                                       'durability': 'volatile'}])
                channels[topic] = writer.register_channel(
                    topic, 'cdr', schema, {'offered_qos_profiles': qos})
            writer.add_message(channels[topic], log_time, cdr_string(text), log_time)
        if rosbag2_record is not None:
            writer.add_metadata('rosbag2', rosbag2_record)
        writer.finish()
