"""
``ros2 bag record``'s options, mapped onto this project's recorder (pure, no rclpy).

The recording itself is ``mecanum_bringup.bag_recorder`` (a rosbag2 bag in MCAP storage,
see its docstring); this module declares rosbag2's (Jazzy) options with their names and
defaults and turns the ones it can honour into the recorder's ROS arguments
(parameters, node name, log level). The others are declared too, so that ``--help``
lists them, and refused with a message saying why (:class:`UnsupportedOption`).

Mapping: TOPICS / ``--topics`` -> parameter ``topics``; ``--services S`` -> the topics
``S/_service_event``; ``-a``/``--all``/``--all-topics`` -> every topic (``topics``
unset); ``--exclude-regex`` and ``--exclude-topics`` -> parameter ``exclude`` (one
regex, searched in the name as rosbag2 does); ``--include-hidden-topics`` ->
``include_hidden_topics``; ``-p/--polling-interval`` (ms) -> ``discovery_period_s``;
``--max-cache-size`` (bytes) -> ``max_cache_size`` (the MCAP chunk held in memory);
``--storage-preset-profile zstd_fast|zstd_small`` -> ``compression: zstd``;
``--use-sim-time`` -> ``use_sim_time``; ``--node-name`` -> the node's name;
``--log-level`` -> the log level. ``-o/--output`` -> ``output`` (default
``rosbag2_YYYY_MM_DD-HH_MM_SS`` as rosbag2).
"""

from argparse import ArgumentParser, Namespace
import datetime
import json
import re
from typing import List

from ros2bag_mcap.api import absolute, service_event_topics, STORAGE_ID

#: rosbag2's default polling interval, ms.
DEFAULT_POLLING_INTERVAL_MS = 100
#: MCAP storage presets of rosbag2_storage_mcap and the recorder's compression for each.
PRESETS = {'none': 'none', 'zstd_fast': 'zstd', 'zstd_small': 'zstd'}
LOG_LEVELS = ['debug', 'info', 'warn', 'error', 'fatal']


class UnsupportedOption(ValueError):
    """An option of rosbag2's ``record`` that the project's recorder cannot honour."""


def default_output(now: datetime.datetime) -> str:
    """Return rosbag2's default bag folder name for a time: rosbag2_YYYY_MM_DD-HH_MM_SS."""
    return now.strftime('rosbag2_%Y_%m_%d-%H_%M_%S')


def add_record_arguments(parser: ArgumentParser) -> None:
    """Declare rosbag2's record options (those not supported say so in their help)."""
    no = ' Not supported by this ros2 bag (refused).'
    parser.add_argument(
        '-o', '--output',
        help='Destination of the bagfile to create, '
             'defaults to a timestamped folder in the current directory.')
    parser.add_argument(
        '-s', '--storage', default=STORAGE_ID,
        help="Storage identifier to be used, defaults to '%(default)s' (the only one here).")
    topics = parser.add_mutually_exclusive_group()
    topics.add_argument(
        'topics_positional', type=str, default=[], metavar='[Topic ...]', nargs='*',
        help='Space-delimited list of topics to record. (deprecated)')
    topics.add_argument(
        '--topics', type=str, default=[], metavar='Topic', nargs='+',
        help='Space-delimited list of topics to record.')
    parser.add_argument(
        '--services', type=str, default=[], metavar='ServiceName', nargs='+',
        help='Space-delimited list of services to record (their service event topics).')
    parser.add_argument(
        '--topic-types', nargs='+', default=[], metavar='TopicType', help='.' + no)
    parser.add_argument(
        '-a', '--all', action='store_true',
        help='Record all topics (Exclude hidden topic). Services are not recorded here.')
    parser.add_argument(
        '--all-topics', action='store_true', help='Record all topics (Exclude hidden topic).')
    parser.add_argument(
        '--all-services', action='store_true',
        help='Record all services via service event topics.' + no)
    parser.add_argument(
        '-e', '--regex', default='',
        help='Record only topics and services containing provided regular expression.' + no)
    parser.add_argument(
        '--exclude-regex', default='',
        help='Exclude topics and services containing provided regular expression. '
             'Works on top of --all or --all-topics.')
    parser.add_argument(
        '--exclude-topic-types', type=str, default=[], metavar='ExcludeTopicTypes',
        nargs='+', help='Space-delimited list of topic types not being recorded.' + no)
    parser.add_argument(
        '--exclude-topics', type=str, default=[], metavar='Topic', nargs='+',
        help='Space-delimited list of topics not being recorded. '
             'Works on top of --all or --all-topics.')
    parser.add_argument(
        '--exclude-services', type=str, default=[], metavar='ServiceName', nargs='+',
        help='Space-delimited list of services not being recorded.')
    parser.add_argument(
        '--include-unpublished-topics', action='store_true',
        help='Discover and record topics which have no publisher.' + no)
    parser.add_argument(
        '--include-hidden-topics', action='store_true',
        help='Discover and record hidden topics as well. '
             'These are topics used internally by ROS 2 implementation.')
    parser.add_argument(
        '--no-discovery', action='store_true',
        help='Disables topic auto discovery during recording.' + no)
    parser.add_argument(
        '-p', '--polling-interval', type=int, default=DEFAULT_POLLING_INTERVAL_MS,
        help='Time in ms to wait between querying available topics for recording.')
    parser.add_argument(
        '--ignore-leaf-topics', action='store_true',
        help='Ignore topics without a subscription.' + no)
    parser.add_argument(
        '--qos-profile-overrides-path',
        help='Path to a yaml file defining overrides of the QoS profile for specific '
             'topics.' + no)
    parser.add_argument(
        '-f', '--serialization-format', default='',
        help="The rmw serialization format in which the messages are saved: 'cdr' only.")
    parser.add_argument(
        '-b', '--max-bag-size', type=int, default=0,
        help='Maximum size in bytes before the bagfile will be split. Only 0 (no '
             'splitting) here.')
    parser.add_argument(
        '-d', '--max-bag-duration', type=int, default=0,
        help='Maximum duration in seconds before the bagfile will be split. Only 0 (no '
             'splitting) here.')
    parser.add_argument(
        '--max-cache-size', type=int, default=None,
        help='Bytes of messages held in memory before they are written (here: the size '
             'of an MCAP chunk; default 786432, as rosbag2 writes MCAP chunks; '
             '0: one chunk per message).')
    parser.add_argument(
        '--disable-keyboard-controls', action='store_true', default=False,
        help='disables keyboard controls for recorder (there are none here)')
    parser.add_argument(
        '--start-paused', action='store_true', default=False,
        help='Start the recorder in a paused state.' + no)
    parser.add_argument(
        '--use-sim-time', action='store_true', default=False,
        help='Use simulation time for message timestamps by subscribing to the /clock '
             'topic. Messages received before the first /clock are written at its time.')
    parser.add_argument(
        '--node-name', type=str, default='rosbag2_recorder',
        help='Specify the recorder node name. Default is %(default)s.')
    parser.add_argument(
        '--custom-data', type=str, metavar='KEY=VALUE', nargs='*', help='.' + no)
    parser.add_argument(
        '--snapshot-mode', action='store_true', help='Enable snapshot mode.' + no)
    parser.add_argument(
        '--log-level', type=str, default='info', choices=LOG_LEVELS, help='Logging level.')
    parser.add_argument(
        '--storage-config-file',
        help='Path to a yaml file defining storage specific configurations.' + no)
    parser.add_argument(
        '--storage-preset-profile', type=str, default='none',
        help='MCAP preset: none (default) or zstd_fast / zstd_small (zstd chunk '
             'compression); fastwrite is not supported.')
    parser.add_argument(
        '--compression-queue-size', type=int, default=1,
        help='Only with rosbag2 compression, which is not supported here (ignored).')
    parser.add_argument(
        '--compression-threads', type=int, default=0,
        help='Only with rosbag2 compression, which is not supported here (ignored).')
    parser.add_argument(
        '--compression-threads-priority', type=int, default=0,
        help='Only with rosbag2 compression, which is not supported here (ignored).')
    parser.add_argument(
        '--compression-mode', type=str, default='none',
        help="rosbag2's file/message compression: only 'none' here (use "
             '--storage-preset-profile zstd_fast for compressed MCAP chunks).')
    parser.add_argument(
        '--compression-format', type=str, default='',
        help="rosbag2's file/message compression format: not supported here.")


def _refuse(option: str, why: str) -> None:
    raise UnsupportedOption(f'{option} is not supported by this ros2 bag (the pip setup '
                            f'records with mecanum_bringup.bag_recorder): {why}')


def check_supported(args: Namespace) -> None:
    """Raise UnsupportedOption for an option the recorder cannot honour."""
    if args.storage != STORAGE_ID:
        _refuse(f'--storage {args.storage}', "bags are written in MCAP storage ('mcap') only")
    flags = (
        ('all_services', '--all-services', 'services are recorded only by --services'),
        ('regex', '--regex', 'list the topics, or use --all with --exclude-regex'),
        ('topic_types', '--topic-types', 'list the topics instead'),
        ('exclude_topic_types', '--exclude-topic-types', 'use --exclude-regex instead'),
        ('include_unpublished_topics', '--include-unpublished-topics',
         'a topic is recorded once it has a publisher'),
        ('no_discovery', '--no-discovery', 'topics are discovered all along'),
        ('ignore_leaf_topics', '--ignore-leaf-topics', 'there is no such filter'),
        ('qos_profile_overrides_path', '--qos-profile-overrides-path',
         'the QoS is adapted to the publishers, as rosbag2 does by default'),
        ('start_paused', '--start-paused', 'there is no pause/resume'),
        ('custom_data', '--custom-data', 'custom_data is always empty'),
        ('snapshot_mode', '--snapshot-mode', 'there is no snapshot service'),
        ('storage_config_file', '--storage-config-file',
         'use --storage-preset-profile or --max-cache-size'),
        ('compression_format', '--compression-format',
         'use --storage-preset-profile zstd_fast (compressed MCAP chunks)'),
    )
    for dest, option, why in flags:
        if getattr(args, dest):
            _refuse(option, why)
    if args.max_bag_size:
        _refuse('--max-bag-size', 'a bag is one file (no splitting)')
    if args.max_bag_duration:
        _refuse('--max-bag-duration', 'a bag is one file (no splitting)')
    if args.compression_mode.lower() != 'none':
        _refuse(f'--compression-mode {args.compression_mode}',
                'use --storage-preset-profile zstd_fast (compressed MCAP chunks)')
    if args.serialization_format not in ('', 'cdr'):
        _refuse(f'--serialization-format {args.serialization_format}',
                "messages are recorded as received ('cdr')")
    if args.storage_preset_profile not in PRESETS:
        _refuse(f'--storage-preset-profile {args.storage_preset_profile}',
                f'the presets here are {", ".join(PRESETS)}')


def check_arguments(args: Namespace) -> None:
    """Raise ValueError (rosbag2's message) for options that do not go together."""
    if args.topics_positional:
        args.topics = args.topics_positional
    if not (args.all or args.all_topics or args.topics or args.services):
        raise ValueError('Need to specify at least one option out of --all, --all-topics, '
                         '--services or --topics')
    if args.exclude_regex and not (args.all or args.all_topics):
        raise ValueError('--exclude-regex argument requires either --all or --all-topics')
    if args.exclude_topics and not (args.all or args.all_topics):
        raise ValueError('--exclude-topics argument requires either --all or --all-topics')
    if args.polling_interval <= 0:
        raise ValueError(f'--polling-interval must be > 0 ms, got {args.polling_interval}')
    if args.max_cache_size is not None and args.max_cache_size < 0:
        raise ValueError(f'--max-cache-size must be >= 0 bytes, got {args.max_cache_size}')
    if args.exclude_regex:
        try:
            re.compile(args.exclude_regex)
        except re.error as error:
            raise ValueError(f'--exclude-regex is not a valid regular expression '
                             f'({error}): {args.exclude_regex!r}') from None


def exclude_pattern(exclude_regex: str, exclude_topics: List[str],
                    exclude_services: List[str]) -> str:
    """Return the recorder's ``exclude`` regex: the regex or any excluded name exactly."""
    names = [absolute(t) for t in exclude_topics or []]
    names += service_event_topics(exclude_services)
    parts = [f'(?:{exclude_regex})'] if exclude_regex else []
    if names:
        parts.append('^(?:' + '|'.join(re.escape(n) for n in names) + ')$')
    return '|'.join(parts)


def _parameter(name: str, value) -> List[str]:
    """Return '-p name:=value' with the value as YAML (JSON is YAML: strings stay strings)."""
    return ['-p', f'{name}:={json.dumps(value)}']


def recorder_arguments(args: Namespace, output: str) -> List[str]:
    """
    Return the ROS arguments that run bag_recorder as these record options ask.

    Raises UnsupportedOption or ValueError (rosbag2's message) for options it refuses.
    """
    check_supported(args)
    check_arguments(args)
    ros_args = ['--ros-args', '-r', f'__node:={args.node_name}',
                '--log-level', args.log_level]
    ros_args += _parameter('output', output)
    if not (args.all or args.all_topics):
        topics = [absolute(t) for t in args.topics] + service_event_topics(args.services)
        ros_args += _parameter('topics', topics)
    exclude = exclude_pattern(args.exclude_regex, args.exclude_topics, args.exclude_services)
    if exclude:
        ros_args += _parameter('exclude', exclude)
    if args.include_hidden_topics:
        ros_args += _parameter('include_hidden_topics', True)
    ros_args += _parameter('discovery_period_s', args.polling_interval / 1000.0)
    if args.max_cache_size is not None:
        ros_args += _parameter('max_cache_size', max(1, args.max_cache_size))
    compression = PRESETS[args.storage_preset_profile]
    if compression != 'none':
        ros_args += _parameter('compression', compression)
    if args.use_sim_time:
        ros_args += _parameter('use_sim_time', True)
    return ros_args
