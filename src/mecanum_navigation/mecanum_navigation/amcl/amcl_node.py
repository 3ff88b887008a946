"""
amcl: nav2_amcl's localisation on a known map for the pip setup (node amcl).

The filter is :mod:`mecanum_navigation.amcl.particle_filter` (pure); this node only translates
ROS messages, parameters and transforms for it.

Subscribes ``map_topic`` ('map'; nav_msgs/OccupancyGrid, transient local: the likelihood
field is rebuilt per map, the particles stay), ``scan_topic`` ('scan';
sensor_msgs/LaserScan, sensor-data QoS), ``initialpose``
(geometry_msgs/PoseWithCovarianceStamped in ``global_frame_id``, what RViz's "2D Pose
Estimate" sends: the covariance's x, y, yaw rows and columns are used; the pose holds
from the next scan on, nav2 also moves it by the odometry since its stamp), ``/tf`` and
``/tf_static`` (``odom_frame_id`` -> ``base_frame_id`` at each scan's stamp, the laser
mount ``base_frame_id`` -> the scan's frame). A scan whose odometry is not known yet is
retried until ``transform_tolerance`` after its stamp, as tf2's message filter would.

Publishes, after each filter update, ``amcl_pose`` (PoseWithCovarianceStamped in
``global_frame_id``, transient local, stamped with the scan) and ``particle_cloud``
(geometry_msgs/PoseArray, reliable; Nav2 publishes nav2_msgs/ParticleCloud, not
available here; also at once after a global localisation request), and with
``tf_broadcast`` the ``global_frame_id`` -> ``odom_frame_id`` transform on ``/tf`` for
every scan, future-dated by ``transform_tolerance`` as nav2_amcl does (so lookups at the
latest scan's time work). Service ``reinitialize_global_localization``
(std_srvs/Empty): particles all over the free space. Before an initial pose
(``/initialpose``, ``set_initial_pose`` or the service) it publishes nothing, as Nav2,
and says once that it waits.

Parameters (nav2_amcl's names; see config/amcl.yaml): alpha1..alpha5, base_frame_id
('base_link'), global_frame_id ('map'), odom_frame_id ('odom'), laser_max_range,
laser_min_range, laser_likelihood_max_dist, laser_model_type (likelihood_field only),
max_beams, max_particles, min_particles, pf_err, pf_z, recovery_alpha_fast,
recovery_alpha_slow, resample_interval, robot_model_type (nav2_amcl::OmniMotionModel
only: this robot is omnidirectional), set_initial_pose, initial_pose.{x, y, z, yaw},
tf_broadcast, transform_tolerance, update_min_a, update_min_d, z_hit, z_rand, z_max and
z_short (accepted, unused by the likelihood field, as in Nav2), sigma_hit, scan_topic,
map_topic. Other nav2_amcl parameters (save_pose_rate, ...) are not supported and are
ignored. A bad value stops the node with one FATAL line naming it.

Resuming after a respawn (not nav2's; ROS 1 amcl's save_pose_rate idea, done with map ->
odom): with ``pose_state_file`` (an absolute path; '' = off, the default) amcl saves its
latest filter update (global -> odom, the odometry pose and the estimate's covariance,
:mod:`mecanum_navigation.amcl.pose_state`) there, atomically, at most every
``save_pose_period_s`` (ROS time, 2 s; at once after a new initial pose) and when it
stops cleanly. An amcl starting with a valid file there resumes from it instead of
``set_initial_pose``: at its first scan it starts the filter at the saved map -> odom
composed with the odometry of that scan, the saved covariance widened by the motion
model's noise for the odometry change since the save (``Resuming from FILE (saved at T
s): (x, y, yaw) ...``). A pose on /initialpose or a global localisation before that
first scan wins. An unreadable or invalid file is an ERROR line, then
``set_initial_pose`` as usual. The launch files give a path unique to the launch, so a
file never outlives the run it belongs to.
"""

import math
import os
from pathlib import Path
import sys
import time
from typing import Optional

from geometry_msgs.msg import Pose, PoseArray, PoseWithCovarianceStamped, TransformStamped
from mecanum_control.angles import quaternion_from_yaw, yaw_from_quaternion
from mecanum_control.log_throttle import KeyedThrottle
from mecanum_control.node_main import run_node
from mecanum_control.parameters import declare_typed
from mecanum_control.runtime_parameters import read_only_parameters
from mecanum_localization.tf_listener import stamp_to_s, TransformListener
from mecanum_localization.transforms import PlanarTransform, TransformBuffer, TransformError
from mecanum_map_server.grid_messages import occupancy_map
from mecanum_map_server.map_io import OccupancyMap
from mecanum_navigation.amcl.particle_filter import (
    AmclConfig, LikelihoodField, ParticleFilter, ScanData)
from mecanum_navigation.amcl.pose_state import (
    load, PoseState, PoseStateError, resume, save, save_due, state_from_estimate)
from nav_msgs.msg import OccupancyGrid
import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import LaserScan
from std_srvs.srv import Empty
from tf2_msgs.msg import TFMessage

OMNI_MODEL = 'nav2_amcl::OmniMotionModel'
LASER_MODEL = 'likelihood_field'
WARNING_PERIOD_S = 5.0
#: How often a scan waiting for its odometry transform is tried again (ROS time), s.
RETRY_PERIOD_S = 0.05
#: AmclConfig fields read from parameters of the same name (defaults: AmclConfig's).
FILTER_PARAMETERS = (
    'alpha1', 'alpha2', 'alpha3', 'alpha4', 'alpha5', 'min_particles', 'max_particles',
    'pf_err', 'pf_z', 'recovery_alpha_slow', 'recovery_alpha_fast', 'resample_interval',
    'update_min_d', 'update_min_a', 'z_hit', 'z_rand', 'z_max', 'z_short', 'sigma_hit',
    'laser_likelihood_max_dist', 'laser_max_range', 'laser_min_range', 'max_beams',
    'do_beamskip', 'beam_skip_distance', 'beam_skip_threshold', 'beam_skip_error_threshold')


class AmclNode(Node):
    """Adaptive Monte Carlo localisation: map -> odom from scans, odometry and a map."""

    def __init__(self, **node_options):
        super().__init__('amcl', **node_options)
        defaults = AmclConfig()
        values = {name: self._declare(name, getattr(defaults, name))
                  for name in FILTER_PARAMETERS}
        self.base_frame = self._frame('base_frame_id', 'base_link')
        self.global_frame = self._frame('global_frame_id', 'map')
        self.odom_frame = self._frame('odom_frame_id', 'odom')
        robot_model = self._declare('robot_model_type', OMNI_MODEL)
        if robot_model != OMNI_MODEL:
            raise ValueError(
                f'parameter robot_model_type {robot_model!r} is not supported: this is a '
                f'mecanum (omnidirectional) robot, use {OMNI_MODEL!r}')
        laser_model = self._declare('laser_model_type', LASER_MODEL)
        if laser_model != LASER_MODEL:
            raise ValueError(f'parameter laser_model_type {laser_model!r} is not supported: '
                             f'only {LASER_MODEL!r}')
        self.transform_tolerance = self._declare('transform_tolerance', 1.0)
        if not (math.isfinite(self.transform_tolerance) and self.transform_tolerance >= 0.0):
            raise ValueError('parameter transform_tolerance must be finite and >= 0, got '
                             f'{self.transform_tolerance}')
        self.tf_broadcast = self._declare('tf_broadcast', True)
        set_initial_pose = self._declare('set_initial_pose', False)
        initial = [self._declare(f'initial_pose.{key}', 0.0) for key in ('x', 'y', 'z', 'yaw')]
        # Not a nav2 parameter: the spread of set_initial_pose (standard deviations, m and
        # rad); nav2's 0.5 m / pi/12 by default. A known start (a simulation's spawn) can
        # be tighter, so the filter does not start with several clusters.
        spread = [self._declare(f'initial_pose.{key}', default) for key, default in
                  (('std_xy', 0.5), ('std_yaw', math.pi / 12.0))]
        if not all(math.isfinite(v) and v > 0.0 for v in spread):
            raise ValueError(f'parameters initial_pose.std_xy and std_yaw must be > 0, '
                             f'got {spread}')
        scan_topic = self._declare('scan_topic', 'scan')
        map_topic = self._declare('map_topic', 'map')
        self.pose_state_file = self._declare('pose_state_file', '')
        if self.pose_state_file:
            _check_pose_state_file(self.pose_state_file)
        self.save_pose_period_s = self._declare('save_pose_period_s', 2.0)
        if not (math.isfinite(self.save_pose_period_s) and self.save_pose_period_s > 0.0):
            raise ValueError('parameter save_pose_period_s must be finite and > 0, got '
                             f'{self.save_pose_period_s}')
        self.config = AmclConfig(**values)
        self.filter = ParticleFilter(self.config)
        # The state of this launch's previous amcl, resumed from at the first scan.
        self.resume_state = self._load_pose_state(set_initial_pose)
        if set_initial_pose:
            # Also when resuming: it checks the parameters and is the fall-back.
            try:
                self.filter.initialize((initial[0], initial[1], initial[3]),
                                       np.diag([spread[0] ** 2, spread[0] ** 2,
                                                spread[1] ** 2]))
            except ValueError as error:
                raise ValueError(f'parameter initial_pose: {error}') from None
            if self.resume_state is None:
                self._log_initial_pose(initial)
        self._initial_pose = initial if set_initial_pose else None
        # The latest filter update as a PoseState, the one last written, and whether the
        # next one is written whatever the period (the first, the first after a new pose).
        self._pose_state: Optional[PoseState] = None
        self._saved_state: Optional[PoseState] = None
        self._save_next = True
        _warm_up(self.config)

        self.tf_buffer = TransformBuffer()
        self.pending_scan: Optional[LaserScan] = None
        self.map_to_odom: Optional[PlanarTransform] = None
        self.waiting_logged = False
        self._warnings = KeyedThrottle(WARNING_PERIOD_S)
        self.update_count = 0
        self.update_total_s = 0.0
        self.update_max_s = 0.0
        self._cloud_poses = []

        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.pose_pub = self.create_publisher(PoseWithCovarianceStamped, 'amcl_pose', latched)
        self.cloud_pub = self.create_publisher(PoseArray, 'particle_cloud', 2)
        self.tf_pub = self.create_publisher(TFMessage, '/tf', 100) if self.tf_broadcast \
            else None
        self.tf_listener = TransformListener(self, self.tf_buffer)
        self.map_sub = self.create_subscription(OccupancyGrid, map_topic, self.on_map, latched)
        self.scan_sub = self.create_subscription(LaserScan, scan_topic, self.on_scan,
                                                 qos_profile_sensor_data)
        self.initial_pose_sub = self.create_subscription(
            PoseWithCovarianceStamped, 'initialpose', self.on_initial_pose, 10)
        self.global_srv = self.create_service(Empty, 'reinitialize_global_localization',
                                              self.on_global_localization)
        self.retry_timer = self.create_timer(RETRY_PERIOD_S, self.process_pending_scan)
        cfg = self.config
        self.get_logger().info(
            f'AMCL started ({OMNI_MODEL}, {LASER_MODEL}): {cfg.min_particles}..'
            f'{cfg.max_particles} particles, {cfg.max_beams} beams, updates every '
            f'{cfg.update_min_d:g} m / {cfg.update_min_a:g} rad; scans on '
            f'{self.scan_sub.topic_name}, map on {self.map_sub.topic_name}, '
            f'{self.global_frame} -> {self.odom_frame} -> {self.base_frame}')
        read_only_parameters(self)

    # --- parameters ------------------------------------------------------------------

    def _declare(self, name: str, default):
        """Declare a parameter and return its value checked against the default's type."""
        return declare_typed(self, name, default)

    def _frame(self, name: str, default: str) -> str:
        """Declare a frame parameter; it must not be empty."""
        frame = self._declare(name, default).strip('/')
        if not frame:
            raise ValueError(f'parameter {name} must not be empty')
        return frame

    def _warn(self, key: str, text: str) -> None:
        """Log a warning, at most once per WARNING_PERIOD_S for the same key."""
        if self._warnings.ready(key):
            self.get_logger().warning(text)

    def _log_initial_pose(self, initial) -> None:
        self.get_logger().info(
            f'Setting pose (set_initial_pose): ({initial[0]:.3f}, {initial[1]:.3f}, '
            f'{initial[3]:.3f}) in the map')

    # --- resuming after a respawn -----------------------------------------------------

    def _load_pose_state(self, set_initial_pose: bool) -> Optional[PoseState]:
        """Return the valid state in pose_state_file, else None (an error logged)."""
        if not self.pose_state_file:
            return None
        instead = 'set_initial_pose' if set_initial_pose else \
            'no pose (waiting for /initialpose)'
        try:
            state = load(self.pose_state_file)
            if state is None:
                return None
            state.check_frames(self.global_frame, self.odom_frame)
        except PoseStateError as error:
            self.get_logger().error(
                f'cannot resume from {self.pose_state_file}: {error}; starting from '
                f'{instead} instead')
            return None
        self.get_logger().info(
            f'Found the pose state of an amcl of this launch in {self.pose_state_file} '
            f'(saved at {state.stamp_s:.3f} s): resuming from it at the first scan'
            + (' (set_initial_pose ignored)' if set_initial_pose else ''))
        return state

    def _resume(self, odom_pose) -> None:
        """Start the filter from resume_state at the current odometry (the first scan's)."""
        state, self.resume_state = self.resume_state, None
        try:
            resumed = resume(state, odom_pose, self.config)
            self.filter.initialize(resumed.pose, resumed.covariance)
        except ValueError as error:
            self.get_logger().error(f'cannot resume from {self.pose_state_file}: {error}')
            if self._initial_pose is not None:
                self._log_initial_pose(self._initial_pose)
            return
        x, y, yaw = resumed.pose
        deviations = ', '.join(f'{math.sqrt(v):.3f}' for v in np.diag(resumed.covariance))
        self.get_logger().info(
            f'Resuming from {self.pose_state_file} (saved at {state.stamp_s:.3f} s): '
            f'({x:.3f}, {y:.3f}, {yaw:.3f}) in {self.global_frame}, standard deviations '
            f'{deviations} (odometry since: {resumed.travelled_m:.2f} m, '
            f'{resumed.turned_rad:.2f} rad)')

    def _restarted(self) -> None:
        """Forget the resume and the old state: the filter was set anew."""
        self.resume_state = None
        self._pose_state = None
        self._save_next = True

    def _keep_pose_state(self, estimate, stamp_s: float) -> None:
        """Remember the update's state; write it when save_pose_period_s has passed."""
        previous = self._saved_state
        try:
            self._pose_state = state_from_estimate(
                stamp_s, self.global_frame, self.odom_frame, estimate.pose,
                estimate.covariance, self.filter.odom_reference)
        except PoseStateError as error:
            self._warn('pose state', f'not saving the pose state: {error}')
            return
        if self._save_next or save_due(None if previous is None else previous.stamp_s,
                                       stamp_s, self.save_pose_period_s):
            self._write_pose_state()

    def _write_pose_state(self) -> None:
        """Write the latest state to pose_state_file (a failure is a warning)."""
        state = self._pose_state
        self._saved_state = state
        self._save_next = False
        try:
            save(self.pose_state_file, state)
        except OSError as error:
            self._warn('save pose state',
                       f'cannot save the pose state to {self.pose_state_file}: {error}')

    # --- inputs ----------------------------------------------------------------------

    def on_map(self, msg: OccupancyGrid) -> None:
        """Build the likelihood field of a new map."""
        frame = msg.header.frame_id.lstrip('/')
        if frame and frame != self.global_frame:
            self._warn('map frame', f'ignoring a map in frame {frame!r}: expected '
                       f'{self.global_frame!r}')
            return
        try:
            occupancy = occupancy_map(msg)
            field = LikelihoodField(occupancy, self.config.laser_likelihood_max_dist)
        except ValueError as error:
            self._warn('map', f'ignoring a map: {error}')
            return
        self.filter.set_map(field)
        self.get_logger().info(
            f'Received a {occupancy.width} x {occupancy.height} map at '
            f'{occupancy.resolution_m:g} m/cell ({field.obstacle_count} obstacle cells, '
            f'{len(field.free_cells)} free)')

    def on_initial_pose(self, msg: PoseWithCovarianceStamped) -> None:
        """(Re)start the filter around an initial pose in the global frame."""
        frame = msg.header.frame_id.lstrip('/')
        if frame != self.global_frame:
            self._warn('initial pose frame', f'ignoring an initial pose in frame {frame!r}: '
                       f'initial poses must be in {self.global_frame!r}')
            return
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        pose = (p.x, p.y, yaw_from_quaternion(q.x, q.y, q.z, q.w))
        c = msg.pose.covariance
        covariance = np.array([[c[i * 6 + j] for j in (0, 1, 5)] for i in (0, 1, 5)])
        try:
            self.filter.initialize(pose, covariance)
        except ValueError as error:
            self._warn('initial pose', f'ignoring an initial pose: {error}')
            return
        self._restarted()
        self.get_logger().info(
            f'Setting pose: ({pose[0]:.3f}, {pose[1]:.3f}, {pose[2]:.3f}) in '
            f'{self.global_frame}, standard deviations '
            f'{", ".join(f"{math.sqrt(max(v, 0.0)):.3f}" for v in np.diag(covariance))}')

    def on_global_localization(self, request, response):
        """Spread the particles over the map's free space (std_srvs/Empty)."""
        try:
            self.filter.global_localization()
        except ValueError as error:
            self.get_logger().warning(f'cannot reinitialize global localization: {error}')
            return response
        self._restarted()
        self.get_logger().info(f'Initializing with a uniform distribution of '
                               f'{self.config.max_particles} particles over the free space')
        self.publish_cloud(self.get_clock().now().to_msg())
        return response

    def on_scan(self, msg: LaserScan) -> None:
        """Take a scan (the newest replaces one still waiting for its odometry)."""
        self.pending_scan = msg
        self.process_pending_scan()

    # --- the filter ------------------------------------------------------------------

    def process_pending_scan(self) -> None:
        """Update the filter with the waiting scan once its transforms are known."""
        msg = self.pending_scan
        if msg is None:
            return
        if not self.filter.initialized and self.resume_state is None:
            self.pending_scan = None
            if not self.waiting_logged:
                self.waiting_logged = True
                self.get_logger().info(
                    'waiting for an initial pose on /initialpose (or a call of '
                    'reinitialize_global_localization): publishing nothing until then')
            return
        if self.filter.field is None:
            self.pending_scan = None
            self._warn('no map', 'no map yet: scans are ignored until one arrives on '
                       f'{self.map_sub.topic_name}')
            return
        frame = msg.header.frame_id.lstrip('/')
        stamp_s = stamp_to_s(msg.header.stamp)
        try:
            if not frame:
                raise TransformError('the scan has no frame_id')
            laser = self.tf_buffer.lookup(self.base_frame, frame)
            odom = self.tf_buffer.lookup(self.odom_frame, self.base_frame, stamp_s)
        except TransformError as error:
            now_s = self.get_clock().now().nanoseconds * 1e-9
            if frame and now_s <= stamp_s + self.transform_tolerance:
                return  # the odometry of that time may still come: try again later
            self.pending_scan = None
            self._warn('transform', f'ignoring a scan: {error}')
            return
        self.pending_scan = None
        if self.resume_state is not None:
            self._resume((odom.x, odom.y, odom.yaw))
            if not self.filter.initialized:
                return
        scan = ScanData(np.asarray(msg.ranges, dtype=float), msg.angle_min,
                        msg.angle_increment, msg.range_min, msg.range_max)
        started = time.perf_counter()
        try:
            result = self.filter.update((odom.x, odom.y, odom.yaw), scan,
                                        (laser.x, laser.y, laser.yaw))
        except ValueError as error:
            self._warn('scan', f'ignoring a scan: {error}')
            return
        if result.updated:
            if result.beams_used == 0:
                self._warn('beams', f'scan with no usable range (of {len(msg.ranges)}: NaN, '
                           'inf or outside range_min..range_max): only odometry applied')
            estimate = self.filter.estimate()
            reference = PlanarTransform(*self.filter.odom_reference)
            self.map_to_odom = PlanarTransform(*estimate.pose).compose(reference.inverse())
            if self.pose_state_file:
                self._keep_pose_state(estimate, stamp_s)
            self.publish_pose(estimate, msg.header.stamp)
            self.publish_cloud(msg.header.stamp)
            elapsed = time.perf_counter() - started
            self.update_count += 1
            self.update_total_s += elapsed
            self.update_max_s = max(self.update_max_s, elapsed)
        self.publish_transform(msg.header.stamp)

    # --- outputs ---------------------------------------------------------------------

    def publish_pose(self, estimate, stamp) -> None:
        """Publish amcl_pose: the estimate and its covariance (x, y, yaw entries)."""
        msg = PoseWithCovarianceStamped()
        msg.header.frame_id = self.global_frame
        msg.header.stamp = stamp
        x, y, yaw = estimate.pose
        msg.pose.pose.position.x, msg.pose.pose.position.y = float(x), float(y)
        q = msg.pose.pose.orientation
        q.x, q.y, q.z, q.w = quaternion_from_yaw(yaw)
        covariance = [0.0] * 36
        for i, row in enumerate((0, 1, 5)):
            for j, col in enumerate((0, 1, 5)):
                covariance[row * 6 + col] = float(estimate.covariance[i, j])
        msg.pose.covariance = covariance
        self.pose_pub.publish(msg)

    def publish_cloud(self, stamp) -> None:
        """Publish the particles as a PoseArray in the global frame (if anyone listens)."""
        if self.cloud_pub.get_subscription_count() == 0:
            return   # up to 2000 poses a filter update, for a viewer or a recording only
        msg = PoseArray()
        msg.header.frame_id = self.global_frame
        msg.header.stamp = stamp
        poses = self.filter.poses
        half = poses[:, 2] / 2.0
        sin_half, cos_half = np.sin(half).tolist(), np.cos(half).tolist()
        # Pose objects are reused (publish serialises at once): half the time of new ones.
        cloud = self._cloud_poses
        cloud.extend(Pose() for _ in range(len(poses) - len(cloud)))
        for pose, (x, y), s, c in zip(cloud, poses[:, :2].tolist(), sin_half, cos_half):
            position, orientation = pose.position, pose.orientation
            position.x, position.y = x, y
            orientation.z, orientation.w = s, c
        msg.poses = cloud[:len(poses)]
        self.cloud_pub.publish(msg)

    def publish_transform(self, stamp) -> None:
        """Publish global -> odom, future-dated by transform_tolerance (nav2_amcl)."""
        if self.tf_pub is None or self.map_to_odom is None:
            return
        transform = TransformStamped()
        nanoseconds = stamp.sec * 10 ** 9 + stamp.nanosec + \
            int(round(self.transform_tolerance * 1e9))
        transform.header.stamp.sec, transform.header.stamp.nanosec = divmod(nanoseconds,
                                                                            10 ** 9)
        transform.header.frame_id = self.global_frame
        transform.child_frame_id = self.odom_frame
        transform.transform.translation.x = self.map_to_odom.x
        transform.transform.translation.y = self.map_to_odom.y
        r = transform.transform.rotation
        r.x, r.y, r.z, r.w = quaternion_from_yaw(self.map_to_odom.yaw)
        self.tf_pub.publish(TFMessage(transforms=[transform]))

    def close(self) -> None:
        """Save the latest pose state; log the filter update time."""
        if self.pose_state_file and self._pose_state is not None \
                and self._pose_state is not self._saved_state:
            self._write_pose_state()
        if self.update_count:
            self.get_logger().info(
                f'filter update: {1e3 * self.update_total_s / self.update_count:.1f} ms mean, '
                f'{1e3 * self.update_max_s:.1f} ms max over {self.update_count} updates')


def _check_pose_state_file(path: str) -> None:
    """Raise ValueError unless path can be the pose state file (absolute, folder writable)."""
    where = f'parameter pose_state_file {path!r}'
    if not os.path.isabs(path):
        raise ValueError(f'{where} must be an absolute path (or empty: no saving)')
    file = Path(path)
    if not file.parent.is_dir():
        raise ValueError(f'{where}: folder {file.parent} does not exist')
    if not os.access(file.parent, os.W_OK | os.X_OK):
        raise ValueError(f'{where}: folder {file.parent} is not writable')
    if file.exists() and not file.is_file():
        raise ValueError(f'{where} exists and is not a file')


def _warm_up(config: AmclConfig) -> None:
    """
    Run the filter once on a small map, so numba loads its compiled loops now.

    Otherwise the first map and the first scan would each stall the node.
    """
    data = np.zeros((20, 20), dtype=np.int8)
    data[0, :] = 100
    field = LikelihoodField(OccupancyMap(0.05, (0.0, 0.0, 0.0), data),
                            config.laser_likelihood_max_dist)
    particle_filter = ParticleFilter(config, field, seed=0)
    particle_filter.initialize((0.5, 0.5, 0.0), np.eye(3) * 0.01)
    particle_filter.update((0.0, 0.0, 0.0), ScanData(np.array([0.4, 0.5]), -1.6, 0.1, 0.0,
                                                     5.0))
    particle_filter.estimate()


def main(args=None) -> int:
    """Run the amcl node until Ctrl-C or SIGTERM."""
    return run_node(AmclNode, 'amcl', args)


if __name__ == '__main__':
    sys.exit(main())
