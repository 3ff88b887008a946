"""
Integration: each node takes its run-time parameters at once, refuses the rest, says why.

Each test creates the real node in the test process (its own rclpy context in the test's
leased ROS domain, spun by the executor its process uses, mecanum_control.node_main's)
beside a client node, and talks to it through rclpy's AsyncParameterClient, i.e. the
node's ~/set_parameters, ~/set_parameters_atomically and ~/describe_parameters services,
as `ros2 param` does: a run-time parameter set takes effect (the node's applied value,
or what it does), an invalid value and a read-only parameter are refused with the
reason, and describe shows read_only with the reason. The helper's rules themselves:
src/mecanum_control/test/test_runtime_parameters.py.
"""

import math
import os
from pathlib import Path
import threading
import time

from geometry_msgs.msg import PoseWithCovarianceStamped
from mecanum_control.motor_controller import MotorController
from mecanum_control.node_main import make_executor
from mecanum_control.parameters import robot_config_read_only_reason
from mecanum_control.velocity_controller import VelocityController
from mecanum_navigation.controller.velocity_smoother_node import VelocitySmootherNode
from mecanum_safety.collision_monitor_node import CollisionMonitorNode
from mecanum_safety.zone_guard_node import ZoneGuardNode
import pytest
import rclpy
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, QoSProfile
from robot_controller.robot_control_node import RobotController
import yaml

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
ZONE_REASON = ('restart to change the authorised zone: a zone that changes under a running '
               'robot is not what an operator expects')


def file_parameters(package: str, name: str, node: str) -> list:
    """Return the node's section of a config file as rclpy Parameters (nested: a.b)."""
    section = yaml.safe_load((REPO / 'src' / package / 'config' / name).read_text())
    parameters = []

    def walk(prefix, value):
        if isinstance(value, dict):
            for key, item in value.items():
                walk(f'{prefix}{key}.', item)
        else:
            parameters.append(Parameter(prefix[:-1], value=value))
    walk('', section[node]['ros__parameters'])
    return parameters


class InProcess:
    """One node of the workspace and a parameter client of it, spun in a thread."""

    def __init__(self, node_class, domain_id: int, overrides=()):
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = node_class(context=self.context, parameter_overrides=list(overrides))
        self.client_node = rclpy.create_node('parameter_test_client', context=self.context)
        self.executor = make_executor(self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.client_node)
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()
        self.client = AsyncParameterClient(self.client_node, self.node.get_name())
        assert self.client.wait_for_services(timeout_sec=30.0), 'no parameter services'

    def _spin(self):
        while self.context.ok() and not self._closing.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    @staticmethod
    def result(future, timeout: float = 20.0):
        """Wait for a service call's future; return its response."""
        deadline = time.monotonic() + timeout
        while not future.done():
            assert time.monotonic() < deadline, 'no answer from the parameter service'
            time.sleep(0.01)
        return future.result()

    def set_one(self, name: str, value):
        """Set one parameter (as `ros2 param set` does); return its SetParametersResult."""
        response = self.result(self.client.set_parameters([Parameter(name, value=value)]))
        assert len(response.results) == 1
        return response.results[0]

    def set_atomically(self, **values):
        """Set parameters in one set_parameters_atomically call; return its result."""
        return self.result(self.client.set_parameters_atomically(
            [Parameter(name, value=value) for name, value in values.items()])).result

    def get(self, name: str):
        """Return a parameter's value as the node's service gives it."""
        return parameter_value_to_python(
            self.result(self.client.get_parameters([name])).values[0])

    def describe(self, name: str):
        """Return a parameter's descriptor (`ros2 param describe`)."""
        return self.result(self.client.describe_parameters([name])).descriptors[0]

    def wait_until(self, condition, timeout: float = 20.0):
        """Wait until condition() holds (the node's thread changes what it looks at)."""
        deadline = time.monotonic() + timeout
        while not condition():
            assert time.monotonic() < deadline, 'the condition never held'
            time.sleep(0.01)

    def close(self):
        self._closing.set()
        self._thread.join(timeout=5)
        close = getattr(self.node, 'close', None)
        if close is not None:
            close()
        self.executor.shutdown()
        self.client_node.destroy_node()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def start_node(ros_env):
    """Return start(node_class, overrides) -> InProcess, in the test's leased domain."""
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    started = []

    def start(node_class, overrides=()):
        started.append(InProcess(node_class, int(ros_env['ROS_DOMAIN_ID']), overrides))
        return started[-1]
    yield start
    for each in started:
        each.close()


def assert_refused(result, reason: str):
    assert not result.successful
    assert result.reason == reason


def assert_read_only(running: InProcess, name: str, reason: str, value):
    """Check that a set of name is refused with the reason; describe says why."""
    before = running.get(name)
    assert_refused(running.set_one(name, value), f'{name} is read-only: {reason}')
    assert running.get(name) == before
    descriptor = running.describe(name)
    assert descriptor.read_only
    assert descriptor.description == f'read-only: {reason}'


def test_robot_controller(start_node):
    running = start_node(RobotController)
    node = running.node
    # A run-time parameter: taken at once (the next command's default speed).
    assert node.limits.linear_speed_mps == 0.2
    assert running.set_one('linear_speed_mps', 0.3).successful
    assert node.limits.linear_speed_mps == 0.3
    assert running.get('linear_speed_mps') == 0.3
    # An integer, as `ros2 param set ... 1` sends it, counts as 1.0.
    assert running.set_one('default_duration_s', 1).successful
    assert node.limits.default_duration_s == 1.0
    # The timer follows publish_rate_hz.
    assert running.set_one('publish_rate_hz', 10.0).successful
    assert node.timer.timer_period_ns == 100_000_000
    # Invalid values: refused with the start-up check's words; nothing changes.
    assert_refused(running.set_one('linear_speed_mps', -1.0),
                   'linear_speed_mps must be > 0, got -1.0')
    assert_refused(running.set_one('linear_speed_mps', 0.6),
                   'linear_speed_mps (0.6) must be <= max_linear_speed_mps (0.5)')
    assert_refused(running.set_one('publish_rate_hz', 0.0),
                   'publish_rate_hz must be positive and finite, got 0.0')
    assert node.limits.linear_speed_mps == 0.3 and running.get('linear_speed_mps') == 0.3
    # chain_start_timeout_s >= blocked_time_s: one at a time it is refused, together not.
    assert_refused(running.set_one('blocked_time_s', 6.0),
                   'chain_start_timeout_s must be finite and >= blocked_time_s (6.0), got 5.0')
    assert running.set_atomically(blocked_time_s=6.0, chain_start_timeout_s=7.0).successful
    assert (node.detector.blocked_time_s, node.detector.start_timeout_s) == (6.0, 7.0)
    # One bad value refuses the whole atomic set.
    assert_refused(running.set_atomically(zone_margin_m=0.1, blocked_speed_ratio=1.5),
                   'blocked_speed_ratio must be within (0, 1), got 1.5')
    assert node.zone_margin_m == 0.05 and node.detector.blocked_speed_ratio == 0.1
    # Read-only parameters, and why.
    assert_read_only(running, 'zone_file', ZONE_REASON, '/tmp/other_zone.yaml')
    assert_read_only(running, 'footprint_radius_m',
                     robot_config_read_only_reason('footprint_radius_m'), 0.1)
    assert running.describe('footprint_radius_m').description.startswith(
        "read-only: the robot's geometry from motor_params.yaml")
    run_time = running.describe('linear_speed_mps')
    assert not run_time.read_only
    assert run_time.description.startswith('settable at run time')
    # use_sim_time stays settable (rclpy's).
    assert running.set_one('use_sim_time', False).successful


def test_velocity_controller(start_node):
    running = start_node(VelocityController)
    node = running.node
    assert running.set_one('kp', 0.05).successful
    assert [pid.gains.kp for pid in node.pids] == [0.05] * 4
    assert running.set_atomically(ki=0.5, max_effort=0.8).successful
    assert all((pid.gains.ki, pid.gains.max_effort) == (0.5, 0.8) for pid in node.pids)
    assert running.set_one('stall_time_s', 1.0).successful
    assert [stall.config.time_s for stall in node.stall_detectors] == [1.0] * 4
    assert running.set_one('measurement_timeout_s', 0.5).successful
    assert node.measurement_timeout_s == 0.5
    assert_refused(running.set_one('kp', -1.0), 'kp must be a finite number >= 0, got -1.0')
    assert_refused(running.set_one('max_effort', 1.5),
                   'max_effort must be in (0, 1] (PWM duty), got 1.5')
    assert_refused(running.set_one('stall_effort_threshold', 'high'),
                   "stall_effort_threshold must be a number, got 'high'")
    assert [pid.gains.kp for pid in node.pids] == [0.05] * 4
    assert_read_only(running, 'wheel_radius_m', (
        "the robot's geometry from motor_params.yaml, shared by the controller, the "
        'simulator and the firmware; edit the file and restart'), 0.1)
    assert_read_only(running, 'control_rate_hz', (
        "the control loop's rate, which the gains were tuned at; restart the node to "
        'change it'), 100.0)


def test_motor_controller(start_node):
    running = start_node(MotorController)
    node = running.node
    assert node.core.cmd_timeout_s == 0.5
    assert running.set_one('cmd_timeout_s', 1.5).successful
    assert node.core.cmd_timeout_s == 1.5
    assert_refused(running.set_one('cmd_timeout_s', 0.0),
                   'cmd_timeout_s must be finite and > 0, got 0.0')
    assert node.core.cmd_timeout_s == 1.5
    # The limits: twist_mux applies them before the chain judges a twist.
    reason = robot_config_read_only_reason('max_velocity_x_m_s')
    assert 'twist_mux' in reason and 'did not judge' in reason
    assert_read_only(running, 'max_velocity_x_m_s', reason, 2.0)
    assert running.describe('absurd_factor').read_only
    assert not running.set_one('absurd_factor', 100.0).successful


def test_collision_monitor(start_node):
    running = start_node(CollisionMonitorNode, file_parameters(
        'mecanum_safety', 'collision_monitor.yaml', 'collision_monitor'))
    node = running.node

    def zone(name):
        return next(zone for zone in node.monitor.zones if zone.name == name)
    assert running.set_one('source_timeout', 0.5).successful
    assert node.monitor.source_timeout == 0.5
    assert running.set_one('max_identical_scans', 8).successful
    assert node.monitor.max_identical_scans == 8
    assert running.set_one('PolygonLimit.linear_limit', 0.1).successful
    assert zone('PolygonLimit').linear_limit == 0.1
    # A zone keeps its shape and action; the new limit acts from the next command on.
    assert (zone('PolygonLimit').radius, zone('PolygonLimit').action_type) == (0.35, 'limit')
    assert running.set_one('FootprintApproach.time_before_collision', 2.0).successful
    assert zone('FootprintApproach').time_before_collision == 2.0
    # Outside the validated ranges: refused.
    assert_refused(running.set_one('PolygonLimit.slowdown_ratio', 2.0),
                   'PolygonLimit.slowdown_ratio must be finite and >= 0 and <= 1, got 2.0')
    assert_refused(running.set_one('FootprintApproach.time_before_collision', 0.0),
                   'FootprintApproach.time_before_collision must be finite and > 0, got 0.0')
    assert_refused(running.set_one('source_timeout', -1.0),
                   'source_timeout must be finite and > 0, got -1.0')
    assert zone('FootprintApproach').time_before_collision == 2.0
    assert node.monitor.source_timeout == 0.5
    zone_reason = ("a zone's shape, action and whether it acts are the safety design "
                   '(config/collision_monitor.yaml), not a tuning: edit the file and restart')
    assert_read_only(running, 'PolygonStop.radius', zone_reason, 0.1)
    assert_read_only(running, 'PolygonStop.enabled', zone_reason, False)
    assert not running.set_one('scan.enabled', False).successful
    assert not running.set_one('polygons', ['PolygonLimit']).successful


def test_zone_guard(start_node):
    running = start_node(ZoneGuardNode, [Parameter('max_position_sigma_m', value=0.25)])
    node = running.node
    assert running.set_one('margin_m', 0.1).successful
    assert node.guard.margin_m == 0.1
    assert running.set_one('pose_timeout_s', 1.0).successful
    assert node.pose_timeout_s == 1.0
    assert running.set_one('max_localisation_jump_m', 1.0).successful
    assert node.jumps.max_jump_m == 1.0
    assert_refused(running.set_one('max_margin_m', 0.05),
                   'max_margin_m (0.05) must be >= margin_m (0.1)')
    assert_refused(running.set_one('pose_timeout_s', 0.0),
                   'pose_timeout_s must be a finite number > 0, got 0.0')
    assert node.guard.max_margin_m == 0.5 and node.pose_timeout_s == 1.0
    # max_position_sigma_m: the last pose covariance is judged again at once.
    publisher = running.client_node.create_publisher(
        PoseWithCovarianceStamped, 'amcl_pose',
        QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = 'map'
    msg.pose.pose.orientation.w = 1.0
    msg.pose.covariance[0] = msg.pose.covariance[7] = 0.3 ** 2   # sigma 0.3 m > 0.25 m
    msg.pose.covariance[35] = 0.01
    publisher.publish(msg)
    running.wait_until(lambda: node.localisation is not None)
    assert 'position sigma' in node.localisation.text
    assert running.set_one('max_position_sigma_m', 0.35).successful
    assert node.guard.max_position_sigma_m == 0.35 and node.localisation is None
    assert_read_only(running, 'zone_file', ZONE_REASON, '/tmp/other_zone.yaml')
    assert_read_only(running, 'require_zone', ZONE_REASON, True)


def test_velocity_smoother(start_node):
    running = start_node(VelocitySmootherNode)
    node = running.node
    assert running.set_one('max_velocity', [0.3, 0.2, 1.0]).successful
    params = node.smoother.params
    assert params.max_velocity == (0.3, 0.2, 1.0)
    assert params.min_velocity == (-0.3, -0.2, -1.0)   # min_velocity unset: -max_velocity
    assert running.set_one('smoothing_frequency', 10.0).successful
    assert node.timer.timer_period_ns == 100_000_000
    assert node.smoother.params.max_velocity == (0.3, 0.2, 1.0)
    assert_refused(running.set_one('max_decel', [1.0, -1.0, -1.0]),
                   'max_decel linear.x must be finite and < 0, got 1.0')
    assert_refused(running.set_one('max_accel', [1.0, 1.0]),
                   'max_accel must be 3 numbers [vx, vy, wz], got [1.0, 1.0]')
    assert math.isclose(node.smoother.params.max_decel[0], -1.5)
    assert_read_only(running, 'feedback', (
        'a topic, frame or mode the node wired up when it started (subscriptions, '
        'publishers, transform lookups); restart the node to change it'), 'CLOSED_LOOP')


def test_navigator_controller_limits(start_node):
    from mecanum_navigation.navigator.navigator_node import NavigatorNode
    running = start_node(NavigatorNode, file_parameters(
        'mecanum_navigation', 'nav2_params.yaml', 'navigator'))
    node = running.node
    before = node.navigator.controller
    assert running.set_one('controller.max_vel_x', 0.3).successful
    params = node.navigator.controller.params
    assert node.navigator.controller is not before
    assert (params.max_vel_x, params.min_vel_x) == (0.3, -0.3)
    assert params.max_vel_y == before.params.max_vel_y
    assert running.set_one('controller.xy_goal_tolerance', 0.1).successful
    assert node.navigator.controller.params.xy_goal_tolerance == 0.1
    assert node.navigator.controller.params.max_vel_x == 0.3
    refused = running.set_one('controller.max_vel_y', 5.0)
    assert not refused.successful
    assert refused.reason.startswith('controller.max_vel_y (5) exceeds the robot limit '
                                     'max_velocity_y_m_s'), refused.reason
    assert_refused(running.set_one('controller.max_vel_theta', -1.0),
                   'controller.max_vel_theta must be finite and > 0, got -1.0')
    assert_read_only(running, 'planner.tolerance',
                     'read once when the node starts; restart the node to change it', 0.5)


#: The reason a node with nothing to change at run time gives (runtime_parameters).
RESTART_REASON = 'read once when the node starts; restart the node to change it'


@pytest.mark.parametrize('package, module, class_name, config, section, name, value, reason', [
    ('robot_simulation', 'simulation_node', 'RobotSimulation', None, None,
     'cmd_timeout_s', 2.0, RESTART_REASON),
    ('mecanum_safety', 'twist_mux_node', 'TwistMuxNode', 'twist_mux.yaml', 'twist_mux',
     'topics.navigation.timeout', 5.0, "the mux's inputs, subscribed when it started (as "
     "twist_mux's); restart twist_mux to change them"),
    ('mecanum_localization', 'ekf_node', 'EkfNode', 'ekf.yaml', 'ekf_filter_node',
     'frequency', 10.0, RESTART_REASON),
    ('mecanum_control', 'encoder_reader', 'EncoderReader', None, None,
     'wheel_radius_m', 0.1, robot_config_read_only_reason('wheel_radius_m')),
])
def test_a_node_without_run_time_parameters_refuses_every_set(
        start_node, package, module, class_name, config, section, name, value, reason):
    # Before, such a set was accepted and changed nothing.
    import importlib
    node_class = getattr(importlib.import_module(f'{package}.{module}'), class_name)
    overrides = file_parameters(package, config, section) if config else ()
    running = start_node(node_class, overrides)
    if name == 'wheel_radius_m':   # declared read-only with motor_params.yaml's reason
        assert_refused(running.set_one(name, value), f'{name} is read-only: {reason}')
        assert running.describe(name).read_only
    else:
        assert_read_only(running, name, reason, value)
