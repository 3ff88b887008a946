"""
A tf2_ros TransformListener for the pip setup: /tf and /tf_static into a TransformBuffer.

tf2_ros is not installable from PyPI; nodes that need transforms create a
:class:`~mecanum_localization.transforms.TransformBuffer` and a
:class:`TransformListener` on their node, then call ``buffer.lookup(target, source,
time_s)`` as they would ``lookup_transform``. Only the planar part (x, y, yaw) of each
transform is kept. Subscriptions use tf2_ros's QoS: /tf volatile, /tf_static transient
local (latched), both reliable with depth 100.
"""

import math
from typing import Callable, Optional

from mecanum_control.angles import yaw_from_quaternion
from mecanum_localization.transforms import PlanarTransform, TransformBuffer
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from tf2_msgs.msg import TFMessage


def stamp_to_s(stamp) -> float:
    """Return a builtin_interfaces/Time in seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


class TransformListener:
    """Feeds every /tf and /tf_static transform a node receives into a buffer."""

    def __init__(self, node: Node, buffer: TransformBuffer,
                 on_update: Optional[Callable[[], None]] = None):
        """Subscribe /tf and /tf_static; on_update runs after each message is stored."""
        self.node = node
        self.buffer = buffer
        self.on_update = on_update
        self.rejected = 0
        dynamic = QoSProfile(depth=100)
        static = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.tf_sub = node.create_subscription(
            TFMessage, '/tf', lambda msg: self.on_message(msg, False), dynamic)
        self.tf_static_sub = node.create_subscription(
            TFMessage, '/tf_static', lambda msg: self.on_message(msg, True), static)

    def on_message(self, msg: TFMessage, static: bool) -> None:
        """Store each transform of a TFMessage; warn (throttled) about unusable ones."""
        for transform in msg.transforms:
            t, q = transform.transform.translation, transform.transform.rotation
            planar = PlanarTransform(t.x, t.y, yaw_from_quaternion(q.x, q.y, q.z, q.w))
            time_s = stamp_to_s(transform.header.stamp)
            try:
                self.buffer.set_transform(transform.header.frame_id, transform.child_frame_id,
                                          planar, time_s, static=static)
            except ValueError as error:
                self.rejected += 1
                if math.isfinite(time_s):
                    self.node.get_logger().warning(f'ignoring transform: {error}',
                                                   throttle_duration_sec=5.0)
        if self.on_update is not None:
            self.on_update()
