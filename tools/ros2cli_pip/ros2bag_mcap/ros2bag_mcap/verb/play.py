"""``ros2 bag play``: publish a bag's messages at their recorded time spacing."""

from ros2bag_mcap.api import (absolute, check_not_negative_float, check_not_negative_int,
                              check_positive_float, print_error, service_event_topics)
from ros2bag_mcap.bag import BagError, check_playable, open_bag
from ros2bag_mcap.offer import parse_overrides
from ros2bag_mcap.selection import TopicFilter
from ros2bag_mcap.verb import VerbExtension
from ros2bag_mcap.verb.info import add_reader_arguments, check_storage
import yaml

#: rosbag2's default /clock frequency for a bare --clock, Hz.
DEFAULT_CLOCK_HZ = 40.0
NOT_HERE = ' Not supported by this ros2 bag (refused).'


class PlayVerb(VerbExtension):
    """Play back ROS data from a bag."""

    def add_arguments(self, parser, cli_name):  # noqa: D102
        add_reader_arguments(parser)
        parser.add_argument(
            '--read-ahead-queue-size', type=int, default=1000,
            help='Accepted for compatibility: messages are read from the file as they are '
                 'needed, so there is no queue to size.')
        parser.add_argument(
            '-r', '--rate', type=check_positive_float, default=1.0,
            help='rate at which to play back messages. Valid range > 0.0.')
        parser.add_argument(
            '--topics', type=str, default=[], metavar='topic', nargs='+',
            help='Space-delimited list of topics to play.')
        parser.add_argument(
            '--services', type=str, default=[], metavar='service', nargs='+',
            help='Space-delimited list of services to play (their service event topics).')
        parser.add_argument(
            '-e', '--regex', default='',
            help='Play only topics and services matches with regular expression.')
        parser.add_argument(
            '-x', '--exclude-regex', default='',
            help='regular expressions to exclude topics and services from replay.')
        parser.add_argument(
            '--exclude-topics', type=str, default=[], metavar='topic', nargs='+',
            help='Space-delimited list of topics not to play.')
        parser.add_argument(
            '--exclude-services', type=str, default=[], metavar='service', nargs='+',
            help='Space-delimited list of services not to play.')
        parser.add_argument(
            '--qos-profile-overrides-path',
            help='Path to a yaml file defining overrides of the QoS profile for specific '
                 'topics.')
        parser.add_argument(
            '-l', '--loop', action='store_true',
            help='enables loop playback when playing a bagfile: it starts back at the '
                 'beginning on reaching the end and plays indefinitely.')
        parser.add_argument(
            '--remap', '-m', default=[], nargs='+',
            help='list of topics to be remapped: in the form '
                 '"old_topic1:=new_topic1 old_topic2:=new_topic2 etc." ')
        parser.add_argument(
            '--storage-config-file',
            help='Path to a yaml file defining storage specific configurations.' + NOT_HERE)
        clock = parser.add_mutually_exclusive_group()
        clock.add_argument(
            '--clock', type=check_positive_float, nargs='?', const=DEFAULT_CLOCK_HZ,
            default=0,
            help='Publish to /clock at a specific frequency in Hz, to act as a ROS Time '
                 f'Source (default {DEFAULT_CLOCK_HZ:g} Hz when given without a value). '
                 'Value must be positive. Defaults to not publishing. '
                 'If specified, /clock topic in the bag file is excluded to publish.')
        clock.add_argument(
            '--clock-topics', type=str, default=[], nargs='+',
            help='List of topics separated by spaces that will trigger a /clock update '
                 'when a message is published on them')
        clock.add_argument(
            '--clock-topics-all', default=False, action='store_true',
            help='Publishes an update on /clock immediately before each replayed message')
        parser.add_argument(
            '-d', '--delay', type=check_not_negative_float, default=0.0,
            help='Sleep duration before play (each loop), in seconds.')
        parser.add_argument(
            '--playback-duration', type=float, default=-1.0,
            help='Playback duration, in seconds. Negative durations mark an infinite '
                 'playback. Default is %(default)d.')
        until = parser.add_mutually_exclusive_group()
        until.add_argument(
            '--playback-until-sec', type=float, default=-1.,
            help='Playback until timestamp, expressed in seconds since epoch. '
                 'A negative value disables this feature.')
        until.add_argument(
            '--playback-until-nsec', type=int, default=-1,
            help='Playback until timestamp, expressed in nanoseconds since epoch. '
                 'A negative value disables this feature.')
        parser.add_argument(
            '--disable-keyboard-controls', action='store_true',
            help='disables keyboard controls for playback (there are none here)')
        parser.add_argument(
            '-p', '--start-paused', action='store_true', default=False,
            help='Start the playback player in a paused state.' + NOT_HERE)
        parser.add_argument(
            '--start-offset', type=check_not_negative_float, default=0.0,
            help='Start the playback player this many seconds into the bag file.')
        parser.add_argument(
            '--wait-for-all-acked', type=check_not_negative_int, default=-1,
            metavar='TIMEOUT',
            help='Wait until all published messages are acknowledged by all subscribers or '
                 'until the timeout elapses in millisecond before play is terminated. '
                 '0 means wait forever. Only for RELIABLE publishers.')
        parser.add_argument(
            '--disable-loan-message', action='store_true', default=False,
            help='Accepted for compatibility (messages are never loaned here).')
        parser.add_argument(
            '--publish-service-requests', action='store_true', default=False,
            help='Publish recorded service requests instead of recorded service '
                 'events.' + NOT_HERE)
        parser.add_argument(
            '--service-requests-source', default='service_introspection',
            choices=['service_introspection', 'client_introspection'],
            help='Only with --publish-service-requests.')
        parser.add_argument(
            '--log-level', type=str, default='info',
            choices=['debug', 'info', 'warn', 'error', 'fatal'],
            help='Logging level.')

    def main(self, *, args):  # noqa: D102
        error = check_storage(args.storage) or refused(args)
        if error:
            return error
        try:
            options = play_options(args)
            bag = open_bag(args.bag_path)
            check_playable(bag)
            from ros2bag_mcap.player import play
            error = play(bag, options)
        except ValueError as error:
            return print_error(str(error))
        except BagError as error:
            return print_error(str(error))
        except KeyboardInterrupt:  # Ctrl-C before the playback started
            return 0
        return print_error(error) if error else 0


def refused(args) -> str:
    """Return an error text for a play option this ros2 bag does not support, else ''."""
    for dest, option in (('storage_config_file', '--storage-config-file'),
                         ('start_paused', '--start-paused'),
                         ('publish_service_requests', '--publish-service-requests')):
        if getattr(args, dest):
            return print_error(f'{option} is not supported by this ros2 bag (ros2bag_mcap)')
    return ''


def play_options(args):
    """Return the PlayOptions of the parsed arguments; ValueError for bad ones."""
    from ros2bag_mcap.player import PlayOptions
    overrides = {}
    if args.qos_profile_overrides_path:
        try:
            with open(args.qos_profile_overrides_path, encoding='utf-8') as file:
                overrides = parse_overrides(yaml.safe_load(file))
        except OSError as error:
            raise ValueError(f"cannot read '{args.qos_profile_overrides_path}': "
                             f'{error.strerror or error}') from None
        except yaml.YAMLError as error:
            raise ValueError(f"'{args.qos_profile_overrides_path}' is not valid YAML "
                             f'({" ".join(str(error).split())})') from None
    for rule in args.remap:
        if ':=' not in rule:
            raise ValueError(f'--remap: {rule!r} is not of the form old_topic:=new_topic')
    until_ns = -1
    if args.playback_until_sec is not None and args.playback_until_sec >= 0:
        until_ns = int(args.playback_until_sec * 1e9)
    elif args.playback_until_nsec is not None and args.playback_until_nsec >= 0:
        until_ns = args.playback_until_nsec
    return PlayOptions(
        rate=args.rate, loop=args.loop, start_offset_s=args.start_offset,
        delay_s=args.delay, clock_hz=args.clock or 0.0,
        clock_topics=[absolute(t) for t in args.clock_topics],
        clock_topics_all=args.clock_topics_all,
        playback_duration_s=args.playback_duration, playback_until_ns=until_ns,
        wait_acked_ms=args.wait_for_all_acked, remap=list(args.remap),
        qos_overrides=overrides,
        topic_filter=TopicFilter(
            topics=[absolute(t) for t in args.topics],
            services=service_event_topics(args.services),
            regex=args.regex, exclude_regex=args.exclude_regex,
            exclude_topics=[absolute(t) for t in args.exclude_topics],
            exclude_services=service_event_topics(args.exclude_services)),
        log_level=args.log_level)
