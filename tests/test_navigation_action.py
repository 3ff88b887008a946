"""
Integration: the navigator's NavigateToPose action and goal_pose, in real processes.

A light world on simulated time: map_server serving a 6 m x 4 m room written here (a
wall segment, a closed box), robot_simulation's kinematic simulation_node obeying the
navigator's cmd_vel_nav directly (odom -> base_link on /tf), and the navigator with
config/nav2_params.yaml (odometry from the simulator's odom, an L-shaped authorised
zone in a zone file, zone_file). The test node drives /clock, publishes map -> odom (x 1,
y 1, yaw 0.3: the robot
starts at map (1, 1, 0.3)) and base_link -> laser on /tf_static, and empty laser scans
(+inf: nothing seen).
"""

import math
from pathlib import Path
import re
import shutil
import subprocess
import threading
import time

from action_msgs.msg import GoalStatus
from geometry_msgs.msg import PoseStamped, TransformStamped, Twist
from mecanum_bringup.system_description import load_system
from mecanum_control.angles import quaternion_from_yaw, wrap_angle, yaw_from_quaternion
from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_localization.transforms import PlanarTransform
from mecanum_map_server.map_io import OccupancyMap, save_map
from mecanum_navigation.navigator import navigator as R
from mecanum_safety.zone import make_zone, zone_file_text
from nav2_msgs.action import FollowWaypoints, NavigateThroughPoses, NavigateToPose
from nav_msgs.msg import OccupancyGrid, Odometry, Path as PathMsg
import numpy as np
import pytest
from rclpy.action import ActionClient
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import LaserScan
from tf2_msgs.msg import TFMessage
import yaml

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
NAV2_PARAMS = yaml.safe_load((REPO / 'src/mecanum_navigation/config/nav2_params.yaml')
                             .read_text())['navigator']['ros__parameters']
XY_TOLERANCE = NAV2_PARAMS['controller']['xy_goal_tolerance']
YAW_TOLERANCE = NAV2_PARAMS['controller']['yaw_goal_tolerance']
ROBOT = load_robot_config(default_config_path())
MAP_TO_ODOM = PlanarTransform(1.0, 1.0, 0.3)
RES = 0.05
# Everything but the top right corner (x > 4.5, y > 2.5), map frame.
ZONE = make_zone([(0.0, 0.0), (6.0, 0.0), (6.0, 2.5), (4.5, 2.5), (4.5, 4.0), (0.0, 4.0)])


def write_room(directory: Path) -> Path:
    """
    Write the room's map (YAML + PGM) into directory; return the YAML's path.

    6 m x 4 m at 0.05 m, walls around, a wall x 3.0..3.05 from y 0 to 2.5, and a closed
    box (outline x 4.5..5.55, y 0.5..1.55) whose free inside cannot be reached.
    """
    data = np.zeros((80, 120), dtype=np.int8)
    data[[0, -1], :] = 100
    data[:, [0, -1]] = 100
    data[:50, 60] = 100                          # the wall segment
    data[10:31, [90, 110]] = 100                 # the box's sides ...
    data[[10, 30], 90:111] = 100                 # ... and its bottom and top
    save_map(OccupancyMap(RES, (0.0, 0.0, 0.0), data), directory / 'room.yaml')
    return directory / 'room.yaml'


def write_launch(directory: Path, map_yaml: Path) -> Path:
    """
    Write the test system's launch file (map_server, simulation_node, navigator).

    The navigator's overrides go in a file of their own with a `navigator:` section,
    after nav2_params.yaml: rcl lets a node's own section win over `-p` (`/**`) values.
    """
    zone_file = directory / 'zone.yaml'
    zone_file.write_text(zone_file_text(ZONE))
    overrides = directory / 'navigator_overrides.yaml'
    overrides.write_text(yaml.safe_dump({'navigator': {'ros__parameters': {
        'odom_topic': 'odom', 'zone_file': str(zone_file)}}}))
    launch = {'launch': [
        {'node': {'pkg': 'mecanum_map_server', 'exec': 'map_server', 'name': 'map_server',
                  'param': [{'name': 'yaml_filename', 'value': str(map_yaml)},
                            {'name': 'use_sim_time', 'value': True}]}},
        {'node': {'pkg': 'robot_simulation', 'exec': 'simulation_node',
                  'name': 'robot_simulation',
                  'param': [{'name': 'use_sim_time', 'value': True}],
                  'remap': [{'from': 'cmd_vel', 'to': 'cmd_vel_nav'}]}},
        {'node': {'pkg': 'mecanum_navigation', 'exec': 'navigator', 'name': 'navigator',
                  'param': [
                      {'from': '$(find-pkg-share mecanum_control)/config/motor_params.yaml'},
                      {'from': '$(find-pkg-share mecanum_navigation)/config/costmap_common.yaml'},
                      {'from': '$(find-pkg-share mecanum_navigation)/config/planner_params.yaml'},
                      {'from': '$(find-pkg-share mecanum_navigation)/config/nav2_params.yaml'},
                      {'from': str(overrides)},
                      {'name': 'use_sim_time', 'value': True}]}},
    ]}
    path = directory / 'navigation_test.launch.yaml'
    path.write_text(yaml.safe_dump(launch, sort_keys=False))
    return path


def transform(parent, child, x, y, yaw):
    """Return a TransformStamped (planar)."""
    msg = TransformStamped()
    msg.header.frame_id, msg.child_frame_id = parent, child
    msg.transform.translation.x, msg.transform.translation.y = x, y
    q = msg.transform.rotation
    q.x, q.y, q.z, q.w = quaternion_from_yaw(yaw)
    return msg


class Scanner:
    """
    Publishes scans from the laser at 10 Hz on the test clock: +inf (nothing seen) ...

    ... except the circles in `circles` ((x, y, radius) in map, which the map lacks, like
    a person), seen from the robot's pose that `robot` (a function, map frame) gives.
    """

    def __init__(self, test_node):
        """Create the publisher and start publishing."""
        self.test_node = test_node
        self.publisher = test_node.node.create_publisher(LaserScan, 'scan', 10)
        self.stop = threading.Event()
        self.circles = []
        self.robot = None
        threading.Thread(target=self._run, daemon=True).start()

    def ranges(self, angles):
        """Return the distance (m) to the circles along each beam (laser frame angles)."""
        ranges = np.full(angles.size, math.inf)
        if not self.circles or self.robot is None:
            return ranges
        x, y, yaw = self.robot()
        laser = PlanarTransform(x, y, yaw).compose(PlanarTransform(
            ROBOT.lidar_mount_x_m, ROBOT.lidar_mount_y_m, ROBOT.lidar_mount_yaw_rad))
        dx, dy = np.cos(angles + laser.yaw), np.sin(angles + laser.yaw)
        for cx, cy, radius in self.circles:
            ox, oy = cx - laser.x, cy - laser.y
            along = dx * ox + dy * oy
            across2 = ox * ox + oy * oy - along ** 2
            hit = (along > 0.0) & (across2 <= radius ** 2)
            distance = along - np.sqrt(np.maximum(radius ** 2 - across2, 0.0))
            ranges = np.where(hit & (distance < ranges), distance, ranges)
        return ranges

    def _run(self):
        while not self.stop.wait(0.1):
            msg = LaserScan()
            msg.header.frame_id = 'laser'
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(self.test_node.clock_ns,
                                                                    10 ** 9)
            msg.angle_min, msg.angle_max = -math.pi, math.pi - 2 * math.pi / 360
            msg.angle_increment = 2 * math.pi / 360
            msg.range_min, msg.range_max = 0.1, 8.0
            angles = msg.angle_min + msg.angle_increment * np.arange(360)
            try:
                msg.ranges = self.ranges(angles).tolist()
            except AssertionError:   # no odometry yet
                msg.ranges = [math.inf] * 360
            try:
                self.publisher.publish(msg)
            except Exception:  # noqa: B902 - the test node shut down
                return


def wait_future(future, timeout=30.0):
    """Wait for an rclpy future (the test node spins in its own thread); return its result."""
    deadline = time.monotonic() + timeout
    while not future.done():
        assert time.monotonic() < deadline, 'no answer in time'
        time.sleep(0.02)
    return future.result()


class Navigation:
    """The test's view of the system: an action client, the robot's pose, the commands."""

    def __init__(self, test_node):
        """Create the client and the recorders."""
        self.test_node = test_node
        self.client = ActionClient(test_node.node, NavigateToPose, 'navigate_to_pose')
        self.odom = test_node.record(Odometry, 'odom')
        self.commands = test_node.record(Twist, 'cmd_vel_nav')
        self.goal_pub = test_node.node.create_publisher(PoseStamped, 'goal_pose', 10)

    def send(self, x, y, yaw, frame='map'):
        """Send a goal; return (goal handle, its feedback list, its result future)."""
        goal = NavigateToPose.Goal()
        goal.pose = pose_stamped(x, y, yaw, frame)
        feedback = []
        handle = wait_future(self.client.send_goal_async(
            goal, feedback_callback=lambda msg: feedback.append(msg.feedback)))
        assert handle.accepted
        return handle, feedback, handle.get_result_async()

    def robot(self):
        """Return the robot's (x, y, yaw) in map from the simulator's latest odometry."""
        msg = self.odom.latest()
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        pose = MAP_TO_ODOM.compose(PlanarTransform(
            p.x, p.y, yaw_from_quaternion(q.x, q.y, q.z, q.w)))
        return pose.x, pose.y, pose.yaw


def pose_stamped(x, y, yaw, frame='map'):
    """Return a PoseStamped."""
    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.pose.position.x, msg.pose.position.y = x, y
    q = msg.pose.orientation
    q.x, q.y, q.z, q.w = quaternion_from_yaw(yaw)
    return msg


def is_zero(twist):
    """Tell whether a Twist commands nothing."""
    return (twist.linear.x, twist.linear.y, twist.angular.z) == (0.0, 0.0, 0.0)


def wait_until(predicate, timeout=30.0, what='condition'):
    """Poll predicate until it is true."""
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f'{what}: not within {timeout} s'
        time.sleep(0.02)


@pytest.fixture
def navigation(start_system, test_node, tmp_path):
    """Start the test system and wait until the navigator has a map and the robot's pose."""
    test_node.start_clock()
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    static = test_node.node.create_publisher(TFMessage, '/tf_static', latched)
    static.publish(TFMessage(transforms=[
        transform('map', 'odom', MAP_TO_ODOM.x, MAP_TO_ODOM.y, MAP_TO_ODOM.yaw),
        transform('base_link', 'laser', ROBOT.lidar_mount_x_m, ROBOT.lidar_mount_y_m,
                  ROBOT.lidar_mount_yaw_rad)]))
    scanner = Scanner(test_node)
    local_costmaps = test_node.record(OccupancyGrid, 'local_costmap/costmap')
    system = start_system(str(write_launch(tmp_path, write_room(tmp_path))))
    system.wait_for_line(r'\[navigator\].*odometry from /odom, commands on /cmd_vel_nav',
                         timeout=40.0)
    system.wait_for_line(r'\[navigator\].*global costmap: 120 x 80 cells')
    system.wait_for_line(r'\[navigator\].*robot pose known: \(1.00, 1.00, 0.30\) in map')
    local_costmaps.wait_for(lambda msg: msg.header.frame_id == 'odom', timeout=20.0)
    navigation = Navigation(test_node)
    assert navigation.client.wait_for_server(timeout_sec=20.0)
    navigation.odom.wait_for(lambda msg: True)
    scanner.robot = navigation.robot
    navigation.scanner = scanner
    navigation.local_costmaps = local_costmaps
    yield system, navigation
    scanner.stop.set()
    del static
    print(system.output())   # shown by pytest when the test failed


def test_bad_goals_are_refused_and_the_zone_is_lethal_in_both_costmaps(
        navigation, test_node):
    """
    Goal in a wall, outside the zone or at its border, off the map, unreachable, NaN, frame.

    (4.4, 3.0) is 0.1 m from the zone's border x = 4.5: the footprint would cross it.
    The robot stays. The zone file's zone is keepout in the global costmap (map) and
    the local one (odom). Global: the cell at (5.3, 3.3), free on the map but in the
    corner the zone leaves out, is lethal (100), as is the map's wall cell (3.02, 1.0);
    (2.0, 2.0) is free (0). Local: the scans see nothing, so only the zone can make a
    lethal cell. The window is 3 m wide round the robot at map (1, 1), and map -> odom
    is (1, 1, 0.3): map (-0.3, 1.0), outside the zone (x < 0), is odom (-1.3 cos 0.3,
    1.3 sin 0.3) = (-1.242, 0.384), inside the window, and lethal; map (1.5, 1.5), odom
    (0.5 cos 0.3 + 0.5 sin 0.3, -0.5 sin 0.3 + 0.5 cos 0.3) = (0.626, 0.330), is free.
    """
    system, nav = navigation
    start = nav.robot()
    cases = [
        ((3.02, 1.0, 0.0, 'map'), R.GOAL_IN_OBSTACLE, r'goal \(3.02, 1.00\) is in an obstacle'),
        ((5.3, 3.3, 0.0, 'map'), R.GOAL_OUTSIDE_ZONE, 'outside the authorised zone'),
        ((4.4, 3.0, 0.0, 'map'), R.GOAL_OUTSIDE_ZONE,
         r"goal \(4.40, 3.00\) is within 0.2 m of the authorised zone's border"),
        ((7.0, 1.0, 0.0, 'map'), R.GOAL_OUTSIDE_MAP,
         r'outside the map \(x 0.00..6.00, y 0.00..4.00 m\)'),
        ((5.0, 1.0, 0.0, 'map'), R.NO_VALID_PATH, 'no valid path to goal.*not reachable'),
        ((math.nan, 1.0, 0.0, 'map'), R.INVALID_GOAL, 'goal pose is not finite'),
        ((1.5, 1.0, 0.0, 'nowhere'), R.INVALID_GOAL,
         "cannot transform the goal from frame 'nowhere' to 'map'"),
    ]
    for (x, y, yaw, frame), code, message in cases:
        _, feedback, result_future = nav.send(x, y, yaw, frame)
        response = wait_future(result_future)
        assert response.status == GoalStatus.STATUS_ABORTED, (x, y)
        assert response.result.error_code == code, response.result.error_msg
        assert re.search(message, response.result.error_msg), response.result.error_msg
        assert feedback == []
    assert all(is_zero(msg) for msg in nav.commands.since(0.0))
    assert nav.robot() == pytest.approx(start, abs=1e-6)
    system.wait_for_line(r'\[navigator\].*goal ended: GOAL_OUTSIDE_ZONE')

    system.wait_for_line(r'\[navigator\].*authorised zone: .*zone.yaml \(6 vertices, 0 '
                         r'exclusion\(s\)\)')
    system.wait_for_line(r'\[navigator\].*global costmap: 120 x 80 cells at 0.05 m from the '
                         r'map, 0 keepout zone\(s\), outside the authorised zone lethal')
    costmap = test_node.record(OccupancyGrid, 'global_costmap/costmap', latched=True) \
        .wait_for(lambda msg: True)

    def value(msg, x, y):
        info = msg.info
        col = math.floor((x - info.origin.position.x) / info.resolution)
        row = math.floor((y - info.origin.position.y) / info.resolution)
        assert 0 <= col < info.width and 0 <= row < info.height, (x, y)
        return msg.data[row * info.width + col]

    assert (value(costmap, 5.3, 3.3), value(costmap, 3.02, 1.0), value(costmap, 2.0, 2.0)) \
        == (100, 100, 0)
    # (A local costmap made before map -> odom was known has no zone yet.)
    local = nav.local_costmaps.wait_for(
        lambda msg: msg.header.frame_id == 'odom' and value(msg, -1.242, 0.384) == 100)
    assert value(local, 0.626, 0.330) == 0


def test_navigate_cancel_preempt_and_goal_pose(navigation, test_node):
    """
    Success with feedback, cancel mid-way, preemption, then a goal from goal_pose.

    1. (1, 3, pi/2), 2 m straight ahead: NONE, the robot within the goal tolerances, the
       distance remaining falling from ~2 m, a plan on `plan` ending at the goal;
    2. (2.2, 1, 0): cancelled once 0.5 m done: CANCELED, zero command, the robot stops;
    3. (2, 3.2, 0) replaced on the way by (1, 1, 0): the first PREEMPTED, the second NONE;
    4. (2, 2, 0) on goal_pose: the robot gets there.
    """
    system, nav = navigation
    plans = test_node.record(PathMsg, 'plan')

    handle, feedback, result_future = nav.send(1.0, 3.0, math.pi / 2)
    response = wait_future(result_future, timeout=40.0)
    assert response.status == GoalStatus.STATUS_SUCCEEDED
    assert (response.result.error_code, response.result.error_msg) == (R.NONE, 'goal reached')
    x, y, yaw = nav.robot()
    assert math.hypot(x - 1.0, y - 3.0) <= XY_TOLERANCE + 0.02
    assert abs(wrap_angle(yaw - math.pi / 2)) <= YAW_TOLERANCE + 0.02
    remaining = [f.distance_remaining for f in feedback]
    assert len(remaining) >= 10
    assert remaining[0] == pytest.approx(2.0, abs=0.15)
    assert remaining[-1] < 0.3
    assert max(b - a for a, b in zip(remaining, remaining[1:])) < 0.1
    assert all(f.number_of_recoveries == 0 for f in feedback)
    assert feedback[-1].current_pose.header.frame_id == 'map'
    last_plan = plans.wait_for(lambda msg: len(msg.poses) > 1)
    assert last_plan.header.frame_id == 'map'
    end = last_plan.poses[-1].pose.position
    assert (end.x, end.y) == pytest.approx((1.0, 3.0), abs=1e-6)

    handle, feedback, result_future = nav.send(2.2, 1.0, 0.0)
    wait_until(lambda: len(feedback) > 1 and feedback[-1].distance_remaining
               < feedback[0].distance_remaining - 0.5, what='half a metre done')
    wait_future(handle.cancel_goal_async())
    response = wait_future(result_future)
    assert response.status == GoalStatus.STATUS_CANCELED
    assert response.result.error_code == R.CANCELED
    wait_until(lambda: is_zero(nav.commands.latest()), timeout=5.0, what='a zero command')
    test_node.wait_sim(0.2, timeout=30.0)
    before = nav.robot()
    test_node.wait_sim(0.5, timeout=30.0)
    assert nav.robot() == pytest.approx(before, abs=1e-6)
    assert is_zero(nav.commands.latest())

    first, first_feedback, first_result = nav.send(2.0, 3.2, 0.0)
    wait_until(lambda: len(first_feedback) > 1 and first_feedback[-1].distance_remaining
               < first_feedback[0].distance_remaining - 0.3, what='the first goal under way')
    second, second_feedback, second_result = nav.send(1.0, 1.0, 0.0)
    response = wait_future(first_result)
    assert response.status == GoalStatus.STATUS_ABORTED
    assert (response.result.error_code, response.result.error_msg) == (
        R.PREEMPTED, 'preempted by a newer goal')
    response = wait_future(second_result, timeout=40.0)
    assert response.result.error_code == R.NONE, response.result.error_msg
    assert math.dist(nav.robot()[:2], (1.0, 1.0)) <= XY_TOLERANCE + 0.02

    nav.goal_pub.publish(pose_stamped(2.0, 2.0, 0.0))
    system.wait_for_line(r'\[navigator\].*goal_pose goal ended: NONE: goal reached', 40.0)
    x, y, yaw = nav.robot()
    assert math.hypot(x - 2.0, y - 2.0) <= XY_TOLERANCE + 0.02
    assert abs(wrap_angle(yaw)) <= YAW_TOLERANCE + 0.02
    assert system.stop() == 0


def test_nav2_clients_follow_waypoints_and_poses_and_get_zone_refusals(navigation, test_node):
    """
    Clients written against Nav2's types only drive the robot through poses.

    nav2_msgs FollowWaypoints and NavigateThroughPoses, on Nav2's action names:

    1. FollowWaypoints through three waypoints: SUCCEEDED, NONE, none missed, the
       feedback's current_waypoint going 0, 1, 2, the robot at the last one;
    2. NavigateThroughPoses whose second pose is outside the authorised zone: the
       first is reached, then ABORTED with GOAL_OUTSIDE_ZONE and the zone named in
       error_msg; number_of_poses_remaining 1 on the way to the first.
    """
    system, nav = navigation
    waypoints_client = ActionClient(test_node.node, FollowWaypoints, 'follow_waypoints')
    poses_client = ActionClient(test_node.node, NavigateThroughPoses, 'navigate_through_poses')
    assert waypoints_client.wait_for_server(timeout_sec=20.0)
    assert poses_client.wait_for_server(timeout_sec=20.0)

    waypoints = [(1.0, 2.5, math.pi / 2), (2.0, 3.0, 0.0), (2.0, 1.5, -math.pi / 2)]
    goal = FollowWaypoints.Goal(poses=[pose_stamped(*w) for w in waypoints])
    feedback = []
    handle = wait_future(waypoints_client.send_goal_async(
        goal, feedback_callback=lambda msg: feedback.append(msg.feedback.current_waypoint)))
    assert handle.accepted
    response = wait_future(handle.get_result_async(), timeout=90.0)
    assert response.status == GoalStatus.STATUS_SUCCEEDED, response.result.error_msg
    assert (response.result.error_code, list(response.result.missed_waypoints)) == (R.NONE, [])
    assert sorted(set(feedback)) == [0, 1, 2] and feedback == sorted(feedback)
    x, y, yaw = nav.robot()
    assert math.hypot(x - 2.0, y - 1.5) <= XY_TOLERANCE + 0.02
    assert abs(wrap_angle(yaw + math.pi / 2)) <= YAW_TOLERANCE + 0.02
    for number in (1, 2, 3):
        system.wait_for_line(rf'\[navigator\].*route pose {number}/3 ended: NONE')

    goal = NavigateThroughPoses.Goal(poses=[pose_stamped(1.5, 1.5, 0.0),
                                            pose_stamped(5.3, 3.3, 0.0)])
    remaining = []
    handle = wait_future(poses_client.send_goal_async(
        goal, feedback_callback=lambda msg: remaining.append(
            msg.feedback.number_of_poses_remaining)))
    assert handle.accepted
    response = wait_future(handle.get_result_async(), timeout=60.0)
    assert response.status == GoalStatus.STATUS_ABORTED
    assert response.result.error_code == R.GOAL_OUTSIDE_ZONE, response.result.error_msg
    assert 'outside the authorised zone' in response.result.error_msg
    assert remaining and remaining[0] == 1
    assert math.dist(nav.robot()[:2], (1.5, 1.5)) <= XY_TOLERANCE + 0.02


def test_the_plan_goes_round_an_obstacle_the_map_lacks(navigation, test_node):
    """
    A person-sized circle the map lacks stands on the straight line to the goal.

    The global costmap's obstacle layer adds it from the scan, so the plan (and the
    robot) go round it with the footprint clear of it, and the goal is reached.
    """
    system, nav = navigation
    plans = test_node.record(PathMsg, 'plan')
    costmaps = test_node.record(OccupancyGrid, 'global_costmap/costmap')
    person = (1.8, 1.0, 0.25)
    nav.scanner.circles = [person]
    # The scan sees its near side (x 1.55..1.8 on the row y = 1): marked lethal (100).
    row = round(1.0 / RES)
    costmaps.wait_for_new(lambda msg: 100 in msg.data[row * msg.info.width + round(1.5 / RES):
                                                      row * msg.info.width + round(1.8 / RES)],
                          timeout=20.0)
    handle, feedback, result_future = nav.send(2.6, 1.0, 0.0)
    closest = []
    while not result_future.done():
        x, y, _ = nav.robot()
        closest.append(math.dist((x, y), person[:2]))
        time.sleep(0.02)
    response = result_future.result()
    assert response.result.error_code == R.NONE, response.result.error_msg
    plan = np.array([(p.pose.position.x, p.pose.position.y) for p in plans.latest().poses])
    assert np.min(np.hypot(plan[:, 0] - 1.8, plan[:, 1] - 1.0)) > person[2] + 0.2
    assert min(closest) > person[2] + ROBOT.footprint_radius_m


def test_navigation_launch_file_describes_the_system():
    """
    navigation.launch.yaml: navigator (robot + nav2 params, zone_file), smoother.

    The collision monitor is the command chain's (command_chain.launch.yaml), not here.
    """
    system = load_system(REPO / 'install/mecanum_navigation/share/mecanum_navigation/launch/'
                         'navigation.launch.py', {'use_sim_time': 'true',
                                                  'zone_file': '/tmp/zone.yaml'})
    nodes = {node.label: node for node in system.nodes}
    assert set(nodes) == {'navigator', 'velocity_smoother'}
    navigator = nodes['navigator']
    files = [source.name for source in navigator.parameters if isinstance(source, Path)]
    assert files == ['motor_params.yaml', 'costmap_common.yaml', 'planner_params.yaml',
                     'nav2_params.yaml']
    assert ('use_sim_time', True) in navigator.parameters
    assert ('zone_file', '/tmp/zone.yaml') in navigator.parameters


@pytest.mark.parametrize('params, message', [
    ({'controller': {'max_vel_x': 1.5}},
     r'parameter controller.max_vel_x \(1.5\) exceeds the robot limit max_velocity_x_m_s'),
    ({'keepout_zones': ['[[0, 0], [1, 1]]']},
     r'parameter keepout_zones: polygons\[0\] must have at least 3 \(x, y\) points'),
    ({'max_recoveries': 2.5}, 'parameter max_recoveries must be an integer, got 2.5'),
], ids=['velocity_above_robot_limit', 'keepout_zone_of_two_points', 'fractional_count'])
def test_bad_parameters_stop_the_navigator_with_a_clear_message(ros_env, tmp_path, params,
                                                                message):
    """A bad value: one FATAL line naming the key, exit code 2, no traceback."""
    params_file = tmp_path / 'params.yaml'
    params_file.write_text(yaml.safe_dump({'navigator': {'ros__parameters': params}}))
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_navigation', 'navigator', '--ros-args',
         '--params-file', str(params_file)],
        env=ros_env, capture_output=True, text=True, timeout=60, cwd=str(REPO))
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert 'Traceback' not in output
    assert re.search(r'\[FATAL\].*' + message, output), output


def test_a_malformed_zone_file_stops_the_navigator_naming_the_file_and_key(ros_env, tmp_path):
    """A zone polygon of two points: one FATAL line with the file and the key, exit 2."""
    zone_file = tmp_path / 'zone.yaml'
    zone_file.write_text('authorised_zone:\n  include: [[0, 0], [1, 1]]\n')
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_navigation', 'navigator', '--ros-args',
         '-p', f'zone_file:={zone_file}'],
        env=ros_env, capture_output=True, text=True, timeout=60, cwd=str(REPO))
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert 'Traceback' not in output
    assert re.search(r'\[FATAL\].*parameter zone_file: ' + re.escape(str(zone_file))
                     + r': authorised_zone.include: the polygon needs at least 3 points',
                     output), output


@pytest.mark.skipif(shutil.which('ros2') is None,
                    reason='no ros2 command: make setup found no upstream ros2cli sources')
def test_ros2_action_send_goal_with_feedback_drives_the_robot(navigation, ros_env):
    """The README's `ros2 action send_goal /navigate_to_pose ... --feedback`, as written."""
    _, nav = navigation
    result = subprocess.run(
        ['ros2', 'action', 'send_goal', '/navigate_to_pose', 'nav2_msgs/action/NavigateToPose',
         '{pose: {header: {frame_id: map}, pose: {position: {x: 1.0, y: 2.5}, '
         'orientation: {w: 1.0}}}}', '--feedback'],
        env=ros_env, capture_output=True, text=True, timeout=120)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    assert 'Goal accepted' in output, output
    assert 'distance_remaining:' in output, output          # the feedback, printed
    assert 'Goal finished with status: SUCCEEDED' in output, output
    pose = nav.robot()
    assert math.hypot(pose[0] - 1.0, pose[1] - 2.5) < 0.3, pose
