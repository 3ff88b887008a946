"""
Tests of the rosbag2 MCAP bag writer: bags written here, read back with mcap + mcap_ros2.

The messages are real ROS messages serialized by rclpy; every expected count, time
and metadata field is worked out from what each test writes.
"""

from builtin_interfaces.msg import Time
from geometry_msgs.msg import TransformStamped
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mecanum_bringup.bag_writer import (
    adapted_request, BagWriter, compile_pattern, duration_yaml, INFINITE_NS, is_hidden_topic,
    OfferedQos)
from mecanum_bringup.message_definitions import message_definition
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import LaserScan
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage
import yaml

S = 10 ** 9
LATCHED = OfferedQos(history='keep_last', depth=1, durability='transient_local',
                     deadline_ns=INFINITE_NS, lifespan_ns=INFINITE_NS, liveliness='automatic',
                     liveliness_lease_duration_ns=INFINITE_NS)
BEST_EFFORT = OfferedQos(history='unknown', depth=0, reliability='best_effort',
                         lifespan_ns=1_500_000_000)
HASH = 'RIHS01_' + '0123456789abcdef' * 4
INFINITE_YAML = {'sec': 9223372036, 'nsec': 854775807}


def scan_msg(sec: int) -> LaserScan:
    """Return a small scan stamped sec."""
    msg = LaserScan()
    msg.header.stamp = Time(sec=sec)
    msg.header.frame_id = 'laser'
    msg.angle_min, msg.angle_max, msg.angle_increment = -1.0, 1.0, 1.0
    msg.range_min, msg.range_max = 0.1, 12.0
    msg.ranges = [float(sec), 2.0, 3.0]
    return msg


def tf_static_msg() -> TFMessage:
    """base_link -> laser."""
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id = 'base_link', 'laser'
    t.transform.translation.x = 0.05
    t.transform.rotation.w = 1.0
    return TFMessage(transforms=[t])


def read_back(path):
    """Return (reader summary, header, [(schema, channel, message, decoded)], metadata records)."""
    with open(path, 'rb') as file:
        reader = make_reader(file, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        summary = reader.get_summary()
        messages = list(reader.iter_decoded_messages(log_time_order=False))
        records = {m.name: m.metadata for m in reader.iter_metadata()}
    return summary, header, messages, records


@pytest.fixture
def written_bag(tmp_path):
    """Write a bag of three topics, four messages, out of time order; return it and the data."""
    scans = [serialize_message(scan_msg(6))]
    chatter = [serialize_message(String(data=text)) for text in ('one', 'two')]
    static = serialize_message(tf_static_msg())
    with BagWriter(str(tmp_path / 'run1'), ros_distro='jazzy') as bag:
        assert bag.add_topic('/scan', 'sensor_msgs/msg/LaserScan', [BEST_EFFORT], HASH)
        assert bag.add_topic('/tf_static', 'tf2_msgs/msg/TFMessage', [LATCHED, LATCHED])
        assert bag.add_topic('/chatter', 'std_msgs/msg/String')
        assert not bag.add_topic('/chatter', 'std_msgs/msg/String')  # once only
        bag.write('/chatter', chatter[0], 5 * S, 5 * S - 100)
        bag.write('/scan', scans[0], 6 * S + 1)
        bag.write('/chatter', chatter[1], 7 * S, 7 * S - 100)
        bag.write('/tf_static', static, 4 * S, 1)
        assert bag.message_count == 4
    return tmp_path / 'run1', {'scan': scans, 'chatter': chatter, 'static': static}


def test_bag_directory_holds_the_mcap_file_and_metadata(written_bag):
    directory, _ = written_bag
    assert sorted(p.name for p in directory.iterdir()) == ['metadata.yaml', 'run1_0.mcap']


def test_messages_read_back_identical_and_decoded(written_bag):
    directory, data = written_bag
    summary, header, messages, _ = read_back(directory / 'run1_0.mcap')
    assert header.profile == 'ros2'
    assert summary.statistics.message_count == 4
    by_topic = {}
    for schema, channel, message, decoded in messages:
        by_topic.setdefault(channel.topic, []).append((message, decoded))
    assert [m.data for m, _ in by_topic['/chatter']] == data['chatter']
    assert [d.data for _, d in by_topic['/chatter']] == ['one', 'two']
    assert [(m.log_time, m.publish_time) for m, _ in by_topic['/chatter']] == [
        (5 * S, 5 * S - 100), (7 * S, 7 * S - 100)]
    (scan_message, scan), = by_topic['/scan']
    assert scan_message.data == data['scan'][0]
    assert (scan_message.log_time, scan_message.publish_time) == (6 * S + 1, 6 * S + 1)
    assert scan.header.stamp.sec == 6 and scan.header.frame_id == 'laser'
    assert list(scan.ranges) == [6.0, 2.0, 3.0]
    (static_message, static), = by_topic['/tf_static']
    assert static_message.data == data['static']
    assert static.transforms[0].child_frame_id == 'laser'
    assert static.transforms[0].transform.translation.x == 0.05


def test_indexed_read_returns_messages_in_log_time_order(written_bag):
    directory, _ = written_bag
    with open(directory / 'run1_0.mcap', 'rb') as file:
        order = [(channel.topic, message.log_time)
                 for _, channel, message in make_reader(file).iter_messages()]
    assert order == [('/tf_static', 4 * S), ('/chatter', 5 * S), ('/scan', 6 * S + 1),
                     ('/chatter', 7 * S)]
    with open(directory / 'run1_0.mcap', 'rb') as file:
        window = [channel.topic for _, channel, _ in make_reader(file).iter_messages(
            starting_at=5 * S, ending_before=7 * S)]
    assert window == ['/chatter', '/scan']  # 7 s excluded


def test_schemas_and_channels_are_as_rosbag2_writes_them(written_bag):
    directory, _ = written_bag
    summary, _, _, _ = read_back(directory / 'run1_0.mcap')
    schemas = {s.name: s for s in summary.schemas.values()}
    assert sorted(schemas) == ['sensor_msgs/msg/LaserScan', 'std_msgs/msg/String',
                               'tf2_msgs/msg/TFMessage']
    for name, schema in schemas.items():
        assert schema.encoding == 'ros2msg'
        assert schema.data == message_definition(name).encode()
    channels = {c.topic: c for c in summary.channels.values()}
    assert {c.message_encoding for c in channels.values()} == {'cdr'}
    assert schemas['sensor_msgs/msg/LaserScan'].id == channels['/scan'].schema_id
    scan_qos = yaml.safe_load(channels['/scan'].metadata['offered_qos_profiles'])
    assert scan_qos == [{
        'history': 'unknown', 'depth': 0, 'reliability': 'best_effort',
        'durability': 'volatile', 'deadline': {'sec': 0, 'nsec': 0},
        'lifespan': {'sec': 1, 'nsec': 500000000}, 'liveliness': 'system_default',
        'liveliness_lease_duration': {'sec': 0, 'nsec': 0},
        'avoid_ros_namespace_conventions': False}]
    assert channels['/scan'].metadata['topic_type_hash'] == HASH
    static_qos = yaml.safe_load(channels['/tf_static'].metadata['offered_qos_profiles'])
    assert [q['durability'] for q in static_qos] == ['transient_local'] * 2
    assert static_qos[0]['deadline'] == INFINITE_YAML
    assert yaml.safe_load(channels['/chatter'].metadata['offered_qos_profiles']) == []
    assert summary.statistics.channel_message_counts == {
        channels['/scan'].id: 1, channels['/tf_static'].id: 1, channels['/chatter'].id: 2}


def test_metadata_yaml_is_rosbag2_version_9(written_bag):
    directory, _ = written_bag
    info = yaml.safe_load((directory / 'metadata.yaml').read_text())
    assert list(info) == ['rosbag2_bagfile_information']
    info = info['rosbag2_bagfile_information']
    assert info['version'] == 9
    assert info['storage_identifier'] == 'mcap'
    assert info['relative_file_paths'] == ['run1_0.mcap']
    # Log times 4 s (tf_static) .. 7 s (chatter).
    assert info['starting_time'] == {'nanoseconds_since_epoch': 4 * S}
    assert info['duration'] == {'nanoseconds': 3 * S}
    assert info['message_count'] == 4
    assert info['files'] == [{'path': 'run1_0.mcap',
                              'starting_time': {'nanoseconds_since_epoch': 4 * S},
                              'duration': {'nanoseconds': 3 * S}, 'message_count': 4}]
    assert (info['compression_format'], info['compression_mode']) == ('', '')
    assert info['custom_data'] == {} and info['ros_distro'] == 'jazzy'
    topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    assert {name: t['message_count'] for name, t in topics.items()} == {
        '/scan': 1, '/tf_static': 1, '/chatter': 2}
    scan = topics['/scan']['topic_metadata']
    assert scan['type'] == 'sensor_msgs/msg/LaserScan'
    assert scan['serialization_format'] == 'cdr'
    assert scan['type_description_hash'] == HASH
    assert topics['/chatter']['topic_metadata']['type_description_hash'] == ''
    assert scan['offered_qos_profiles'][0]['reliability'] == 'best_effort'
    static = topics['/tf_static']['topic_metadata']['offered_qos_profiles']
    assert static[0] == {
        'history': 'keep_last', 'depth': 1, 'reliability': 'reliable',
        'durability': 'transient_local', 'deadline': INFINITE_YAML, 'lifespan': INFINITE_YAML,
        'liveliness': 'automatic', 'liveliness_lease_duration': INFINITE_YAML,
        'avoid_ros_namespace_conventions': False}


def test_mcap_carries_rosbag2_metadata_record(written_bag):
    directory, _ = written_bag
    _, _, _, records = read_back(directory / 'run1_0.mcap')
    serialized = yaml.safe_load(records['rosbag2']['serialized_metadata'])
    on_disk = yaml.safe_load((directory / 'metadata.yaml').read_text())
    assert serialized == on_disk['rosbag2_bagfile_information']


def test_existing_directory_is_refused_and_left_alone(tmp_path):
    (tmp_path / 'old').mkdir()
    (tmp_path / 'old' / 'keep.txt').write_text('data')
    with pytest.raises(FileExistsError, match='already exists'):
        BagWriter(str(tmp_path / 'old'))
    assert [p.name for p in (tmp_path / 'old').iterdir()] == ['keep.txt']


def test_parent_directories_are_created_and_trailing_slash_ignored(tmp_path):
    with BagWriter(f'{tmp_path}/a/b/run2/') as bag:
        assert bag.file_name == 'run2_0.mcap'
    assert (tmp_path / 'a/b/run2/run2_0.mcap').is_file()


@pytest.mark.parametrize('size', [0, -5, 1.5, True, '100'])
def test_bad_cache_size_is_refused(tmp_path, size):
    with pytest.raises(ValueError, match='max_cache_size'):
        BagWriter(str(tmp_path / 'bag'), max_cache_size=size)
    assert not (tmp_path / 'bag').exists()


def test_bad_compression_is_refused(tmp_path):
    with pytest.raises(ValueError, match='compression'):
        BagWriter(str(tmp_path / 'bag'), compression='gzip')
    assert not (tmp_path / 'bag').exists()


def test_bad_writes_are_refused(tmp_path):
    with BagWriter(str(tmp_path / 'bag')) as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
        data = serialize_message(String(data='x'))
        with pytest.raises(ValueError, match='absolute'):
            bag.add_topic('chatter', 'std_msgs/msg/String')
        with pytest.raises(ValueError, match="'/other' was not added"):
            bag.write('/other', data, 1)
        for bad_time in (-1, 1.5, float('nan'), None, True, 2 ** 64):
            with pytest.raises(ValueError, match='log_time_ns'):
                bag.write('/chatter', data, bad_time)
        with pytest.raises(ValueError, match='publish_time_ns'):
            bag.write('/chatter', data, 1, -1)
        bag.write('/chatter', data, 10)
    with pytest.raises(ValueError, match='closed'):
        bag.write('/chatter', data, 11)
    assert bag.close()['message_count'] == 1  # closing again changes nothing
    summary, _, messages, _ = read_back(tmp_path / 'bag' / 'bag_0.mcap')
    assert [m.log_time for _, _, m, _ in messages] == [10]


def test_unknown_type_is_recorded_with_an_unknown_schema(tmp_path):
    with BagWriter(str(tmp_path / 'bag')) as bag:
        bag.add_topic('/odd', 'no_such_msgs/msg/Odd')
        bag.write('/odd', b'\x00\x01\x00\x00abcd', 3)
        assert 'no_such_msgs' in bag.missing_definitions['no_such_msgs/msg/Odd']
    with open(tmp_path / 'bag' / 'bag_0.mcap', 'rb') as file:
        reader = make_reader(file)
        (schema, channel, message), = list(reader.iter_messages())
    assert (schema.name, schema.encoding, schema.data) == ('no_such_msgs/msg/Odd', 'unknown', b'')
    assert message.data == b'\x00\x01\x00\x00abcd'
    info = yaml.safe_load((tmp_path / 'bag' / 'metadata.yaml').read_text())
    assert info['rosbag2_bagfile_information']['message_count'] == 1


def test_empty_bag_is_valid(tmp_path):
    BagWriter(str(tmp_path / 'empty')).close()
    summary, _, messages, _ = read_back(tmp_path / 'empty' / 'empty_0.mcap')
    assert messages == [] and summary.statistics.message_count == 0
    info = yaml.safe_load((tmp_path / 'empty' / 'metadata.yaml').read_text())
    info = info['rosbag2_bagfile_information']
    assert (info['message_count'], info['topics_with_message_count']) == (0, [])
    assert info['starting_time']['nanoseconds_since_epoch'] == 0
    assert info['duration']['nanoseconds'] == 0


@pytest.mark.parametrize('compression', ['none', 'zstd', 'lz4'])
def test_small_chunks_and_compression_keep_every_message(tmp_path, compression):
    texts = [f'message {i}' for i in range(50)]
    with BagWriter(str(tmp_path / 'bag'), max_cache_size=100, compression=compression) as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
        for i, text in enumerate(texts):
            bag.write('/chatter', serialize_message(String(data=text)), i * 1000)
    summary, _, messages, _ = read_back(tmp_path / 'bag' / 'bag_0.mcap')
    assert summary.statistics.chunk_count > 10
    assert [d.data for _, _, _, d in messages] == texts


def test_qos_durations_and_policies():
    assert duration_yaml(1_500_000_000) == {'sec': 1, 'nsec': 500000000}
    assert duration_yaml(INFINITE_NS) == INFINITE_YAML
    with pytest.raises(ValueError, match='reliability'):
        OfferedQos(reliability='sometimes')
    with pytest.raises(ValueError, match='depth'):
        OfferedQos(depth=-1)
    with pytest.raises(ValueError, match='deadline_ns'):
        OfferedQos(deadline_ns=0.5)


def test_subscription_matches_every_offer():
    reliable = OfferedQos()
    assert adapted_request([]) == (True, False)
    assert adapted_request([reliable]) == (True, False)
    assert adapted_request([LATCHED]) == (True, True)
    assert adapted_request([LATCHED, reliable]) == (True, False)  # one volatile publisher
    assert adapted_request([LATCHED, BEST_EFFORT]) == (False, False)


def test_hidden_topics_and_patterns():
    assert is_hidden_topic('/navigate/_action/feedback')
    assert is_hidden_topic('/_private')
    assert not is_hidden_topic('/tf_static') and not is_hidden_topic('/a_b/c_')
    assert compile_pattern('exclude', '') is None
    assert compile_pattern('exclude', '^/rosout$').search('/rosout')
    with pytest.raises(ValueError, match='parameter exclude'):
        compile_pattern('exclude', '([unclosed')
