"""
slam: online SLAM from the lidar and odometry, slam_toolbox's online_async job.

Subscribes ``scan`` (sensor_msgs/LaserScan, sensor-data QoS, depth 1: when a scan
takes longer than the scan period the newest one is processed next, as online_async
drops scans) and reads ``odom -> base_link`` (at the scan's stamp) and the laser mount
from ``/tf`` and ``/tf_static``. A scan newer than the newest odometry waits for it (as
slam_toolbox's tf message filter), up to ``transform_timeout`` of the node's clock, then
takes the newest odometry: the odometry of a scan's own time, not of up to one odometry
period earlier, whatever the machine's speed (in lockstep at max speed a scan is taken
before the EKF has published its time). Publishes:

* ``map`` (nav_msgs/OccupancyGrid, transient local) and ``map_metadata`` every
  ``map_update_interval`` seconds once it changed;
* ``map -> odom`` on ``/tf`` every ``transform_publish_period`` seconds, stamped
  ``transform_timeout`` ahead (as slam_toolbox), so lookups at the newest odometry work;
* ``pose`` (geometry_msgs/PoseWithCovarianceStamped): base_link in map at each scan.

Save the map with Nav2's command (``map_saver_cli -f ~/maps/home``): it takes the
latched ``map``. Parameters: slam_toolbox's names (config/slam_params.yaml); the
algorithm is :mod:`mecanum_navigation.slam.slam` (no ROS).
"""

from collections import deque
from dataclasses import fields
import math
import sys
import time
from typing import Optional

from geometry_msgs.msg import PoseWithCovarianceStamped, TransformStamped
from mecanum_control.angles import quaternion_from_yaw
from mecanum_control.log_throttle import KeyedThrottle
from mecanum_control.node_main import run_node
from mecanum_control.runtime_parameters import read_only_parameters
from mecanum_localization.tf_listener import stamp_to_s, TransformListener
from mecanum_localization.transforms import PlanarTransform, TransformBuffer, TransformError
from mecanum_map_server.grid_messages import occupancy_grid
from mecanum_navigation.slam.slam import OnlineSlam, SlamConfig
from nav_msgs.msg import MapMetaData, OccupancyGrid
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import LaserScan
from tf2_msgs.msg import TFMessage

#: Seconds between repeats of one kind of warning.
WARNING_PERIOD_S = 5.0
#: Scans kept while they wait for odometry (10 Hz scans wait at most transform_timeout).
MAX_WAITING_SCANS = 10


class SlamNode(Node):
    """Maps with OnlineSlam and publishes map, map -> odom and the robot's pose."""

    def __init__(self, **node_options):
        super().__init__('slam_toolbox', **node_options)
        self.odom_frame = self._declare('odom_frame', 'odom')
        self.map_frame = self._declare('map_frame', 'map')
        self.base_frame = self._declare('base_frame', 'base_link')
        scan_topic = self._declare('scan_topic', 'scan')
        self.map_update_interval_s = self._positive('map_update_interval', 5.0)
        transform_period_s = self._positive('transform_publish_period', 0.05)
        self.transform_timeout_s = self._positive('transform_timeout', 0.2)
        self.throttle_scans = self._declare('throttle_scans', 1)
        if self.throttle_scans < 1:
            raise ValueError(f'parameter throttle_scans must be >= 1, got {self.throttle_scans}')
        defaults = SlamConfig()
        values = {item.name: self._declare(item.name, getattr(defaults, item.name))
                  for item in fields(SlamConfig)}
        self.slam = OnlineSlam(SlamConfig(**values))  # ValueError names the bad field
        self.warnings = KeyedThrottle(WARNING_PERIOD_S)
        self.scan_count = 0
        self.map_changed = False
        self.process_times_s = []
        self.last_scan_stamp = None

        self.waiting_scans = deque(maxlen=MAX_WAITING_SCANS)
        self.tf_buffer = TransformBuffer()
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.map_pub = self.create_publisher(OccupancyGrid, 'map', latched)
        self.metadata_pub = self.create_publisher(MapMetaData, 'map_metadata', latched)
        self.pose_pub = self.create_publisher(PoseWithCovarianceStamped, 'pose', 10)
        self.tf_pub = self.create_publisher(TFMessage, '/tf', 100)
        self.tf_listener = TransformListener(self, self.tf_buffer, self.take_waiting_scans)
        scan_qos = QoSProfile(depth=1, reliability=qos_profile_sensor_data.reliability)
        self.scan_sub = self.create_subscription(LaserScan, scan_topic, self.on_scan, scan_qos)
        self.transform_timer = self.create_timer(transform_period_s, self.publish_transform)
        self.map_timer = self.create_timer(self.map_update_interval_s, self.publish_map)
        self.get_logger().info(
            f'SLAM started: scans on {self.scan_sub.topic_name}, {self.map_frame} -> '
            f'{self.odom_frame} -> {self.base_frame}, {values["resolution"]:g} m cells, '
            f'loop closing {"on" if values["do_loop_closing"] else "off"}')
        read_only_parameters(self)

    def _declare(self, name: str, default):
        """Declare a parameter; return its value checked against the default's type."""
        value = self.declare_parameter(
            name, default, ParameterDescriptor(dynamic_typing=True)).value
        if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if type(value) is not type(default):
            raise ValueError(f'parameter {name} must be of type {type(default).__name__}, '
                             f'got {value!r}')
        return value

    def _positive(self, name: str, default: float) -> float:
        value = self._declare(name, default)
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f'parameter {name} must be a positive number, got {value}')
        return value

    def on_scan(self, msg: LaserScan) -> None:
        """Queue a scan (every throttle_scans-th) until the odometry at its stamp is known."""
        self.scan_count += 1
        if (self.scan_count - 1) % self.throttle_scans:
            return
        self.waiting_scans.append(msg)
        self.take_waiting_scans()

    def take_waiting_scans(self) -> None:
        """Add the waiting scans whose odometry has come, or that waited transform_timeout."""
        now_s = None
        while self.waiting_scans:
            msg = self.waiting_scans[0]
            stamp_s = stamp_to_s(msg.header.stamp)
            try:
                odom = self.tf_buffer.lookup(self.odom_frame, self.base_frame, stamp_s)
            except TransformError:
                if now_s is None:
                    now_s = self.get_clock().now().nanoseconds * 1e-9
                if now_s - stamp_s < self.transform_timeout_s:
                    return
                odom = None
            self.waiting_scans.popleft()
            self.add_scan(msg, odom)

    def add_scan(self, msg: LaserScan, odom: Optional[PlanarTransform]) -> None:
        """Add a scan with the odometry pose at its stamp (odom), None: the newest one."""
        frame = msg.header.frame_id.lstrip('/')
        try:
            if odom is None:
                odom = self.tf_buffer.lookup(self.odom_frame, self.base_frame)
            mount = self.tf_buffer.lookup(self.base_frame, frame)
        except TransformError as error:
            self._warn('tf', f'scan skipped: {error}')
            return
        start = time.perf_counter()
        try:
            added = self.slam.add_scan((odom.x, odom.y, odom.yaw), msg.ranges, msg.angle_min,
                                       msg.angle_increment, msg.range_min, msg.range_max,
                                       (mount.x, mount.y, mount.yaw))
        except ValueError as error:
            self._warn('scan', f'scan skipped: {error}')
            return
        self.last_scan_stamp = msg.header.stamp
        if added:
            self.map_changed = True
            self.process_times_s.append(time.perf_counter() - start)
            count = self.slam.keyframe_count
            if count == 1 or count % 50 == 0:
                times = sorted(self.process_times_s)
                self.get_logger().info(
                    f'{count} keyframes, {self.slam.loop_closure_count} loop closure(s); '
                    f'keyframe processing {1e3 * times[len(times) // 2]:.1f} ms median, '
                    f'{1e3 * times[-1]:.1f} ms max')
        self.publish_pose(msg.header.stamp)

    def _warn(self, key: str, text: str) -> None:
        if self.warnings.ready(key):
            self.get_logger().warning(text)

    def publish_pose(self, stamp) -> None:
        """Publish base_link's pose in the map."""
        x, y, yaw = self.slam.pose()
        msg = PoseWithCovarianceStamped()
        msg.header.stamp = stamp
        msg.header.frame_id = self.map_frame
        msg.pose.pose.position.x, msg.pose.pose.position.y = float(x), float(y)
        q = msg.pose.pose.orientation
        q.x, q.y, q.z, q.w = quaternion_from_yaw(float(yaw))
        self.pose_pub.publish(msg)

    def publish_transform(self) -> None:
        """Publish map -> odom, stamped transform_timeout ahead of now."""
        x, y, yaw = self.slam.map_to_odom()
        msg = TransformStamped()
        msg.header.stamp = (self.get_clock().now()
                            + Duration(seconds=self.transform_timeout_s)).to_msg()
        msg.header.frame_id = self.map_frame
        msg.child_frame_id = self.odom_frame
        msg.transform.translation.x, msg.transform.translation.y = float(x), float(y)
        q = msg.transform.rotation
        q.x, q.y, q.z, q.w = quaternion_from_yaw(float(yaw))
        self.tf_pub.publish(TFMessage(transforms=[msg]))

    def publish_map(self) -> None:
        """Publish the map when keyframes were added since the last one."""
        if not self.map_changed:
            return
        self.map_changed = False
        grid = self.slam.occupancy_map()
        msg = occupancy_grid(grid, self.map_frame, self.get_clock().now().to_msg())
        self.map_pub.publish(msg)
        self.metadata_pub.publish(msg.info)

    def close(self) -> None:
        """Publish the final map, so a saver still gets everything mapped."""
        if self.slam.keyframe_count:
            self.map_changed = True
            self.publish_map()


def main(args=None) -> int:
    """Run the SLAM node until Ctrl-C or SIGTERM."""
    return run_node(SlamNode, 'slam_toolbox', args)


if __name__ == '__main__':
    sys.exit(main())
