"""
command_script: send a list of text commands to robot_controller, one after another.

Parameters: ``commands`` (string array, required), ``start_delay_s`` (wait after
robot_controller is found, default 1.0), ``command_timeout_s`` (longest wait for
one command to finish, default 90.0). Publishes ``control_command``
(std_msgs/String); listens to ``control_status`` (std_msgs/String) for
``done:``/``rejected:`` and to ``robot_status`` (std_msgs/String) to report
where the robot got to (the first status received after a command finished).
Exits 0 when every command finished, 1 when one was rejected or timed out, so
launch files can end a system with ``on_exit: shutdown``.
"""

import sys
from typing import List, Optional

from mecanum_control.runtime_parameters import read_only_parameters
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import String


class CommandScript(Node):
    """Plays a fixed list of text commands, waiting for each to finish."""

    def __init__(self):
        super().__init__('command_script')
        self.commands: List[str] = list(
            self.declare_parameter('commands', Parameter.Type.STRING_ARRAY).value or [])
        self.start_delay_s = float(self.declare_parameter('start_delay_s', 1.0).value)
        self.command_timeout_s = float(self.declare_parameter('command_timeout_s', 90.0).value)
        if not self.commands:
            raise ValueError('parameter "commands" must list at least one command')

        self.next_index = 0
        self.waiting_since = None
        self.ready_since = None
        self.finished_command: Optional[str] = None
        self.all_done_at = None
        self.exit_code: Optional[int] = None

        self.command_pub = self.create_publisher(String, 'control_command', 10)
        self.status_sub = self.create_subscription(
            String, 'control_status', self.on_control_status, 10)
        self.robot_status_sub = self.create_subscription(
            String, 'robot_status', self.on_robot_status, 10)
        self.timer = self.create_timer(0.1, self.on_timer)
        self.get_logger().info(
            f'Command script with {len(self.commands)} commands; waiting for robot_controller')
        read_only_parameters(self)

    def on_robot_status(self, msg: String) -> None:
        """Report where the robot is once the last command has finished."""
        if self.finished_command is not None:
            self.get_logger().info(f'after {self.finished_command!r}: {msg.data}')
            self.finished_command = None
            if self.all_done_at is not None:
                self.exit_code = 0

    def on_control_status(self, msg: String) -> None:
        """Advance on done, stop on rejection; accepted/interrupted need nothing."""
        if self.waiting_since is None or not msg.data.startswith(('done', 'rejected')):
            return
        command = self.commands[self.next_index - 1]
        if msg.data.startswith('done'):
            self.get_logger().info(
                f'[{self.next_index}/{len(self.commands)}] finished {command!r}')
            self.finished_command = command
            self.waiting_since = None
            if self.next_index == len(self.commands):
                self.get_logger().info('All commands finished')
                self.all_done_at = self.get_clock().now()
        else:
            self.get_logger().error(f'Command {command!r} failed: {msg.data}')
            self.exit_code = 1

    def on_timer(self) -> None:
        """Wait for the controller, then send the next command when the last one is done."""
        now = self.get_clock().now()
        if self.all_done_at is not None:
            # Normally the exit follows the next robot_status; do not wait forever.
            if (now - self.all_done_at).nanoseconds > 1e9:
                self.exit_code = 0
            return
        if self.ready_since is None:
            if self.command_pub.get_subscription_count() > 0:
                self.ready_since = now
            return
        if (now - self.ready_since).nanoseconds < self.start_delay_s * 1e9:
            return
        if self.waiting_since is not None:
            if (now - self.waiting_since).nanoseconds > self.command_timeout_s * 1e9:
                self.get_logger().error(
                    f'Command {self.commands[self.next_index - 1]!r} did not finish within '
                    f'{self.command_timeout_s:g} s')
                self.exit_code = 1
            return
        if self.next_index < len(self.commands):
            command = self.commands[self.next_index]
            self.next_index += 1
            self.get_logger().info(
                f'[{self.next_index}/{len(self.commands)}] sending {command!r}')
            self.waiting_since = now
            self.command_pub.publish(String(data=command))


def main(args=None):
    """Run the script; the exit code tells whether every command finished."""
    rclpy.init(args=args)
    exit_code = 1
    node = None
    try:
        node = CommandScript()
        while rclpy.ok() and node.exit_code is None:
            rclpy.spin_once(node, timeout_sec=0.1)
        exit_code = node.exit_code if node.exit_code is not None else 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ValueError as error:
        print(f'command_script: {error}', file=sys.stderr)
        exit_code = 2
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    sys.exit(exit_code)


if __name__ == '__main__':
    main()
