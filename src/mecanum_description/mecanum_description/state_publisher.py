"""
state_publisher: the robot_state_publisher of the pip setup (node robot_state_publisher).

Reads the URDF in ``robot_description`` (required) and publishes it on
``/robot_description`` (std_msgs/String, transient local, depth 1), every fixed joint
as one message on ``/tf_static`` (tf2_msgs/TFMessage, transient local, depth 1,
stamped with the node's clock at start), and, for each ``joint_states``
(sensor_msgs/JointState) message, the transforms of the moving joints in it on
``/tf``, stamped with the joint state's stamp (the node's clock if it has none).
Frames are ``frame_prefix`` + link name; a transform takes points from the child
link frame to the parent's (tf2). Joint names that are not moving joints of the
robot are ignored and positions that are NaN or infinite are skipped, each with a
throttled warning.

Parameters: ``robot_description`` (URDF XML, read-only), ``frame_prefix`` (''),
``publish_frequency`` (20.0 Hz: each joint's transform is published at most this
often, in message time), ``use_sim_time``.
"""

import sys

from builtin_interfaces.msg import Time
from geometry_msgs.msg import TransformStamped
from mecanum_control.node_main import run_node
from mecanum_control.parameters import declare_number
from mecanum_control.runtime_parameters import read_only_parameters
from mecanum_description.joint_states import joint_state_transforms, PublishThrottle
from mecanum_description.robot_model import parse_urdf, Transform, UrdfError
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

MAX_PUBLISH_FREQUENCY_HZ = 1000.0


def transform_message(transform: Transform, stamp: Time, frame_prefix: str) -> TransformStamped:
    """Return transform as a TransformStamped with prefixed frame names."""
    msg = TransformStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_prefix + transform.parent
    msg.child_frame_id = frame_prefix + transform.child
    t = msg.transform.translation
    t.x, t.y, t.z = (float(v) for v in transform.translation)
    r = msg.transform.rotation
    r.x, r.y, r.z, r.w = (float(v) for v in transform.rotation)
    return msg


class StatePublisher(Node):
    """Publishes the robot description and its joints' transforms."""

    def __init__(self, **node_options):
        super().__init__('robot_state_publisher', **node_options)
        description = self.declare_parameter(
            'robot_description', '',
            ParameterDescriptor(read_only=True, description='the robot URDF (XML)')).value
        self.frame_prefix = str(self.declare_parameter('frame_prefix', '').value)
        publish_frequency = declare_number(self, 'publish_frequency', 20.0)
        if not 0.0 < publish_frequency <= MAX_PUBLISH_FREQUENCY_HZ:
            raise ValueError('parameter publish_frequency must be > 0 and <= '
                             f'{MAX_PUBLISH_FREQUENCY_HZ:g} Hz, got {publish_frequency}')
        if not description:
            raise ValueError('parameter robot_description is empty: pass the URDF (XML), '
                             'e.g. the output of xacro on a .urdf.xacro file')
        try:
            self.model = parse_urdf(description)
        except UrdfError as error:
            raise ValueError(f'parameter robot_description is not a valid URDF: {error}') \
                from None
        self.throttle = PublishThrottle(round(1e9 / publish_frequency))

        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.description_pub = self.create_publisher(String, '/robot_description', latched)
        self.static_pub = self.create_publisher(TFMessage, '/tf_static', latched)
        self.tf_pub = self.create_publisher(TFMessage, '/tf', 100)
        self.joint_sub = self.create_subscription(
            JointState, 'joint_states', self.on_joint_states, qos_profile_sensor_data)

        self.description_pub.publish(String(data=description))
        stamp = self.get_clock().now().to_msg()
        self.static_pub.publish(TFMessage(transforms=[
            transform_message(t, stamp, self.frame_prefix)
            for t in self.model.fixed_transforms()]))
        moving = [j.name for j in self.model.moving_joints()]
        self.get_logger().info(
            f'Robot state publisher started: robot {self.model.name!r}, '
            f'{len(self.model.links)} links, {len(self.model.static_joints())} fixed '
            f'transforms on /tf_static, moving joints: {", ".join(moving) or "none"}')
        read_only_parameters(self)

    def on_joint_states(self, msg: JointState) -> None:
        """Publish the transforms of the moving joints in one joint state."""
        try:
            update = joint_state_transforms(self.model, list(msg.name), list(msg.position))
        except ValueError as error:
            self.get_logger().warning(f'joint_states ignored: {error}',
                                      throttle_duration_sec=5.0)
            return
        if update.unknown:
            self.get_logger().warning(
                'joint_states: ignoring joints that are not moving joints of '
                f'{self.model.name!r}: {", ".join(update.unknown)}', throttle_duration_sec=10.0)
        if update.not_finite:
            self.get_logger().warning(
                f'joint_states: skipping non-finite positions of {", ".join(update.not_finite)}',
                throttle_duration_sec=2.0)
        if not update.transforms:
            return
        stamp = msg.header.stamp
        if stamp.sec == 0 and stamp.nanosec == 0:
            stamp = self.get_clock().now().to_msg()
        if not self.throttle.ready(list(update.positions),
                                   stamp.sec * 1_000_000_000 + stamp.nanosec):
            return
        self.tf_pub.publish(TFMessage(transforms=[
            transform_message(t, stamp, self.frame_prefix) for t in update.transforms]))


def main(args=None) -> int:
    """Run the state_publisher node until Ctrl-C or SIGTERM."""
    return run_node(StatePublisher, 'robot_state_publisher', args)


if __name__ == '__main__':
    sys.exit(main())
