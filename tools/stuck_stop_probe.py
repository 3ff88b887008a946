#!/usr/bin/env python3
"""
Catch a node process that does not end after Ctrl-C, with every thread's native stack.

Starts a launch file under the real ROS 2 launch (tests/real_launch/run_launch_file.py,
as tests/test_real_launch.py does) in a ROS domain of its own, waits until the system is
up, sends Ctrl-C to the whole process group and, WAIT_S later, attaches gdb to each of
its processes still alive and saves `thread apply all bt` to OUT/gdb_PID.txt. Repeats
TRIALS times and prints one line per trial. Alive is not stuck (gdb itself holds the
process a moment; launch's exit code says whether all ended in time): look for a main
thread in rcl_node_fini. Rare stuck stops (1 in 15-30 under load on
2026-11-29) show up beside a load: run a scenario batch at the same time, e.g.
`run_scenarios ... --jobs 2 --cold`.

    ./mecanum exec python tools/stuck_stop_probe.py [--launch FILE] [--trials N]
        [--ready PATTERN] [--wait-s S] [--out DIR]
"""

import argparse
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

REPO = Path(__file__).resolve().parents[1]
DRIVER = REPO / 'tests' / 'real_launch' / 'run_launch_file.py'


def trial(launch: Path, ready: str, wait_s: float, out: Path, env: dict) -> str:
    """Run one start and Ctrl-C; return a line saying what was left and where it is saved."""
    launch_process = subprocess.Popen(
        [sys.executable, str(DRIVER), str(launch)], env=env, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True, start_new_session=True)
    for line in launch_process.stdout:
        if ready in line:
            break
    time.sleep(2.0)     # up and running a moment, as the test's STAY_UP_S
    group = subprocess.run(['pgrep', '-g', str(launch_process.pid)], capture_output=True,
                           text=True).stdout.split()
    os.killpg(launch_process.pid, signal.SIGINT)
    time.sleep(wait_s)
    left = []
    for pid in group:
        if int(pid) == launch_process.pid or not Path(f'/proc/{pid}').exists():
            continue
        try:
            command = Path(f'/proc/{pid}/cmdline').read_bytes().replace(b'\0', b' ')[:100]
        except OSError:
            continue    # ended meanwhile
        if not command.split():
            continue    # ended meanwhile (a zombie has no command line)
        stacks = subprocess.run(['gdb', '-p', pid, '-batch', '-ex', 'thread apply all bt 30'],
                                capture_output=True, text=True).stdout
        (out / f'gdb_{pid}.txt').write_text(command.decode(errors='replace') + '\n' + stacks)
        left.append(f'{pid} ({command.decode(errors="replace").split()[1]})')
    launch_process.communicate(timeout=60)
    return (f'rc {launch_process.returncode}, alive {wait_s:g} s after Ctrl-C: '
            f'{", ".join(left) or "none"}')


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--launch', type=Path,
                        default=REPO / 'src/mecanum_bringup/launch/robot.launch.py')
    parser.add_argument('--trials', type=int, default=20)
    parser.add_argument('--ready', default='ready for goals',
                        help='an output line that says the system is up')
    parser.add_argument('--wait-s', type=float, default=2.5,
                        help='seconds after Ctrl-C a process must have ended by')
    parser.add_argument('--out', type=Path, default=Path('/tmp/stuck_stop_probe'))
    parser.add_argument('--domain-id', type=int, default=77)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, ROS_DOMAIN_ID=str(args.domain_id),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    for number in range(args.trials):
        print(f'trial {number}: {trial(args.launch, args.ready, args.wait_s, args.out, env)}',
              flush=True)
    print(f'stacks of processes left: {args.out}/gdb_PID.txt')
    return 0


if __name__ == '__main__':
    sys.exit(main())
