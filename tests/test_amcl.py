"""
Integration: the amcl node localising the robot in the apartment, in real processes.

The system (a launch file written here): map_server serving maps/apartment.yaml,
robot_simulation's kinematic simulation_node (cmd_vel -> odom and odom -> base_link on
/tf; its odom frame starts at the world's robot_start, so the truth is robot_start
composed with its odometry: no slip) and amcl with config/amcl.yaml, all on sim time.
The test node drives /clock, publishes the laser mount (motor_params.yaml) on /tf_static
and, for every new odometry message (about every 0.1 s), a scan of robot_simulation's
lidar in the apartment world taken at the true pose, stamped with the odometry's time.
The respawn test also lets the launch runner respawn a killed amcl.
"""

import math
import os
from pathlib import Path
import re
import signal
import subprocess
import threading
import time

from geometry_msgs.msg import PoseArray, PoseWithCovarianceStamped, TransformStamped, Twist
from mecanum_bringup.system_description import load_system
from mecanum_control.angles import quaternion_from_yaw, wrap_angle, yaw_from_quaternion
from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_localization.transforms import PlanarTransform
from nav_msgs.msg import Odometry
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile
from robot_simulation.sensors import Lidar, LidarConfig
from robot_simulation.world import find_world, load_world
from sensor_msgs.msg import LaserScan
from std_srvs.srv import Empty
from tests.conftest import OutputProcess
from tf2_msgs.msg import TFMessage
import yaml

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
AMCL_PARAMS = yaml.safe_load((REPO / 'src/mecanum_navigation/config/amcl.yaml').read_text())[
    'amcl']['ros__parameters']
ROBOT = load_robot_config(default_config_path())
WORLD = load_world(find_world('apartment'))
START = PlanarTransform(*WORLD.robot_start)


def write_launch(directory: Path, amcl_params=(), respawn: bool = False) -> Path:
    """
    Write the test system: map_server, simulation_node, amcl (config/amcl.yaml).

    amcl_params: (name, value) pairs for amcl after its file; respawn: the launch
    runner restarts amcl when it exits (as localization.launch.yaml does), after 1 s.
    """
    amcl = {'pkg': 'mecanum_navigation', 'exec': 'amcl', 'name': 'amcl',
            'param': [{'from': '$(find-pkg-share mecanum_navigation)/config/amcl.yaml'},
                      {'name': 'use_sim_time', 'value': True},
                      *({'name': name, 'value': value} for name, value in amcl_params)]}
    if respawn:
        amcl.update({'respawn': 'true', 'respawn_delay': 1.0})
    launch = {'launch': [
        {'node': {'pkg': 'mecanum_map_server', 'exec': 'map_server', 'name': 'map_server',
                  'param': [{'name': 'yaml_filename', 'value': 'apartment'},
                            {'name': 'use_sim_time', 'value': True}]}},
        {'node': {'pkg': 'robot_simulation', 'exec': 'simulation_node',
                  'name': 'robot_simulation',
                  'param': [{'name': 'use_sim_time', 'value': True}]}},
        {'node': amcl},
    ]}
    path = directory / 'amcl_test.launch.yaml'
    path.write_text(yaml.safe_dump(launch, sort_keys=False))
    return path


def odometry_pose(msg: Odometry) -> PlanarTransform:
    """Return an Odometry message's planar pose."""
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    return PlanarTransform(p.x, p.y, yaw_from_quaternion(q.x, q.y, q.z, q.w))


class LidarSimulator:
    """Publishes, for each new odometry message, the scan seen from the true pose."""

    def __init__(self, test_node, odometry):
        """Build the lidar in the apartment world and start publishing."""
        self.odometry = odometry
        self.lidar = Lidar(LidarConfig(mount_x_m=ROBOT.lidar_mount_x_m,
                                       mount_y_m=ROBOT.lidar_mount_y_m,
                                       mount_yaw_rad=ROBOT.lidar_mount_yaw_rad),
                           WORLD.segments, seed=0)
        self.circles = np.array([(c.center[0], c.center[1], c.radius_m)
                                 for c in WORLD.circles]).reshape(-1, 3)
        self.publisher = test_node.node.create_publisher(LaserScan, 'scan', 10)
        self.stop = threading.Event()
        threading.Thread(target=self._run, daemon=True).start()

    def _run(self):
        last_stamp = None
        while not self.stop.wait(0.1):
            msg = self.odometry.latest()
            if msg is None or msg.header.stamp == last_stamp:
                continue
            last_stamp = msg.header.stamp
            truth = START.compose(odometry_pose(msg))
            scan = LaserScan()
            scan.header.stamp = msg.header.stamp
            scan.header.frame_id = 'laser'
            for name, value in self.lidar.scan_fields().items():
                setattr(scan, name, value)
            scan.ranges = self.lidar.scan(truth.x, truth.y, truth.yaw, self.circles).tolist()
            try:
                self.publisher.publish(scan)
            except Exception:  # noqa: B902 - the test node shut down
                return


def start_simulated_sensors(test_node):
    """
    Start the test clock, publish the laser mount and simulate the lidar.

    Returns the odometry recorder and the LidarSimulator (stop it at the end).
    """
    test_node.start_clock()
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    static = test_node.node.create_publisher(TFMessage, '/tf_static', latched)
    mount = TransformStamped()
    mount.header.frame_id, mount.child_frame_id = 'base_link', 'laser'
    mount.transform.translation.x = ROBOT.lidar_mount_x_m
    mount.transform.translation.y = ROBOT.lidar_mount_y_m
    r = mount.transform.rotation
    r.x, r.y, r.z, r.w = quaternion_from_yaw(ROBOT.lidar_mount_yaw_rad)
    static.publish(TFMessage(transforms=[mount]))
    odometry = test_node.record(Odometry, 'odom')
    return odometry, LidarSimulator(test_node, odometry)


def drive(test_node, cmd_pub, vx, vy, wz, seconds):
    """Command (vx, vy, wz) for a span of simulated time."""
    end = test_node.clock_ns + int(seconds * 1e9)
    while test_node.clock_ns < end:
        twist = Twist()
        twist.linear.x, twist.linear.y, twist.angular.z = vx, vy, wz
        cmd_pub.publish(twist)
        time.sleep(0.05)


def stamp_s(stamp) -> float:
    """Return a message stamp in seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def pose_of(msg: PoseWithCovarianceStamped) -> PlanarTransform:
    """Return an amcl_pose message's planar pose."""
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    return PlanarTransform(p.x, p.y, yaw_from_quaternion(q.x, q.y, q.z, q.w))


def initial_pose(x, y, yaw, variances):
    """Return a PoseWithCovarianceStamped in map with x, y, yaw variances."""
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = 'map'
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    q = msg.pose.pose.orientation
    q.x, q.y, q.z, q.w = quaternion_from_yaw(yaw)
    covariance = [0.0] * 36
    covariance[0], covariance[7], covariance[35] = variances
    msg.pose.covariance = covariance
    return msg


def wait_until(predicate, timeout=30.0, what='condition'):
    """Poll predicate until it is true."""
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f'{what}: not within {timeout} s'
        time.sleep(0.02)


def test_amcl_localises_the_robot_from_a_wrong_initial_pose(
        start_system, test_node, tmp_path):
    """
    Nothing before an initial pose; from 0.5 m / 30 deg off, within 10 cm / 5 deg.

    Then amcl_pose and particle_cloud are published, a NaN covariance is refused, and
    reinitialize_global_localization spreads max_particles over the apartment.
    """
    odometry, lidar = start_simulated_sensors(test_node)
    poses = test_node.record(PoseWithCovarianceStamped, 'amcl_pose')
    clouds = test_node.record(PoseArray, 'particle_cloud')
    transforms = test_node.record(TFMessage, '/tf')
    initial_pub = test_node.node.create_publisher(PoseWithCovarianceStamped, 'initialpose', 10)
    cmd_pub = test_node.node.create_publisher(Twist, 'cmd_vel', 10)
    system = start_system(str(write_launch(tmp_path)))
    try:
        system.wait_for_line(r'\[amcl\].*Received a 220 x 180 map at 0.05 m/cell', 60.0)
        system.wait_for_line(r'\[amcl\].*waiting for an initial pose on /initialpose', 30.0)

        def map_to_odom():
            for msg in reversed(list(transforms.since(0.0))):
                for t in msg.transforms:
                    if t.header.frame_id == 'map' and t.child_frame_id == 'odom':
                        q = t.transform.rotation
                        return PlanarTransform(t.transform.translation.x,
                                               t.transform.translation.y,
                                               yaw_from_quaternion(q.x, q.y, q.z, q.w))
            return None

        # Nav2: nothing before an initial pose.
        assert poses.latest() is None and clouds.latest() is None and map_to_odom() is None

        wait_until(lambda: initial_pub.get_subscription_count() > 0, what='amcl subscribed')
        initial_pub.publish(initial_pose(3.0, 2.0, 0.0, (0.25, math.nan, 0.25)))
        system.wait_for_line(r'\[amcl\].*WARN.*ignoring an initial pose: initial covariance '
                             r'must be a finite 3x3 matrix')
        guess = START.compose(PlanarTransform(0.5 * math.cos(2.0), 0.5 * math.sin(2.0),
                                              math.radians(30.0)))
        initial_pub.publish(initial_pose(guess.x, guess.y, guess.yaw,
                                         (0.25, 0.25, math.radians(30.0) ** 2)))
        system.wait_for_line(r'\[amcl\].*Setting pose: \(2\.7\d\d, 2\.4\d\d, 0\.524\) in map')
        poses.wait_for(lambda msg: True, timeout=20.0)

        drive(test_node, cmd_pub, 0.3, 0.0, 0.3, 3.0)
        drive(test_node, cmd_pub, 0.0, 0.25, -0.3, 3.0)
        drive(test_node, cmd_pub, 0.0, 0.0, 0.0, 1.0)   # stopped: the last scans republish
        odom = odometry_pose(odometry.latest())
        truth = START.compose(odom)
        assert math.hypot(truth.x - START.x, truth.y - START.y) > 0.8   # it did move
        estimate = map_to_odom().compose(odom)
        error_m = math.hypot(estimate.x - truth.x, estimate.y - truth.y)
        error_deg = math.degrees(abs(wrap_angle(estimate.yaw - truth.yaw)))
        print(f'amcl error: {error_m:.3f} m, {error_deg:.2f} deg')
        assert error_m < 0.1 and error_deg < 5.0, (error_m, error_deg)

        pose = poses.latest()
        assert pose.header.frame_id == 'map'
        p = pose.pose.pose.position
        assert math.hypot(p.x - truth.x, p.y - truth.y) < 0.1 + AMCL_PARAMS['update_min_d']
        covariance = np.array(pose.pose.covariance).reshape(6, 6)
        assert np.isfinite(covariance).all()
        assert 0.0 < covariance[0, 0] < 0.01 and 0.0 < covariance[5, 5] < 0.01
        cloud = clouds.latest()
        assert cloud.header.frame_id == 'map'
        count = len(cloud.poses)
        assert AMCL_PARAMS['min_particles'] <= count <= AMCL_PARAMS['max_particles']
        xs = [q.position.x for q in cloud.poses]
        assert max(xs) - min(xs) < 1.0

        client = test_node.node.create_client(Empty, 'reinitialize_global_localization')
        before = time.monotonic()
        test_node.call(client, Empty.Request())
        system.wait_for_line(r'\[amcl\].*Initializing with a uniform distribution of 2000')
        wait_until(lambda: any(len(msg.poses) == AMCL_PARAMS['max_particles']
                               for msg in clouds.since(before)), what='the spread particles')
        spread = next(msg for msg in clouds.since(before)
                      if len(msg.poses) == AMCL_PARAMS['max_particles'])
        xs = [q.position.x for q in spread.poses]
        ys = [q.position.y for q in spread.poses]
        assert max(xs) - min(xs) > 8.0 and max(ys) - min(ys) > 6.0
        assert system.stop() == 0
        match = re.search(r'filter update: ([\d.]+) ms mean', system.output())
        assert match, system.output()
        print(f'amcl filter update (with publishing): {match.group(1)} ms mean')
    finally:
        lidar.stop.set()
        print(system.output())   # shown by pytest when the test failed


def test_a_respawned_amcl_resumes_where_the_last_one_was(start_system, test_node, tmp_path):
    """
    The fault sweep's bug: amcl killed away from its start, respawned sure of the start.

    amcl starts from set_initial_pose at the robot's start with a small spread (as the
    scenarios do), follows the robot 1 m away and is killed (SIGKILL); the robot moves
    on while it is dead and the launch runner respawns it with the same parameters. The
    new amcl must resume from its pose_state_file (the last map -> odom composed with the
    current odometry): its first amcl_pose within 0.1 m and 5 deg of the truth, not at
    the start pose set_initial_pose gives again.
    """
    odometry, lidar = start_simulated_sensors(test_node)
    poses = test_node.record(PoseWithCovarianceStamped, 'amcl_pose')
    cmd_pub = test_node.node.create_publisher(Twist, 'cmd_vel', 10)
    state_file = tmp_path / 'amcl_pose_state.yaml'
    system = start_system(str(write_launch(tmp_path, [
        ('set_initial_pose', True), ('initial_pose.x', START.x), ('initial_pose.y', START.y),
        ('initial_pose.yaw', START.yaw), ('initial_pose.std_xy', 0.05),
        ('initial_pose.std_yaw', 0.05), ('pose_state_file', str(state_file)),
        ('save_pose_period_s', 1.0)], respawn=True)))

    def truth_at(stamp) -> PlanarTransform:
        """Return the true pose at a scan's stamp (from the odometry it was taken with)."""
        wait_until(lambda: odometry.messages_between(stamp_s(stamp), math.inf),
                   what='odometry of that time')
        msg = min(odometry.messages_between(stamp_s(stamp) - 0.2, stamp_s(stamp) + 0.2),
                  key=lambda m: abs(stamp_s(m.header.stamp) - stamp_s(stamp)))
        return START.compose(odometry_pose(msg))

    try:
        system.wait_for_line(
            r'\[amcl\].*Setting pose \(set_initial_pose\): \(2\.950, 2\.000,', 60.0)
        poses.wait_for(lambda msg: True, timeout=60.0)
        drive(test_node, cmd_pub, 0.3, 0.0, 0.2, 4.0)
        drive(test_node, cmd_pub, 0.0, 0.0, 0.0, 0.5)
        away = poses.wait_for(lambda msg: math.hypot(msg.pose.pose.position.x - START.x,
                                                     msg.pose.pose.position.y - START.y) > 0.9)
        truth = truth_at(away.header.stamp)
        assert math.hypot(pose_of(away).x - truth.x, pose_of(away).y - truth.y) < 0.1

        os.kill(system.node_pid('amcl'), signal.SIGKILL)
        system.wait_for_line(r'\[runner\] respawning amcl in 1 s')
        drive(test_node, cmd_pub, 0.0, 0.3, 0.0, 1.5)    # while amcl is dead (or starting)
        drive(test_node, cmd_pub, 0.0, 0.0, 0.0, 0.5)
        restarted, _ = system.wait_for_line_at(r'\[runner\] restarted amcl \(start 2,')
        first = poses.wait_since(restarted, lambda msg: True, timeout=60.0)
        estimate, truth = pose_of(first), truth_at(first.header.stamp)
        error_m = math.hypot(estimate.x - truth.x, estimate.y - truth.y)
        error_deg = math.degrees(abs(wrap_angle(estimate.yaw - truth.yaw)))
        print(f'first pose of the respawned amcl: ({estimate.x:.3f}, {estimate.y:.3f}, '
              f'{estimate.yaw:.3f}), truth ({truth.x:.3f}, {truth.y:.3f}, {truth.yaw:.3f}): '
              f'{error_m:.3f} m, {error_deg:.2f} deg off')
        assert math.hypot(truth.x - START.x, truth.y - START.y) > 0.9   # far from the start
        assert error_m < 0.1 and error_deg < 5.0, (error_m, error_deg)
        output = system.output()
        assert len(re.findall(r'Setting pose \(set_initial_pose\)', output)) == 1, output
        assert len(re.findall(rf'\[amcl\].*Resuming from {re.escape(str(state_file))} '
                              r'\(saved at \d+\.\d+ s\): \(', output)) == 1, output

        assert system.stop() == 0
        # The respawned amcl saved its state too (on its updates and when it stopped).
        text = state_file.read_text()
        assert len(text) < 1000, text
        saved = yaml.safe_load(text)
        assert saved['stamp'] >= stamp_s(first.header.stamp), text
        assert not list(tmp_path.glob('*.tmp')), list(tmp_path.iterdir())
    finally:
        lidar.stop.set()
        print(system.output())   # shown by pytest when the test failed


def test_localization_launch_file_describes_the_system():
    """localization.launch.yaml: map_server with the map argument, amcl with amcl.yaml."""
    system = load_system(REPO / 'install/mecanum_navigation/share/mecanum_navigation/launch/'
                         'localization.launch.py', {'use_sim_time': 'true', 'map': 'lab_map'})
    nodes = {node.label: node for node in system.nodes}
    assert set(nodes) == {'map_server', 'amcl'}
    amcl = nodes['amcl']
    assert [s.name for s in amcl.parameters if isinstance(s, Path)] == ['amcl.yaml']
    assert ('use_sim_time', True) in amcl.parameters
    assert ('yaml_filename', 'lab_map') in nodes['map_server'].parameters
    # A state file of this launch only, in the system temp folder, for a respawned amcl.
    assert amcl.respawn
    state_file = dict(p for p in amcl.parameters if isinstance(p, tuple))['pose_state_file']
    folder = os.environ.get('TMPDIR', '/tmp')
    assert re.fullmatch(rf'{re.escape(folder)}/amcl_pose_amcl_\w+_\d+_\d+\.yaml', state_file)
    again = load_system(REPO / 'install/mecanum_navigation/share/mecanum_navigation/launch/'
                        'localization.launch.py')
    assert ('pose_state_file', state_file) not in next(
        node for node in again.nodes if node.label == 'amcl').parameters


@pytest.mark.parametrize('params, message', [
    ({'robot_model_type': 'nav2_amcl::DifferentialMotionModel'},
     r"parameter robot_model_type 'nav2_amcl::DifferentialMotionModel' is not supported: "
     r'this is a mecanum \(omnidirectional\) robot'),
    ({'min_particles': 600, 'max_particles': 500},
     r'parameter max_particles must be >= min_particles \(600\), got 500'),
    ({'laser_model_type': 'beam'}, r"parameter laser_model_type 'beam' is not supported"),
    ({'alpha1': 'high'}, r"parameter alpha1 must be a number, got 'high'"),
    ({'pose_state_file': 'amcl_pose.yaml'},
     r"parameter pose_state_file 'amcl_pose.yaml' must be an absolute path"),
    ({'pose_state_file': '/no/such/folder/amcl_pose.yaml'},
     r"parameter pose_state_file '/no/such/folder/amcl_pose.yaml': folder /no/such/folder "
     r'does not exist'),
    ({'save_pose_period_s': 0.0}, r'parameter save_pose_period_s must be finite and > 0'),
], ids=['differential_model', 'min_above_max_particles', 'beam_model', 'text_alpha',
        'relative_state_file', 'state_file_folder_missing', 'zero_save_period'])
def test_bad_parameters_stop_amcl_with_a_clear_message(ros_env, tmp_path, params, message):
    """A bad value: one FATAL line naming the parameter, exit code 2, no traceback."""
    params_file = tmp_path / 'params.yaml'
    params_file.write_text(yaml.safe_dump({'amcl': {'ros__parameters': params}}))
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_navigation', 'amcl', '--ros-args',
         '--params-file', str(params_file)],
        env=ros_env, capture_output=True, text=True, timeout=60, cwd=str(REPO))
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert 'Traceback' not in output
    assert len(re.findall(r'\[FATAL\]', output)) == 1, output
    assert re.search(r'\[FATAL\].*' + message, output), output


def test_a_corrupt_pose_state_file_is_an_error_then_set_initial_pose(ros_env, tmp_path):
    """Never a crash: one ERROR line naming the file and what is wrong, then the start pose."""
    state_file = tmp_path / 'amcl_pose.yaml'
    state_file.write_text('format: mecanum_amcl_pose_state/1\nstamp: 3.0\n')  # cut short
    params_file = tmp_path / 'params.yaml'
    params_file.write_text(yaml.safe_dump({'amcl': {'ros__parameters': {
        'set_initial_pose': True, 'initial_pose': {'x': 1.0, 'y': 2.0, 'yaw': 0.5},
        'pose_state_file': str(state_file)}}}))
    amcl = OutputProcess(['./mecanum', 'run', 'mecanum_navigation', 'amcl', '--ros-args',
                          '--params-file', str(params_file)], ros_env, cwd=str(REPO))
    try:
        amcl.wait_for_line(r'AMCL started', timeout=60.0)
        output = amcl.output()
        errors = re.findall(r'\[ERROR\].*', output)
        assert len(errors) == 1 and re.search(
            rf'cannot resume from {re.escape(str(state_file))}: missing global_frame_id, '
            r'odom_frame_id, map_to_odom, odom_pose, covariance; starting from '
            r'set_initial_pose instead', errors[0]), output
        assert re.search(r'Setting pose \(set_initial_pose\): \(1\.000, 2\.000, 0\.500\)',
                         output), output
    finally:
        amcl.process.send_signal(signal.SIGINT)
        assert amcl.process.wait(timeout=15) == 0, amcl.output()
    assert 'Traceback' not in amcl.output()
