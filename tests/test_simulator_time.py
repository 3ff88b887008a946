"""Integration: simulator_node paces /clock to real_time_factor, or runs flat out."""

import os
from pathlib import Path
import signal
import subprocess
import time

import pytest
from rosgraph_msgs.msg import Clock

#: alone: measures simulated seconds per wall second.
pytestmark = [pytest.mark.integration, pytest.mark.alone]
REPO = Path(__file__).resolve().parents[1]


def simulated_seconds_in(test_node, env, real_time_factor: str, wall_s: float) -> float:
    """Run simulator_node alone for wall_s; return how far /clock advanced meanwhile."""
    clock = test_node.record(Clock, '/clock')
    process = subprocess.Popen(
        ['./mecanum', 'run', 'robot_simulation', 'simulator_node', '--ros-args', '-p',
         f'real_time_factor:={real_time_factor}', '-p', 'world:=lab'],
        cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT,
        start_new_session=True)
    try:
        first = clock.wait_for(lambda m: True, timeout=20.0)
        start = time.monotonic()
        time.sleep(wall_s)
        last = clock.latest()
        elapsed_wall = time.monotonic() - start
    finally:
        os.killpg(process.pid, signal.SIGINT)
        assert process.wait(timeout=15) == 0

    def seconds(msg):
        return msg.clock.sec + msg.clock.nanosec * 1e-9
    return (seconds(last) - seconds(first)) / elapsed_wall


def test_real_time_factor_two_runs_twice_as_fast_as_the_wall_clock(ros_env, test_node):
    """real_time_factor 2: about 2 simulated seconds per wall second."""
    rate = simulated_seconds_in(test_node, ros_env, '2.0', 3.0)
    assert rate == pytest.approx(2.0, rel=0.15)


def test_real_time_factor_zero_runs_as_fast_as_possible(ros_env, test_node):
    """real_time_factor 0: far faster than real time (the core alone does > 100x)."""
    rate = simulated_seconds_in(test_node, ros_env, '0', 3.0)
    print(f'simulator_node flat out: {rate:.1f} simulated s per wall s')
    assert rate > 10.0
