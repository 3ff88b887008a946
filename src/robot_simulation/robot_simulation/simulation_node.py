"""
simulation_node: the seed's kinematic robot simulation, for quick experiments.

Subscribes ``cmd_vel`` (geometry_msgs/Twist, base_link, m/s and rad/s).
Publishes ``robot_status`` (std_msgs/String, "Position: x=.., y=.., theta=..",
as in the seed), ``odom`` (nav_msgs/Odometry, odom -> base_link) and, when
``publish_tf`` is true, the same transform on ``/tf`` (tf2_msgs/TFMessage).
Parameters: ``update_rate_hz`` (50.0), ``status_rate_hz`` (10.0),
``cmd_timeout_s`` (0.5), ``initial_x_m``/``initial_y_m``/``initial_yaw_rad``,
``odom_frame_id`` ('odom'), ``base_frame_id`` ('base_link'), ``publish_tf`` (true).
The model (:mod:`robot_simulation.kinematic_model`) has no dynamics or slip.
"""

import sys

from geometry_msgs.msg import Twist
from mecanum_control.messages import odometry_transform, planar_odometry
from mecanum_control.node_main import run_node
from mecanum_control.runtime_parameters import read_only_parameters
from nav_msgs.msg import Odometry
from rclpy.node import Node
from robot_simulation.kinematic_model import KinematicBase, Pose2D
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage


class RobotSimulation(Node):
    """Integrates cmd_vel into a pose and reports it."""

    def __init__(self, **node_options):
        super().__init__('robot_simulation', **node_options)
        update_rate_hz = float(self.declare_parameter('update_rate_hz', 50.0).value)
        status_rate_hz = float(self.declare_parameter('status_rate_hz', 10.0).value)
        cmd_timeout_s = float(self.declare_parameter('cmd_timeout_s', 0.5).value)
        initial = Pose2D(float(self.declare_parameter('initial_x_m', 0.0).value),
                         float(self.declare_parameter('initial_y_m', 0.0).value),
                         float(self.declare_parameter('initial_yaw_rad', 0.0).value))
        self.odom_frame_id = self.declare_parameter('odom_frame_id', 'odom').value
        self.base_frame_id = self.declare_parameter('base_frame_id', 'base_link').value
        self.publish_tf = bool(self.declare_parameter('publish_tf', True).value)
        for name, value in (('update_rate_hz', update_rate_hz),
                            ('status_rate_hz', status_rate_hz)):
            if not value > 0.0:
                raise ValueError(f'{name} must be positive, got {value}')

        self.model = KinematicBase(initial, cmd_timeout_s)
        self.last_step = None

        self.status_pub = self.create_publisher(String, 'robot_status', 10)
        self.odom_pub = self.create_publisher(Odometry, 'odom', 10)
        self.tf_pub = self.create_publisher(TFMessage, '/tf', 100) if self.publish_tf else None
        self.cmd_sub = self.create_subscription(Twist, 'cmd_vel', self.on_cmd_vel, 10)
        self.step_timer = self.create_timer(1.0 / update_rate_hz, self.on_step)
        self.status_timer = self.create_timer(1.0 / status_rate_hz, self.on_status)
        self.get_logger().info('Robot simulation (kinematic) started')
        read_only_parameters(self)

    def on_cmd_vel(self, msg: Twist) -> None:
        """Take a new body twist; reject NaN/inf with a warning."""
        now_s = self.get_clock().now().nanoseconds * 1e-9
        try:
            self.model.command(msg.linear.x, msg.linear.y, msg.angular.z, now_s)
        except ValueError as error:
            self.get_logger().warning(f'Ignoring cmd_vel: {error}')

    def on_step(self) -> None:
        """Advance the model to now and publish odometry."""
        now = self.get_clock().now()
        dt_s = 0.0 if self.last_step is None else (now - self.last_step).nanoseconds * 1e-9
        self.last_step = now
        pose = self.model.step(now.nanoseconds * 1e-9, dt_s)
        odom = planar_odometry(now.to_msg(), self.odom_frame_id, self.base_frame_id,
                               (pose.x, pose.y, pose.yaw), self.model.twist)
        self.odom_pub.publish(odom)
        if self.tf_pub is not None:
            self.tf_pub.publish(TFMessage(transforms=[odometry_transform(odom)]))

    def on_status(self) -> None:
        """Publish the seed's human-readable position line."""
        pose = self.model.pose
        self.status_pub.publish(String(
            data=f'Position: x={pose.x:.2f}, y={pose.y:.2f}, theta={pose.yaw:.2f}'))


def main(args=None) -> int:
    """Run the simulation node until Ctrl-C or SIGTERM (a second one while closing too)."""
    return run_node(RobotSimulation, 'robot_simulation', args)


if __name__ == '__main__':
    sys.exit(main())
