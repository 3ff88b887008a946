"""The ``ros2 bag`` command: its verbs are the ``ros2bag_mcap.verb`` entry points."""

from ros2cli.command import add_subparsers_on_demand
from ros2cli.command import CommandExtension


class BagCommand(CommandExtension):
    """Various rosbag related sub-commands."""

    def add_arguments(self, parser, cli_name):
        """Add the verbs (info, play, record) as sub-commands."""
        self._subparser = parser
        add_subparsers_on_demand(
            parser, cli_name, '_verb', 'ros2bag_mcap.verb', required=False)

    def main(self, *, parser, args):
        """Run the chosen verb, or print the help without one."""
        if not hasattr(args, '_verb'):
            self._subparser.print_help()
            return 0
        extension = getattr(args, '_verb')
        return extension.main(args=args)
