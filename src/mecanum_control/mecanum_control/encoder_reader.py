"""
encoder_reader: wheel encoder counters -> joint states and wheel odometry.

Subscribes ``wheel_ticks`` (mecanum_interfaces/WheelTicks, FL FR RL RR counters).
Publishes ``joint_states`` (sensor_msgs/JointState: wheel angles rad, speeds rad/s,
joint names from ``wheel_joint_names``), ``odom`` (nav_msgs/Odometry, odom ->
base_link, twist in base_link, covariances from parameters) and, with
``publish_tf``, the same transform on ``/tf``. Counter wrap-around, lost,
duplicated and stale samples and board resets are handled by
:mod:`mecanum_control.wheel_odometry`.

Parameters: the robot parameters of motor_params.yaml, ``odom_frame_id`` ('odom'),
``base_frame_id`` ('base_link'), ``publish_tf`` (true; false when an EKF publishes
odom -> base_link), ``velocity_window_s`` (0.06), ``pose_covariance_diagonal`` and
``twist_covariance_diagonal`` (x, y, z, roll, pitch, yaw).
"""

import sys

from mecanum_control.messages import odometry_transform, planar_odometry
from mecanum_control.node_main import run_node
from mecanum_control.parameters import covariance_from_diagonal, declare_robot_config
from mecanum_control.runtime_parameters import read_only_parameters
from mecanum_control.wheel_odometry import EncoderSample, WheelOdometry
from mecanum_interfaces.msg import WheelTicks
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import JointState
from tf2_msgs.msg import TFMessage


class EncoderReader(Node):
    """Turns encoder counters into joint states and odometry."""

    def __init__(self, **node_options):
        super().__init__('encoder_reader', **node_options)
        config = declare_robot_config(self)
        self.joint_names = list(config.wheel_joint_names)
        self.odom_frame_id = self.declare_parameter('odom_frame_id', 'odom').value
        self.base_frame_id = self.declare_parameter('base_frame_id', 'base_link').value
        self.publish_tf = bool(self.declare_parameter('publish_tf', True).value)
        velocity_window_s = float(self.declare_parameter('velocity_window_s', 0.06).value)
        default_diagonal = [0.001, 0.001, 0.001, 0.001, 0.001, 0.01]
        self.pose_covariance, self.twist_covariance = (
            covariance_from_diagonal(name, self.declare_parameter(name, default_diagonal).value)
            for name in ('pose_covariance_diagonal', 'twist_covariance_diagonal'))
        self.odometry = WheelOdometry(config.geometry, config.rad_per_count,
                                      config.max_wheel_speed_rad_s, velocity_window_s)

        self.joint_pub = self.create_publisher(JointState, 'joint_states', 10)
        self.odom_pub = self.create_publisher(Odometry, 'odom', 10)
        self.tf_pub = self.create_publisher(TFMessage, '/tf', 100) if self.publish_tf else None
        self.ticks_sub = self.create_subscription(WheelTicks, 'wheel_ticks', self.on_ticks, 50)
        self.get_logger().info(
            f'Encoder reader started: {config.counts_per_wheel_rev:.0f} counts per wheel '
            f'revolution, joints {", ".join(self.joint_names)}')
        read_only_parameters(self)

    def on_ticks(self, msg: WheelTicks) -> None:
        """Integrate one counter sample and publish the results."""
        sample = EncoderSample(msg.sequence, msg.board_time_us, tuple(int(t) for t in msg.ticks))
        result = self.odometry.update(sample)
        if result.status in ('duplicate', 'stale', 'glitch', 'reset'):
            self.get_logger().warning(f'wheel_ticks sample {result.status}: {result.detail}',
                                      throttle_duration_sec=2.0)
            if result.status != 'reset':
                return
        elif result.lost:
            self.get_logger().debug(f'{result.lost} wheel_ticks samples lost before '
                                    f'{msg.sequence}; distance is kept (absolute counters)')
        self.publish(msg.header.stamp)

    def publish(self, stamp) -> None:
        """Publish joint_states, odom and (optionally) the odom -> base_link transform."""
        odometry = self.odometry
        joints = JointState()
        joints.header.stamp = stamp
        joints.name = self.joint_names
        joints.position = [float(p) for p in odometry.wheel_positions_rad]
        joints.velocity = [float(v) for v in odometry.wheel_velocities_rad_s]
        self.joint_pub.publish(joints)

        odom = planar_odometry(stamp, self.odom_frame_id, self.base_frame_id, odometry.pose,
                               odometry.twist, self.pose_covariance, self.twist_covariance)
        self.odom_pub.publish(odom)
        if self.tf_pub is not None:
            self.tf_pub.publish(TFMessage(transforms=[odometry_transform(odom)]))


def main(args=None) -> int:
    """Run the encoder_reader node until Ctrl-C or SIGTERM."""
    return run_node(EncoderReader, 'encoder_reader', args)


if __name__ == '__main__':
    sys.exit(main())
