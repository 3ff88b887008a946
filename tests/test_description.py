"""
Integration: the robot description published by state_publisher, in real processes.

description.launch.yaml runs state_publisher with the URDF that the real xacro makes
(through the runner's $(command ...)); display.launch.yaml adds joint_state_publisher.
Both on simulated time driven by the test. Expected values come from motor_params.yaml.
"""

import math
from pathlib import Path
import re
import subprocess
import time

from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_description.robot_model import parse_urdf
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
CONFIG = load_robot_config(default_config_path())
R = CONFIG.geometry.wheel_radius_m
LX = CONFIG.geometry.half_wheelbase_m
LY = CONFIG.geometry.half_track_m
FL, FR, RL, RR = CONFIG.wheel_joint_names
H = math.sqrt(0.5)


def latched(test_node, msg_type, topic: str) -> list:
    """Subscribe to a transient-local topic; return the list its messages go to."""
    messages = []
    qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    test_node.node.create_subscription(msg_type, topic, messages.append, qos)
    return messages


def wait_until(condition, what: str, timeout: float = 20.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f'timed out waiting for {what}')


def by_child(message: TFMessage) -> dict:
    return {t.child_frame_id: t for t in message.transforms}


def xyz(transform) -> tuple:
    t = transform.transform.translation
    return (t.x, t.y, t.z)


def quaternion(transform) -> tuple:
    r = transform.transform.rotation
    return (r.x, r.y, r.z, r.w)


def stamp_of(seconds: float):
    state = JointState()
    state.header.stamp.sec = int(seconds)
    state.header.stamp.nanosec = int(round((seconds % 1) * 1e9))
    return state


@pytest.fixture
def description(start_system, test_node):
    """Start description.launch.yaml on sim time; return (system, test_node)."""
    test_node.start_clock()
    system = start_system('mecanum_description', 'description.launch.yaml',
                          'use_sim_time:=true')
    system.wait_for_line(r'\[robot_state_publisher\].*Robot state publisher started')
    return system, test_node


def test_description_and_fixed_frames_are_latched(description):
    _, test_node = description
    descriptions = latched(test_node, String, '/robot_description')
    statics = latched(test_node, TFMessage, '/tf_static')
    text = wait_until(lambda: descriptions and descriptions[0].data, '/robot_description')
    model = parse_urdf(text)
    assert model.name == 'mecanum_robot' and model.root == 'base_link'
    assert [j.name for j in model.moving_joints()] == [FL, FR, RL, RR]

    # Every fixed joint in one message.
    static = wait_until(lambda: statics and statics[0], '/tf_static')
    frames = by_child(static)
    assert set(frames) == {'base_footprint', 'laser', 'imu_link'}
    assert frames['base_footprint'].header.frame_id == 'base_link'
    assert xyz(frames['base_footprint']) == pytest.approx((0, 0, -R))
    assert frames['laser'].header.frame_id == 'base_link'
    assert xyz(frames['laser']) == pytest.approx(
        (CONFIG.lidar_mount_x_m, CONFIG.lidar_mount_y_m, CONFIG.lidar_mount_z_m))
    half_yaw = CONFIG.lidar_mount_yaw_rad / 2
    assert quaternion(frames['laser']) == pytest.approx(
        (0, 0, math.sin(half_yaw), math.cos(half_yaw)))
    assert frames['imu_link'].header.frame_id == 'base_link'
    assert xyz(frames['imu_link']) == pytest.approx((0, 0, CONFIG.imu_mount_z_m))
    assert quaternion(frames['imu_link']) == pytest.approx((0, 0, 0, 1))


def test_joint_states_turn_into_wheel_transforms(description):
    system, test_node = description
    tf = test_node.record(TFMessage, '/tf')
    joints = test_node.node.create_publisher(JointState, 'joint_states', 10)
    wait_until(lambda: joints.get_subscription_count() > 0, 'the joint_states subscriber')

    # A quarter turn of the front left wheel: a rotation about y by pi/2, at its corner.
    sent = 100.0
    while True:
        state = stamp_of(sent)
        state.name, state.position = [FL], [math.pi / 2]
        joints.publish(state)
        try:
            msg = tf.wait_for(lambda m: 'front_left_wheel_link' in by_child(m), timeout=1.0)
            break
        except AssertionError:
            sent += 1.0     # published before discovery completed: send again, later
            assert sent < 120.0, 'no /tf for the front left wheel'
    wheel = by_child(msg)['front_left_wheel_link']
    assert wheel.header.frame_id == 'base_link'
    # Stamped with the joint state's stamp (one of those sent).
    assert 100 <= wheel.header.stamp.sec <= sent and wheel.header.stamp.nanosec == 0
    assert xyz(wheel) == pytest.approx((LX, LY, 0))
    assert quaternion(wheel) == pytest.approx((0, H, 0, H))

    # An unknown joint is ignored and a NaN position skipped: the rest still goes out.
    state = stamp_of(sent + 1.0)
    state.name = [FL, 'no_such_joint', FR]
    state.position = [float('nan'), 1.0, 0.5]
    joints.publish(state)
    msg = tf.wait_for(lambda m: 'front_right_wheel_link' in by_child(m))
    assert set(by_child(msg)) == {'front_right_wheel_link'}
    assert xyz(by_child(msg)['front_right_wheel_link']) == pytest.approx((LX, -LY, 0))
    assert quaternion(by_child(msg)['front_right_wheel_link']) == pytest.approx(
        (0, math.sin(0.25), 0, math.cos(0.25)))
    system.wait_for_line(r'\[robot_state_publisher\].*WARN.*no_such_joint')
    system.wait_for_line(r'\[robot_state_publisher\].*WARN.*non-finite positions of '
                         + re.escape(FL))
    assert system.process.poll() is None


def test_display_holds_every_wheel_at_zero(start_system, test_node):
    test_node.start_clock()
    states = test_node.record(JointState, 'joint_states')
    tf = test_node.record(TFMessage, '/tf')
    start_system('mecanum_description', 'display.launch.yaml', 'use_sim_time:=true')
    state = states.wait_for(lambda m: len(m.name) > 0)
    assert list(state.name) == [FL, FR, RL, RR]
    assert list(state.position) == [0.0] * 4
    msg = tf.wait_for(lambda m: len(m.transforms) == 4)
    wheels = by_child(msg)
    assert {name: xyz(t) for name, t in wheels.items()} == {
        'front_left_wheel_link': pytest.approx((LX, LY, 0)),
        'front_right_wheel_link': pytest.approx((LX, -LY, 0)),
        'rear_left_wheel_link': pytest.approx((-LX, LY, 0)),
        'rear_right_wheel_link': pytest.approx((-LX, -LY, 0))}
    assert all(quaternion(t) == (0, 0, 0, 1) for t in wheels.values())
    # Stamped on the simulated clock (the test's, which started at 0).
    assert msg.transforms[0].header.stamp.sec < 1000


@pytest.mark.parametrize('parameters, message', [
    ([], 'parameter robot_description is empty'),
    (['-p', 'robot_description:=<robot name="r"><link name="a"/><joint name="j" type="fixed">'
      '<parent link="a"/><child link="ghost"/></joint></robot>'],
     "not a valid URDF: joint 'j': child link 'ghost' does not exist"),
    (['-p', 'robot_description:=<robot name="r"><link name="a"></robot>'],
     'not well-formed XML'),
    (['-p', 'robot_description:=<robot name="r"><link name="a"/><link name="b"/></robot>'],
     'exactly one root link, found 2'),
    (['-p', 'robot_description:=<robot name="r"><link name="a"/></robot>',
      '-p', 'publish_frequency:=0'], 'publish_frequency must be > 0'),
])
def test_bad_robot_description_stops_the_node(ros_env, parameters, message):
    """The node exits 2 with one FATAL line naming the problem, no traceback."""
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_description', 'state_publisher', '--ros-args',
         *parameters], env=ros_env, capture_output=True, text=True, timeout=60,
        cwd=str(REPO))
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert 'Traceback' not in output
    assert re.search(r'\[FATAL\].*' + re.escape(message), output), output


def test_an_idle_node_stops_on_ctrl_c_at_once(start_system, test_node):
    """state_publisher has no timer: with no joint_states it must still see SIGINT."""
    system = start_system('mecanum_description', 'description.launch.yaml')
    system.wait_for_line(r'\[robot_state_publisher\].*Robot state publisher started')
    time.sleep(1.0)  # idle: nothing wakes the node but the signal
    started = time.monotonic()
    assert system.stop() == 0
    print(f'stopped in {time.monotonic() - started:.2f} s')
    # The runner escalates to SIGTERM after 3 s when a node ignores SIGINT.
    assert 'sending SIGTERM' not in system.output(), system.output()
