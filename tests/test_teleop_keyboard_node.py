"""
The teleop_keyboard node (mecanum_control), end to end in its own process.

Its stdin is a real pseudo-terminal the test types into, and a real rclpy subscription
in a leased ROS domain records what it publishes on cmd_vel. The key logic itself is
unit tested in mecanum_control's test/test_teleop_keys.py.
"""

import os
import signal
import subprocess
import sys
import threading
import time

from geometry_msgs.msg import Twist, TwistStamped
from mecanum_bringup.isolation import isolated_environment, lease_domain_id
from mecanum_control.teleop_keys import QUIT_KEY
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from tests.conftest import TerminalProcess

SPEED = 0.3
TURN = 1.0
MAX_SPEED = 0.8
MAX_TURN = 2.5


# --- the node, end to end --------------------------------------------------------------

MODULE = 'mecanum_control.teleop_keyboard'


@pytest.fixture(name='ros_domain')
def ros_domain_fixture(monkeypatch):
    """Lease a ROS domain; discovery stays on localhost, also for this process."""
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    with lease_domain_id() as lease:
        yield lease.domain_id


class CmdVelRecorder:
    """Records cmd_vel in the given domain from a node spun in a background thread."""

    def __init__(self, domain_id: int, msg_type):
        """Start the recorder node."""
        self.messages = []
        self._lock = threading.Lock()
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node('teleop_test_recorder', context=self.context)
        self.node.create_subscription(msg_type, 'cmd_vel', self._on_message, 100)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self):
        while self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except Exception:  # noqa: B902 - shutting down mid-spin
                if self.context.ok():
                    raise

    def _on_message(self, msg):
        with self._lock:
            self.messages.append((time.monotonic(), msg))

    def since(self, start: float) -> list:
        """Return (time, message) pairs received at or after monotonic time start."""
        with self._lock:
            return [(when, msg) for when, msg in self.messages if when >= start]

    def close(self):
        """Stop the recorder node."""
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self._thread.join(timeout=5)


def twist_of(msg) -> tuple:
    """(vx, vy, wz) of a Twist or TwistStamped."""
    twist = msg.twist if isinstance(msg, TwistStamped) else msg
    return (twist.linear.x, twist.linear.y, twist.angular.z)


class TeleopProcess(TerminalProcess):
    """The teleop_keyboard node in its own process, its stdin a pseudo-terminal."""

    def __init__(self, domain_id: int, *parameters: str):
        """Start the node with parameters (name:=value)."""
        ros_args = ['--ros-args'] + [arg for p in parameters for arg in ('-p', p)]
        super().__init__([sys.executable, '-m', MODULE, *ros_args],
                         isolated_environment(os.environ, domain_id))

    def hold(self, key: str, recorder: CmdVelRecorder, twist: tuple,
             timeout: float = 15.0) -> float:
        """
        Type key every 50 ms, as a held key repeats, until twist is received.

        Return the monotonic time of the last key typed. Holding covers the DDS
        discovery time: twists published before the subscription matched are lost.
        """
        start = time.monotonic()
        while time.monotonic() - start < timeout:
            self.type_keys(key)
            typed = time.monotonic()
            time.sleep(0.05)
            if any(twist_of(msg) == pytest.approx(twist) for _, msg in recorder.since(start)):
                return typed
        raise AssertionError(f'holding {key!r} did not give {twist}:\n{self.output()}')


@pytest.mark.integration
def test_node_without_terminal_exits_2_with_a_clear_message(ros_domain):
    """With stdin not a TTY (here /dev/null) the node refuses to start: exit code 2."""
    result = subprocess.run(
        [sys.executable, '-m', MODULE], stdin=subprocess.DEVNULL, capture_output=True,
        text=True, timeout=30, env=isolated_environment(os.environ, ros_domain))
    assert result.returncode == 2
    assert 'teleop_keyboard needs an interactive terminal' in result.stderr
    assert './mecanum run mecanum_control teleop_keyboard' in result.stderr


@pytest.mark.integration
def test_node_keys_repeat_timeout_and_ctrl_c(ros_domain):
    """
    Typed keys become cmd_vel Twists; the twist repeats, times out, and Ctrl-C stops.

    J strafes left, L right; with no key for key_timeout_s (0.6 s) a zero twist follows
    the repeated ones and then the node is quiet; q then I is 10 % faster forward;
    Ctrl-C publishes zero, exits 0 and restores the terminal settings.
    """
    recorder = CmdVelRecorder(ros_domain, Twist)
    teleop = TeleopProcess(ros_domain, 'key_timeout_s:=0.6', 'repeat_rate_hz:=10.0')
    try:
        teleop.wait_for_output('currently:\tspeed 0.3 m/s\tturn 1 rad/s')
        assert 'M    <    >' in teleop.output()
        teleop.hold('J', recorder, (0.0, 0.3, 0.0))
        last_key = teleop.hold('L', recorder, (0.0, -0.3, 0.0))
        deadline = last_key + 5.0
        while not any(twist_of(m) == (0.0, 0.0, 0.0) for _, m in recorder.since(last_key)):
            assert time.monotonic() < deadline, 'no zero twist after the key timeout'
            time.sleep(0.02)
        after = recorder.since(last_key)
        stop_time = next(when for when, m in after if twist_of(m) == (0.0, 0.0, 0.0))
        repeats = [when for when, m in after if when < stop_time]
        assert 0.5 < stop_time - last_key < 1.5
        assert all(twist_of(m) == pytest.approx((0.0, -0.3, 0.0))
                   for when, m in after if when < stop_time)
        assert len([when for when in repeats if when > last_key + 0.15]) >= 2
        time.sleep(0.4)
        assert len(recorder.since(stop_time + 0.01)) == 0, 'twists after stopping'

        teleop.type_keys('q')
        teleop.hold('I', recorder, (0.33, 0.0, 0.0))
        assert 'currently:\tspeed 0.33 m/s\tturn 1.1 rad/s' in teleop.output()
        quit_time = time.monotonic()
        teleop.type_keys(QUIT_KEY)
        assert teleop.process.wait(timeout=10) == 0
        time.sleep(0.2)
        assert twist_of(recorder.since(quit_time)[-1][1]) == (0.0, 0.0, 0.0)
        assert teleop.terminal_restored()
    finally:
        teleop.close()
        recorder.close()


@pytest.mark.integration
def test_node_stamped_and_sigterm_while_moving(ros_domain):
    """
    With stamped:=true it publishes TwistStamped in base_link; SIGTERM publishes zero.

    Holding U moves diagonally forward-left; SIGTERM while moving (and within the
    key timeout) still ends with a zero twist, exit code 0 and the terminal restored.
    """
    recorder = CmdVelRecorder(ros_domain, TwistStamped)
    teleop = TeleopProcess(ros_domain, 'stamped:=true', 'speed_m_s:=0.2')
    try:
        teleop.wait_for_output('currently:\tspeed 0.2 m/s')
        teleop.hold('U', recorder, (0.2, 0.2, 0.0))
        moving = [m for _, m in recorder.since(0.0) if twist_of(m) != (0.0, 0.0, 0.0)]
        assert {m.header.frame_id for m in moving} == {'base_link'}
        assert all(m.header.stamp.sec > 0 for m in moving)
        signal_time = time.monotonic()
        teleop.process.send_signal(signal.SIGTERM)
        assert teleop.process.wait(timeout=10) == 0
        time.sleep(0.2)
        assert twist_of(recorder.since(signal_time)[-1][1]) == (0.0, 0.0, 0.0)
        assert teleop.terminal_restored()
    finally:
        teleop.close()
        recorder.close()
