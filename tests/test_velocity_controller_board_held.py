"""
velocity_controller takes hardware_interface's word that it holds the board at zero.

After a respawn of velocity_controller, hardware_interface once held the board at zero
for a killed process's stale writer on motor_efforts, which the new velocity_controller's
DDS participant never lists: the new controller pushed against the held board and latched
a stall on all four wheels, for good (tests/test_command_chain_faults.py, CI 2026-11-29).
hardware_interface says so on /diagnostics (its publisher check of motor_efforts); here a
real velocity_controller (rclpy, DDS, its own domain) is fed wheels standing still, a
target, and that status: it must zero its efforts and judge no stall while the board is
held, and control (and stall judging) must resume once hardware_interface says the
publishers are gone.
"""

import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from mecanum_control.velocity_controller import VelocityController
import pytest
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_msgs.msg import Float32MultiArray
from tests.test_runtime_parameter_nodes import InProcess

JOINTS = ['front_left_wheel_joint', 'front_right_wheel_joint', 'rear_left_wheel_joint',
          'rear_right_wheel_joint']
HELD_NAME = 'mecanum_control: hardware_interface publishers of /motor_efforts'


def status(unexpected: str) -> DiagnosticArray:
    """hardware_interface's publisher check of motor_efforts, as it publishes it."""
    return DiagnosticArray(status=[DiagnosticStatus(
        level=DiagnosticStatus.ERROR if unexpected else DiagnosticStatus.OK, name=HELD_NAME,
        message='...', values=[KeyValue(key='topic', value='/motor_efforts'),
                               KeyValue(key='expected_publishers', value='/velocity_controller'),
                               KeyValue(key='unexpected_publishers', value=unexpected)])])


class Feed:
    """Wheels standing still at 50 Hz, a 10 rad/s target at 20 Hz, the status at 2 Hz."""

    def __init__(self, test_node, unexpected: str = '(an endpoint of no known ROS node)'):
        node = test_node.node
        self.joints = node.create_publisher(JointState, 'joint_states', 10)
        self.targets = node.create_publisher(Float32MultiArray, 'motor_speeds', 10)
        self.diagnostics = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.unexpected = unexpected
        self.statuses_sent = 0
        self._stop = threading.Event()
        self._clock = node.get_clock()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        tick = 0
        while not self._stop.wait(0.02):
            msg = JointState(name=JOINTS, position=[0.0] * 4, velocity=[0.0] * 4)
            msg.header.stamp = self._clock.now().to_msg()
            self.joints.publish(msg)
            if tick % 2 == 0:
                self.targets.publish(Float32MultiArray(data=[10.0] * 4))
            if tick % 25 == 0:
                self.diagnostics.publish(status(self.unexpected))
                self.statuses_sent += 1
            tick += 1

    def stop(self):
        self._stop.set()
        self._thread.join(timeout=5)


@pytest.fixture
def controller(ros_env):
    running = InProcess(VelocityController, int(ros_env['ROS_DOMAIN_ID']), [
        Parameter('motor_speeds_publishers', value=''),
        Parameter('joint_states_publishers', value=''),
        Parameter('motor_efforts_publishers', value=''),
        Parameter('stall_time_s', value=0.3)])
    yield running
    running.close()


def test_no_stall_is_judged_while_hardware_interface_holds_the_board(controller, test_node):
    node = controller.node
    efforts = test_node.record(Float32MultiArray, 'motor_efforts')
    feed = Feed(test_node)
    try:
        # From the second status on (the first may arrive before discovery matched),
        # 1 s of control (stall_time_s is 0.3 s) against wheels that do not turn.
        controller.wait_until(lambda: feed.statuses_sent >= 2)
        held_from = time.monotonic() + 0.1
        time.sleep(1.1)
        window = efforts.since(held_from)
        assert len(window) > 20
        pushing = [list(m.data) for m in window if list(m.data) != [0.0] * 4]
        assert pushing == [], f'efforts against the held board: {pushing[:3]}'
        assert not any(stall.stalled for stall in node.stall_detectors)
        # hardware_interface: the publishers are gone; control resumes, and with the
        # wheels still standing, the stall is judged again (the latch was only held off).
        feed.unexpected = ''
        controller.wait_until(lambda: node._board_held_until is None)
        efforts.wait_for_new(lambda m: max(m.data) > 0.3, timeout=10.0)
        controller.wait_until(lambda: all(s.stalled for s in node.stall_detectors))
    finally:
        feed.stop()


def test_no_stall_is_judged_while_nobody_takes_the_efforts(controller, test_node):
    """
    A controller whose motor_efforts has no subscriber holds its loops and judges no stall.

    After a double respawn of velocity_controller (test_command_chain_faults, CI
    2026-11-29), the new controller latched all four wheels as stalled 0.4 s after it
    became active: its inputs had matched, hardware_interface had not yet matched its
    motor_efforts, so no effort reached the board and the wheels stood still. Here the
    board holds nothing (hardware_interface says so) and nobody subscribes to
    motor_efforts for 1 s of measurements (stall_time_s 0.3 s): no stall; then a
    subscriber comes, the wheels still stand, and the stall is judged.
    """
    node = controller.node
    feed = Feed(test_node, unexpected='')
    try:
        controller.wait_until(lambda: node.state == 'ok')
        since = node.measured_time
        controller.wait_until(lambda: (node.measured_time - since).nanoseconds > 1e9)
        assert not any(stall.stalled for stall in node.stall_detectors), (
            'a stall latched while no subscriber took the efforts')
        assert node.efforts == [0.0] * 4
        efforts = test_node.record(Float32MultiArray, 'motor_efforts')
        efforts.wait_for_new(lambda m: max(m.data) > 0.3, timeout=10.0)
        controller.wait_until(lambda: all(s.stalled for s in node.stall_detectors))
    finally:
        feed.stop()
