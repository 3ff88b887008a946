"""
Run one launch file under the real ROS 2 launch (launch, launch_ros) until SIGINT.

Test helper of tests/test_real_launch.py, run in a prefix where the vendor's Jazzy
launch packages are built. Prints one line per process event, for the test to read:
``START <name> <pid>`` and ``EXIT <name> <return code>``; the real launch's own
output (and a load error's traceback) comes on stderr. Exit code: LaunchService's.

Usage: python run_launch_file.py FILE [name:=value ...]
"""

import sys

from launch import LaunchDescription, LaunchService
from launch.actions import IncludeLaunchDescription, RegisterEventHandler
from launch.event_handlers import OnProcessExit, OnProcessStart
from launch.launch_description_sources import AnyLaunchDescriptionSource


def say(text: str) -> None:
    """Print an event line at once."""
    print(text, flush=True)


def main(argv) -> int:
    """Launch argv[0] with the name:=value arguments after it."""
    path, arguments = argv[0], [a.split(':=', 1) for a in argv[1:]]
    description = LaunchDescription([
        RegisterEventHandler(OnProcessStart(on_start=lambda event, _context: say(
            f'START {event.action.name} {event.pid}'))),
        RegisterEventHandler(OnProcessExit(on_exit=lambda event, _context: say(
            f'EXIT {event.action.name} {event.returncode}'))),
        IncludeLaunchDescription(AnyLaunchDescriptionSource(path),
                                 launch_arguments=[tuple(a) for a in arguments]),
    ])
    service = LaunchService(argv=argv[1:])
    service.include_launch_description(description)
    return service.run()


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
