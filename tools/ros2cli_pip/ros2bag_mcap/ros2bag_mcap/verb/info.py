"""``ros2 bag info``: print a bag's metadata, laid out as rosbag2 does."""

import os
import sys

from ros2bag_mcap.api import print_error, STORAGE_ID
from ros2bag_mcap.bag import BagError, open_bag
from ros2bag_mcap.info import format_info, topic_names
from ros2bag_mcap.verb import VerbExtension


def add_reader_arguments(parser) -> None:
    """Add the bag path and -s/--storage (rosbag2's add_standard_reader_args)."""
    parser.add_argument('bag_path', help='Bag to open (a bag folder or an .mcap file)')
    parser.add_argument(
        '-s', '--storage', default='',
        help=f"Storage implementation of bag: '{STORAGE_ID}' (the only one here). "
             'By default attempts to detect automatically - use this argument to override.')


def check_storage(storage: str) -> str:
    """Return an error text unless storage is '' (detect) or 'mcap'."""
    if storage not in ('', STORAGE_ID):
        return print_error(f"storage '{storage}' is not supported: this ros2 bag "
                           f"(ros2bag_mcap) reads '{STORAGE_ID}' bags only")
    return ''


class InfoVerb(VerbExtension):
    """Print information about a bag to the screen."""

    def add_arguments(self, parser, cli_name):  # noqa: D102
        add_reader_arguments(parser)
        parser.add_argument(
            '-t', '--topic-name', action='store_true',
            help='Only display topic names.')
        parser.add_argument(
            '-v', '--verbose', action='store_true',
            help='Display request/response information for services (not supported here)')

    def main(self, *, args):  # noqa: D102
        error = check_storage(args.storage)
        if error:
            return error
        if args.verbose:
            return print_error('-v/--verbose (service request/response counts) is not '
                               'supported by this ros2 bag (ros2bag_mcap)')
        try:
            bag = open_bag(args.bag_path)
        except BagError as error:
            return print_error(str(error))
        text = '\n'.join(topic_names(bag.metadata)) if args.topic_name \
            else format_info(bag.metadata)
        try:
            if text:
                print(text)
            sys.stdout.flush()
        except BrokenPipeError:  # `ros2 bag info BAG | head`: the rest is not wanted
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
