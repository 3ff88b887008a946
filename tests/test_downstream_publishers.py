"""
Integration: a stray publisher downstream of the command chain stops the wheels, by name.

emulated_control.launch.yaml runs the control stack (hardware_interface, encoder_reader,
velocity_controller, motor_controller; real processes, real DDS, its own ROS domain)
against the board emulator on a real pty, on the wall clock. The test node plays the
command chain (the expected publisher of cmd_vel_safe, launch argument
cmd_vel_safe_publishers) and drives forward. Then, one topic at a time, a rogue process
(its own rclpy node) publishes a command of its own on cmd_vel_safe, motor_speeds,
motor_efforts or joint_states, which nothing in the stack expects: the node consuming
that topic must stop the wheels within a few seconds, log an ERROR naming the rogue and
report it on /diagnostics; once the rogue has gone (Ctrl-C), driving resumes.
Odometry is watched, not joint_states, which one rogue fakes.
"""

import math
import os
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
import pytest
from tests.conftest import OutputProcess

#: alone: the emulated board runs on the wall clock, like tests/test_control_emulated.py.
pytestmark = [pytest.mark.integration, pytest.mark.alone]
REPO = Path(__file__).resolve().parents[1]

#: Longest time (s) from the consumer naming the rogue to wheels at rest: the wheels
#: spin down (about 0.5 s, tests/test_control_emulated.py), with a margin for a loaded
#: machine. Naming it takes a check period (publisher_check_period_s, 1 s) after DDS
#: discovery has told the consumer the rogue's node (up to DISCOVERY_LAG_S).
STOP_WITHIN_S = 4.0

#: A rogue node: publishes one message on a topic at 50 Hz until SIGINT, then leaves
#: cleanly (its endpoints are withdrawn at once). Prints 'rogue ready' once a
#: subscriber of the topic has matched its publisher.
ROGUE_CODE = """
import signal, sys, threading, time
import rclpy
from rclpy.signals import SignalHandlerOptions
from geometry_msgs.msg import Twist
from sensor_msgs.msg import JointState
from std_msgs.msg import Float32MultiArray

name, topic = sys.argv[1], sys.argv[2]
if topic == 'cmd_vel_safe':
    msg = Twist()
    msg.linear.y = 0.3
elif topic == 'joint_states':
    msg = JointState(name=sys.argv[3].split(','), position=[0.0] * 4, velocity=[0.0] * 4)
elif topic == 'motor_speeds':
    msg = Float32MultiArray(data=[5.0] * 4)
else:
    msg = Float32MultiArray(data=[0.3] * 4)
stop = threading.Event()
signal.signal(signal.SIGINT, lambda *_: stop.set())
rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
node = rclpy.create_node(name)
publisher = node.create_publisher(type(msg), topic, 10)
while publisher.get_subscription_count() == 0 and not stop.is_set():
    stop.wait(0.02)
print('rogue ready', flush=True)
while not stop.is_set():
    if topic == 'joint_states':
        msg.header.stamp = node.get_clock().now().to_msg()
    publisher.publish(msg)
    stop.wait(0.02)
node.destroy_publisher(publisher)
node.destroy_node()
rclpy.shutdown()
print('rogue gone', flush=True)
"""


class Driver:
    """The command chain's output, played by the test node: one twist at 20 Hz."""

    def __init__(self, test_node):
        self.publisher = test_node.node.create_publisher(Twist, 'cmd_vel_safe', 10)
        self.twist = Twist()
        self.twist.linear.x = 0.4
        self._context = test_node.context
        threading.Thread(target=self._run, daemon=True).start()

    def _run(self):
        while self._context.ok():
            try:
                self.publisher.publish(self.twist)
            except Exception:  # noqa: B902 - context shut down
                return
            time.sleep(0.05)


#: Below this speed (m/s, rad/s) the robot is at rest: a wheel still settling moves one
#: encoder count per velocity window (about 0.0015 m/s); the commands are 0.3-0.4 m/s.
REST_SPEED = 0.01


def at_rest(msg: Odometry) -> bool:
    """Tell whether the wheel odometry says the robot stands (practically) still."""
    twist = msg.twist.twist
    return max(abs(twist.linear.x), abs(twist.linear.y), abs(twist.angular.z)) < REST_SPEED


#: Odometry samples in a row at rest (encoder_reader publishes at the board's 50 Hz, so
#: 0.2 s) before the robot counts as stopped: a single sample proved little on CI's
#: loaded machine (the robot stood "0.05 s after" the consumer's ERROR arrived, yet moved
#: at 0.05 m/s in the second after).
REST_SAMPLES = 10


def wait_at_rest(odom, since: float, timeout: float) -> float:
    """Wait for REST_SAMPLES odometry samples in a row at rest; return the last's arrival."""
    deadline = time.monotonic() + timeout
    while True:
        run = 0
        for when, msg in odom.received_since(since):
            run = run + 1 if at_rest(msg) else 0
            if run >= REST_SAMPLES:
                return when
        if time.monotonic() > deadline:
            raise AssertionError(f'not at rest for {REST_SAMPLES} odometry samples in a row '
                                 f'within {timeout} s')
        time.sleep(0.02)


def what_happened(system, odom, since: float) -> str:
    """Describe the odometry twists and the system log since monotonic time since."""
    twists = [f'{when - since:6.3f} s  vx {m.twist.twist.linear.x:+.3f}  '
              f'vy {m.twist.twist.linear.y:+.3f}  wz {m.twist.twist.angular.z:+.3f}'
              for when, m in odom.received_since(since)]
    lines = [f'{when - since:6.3f} s  {line}' for when, line in system.lines_since(since)]
    return ('odometry twist (arrival after the rogue matched):\n' + '\n'.join(twists)
            + '\nsystem log since the rogue matched:\n' + '\n'.join(lines))


def driving(msg: Odometry) -> bool:
    """Tell whether the robot drives forward as the test node commands."""
    return msg.twist.twist.linear.x > 0.3


def start_rogue(env, name: str, topic: str, joint_names) -> OutputProcess:
    """Start a rogue publisher process; return it once its publisher is matched."""
    rogue = OutputProcess([sys.executable, '-c', ROGUE_CODE, name, topic,
                           ','.join(joint_names)], env, cwd=REPO)
    rogue.wait_for_line('rogue ready')
    return rogue


def stop_rogue(rogue: OutputProcess):
    """Ctrl-C the rogue; it withdraws its publisher and exits."""
    if rogue.process.poll() is None:
        os.killpg(rogue.process.pid, signal.SIGINT)
    try:
        assert rogue.process.wait(timeout=15) == 0, rogue.output()
    except subprocess.TimeoutExpired:
        os.killpg(rogue.process.pid, signal.SIGKILL)
        raise


#: (topic, the node that consumes it and must stop the robot, other nodes watching it)
#: velocity_controller watches its own output too (it then clears the stall latches that
#: hardware_interface's zero caused, and resumes after it); it has no subscription on the
#: topic, so DDS may tell it about the rogue seconds later than the consumer
#: (DISCOVERY_LAG_S).
ROUNDS = [('cmd_vel_safe', 'motor_controller', ()),
          ('motor_efforts', 'hardware_interface', ('velocity_controller',)),
          ('motor_speeds', 'velocity_controller', ()),
          ('joint_states', 'velocity_controller', ())]
#: Longest wait (s) for a node that does not subscribe the rogue's topic to discover it.
DISCOVERY_LAG_S = 15.0


def test_a_rogue_publisher_downstream_of_the_chain_stops_the_wheels_until_it_leaves(
        start_system, test_node, ros_env, tmp_path):
    from mecanum_control.robot_config import default_config_path, load_robot_config
    joint_names = load_robot_config(default_config_path()).wheel_joint_names
    system = start_system(
        'mecanum_control', 'emulated_control.launch.yaml', f'port:={tmp_path / "ttyESP32"}',
        f'estop_latch_file:={tmp_path / "estop_latched"}',
        'cmd_vel_safe_publishers:=integration_test')
    system.wait_for_line(r'\[hardware_interface\].*Connected to the board')
    system.wait_for_line(r'\[motor_controller\].*Motor controller started')
    system.wait_for_line(r'\[velocity_controller\].*control active')
    odom = test_node.record(Odometry, 'odom')
    diagnostics = test_node.record(DiagnosticArray, '/diagnostics')
    Driver(test_node)
    odom.wait_for(driving, timeout=10.0)

    for topic, consumer, watchers in ROUNDS:
        rogue_name = f'rogue_on_{topic}'
        rogue = start_rogue(ros_env, rogue_name, topic, joint_names)
        try:
            matched_at, _ = rogue.wait_for_line_at('rogue ready')
            # The consumer names the rogue once DDS discovery told it the publisher's node
            # (seen 3 s after the match on a loaded machine); from then on the wheels
            # stop. A single odometry sample at rest before that proves nothing: the
            # rogue's and the chain's commands may alternate meanwhile.
            noticed_at, _ = system.wait_for_line_at(
                rf'\[{consumer}\].*\[ERROR\].*/{topic} has unexpected publisher\(s\): '
                rf'/{rogue_name} ', timeout=DISCOVERY_LAG_S)
            try:
                rest_at = wait_at_rest(odom, noticed_at, timeout=STOP_WITHIN_S)
            except AssertionError as error:
                raise AssertionError(f'{topic}: {error}\n'
                                     f'{what_happened(system, odom, matched_at)}') from None
            print(f'{topic}: named {noticed_at - matched_at:.2f} s after the rogue was '
                  f'matched, at rest {rest_at - noticed_at:.2f} s after that '
                  f'({REST_SAMPLES} odometry samples in a row)')
            diagnostics.wait_for(lambda m: any(
                s.level == DiagnosticStatus.ERROR and f'/{rogue_name}' in s.message
                and consumer in s.name for s in m.status), timeout=3.0)
            for watcher in watchers:
                system.wait_for_line(rf'\[{watcher}\].*\[ERROR\].*/{topic} has unexpected '
                                     rf'publisher\(s\): /{rogue_name} ', DISCOVERY_LAG_S)
            # It stays at rest while the rogue publishes (1 s of odometry).
            still_from = time.monotonic()
            time.sleep(1.0)
            window = odom.since(still_from)
            moving = [(m.twist.twist.linear.x, m.twist.twist.linear.y, m.twist.twist.angular.z)
                      for m in window if not at_rest(m)]
            travel_m = math.inf if not window else math.hypot(
                window[-1].pose.pose.position.x - window[0].pose.pose.position.x,
                window[-1].pose.pose.position.y - window[0].pose.pose.position.y)
            assert len(window) > 10 and not moving and travel_m < 0.01, (
                f'{topic}: moved while the rogue published ({len(moving)} of {len(window)} '
                f'samples moving, {travel_m:.3f} m)\n{what_happened(system, odom, matched_at)}')
        finally:
            stop_rogue(rogue)
        gone_at = time.monotonic()
        for node in (consumer, *watchers):
            system.wait_for_line(rf'\[{node}\].*/{rogue_name} gone', DISCOVERY_LAG_S)
        odom.wait_since(gone_at, driving, timeout=6.0)
        print(f'{topic}: driving again {time.monotonic() - gone_at:.2f} s after the rogue left')
