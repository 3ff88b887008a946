"""
teleop_keyboard: drive the robot from the keyboard, like teleop_twist_keyboard.

Reads keys from the terminal (stdin in raw mode) and publishes ``cmd_vel``
(geometry_msgs/Twist, or TwistStamped with header.frame_id ``frame_id`` when
``stamped``; base_link, m/s and rad/s) at once on every key, as teleop_twist_keyboard
does: run by hand it drives the seed's simulation_node, and beside the command chain it
is the chain's ``external`` input. teleop.launch remaps it to ``cmd_vel_teleop``, the
chain's teleop_keyboard input (mecanum_safety config/twist_mux.yaml: above navigation
and text commands, then collision_monitor and zone_guard); by hand: ``--ros-args -r
cmd_vel:=cmd_vel_teleop``. The key bindings, the
holonomic (shift) mode included, are those of teleop_twist_keyboard; they live in
:mod:`mecanum_control.teleop_keys`.

Parameters: ``speed_m_s`` (0.3) and ``turn_rad_s`` (1.0) are the starting speeds,
``max_speed_m_s`` (0.8) and ``max_turn_rad_s`` (2.5) bound them; ``repeat_rate_hz``
(10.0) republishes a non-zero twist so the command chain's timeouts do not stop
the robot while a key is held; with no key for ``key_timeout_s`` (0.8, longer than a
terminal's auto-repeat delay) the twist becomes zero (a lost terminal stops the
robot); ``stamped`` (false), ``frame_id`` (base_link).

Needs an interactive terminal: without one it exits with code 2. Ctrl-C, end of input,
SIGINT, SIGTERM and SIGHUP publish a zero twist, restore the terminal and exit.
"""

import codecs
import contextlib
import os
import select
import signal
import sys
import termios
import time
import tty

from geometry_msgs.msg import Twist, TwistStamped
from mecanum_control.parameters import positive
from mecanum_control.runtime_parameters import read_only_parameters
from mecanum_control.teleop_keys import (
    apply_key, HELP_TEXT, QUIT_KEY, SPEED_BINDINGS, speeds_text, TeleopState, twist_from_state)
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

NODE_NAME = 'teleop_keyboard'
NOT_A_TTY_MESSAGE = (
    'teleop_keyboard needs an interactive terminal; run it with '
    '`./mecanum run mecanum_control teleop_keyboard` or '
    '`ros2 run mecanum_control teleop_keyboard`, or in launch with a terminal prefix '
    'such as xterm -e')
# Print the help text again after this many speed lines, as teleop_twist_keyboard does.
HELP_EVERY_SPEED_LINES = 15


class TeleopKeyboard(Node):
    """Turns key presses into cmd_vel twists; republishes them while keys keep coming."""

    def __init__(self):
        super().__init__(NODE_NAME)
        speed = positive('speed_m_s', self.declare_parameter('speed_m_s', 0.3).value)
        turn = positive('turn_rad_s', self.declare_parameter('turn_rad_s', 1.0).value)
        max_speed = positive('max_speed_m_s',
                             self.declare_parameter('max_speed_m_s', 0.8).value)
        max_turn = positive('max_turn_rad_s',
                            self.declare_parameter('max_turn_rad_s', 2.5).value)
        repeat_rate_hz = positive('repeat_rate_hz',
                                  self.declare_parameter('repeat_rate_hz', 10.0).value)
        self.key_timeout_s = positive('key_timeout_s',
                                      self.declare_parameter('key_timeout_s', 0.8).value)
        self.stamped = bool(self.declare_parameter('stamped', False).value)
        self.frame_id = str(self.declare_parameter('frame_id', 'base_link').value)
        self.state = TeleopState.initial(speed, turn, max_speed, max_turn)
        if (self.state.speed_m_s, self.state.turn_rad_s) != (speed, turn):
            self.get_logger().warning(
                f'speed_m_s {speed} / turn_rad_s {turn} above max_speed_m_s {max_speed} / '
                f'max_turn_rad_s {max_turn}: starting at the maxima')
        self.repeat_period_s = 1.0 / repeat_rate_hz
        self._last_key_s = time.monotonic()
        self._speed_lines = 0

        self.cmd_pub = self.create_publisher(
            TwistStamped if self.stamped else Twist, 'cmd_vel', 10)
        # Key timing is wall time, also with use_sim_time: keys come from a person.
        self.timer = self.create_timer(self.repeat_period_s, self.on_timer,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(
            f'Keyboard teleop started: publishing {"TwistStamped" if self.stamped else "Twist"}'
            f' on {self.cmd_pub.topic_name}, max {max_speed} m/s and {max_turn} rad/s, '
            f'repeat {repeat_rate_hz} Hz, key timeout {self.key_timeout_s} s')
        read_only_parameters(self)

    def handle_key(self, key: str) -> bool:
        """Apply one key and publish the twist; return False for the quit key (Ctrl-C)."""
        self.state, _bound = apply_key(self.state, key)
        self._last_key_s = time.monotonic()
        if key in SPEED_BINDINGS:
            print(speeds_text(self.state), flush=True)
            self._speed_lines += 1
            if self._speed_lines % HELP_EVERY_SPEED_LINES == 0:
                print(HELP_TEXT, flush=True)
        self.publish_twist()
        return key != QUIT_KEY

    def on_timer(self) -> None:
        """Republish a non-zero twist; make it zero once no key came for key_timeout_s."""
        if not self.state.moving:
            return
        if time.monotonic() - self._last_key_s >= self.key_timeout_s:
            self.state = self.state.stopped()
        self.publish_twist()

    def publish_twist(self) -> None:
        """Publish the twist of the current state."""
        self._publish(*twist_from_state(self.state))

    def _publish(self, vx: float, vy: float, wz: float) -> None:
        twist = Twist()
        twist.linear.x, twist.linear.y, twist.angular.z = vx, vy, wz
        if self.stamped:
            msg = TwistStamped(twist=twist)
            msg.header.stamp = self.get_clock().now().to_msg()
            msg.header.frame_id = self.frame_id
            self.cmd_pub.publish(msg)
        else:
            self.cmd_pub.publish(twist)

    def close(self) -> None:
        """Publish a zero twist on the way out and give it a moment to be delivered."""
        self.state = self.state.stopped()
        self._publish(0.0, 0.0, 0.0)
        self.cmd_pub.wait_for_all_acked(Duration(seconds=0.5))


@contextlib.contextmanager
def raw_terminal(fd: int):
    """
    Put the terminal fd in raw mode for the block, then restore its settings.

    Output processing stays on so that printed lines still start at the left margin.
    The settings are restored even on exceptions (unless the terminal is gone).
    """
    saved = termios.tcgetattr(fd)
    try:
        tty.setraw(fd, termios.TCSADRAIN)
        mode = termios.tcgetattr(fd)
        mode[1] |= termios.OPOST | termios.ONLCR
        termios.tcsetattr(fd, termios.TCSADRAIN, mode)
        yield
    finally:
        try:
            termios.tcsetattr(fd, termios.TCSADRAIN, saved)
        except termios.error:
            pass  # the terminal was closed


def run_key_loop(node: TeleopKeyboard, fd: int) -> None:
    """
    Read keys from fd and spin node in between, until Ctrl-C or end of input.

    One thread: select() waits briefly for input, then the node's ready callbacks
    (the repeat timer) run.
    """
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    decoder = codecs.getincrementaldecoder('utf-8')(errors='replace')
    poll_s = min(0.02, node.repeat_period_s / 4)
    try:
        while node.context.ok():
            readable, _, _ = select.select([fd], [], [], poll_s)
            if readable:
                try:
                    data = os.read(fd, 64)
                except OSError:  # EIO: the terminal was hung up
                    data = b''
                if not data:
                    node.get_logger().warning('terminal closed: stopping')
                    return
                for key in decoder.decode(data):
                    if not node.handle_key(key):
                        return
            executor.spin_once(timeout_sec=0)
    finally:
        executor.remove_node(node)
        executor.shutdown()


def _raise_keyboard_interrupt(_signum, _frame):
    raise KeyboardInterrupt


def main(args=None) -> int:
    """Run the teleop_keyboard node until Ctrl-C or a signal; return an exit code."""
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
    signal.signal(signal.SIGHUP, _raise_keyboard_interrupt)
    logger = rclpy.logging.get_logger(NODE_NAME)
    if not sys.stdin.isatty():
        logger.fatal(NOT_A_TTY_MESSAGE)
        rclpy.try_shutdown()
        return 2
    try:
        node = TeleopKeyboard()
    except ValueError as error:
        logger.fatal(f'{error}')
        rclpy.try_shutdown()
        return 2
    except KeyboardInterrupt:
        rclpy.try_shutdown()
        return 0
    try:
        with raw_terminal(sys.stdin.fileno()):
            print(HELP_TEXT, flush=True)
            print(speeds_text(node.state), flush=True)
            run_key_loop(node, sys.stdin.fileno())
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        try:
            node.close()
        except Exception as error:  # noqa: B902 - report, then still clean up
            node.get_logger().error(f'could not publish the final zero twist: {error}')
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
