"""
Benchmark: what a node process costs to end on Ctrl-C, with and without the teardown.

Each node process of this workspace ends through mecanum_control.node_main.run_node:
the node closes, rclpy shuts down, then the process leaves without the interpreter's
teardown (node_main.leave_process), unless $MECANUM_NODE_TEARDOWN=full. This starts
each node executable below in a ROS domain of its own, lets it run, sends SIGINT and
measures the wall time to its exit and the CPU time it used from the signal on
(its rusage at exit minus /proc's count at the signal), both ways, trials interleaved.
Every scenario, sweep variant and integration test stops a dozen such processes.

Run: ./mecanum exec python bench/node_exit.py [--trials 5]
"""

import argparse
import os
from pathlib import Path
import signal
import statistics
import subprocess
import sys
import time

REPO = Path(__file__).resolve().parents[1]
#: (package, executable, extra ROS arguments) of the node processes measured.
NODES = [
    ('robot_simulation', 'simulator_node', ['-p', 'world:=apartment']),
    ('mecanum_localization', 'ekf_node', []),
    ('mecanum_control', 'motor_controller', []),
    ('mecanum_safety', 'collision_monitor', [
        '--params-file',
        str(REPO / 'install/mecanum_safety/share/mecanum_safety/config/collision_monitor.yaml')]),
    ('mecanum_safety', 'twist_mux', [
        '--params-file',
        str(REPO / 'install/mecanum_safety/share/mecanum_safety/config/twist_mux.yaml')]),
]
RUN_BEFORE_SIGINT_S = 3.0
WAYS = ('full teardown', 'leave_process')


def cpu_seconds(pid: int) -> float:
    """Return the user + system CPU seconds of a running process so far."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def one_exit(executable: Path, extra, env) -> tuple:
    """Start, run, SIGINT; return (wall s to exit, CPU s from the signal, exit code)."""
    process = subprocess.Popen([str(executable), '--ros-args', *extra], env=env,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(RUN_BEFORE_SIGINT_S)
    if process.poll() is not None:
        raise RuntimeError(f'{executable.name} ended by itself (code {process.returncode})')
    before = cpu_seconds(process.pid)
    started = time.monotonic()
    process.send_signal(signal.SIGINT)
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.monotonic() - started
    return wall, usage.ru_utime + usage.ru_stime - before, os.waitstatus_to_exitcode(status)


def main() -> int:
    """Measure every node both ways; print a table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--trials', type=int, default=5)
    parser.add_argument('--domain', type=int, default=97, help='ROS_DOMAIN_ID to use')
    options = parser.parse_args()
    rows = []
    for package, name, extra in NODES:
        executable = REPO / 'install' / package / 'lib' / package / name
        results = {way: [] for way in WAYS}
        for _ in range(options.trials):
            for way in WAYS:
                env = dict(os.environ, ROS_DOMAIN_ID=str(options.domain),
                           ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
                env.pop('MECANUM_NODE_TEARDOWN', None)
                if way == 'full teardown':
                    env['MECANUM_NODE_TEARDOWN'] = 'full'
                wall, cpu, code = one_exit(executable, extra, env)
                if code != 0:
                    print(f'{name} ({way}) exited with {code}', file=sys.stderr)
                results[way].append((wall, cpu))
        rows.append((name, results))
    print(f'{options.trials} trials each, interleaved; medians (max)')
    print('| node | way | exit wall s | CPU s from SIGINT |')
    print('|---|---|---|---|')
    totals = dict.fromkeys(WAYS, 0.0)
    for name, results in rows:
        for way in WAYS:
            walls = [w for w, _ in results[way]]
            cpus = [c for _, c in results[way]]
            totals[way] += statistics.median(cpus)
            print(f'| {name} | {way} | {statistics.median(walls):.2f} ({max(walls):.2f}) | '
                  f'{statistics.median(cpus):.2f} ({max(cpus):.2f}) |')
    full, leave = totals[WAYS[0]], totals[WAYS[1]]
    print(f'\nCPU s to end these {len(rows)} processes (sum of medians): {full:.2f} with the '
          f'teardown, {leave:.2f} leaving ({full / max(leave, 1e-9):.1f}x)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
