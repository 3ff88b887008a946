"""
navigator: NavigateToPose for the mecanum robot (Nav2's bt_navigator, as one node).

It also does the jobs of Nav2's planner, controller and behaviour servers and of both
costmaps. The state machine is :mod:`mecanum_navigation.navigator.navigator` (pure); this
node only translates ROS messages, parameters and transforms for it.

Action servers, Nav2's types and names: ``navigate_to_pose`` (nav2_msgs/NavigateToPose),
``navigate_through_poses`` (nav2_msgs/NavigateThroughPoses: the poses one after the
other, the first that fails ends it) and ``follow_waypoints`` (nav2_msgs/FollowWaypoints:
number_of_loops, goal_index; a waypoint that fails is in missed_waypoints and ends the
route unless ``waypoint_follower.stop_on_failure`` is false); their sequencing is
:mod:`mecanum_navigation.navigator.route`. A failed goal's ``error_code`` is one of
mecanum_navigation.navigator.navigator's codes (9000 UNKNOWN ... 9107 INVALID_GOAL; e.g. 9100
GOAL_OUTSIDE_ZONE: the authorised zone's refusal), ``error_msg`` says why in words.
A new goal of any kind preempts the running one (PREEMPTED). Subscribes ``goal_pose``
(geometry_msgs/PoseStamped, what RViz's "2D Goal Pose" and Foxglove send: a navigation
without an action client, its end is logged),
``map`` (nav_msgs/OccupancyGrid, transient local) for the global costmap (static layer,
``keepout_zones``, the authorised zone, an obstacle layer from the scan unless
``global_costmap.obstacle_layer`` is false, inflation with the inscribed radius
footprint_radius_m of motor_params.yaml; rebuilt at ``global_costmap.update_frequency``,
so replanning goes round people and furniture the map lacks, as Nav2's default global
costmap), ``scan`` (sensor_msgs/LaserScan, sensor-data QoS) for both costmaps (the local
one a rolling window in ``odom_frame`` with obstacle, zone and inflation layers; the
laser's pose from TF),
``odom_topic`` (nav_msgs/Odometry, default 'odometry/filtered': the body twist for the
controller), ``/tf`` and ``/tf_static`` (map -> odom -> base_link).
Publishes ``cmd_vel_nav`` (geometry_msgs/Twist in base_link: Nav2's controller output,
for velocity_smoother; zero when a goal ends in any way), ``plan`` (nav_msgs/Path in
``global_frame``, on every (re)plan), ``global_costmap/costmap`` (OccupancyGrid, Nav2's
cost translation, latched, at ``global_costmap.publish_frequency``) and ``local_costmap/costmap``
(at ``local_costmap.publish_frequency``). The control loop runs at
``controller_frequency`` on ROS time (use_sim_time works).

Parameters: see config/nav2_params.yaml (Nav2's names, grouped controller.*, planner.*,
progress_checker.*, global_costmap.*, local_costmap.*), plus the robot parameters of
motor_params.yaml. A bad value stops the node with one FATAL line naming the key.
Set at run time (``ros2 param set /navigator controller.max_vel_x 0.3``, checked as at
start-up, see :mod:`mecanum_control.runtime_parameters`): the controller's speed limits
and goal tolerances (RUNTIME_CONTROLLER_KEYS); the controller restarts with them at the
next cycle (it finds its place on the path again). Every other parameter is read-only.

The authorised zone: ``zone_file`` (a standalone zone file, mecanum_safety.zone's
format, e.g. mecanum_safety's zones/apartment.yaml; '' = no zone), read once at start
(a malformed file
stops the node naming the file and the key). Everything outside it, and inside its
exclusions, is lethal in both costmaps before inflation (costmap.ZoneLayer, as Nav2's
keepout filter), so no plan and no local trajectory leaves it; in the local costmap the
zone is placed with the latest map -> odom on /tf (missing: the last placement is kept,
with a throttled warning). Goals outside it, or whose only route leaves it, are refused
with GOAL_OUTSIDE_ZONE.

Concurrency: single-threaded. Goals are accepted by rclpy's executor and queued; the
control-loop timer starts them, publishes their feedback and, once the navigator has an
outcome, executes the deferred goal (ServerGoalHandle.execute, as rclpy's
handle_accepted_callback allows), whose execute callback sets the terminal state and
returns the result at once. Nothing blocks or runs concurrently, so there are no locks;
the price is that a running goal reports status ACCEPTED (not EXECUTING) until it ends.
A blocking execute_callback would need a MultiThreadedExecutor and locks, and an async one
keeps the executor busy-polling (rclpy 7 re-runs a pending coroutine task every spin).
"""

from collections import deque
import dataclasses
import math
import sys
import time
from typing import Dict, Hashable, Optional

from geometry_msgs.msg import PoseStamped, Twist
from mecanum_control.angles import quaternion_from_yaw, yaw_from_quaternion
from mecanum_control.node_main import run_node
from mecanum_control.parameters import declare_robot_config, declare_typed
from mecanum_control.runtime_parameters import RuntimeParameters
from mecanum_localization.tf_listener import stamp_to_s, TransformListener
from mecanum_localization.transforms import PlanarTransform, TransformBuffer, TransformError
from mecanum_map_server.grid_messages import occupancy_grid, occupancy_map
from mecanum_map_server.map_io import OccupancyMap
from mecanum_navigation.controller.local_controller import (
    ControllerParams, LocalController, ProgressChecker)
from mecanum_navigation.costmap.costmap_2d import (
    Costmap2D, InflationLayer, KeepoutLayer, LayeredCostmap, ObstacleLayer, RollingWindow,
    StaticLayer, ZoneLayer)
from mecanum_navigation.navigator import navigator as nav
from mecanum_navigation.navigator.route import Route
from mecanum_navigation.planner.planner import GridPlanner
from mecanum_safety.zone import load_zone_file, Zone, ZoneError
from nav2_msgs.action import FollowWaypoints, NavigateThroughPoses, NavigateToPose
from nav2_msgs.msg import MissedWaypoint
from nav_msgs.msg import OccupancyGrid, Odometry, Path
import numpy as np
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import LaserScan
import yaml

#: Result code (mecanum_navigation.navigator.navigator's) -> its name (for the log).
CODE_NAMES = {getattr(nav, name): name for name in (
    'NONE', 'UNKNOWN', 'TF_ERROR', 'GOAL_OUTSIDE_ZONE', 'GOAL_IN_OBSTACLE', 'GOAL_OUTSIDE_MAP',
    'NO_VALID_PATH', 'STUCK', 'CANCELED', 'PREEMPTED', 'INVALID_GOAL')}
#: The controller parameters read from controller.* (the others come from elsewhere).
CONTROLLER_KEYS = (
    'max_vel_x', 'max_vel_y', 'max_vel_theta', 'acc_lim_x', 'acc_lim_y', 'acc_lim_theta',
    'sim_time', 'sim_granularity', 'vx_samples', 'vy_samples', 'vtheta_samples',
    'lookahead_dist', 'near_goal_distance', 'approach_time', 'max_robot_pose_search_dist',
    'xy_goal_tolerance', 'yaw_goal_tolerance', 'stateful', 'allow_unknown', 'heading_mode',
    'goal_dist_weight', 'path_dist_weight', 'heading_weight', 'obstacle_weight',
    'smoothness_weight', 'collision_margin')
#: controller.* velocity / acceleration limit -> the motor_params.yaml limit it may not exceed.
ROBOT_LIMITS = {
    'max_vel_x': 'max_velocity_x_m_s', 'max_vel_y': 'max_velocity_y_m_s',
    'max_vel_theta': 'max_angular_velocity_rad_s', 'acc_lim_x': 'max_acceleration_x_m_s2',
    'acc_lim_y': 'max_acceleration_y_m_s2', 'acc_lim_theta': 'max_angular_acceleration_rad_s2'}
#: controller.* keys settable at run time (ros2 param set).
RUNTIME_CONTROLLER_KEYS = ('max_vel_x', 'max_vel_y', 'max_vel_theta', 'xy_goal_tolerance',
                           'yaw_goal_tolerance')
WARNING_PERIOD_S = 5.0
#: Scans kept waiting for their pose (10 Hz: 0.5 s worth).
MAX_PENDING_SCANS = 5


class NavigatorNode(Node):
    """NavigateToPose action server and goal_pose listener driving the Navigator."""

    def __init__(self, **node_options):
        super().__init__('navigator', **node_options)
        self.runtime = RuntimeParameters(self)
        config = declare_robot_config(self)
        self.global_frame = self._declare('global_frame', 'map')
        self.odom_frame = self._declare('odom_frame', 'odom')
        self.base_frame = self._declare('robot_base_frame', 'base_link')
        odom_topic = self._declare('odom_topic', 'odometry/filtered')
        self.waypoints_stop_on_failure = self._declare('waypoint_follower.stop_on_failure', True)
        for name, frame in (('global_frame', self.global_frame),
                            ('odom_frame', self.odom_frame),
                            ('robot_base_frame', self.base_frame), ('odom_topic', odom_topic)):
            if not frame.strip('/'):
                raise ValueError(f'parameter {name} must not be empty')
        frequency = _positive('controller_frequency',
                              self._declare('controller_frequency', 20.0))
        self.transform_tolerance = _positive(
            'transform_tolerance', self._declare('transform_tolerance', 0.3))
        controller_params = self._controller_params(config, frequency)
        behaviour = {key: self._declare(key, default) for key, default in (
            ('replan_frequency', 1.0), ('failure_tolerance', 0.3), ('max_recoveries', 6),
            ('spin_dist', 1.57), ('max_rotational_vel', 1.0), ('backup_dist', 0.15),
            ('backup_speed', 0.1), ('wait_duration', 2.0), ('time_allowance', 10.0))}
        self.zone_file = self._declare('zone_file', '')
        zone = self._load_zone(self.zone_file)
        self.zone_layer = None if zone is None else ZoneLayer(zone)
        # The local costmap's copy is placed with map -> odom once that is known.
        self.local_zone_layer = None if zone is None else ZoneLayer(zone, frame_pose=None)
        navigator_params = _build('', nav.NavigatorParams, {
            **behaviour, 'authorised_zone': zone, 'robot_radius_m': config.footprint_radius_m})
        progress_checker = _build('progress_checker', ProgressChecker, {
            key: self._declare(f'progress_checker.{key}', default) for key, default in
            (('required_movement_radius', 0.5), ('movement_time_allowance', 10.0))})
        planner = _build('planner', GridPlanner, {
            key: self._declare(f'planner.{key}', default) for key, default in
            (('tolerance', 0.0), ('allow_unknown', False), ('cost_weight', 1.0),
             ('smooth_path', True))})
        self.inscribed_radius_m = config.footprint_radius_m
        self.keepout_layer = self._keepout_layer(self._declare('keepout_zones', [], list))
        self.static_options = {
            key: self._declare(f'global_costmap.{key}', default) for key, default in
            (('lethal_cost_threshold', 100), ('track_unknown_space', True))}
        _build('global_costmap', StaticLayer, {
            'occupancy_map': OccupancyMap(1.0, (0.0, 0.0, 0.0), np.zeros((1, 1))),
            **self.static_options})
        self.global_inflation = self._inflation('global_costmap')
        self.global_obstacle_layer = None
        if self._declare('global_costmap.obstacle_layer', True):
            self.global_obstacle_layer = _build('global_costmap', ObstacleLayer, {
                key: self._declare(f'global_costmap.{key}', default) for key, default in
                (('obstacle_max_range', 2.5), ('obstacle_min_range', 0.0),
                 ('raytrace_max_range', 3.0), ('raytrace_min_range', 0.0))})
        self.global_persistence_s = self._declare('global_costmap.observation_persistence', 2.0)
        if not (math.isfinite(self.global_persistence_s) and self.global_persistence_s >= 0.0):
            raise ValueError('parameter global_costmap.observation_persistence must be >= 0 s, '
                             f'got {self.global_persistence_s}')
        self.global_scans = deque()   # (stamp s, laser pose in map, LaserScan), oldest first
        self.global_update_period_s = 1.0 / _positive(
            'global_costmap.update_frequency',
            self._declare('global_costmap.update_frequency', 1.0))
        self.global_publish_period_s = 1.0 / _positive(
            'global_costmap.publish_frequency',
            self._declare('global_costmap.publish_frequency', 1.0))
        self.last_global_update_s = -math.inf
        self.last_global_publish_s = -math.inf
        self.local_window, self.obstacle_layer, self.local_costmap = self._local_costmap()
        self.local_update_period_s = 1.0 / _positive(
            'local_costmap.update_frequency',
            self._declare('local_costmap.update_frequency', 5.0))
        self.local_publish_period_s = 1.0 / _positive(
            'local_costmap.publish_frequency',
            self._declare('local_costmap.publish_frequency', 2.0))

        controller = LocalController(controller_params)
        self.navigator = nav.Navigator(
            navigator_params, controller,
            lambda costmap, start, goal: planner.plan(costmap, start, goal).points,
            progress_checker)
        _warm_up(planner, controller)
        self.tf_buffer = TransformBuffer()
        self.global_costmap: Optional[Costmap2D] = None
        self.global_base: Optional[Costmap2D] = None   # static + keepout + zone, not inflated
        self.global_static: Optional[Costmap2D] = None  # the base, inflated
        self.global_unzoned: Optional[Costmap2D] = None  # static + keepout, inflated
        self.pending_scans = deque(maxlen=MAX_PENDING_SCANS)
        self.odom_twist: Optional[nav.Twist2D] = None
        self.new_goals = deque()
        self.goal_handles: Dict[Hashable, object] = {}
        self.results: Dict[Hashable, nav.Outcome] = {}
        #: Route goals (NavigateThroughPoses, FollowWaypoints) by goal id: (handle, Route).
        self.routes: Dict[bytes, tuple] = {}
        self.route_legs = 0
        self.topic_goals = 0
        self.last_local_update_s = -math.inf
        self.last_local_publish_s = -math.inf
        self.pose_known = False
        self.cycle_count = 0
        self.cycle_total_s = 0.0
        self.cycle_max_s = 0.0

        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.cmd_pub = self.create_publisher(Twist, 'cmd_vel_nav', 10)
        self.plan_pub = self.create_publisher(Path, 'plan', latched)
        self.global_costmap_pub = self.create_publisher(
            OccupancyGrid, 'global_costmap/costmap', latched)
        self.local_costmap_pub = self.create_publisher(OccupancyGrid, 'local_costmap/costmap', 1)
        self.tf_listener = TransformListener(self, self.tf_buffer)
        self.map_sub = self.create_subscription(OccupancyGrid, 'map', self.on_map, latched)
        self.scan_sub = self.create_subscription(LaserScan, 'scan', self.on_scan,
                                                 qos_profile_sensor_data)
        self.odom_sub = self.create_subscription(Odometry, odom_topic, self.on_odom, 10)
        self.goal_sub = self.create_subscription(PoseStamped, 'goal_pose', self.on_goal_pose,
                                                 10)
        self.action_server = ActionServer(
            self, NavigateToPose, 'navigate_to_pose', self.on_execute,
            goal_callback=lambda _request: GoalResponse.ACCEPT,
            handle_accepted_callback=self.on_goal_accepted,
            cancel_callback=lambda _handle: CancelResponse.ACCEPT)
        self.route_servers = [ActionServer(
            self, action, name, self.on_execute_route,
            goal_callback=self.on_route_goal,
            handle_accepted_callback=self.on_route_accepted,
            cancel_callback=lambda _handle: CancelResponse.ACCEPT)
            for action, name in ((NavigateThroughPoses, 'navigate_through_poses'),
                                 (FollowWaypoints, 'follow_waypoints'))]
        self.control_timer = self.create_timer(1.0 / frequency, self.on_control_timer)
        self.get_logger().info(
            f'Navigator (Nav2 bt_navigator) started: {frequency:g} Hz control, '
            f'replanning at {navigator_params.replan_frequency:g} Hz, footprint radius '
            f'{self.inscribed_radius_m:g} m, goals in {self.global_frame}, odometry from '
            f'{self.odom_sub.topic_name}, commands on {self.cmd_pub.topic_name}')
        if zone is None:
            zone_text = ('none (zone_file empty)' if not self.zone_file
                         else f'none declared in {self.zone_file}')
        else:
            zone_text = (f'{self.zone_file} ({len(zone.include)} vertices, '
                         f'{len(zone.exclude)} exclusion(s)): plans and trajectories stay in '
                         'it')
        self.get_logger().info(f'authorised zone: {zone_text}')
        self.runtime.start()

    # --- parameters ------------------------------------------------------------------

    def _declare(self, name: str, default, kind: type = None):
        """Declare a parameter and return its value checked against the default's type."""
        return declare_typed(self, name, default, kind)

    def _controller_params(self, config, frequency: float) -> ControllerParams:
        """Read controller.* (defaults: the robot's limits) and check them against them."""
        base = ControllerParams.from_robot_config(config)

        def check(name: str, value: float) -> float:
            key = name[len('controller.'):]
            _positive(name, value)
            limit_name = ROBOT_LIMITS.get(key)
            if limit_name is not None and value > getattr(config, limit_name) + 1e-9:
                raise ValueError(f'parameter {name} ({value:g}) exceeds the robot limit '
                                 f'{limit_name} ({getattr(config, limit_name):g}, '
                                 'motor_params.yaml)')
            return value
        values = {}
        for key in CONTROLLER_KEYS:
            if key in RUNTIME_CONTROLLER_KEYS:
                values[key] = self.runtime.declare(f'controller.{key}', getattr(base, key),
                                                   check=check, kind=float)
            else:
                value = self._declare(f'controller.{key}', getattr(base, key))
                values[key] = check(f'controller.{key}', value) if key in ROBOT_LIMITS else value
        self.runtime.joint([f'controller.{key}' for key in RUNTIME_CONTROLLER_KEYS],
                           apply=self._set_controller_limits)
        values.update(controller_frequency=frequency,
                      transform_tolerance=self.transform_tolerance)
        return _build('controller', ControllerParams.from_robot_config,
                      {'config': config, **values})

    def _set_controller_limits(self, values: Dict[str, float]) -> None:
        """Restart the controller with new run-time controller.* values (the next cycle)."""
        changes = {name[len('controller.'):]: value for name, value in values.items()}
        for key in ('x', 'y'):   # min_vel_* follow max_vel_* (a mecanum base backs up)
            if f'max_vel_{key}' in changes:
                changes[f'min_vel_{key}'] = -changes[f'max_vel_{key}']
        params = dataclasses.replace(self.navigator.controller.params, **changes)
        self.navigator.controller = LocalController(params)

    def _keepout_layer(self, zones: list) -> KeepoutLayer:
        """Parse keepout_zones (Nav2 footprint strings '[[x, y], ...]') into a layer."""
        polygons = []
        for index, text in enumerate(zones):
            try:
                polygon = yaml.safe_load(text) if isinstance(text, str) else None
            except yaml.YAMLError:
                polygon = None
            if not isinstance(polygon, list):
                raise ValueError(f'parameter keepout_zones[{index}] must be a string like '
                                 f"'[[x, y], [x, y], [x, y]]' (m, {self.global_frame} frame), "
                                 f'got {text!r}')
            polygons.append(polygon)
        try:
            return KeepoutLayer(polygons)
        except ValueError as error:
            raise ValueError(f'parameter keepout_zones: {error}') from None

    @staticmethod
    def _load_zone(zone_file: str) -> Optional[Zone]:
        """Load the zone file ('' = no zone); a malformed one raises naming file and key."""
        if not zone_file or zone_file.strip() == 'unrestricted':   # no zone, on purpose
            return None
        try:
            return load_zone_file(zone_file)
        except ZoneError as error:   # names the file and the key
            raise ValueError(f'parameter zone_file: {error}') from None

    def _inflation(self, group: str) -> InflationLayer:
        """Read group.inflation_radius and cost_scaling_factor into an InflationLayer."""
        return _build(group, InflationLayer, {
            'inscribed_radius': self.inscribed_radius_m,
            'inflation_radius': self._declare(f'{group}.inflation_radius', 0.5),
            'cost_scaling_factor': self._declare(f'{group}.cost_scaling_factor', 4.0)})

    def _local_costmap(self):
        """Read local_costmap.* and build the rolling window and its layers."""
        size = {key: _positive(f'local_costmap.{key}',
                               self._declare(f'local_costmap.{key}', default))
                for key, default in (('width', 3.0), ('height', 3.0), ('resolution', 0.05))}
        window = RollingWindow(size['width'], size['height'], size['resolution'])
        obstacles = _build('local_costmap', ObstacleLayer, {
            key: self._declare(f'local_costmap.{key}', default) for key, default in
            (('obstacle_max_range', 2.5), ('obstacle_min_range', 0.0),
             ('raytrace_max_range', 3.0), ('raytrace_min_range', 0.0))})
        zone = [] if self.local_zone_layer is None else [self.local_zone_layer]
        layered = LayeredCostmap(window.costmap,
                                 [obstacles, *zone, self._inflation('local_costmap')])
        return window, obstacles, layered

    # --- inputs ----------------------------------------------------------------------

    def on_map(self, msg: OccupancyGrid) -> None:
        """Rebuild the global costmap from a new map and publish it (latched)."""
        frame = msg.header.frame_id.lstrip('/')
        if frame and frame != self.global_frame:
            self.get_logger().warning(f'ignoring a map in frame {frame!r}: expected '
                                      f'{self.global_frame!r}', throttle_duration_sec=5.0)
            return
        try:
            occupancy = occupancy_map(msg)
            costmap = Costmap2D.like_map(occupancy)
        except ValueError as error:
            self.get_logger().warning(f'ignoring a map: {error}', throttle_duration_sec=5.0)
            return
        static = StaticLayer(occupancy, **self.static_options)
        LayeredCostmap(costmap, [static, self.keepout_layer]).update()
        unzoned = None
        if self.zone_layer is not None:
            unzoned = costmap.copy()
            self.global_inflation.update(unzoned)
            self.zone_layer.update(costmap)
        self.global_base = costmap
        self.global_static = costmap.copy()
        self.global_inflation.update(self.global_static)
        self.global_unzoned = unzoned
        self.global_scans.clear()
        self._update_global_costmap(-math.inf)
        self.last_global_publish_s = -math.inf
        zone_text = '' if self.zone_layer is None else ', outside the authorised zone lethal'
        self.get_logger().info(
            f'global costmap: {costmap.size_x} x {costmap.size_y} cells at '
            f'{costmap.resolution_m:g} m from the map, {len(self.keepout_layer.polygons)} '
            f'keepout zone(s){zone_text}')

    def _update_global_costmap(self, now_s: float) -> None:
        """
        Rebuild the global costmap: static + keepout + zone, recent scans, inflation.

        Only the scans of the last observation_persistence seconds mark (Nav2's
        observation persistence, applied to a layer rebuilt each time): a person who
        walked on leaves no trail of obstacles behind.
        """
        if self.global_obstacle_layer is None:
            self.global_costmap = self.global_static
            return
        while self.global_scans and self.global_scans[0][0] < now_s - self.global_persistence_s:
            self.global_scans.popleft()
        layer = self.global_obstacle_layer
        layer.clear()
        for _, sensor, msg in self.global_scans:
            layer.add_scan(sensor.x, sensor.y, sensor.yaw, msg.ranges, msg.angle_min,
                           msg.angle_increment, msg.range_min, msg.range_max)
        costmap = self.global_base.copy()
        layer.update(costmap)
        self.global_inflation.update(costmap)
        self.global_costmap = costmap

    def _add_scan(self, layer: ObstacleLayer, frame_to: str, msg: LaserScan) -> int:
        """Buffer a scan in layer, seen from the laser's pose in frame_to at its stamp."""
        sensor = self.tf_buffer.lookup(frame_to, msg.header.frame_id.lstrip('/'),
                                       stamp_to_s(msg.header.stamp))
        return layer.add_scan(sensor.x, sensor.y, sensor.yaw, msg.ranges, msg.angle_min,
                              msg.angle_increment, msg.range_min, msg.range_max)

    def on_scan(self, msg: LaserScan) -> None:
        """Queue a scan until the laser's pose at its time is known (tf2 MessageFilter)."""
        self.pending_scans.append(msg)
        self._process_scans()

    def _process_scans(self) -> None:
        """
        Put the queued scans, oldest first, into both costmaps once their poses are known.

        A scan waits until odom -> laser is known at its stamp (the EKF publishes after
        the scan is taken): the newest pose instead would put a scan taken while turning
        at 1 rad/s 0.1 rad askew, marking phantom walls 0.25 m off at 2.5 m. A scan still
        unplaced transform_tolerance after its stamp is dropped, as Nav2's MessageFilter
        drops it.
        """
        now_s = self.get_clock().now().nanoseconds * 1e-9
        while self.pending_scans:
            msg = self.pending_scans[0]
            try:
                ignored = self._add_scan(self.obstacle_layer, self.odom_frame, msg)
            except TransformError as error:
                if now_s <= stamp_to_s(msg.header.stamp) + self.transform_tolerance:
                    return   # its pose may still come
                self.pending_scans.popleft()
                self.get_logger().warning(f'ignoring a scan: {error}',
                                          throttle_duration_sec=WARNING_PERIOD_S)
                continue
            except ValueError as error:
                self.pending_scans.popleft()
                self.get_logger().warning(f'ignoring a scan: {error}',
                                          throttle_duration_sec=WARNING_PERIOD_S)
                continue
            self.pending_scans.popleft()
            self._report_ignored(ignored, msg)
            if self.global_obstacle_layer is not None and self.global_base is not None:
                try:
                    self.global_scans.append((
                        stamp_to_s(msg.header.stamp),
                        self.tf_buffer.lookup(self.global_frame, msg.header.frame_id.lstrip('/'),
                                              stamp_to_s(msg.header.stamp)), msg))
                except TransformError:
                    pass   # no map -> odom at that time yet: the local costmap has it

    def _report_ignored(self, ignored: int, msg: LaserScan) -> None:
        """Warn (throttled) about ranges that could not be used."""
        if ignored:
            self.get_logger().warning(
                f'scan: {ignored} of {len(msg.ranges)} ranges unusable (NaN, -inf or below '
                'range_min), ignored', throttle_duration_sec=WARNING_PERIOD_S)

    def on_odom(self, msg: Odometry) -> None:
        """Keep the body twist of the latest odometry (ignored when not finite)."""
        twist = msg.twist.twist
        values = (twist.linear.x, twist.linear.y, twist.angular.z)
        if all(math.isfinite(v) for v in values):
            self.odom_twist = values
        else:
            self.get_logger().warning(f'ignoring odometry with a non-finite twist {values}',
                                      throttle_duration_sec=WARNING_PERIOD_S)

    def on_goal_accepted(self, goal_handle) -> None:
        """Queue an accepted action goal; the control loop starts it (deferred execution)."""
        goal_id = bytes(goal_handle.goal_id.uuid)
        self.goal_handles[goal_id] = goal_handle
        self.new_goals.append((goal_id, goal_handle.request.pose))

    def on_goal_pose(self, msg: PoseStamped) -> None:
        """Queue a goal from goal_pose (RViz): a navigation without an action client."""
        self.topic_goals += 1
        self.new_goals.append((('goal_pose', self.topic_goals), msg))

    def _goal_in_map(self, msg: PoseStamped):
        """Return ((x, y, yaw) in global_frame, why it is invalid or '')."""
        p, q = msg.pose.position, msg.pose.orientation
        pose = (p.x, p.y, yaw_from_quaternion(q.x, q.y, q.z, q.w))
        norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
        if math.isfinite(norm) and norm < 1e-6:
            return pose, 'goal orientation is a zero quaternion (not a rotation)'
        frame = msg.header.frame_id.lstrip('/') or self.global_frame
        if frame == self.global_frame:
            return pose, ''
        try:
            transform = self.tf_buffer.lookup(self.global_frame, frame)
        except TransformError as error:
            return pose, (f'cannot transform the goal from frame {frame!r} to '
                          f'{self.global_frame!r}: {error}')
        moved = transform.compose(PlanarTransform(*pose)) if all(
            math.isfinite(v) for v in pose) else None
        return ((moved.x, moved.y, moved.yaw) if moved else pose), ''

    def _tick_inputs(self, now_s: float) -> nav.TickInputs:
        """Look up the robot's poses, update the local costmap when due; return the inputs."""
        robot_in_map = robot_in_odom = None
        error = ''
        try:
            robot_in_odom = self.tf_buffer.lookup(self.odom_frame, self.base_frame)
            robot_in_map = self.tf_buffer.lookup(self.global_frame, self.base_frame)
        except TransformError as lookup_error:
            error = str(lookup_error)
        self._process_scans()
        if self.global_base is not None and \
                now_s - self.last_global_update_s >= self.global_update_period_s - 1e-9:
            self._update_global_costmap(now_s)
            self.last_global_update_s = now_s
        # The costmaps go out only to a subscriber (a viewer, a recording): a grid of
        # every cell a second for nobody cost a conversion and a copy each time.
        if self.global_costmap is not None and \
                now_s - self.last_global_publish_s >= self.global_publish_period_s - 1e-9 \
                and self.global_costmap_pub.get_subscription_count() > 0:
            self.global_costmap_pub.publish(occupancy_grid(
                self.global_costmap.to_occupancy_map(), self.global_frame,
                self.get_clock().now().to_msg()))
            self.last_global_publish_s = now_s
        if robot_in_odom is not None and \
                now_s - self.last_local_update_s >= self.local_update_period_s - 1e-9:
            self.local_window.move_to(robot_in_odom.x, robot_in_odom.y)
            self._place_local_zone()
            self.local_costmap.update()
            self.last_local_update_s = now_s
        if self.last_local_update_s > -math.inf and \
                now_s - self.last_local_publish_s >= self.local_publish_period_s - 1e-9 \
                and self.local_costmap_pub.get_subscription_count() > 0:
            self.local_costmap_pub.publish(occupancy_grid(
                self.local_costmap.costmap.to_occupancy_map(), self.odom_frame,
                self.get_clock().now().to_msg()))
            self.last_local_publish_s = now_s
        if robot_in_map is not None and not self.pose_known:
            self.pose_known = True
            self.get_logger().info(
                f'robot pose known: ({robot_in_map.x:.2f}, {robot_in_map.y:.2f}, '
                f'{robot_in_map.yaw:.2f}) in {self.global_frame}; ready for goals')
        # Fresh when odom -> base_link is known at now - tolerance (else it is older).
        fresh = self.tf_buffer.can_transform(self.odom_frame, self.base_frame,
                                             now_s - self.transform_tolerance)
        return nav.TickInputs(
            now_s=now_s,
            robot_in_map=None if robot_in_map is None else _pose(robot_in_map),
            robot_in_odom=None if robot_in_odom is None else _pose(robot_in_odom),
            local_costmap=self.local_costmap.costmap, global_costmap=self.global_costmap,
            static_costmap=self.global_static,
            twist=self.odom_twist, pose_age_s=0.0 if fresh else 2.0 * self.transform_tolerance,
            pose_error=error, obstacle_points=self.obstacle_layer.latest_points,
            unzoned_costmap=self.global_unzoned)

    def _place_local_zone(self) -> None:
        """Place the zone in the local costmap (odom) with the latest map -> odom."""
        layer = self.local_zone_layer
        if layer is None:
            return
        try:
            odom_in_map = self.tf_buffer.lookup(self.global_frame, self.odom_frame)
        except TransformError as error:
            kept = ('keeps its last placement' if layer.frame_pose is not None
                    else 'is not in it yet')
            self.get_logger().warning(
                f'local costmap: no {self.global_frame} -> {self.odom_frame} transform '
                f'({error}); the authorised zone {kept}',
                throttle_duration_sec=WARNING_PERIOD_S)
            return
        layer.set_frame_pose(odom_in_map.x, odom_in_map.y, odom_in_map.yaw)

    # --- the control loop ----------------------------------------------------------

    def on_control_timer(self) -> None:
        """Start new goals, handle cancels, tick the navigator and publish what it decided."""
        started = time.perf_counter()
        now = self.get_clock().now()
        now_s = now.nanoseconds * 1e-9
        while self.new_goals:
            goal_id, msg = self.new_goals.popleft()
            pose, invalid = self._goal_in_map(msg)
            self.navigator.submit(goal_id, pose, invalid)
        for goal_id, handle in self.goal_handles.items():
            if handle.is_cancel_requested:
                self.navigator.cancel(goal_id)
        for handle, route in self.routes.values():
            active = self.navigator.active_goal_id
            if handle.is_cancel_requested and _is_leg(active) and active[1] == bytes(
                    handle.goal_id.uuid):
                self.navigator.cancel(active)
        out = self.navigator.tick(self._tick_inputs(now_s))
        if out.clear_local_costmap:   # Nav2's recovery clears both costmaps' obstacles
            self.obstacle_layer.clear()
            self.last_local_update_s = -math.inf
            if self.global_obstacle_layer is not None:
                self.global_scans.clear()
                self.last_global_update_s = -math.inf
        if out.new_plan is not None:
            self._publish_plan(out.new_plan, now)
        if out.twist is not None:
            self.cmd_pub.publish(_twist(out.twist))
        if out.feedback is not None:
            self._publish_feedback(out.feedback, now)
        for event in out.events:
            self.get_logger().info(event)
        for warning in out.warnings:
            self.get_logger().warning(warning, throttle_duration_sec=WARNING_PERIOD_S)
        for outcome in out.outcomes:
            self._finish(outcome)
        elapsed = time.perf_counter() - started
        self.cycle_count += 1
        self.cycle_total_s += elapsed
        self.cycle_max_s = max(self.cycle_max_s, elapsed)

    def _finish(self, outcome: nav.Outcome) -> None:
        """Log a goal's end and, for an action goal, execute it to send its result."""
        name = CODE_NAMES.get(outcome.code, str(outcome.code))
        if _is_leg(outcome.goal_id):
            self._leg_ended(outcome, name)
            return
        source = 'goal_pose goal' if isinstance(outcome.goal_id, tuple) else 'goal'
        self._log_end(f'{source} ended: {name}: {outcome.message}', outcome.code)
        handle = self.goal_handles.pop(outcome.goal_id, None)
        if handle is not None:
            self.results[outcome.goal_id] = outcome
            handle.execute()

    def _log_end(self, text: str, code: int) -> None:
        """Log a goal's (or a leg's) end: info when it succeeded, else a warning."""
        if code == nav.NONE:
            self.get_logger().info(text)
        else:
            self.get_logger().warning(text)

    # --- routes: NavigateThroughPoses, FollowWaypoints -----------------------------

    def on_route_goal(self, request) -> GoalResponse:
        """Accept a route goal that has poses (and, for FollowWaypoints, a valid start)."""
        if not request.poses:
            self.get_logger().warning('route goal refused: it has no poses')
            return GoalResponse.REJECT
        if getattr(request, 'goal_index', 0) >= len(request.poses):
            self.get_logger().warning(
                f'waypoints goal refused: goal_index {request.goal_index} is not one of its '
                f'{len(request.poses)} waypoints')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def on_route_accepted(self, goal_handle) -> None:
        """Start a route: its first pose is queued as a leg (the control loop starts it)."""
        request = goal_handle.request
        waypoints = isinstance(request, FollowWaypoints.Goal)
        route = Route(len(request.poses),
                      start_index=request.goal_index if waypoints else 0,
                      loops=request.number_of_loops if waypoints else 0,
                      stop_on_failure=self.waypoints_stop_on_failure if waypoints else True)
        key = bytes(goal_handle.goal_id.uuid)
        self.routes[key] = (goal_handle, route)
        self.get_logger().info(
            f'{"waypoints" if waypoints else "through-poses"} goal: {route.count} poses'
            + (f' from {route.start_index}, {route.loops} extra loop(s)' if waypoints else ''))
        self._queue_leg(key)

    def _queue_leg(self, key: bytes) -> None:
        handle, route = self.routes[key]
        self.route_legs += 1
        self.new_goals.append((('route', key, route.index, self.route_legs),
                               handle.request.poses[route.index]))

    def _leg_ended(self, outcome: nav.Outcome, name: str) -> None:
        """Take the end of a route's leg: queue the next pose, or end the route."""
        key, index = outcome.goal_id[1], outcome.goal_id[2]
        handle, route = self.routes[key]
        self._log_end(f'route pose {index + 1}/{route.count} ended: {name}: '
                      f'{outcome.message}', outcome.code)
        if outcome.code in (nav.CANCELED, nav.PREEMPTED):
            route.abort(outcome.code, outcome.message)
        elif route.leg_ended(outcome.code, outcome.message) is not None:
            self._queue_leg(key)
            return
        handle.execute()

    def on_execute_route(self, goal_handle):
        """Set a finished route's terminal state; return its result."""
        key = bytes(goal_handle.goal_id.uuid)
        _, route = self.routes.pop(key)
        waypoints = isinstance(goal_handle.request, FollowWaypoints.Goal)
        result = (FollowWaypoints if waypoints else NavigateThroughPoses).Result()
        result.error_code, result.error_msg = route.error_code, route.error_msg
        if waypoints:
            for index, code, _message in route.missed:
                missed = MissedWaypoint(index=index, error_code=code)
                missed.goal = goal_handle.request.poses[index]
                result.missed_waypoints.append(missed)
        _end_goal(goal_handle, route.error_code)
        self.get_logger().info(
            f'route ended: {CODE_NAMES.get(route.error_code, route.error_code)}'
            + (f', {len(route.missed)} waypoint(s) missed' if waypoints else ''))
        return result

    def on_execute(self, goal_handle) -> NavigateToPose.Result:
        """Set the terminal state of a goal whose outcome is known; return its result."""
        outcome = self.results.pop(bytes(goal_handle.goal_id.uuid), None)
        result = NavigateToPose.Result()
        if outcome is None:  # not started by the control loop: cannot happen
            result.error_code = nav.UNKNOWN
            result.error_msg = 'goal executed without an outcome'
            goal_handle.abort()
            return result
        result.error_code = outcome.code
        result.error_msg = outcome.message
        _end_goal(goal_handle, outcome.code)
        return result

    # --- outputs ---------------------------------------------------------------------

    def _publish_plan(self, points, now) -> None:
        """Publish a plan as a nav_msgs/Path, each pose facing along it, the last the goal."""
        goal = self.navigator.active_goal_pose
        path = Path()
        path.header.frame_id = self.global_frame
        path.header.stamp = now.to_msg()
        for index, (x, y) in enumerate(points):
            if index + 1 < len(points):
                yaw = math.atan2(points[index + 1][1] - y, points[index + 1][0] - x)
            else:
                yaw = goal[2] if goal is not None else 0.0
            pose = PoseStamped()
            pose.header = path.header
            pose.pose.position.x, pose.pose.position.y = float(x), float(y)
            q = pose.pose.orientation
            q.x, q.y, q.z, q.w = quaternion_from_yaw(yaw)
            path.poses.append(pose)
        self.plan_pub.publish(path)

    def _publish_feedback(self, feedback: nav.Feedback, now) -> None:
        """Publish the feedback of an action goal (goal_pose goals have no client)."""
        route = None
        if _is_leg(feedback.goal_id):
            handle, route = self.routes.get(feedback.goal_id[1], (None, None))
        else:
            handle = self.goal_handles.get(feedback.goal_id)
        if handle is None:
            return
        if isinstance(handle.request, FollowWaypoints.Goal):
            handle.publish_feedback(FollowWaypoints.Feedback(current_waypoint=route.index))
            return
        msg = (NavigateToPose.Feedback() if route is None
               else NavigateThroughPoses.Feedback(number_of_poses_remaining=route.poses_remaining))
        msg.current_pose.header.frame_id = self.global_frame
        msg.current_pose.header.stamp = now.to_msg()
        x, y, yaw = feedback.pose_in_map
        msg.current_pose.pose.position.x, msg.current_pose.pose.position.y = x, y
        q = msg.current_pose.pose.orientation
        q.x, q.y, q.z, q.w = quaternion_from_yaw(yaw)
        msg.navigation_time = Duration(seconds=feedback.navigation_time_s).to_msg()
        msg.estimated_time_remaining = Duration(
            seconds=feedback.estimated_time_remaining_s).to_msg()
        msg.number_of_recoveries = feedback.number_of_recoveries
        msg.distance_remaining = float(feedback.distance_remaining_m)
        handle.publish_feedback(msg)

    def close(self) -> None:
        """Stop the robot if it was navigating and log the control cycle time."""
        if self.navigator.active_goal_id is not None:
            self.cmd_pub.publish(Twist())
        if self.cycle_count:
            self.get_logger().info(
                f'control cycle: {1e3 * self.cycle_total_s / self.cycle_count:.1f} ms mean, '
                f'{1e3 * self.cycle_max_s:.1f} ms max over {self.cycle_count} cycles')


def _warm_up(planner: GridPlanner, controller: LocalController) -> None:
    """
    Run each computation once on a small grid, so numba loads its compiled loops now.

    Otherwise the first plan, scan and inflation would each stall a control cycle (by
    up to half a second on a loaded machine).
    """
    costmap = Costmap2D(20, 20, 0.05, -0.5, -0.5)
    obstacles = ObstacleLayer()
    obstacles.add_scan(0.0, 0.0, 0.0, [0.3, math.inf], 0.0, 1.0)
    LayeredCostmap(costmap, [obstacles, InflationLayer(0.1)]).update()
    costmap.costs.fill(0)
    planner.plan(costmap, (-0.3, -0.3), (0.3, 0.3))
    controller.compute_velocity((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), [(0.0, 0.0), (0.2, 0.0, 0.0)],
                                costmap)
    controller.reset()


def _end_goal(goal_handle, code: int) -> None:
    """Set an action goal's terminal state from its result code."""
    if code == nav.NONE:
        goal_handle.succeed()
    elif code == nav.CANCELED and goal_handle.is_cancel_requested:
        goal_handle.canceled()
    else:
        goal_handle.abort()


def _is_leg(goal_id) -> bool:
    """Whether a navigator goal id is a route's leg: ('route', route key, index, n)."""
    return isinstance(goal_id, tuple) and goal_id[0] == 'route'


def _pose(transform: PlanarTransform) -> nav.Pose2D:
    """Return a transform as an (x, y, yaw) pose."""
    return (transform.x, transform.y, transform.yaw)


def _twist(values: nav.Twist2D) -> Twist:
    """Return a body twist (vx, vy, wz) as a geometry_msgs/Twist."""
    msg = Twist()
    msg.linear.x, msg.linear.y, msg.angular.z = (float(v) for v in values)
    return msg


def _positive(name: str, value: float) -> float:
    """Return value if finite and > 0, else raise ValueError naming the parameter."""
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f'parameter {name} must be finite and > 0, got {value!r}')
    return value


def _build(group: str, factory, kwargs: dict):
    """Call factory(**kwargs); a ValueError is re-raised naming the parameter key."""
    try:
        return factory(**kwargs)
    except ValueError as error:
        text = str(error)
        prefix = f'{group}.' if group else ''
        if text.split(' ', 1)[0] in kwargs:
            raise ValueError(f'parameter {prefix}{text}') from None
        raise ValueError(f'{group or "navigator"} parameters: {text}') from None


def main(args=None) -> int:
    """Run the navigator node until Ctrl-C or SIGTERM."""
    return run_node(NavigatorNode, 'navigator', args)


if __name__ == '__main__':
    sys.exit(main())
