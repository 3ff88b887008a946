"""
static_transform_publisher: tf2_ros' tool for one fixed transform, for the pip setup.

``static_transform_publisher --x 2.95 --y 2.0 --yaw 0 --frame-id map --child-frame-id
odom`` publishes that transform once on ``/tf_static`` (tf2_msgs/TFMessage, transient
local, as tf2_ros' StaticTransformBroadcaster latches it), stamped with the node's
clock, and stays up so late subscribers get it. Arguments: see
:mod:`mecanum_description.static_transform`. Bad arguments: one FATAL line, exit 2.
"""

import sys

from mecanum_control.node_main import run_node
from mecanum_control.runtime_parameters import read_only_parameters
from mecanum_description.state_publisher import transform_message
from mecanum_description.static_transform import parse_static_transform
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.utilities import remove_ros_args
from tf2_msgs.msg import TFMessage


class StaticTransformPublisher(Node):
    """Latches one transform on /tf_static."""

    def __init__(self, argv):
        transform = parse_static_transform(argv)
        super().__init__(f'static_transform_publisher_{transform.parent}_{transform.child}'
                         .replace('/', '_'))
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.tf_pub = self.create_publisher(TFMessage, '/tf_static', latched)
        stamp = self.get_clock().now().to_msg()
        self.tf_pub.publish(TFMessage(transforms=[transform_message(transform, stamp, '')]))
        t = transform.translation
        self.get_logger().info(
            f'Spinning until stopped - publishing transform {transform.parent} -> '
            f'{transform.child}: translation ({t[0]}, {t[1]}, {t[2]}), rotation '
            f'(x {transform.rotation[0]:.6f}, y {transform.rotation[1]:.6f}, '
            f'z {transform.rotation[2]:.6f}, w {transform.rotation[3]:.6f})')
        read_only_parameters(self)


def main(args=None) -> int:
    """Run the static_transform_publisher until Ctrl-C or SIGTERM."""
    argv = remove_ros_args(args=sys.argv if args is None else args)[1:]
    return run_node(lambda: StaticTransformPublisher(argv), 'static_transform_publisher', args)


if __name__ == '__main__':
    sys.exit(main())
