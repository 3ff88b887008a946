"""
Integration: `ros2 param set` changes what the running robot does, or says why it cannot.

The minimal system (robot_controller and robot_simulation, real processes started by
mecanum_bringup.launch_runner in a leased ROS domain) runs; the real `ros2` command
(make setup's upstream ros2cli, without the daemon) sets robot_controller's
linear_speed_mps to 0.3, and the next plain 'forward' drives at 0.3 m/s instead of the
0.2 m/s of config/robot_controller.yaml; a set of footprint_radius_m, read-only (the
robot's geometry from motor_params.yaml), prints the reason, and `ros2 param describe`
shows it read-only. Each node's run-time parameters in detail:
tests/test_runtime_parameter_nodes.py.
"""

import re
import subprocess
import time

from geometry_msgs.msg import Twist
import pytest
from std_msgs.msg import String
from tests.conftest import ROS2

pytestmark = [pytest.mark.integration, pytest.mark.usefixtures('needs_ros2')]


def ros2_param(env, *args, timeout: float = 60.0) -> subprocess.CompletedProcess:
    """
    Run `ros2 param ARGS --no-daemon` until it finds the node; return its result.

    Without the daemon each command discovers the graph anew, so one that did not find
    the node yet ('Node not found') is run again, as a user would.
    """
    deadline = time.monotonic() + timeout
    while True:
        result = subprocess.run([ROS2, 'param', *args, '--no-daemon'], env=env,
                                capture_output=True, text=True, timeout=timeout)
        if 'Node not found' not in result.stdout + result.stderr:
            return result
        assert time.monotonic() < deadline, f'ros2 param {" ".join(args)}: {result}'


def test_ros2_param_set_changes_the_next_command_s_speed(start_system, test_node, ros_env):
    node = test_node.node
    cmd_vel = test_node.record(Twist, 'cmd_vel')
    status = test_node.record(String, 'control_status')
    command_pub = node.create_publisher(String, 'control_command', 10)
    system = start_system('mecanum_bringup', 'minimal.launch.yaml')
    system.wait_for_line(r'\[robot_controller\].*ready')

    result = ros2_param(ros_env, 'set', '/robot_controller', 'linear_speed_mps', '0.3')
    assert result.stdout.strip() == 'Set parameter successful', result
    system.wait_for_line(r'\[robot_controller\]: linear_speed_mps 0\.2 -> 0\.3$')
    got = ros2_param(ros_env, 'get', '/robot_controller', 'linear_speed_mps')
    assert got.stdout.strip() == 'Double value is: 0.3', got

    deadline = time.monotonic() + 20.0
    while command_pub.get_subscription_count() == 0:
        assert time.monotonic() < deadline, 'robot_controller does not take control_command'
        time.sleep(0.05)
    started = time.monotonic()
    command_pub.publish(String(data='forward'))
    status.wait_for(lambda m: m.data == 'accepted: forward')
    cmd_vel.wait_for(lambda m: m.linear.x != 0.0)
    status.wait_for(lambda m: m.data == 'done: forward')
    moving = [m.linear.x for m in cmd_vel.since(started) if m.linear.x != 0.0]
    assert moving and all(x == pytest.approx(0.3) for x in moving), moving

    # A read-only parameter: refused, with the reason; unchanged; describe says so.
    refused = ros2_param(ros_env, 'set', '/robot_controller', 'footprint_radius_m', '0.1')
    assert refused.stderr.strip() == (
        "Setting parameter failed: footprint_radius_m is read-only: the robot's geometry "
        'from motor_params.yaml, shared by the controller, the simulator and the '
        'firmware; edit the file and restart'), refused
    got = ros2_param(ros_env, 'get', '/robot_controller', 'footprint_radius_m')
    assert got.stdout.strip() == 'Double value is: 0.2', got
    described = ros2_param(ros_env, 'describe', '/robot_controller', 'footprint_radius_m')
    assert re.search(r"Description: read-only: the robot's geometry from motor_params",
                     described.stdout), described
    assert 'Read only: true' in described.stdout, described
    # An invalid value: refused with the reason.
    invalid = ros2_param(ros_env, 'set', '/robot_controller', 'linear_speed_mps', '-1.0')
    assert invalid.stderr.strip() == (
        'Setting parameter failed: linear_speed_mps must be > 0, got -1.0'), invalid
    assert system.stop() == 0
