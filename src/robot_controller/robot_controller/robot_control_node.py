"""
robot_control_node: text commands on ``control_command`` to velocity on ``cmd_vel``.

Subscribes ``control_command`` (std_msgs/String), e.g. "forward 0.5 m",
"strafe left 2 s", "rotate right 90 deg", "stop" (grammar in
:mod:`robot_controller.command_parser`). Publishes ``cmd_vel``
(geometry_msgs/Twist, base_link frame, m/s and rad/s) at ``publish_rate_hz``
while a motion lasts, then one zero twist; and ``control_status``
(std_msgs/String): ``accepted: <command>``, ``done: <motion>`` (finished, or
``done: stop``), ``interrupted: <motion>`` (replaced or stopped before its end)
and ``rejected: <reason>``. A new command replaces the running one; a rejected
command never moves the robot (the running motion, if any, is stopped).

Motions are timed on the node's clock. On simulated time (``use_sim_time``) that clock
reads 0 until the first /clock message arrives, which on a loaded machine can be seconds
after the node is up (DDS discovery). A command accepted before then waits, without
moving the robot, and starts at the clock's first tick, so that it still lasts its full
duration.
"""

import sys

from geometry_msgs.msg import Twist
from mecanum_control.node_main import run_node
from rclpy.duration import Duration
from rclpy.node import Node
from robot_controller.command_parser import CommandError, CommandLimits, Motion, parse_command
from std_msgs.msg import String


class RobotController(Node):
    """Turns text commands into timed velocity commands."""

    def __init__(self, **node_options):
        super().__init__('robot_controller', **node_options)
        defaults = CommandLimits()
        self.limits = CommandLimits(
            linear_speed_mps=self.declare_parameter(
                'linear_speed_mps', defaults.linear_speed_mps).value,
            angular_speed_radps=self.declare_parameter(
                'angular_speed_radps', defaults.angular_speed_radps).value,
            max_linear_speed_mps=self.declare_parameter(
                'max_linear_speed_mps', defaults.max_linear_speed_mps).value,
            max_angular_speed_radps=self.declare_parameter(
                'max_angular_speed_radps', defaults.max_angular_speed_radps).value,
            default_duration_s=self.declare_parameter(
                'default_duration_s', defaults.default_duration_s).value,
            max_duration_s=self.declare_parameter(
                'max_duration_s', defaults.max_duration_s).value)
        publish_rate_hz = self.declare_parameter('publish_rate_hz', 20.0).value
        if not publish_rate_hz > 0.0:
            raise ValueError(f'publish_rate_hz must be positive, got {publish_rate_hz}')

        self.motion = None
        self.motion_text = ''
        self.motion_end = None   # None while a motion waits for the clock to start

        self.cmd_vel_pub = self.create_publisher(Twist, 'cmd_vel', 10)
        self.status_pub = self.create_publisher(String, 'control_status', 10)
        self.command_sub = self.create_subscription(
            String, 'control_command', self.on_command, 10)
        self.timer = self.create_timer(1.0 / publish_rate_hz, self.on_timer)
        self.get_logger().info('Robot controller ready; send text commands on control_command')

    def on_command(self, msg: String) -> None:
        """Parse a command and start (or stop) the motion it describes."""
        text = msg.data.strip()
        try:
            motion = parse_command(text, self.limits)
        except CommandError as error:
            self.get_logger().warning(f'Rejected command {text!r}: {error}')
            self.interrupt()
            self.report(f'rejected: {error}')
            return
        self.interrupt()
        if motion.is_stop:
            self.finish('done: stop')
            return
        self.motion = motion
        self.motion_text = text
        self.report(f'accepted: {text}')
        if self.clock_started():
            self.start_motion()
        else:
            self.get_logger().warning(
                f'Holding {text!r} until the clock starts (use_sim_time is set and no '
                '/clock message has arrived yet)')

    def clock_started(self) -> bool:
        """Whether the node's clock runs: simulated time reads 0 until the first /clock."""
        return self.get_clock().now().nanoseconds > 0

    def start_motion(self) -> None:
        """Start timing the accepted motion now, and send its first twist."""
        motion = self.motion
        self.motion_end = self.get_clock().now() + Duration(seconds=motion.duration_s)
        self.get_logger().info(
            f'Executing {self.motion_text!r}: vx={motion.vx:.3f} m/s vy={motion.vy:.3f} m/s '
            f'wz={motion.wz:.3f} rad/s for {motion.duration_s:.2f} s')
        self.publish_twist(motion)

    def on_timer(self) -> None:
        """Keep publishing the running motion, and end it when its time is up."""
        if self.motion is None:
            return
        if self.motion_end is None:   # accepted before the clock started
            if self.clock_started():
                self.start_motion()
            return
        if self.get_clock().now() >= self.motion_end:
            self.finish(f'done: {self.motion.name}')
        else:
            self.publish_twist(self.motion)

    def interrupt(self) -> None:
        """End the running motion early, if there is one."""
        if self.motion is not None:
            self.finish(f'interrupted: {self.motion.name}')

    def finish(self, status: str) -> None:
        """Stop the robot and report status."""
        self.motion = None
        self.motion_end = None
        self.cmd_vel_pub.publish(Twist())
        self.report(status)

    def publish_twist(self, motion: Motion) -> None:
        """Publish the motion's body twist on cmd_vel."""
        twist = Twist()
        twist.linear.x = motion.vx
        twist.linear.y = motion.vy
        twist.angular.z = motion.wz
        self.cmd_vel_pub.publish(twist)

    def report(self, status: str) -> None:
        """Publish a status line on control_status."""
        self.status_pub.publish(String(data=status))

    def close(self) -> None:
        """Stop the robot: a final zero twist (while the context is still valid)."""
        if self.context.ok():
            self.cmd_vel_pub.publish(Twist())


def main(args=None) -> int:
    """Run the robot_controller node until Ctrl-C or SIGTERM, then stop the robot."""
    return run_node(RobotController, 'robot_controller', args)


if __name__ == '__main__':
    sys.exit(main())
