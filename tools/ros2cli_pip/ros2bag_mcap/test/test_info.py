"""``ros2 bag info``: the text of bags written here, and one-line errors for bad input."""

from argparse import Namespace
import os
import shutil
import time

import pytest
from ros2bag_mcap.bag import BagError, iter_messages, open_bag
from ros2bag_mcap.info import format_file_size, format_info, TopicInformation
from ros2bag_mcap.verb.info import InfoVerb

from bag_samples import cdr_string, MESSAGES, START_NS, write_mcap  # noqa: I100

S = 10 ** 9


def folder_size(directory) -> int:
    return sum(os.path.getsize(os.path.join(directory, n)) for n in os.listdir(directory))


def expected_info(files: str, size: int, distro: str = 'jazzy') -> str:
    """Return the info of the test bag (6 messages 0.1 s apart from START_NS), in UTC."""
    return (
        '\n'
        f'Files:             {files}\n'
        f'Bag size:          {format_file_size(size)}\n'
        'Storage id:        mcap\n'
        f'ROS Distro:        {distro}\n'
        'Duration:          0.500000000s\n'
        'Start:             Nov 14 2023 22:13:20.500000000 (1700000000.500000000)\n'
        'End:               Nov 14 2023 22:13:21.000000000 (1700000001.000000000)\n'
        'Messages:          6\n'
        'Topic information: Topic: /chatter | Type: std_msgs/msg/String | Count: 3 | '
        'Serialization Format: cdr\n'
        '                   Topic: /latched | Type: std_msgs/msg/String | Count: 3 | '
        'Serialization Format: cdr\n'
        'Service:           0\n'
        'Service information: ')


def test_info_of_a_project_bag_folder_is_rosbag2s_layout(project_bag):
    bag = open_bag(str(project_bag))
    assert format_info(bag.metadata, localtime=time.gmtime) == expected_info(
        'test_bag_0.mcap', folder_size(project_bag))
    latched = bag.metadata.topics[1]
    assert latched.offered_qos_profiles[0]['durability'] == 'transient_local'


def test_info_without_metadata_yaml_reads_the_mcap_summary(project_bag):
    os.remove(project_bag / 'metadata.yaml')
    bag = open_bag(str(project_bag))
    assert format_info(bag.metadata, localtime=time.gmtime) == expected_info(
        'test_bag_0.mcap', folder_size(project_bag))
    # The QoS comes from the channel's metadata then.
    assert bag.metadata.topics[1].offered_qos_profiles[0]['durability'] == 'transient_local'


def test_info_of_a_single_mcap_file(project_bag):
    path = str(project_bag / 'test_bag_0.mcap')
    bag = open_bag(path)
    assert format_info(bag.metadata, localtime=time.gmtime) == expected_info(
        path, os.path.getsize(path))


def test_info_of_an_mcap_without_rosbag2_metadata_or_summary(tmp_path):
    plain = tmp_path / 'plain.mcap'
    write_mcap(plain, MESSAGES)
    assert format_info(open_bag(str(plain)).metadata, localtime=time.gmtime) == \
        expected_info(str(plain), os.path.getsize(plain), distro='unknown')
    bare = tmp_path / 'bare.mcap'
    write_mcap(bare, MESSAGES, summary=False,
               rosbag2_record={'serialized_metadata': 'ros_distro: rolling\n'})
    assert format_info(open_bag(str(bare)).metadata, localtime=time.gmtime) == \
        expected_info(str(bare), os.path.getsize(bare), distro='rolling')


def test_info_of_a_folder_of_split_files_without_metadata(tmp_path):
    write_mcap(tmp_path / 'b_0.mcap', MESSAGES[:4])
    write_mcap(tmp_path / 'b_1.mcap', MESSAGES[4:])
    bag = open_bag(str(tmp_path))
    text = format_info(bag.metadata, localtime=time.gmtime)
    assert text.startswith('\nFiles:             b_0.mcap\n                   b_1.mcap\n')
    assert text.endswith(expected_info('-', 0, 'unknown').split('Storage id:')[1].replace(
        'ROS Distro:        unknown\n', 'ROS Distro:        unknown\n'))
    assert [m.data for m in iter_messages(bag)] == [cdr_string(t) for _, _, t in MESSAGES]


def test_services_are_counted_apart_from_topics(project_bag):
    metadata = open_bag(str(project_bag)).metadata
    metadata.topics.append(TopicInformation(
        '/add/_service_event', 'example_interfaces/srv/AddTwoInts_Event', message_count=4))
    metadata.topics.append(TopicInformation(
        '/mul/_service_event', 'example_interfaces/srv/Mul_Event', message_count=2))
    metadata.message_count += 6
    text = format_info(metadata, localtime=time.gmtime)
    assert 'Messages:          6\n' in text
    assert 'service_event' not in text.split('Service:')[0]
    assert text.endswith(
        'Service:           2\n'
        'Service information: Service: /add | Type: example_interfaces/srv/AddTwoInts | '
        'Event Count: 4 | Serialization Format: cdr\n'
        '                     Service: /mul | Type: example_interfaces/srv/Mul | '
        'Event Count: 2 | Serialization Format: cdr\n')


def test_an_empty_bag(tmp_path):
    bag_writer = pytest.importorskip('mecanum_bringup.bag_writer')
    bag_writer.BagWriter(str(tmp_path / 'empty')).close()
    text = format_info(open_bag(str(tmp_path / 'empty')).metadata, localtime=time.gmtime)
    assert 'Duration:          0.000000000s\n' in text
    assert 'Start:             Jan  1 1970 00:00:00.000000000 (0.000000000)\n' in text
    assert 'Messages:          0\nTopic information: \nService:' in text


@pytest.mark.parametrize('size, text', [
    (0, '0 B'), (1023, '1023 B'), (1024, '1.0 KiB'), (45568, '44.5 KiB'),
    (int(2.5 * 1024 ** 2), '2.5 MiB'), (3 * 1024 ** 3, '3.0 GiB'), (2 * 1024 ** 5, '2048.0 TiB')])
def test_sizes_as_rosbag2_shows_them(size, text):
    assert format_file_size(size) == text


def test_messages_in_log_time_order_filtered_by_topic_and_start(project_bag):
    bag = open_bag(str(project_bag))
    messages = list(iter_messages(bag))
    assert [(m.topic, m.log_time_ns) for m in messages] == [(t, s) for t, s, _ in MESSAGES]
    assert messages[3].data == cdr_string('message 3')
    assert [m.log_time_ns for m in iter_messages(bag, ['/latched'], START_NS + S // 5)] == [
        START_NS + 3 * S // 10, START_NS + 5 * S // 10]


def run_info(path, **options) -> str:
    """Run the info verb; return what it returns (an error text or 0)."""
    args = Namespace(bag_path=str(path), storage='', topic_name=False, verbose=False)
    vars(args).update(options)
    return InfoVerb().main(args=args)


def assert_one_line_error(result, *words):
    assert isinstance(result, str), result
    assert result.startswith('[ERROR] [ros2bag]: ') and '\n' not in result, result
    for word in words:
        assert word in result, result


def test_errors_are_one_line(tmp_path, project_bag):
    assert_one_line_error(run_info(tmp_path / 'missing'), 'does not exist')
    (tmp_path / 'empty').mkdir()
    assert_one_line_error(run_info(tmp_path / 'empty'), 'is not a bag')
    text = tmp_path / 'text.mcap'
    text.write_text('hello, this is not MCAP\n' * 10)
    assert_one_line_error(run_info(text), 'not an MCAP file')
    data = (project_bag / 'test_bag_0.mcap').read_bytes()
    for cut in (len(data) // 2, len(data) - 5, 12):
        truncated = tmp_path / f'cut_{cut}.mcap'
        truncated.write_bytes(data[:cut])
        assert_one_line_error(run_info(truncated), 'truncated or corrupt')
    corrupt = tmp_path / 'corrupt.mcap'
    corrupt.write_bytes(data[:100] + bytes(len(data) - 200) + data[-100:])
    assert_one_line_error(run_info(corrupt), 'corrupt')
    assert_one_line_error(run_info(project_bag, storage='sqlite3'), 'sqlite3')
    assert_one_line_error(run_info(project_bag, verbose=True), 'verbose')


@pytest.mark.parametrize('content, words', [
    ('rosbag2_bagfile_information: {version: 9\n', ('not valid YAML',)),
    ('- just\n- a list\n', ('missing field rosbag2_bagfile_information',)),
    ('rosbag2_bagfile_information:\n  version: 9\n', ('missing field topics_with_message',)),
    ('rosbag2_bagfile_information:\n  topics_with_message_count: []\n'
     '  relative_file_paths: [a.mcap]\n  storage_identifier: mcap\n'
     '  starting_time: {nanoseconds_since_epoch: 0}\n  duration: {nanoseconds: five}\n',
     ('duration.nanoseconds is not int',)),
])
def test_malformed_metadata_yaml_is_one_line_error(project_bag, content, words):
    (project_bag / 'metadata.yaml').write_text(content)
    assert_one_line_error(run_info(project_bag), 'metadata.yaml', *words)


def test_topic_names_only(project_bag, capsys):
    assert run_info(project_bag, topic_name=True) == 0
    assert capsys.readouterr().out == '/chatter\n/latched\n'


def test_a_truncated_file_stops_message_reading_with_an_error(tmp_path, project_bag):
    data = (project_bag / 'test_bag_0.mcap').read_bytes()
    shutil.copytree(project_bag, tmp_path / 'copy')
    (tmp_path / 'copy' / 'test_bag_0.mcap').write_bytes(data[:len(data) // 2])
    bag = open_bag(str(tmp_path / 'copy'))  # metadata.yaml alone is fine, as rosbag2
    with pytest.raises(BagError, match='truncated or corrupt'):
        list(iter_messages(bag))
