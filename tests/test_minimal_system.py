"""Integration: the minimal system through the pip-mode runner, over real DDS.

robot_controller and robot_simulation run as separate processes started by
mecanum_bringup.launch_runner, in their own ROS domain, on simulated time that
this test publishes on /clock. The minimal system has no command chain:
robot_controller publishes cmd_vel, as in the seed tutorial, which the kinematic
simulation takes, and robot_controller, seeing no chain output (cmd_vel_safe), does not
watch it.
"""

import math
import os
import signal
import time

from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
import pytest
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

pytestmark = pytest.mark.integration


def test_commands_cross_processes_and_ctrl_c_leaves_nothing(start_system, test_node,
                                                            processes_with_marker):
    node = test_node.node
    test_node.start_clock()
    tf = test_node.record(TFMessage, '/tf')
    # The twist the simulation applies (its odometry), not a subscription of cmd_vel: with
    # one, robot_controller's hold until cmd_vel has a subscriber would count the test
    # and start the motion before the simulation had discovered it (CI at faf6f6a, loaded:
    # 0.258 m of 0.3 m).
    odom = test_node.record(Odometry, 'odom')
    status = test_node.record(String, 'control_status')
    command_pub = node.create_publisher(String, 'control_command', 10)

    system = start_system('mecanum_bringup', 'minimal.launch.yaml', 'use_sim_time:=true')
    system.wait_for_line(r'\[robot_controller\].*ready')
    system.wait_for_line(r'\[robot_simulation\].*started')
    # The simulation publishes odom -> base_link on /tf from its own process.
    first = tf.wait_for(lambda m: m.transforms)
    assert (first.transforms[0].header.frame_id, first.transforms[0].child_frame_id) == (
        'odom', 'base_link')

    deadline = time.monotonic() + 20
    while command_pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    # robot_controller publishes the seed's cmd_vel (no chain input here).
    while time.monotonic() < deadline and not any(
            info.node_name == 'robot_controller'
            for info in node.get_publishers_info_by_topic('/cmd_vel')):
        time.sleep(0.05)
    assert [info.node_name for info in node.get_publishers_info_by_topic('/cmd_vel')] == [
        'robot_controller']
    assert node.get_publishers_info_by_topic('/cmd_vel_text') == []
    command_pub.publish(String(data='strafe left 0.3 m at 0.3 m/s'))
    status.wait_for(lambda m: m.data == 'accepted: strafe left 0.3 m at 0.3 m/s')
    odom.wait_for(lambda m: abs(m.twist.twist.linear.y - 0.3) < 1e-9
                  and m.twist.twist.linear.x == 0.0)
    status.wait_for(lambda m: m.data == 'done: strafe left')
    # The simulation stops with the final zero twist: wait until its pose stands still
    # (two transforms 0.1 s of sim time apart, unchanged), not for a guessed time.
    done_at = time.monotonic()

    def settled(_msg) -> bool:
        late = [m.transforms[0] for when, m in tf.messages if when > done_at]
        return len(late) >= 2 and (
            late[-1].header.stamp.sec + late[-1].header.stamp.nanosec * 1e-9
            - late[0].header.stamp.sec - late[0].header.stamp.nanosec * 1e-9 >= 0.1) and \
            late[-1].transform.translation.y == late[-2].transform.translation.y
    tf.wait_for(settled, timeout=20)
    pose = tf.latest().transforms[0].transform
    # 0.3 m to the left within one controller period (0.05 s of 0.3 m/s) and latency.
    assert pose.translation.y == pytest.approx(0.3, abs=0.03)
    assert pose.translation.x == pytest.approx(0.0, abs=1e-6)
    assert 2 * math.atan2(pose.rotation.z, pose.rotation.w) == pytest.approx(0.0, abs=1e-6)

    pids = [system.node_pid('robot_controller'), system.node_pid('robot_simulation')]
    started = time.monotonic()
    assert system.stop(signal.SIGINT) == 0
    assert time.monotonic() - started < 6.0
    assert 'shutting down (received SIGINT)' in system.output()
    for pid in pids:
        assert not os.path.exists(f'/proc/{pid}') or \
            open(f'/proc/{pid}/stat').read().rsplit(')', 1)[1].split()[0] == 'Z'
    assert processes_with_marker(system.marker) == []


def test_a_command_sent_before_the_clock_starts_waits_for_it(start_system, test_node):
    """
    Hold a command sent before the clock starts, then run it for its full duration.

    On sim time a node's clock reads 0 until its first /clock (DDS discovery can take
    seconds on a loaded machine). A timed command accepted then must neither move the
    robot nor be cut short: it starts at the clock's first tick and lasts its duration.
    """
    cmd_vel = test_node.record(Twist, 'cmd_vel')
    status = test_node.record(String, 'control_status')
    command_pub = test_node.node.create_publisher(String, 'control_command', 10)
    system = start_system('mecanum_bringup', 'minimal.launch.yaml', 'use_sim_time:=true')
    system.wait_for_line(r'\[robot_controller\].*ready')
    deadline = time.monotonic() + 20
    while command_pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    command_pub.publish(String(data='forward 0.4 m at 0.2 m/s'))
    status.wait_for(lambda m: m.data == 'accepted: forward 0.4 m at 0.2 m/s')
    system.wait_for_line(r'\[robot_controller\].*Holding .* until the clock starts')
    time.sleep(0.5)
    assert not [m for _, m in cmd_vel.messages if m.linear.x != 0.0]

    # The clock starts at 10 s, as from a simulator that has been running a while.
    test_node.clock_ns = 10 * 10 ** 9
    test_node.start_clock()
    status.wait_for(lambda m: m.data == 'done: forward', timeout=30.0)
    # The motion lasted its 2 s of simulated time after the clock started (without the
    # wait it was over at the first tick: its end had been set to 0 + 2 s).
    assert test_node.clock_ns * 1e-9 - 10.0 >= 1.95
    # At 20 Hz: 40 twists.
    assert len([m for _, m in cmd_vel.messages if m.linear.x > 0.0]) >= 30


def test_respawned_node_rejoins_the_graph(start_system, test_node, processes_with_marker):
    test_node.start_clock()
    robot_status = test_node.record(String, 'robot_status')
    system = start_system('mecanum_bringup', 'minimal.launch.yaml', 'use_sim_time:=true')
    robot_status.wait_for(lambda m: m.data.startswith('Position:'))
    os.kill(system.node_pid('robot_simulation'), signal.SIGKILL)
    system.node_pid('robot_simulation', start=2)
    count_before = len(robot_status.messages)
    robot_status.wait_for(lambda m: len(robot_status.messages) > count_before + 5)
    assert system.stop(signal.SIGTERM) == 0
    assert processes_with_marker(system.marker) == []


def test_bad_launch_argument_is_refused_before_anything_starts(start_system,
                                                               processes_with_marker):
    system = start_system('mecanum_bringup', 'minimal.launch.yaml', 'no_such_arg:=1')
    assert system.process.wait(timeout=20) == 2
    assert 'unknown launch argument(s) no_such_arg' in system.output()
    assert processes_with_marker(system.marker) == []
