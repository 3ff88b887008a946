"""
Integration: the collision_monitor node (collision_monitor.launch.yaml) on simulated time.

The test node publishes what the robot would: the laser mount on /tf_static (5 cm ahead
of base_link as motor_params.yaml's lidar_mount_x_m, but turned by 180 degrees, so a node
ignoring the transform would see the wall behind the robot), LaserScans of a room (360
beams of 1 degree, ranges from the geometry): a wall across the robot's path at a
chosen distance, the other three ROOM_M away, beyond every zone's reach (a closed room,
as the apartment: every beam returns), and commands on cmd_vel_mux (the twist_mux's
output) about every 50 ms. Expected outputs are worked out from
config/collision_monitor.yaml: unchanged commands when nothing is near, zero in the stop
zone, and for the approach zone what the pure core computes for the same scan (its
float32 ranges) and zones read from the file here.

A bad lidar stops the robot until good scans return (issue 31): a blinded one (every
range +inf), a frozen one (the same noisy ranges again and again, new stamps) and one
stamping its scans in the future.
"""

import math
from pathlib import Path
import re
import subprocess
import time

from geometry_msgs.msg import PolygonStamped, TransformStamped, Twist
from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_safety.collision_monitor import (
    CollisionMonitor, scan_to_points, SourceData, Zone)
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import LaserScan
from std_msgs.msg import String
from tests.conftest import LoopThread
from tf2_msgs.msg import TFMessage
import yaml

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
PARAMS = yaml.safe_load(
    (REPO / 'src/mecanum_safety/config/collision_monitor.yaml').read_text()
)['collision_monitor']['ros__parameters']
MOUNT = (load_robot_config(default_config_path()).lidar_mount_x_m, 0.0, math.pi)
BEAMS = 360
RANGE_MIN_M, RANGE_MAX_M = 0.15, 12.0
#: Distance (m) from base_link to the room's back and side walls.
ROOM_M = 2.0


def vertices(points):
    """Return [(x, y), ...] from the config's points (flat list, or Nav2 Jazzy's string)."""
    if isinstance(points, str):
        points = yaml.safe_load(points)
    if all(isinstance(p, list) for p in points):
        return [tuple(p) for p in points]
    return list(zip(points[0::2], points[1::2]))


def config_zones():
    """Return the zones of collision_monitor.yaml, read independently of the node."""
    zones = []
    for name in PARAMS['polygons']:
        p = PARAMS[name]
        shape = ({'radius': p['radius']} if p['type'] == 'circle'
                 else {'points': vertices(p['points'])})
        options = {key: p[key] for key in (
            'min_points', 'slowdown_ratio', 'linear_limit', 'angular_limit',
            'time_before_collision', 'simulation_time_step', 'enabled') if key in p}
        options.setdefault('simulation_time_step', 0.1)   # the node's default (Nav2's)
        zones.append(Zone(name, p['action_type'], **shape, **options))
    return zones


def wall_scan(distance_m, stamp_ns, noise_m=0.0, rng=None):
    """
    Return a LaserScan of the room: a wall across x = distance_m in base_link.

    The back and side walls are at x = -ROOM_M and y = +-ROOM_M; noise_m adds gaussian
    noise (m, 1 sigma, from rng) to every range, as a real lidar has.
    """
    msg = LaserScan()
    msg.header.frame_id = 'laser'
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10 ** 9)
    msg.angle_min = -math.pi
    msg.angle_increment = 2.0 * math.pi / BEAMS
    msg.angle_max = msg.angle_min + (BEAMS - 1) * msg.angle_increment
    msg.range_min, msg.range_max = RANGE_MIN_M, RANGE_MAX_M
    # Beam i leaves the laser at (MOUNT x, 0) along base_link angle yaw + angle_i; its
    # range is that of the nearest wall it meets.
    angles = MOUNT[2] + msg.angle_min + msg.angle_increment * np.arange(BEAMS)
    cos, sin = np.cos(angles), np.sin(angles)
    ranges = np.full(BEAMS, math.inf)
    with np.errstate(divide='ignore'):
        for along, offset in ((cos, distance_m - MOUNT[0]), (cos, -ROOM_M - MOUNT[0]),
                              (sin, ROOM_M), (sin, -ROOM_M)):
            hit = offset / along
            ranges = np.where((np.abs(along) > 1e-9) & (hit > 0.0), np.minimum(ranges, hit),
                              ranges)
    if noise_m > 0.0:
        ranges = ranges + rng.normal(0.0, noise_m, BEAMS)
    ranges[ranges > RANGE_MAX_M] = math.inf
    msg.ranges = ranges.tolist()
    return msg


def expected_twist(command, distance_m):
    """Return what the core allows for command with a wall at distance_m (fresh data)."""
    scan = wall_scan(distance_m, 0)
    points = scan_to_points(np.array(scan.ranges), scan.angle_min, scan.angle_increment,
                            scan.range_min, scan.range_max, MOUNT,
                            too_close_as_range_min=True)
    monitor = CollisionMonitor(config_zones(), PARAMS['source_timeout'])
    return monitor.process(command, [SourceData('scan', points, 0.0)])


class Publishers(LoopThread):
    """
    Publishes commands (~20 Hz) and room scans (~10 Hz) from a thread, while set.

    Scans carry noise_m of noise and are stamped stamp_offset_s after the test's clock;
    lidar 'blinded' sends every range +inf, 'frozen' the last ranges again (new stamps;
    frozen_repeats counts them).
    """

    def __init__(self, test_node):
        """Create the publishers; start() begins publishing."""
        self.test_node = test_node
        self.cmd_pub = test_node.node.create_publisher(Twist, PARAMS['cmd_vel_in_topic'], 10)
        self.scan_pub = test_node.node.create_publisher(LaserScan, 'scan', 10)
        self.command = None
        self.scans = False
        self.wall_m = 3.0
        self.noise_m = 0.0
        self.lidar = 'healthy'
        self.stamp_offset_s = 0.0
        self.frozen_repeats = 0
        self.last_scan_stamp_s = math.nan
        self._rng = np.random.default_rng(31)
        super().__init__()

    def _scan(self, stamp_ns, previous):
        """Return the next scan of the lidar as it is now."""
        msg = wall_scan(self.wall_m, stamp_ns, self.noise_m, self._rng)
        if self.lidar == 'blinded':
            msg.ranges = [math.inf] * BEAMS
        elif self.lidar == 'frozen' and previous is not None:
            msg.ranges = previous.ranges
            self.frozen_repeats += 1
        return msg

    def _run(self):
        tick = 0
        previous = None
        while not self._stop.is_set():
            if self.scans and tick % 2 == 0:
                stamp_ns = self.test_node.clock_ns
                previous = self._scan(stamp_ns + int(self.stamp_offset_s * 1e9), previous)
                self.scan_pub.publish(previous)
                self.last_scan_stamp_s = stamp_ns * 1e-9
            command = self.command
            if command is not None:
                msg = Twist()
                msg.linear.x, msg.linear.y, msg.angular.z = (float(v) for v in command)
                self.cmd_pub.publish(msg)
            tick += 1
            time.sleep(0.05)


def twist_of(msg):
    """Return (vx, vy, wz) of a Twist."""
    return np.array([msg.linear.x, msg.linear.y, msg.angular.z])


def settle(out, state, twist, state_text, count=4):
    """Wait until outputs equal twist with state_text, then check the next count outputs."""
    out.wait_for_new(lambda m: np.allclose(twist_of(m), twist, rtol=0.0, atol=1e-6))
    state.wait_for_new(lambda m: m.data == state_text)
    start = time.monotonic()
    deadline = start + 20.0
    while len(out.since(start)) < count and time.monotonic() < deadline:
        time.sleep(0.02)
    following = out.since(start)
    assert len(following) >= count
    for msg in following:
        assert twist_of(msg) == pytest.approx(twist, abs=1e-6)
    assert all(m.data == state_text for m in state.since(start))


def publish_mount(test_node):
    """Publish the laser mount (base_link -> laser) on /tf_static."""
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    static = test_node.node.create_publisher(TFMessage, '/tf_static', latched)
    mount = TransformStamped()
    mount.header.frame_id, mount.child_frame_id = 'base_link', 'laser'
    mount.transform.translation.x = MOUNT[0]
    mount.transform.rotation.z, mount.transform.rotation.w = (math.sin(MOUNT[2] / 2),
                                                              math.cos(MOUNT[2] / 2))
    static.publish(TFMessage(transforms=[mount]))
    return static


def test_zones_sources_and_transforms(start_system, test_node):
    test_node.start_clock()
    out = test_node.record(Twist, PARAMS['cmd_vel_out_topic'])
    state = test_node.record(String, 'collision_monitor_state')
    polygons = {}
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    for name in PARAMS['polygons']:
        polygons[name] = []
        test_node.node.create_subscription(PolygonStamped, f'/collision_monitor/{name}',
                                           polygons[name].append, latched)
    system = start_system('mecanum_safety', 'collision_monitor.launch.yaml',
                          'use_sim_time:=true')
    system.wait_for_line(r'\[collision_monitor\].*Collision monitor started')
    publishers = Publishers(test_node)
    publishers.start()
    try:
        # Scans of a far wall, but no laser mount yet: the source is unusable -> stop.
        publishers.wall_m = 3.0
        publishers.scans = True
        publishers.command = (0.3, 0.0, 0.0)
        settle(out, state, (0.0, 0.0, 0.0), 'STOP invalid source: scan no transform')
        system.wait_for_line(r'\[WARN\].*no transform base_link <- laser yet')

        # The mount arrives: nothing within reach, every command passes unchanged.
        publish_mount(test_node)
        for command in [(0.5, 0.0, 0.0), (0.2, -0.4, 1.0), (-0.6, 0.0, -2.0)]:
            assert expected_twist(command, 3.0).action == 'none'
            publishers.command = command
            settle(out, state, command, 'DO_NOTHING')

        # A wall 0.205 m ahead, inside PolygonStop: zero out for every command but one
        # that backs straight away from it (Nav2's stop would hold that too), which is
        # only limited by PolygonLimit (0.2 m/s).
        publishers.wall_m = 0.205
        for command in [(0.3, 0.0, 0.0), (0.0, 0.3, 0.0)]:
            assert expected_twist(command, 0.205).zone == 'PolygonStop'
            publishers.command = command
            settle(out, state, (0.0, 0.0, 0.0), 'STOP PolygonStop')
        backward = expected_twist((-0.3, 0.0, 0.0), 0.205)
        assert backward.zone == 'PolygonLimit'
        assert backward.twist == pytest.approx((-0.2, 0.0, 0.0))
        publishers.command = (-0.3, 0.0, 0.0)
        settle(out, state, backward.twist, 'LIMIT PolygonLimit')

        # A wall 0.6 m ahead: the footprint approach limits motion towards it as the core
        # computes; backing off and strafing along it pass unchanged.
        publishers.wall_m = 0.6
        for command in [(0.5, 0.0, 0.0), (0.5, 0.3, 0.2)]:
            result = expected_twist(command, 0.6)
            assert result.zone == 'FootprintApproach'
            assert 0.0 < result.twist[0] < command[0]
            publishers.command = command
            settle(out, state, result.twist, 'APPROACH FootprintApproach')
        for command in [(-0.3, 0.0, 0.0), (0.0, 0.3, 0.0)]:
            assert expected_twist(command, 0.6).action == 'none'
            publishers.command = command
            settle(out, state, command, 'DO_NOTHING')

        # The laser goes quiet: after source_timeout (not before) the robot is stopped.
        publishers.wall_m = 3.0
        publishers.command = (0.3, 0.0, 0.0)
        settle(out, state, (0.3, 0.0, 0.0), 'DO_NOTHING', count=2)
        publishers.scans = False
        time.sleep(0.2)
        last_scan_s = publishers.last_scan_stamp_s
        out.wait_for_new(lambda m: np.all(twist_of(m) == 0.0))
        assert test_node.clock_ns * 1e-9 - last_scan_s >= PARAMS['source_timeout']
        settle(out, state, (0.0, 0.0, 0.0), 'STOP invalid source: scan stale', count=2)

        # No command input: nothing published.
        publishers.command = None
        time.sleep(0.5)
        quiet_since = time.monotonic()
        time.sleep(1.0)
        assert out.since(quiet_since) == []
    finally:
        publishers.stop()

    # The zones for RViz / Foxglove, in base_link.
    for zone in config_zones():
        assert polygons[zone.name], f'no polygon on /collision_monitor/{zone.name}'
        msg = polygons[zone.name][-1]
        assert msg.header.frame_id == 'base_link'
        outline = np.array([(p.x, p.y) for p in msg.polygon.points])
        if zone.radius is not None:
            assert len(outline) >= 16
            assert np.hypot(outline[:, 0], outline[:, 1]) == pytest.approx(zone.radius,
                                                                           abs=1e-6)
        else:
            assert outline == pytest.approx(np.array(zone.points), abs=1e-6)
    assert 'Traceback' not in system.output()


#: What each lidar fault of the test does to the Publishers, and the state it gives.
LIDAR_FAULTS = {
    'blinded': ({'lidar': 'blinded'}, 'blinded',
                r"source 'scan': only 0% of its beams are usable"),
    'frozen': ({'lidar': 'frozen'}, 'frozen',
               r"source 'scan': \d+ identical scans in a row"),
    'future': ({'stamp_offset_s': 1.0}, 'stamped in the future',
               r"source 'scan' is stamped (0\.9\d*|1(\.0\d*)?) s in the future"),
}


@pytest.mark.parametrize('fault', list(LIDAR_FAULTS))
def test_a_bad_lidar_stops_the_robot_until_good_scans_return(start_system, test_node, fault):
    """
    Healthy noisy scans of a far wall let a command through; the fault stops it.

    The state and the log say why (the source and what is wrong with it); once healthy
    scans return, the command passes again (no latch).
    """
    settings, kind, log_reason = LIDAR_FAULTS[fault]
    test_node.start_clock()
    out = test_node.record(Twist, PARAMS['cmd_vel_out_topic'])
    state = test_node.record(String, 'collision_monitor_state')
    system = start_system('mecanum_safety', 'collision_monitor.launch.yaml',
                          'use_sim_time:=true')
    system.wait_for_line(r'\[collision_monitor\].*Collision monitor started')
    publish_mount(test_node)
    publishers = Publishers(test_node)
    publishers.noise_m = 0.01       # the simulated lidar's noise (LidarConfig)
    publishers.scans = True
    publishers.command = (0.3, 0.0, 0.0)
    publishers.start()
    try:
        settle(out, state, (0.3, 0.0, 0.0), 'DO_NOTHING')
        for key, value in settings.items():
            setattr(publishers, key, value)
        settle(out, state, (0.0, 0.0, 0.0), f'STOP invalid source: scan {kind}')
        system.wait_for_line(rf'\[collision_monitor\].*Robot to stop due to invalid source: '
                             rf'scan {kind}: {log_reason}')
        if fault == 'frozen':
            # Not at the first repeat: only after max_identical_scans of them.
            assert publishers.frozen_repeats >= PARAMS['max_identical_scans']
        publishers.lidar, publishers.stamp_offset_s = 'healthy', 0.0
        settle(out, state, (0.3, 0.0, 0.0), 'DO_NOTHING')
        system.wait_for_line(r'\[collision_monitor\].*Robot to continue normal operation')
    finally:
        publishers.stop()
    assert 'Traceback' not in system.output()


@pytest.mark.parametrize('arguments, message', [
    ([], 'parameter polygons is empty'),
    (['-p', 'polygons:=[Stop]', '-p', 'Stop.type:=circle', '-p', 'Stop.radius:=-0.3',
      '-p', 'Stop.action_type:=stop'], r'parameter Stop\.radius must be finite and > 0'),
    (['-p', 'polygons:=[Slow]', '-p', 'Slow.type:=polygon', '-p',
      'Slow.points:=[0.5, 0.5, 0.5]', '-p', 'Slow.action_type:=slowdown'],
     r'parameter Slow\.points must hold an even number of values'),
    (['-p', 'polygons:=[Stop]', '-p', 'Stop.type:=circle', '-p', 'Stop.radius:=0.3',
      '-p', 'Stop.action_type:=stop', '-p', 'min_valid_beam_fraction:=1.5'],
     r'parameter min_valid_beam_fraction must be finite and >= 0 and <= 1, got 1\.5'),
    (['-p', 'polygons:=[Stop]', '-p', 'Stop.type:=circle', '-p', 'Stop.radius:=0.3',
      '-p', 'Stop.action_type:=stop', '-p', 'max_identical_scans:=-1'],
     r'parameter max_identical_scans must be an integer >= 0 \(0: no check\), got -1'),
])
def test_bad_parameters_stop_the_node_with_a_clear_message(ros_env, arguments, message):
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_safety', 'collision_monitor', '--ros-args',
         *arguments], env=ros_env, capture_output=True, text=True, timeout=60,
        cwd=str(REPO))
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert 'Traceback' not in output
    assert re.search(r'\[FATAL\].*' + message, output), output
