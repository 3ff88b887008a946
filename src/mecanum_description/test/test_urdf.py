"""
The robot's URDF, as the real xacro makes it from the source, against motor_params.yaml.

Expected values are worked out from the config by hand (signs per REP-103: x forward,
y left), not taken from the URDF.
"""

import math
from pathlib import Path
import xml.etree.ElementTree as ElementTree

from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_description.robot_model import parse_urdf, rotate_vector
import numpy as np
import pytest
import xacro
import yaml

PACKAGE = Path(__file__).resolve().parents[1]
XACRO_FILE = PACKAGE / 'urdf' / 'mecanum_robot.urdf.xacro'
CONFIG = load_robot_config(default_config_path())
R = CONFIG.geometry.wheel_radius_m
LX = CONFIG.geometry.half_wheelbase_m
LY = CONFIG.geometry.half_track_m
WHEELS = ['front_left_wheel_link', 'front_right_wheel_link', 'rear_left_wheel_link',
          'rear_right_wheel_link']


def process(**mappings) -> str:
    return xacro.process_file(str(XACRO_FILE), mappings=mappings).toxml()


@pytest.fixture(scope='module')
def urdf_text():
    return process()


@pytest.fixture(scope='module')
def model(urdf_text):
    return parse_urdf(urdf_text)


def point_in(model, link, point, positions=None, base=None):
    pose = model.link_pose(link, positions, base)
    moved = rotate_vector(pose.rotation, point)
    return tuple(a + b for a, b in zip(pose.translation, moved))


def test_every_frame_the_nodes_use_exists(model):
    # base_link is the root: the EKF publishes odom -> base_link, and a frame has one parent.
    assert model.root == 'base_link'
    for frame in ['base_footprint', 'base_link', 'laser', 'imu_link'] + WHEELS:
        assert frame in model.links, frame


def test_wheel_joints_are_the_configured_ones_in_order(model):
    names = [j.name for j in model.moving_joints()]
    assert names == list(CONFIG.wheel_joint_names)
    for name, link in zip(CONFIG.wheel_joint_names, WHEELS):
        joint = model.joints[name]
        assert (joint.joint_type, joint.parent, joint.child) == ('continuous', 'base_link', link)
        assert joint.axis == (0.0, 1.0, 0.0)


@pytest.mark.parametrize('link, x_sign, y_sign', [
    ('front_left_wheel_link', 1, 1), ('front_right_wheel_link', 1, -1),
    ('rear_left_wheel_link', -1, 1), ('rear_right_wheel_link', -1, -1)])
def test_wheels_sit_at_their_corners_at_axle_height(model, link, x_sign, y_sign):
    pose = model.link_pose(link)            # in base_link, at axle height
    assert pose.translation == pytest.approx((x_sign * LX, y_sign * LY, 0.0), abs=1e-12)
    assert pose.rotation == pytest.approx((0, 0, 0, 1))
    # The wheel's lowest point touches the ground (base_footprint's height).
    ground = model.link_pose('base_footprint').translation[2]
    assert point_in(model, link, (0, 0, -R))[2] == pytest.approx(ground, abs=1e-12)


@pytest.mark.parametrize('joint, link', [
    (0, 'front_left_wheel_link'), (1, 'front_right_wheel_link'),
    (2, 'rear_left_wheel_link'), (3, 'rear_right_wheel_link')])
def test_a_positive_wheel_angle_rolls_forward(model, joint, link):
    """A quarter turn brings the wheel's top forward by the radius, on both sides."""
    positions = {CONFIG.wheel_joint_names[joint]: math.pi / 2}
    centre = model.link_pose(link).translation
    top = point_in(model, link, (0, 0, R), positions)
    assert np.subtract(top, centre) == pytest.approx((R, 0, 0), abs=1e-12)


def test_base_footprint_is_on_the_ground_below_base_link(model):
    pose = model.link_pose('base_footprint')
    assert pose.parent == 'base_link'
    assert pose.translation == pytest.approx((0, 0, -R))
    assert pose.rotation == (0, 0, 0, 1)


def test_laser_is_at_the_lidar_mount(model):
    pose = model.link_pose('laser', base='base_link')
    assert pose.translation == pytest.approx(
        (CONFIG.lidar_mount_x_m, CONFIG.lidar_mount_y_m, CONFIG.lidar_mount_z_m))
    half = CONFIG.lidar_mount_yaw_rad / 2
    assert pose.rotation == pytest.approx((0, 0, math.sin(half), math.cos(half)))


def test_imu_is_on_the_yaw_axis_aligned(model):
    pose = model.link_pose('imu_link', base='base_link')
    assert pose.translation == pytest.approx((0, 0, CONFIG.imu_mount_z_m))
    assert pose.rotation == (0, 0, 0, 1)


def test_chassis_box_is_the_configured_size_with_its_underside_below_the_axles(urdf_text):
    base_link = next(link for link in ElementTree.fromstring(urdf_text).iter('link')
                     if link.get('name') == 'base_link')
    box = base_link.find('collision/geometry/box')
    size = [float(v) for v in box.get('size').split()]
    assert size == pytest.approx(
        [CONFIG.chassis_length_m, CONFIG.chassis_width_m, CONFIG.chassis_height_m])
    centre_z = float(base_link.find('collision/origin').get('xyz').split()[2])
    assert centre_z - CONFIG.chassis_height_m / 2 == pytest.approx(-0.01)
    assert base_link.find('visual/geometry/mesh').get('filename') == \
        'package://mecanum_description/meshes/chassis.stl'


def test_meshes_referenced_exist(urdf_text):
    prefix = 'package://mecanum_description/'
    meshes = {m.get('filename') for m in ElementTree.fromstring(urdf_text).iter('mesh')}
    assert meshes == {prefix + 'meshes/chassis.stl', prefix + 'meshes/wheel.stl'}
    for uri in meshes:
        assert (PACKAGE / uri[len(prefix):]).is_file(), uri


def test_total_mass_is_the_robot_mass(model):
    masses = {name: link.inertial.mass_kg for name, link in model.links.items()
              if link.inertial is not None}
    assert sum(masses.values()) == pytest.approx(CONFIG.robot_mass_kg)
    # 4 wheels of 0.1 kg, the chassis the rest.
    assert [masses[w] for w in WHEELS] == pytest.approx([0.1] * 4)
    assert masses['base_link'] == pytest.approx(CONFIG.robot_mass_kg - 0.4)


def test_inertias_are_physical(model):
    inertials = [link.inertial for link in model.links.values() if link.inertial]
    assert len(inertials) == 5
    for inertial in inertials:
        moments = np.linalg.eigvalsh(np.array(inertial.matrix()))
        assert moments.min() > 0, moments
        a, b, c = sorted(moments)
        assert a + b >= c * (1 - 1e-9), moments          # triangle inequality
    # The chassis is a solid box: m (w^2 + h^2) / 12 about x, by hand.
    chassis = model.links['base_link'].inertial
    m = CONFIG.robot_mass_kg - 0.4
    assert chassis.ixx == pytest.approx(
        m * (CONFIG.chassis_width_m ** 2 + CONFIG.chassis_height_m ** 2) / 12)
    wheel = model.links['front_left_wheel_link'].inertial
    assert wheel.iyy == pytest.approx(0.1 * R ** 2 / 2)    # about the axle


def test_urdf_survives_launch_ros_reading_it_as_yaml(urdf_text, model):
    """launch_ros reads a substituted parameter value as YAML: it must stay one string."""
    value = yaml.safe_load(urdf_text)
    assert isinstance(value, str)
    again = parse_urdf(value)
    assert again.joints == model.joints and again.links == model.links


def test_geometry_follows_the_config_file(tmp_path):
    """Another config (xacro argument config:=FILE) moves the wheels and the lidar."""
    text = default_config_path().read_text()
    document = yaml.safe_load(text)
    params = document['/**']['ros__parameters']
    params.update(wheel_radius_m=0.05, half_wheelbase_m=0.2, half_track_m=0.15,
                  lidar_mount_x_m=-0.03, lidar_mount_yaw_rad=math.pi / 2, robot_mass_kg=6.0)
    config = tmp_path / 'motor_params.yaml'
    config.write_text(yaml.safe_dump(document))
    model = parse_urdf(process(config=str(config)))
    assert model.link_pose('rear_right_wheel_link').translation == \
        pytest.approx((-0.2, -0.15, 0.0))
    assert model.link_pose('base_footprint').translation == pytest.approx((0, 0, -0.05))
    laser = model.link_pose('laser', base='base_link')
    assert laser.translation[0] == pytest.approx(-0.03)
    assert laser.rotation == pytest.approx((0, 0, math.sqrt(0.5), math.sqrt(0.5)))
    total = sum(link.inertial.mass_kg for link in model.links.values() if link.inertial)
    assert total == pytest.approx(6.0)
