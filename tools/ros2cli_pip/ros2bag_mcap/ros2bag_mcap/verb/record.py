"""
``ros2 bag record``: record topics into an MCAP bag with this project's recorder.

The recording is ``mecanum_bringup.bag_recorder`` (the workspace's rosbag2-compatible
recorder), run in this process with the ROS arguments that
:func:`ros2bag_mcap.record_options.recorder_arguments` makes of rosbag2's options.
Ctrl-C (SIGINT) or SIGTERM finish the bag (summary, index, metadata.yaml); exit code 0.
"""

import datetime
import os

from ros2bag_mcap.api import print_error, print_warn
from ros2bag_mcap.record_options import (add_record_arguments, default_output,
                                         recorder_arguments)
from ros2bag_mcap.verb import VerbExtension


class RecordVerb(VerbExtension):
    """Record ROS data to a bag."""

    def add_arguments(self, parser, cli_name):  # noqa: D102
        add_record_arguments(parser)

    def main(self, *, args):  # noqa: D102
        output = args.output or default_output(datetime.datetime.now())
        try:
            ros_args = recorder_arguments(args, output)
        except ValueError as error:
            return print_error(str(error))
        if (args.all or args.all_topics) and args.topics:
            print(print_warn('--all or --all-topics will override --topics'))
        if os.path.exists(output):
            return print_error(f"Output folder '{output}' already exists.")
        try:
            from mecanum_bringup.bag_recorder import main as recorder_main
        except ImportError as error:
            return print_error(
                'ros2 bag record needs the recorder of this workspace, '
                f'mecanum_bringup.bag_recorder ({error}): source install/setup.bash')
        code = recorder_main(['ros2', *ros_args])
        return code or 0
