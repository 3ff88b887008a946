"""
Integration: the zone_guard node in its own process, on simulated time.

The test node plays the rest of the robot: /clock, the transforms map -> odom (as amcl:
future-dated by 0.5 s) and odom -> base_link (as the EKF: stamped now) on /tf, amcl_pose
with its covariance, and commands on cmd_vel_monitored about every 50 ms; it records
cmd_vel_safe, zone_guard_state and /diagnostics. The zone is a 4 m square written into a zone file;
the expected twists are what the pure core computes for the same pose (its own tests
work the numbers out by hand: 1 m from the border, 0.75 m of travel is allowed).
Further tests: an unhealthy localisation (NaN, a covariance not symmetric positive
semi-definite, a sigma above max_position_sigma_m) stops all but turning on the spot,
also heard from SLAM's volatile pose topic; outside the zone only motion back in
passes; a pose stamped in the future is not trusted; with require_zone an empty
zone_file stops everything, and zone_file:=unrestricted is no zone (for robot_controller
and the navigator too).
"""

import math
from pathlib import Path
import re
import subprocess
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped, TransformStamped, Twist
from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_localization.transforms import PlanarTransform
from mecanum_safety.zone import load_zone_file
from mecanum_safety.zone_guard import guard_scale
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import String
from tests.conftest import LoopThread
from tf2_msgs.msg import TFMessage
import yaml

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
PARAMS = yaml.safe_load(
    (REPO / 'src/mecanum_safety/config/zone_guard.yaml').read_text()
)['zone_guard']['ros__parameters']
RADIUS_M = load_robot_config(default_config_path()).footprint_radius_m
SQUARE = 'authorised_zone:\n  include: [[0, 0], [4, 0], [4, 4], [0, 4]]\n'
#: Where odom is in map (as if amcl had corrected some drift).
MAP_TO_ODOM = PlanarTransform(0.5, -0.3, 0.4)
#: amcl future-dates map -> odom by its transform_tolerance.
AMCL_TOLERANCE_S = 0.5
#: The guard's pose_covariance_topic by default (amcl's; command_chain.launch passes it).
AMCL_POSE = 'amcl_pose'


def write_launch(directory: Path, zone_file: str, extra_nodes=(), **parameters) -> Path:
    """Write the test system: the zone guard alone, as command_chain.launch.yaml starts it."""
    launch = {'launch': [
        {'node': {'pkg': 'mecanum_safety', 'exec': 'zone_guard', 'name': 'zone_guard',
                  'param': [
                      {'from': '$(find-pkg-share mecanum_control)/config/motor_params.yaml'},
                      {'from': '$(find-pkg-share mecanum_safety)/config/zone_guard.yaml'},
                      {'name': 'zone_file', 'value': zone_file},
                      {'name': 'use_sim_time', 'value': True}] + [
                      {'name': name, 'value': value} for name, value in parameters.items()]}},
        *extra_nodes,
    ]}
    path = directory / 'zone_guard_test.launch.yaml'
    path.write_text(yaml.safe_dump(launch, sort_keys=False))
    return path


def transform(parent, child, planar, stamp_ns):
    """Return a TransformStamped of a planar transform."""
    msg = TransformStamped()
    msg.header.frame_id, msg.child_frame_id = parent, child
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10 ** 9)
    msg.transform.translation.x, msg.transform.translation.y = planar.x, planar.y
    msg.transform.rotation.z = math.sin(planar.yaw / 2.0)
    msg.transform.rotation.w = math.cos(planar.yaw / 2.0)
    return msg


class Robot(LoopThread):
    """Publishes /tf (map -> odom, odom -> base_link) and commands from a thread (~20 Hz)."""

    def __init__(self, test_node):
        """Create the publishers; start() begins publishing."""
        self.test_node = test_node
        node = test_node.node
        self.tf_pub = node.create_publisher(TFMessage, '/tf', QoSProfile(depth=100))
        self.cmd_pub = node.create_publisher(Twist, PARAMS['cmd_vel_in_topic'], 10)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.covariance_pub = node.create_publisher(
            PoseWithCovarianceStamped, AMCL_POSE, latched)
        self.pose = None            # (x, y, yaw) of base_link in map; None: no /tf
        self.ekf = True             # publish odom -> base_link
        self.map_to_odom = MAP_TO_ODOM  # what the localisation believes
        self.future_s = 0.0         # stamp every transform this far in the future (s)
        self.command = None
        self.last_ekf_stamp_s = math.nan
        super().__init__()

    def publish_sigma(self, sigma_m, publisher=None):
        """Publish amcl_pose with position standard deviations sigma_m along y, half along x."""
        covariance = [0.0] * 36
        covariance[0], covariance[7], covariance[35] = (sigma_m / 2) ** 2, sigma_m ** 2, 0.01
        self.publish_covariance(covariance, publisher=publisher)

    def publish_covariance(self, covariance, position=(0.0, 0.0, 0.0), publisher=None):
        """Publish a pose with covariance (on amcl_pose unless publisher is given)."""
        msg = PoseWithCovarianceStamped()
        msg.header.frame_id = 'map'
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(self.test_node.clock_ns,
                                                                10 ** 9)
        msg.pose.pose.position.x, msg.pose.pose.position.y, msg.pose.pose.position.z = (
            float(v) for v in position)
        msg.pose.covariance = [float(v) for v in covariance]
        (publisher or self.covariance_pub).publish(msg)

    def _run(self):
        while not self._stop.is_set():
            pose = self.pose
            if pose is not None:
                now_ns = self.test_node.clock_ns + int(self.future_s * 1e9)
                future_ns = now_ns + int(AMCL_TOLERANCE_S * 1e9)
                transforms = [transform('map', 'odom', self.map_to_odom, future_ns)]
                if self.ekf:
                    odom_to_base = self.map_to_odom.inverse().compose(PlanarTransform(*pose))
                    transforms.append(transform('odom', 'base_link', odom_to_base, now_ns))
                    self.last_ekf_stamp_s = now_ns * 1e-9
                self.tf_pub.publish(TFMessage(transforms=transforms))
            command = self.command
            if command is not None:
                msg = Twist()
                msg.linear.x, msg.linear.y, msg.angular.z = (float(v) for v in command)
                self.cmd_pub.publish(msg)
            time.sleep(0.05)


def twist_of(msg):
    """Return (vx, vy, wz) of a Twist."""
    return np.array([msg.linear.x, msg.linear.y, msg.angular.z])


def expected(zone, pose, command, margin_m):
    """Return the twist the core allows and its scale."""
    result = guard_scale(zone, pose, command, RADIUS_M, margin_m, PARAMS['horizon_s'])
    return np.array(command) * result.scale, result.scale


def settle(out, state, twist, state_pattern, count=3):
    """Wait for the output twist and a matching state; check the next count outputs."""
    out.wait_for_new(lambda m: np.allclose(twist_of(m), twist, rtol=0.0, atol=1e-6))
    state.wait_for_new(lambda m: m.data.startswith(state_pattern))
    start = time.monotonic()
    deadline = start + 10.0
    while len(out.since(start)) < count and time.monotonic() < deadline:
        time.sleep(0.02)
    following = out.since(start)
    assert len(following) >= count
    for msg in following:
        assert twist_of(msg) == pytest.approx(twist, abs=1e-6)


def wait_for_diagnostics(diagnostics, level, message):
    """Wait for a new /diagnostics status of the guard with level and message."""
    diagnostics.wait_for_new(lambda m: any(
        s.name == 'zone_guard: Authorised zone' and s.level == level
        and s.message.startswith(message) for s in m.status), timeout=5.0)


def test_commands_are_kept_inside_the_zone(start_system, test_node, tmp_path):
    zone_path = tmp_path / 'zone.yaml'
    zone_path.write_text(SQUARE)
    zone = load_zone_file(zone_path)
    test_node.start_clock()
    out = test_node.record(Twist, PARAMS['cmd_vel_out_topic'])
    state = test_node.record(String, PARAMS['state_topic'])
    diagnostics = test_node.record(DiagnosticArray, '/diagnostics')
    system = start_system(str(write_launch(tmp_path, str(zone_path))))
    system.wait_for_line(r'\[zone_guard\].*Zone guard started')
    robot = Robot(test_node)
    robot.start()
    margin = PARAMS['margin_m']
    try:
        # No transform yet: stopped, and the state says why.
        robot.command = (0.3, 0.0, 0.0)
        settle(out, state, (0.0, 0.0, 0.0), 'STOP no pose: no transform map -> base_link')

        # Far from the border: unchanged.
        robot.pose = (2.0, 2.0, 0.3)
        for command in [(0.3, 0.0, 0.0), (0.2, -0.4, 1.0), (-0.6, 0.0, -2.0)]:
            assert expected(zone, robot.pose, command, margin)[1] == 1.0
            robot.command = command
            settle(out, state, command, 'ALLOW')
        wait_for_diagnostics(diagnostics, DiagnosticStatus.OK, 'ALLOW')

        # 0.5 m from the right border, driving at it: 0.25 m of travel left in 1 s.
        robot.pose = (3.5, 2.0, 0.0)
        robot.command = (0.5, 0.0, 0.0)
        twist, scale = expected(zone, robot.pose, robot.command, margin)
        assert scale == pytest.approx(0.5)
        settle(out, state, twist, 'SCALE 0.50 (0.30 m from the border)')
        wait_for_diagnostics(diagnostics, DiagnosticStatus.WARN, 'SCALE 0.50')
        # Strafing along it, or backing away: unchanged.
        for command in [(0.0, 0.4, 0.0), (-0.5, 0.0, 0.5)]:
            robot.command = command
            settle(out, state, command, 'ALLOW')

        # amcl is unsure (sigma 0.05 m along y, 0.025 m along x): toward the right border
        # the error along its normal (x) counts: margin 0.05 + 2 * 0.025 = 0.10 m.
        robot.publish_sigma(0.05)
        robot.command = (0.5, 0.0, 0.0)
        twist, scale = expected(zone, robot.pose, robot.command,
                                margin + PARAMS['covariance_factor'] * 0.025)
        assert scale == pytest.approx(0.4)
        settle(out, state, twist, 'SCALE 0.40')
        # Toward the top border (y = 4, 0.5 m away), y's 0.05 m: 0.05 + 2 * 0.05 = 0.15 m.
        robot.pose = (2.0, 3.5, math.pi / 2)
        twist, scale = expected(zone, robot.pose, robot.command,
                                margin + PARAMS['covariance_factor'] * 0.05)
        assert scale == pytest.approx(0.3)
        settle(out, state, twist, 'SCALE 0.30')
        robot.publish_sigma(0.0)
        robot.pose = (3.5, 2.0, 0.0)

        # At the margin: toward the border stops, away and along pass.
        robot.pose = (4.0 - RADIUS_M - margin, 2.0, math.pi / 2)
        robot.command = (0.0, -0.3, 0.0)       # facing north, strafing east
        settle(out, state, (0.0, 0.0, 0.0), 'STOP at the border')
        wait_for_diagnostics(diagnostics, DiagnosticStatus.ERROR, 'STOP at the border')
        for command in [(0.0, 0.3, 0.0), (0.3, 0.0, 0.0), (0.0, 0.0, 1.5)]:
            robot.command = command
            settle(out, state, command, 'ALLOW')

        # The EKF goes quiet (amcl's future-dated map -> odom still comes): after
        # pose_timeout_s (not before) the robot is stopped; a zero command passes.
        robot.pose = (2.0, 2.0, 0.0)
        robot.command = (0.3, 0.0, 0.0)
        settle(out, state, (0.3, 0.0, 0.0), 'ALLOW')
        robot.ekf = False
        time.sleep(0.1)
        last_stamp_s = robot.last_ekf_stamp_s
        out.wait_for_new(lambda m: np.all(twist_of(m) == 0.0))
        assert test_node.clock_ns * 1e-9 - last_stamp_s >= PARAMS['pose_timeout_s']
        settle(out, state, (0.0, 0.0, 0.0),
               'STOP no pose: map -> base_link older than 0.5 s (localisation lost?)')
        system.wait_for_line(r'\[WARN\].*map -> base_link is [0-9.]+ s old \(its oldest '
                             r'link odom -> base_link\)')
        robot.command = (0.0, 0.0, 0.0)
        settle(out, state, (0.0, 0.0, 0.0), 'ALLOW zero command (no pose)')
        # The EKF is back: commands pass again.
        robot.ekf = True
        robot.command = (0.3, 0.0, 0.0)
        settle(out, state, (0.3, 0.0, 0.0), 'ALLOW')

        # A non-finite command stops.
        robot.command = (math.nan, 0.0, 0.0)
        settle(out, state, (0.0, 0.0, 0.0), 'STOP invalid command')
    finally:
        robot.stop()
    assert 'Traceback' not in system.output()


def test_without_a_zone_every_command_passes(start_system, test_node, tmp_path):
    test_node.start_clock()
    out = test_node.record(Twist, PARAMS['cmd_vel_out_topic'])
    state = test_node.record(String, PARAMS['state_topic'])
    system = start_system(str(write_launch(tmp_path, '')))
    system.wait_for_line(r'\[zone_guard\].*Zone guard started.*no zone declared')
    robot = Robot(test_node)            # no /tf at all: no pose needed
    robot.start()
    try:
        for command in [(0.3, 0.0, 0.0), (-5.0, 2.0, 3.0)]:
            robot.command = command
            settle(out, state, command, 'ALLOW no zone declared')
    finally:
        robot.stop()
    assert 'Traceback' not in system.output()


@pytest.mark.parametrize('arguments, message', [
    (['-p', 'horizon_s:=-1.0'], r'parameter horizon_s must be a finite number > 0'),
    (['-p', 'margin_m:=0.6'], r'parameter max_margin_m \(0.5\) must be >= margin_m \(0.6\)'),
    (['-p', 'pose_timeout_s:=0.0'], r'parameter pose_timeout_s must be a finite number > 0'),
    (['-p', 'max_position_sigma_m:=0.0'],
     r'parameter max_position_sigma_m must be a finite number > 0'),
    (['-p', 'zone_file:=/nonexistent/zone.yaml'],
     r'parameter zone_file: /nonexistent/zone.yaml: cannot read the zone file'),
])
def test_bad_parameters_stop_the_node_with_a_clear_message(ros_env, arguments, message):
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_safety', 'zone_guard', '--ros-args', *arguments],
        env=ros_env, capture_output=True, text=True, timeout=60, cwd=str(REPO))
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert 'Traceback' not in output
    assert re.search(r'\[FATAL\].*' + message, output), output


# --- the localisation's health, outside the zone, future-dated poses, zone files ---------

MAX_SIGMA = PARAMS['max_position_sigma_m']


def covariance36(xx, xy, yx, yy):
    """Return a 6x6 row-major pose covariance with this x-y block (yaw variance 0.01)."""
    values = [0.0] * 36
    values[0], values[1], values[6], values[7], values[35] = xx, xy, yx, yy, 0.01
    return values


def start_guard(start_system, test_node, tmp_path, zone_file=None, **parameters):
    """Start the zone guard in the 4 m square (zone_file None) and the robot at (2, 2)."""
    if zone_file is None:
        zone_file = tmp_path / 'zone.yaml'
        zone_file.write_text(SQUARE)
    test_node.start_clock()
    recorders = (test_node.record(Twist, PARAMS['cmd_vel_out_topic']),
                 test_node.record(String, PARAMS['state_topic']),
                 test_node.record(DiagnosticArray, '/diagnostics'))
    system = start_system(str(write_launch(tmp_path, str(zone_file), **parameters)))
    system.wait_for_line(r'\[zone_guard\].*Zone guard started')
    robot = Robot(test_node)
    robot.pose = (2.0, 2.0, 0.0)
    robot.start()
    return (system, robot, *recorders)


def test_an_unhealthy_localisation_stops_all_but_turning_until_healthy(
        start_system, test_node, tmp_path):
    system, robot, out, state, diagnostics = start_guard(start_system, test_node, tmp_path)
    try:
        robot.publish_sigma(0.03)                        # amcl's usual: healthy
        robot.command = (0.3, 0.0, 0.0)
        settle(out, state, (0.3, 0.0, 0.0), 'ALLOW')

        # NaN in the covariance: stopped, the state and the log say why.
        robot.publish_covariance([math.nan] * 36)
        settle(out, state, (0.0, 0.0, 0.0),
               'STOP localisation unhealthy: NaN/inf in the covariance (36 of 36 values)')
        system.wait_for_line(r'\[WARN\].*localisation unhealthy \(/amcl_pose\): NaN/inf in '
                             r'the covariance .*stopping every motion but turning on the spot')
        wait_for_diagnostics(diagnostics, DiagnosticStatus.ERROR, 'STOP localisation unhealthy')
        # Turning on the spot passes (it moves no footprint, and lets amcl update).
        robot.command = (0.0, 0.0, 0.5)
        settle(out, state, (0.0, 0.0, 0.5),
               'ALLOW turning on the spot (localisation unhealthy: NaN/inf in the covariance')
        # A ramped spin (the navigator's recovery through the smoother) keeps a decaying
        # translation while wz ramps up: only its rotation passes (it used to be stopped,
        # and a robot whose amcl had spread never turned, so amcl never recovered).
        robot.command = (0.02, -0.01, 0.3)
        settle(out, state, (0.0, 0.0, 0.3),
               'ALLOW turning on the spot (localisation unhealthy: NaN/inf in the covariance')
        robot.command = (0.1, 0.0, 0.3)
        settle(out, state, (0.0, 0.0, 0.0), 'STOP localisation unhealthy: NaN/inf in the covar')
        robot.command = (0.0, 0.0, 0.0)
        settle(out, state, (0.0, 0.0, 0.0),
               'ALLOW zero command (localisation unhealthy: NaN/inf in the covariance)')

        robot.command = (0.3, 0.0, 0.0)
        for covariance, position, why in [
                (covariance36(0.16, 0.0, 0.0, 0.01), (0.0, 0.0, 0.0),
                 f'position sigma 0.40 m > max_position_sigma_m {MAX_SIGMA:g} m'),
                (covariance36(0.01, 0.02, 0.02, 0.01), (0.0, 0.0, 0.0),
                 'covariance not positive semi-definite (eigenvalue -0.01)'),
                (covariance36(0.01, 0.002, 0.0, 0.01), (0.0, 0.0, 0.0),
                 'covariance not symmetric'),
                (covariance36(0.001, 0.0, 0.0, 0.001), (math.nan, 2.0, 0.0),
                 'NaN/inf in the pose')]:
            robot.publish_covariance(covariance, position)
            settle(out, state, (0.0, 0.0, 0.0), f'STOP localisation unhealthy: {why}')

        # Healthy values again: commands pass.
        robot.publish_sigma(0.03)
        settle(out, state, (0.3, 0.0, 0.0), 'ALLOW')
        system.wait_for_line(r'\[INFO\].*localisation healthy again \(/amcl_pose\)')
    finally:
        robot.stop()
    assert 'Traceback' not in system.output()


def test_slams_volatile_pose_topic_is_heard(start_system, test_node, tmp_path):
    """slam_toolbox publishes pose volatile: a transient-local subscription hears nothing."""
    system, robot, out, state, _ = start_guard(start_system, test_node, tmp_path,
                                               pose_covariance_topic='pose')
    slam = test_node.node.create_publisher(PoseWithCovarianceStamped, 'pose', 10)
    try:
        robot.command = (0.3, 0.0, 0.0)
        settle(out, state, (0.3, 0.0, 0.0), 'ALLOW')
        deadline = time.monotonic() + 20.0      # volatile: publish once it is matched
        while slam.get_subscription_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert slam.get_subscription_count() >= 1
        robot.publish_sigma(0.4, publisher=slam)
        settle(out, state, (0.0, 0.0, 0.0), 'STOP localisation unhealthy: position sigma 0.40')
        robot.publish_sigma(0.0, publisher=slam)      # SLAM's own: zeros
        settle(out, state, (0.3, 0.0, 0.0), 'ALLOW')
    finally:
        robot.stop()
    output = system.output()
    assert 'Traceback' not in output and 'incompatible' not in output.lower()


def test_outside_the_zone_only_motion_back_in_passes(start_system, test_node, tmp_path):
    system, robot, out, state, diagnostics = start_guard(start_system, test_node, tmp_path)
    robot.pose = (4.1, 2.0, 0.0)                     # the centre 0.1 m out of x = 4
    try:
        for command in [(0.0, 0.3, 0.0), (0.3, 0.0, 0.0), (-0.02, 0.4, 0.0)]:
            robot.command = command                  # along, out, nearly along
            settle(out, state, (0.0, 0.0, 0.0), 'STOP outside the zone')
        wait_for_diagnostics(diagnostics, DiagnosticStatus.ERROR, 'STOP outside the zone')
        for command in [(-0.3, 0.0, 0.0), (-0.2, 0.3, 0.0)]:
            robot.command = command
            settle(out, state, command, 'ALLOW back into the zone')
        robot.command = (0.0, 0.0, 1.0)
        settle(out, state, (0.0, 0.0, 1.0), 'ALLOW turning on the spot outside the zone')
    finally:
        robot.stop()
    assert 'Traceback' not in system.output()


def test_a_pose_stamped_in_the_future_is_not_trusted(start_system, test_node, tmp_path):
    """Stamped 2 s ahead, a pose would stay "fresh" 2 s after its publisher stopped."""
    system, robot, out, state, _ = start_guard(start_system, test_node, tmp_path)
    try:
        robot.command = (0.3, 0.0, 0.0)
        settle(out, state, (0.3, 0.0, 0.0), 'ALLOW')
        robot.future_s = 2.0
        settle(out, state, (0.0, 0.0, 0.0),
               'STOP no pose: map -> base_link stamped in the future (clock mismatch?)')
        system.wait_for_line(r'\[WARN\].*map -> base_link is stamped [0-9.]+ s in the future')
        robot.future_s = 0.0                          # once the clock has caught up: fresh
        settle(out, state, (0.3, 0.0, 0.0), 'ALLOW')
    finally:
        robot.stop()
    assert 'Traceback' not in system.output()


def test_with_require_zone_an_empty_zone_file_stops_everything(start_system, test_node,
                                                               tmp_path):
    """The real robot (real_robot.launch sets require_zone) never drives without a zone."""
    system, robot, out, state, diagnostics = start_guard(
        start_system, test_node, tmp_path, zone_file='', require_zone=True)
    try:
        system.wait_for_line(r'\[ERROR\].*zone_file is empty and require_zone is true.*'
                             r'zone_file:=unrestricted')
        for command in [(0.3, 0.0, 0.0), (0.0, 0.0, 1.0)]:
            robot.command = command
            settle(out, state, (0.0, 0.0, 0.0), 'STOP no zone file: give zone_file:=<zone '
                   'file> (see mecanum_safety/zones) or zone_file:=unrestricted')
        wait_for_diagnostics(diagnostics, DiagnosticStatus.ERROR, 'STOP no zone file')
    finally:
        robot.stop()
    assert 'Traceback' not in system.output()


def test_zone_file_unrestricted_is_no_zone_on_purpose(start_system, test_node, tmp_path):
    controller = {'node': {
        'pkg': 'robot_controller', 'exec': 'robot_control_node', 'name': 'robot_controller',
        'param': [{'from': '$(find-pkg-share mecanum_control)/config/motor_params.yaml'},
                  {'from': '$(find-pkg-share robot_controller)/config/robot_controller.yaml'},
                  {'name': 'zone_file', 'value': 'unrestricted'},
                  {'name': 'use_sim_time', 'value': True}]}}
    test_node.start_clock()
    out = test_node.record(Twist, PARAMS['cmd_vel_out_topic'])
    state = test_node.record(String, PARAMS['state_topic'])
    system = start_system(str(write_launch(tmp_path, 'unrestricted', [controller],
                                           require_zone=True)))
    system.wait_for_line(r'\[zone_guard\].*Zone guard started.*zone_file:=unrestricted')
    system.wait_for_line(r'\[robot_controller\].*Robot controller ready.*no authorised zone')
    robot = Robot(test_node)            # no /tf at all: no pose needed
    robot.start()
    try:
        robot.command = (0.3, 0.0, 0.0)
        settle(out, state, (0.3, 0.0, 0.0), 'ALLOW unrestricted (no zone)')
    finally:
        robot.stop()
    assert 'Traceback' not in system.output()


def test_the_navigator_reads_unrestricted_as_no_zone():
    from mecanum_navigation.navigator.navigator_node import NavigatorNode
    assert NavigatorNode._load_zone('unrestricted') is None
    assert NavigatorNode._load_zone('') is None


def test_a_jump_of_the_localisation_stops_until_the_pose_is_set(start_system, test_node,
                                                                 tmp_path):
    """
    A respawned amcl starting from its initial pose makes map -> odom jump: latched.

    Found by the fault sweep (amcl killed near the border): the new amcl was sure of
    the start pose, 1.2 m from the robot, and the zone guard let the robot out of the
    zone. The guard cannot tell which estimate is right: it stops all but turning on
    the spot until the pose is set on /initialpose.
    """
    system, robot, out, state, diagnostics = start_guard(start_system, test_node, tmp_path)
    initial_pose = test_node.node.create_publisher(PoseWithCovarianceStamped, 'initialpose',
                                                   10)
    try:
        robot.publish_sigma(0.03)
        robot.command = (0.3, 0.0, 0.0)
        settle(out, state, (0.3, 0.0, 0.0), 'ALLOW')
        # The localisation changes its mind by 1.2 m (the robot itself did not move),
        # with a healthy covariance: the covariance check alone would let it drive.
        robot.map_to_odom = PlanarTransform(MAP_TO_ODOM.x + 1.2, MAP_TO_ODOM.y,
                                            MAP_TO_ODOM.yaw)
        robot.pose = (3.2, 2.0, 0.0)
        settle(out, state, (0.0, 0.0, 0.0), 'STOP localisation unhealthy: localisation '
               'jumped 1.20 m')
        system.wait_for_line(r'\[ERROR\].*localisation jumped 1.20 m, 0 deg at once')
        wait_for_diagnostics(diagnostics, DiagnosticStatus.ERROR, 'STOP localisation')
        robot.command = (0.0, 0.0, 0.5)     # turning on the spot still passes
        settle(out, state, (0.0, 0.0, 0.5), 'ALLOW turning on the spot (localisation '
               'unhealthy: localisation jumped')
        robot.publish_sigma(0.03)            # a healthy covariance does not clear it
        robot.command = (0.3, 0.0, 0.0)
        settle(out, state, (0.0, 0.0, 0.0), 'STOP localisation unhealthy: localisation '
               'jumped')
        # The operator sets the pose: cleared; commands pass.
        deadline = time.monotonic() + 20.0
        while initial_pose.get_subscription_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.02)
        initial_pose.publish(PoseWithCovarianceStamped())
        system.wait_for_line(r'pose set on /initialpose: the localisation jump is cleared')
        settle(out, state, (0.3, 0.0, 0.0), 'ALLOW')
    finally:
        robot.stop()
    assert 'Traceback' not in system.output()


def test_the_scenario_runner_hears_whether_the_zone_guard_has_a_pose(
        start_system, test_node, ros_env, tmp_path):
    """
    The runner starts a scenario's first step only once the zone guard has a pose.

    It reads the guard's /diagnostics (ScenarioDriver.zone_guard_pose): without /tf the
    guard says why it has none, with map -> odom -> base_link it gives the pose. A first
    text command once went out before the guard's process had amcl's transform and was
    stopped ('no transform map -> base_link').
    """
    from mecanum_bringup.scenario_driver import ScenarioDriver
    zone_file = tmp_path / 'zone.yaml'
    zone_file.write_text(SQUARE)
    test_node.start_clock()
    system = start_system(str(write_launch(tmp_path, str(zone_file))))
    system.wait_for_line(r'\[zone_guard\].*Zone guard started')
    driver = ScenarioDriver(int(ros_env['ROS_DOMAIN_ID']))
    robot = Robot(test_node)
    robot.start()
    try:
        def heard(prefix: str) -> bool:
            deadline = time.monotonic() + 20.0
            while time.monotonic() < deadline:
                if (driver.zone_guard_pose() or '').startswith(prefix):
                    return True
                time.sleep(0.05)
            return False

        assert heard('no pose: no transform map -> base_link'), driver.zone_guard_pose()
        robot.pose = (2.0, 2.0, 0.0)
        assert heard('(2.00, 2.00, 0.00)'), driver.zone_guard_pose()
        driver.stop_watching_diagnostics()
    finally:
        robot.stop()
        driver.close()
    assert 'Traceback' not in system.output()
