"""
demo: the main job. The simulated robot tours the apartment and reports what it did.

Usage: ``make demo`` (pip setup: ``./mecanum run mecanum_bringup demo``; apt ROS:
``ros2 run mecanum_bringup demo``), options ``--out DIR``, ``--real-time-factor X``,
``--lockstep`` (simulated time waits for the stack; then ``--real-time-factor max``
runs as fast as it answers; by default the demo runs on the wall clock, which checks
that the stack keeps up in real time), ``--foxglove`` (watch it live in Foxglove on
ws://localhost:8765), ``--no-record``.

It brings up the whole robot (mecanum_bringup robot.launch: the simulator with the
apartment and its walking person, the control stack on the simulated ESP32, the EKF,
map_server + amcl, navigation) isolated in its own ROS domain, sends the 12 goals of
``scenarios/apartment_tour.yaml`` and prints progress as it goes. It ends with a report
folder (default ``reports/demo_YYYYmmdd_HHMMSS``):

* ``run.png``: the map, the planned paths, the driven path (ground truth), amcl's
  estimate, the goals and any collision;
* ``summary.json``: goals reached, time, distance, collisions, localisation error, and
  every step and criterion;
* ``bag/``: every topic as an MCAP rosbag2 (``ros2 bag info reports/.../bag``, or open
  the .mcap in Foxglove);
* ``system.log``: every node's output.

Ctrl-C (or SIGTERM) stops the robot and the system cleanly and still writes the report and the
recording of what happened so far. Exit code 0 when the tour passed.
"""

import argparse
from datetime import datetime
import json
from pathlib import Path
import sys
from typing import Optional, Sequence

from mecanum_bringup.scenario_loader import load_scenario, ScenarioError
from mecanum_bringup.scenario_runner import (
    interrupt, INTERRUPTED, parse_real_time_factor, run_scenario, RunOptions, SIGNAL_NAMES,
    stopping_cleanly_on_signals)

TOUR_FILE = 'apartment_tour.yaml'


def tour_file() -> Path:
    """Return the installed apartment tour scenario."""
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory('mecanum_bringup')) / 'scenarios' / TOUR_FILE


def recording_summary(bag_dir: Path) -> str:
    """Return 'N messages on M topics in FILE' for a bag folder, read with the mcap library."""
    from mcap.reader import make_reader
    files = sorted(bag_dir.glob('*.mcap'))
    if not files:
        return 'no recording'
    messages = topics = 0
    for file in files:
        with open(file, 'rb') as stream:
            statistics = make_reader(stream).get_summary().statistics
            messages += statistics.message_count
            topics += statistics.channel_count
    return f'{messages} messages on {topics} topics in {files[0]}'


def program_arguments(argv: Sequence[str]) -> list:
    """
    Return argv without ROS arguments and empty words.

    ros2 launch runs the demo as a node (demo.launch.yaml): it appends ``--ros-args``
    and passes an empty ``demo_args`` as an empty word.
    """
    from rclpy.utilities import remove_ros_args
    return [word for word in remove_ros_args(['demo', *argv])[1:] if word]


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the tour and print where its report is; returns the exit code."""
    parser = argparse.ArgumentParser(prog='demo', description='The simulated mecanum robot '
                                     'tours the apartment and writes a report.')
    parser.add_argument('--out', help='report folder (default reports/demo_<date>_<time>)')
    parser.add_argument('--real-time-factor', type=parse_real_time_factor, default=None,
                        help='simulated seconds per wall second (default: the scenario, 1); '
                        "'max' with --lockstep")
    parser.add_argument('--lockstep', action='store_true',
                        help='simulated time waits for the stack (as run_scenarios does)')
    parser.add_argument('--foxglove', action='store_true',
                        help='serve the running system to Foxglove on ws://localhost:8765')
    parser.add_argument('--no-record', action='store_true', help='do not record a bag')
    parser.add_argument('--scenario', default=None, help='another scenario file to run')
    parser.add_argument('--no-compose', action='store_true',
                        help='run every node in its own process (default: composed)')
    options = parser.parse_args(program_arguments(sys.argv[1:] if argv is None else argv))
    if options.real_time_factor == 0.0 and not options.lockstep:
        parser.error('--real-time-factor max needs --lockstep')
    try:
        scenario = load_scenario(options.scenario or tour_file())
    except ScenarioError as error:
        print(f'demo: {error}', file=sys.stderr)
        return 2
    out = Path(options.out or Path('reports') / datetime.now().strftime('demo_%Y%m%d_%H%M%S'))
    print(f'demo: {scenario.description}', flush=True)
    print(f'demo: bringing up the simulated robot (simulator, control, EKF, amcl, '
          f'navigation); report in {out / scenario.name}; Ctrl-C stops cleanly', flush=True)
    if options.foxglove:
        print('demo: live view: open Foxglove, connect to ws://localhost:8765', flush=True)

    def on_signal(signum, frame) -> None:
        if not INTERRUPTED.is_set():
            print(f'\ndemo: {SIGNAL_NAMES.get(signum, signum)}: stopping the robot and writing '
                  'the report ...', flush=True)
        interrupt(signum, frame)
    with stopping_cleanly_on_signals(on_signal):
        result = run_scenario(scenario, RunOptions(
            out, options.real_time_factor, record=not options.no_record,
            foxglove=options.foxglove, progress=lambda text: print(text, flush=True),
            compose=not options.no_compose, lockstep=options.lockstep))
    run_dir = out / scenario.name
    summary = json.loads((run_dir / 'summary.json').read_text())
    print()
    numbers = {key: _number(summary[key]) for key in (
        'distance_m', 'duration_s', 'localization_error_max_m', 'localization_error_rms_m')}
    print(f'demo: {summary["verdict"].upper()}: {summary["goals_reached"]} of '
          f'{summary["goals_total"]} goals reached, {summary["collisions"]} collisions, '
          f'{numbers["distance_m"]} m in {numbers["duration_s"]} s simulated '
          f'({result.wall_time_s:.0f} s wall), localisation error max '
          f'{numbers["localization_error_max_m"]} m, RMS {numbers["localization_error_rms_m"]} m')
    if summary['aborted']:
        print(f"demo: stopped early: {summary['aborted']}")
    failure = result.first_failure
    if failure and result.verdict and result.verdict.verdict != 'pass':
        print(f'demo: first failure: {failure}')
    print(f'demo: report: {run_dir}/run.png, summary.json, system.log')
    if not options.no_record:
        print(f'demo: recording: {recording_summary(run_dir / "bag")}')
    # Stopped by the operator (Ctrl-C, launch's SIGINT): a clean end, not a failure of
    # the robot (under ros2 launch, exit code 1 is 'process has died', an ERROR).
    if INTERRUPTED.is_set():
        return 0
    return 0 if result.status == 'OK' else 1


def _number(value) -> str:
    return '?' if value is None else f'{value:.2f}'


if __name__ == '__main__':
    sys.exit(main())
