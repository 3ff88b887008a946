"""
Integration: the real `ros2` command in the pip setup, against the running robot.

make setup builds the upstream Jazzy ros2cli and launch (tools/ros2_upstream.py) into
.venv/ros2cli, and tools/env.sh puts `ros2` on the PATH. With the minimal system (the
seed's two nodes) running in a leased ROS domain, the commands the docs give work as on
an apt install: `ros2 node list`, `ros2 topic list -t`, `ros2 topic pub --once`, `ros2
topic echo --once`, `ros2 topic hz`, `ros2 param get`; and `ros2 launch` is the real
one. The ros2 daemon is not used (`--no-daemon`): it would outlive the test. Without it
each command discovers the graph anew, which takes a moment: a command that found
nothing yet is run again, as a user would.
"""

import os
from pathlib import Path
import re
import signal
import subprocess
import time

import pytest
from tests.conftest import ROS2, RUN_MARKER

pytestmark = [pytest.mark.integration, pytest.mark.usefixtures('needs_ros2')]

REPO = Path(__file__).resolve().parents[1]


def ros2(env, *args, timeout=60.0) -> str:
    """Run `ros2 ARGS` in env; return its output (it must succeed)."""
    result = subprocess.run([ROS2, *args], env=env, capture_output=True, text=True,
                            timeout=timeout)
    assert result.returncode == 0, f'ros2 {" ".join(args)}:\n{result.stdout}{result.stderr}'
    return result.stdout


def wait_for_output(env, args, pattern, timeout=60.0) -> re.Match:
    """Run `ros2 ARGS` until it succeeds with output matching pattern (discovery)."""
    deadline = time.monotonic() + timeout
    while True:
        result = subprocess.run([ROS2, *args], env=env, capture_output=True, text=True,
                                timeout=timeout)
        match = re.search(pattern, result.stdout, re.M) if result.returncode == 0 else None
        if match:
            return match
        assert time.monotonic() < deadline, (
            f'ros2 {" ".join(args)}: no {pattern!r} in\n{result.stdout}{result.stderr}')
        time.sleep(0.2)


def test_ros2_topic_node_and_param_against_the_minimal_system(start_system, ros_env):
    system = start_system('mecanum_bringup', 'minimal.launch.yaml')
    system.wait_for_line(r'\[robot_controller\].*ready')
    wait_for_output(ros_env, ('node', 'list', '--no-daemon'),
                    r'^/robot_controller$(.|\n)*^/robot_simulation$')
    wait_for_output(ros_env, ('topic', 'list', '-t', '--no-daemon'),
                    r'^/robot_status \[std_msgs/msg/String\]$')
    wait_for_output(ros_env, ('param', 'get', '--no-daemon', '/robot_controller',
                              'linear_speed_mps'), r'^Double value is: 0\.2$')
    # `ros2 topic pub` waits for the subscriber (-w 1) before it publishes once.
    ros2(ros_env, 'topic', 'pub', '--once', '-w', '1', '/control_command',
         'std_msgs/msg/String', "{data: 'forward 0.5 m'}")
    deadline = time.monotonic() + 30.0
    while True:
        echoed = ros2(ros_env, 'topic', 'echo', '--once', '/robot_status',
                      'std_msgs/msg/String')
        x = float(re.search(r'Position: x=(-?\d+\.\d+)', echoed).group(1))
        if x > 0.45:
            break
        assert time.monotonic() < deadline, echoed
    # `ros2 topic hz` runs until Ctrl-C; its first rate line is enough.
    process = subprocess.Popen([ROS2, 'topic', 'hz', '/robot_status'], env=ros_env,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                               start_new_session=True)
    try:
        line = ''
        while 'average rate:' not in line:
            line = process.stdout.readline()
            assert line, 'ros2 topic hz ended without a rate'
    finally:
        os.killpg(process.pid, signal.SIGINT)
        process.wait(timeout=15)
    assert system.stop() == 0


def test_ros2_launch_is_the_real_launch_and_stops_clean_on_ctrl_c(ros_env, marked_env):
    env = dict(ros_env, **{RUN_MARKER: marked_env.marker})
    process = subprocess.Popen([ROS2, 'launch', 'mecanum_bringup', 'minimal.launch.py'],
                               env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               text=True, start_new_session=True)
    lines = []
    try:
        deadline = time.monotonic() + 60.0
        while not any('Robot controller ready' in line for line in lines):
            line = process.stdout.readline()
            assert line and time.monotonic() < deadline, ''.join(lines)
            lines.append(line)
        # launch.launch_service is the real one (its log line names each process).
        assert any(re.search(r'\[INFO\] \[launch\]', line) for line in lines), ''.join(lines)
        wait_for_output(ros_env, ('node', 'list', '--no-daemon'), r'^/robot_simulation$')
    finally:
        os.killpg(process.pid, signal.SIGINT)
        rest, _ = process.communicate(timeout=30)
    output = ''.join(lines) + rest
    assert process.returncode == 0, output
    assert 'process has died' not in output and '[ERROR]' not in output, output
    assert marked_env.leftovers() == []
