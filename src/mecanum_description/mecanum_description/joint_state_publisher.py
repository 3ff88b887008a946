"""
joint_state_publisher: every moving joint at position 0, for displaying the model.

Subscribes ``/robot_description`` (std_msgs/String, transient local, as
robot_state_publisher latches it) and publishes ``joint_states``
(sensor_msgs/JointState) at ``rate_hz`` (10.0) with position 0 (rad or m) for each
revolute, continuous and prismatic joint that does not mimic another, stamped with
the node's clock. Nothing is published until a valid description has arrived; an
invalid one is reported and the previous one kept. Only for display.launch.yaml:
the real robot's joint states come from encoder_reader.
"""

import sys
from typing import List

from mecanum_control.node_main import run_node
from mecanum_control.parameters import declare_number, positive
from mecanum_control.runtime_parameters import read_only_parameters
from mecanum_description.robot_model import parse_urdf, UrdfError
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import String


class JointStatePublisher(Node):
    """Publishes zero positions for the moving joints of the robot description."""

    def __init__(self):
        super().__init__('joint_state_publisher')
        rate_hz = positive('rate_hz', declare_number(self, 'rate_hz', 10.0))
        self.joint_names: List[str] = []

        self.joint_pub = self.create_publisher(JointState, 'joint_states', 10)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.description_sub = self.create_subscription(
            String, '/robot_description', self.on_description, latched)
        self.timer = self.create_timer(1.0 / rate_hz, self.publish)
        read_only_parameters(self)

    def on_description(self, msg: String) -> None:
        """Take the moving joints of a new robot description."""
        try:
            model = parse_urdf(msg.data)
        except UrdfError as error:
            self.get_logger().error(f'robot_description ignored: {error}')
            return
        self.joint_names = [j.name for j in model.moving_joints() if j.mimic is None]
        self.get_logger().info(f'Publishing joint states of {model.name!r}: '
                               f'{", ".join(self.joint_names) or "no moving joints"}')

    def publish(self) -> None:
        """Publish every joint at position 0."""
        if not self.joint_names:
            return
        msg = JointState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.name = list(self.joint_names)
        msg.position = [0.0] * len(self.joint_names)
        self.joint_pub.publish(msg)


def main(args=None) -> int:
    """Run the joint_state_publisher node until Ctrl-C or SIGTERM."""
    return run_node(JointStatePublisher, 'joint_state_publisher', args)


if __name__ == '__main__':
    sys.exit(main())
