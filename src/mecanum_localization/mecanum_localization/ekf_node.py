"""
ekf_node: a planar EKF configured like robot_localization's ekf_node.

Parameters: robot_localization's keys (see :mod:`mecanum_localization.ekf_config` and
the README), read from the node's parameter file; the default node name is
``ekf_filter_node``, as in robot_localization's examples.

Subscribes the configured sensors, ``odomN`` (nav_msgs/Odometry), ``imuN``
(sensor_msgs/Imu), ``poseN`` (PoseWithCovarianceStamped) and ``twistN``
(TwistWithCovarianceStamped), best-effort QoS (matches reliable and best-effort
publishers) with depth ``*_queue_size``; ``/tf_static`` (transient local) for the static
transforms from sensor frames to base_link_frame; ``set_pose``
(PoseWithCovarianceStamped). Service ``set_pose`` (mecanum_interfaces/SetPose).
Publishes ``odometry/filtered`` (nav_msgs/Odometry, world_frame -> base_link_frame,
twist in base_link_frame), ``accel/filtered`` (AccelWithCovarianceStamped, base_link_frame)
with ``publish_acceleration``, and world_frame -> base_link_frame on ``/tf`` with
``publish_tf``.

Every ``1 / frequency`` s the queued measurements are fused in stamp order and the
estimate is published with the stamp of the latest one; with no measurement for
``sensor_timeout`` the filter predicts up to the current time instead. A sensor's
messages are dropped, with a throttled warning, while its frame has no transform to
base_link_frame (e.g. /tf_static not heard yet) or its values are unusable; the first
one used is logged ("imu0 imu/data_raw: first message taken in"), so a launch can tell
when every sensor is being fused.
"""

from itertools import count
import math
import sys
import time
from typing import List, Optional, Sequence, Set, Tuple

from builtin_interfaces.msg import Time
from geometry_msgs.msg import (
    AccelWithCovarianceStamped, PoseWithCovarianceStamped, TwistWithCovarianceStamped)
from mecanum_control.angles import yaw_from_quaternion
from mecanum_control.log_throttle import KeyedThrottle
from mecanum_control.messages import odometry_transform, planar_odometry
from mecanum_control.node_main import run_node
from mecanum_control.runtime_parameters import read_only_parameters
from mecanum_interfaces.srv import SetPose
from mecanum_localization.ekf import (
    AX, AY, Measurement, PlanarEkf, VX, VY, VYAW, X, Y, YAW)
from mecanum_localization.ekf_config import EkfConfig, parse_ekf_config, SensorConfig
from mecanum_localization.sensor_fusion import Conversion, planar_covariance_6, SensorFrontEnd
from mecanum_localization.transforms import (
    IDENTITY, PlanarTransform, TransformBuffer, TransformError)
from nav_msgs.msg import Odometry
import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu
from std_msgs.msg import Header
from tf2_msgs.msg import TFMessage

#: Variance published for what a planar filter does not estimate (z, roll, pitch, ...):
#: small, but not zero, so consumers inverting the covariance do not fail.
FIXED_VARIANCE = 1e-9
#: Seconds between two warnings of the same kind about the same topic or frame.
WARNING_PERIOD_S = 5.0
NS_PER_S = 1_000_000_000
MESSAGE_TYPES = {'odom': Odometry, 'imu': Imu, 'pose': PoseWithCovarianceStamped,
                 'twist': TwistWithCovarianceStamped}


def covariance_6(covariance: np.ndarray, indices: Sequence[int]) -> List[float]:
    """Return a row-major ROS 6x6 covariance holding the planar block of the state."""
    matrix = np.diag([FIXED_VARIANCE] * 6)
    ros = (0, 1, 5)
    matrix[np.ix_(ros, ros)] = covariance[np.ix_(indices, indices)]
    return [float(v) for v in matrix.reshape(-1)]


class EkfNode(Node):
    """Fuses odometry, IMU, pose and twist messages into odometry/filtered and /tf."""

    def __init__(self, **node_options):
        super().__init__('ekf_filter_node',
                         automatically_declare_parameters_from_overrides=True, **node_options)
        params = {name: parameter.value
                  for name, parameter in self.get_parameters_by_prefix('').items()}
        self.config: EkfConfig = parse_ekf_config(params)
        config = self.config
        self.filter = PlanarEkf(config.process_noise, config.initial_covariance,
                                config.initial_state, config.smooth_lagged_data,
                                config.history_length_s)
        started = time.monotonic()
        _warm_up()
        if time.monotonic() - started > 2.0:
            self.get_logger().info(
                f'compiled the numba kernels of the filter in {time.monotonic() - started:.1f} s '
                '(first run; numba caches them for the next)')
        self.frames = TransformBuffer()
        self.front_ends = {s.name: SensorFrontEnd(s, config.gravitational_acceleration_m_s2)
                           for s in config.sensors}
        self._pending: List[Tuple[float, int, Measurement]] = []
        self._sequence = count()
        self._epoch_ns: Optional[int] = None
        self._last_now_ns: Optional[int] = None
        self._last_published_time: Optional[float] = None
        self._last_measurement_s = -math.inf  # stamp of the newest measurement fused
        self._warnings = KeyedThrottle(WARNING_PERIOD_S)
        self._sensors_in_use: Set[str] = set()   # sensors whose messages have been used

        self.odom_pub = self.create_publisher(Odometry, 'odometry/filtered', 10)
        self.accel_pub = (self.create_publisher(AccelWithCovarianceStamped, 'accel/filtered', 10)
                          if config.publish_acceleration else None)
        self.tf_pub = (self.create_publisher(TFMessage, '/tf', 100)
                       if config.publish_tf else None)
        for sensor in config.sensors:
            qos = QoSProfile(depth=sensor.queue_size,
                             reliability=ReliabilityPolicy.BEST_EFFORT)
            callback = getattr(self, f'_on_{sensor.kind}')
            self.create_subscription(
                MESSAGE_TYPES[sensor.kind], sensor.topic,
                lambda msg, sensor=sensor, callback=callback: callback(sensor, msg), qos)
        latched = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                             reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(TFMessage, '/tf_static', self._on_tf_static, latched)
        self.create_subscription(PoseWithCovarianceStamped, 'set_pose',
                                 lambda msg: self._set_pose(msg, 'set_pose topic'), 10)
        self.create_service(SetPose, 'set_pose', self._on_set_pose_service)
        self.timer = self.create_timer(1.0 / config.frequency_hz, self._on_timer)

        for warning in config.warnings:
            self.get_logger().warning(warning)
        if config.unknown_keys:
            self.get_logger().warning(
                f'unknown parameters (not robot_localization keys) ignored: '
                f'{", ".join(config.unknown_keys)}')
        if config.ignored_keys:
            self.get_logger().info(f'robot_localization parameters not supported, ignored: '
                                   f'{", ".join(config.ignored_keys)}')
        inputs = '; '.join(f'{s.name} {s.topic} ({", ".join(s.fused_variables) or "nothing"})'
                           for s in config.sensors) or 'nothing'
        outputs = (f', {config.world_frame} -> {config.base_link_frame} on /tf'
                   if config.publish_tf else '')
        self.get_logger().info(f'EKF started at {config.frequency_hz:g} Hz: fusing {inputs}; '
                               f'publishing odometry/filtered{outputs}')
        read_only_parameters(self)

    # -- time ---------------------------------------------------------------------------

    def _seconds(self, stamp_ns: int) -> float:
        """Stamp in ns -> float seconds since an epoch (exact to the ns for ~100 days)."""
        if self._epoch_ns is None:
            self._epoch_ns = stamp_ns - stamp_ns % NS_PER_S
        return (stamp_ns - self._epoch_ns) * 1e-9

    def _stamp(self, seconds: float) -> Time:
        stamp_ns = self._epoch_ns + int(round(seconds * 1e9))
        return Time(sec=stamp_ns // NS_PER_S, nanosec=stamp_ns % NS_PER_S)

    @staticmethod
    def _ns(stamp: Time) -> int:
        return stamp.sec * NS_PER_S + stamp.nanosec

    def _warn(self, key: str, text: str) -> None:
        """Log a warning, at most once per WARNING_PERIOD_S for the same key."""
        if self._warnings.ready(key):
            self.get_logger().warning(text)

    # -- frames -------------------------------------------------------------------------

    def _on_tf_static(self, msg: TFMessage) -> None:
        for transform in msg.transforms:
            translation, rotation = transform.transform.translation, transform.transform.rotation
            planar = PlanarTransform(translation.x, translation.y, yaw_from_quaternion(
                rotation.x, rotation.y, rotation.z, rotation.w))
            if not all(math.isfinite(v) for v in (planar.x, planar.y, planar.yaw)):
                self._warn(f'tf {transform.child_frame_id}', '/tf_static transform '
                           f'{transform.header.frame_id} -> {transform.child_frame_id} is not '
                           'finite: ignored')
                continue
            self.frames.set_transform(transform.header.frame_id, transform.child_frame_id,
                                      planar, static=True)

    def _mount(self, frame_id: str, topic: str) -> Optional[PlanarTransform]:
        """Return the sensor frame in base_link_frame, or None (warned)."""
        base = self.config.base_link_frame
        try:
            return self.frames.lookup(base, frame_id or base)
        except TransformError:
            self._warn(f'frame {frame_id}', f'{topic}: no transform from frame {frame_id!r} to '
                       f'{base} on /tf_static: message dropped')
            return None

    def _in_world(self, frame_id: str, topic: str) -> Optional[PlanarTransform]:
        """Return the message frame in world_frame (identity if empty), or None (warned)."""
        world = self.config.world_frame
        if not frame_id.lstrip('/') or frame_id.lstrip('/') == world:
            return IDENTITY
        try:
            return self.frames.lookup(world, frame_id)
        except TransformError:
            self._warn(f'frame {frame_id}', f'{topic}: pose in frame {frame_id!r} and no static '
                       f'transform from it to {world}: pose dropped')
            return None

    # -- sensor messages ------------------------------------------------------------------

    def _queue(self, sensor: SensorConfig, conversions: Sequence[Conversion]) -> None:
        problems = [c.problem for c in conversions if c.problem]
        if problems:
            self._warn(f'{sensor.topic} problem', f'{sensor.topic}: {problems[0]}: message '
                       'skipped')
            return
        measurements = [m for conversion in conversions for m in conversion.measurements]
        for measurement in measurements:
            self._pending.append((measurement.time_s, next(self._sequence), measurement))
        if measurements and sensor.name not in self._sensors_in_use:
            # Until then its messages were dropped (warned: no transform, unusable values).
            self._sensors_in_use.add(sensor.name)
            self.get_logger().info(f'{sensor.name} {sensor.topic}: first message taken in, '
                                   'fusing it from now on')

    def _pose_conversion(self, sensor: SensorConfig, time_s: float, header_frame: str,
                         pose, covariance, child_frame: str = '') -> Optional[Conversion]:
        front = self.front_ends[sensor.name]
        if not front.uses_pose:
            return Conversion()
        frame = self._in_world(header_frame, sensor.topic)
        child = (self._mount(child_frame, sensor.topic)
                 if sensor.pose_use_child_frame else IDENTITY)
        if frame is None or child is None:
            return None
        q = pose.orientation
        return front.pose(time_s, pose.position.x, pose.position.y,
                          yaw_from_quaternion(q.x, q.y, q.z, q.w), covariance, frame, child)

    def _twist_conversion(self, sensor: SensorConfig, time_s: float, frame_id: str, twist,
                          covariance) -> Optional[Conversion]:
        front = self.front_ends[sensor.name]
        if not front.uses_twist:
            return Conversion()
        mount = self._mount(frame_id, sensor.topic)
        if mount is None:
            return None
        return front.twist(time_s, twist.linear.x, twist.linear.y, twist.angular.z,
                           covariance, mount)

    def _on_odom(self, sensor: SensorConfig, msg: Odometry) -> None:
        time_s = self._seconds(self._ns(msg.header.stamp))
        conversions = [
            self._pose_conversion(sensor, time_s, msg.header.frame_id, msg.pose.pose,
                                  msg.pose.covariance, msg.child_frame_id),
            self._twist_conversion(sensor, time_s, msg.child_frame_id, msg.twist.twist,
                                   msg.twist.covariance)]
        self._queue(sensor, [c for c in conversions if c is not None])

    def _on_pose(self, sensor: SensorConfig, msg: PoseWithCovarianceStamped) -> None:
        time_s = self._seconds(self._ns(msg.header.stamp))
        conversion = self._pose_conversion(sensor, time_s, msg.header.frame_id,
                                           msg.pose.pose, msg.pose.covariance)
        if conversion is not None:
            self._queue(sensor, [conversion])

    def _on_twist(self, sensor: SensorConfig, msg: TwistWithCovarianceStamped) -> None:
        time_s = self._seconds(self._ns(msg.header.stamp))
        conversion = self._twist_conversion(sensor, time_s, msg.header.frame_id,
                                            msg.twist.twist, msg.twist.covariance)
        if conversion is not None:
            self._queue(sensor, [conversion])

    def _on_imu(self, sensor: SensorConfig, msg: Imu) -> None:
        mount = self._mount(msg.header.frame_id, sensor.topic)
        if mount is None:
            return
        q, a = msg.orientation, msg.linear_acceleration
        conversion = self.front_ends[sensor.name].imu(
            self._seconds(self._ns(msg.header.stamp)), (q.x, q.y, q.z, q.w),
            msg.orientation_covariance, msg.angular_velocity.z, msg.angular_velocity_covariance,
            (a.x, a.y, a.z), msg.linear_acceleration_covariance, mount)
        self._queue(sensor, [conversion])

    # -- set_pose -------------------------------------------------------------------------

    def _on_set_pose_service(self, request: SetPose.Request,
                             response: SetPose.Response) -> SetPose.Response:
        self._set_pose(request.pose, 'set_pose service')
        return response

    def _set_pose(self, msg: PoseWithCovarianceStamped, source: str) -> None:
        """Restart the filter at the pose (robot_localization's set_pose)."""
        stamp_ns = self._ns(msg.header.stamp) or self.get_clock().now().nanoseconds
        frame = self._in_world(msg.header.frame_id, source)
        if frame is None:
            return
        q = msg.pose.pose.orientation
        pose = frame.compose(PlanarTransform(msg.pose.pose.position.x, msg.pose.pose.position.y,
                                             yaw_from_quaternion(q.x, q.y, q.z, q.w)))
        rotation = np.eye(3)
        rotation[:2, :2] = frame.rotation()
        covariance = rotation @ planar_covariance_6(msg.pose.covariance) @ rotation.T
        try:
            self.filter.set_pose(self._seconds(stamp_ns), pose.x, pose.y, pose.yaw, covariance)
        except ValueError as error:
            self._warn(source, f'{source}: {error}: ignored')
            return
        self._pending.clear()
        self._last_published_time = None
        self._last_measurement_s = self._seconds(stamp_ns)
        self.get_logger().info(f'{source}: pose set to x {pose.x:.3f} m, y {pose.y:.3f} m, '
                               f'yaw {pose.yaw:.3f} rad in {self.config.world_frame}')

    # -- the filter loop ------------------------------------------------------------------

    def _on_timer(self) -> None:
        now_ns = self.get_clock().now().nanoseconds
        if self._last_now_ns is not None and now_ns < self._last_now_ns:
            if self.config.reset_on_time_jump:
                self.get_logger().warning('time jumped back: filter reset')
                self.filter.reset()
                self._pending.clear()
                self._last_published_time = None
                self._last_measurement_s = -math.inf
                for front in self.front_ends.values():
                    front.reset()
            else:
                self._warn('time jump', 'time jumped back (reset_on_time_jump is false: '
                           'older measurements will be dropped)')
        self._last_now_ns = now_ns
        self._fuse_pending()
        if not self.filter.initialized:
            return
        now = self._seconds(now_ns)
        # No measurement for sensor_timeout: predict to now on every cycle (a dropout).
        if now - self._last_measurement_s >= self.config.sensor_timeout_s:
            self.filter.predict_to(now)
        if self.filter.time_s != self._last_published_time:
            self._publish()
            self._last_published_time = self.filter.time_s

    def _fuse_pending(self) -> None:
        pending, self._pending = sorted(self._pending, key=lambda item: item[:2]), []
        for _, _, measurement in pending:
            self._last_measurement_s = max(self._last_measurement_s, measurement.time_s)
            result = self.filter.process(measurement)
            if not result.accepted:
                self._warn(f'{measurement.source} {result.status}',
                           f'{measurement.source} at {measurement.time_s:.3f} s rejected '
                           f'({result.status}): {result.reason}')

    def _publish(self) -> None:
        config, state, covariance = self.config, self.filter.state, self.filter.covariance
        stamp = self._stamp(self.filter.time_s)
        odom = planar_odometry(
            stamp, config.world_frame, config.base_link_frame,
            (state[X], state[Y], state[YAW]), (state[VX], state[VY], state[VYAW]),
            covariance_6(covariance, (X, Y, YAW)), covariance_6(covariance, (VX, VY, VYAW)))
        self.odom_pub.publish(odom)
        if self.accel_pub is not None:
            accel = AccelWithCovarianceStamped()
            accel.header.stamp = stamp
            accel.header.frame_id = config.base_link_frame
            accel.accel.accel.linear.x = float(state[AX])
            accel.accel.accel.linear.y = float(state[AY])
            matrix = np.diag([FIXED_VARIANCE] * 6)
            matrix[:2, :2] = covariance[np.ix_((AX, AY), (AX, AY))]
            accel.accel.covariance = [float(v) for v in matrix.reshape(-1)]
            self.accel_pub.publish(accel)
        if self.tf_pub is not None:
            transform = odometry_transform(odom)
            if config.transform_time_offset_s:
                transform.header = Header(frame_id=config.world_frame, stamp=self._stamp(
                    self.filter.time_s + config.transform_time_offset_s))
            self.tf_pub.publish(TFMessage(transforms=[transform]))


def _warm_up() -> None:
    """
    Run a filter once through both kinds of update, so numba loads its compiled loops now.

    Otherwise the first measurements would stall the node (the first run ever compiles
    them: seconds; numba caches the result for later runs).
    """
    warm = PlanarEkf(np.eye(8) * 0.01, np.eye(8), smooth_lagged_data=True,
                     history_length_s=1.0)
    warm.process(Measurement(0.0, (VX, VY, VYAW), (0.0, 0.0, 0.0), np.eye(3)))
    warm.process(Measurement(0.1, (VYAW, AX, AY), (0.0, 0.0, 0.0), np.eye(3),
                             specific_force=True))
    warm.process(Measurement(0.05, (X, Y, YAW), (0.0, 0.0, 0.0), np.eye(3), 5.0))


def main(args=None) -> int:
    """Run the ekf_node until Ctrl-C or SIGTERM."""
    return run_node(EkfNode, 'ekf_filter_node', args)


if __name__ == '__main__':
    sys.exit(main())
