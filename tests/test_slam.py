"""
Integration: online SLAM maps the apartment while the simulated robot explores it.

The full simulated robot (mecanum_bringup simulation.launch.yaml: simulator, control
stack on the simulated ESP32, description, EKF) and slam.launch.yaml run in their own
processes on simulated time, in lockstep at max speed (simulated time waits for every
node, so a busy machine slows the test down instead of changing what SLAM sees). The test
drives a scripted exploration through every room and back (a waypoint follower on the
simulator's ground truth, as a person with a remote would), then checks what SLAM published: the
map's walls against the world's ground-truth map, SLAM's pose against the ground truth,
and that map_saver_cli saves the map in the Nav2 format.

SLAM's map frame starts at the robot's start pose (map == odom at the first scan); the
world frame is shifted by the start pose to compare.
"""

import math
from pathlib import Path
import subprocess
import threading
from typing import Optional

from geometry_msgs.msg import PoseWithCovarianceStamped, Twist
from mecanum_map_server.grid_messages import occupancy_map
from mecanum_map_server.map_io import load_map, OccupancyMap
from mecanum_navigation.slam.slam import occupied_overlap
from nav_msgs.msg import OccupancyGrid, Odometry
import numpy as np
import pytest
from robot_simulation.world import find_world, load_world
import yaml

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
WORLD = load_world(find_world('apartment'))
START = WORLD.robot_start
# Through the living room, the kitchen, the hallway, the bedroom and back (world frame).
ROUTE = [(4.5, 2.5), (5.0, 3.3), (6.6, 3.3), (8.5, 3.3), (8.5, 4.6), (5.1, 4.6), (5.1, 6.3),
         (3.0, 6.3), (5.1, 6.3), (5.1, 4.6), (1.5, 4.6), (1.5, 3.2), (2.95, 2.0)]
SPEED_M_S = 0.4


def write_world(directory: Path) -> Path:
    """
    Write the apartment without its walking person: the route crosses the person's loop.

    Every command goes through the collision monitor, which holds the robot in front of
    the person while the person waits for the robot; when that ends depends on where the
    person is when the route starts (the wall clock), so the route's duration would too.
    """
    document = yaml.safe_load(find_world('apartment').read_text())
    document['world']['moving_obstacles'] = []
    path = directory / 'apartment_without_person.yaml'
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    return path


def write_launch(directory: Path) -> Path:
    """Write the test's system: bringup's simulated robot and online SLAM."""
    launch = {'launch': [
        {'include': {
            'file': '$(find-pkg-share mecanum_bringup)/launch/simulation.launch.yaml',
            'arg': [{'name': 'world', 'value': str(write_world(directory))},
                    {'name': 'board_port', 'value': str(directory / 'ttySIM')},
                    {'name': 'estop_latch_file', 'value': str(directory / 'estop')},
                    {'name': 'lockstep', 'value': 'true'},
                    {'name': 'real_time_factor', 'value': '0'}]}},
        {'include': {
            'file': '$(find-pkg-share mecanum_navigation)/launch/slam.launch.yaml',
            'arg': [{'name': 'use_sim_time', 'value': 'true'}]}},
    ]}
    path = directory / 'slam_test.launch.yaml'
    path.write_text(yaml.safe_dump(launch, sort_keys=False))
    return path


def planar(msg):
    """Return (t s, x, y, yaw) of an Odometry or PoseWithCovarianceStamped."""
    pose = msg.pose.pose
    return (msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9, pose.position.x,
            pose.position.y, 2.0 * math.atan2(pose.orientation.z, pose.orientation.w))


class Driver:
    """
    Follows ROUTE on the ground truth: world-frame velocity to the next waypoint.

    It runs on simulated time: each ground-truth message (50 Hz) may bring a new command,
    one every COMMAND_PERIOD_S of simulated time. With lockstep_name it takes part in the
    simulator's lockstep (TestNode.answer_clock), so simulated time waits for its commands
    and the route is driven the same way at any speed and load: CI at 870cc44, without it,
    had the driver fall behind at max speed on a loaded machine, the robot overshoot a
    corner into the collision monitor's stop zone and the route never end.
    """

    COMMAND_PERIOD_S = 0.05

    def __init__(self, test_node, lockstep_name: Optional[str] = None):
        """Create the command publisher and follow the ground truth from now on."""
        self.publisher = test_node.node.create_publisher(Twist, 'cmd_vel', 10)
        self.done = threading.Event()
        self.index = 0
        self.latest = None
        self.last_command_s = -math.inf
        test_node.node.create_subscription(Odometry, 'ground_truth/odom', self.on_truth, 50)
        if lockstep_name is not None:
            # After the ground truth's subscription: its callbacks run first in a round.
            test_node.answer_clock(lockstep_name)

    def on_truth(self, msg):
        """Send the next command when it is due; stop the robot at the route's end."""
        if self.done.is_set():
            return
        t, x, y, yaw = self.latest = planar(msg)
        if t - self.last_command_s < self.COMMAND_PERIOD_S:
            return
        self.last_command_s = t
        while self.index < len(ROUTE) and math.hypot(ROUTE[self.index][0] - x,
                                                     ROUTE[self.index][1] - y) < 0.08:
            self.index += 1
        if self.index == len(ROUTE):
            self.publisher.publish(Twist())
            self.done.set()
            return
        gx, gy = ROUTE[self.index]
        dx, dy = gx - x, gy - y
        distance = math.hypot(dx, dy)
        speed = min(SPEED_M_S, 1.0 * distance)
        vx_world, vy_world = speed * dx / distance, speed * dy / distance
        # Face the direction of travel (a turn at each waypoint, strafing meanwhile).
        heading_error = math.atan2(math.sin(math.atan2(dy, dx) - yaw),
                                   math.cos(math.atan2(dy, dx) - yaw))
        cmd = Twist()
        cmd.linear.x = math.cos(yaw) * vx_world + math.sin(yaw) * vy_world
        cmd.linear.y = -math.sin(yaw) * vx_world + math.cos(yaw) * vy_world
        cmd.angular.z = max(-1.0, min(1.0, 1.5 * heading_error))
        self.publisher.publish(cmd)


def test_route_is_free():
    """The scripted route keeps 0.25 m from every obstacle (the robot is 0.2 m in radius)."""
    points = [START[:2]] + ROUTE
    for (x0, y0), (x1, y1) in zip(points, points[1:]):
        for f in np.linspace(0.0, 1.0, 50):
            x, y = x0 + f * (x1 - x0), y0 + f * (y1 - y0)
            assert WORLD.is_free(x, y, clearance_m=0.25), (x, y)


@pytest.mark.long
def test_slam_maps_the_apartment(start_system, test_node, ros_env, tmp_path):
    system = start_system(str(write_launch(tmp_path)))
    truth = test_node.record(Odometry, 'ground_truth/odom')
    poses = test_node.record(PoseWithCovarianceStamped, 'pose')
    maps = test_node.record(OccupancyGrid, 'map', latched=True)
    system.wait_for_line(r'\[hardware_interface\].*IMU calibrated at rest', timeout=90)
    system.wait_for_line(r'\[slam_toolbox\].*1 keyframes', timeout=60)
    truth.wait_for(lambda m: True)

    driver = Driver(test_node, lockstep_name='slam_test_route')
    assert driver.done.wait(timeout=400), (
        f'the route was not driven in time: the robot is at (t s, x, y, yaw) '
        f'{driver.latest}, heading for waypoint {driver.index} '
        f'{ROUTE[min(driver.index, len(ROUTE) - 1)]}\n{system.output()}')
    # The last map update (map_update_interval 2 s) after the last keyframe.
    end_s = planar(truth.latest())[0]
    truth.wait_for_new(lambda m: planar(m)[0] >= end_s + 3.0, timeout=60)

    # Trajectory: SLAM's pose against the ground truth, both in the world frame.
    truth_track = np.array([planar(m) for m in truth.since(0.0)])
    estimate = np.array([planar(m) for m in poses.since(0.0)])
    c, s = math.cos(START[2]), math.sin(START[2])
    world_x = START[0] + c * estimate[:, 1] - s * estimate[:, 2]
    world_y = START[1] + s * estimate[:, 1] + c * estimate[:, 2]
    true_x = np.interp(estimate[:, 0], truth_track[:, 0], truth_track[:, 1])
    true_y = np.interp(estimate[:, 0], truth_track[:, 0], truth_track[:, 2])
    errors = np.hypot(world_x - true_x, world_y - true_y)
    rms = float(np.sqrt(np.mean(errors ** 2)))

    # The map, moved into the world frame, against the world's ground-truth map.
    grid = occupancy_map(maps.latest())
    ox, oy, oyaw = grid.origin
    moved = OccupancyMap(grid.resolution_m, (START[0] + c * ox - s * oy,
                                             START[1] + s * ox + c * oy, oyaw + START[2]),
                         grid.data)
    overlap = occupied_overlap(moved, WORLD.to_occupancy_map(grid.resolution_m))
    print(f'SLAM: trajectory RMS {rms:.3f} m, max {errors.max():.3f} m over '
          f'{len(errors)} poses; map overlap {overlap}')
    worst = np.argsort(errors)[-3:]
    print('worst (t s, m):', [(round(float(estimate[i, 0]), 1), round(float(errors[i]), 3))
                              for i in worst])
    assert rms < 0.05
    # Transient errors of 0.2-0.5 m between keyframes were seen early in some runs
    # (issue 7 note); most poses are within a few centimetres.
    assert np.percentile(errors, 95) < 0.1
    precision, recall = overlap
    assert precision > 0.9, 'walls where the world has none'
    assert recall > 0.8, 'the walls the route sees are mapped'

    # Saved the Nav2 way, the map loads back as published.
    saved = tmp_path / 'apartment_slam'
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_map_server', 'map_saver_cli', '-f', str(saved)],
        env=ros_env, capture_output=True, text=True, timeout=60, cwd=str(REPO))
    assert result.returncode == 0, result.stdout + result.stderr
    again = load_map(saved.with_suffix('.yaml'))
    assert again.data.shape == grid.data.shape
    assert system.stop() == 0
