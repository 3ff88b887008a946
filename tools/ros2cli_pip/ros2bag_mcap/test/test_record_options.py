"""``ros2 bag record``'s options as the recorder's ROS arguments, and the refused ones."""

from argparse import ArgumentParser
import datetime
import json

import pytest
from ros2bag_mcap.record_options import (add_record_arguments, default_output,
                                         exclude_pattern, recorder_arguments,
                                         UnsupportedOption)


def parse(*argv):
    """Return the parsed record options of a command line."""
    parser = ArgumentParser()
    add_record_arguments(parser)
    return parser.parse_args(list(argv))


def parameters(ros_args):
    """Return the -p name:=value pairs of ROS arguments, values decoded."""
    pairs = [ros_args[i + 1] for i, arg in enumerate(ros_args) if arg == '-p']
    return {name: json.loads(value) for name, value in (p.split(':=', 1) for p in pairs)}


def test_topics_output_and_rosbag2_defaults():
    ros_args = recorder_arguments(parse('/a', 'b', '-o', 'out'), 'out')
    assert ros_args[:5] == ['--ros-args', '-r', '__node:=rosbag2_recorder',
                            '--log-level', 'info']
    # rosbag2 polls for topics every 100 ms.
    assert parameters(ros_args) == {'output': 'out', 'topics': ['/a', '/b'],
                                    'discovery_period_s': 0.1}
    # --topics and --services (their event topics); an output that looks like a number
    # stays a string.
    assert parameters(recorder_arguments(
        parse('--topics', '/a', '--services', '/add'), '2024'))['topics'] == [
            '/a', '/add/_service_event']
    assert parameters(recorder_arguments(parse('/a'), '2024'))['output'] == '2024'


def test_all_topics_with_exclusions():
    values = parameters(recorder_arguments(
        parse('-a', '--exclude-regex', '^/rosout', '--exclude-topics', '/tf', 'odom'), 'x'))
    assert 'topics' not in values
    assert values['exclude'] == r'(?:^/rosout)|^(?:/tf|/odom)$'
    assert exclude_pattern('', ['/a.b'], ['/s']) == r'^(?:/a\.b|/s/_service_event)$'


def test_other_mapped_options():
    values = parameters(recorder_arguments(parse(
        '--all-topics', '--include-hidden-topics', '-p', '250', '--max-cache-size', '0',
        '--storage-preset-profile', 'zstd_fast', '--use-sim-time', '--node-name', 'rec',
        '--log-level', 'warn', '-s', 'mcap', '-f', 'cdr'), 'x'))
    assert values == {'output': 'x', 'include_hidden_topics': True,
                      'discovery_period_s': 0.25, 'max_cache_size': 1,
                      'compression': 'zstd', 'use_sim_time': True}
    ros_args = recorder_arguments(parse('-a', '--node-name', 'rec', '--log-level', 'warn'),
                                  'x')
    assert ros_args[:5] == ['--ros-args', '-r', '__node:=rec', '--log-level', 'warn']


def test_default_output_is_rosbag2s():
    assert default_output(datetime.datetime(2026, 11, 28, 12, 18, 34)) == \
        'rosbag2_2026_11_28-12_18_34'


@pytest.mark.parametrize('argv, words', [
    (['-a', '-s', 'sqlite3'], ['--storage sqlite3', 'mcap']),
    (['--all-services'], ['--all-services']),
    (['-e', 'scan'], ['--regex']),
    (['--topic-types', 'std_msgs/msg/String'], ['--topic-types']),
    (['-a', '--no-discovery'], ['--no-discovery']),
    (['-a', '-b', '1000'], ['--max-bag-size', 'splitting']),
    (['-a', '-d', '60'], ['--max-bag-duration']),
    (['-a', '--compression-mode', 'file'], ['--compression-mode file', 'zstd_fast']),
    (['-a', '--storage-preset-profile', 'fastwrite'], ['fastwrite']),
    (['-a', '--snapshot-mode'], ['--snapshot-mode']),
    (['-a', '--qos-profile-overrides-path', 'q.yaml'], ['--qos-profile-overrides-path']),
    (['-a', '-f', 'json'], ['--serialization-format json']),
])
def test_unsupported_options_are_refused_with_a_reason(argv, words):
    with pytest.raises(UnsupportedOption) as error:
        recorder_arguments(parse(*argv), 'x')
    assert 'not supported by this ros2 bag' in str(error.value)
    for word in words:
        assert word in str(error.value)


@pytest.mark.parametrize('argv, words', [
    ([], ['Need to specify at least one option']),
    (['/a', '--exclude-regex', 'x'], ['--exclude-regex argument requires']),
    (['/a', '--exclude-topics', '/b'], ['--exclude-topics argument requires']),
    (['-a', '-p', '0'], ['--polling-interval']),
    (['-a', '--exclude-regex', '('], ['not a valid regular expression']),
])
def test_options_that_do_not_go_together(argv, words):
    with pytest.raises(ValueError) as error:
        recorder_arguments(parse(*argv), 'x')
    assert not isinstance(error.value, UnsupportedOption)
    for word in words:
        assert word in str(error.value)
