"""
Tests of the complete ros2msg definitions, on installed and hand-written .msg files.

The expected texts are assembled by hand from the .msg files following rosbag2's
rule (dependencies sorted by name, depth first, each once); the definitions must
also let mcap_ros2's decoder read CDR bytes serialized by rclpy, field by field.
"""

import math
import os

from ament_index_python.packages import get_package_share_directory
from builtin_interfaces.msg import Time
from geometry_msgs.msg import TransformStamped
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
from mecanum_bringup.message_definitions import (
    message_definition, MessageDefinitionError, msg_dependencies, SEPARATOR,
    split_type_name)
from nav_msgs.msg import Odometry
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import LaserScan
from tf2_msgs.msg import TFMessage


def installed_text(type_name: str) -> str:
    """Return the .msg file of an installed type, read here independently."""
    package, _, name = type_name.split('/')
    path = os.path.join(get_package_share_directory(package), 'msg', name + '.msg')
    with open(path, encoding='utf-8', newline='') as file:
        return file.read()


def nested(type_name: str, text: str) -> str:
    """Return the delimiter and text of one nested type."""
    return f'\n{SEPARATOR}\nMSG: {type_name}\n{text}'


def decode(type_name: str, msg):
    """Serialize msg with rclpy, decode it with mcap_ros2 and our definition."""
    schema = Schema(id=1, name=type_name, encoding='ros2msg',
                    data=message_definition(type_name).encode())
    decoder = DecoderFactory().decoder_for('cdr', schema)
    assert decoder is not None
    return decoder(serialize_message(msg))


def test_separator_is_80_equal_signs():
    assert SEPARATOR == '=' * 80


def test_type_without_nested_types_is_its_msg_file():
    assert message_definition('std_msgs/msg/String') == installed_text('std_msgs/msg/String')
    assert message_definition('builtin_interfaces/msg/Time') == \
        installed_text('builtin_interfaces/msg/Time')


def test_pose_stamped_lists_nested_types_sorted_depth_first():
    # PoseStamped uses {geometry_msgs/Pose (written 'Pose'), std_msgs/Header}; Pose uses
    # Point and Quaternion; Header uses builtin_interfaces/Time.
    expected = (installed_text('geometry_msgs/msg/PoseStamped')
                + nested('geometry_msgs/Pose', installed_text('geometry_msgs/msg/Pose'))
                + nested('geometry_msgs/Point', installed_text('geometry_msgs/msg/Point'))
                + nested('geometry_msgs/Quaternion',
                         installed_text('geometry_msgs/msg/Quaternion'))
                + nested('std_msgs/Header', installed_text('std_msgs/msg/Header'))
                + nested('builtin_interfaces/Time', installed_text('builtin_interfaces/msg/Time')))
    assert message_definition('geometry_msgs/msg/PoseStamped') == expected


def test_each_nested_type_appears_once():
    definition = message_definition('nav_msgs/msg/Odometry')
    headers = [line for line in definition.split('\n') if line.startswith('MSG: ')]
    assert headers == ['MSG: geometry_msgs/PoseWithCovariance', 'MSG: geometry_msgs/Pose',
                       'MSG: geometry_msgs/Point', 'MSG: geometry_msgs/Quaternion',
                       'MSG: geometry_msgs/TwistWithCovariance', 'MSG: geometry_msgs/Twist',
                       'MSG: geometry_msgs/Vector3', 'MSG: std_msgs/Header',
                       'MSG: builtin_interfaces/Time']


def test_workspace_interfaces_are_found():
    definition = message_definition('mecanum_interfaces/msg/WheelTicks')
    assert definition.startswith(installed_text('mecanum_interfaces/msg/WheelTicks'))
    assert '\nMSG: std_msgs/Header\n' in definition


def test_results_are_cached():
    assert message_definition('sensor_msgs/msg/LaserScan') is \
        message_definition('sensor_msgs/msg/LaserScan')


def test_dependencies_of_a_hand_written_text():
    text = ('# Comment naming geometry_msgs/Fake things\n'
            'Inner a  # relative: same package\n'
            '  other_pkg/Thing[] things\n'
            'Leaf[<=3] bounded\n'
            'Leaf[4] fixed\n'
            'uint8 CONSTANT=1\n'
            'string<=5 short_text\n'
            'float64 with_default 1.5\n'
            'builtin_interfaces/Time stamp\n')
    assert msg_dependencies(text, 'pkg') == [
        'builtin_interfaces/Time', 'other_pkg/Thing', 'pkg/Inner', 'pkg/Leaf']


def test_type_names_are_split():
    assert split_type_name('sensor_msgs/msg/LaserScan') == ('sensor_msgs', 'msg', 'LaserScan')
    assert split_type_name('std_msgs/Header') == ('std_msgs', 'msg', 'Header')
    for bad in ('LaserScan', 'sensor_msgs/msg/', 'a/b/c/d', '', 'sensor msgs/msg/X', None):
        with pytest.raises(MessageDefinitionError, match='not a message type name'):
            split_type_name(bad)


def test_unknown_types_give_a_clear_error():
    with pytest.raises(MessageDefinitionError, match="package 'no_such_msgs' not found"):
        message_definition('no_such_msgs/msg/Thing')
    with pytest.raises(MessageDefinitionError, match='std_msgs/msg/NoSuchType'):
        message_definition('std_msgs/msg/NoSuchType')
    with pytest.raises(MessageDefinitionError, match='not a message type name'):
        message_definition('std_msgs')


@pytest.fixture
def fake_msgs(tmp_path, monkeypatch):
    """Make a package 'fake_msgs' in an ament prefix of its own; return a .msg writer."""
    (tmp_path / 'share/ament_index/resource_index/packages').mkdir(parents=True)
    (tmp_path / 'share/ament_index/resource_index/packages/fake_msgs').write_text('')
    msg_dir = tmp_path / 'share/fake_msgs/msg'
    msg_dir.mkdir(parents=True)
    monkeypatch.setenv('AMENT_PREFIX_PATH',
                       f'{tmp_path}{os.pathsep}{os.environ["AMENT_PREFIX_PATH"]}')

    def write(name: str, text: str) -> str:
        (msg_dir / f'{name}.msg').write_bytes(text.encode())
        return text
    return write


def test_hand_written_package_expands_as_worked_out(fake_msgs):
    outer = fake_msgs('Outer', '# outer\nInner a\nfake_msgs/Inner[] b\nLeaf[<=3] c\n'
                               'std_msgs/Header header\nuint8 K=1\r\nstring<=5 s\n')
    inner = fake_msgs('Inner', 'fake_msgs/Leaf leaf\nfloat64 x\n')
    leaf = fake_msgs('Leaf', 'int32 v')
    # Outer's dependencies sorted: fake_msgs/Inner, fake_msgs/Leaf, std_msgs/Header.
    # Inner is expanded first and brings Leaf, so Outer's own Leaf is not repeated.
    expected = (outer + nested('fake_msgs/Inner', inner) + nested('fake_msgs/Leaf', leaf)
                + nested('std_msgs/Header', installed_text('std_msgs/msg/Header'))
                + nested('builtin_interfaces/Time', installed_text('builtin_interfaces/msg/Time')))
    assert message_definition('fake_msgs/msg/Outer') == expected


def test_missing_nested_type_names_both_types(fake_msgs):
    fake_msgs('Broken', 'fake_msgs/Missing m\n')
    with pytest.raises(MessageDefinitionError,
                       match=r'fake_msgs/msg/Broken.*fake_msgs/Missing'):
        message_definition('fake_msgs/msg/Broken')


def test_nesting_depth_is_limited_to_50_types(fake_msgs):
    for i in range(51):
        fake_msgs(f'Chain{i}', f'Chain{i + 1} next\n' if i < 50 else 'int8 end\n')
    assert message_definition('fake_msgs/msg/Chain1').count('\nMSG: ') == 49
    with pytest.raises(MessageDefinitionError, match='deeper than 50'):
        message_definition('fake_msgs/msg/Chain0')


def test_mcap_ros2_decodes_a_laser_scan():
    scan = LaserScan()
    scan.header.stamp = Time(sec=12, nanosec=345)
    scan.header.frame_id = 'laser'
    scan.angle_min, scan.angle_max, scan.angle_increment = -1.5, 1.5, 0.75
    scan.range_min, scan.range_max = 0.1, 12.0
    scan.ranges = [1.0, 2.5, math.inf, 0.25, 3.0]
    decoded = decode('sensor_msgs/msg/LaserScan', scan)
    assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == (12, 345)
    assert decoded.header.frame_id == 'laser'
    assert (decoded.angle_min, decoded.angle_max, decoded.angle_increment) == (-1.5, 1.5, 0.75)
    assert decoded.range_max == pytest.approx(12.0)
    assert list(decoded.ranges) == [1.0, 2.5, math.inf, 0.25, 3.0]
    assert list(decoded.intensities) == []


def test_mcap_ros2_decodes_nested_and_array_types():
    odom = Odometry()
    odom.header.frame_id, odom.child_frame_id = 'odom', 'base_link'
    odom.pose.pose.position.x, odom.pose.pose.orientation.w = 1.25, 1.0
    odom.pose.covariance[35] = 0.5
    odom.twist.twist.angular.z = -0.75
    decoded = decode('nav_msgs/msg/Odometry', odom)
    assert (decoded.header.frame_id, decoded.child_frame_id) == ('odom', 'base_link')
    assert decoded.pose.pose.position.x == 1.25 and decoded.pose.pose.orientation.w == 1.0
    assert decoded.pose.covariance[35] == 0.5 and len(decoded.pose.covariance) == 36
    assert decoded.twist.twist.angular.z == -0.75

    transforms = []
    for child, x in (('laser', 0.05), ('imu', -0.1)):
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id = 'base_link', child
        t.transform.translation.x = x
        transforms.append(t)
    decoded = decode('tf2_msgs/msg/TFMessage', TFMessage(transforms=transforms))
    assert [(t.child_frame_id, t.transform.translation.x) for t in decoded.transforms] == [
        ('laser', 0.05), ('imu', -0.1)]
