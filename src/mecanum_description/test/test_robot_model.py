"""URDF parsing, validation and transforms, against cases worked out by hand."""

import math

from mecanum_description.robot_model import (
    parse_urdf, quaternion_from_axis_angle, quaternion_from_rpy, quaternion_multiply,
    rotate_vector, UrdfError)
import pytest

H = math.sqrt(0.5)  # sin(45 deg) = cos(45 deg)


def approx(values, tolerance=1e-12):
    return pytest.approx(tuple(values), abs=tolerance)


def urdf(*body: str) -> str:
    return '<robot name="test">' + ''.join(body) + '</robot>'


def links(*names: str) -> str:
    return ''.join(f'<link name="{n}"/>' for n in names)


def joint(name, parent, child, joint_type='fixed', xyz='0 0 0', rpy='0 0 0', extra=''):
    return (f'<joint name="{name}" type="{joint_type}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{xyz}" rpy="{rpy}"/>{extra}</joint>')


@pytest.mark.parametrize('rpy, expected', [
    ((0, 0, 0), (0, 0, 0, 1)),
    ((0, 0, math.pi / 2), (0, 0, H, H)),          # yaw 90 deg: about z
    ((math.pi, 0, 0), (1, 0, 0, 0)),              # roll 180 deg: about x
    ((0, math.pi / 2, 0), (0, H, 0, H)),          # pitch 90 deg: about y
    # Rz(90) Rx(90): x -> y, y -> z, z -> x, i.e. 120 deg about (1, 1, 1).
    ((math.pi / 2, 0, math.pi / 2), (0.5, 0.5, 0.5, 0.5)),
])
def test_quaternion_from_rpy(rpy, expected):
    assert quaternion_from_rpy(*rpy) == approx(expected)


def test_rpy_is_fixed_axis_roll_then_pitch_then_yaw():
    q = quaternion_from_rpy(math.pi / 2, 0, math.pi / 2)
    # Roll 90 about x takes y to z, yaw 90 about z leaves z: y -> z.
    assert rotate_vector(q, (0, 1, 0)) == approx((0, 0, 1))
    # Roll leaves x, yaw takes it to y: x -> y.
    assert rotate_vector(q, (1, 0, 0)) == approx((0, 1, 0))


def test_axis_angle_and_products():
    # 90 deg about an unnormalised y axis.
    q = quaternion_from_axis_angle((0, 2, 0), math.pi / 2)
    assert q == approx((0, H, 0, H))
    assert rotate_vector(q, (0, 0, 1)) == approx((1, 0, 0))   # z -> x about +y
    # Two quarter turns about z are a half turn; the product rotates x to -x.
    quarter = quaternion_from_axis_angle((0, 0, 1), math.pi / 2)
    half = quaternion_multiply(quarter, quarter)
    assert half == approx((0, 0, 1, 0))
    assert rotate_vector(half, (1, 0, 0)) == approx((-1, 0, 0))
    # Order matters: yaw after roll differs from roll after yaw.
    roll = quaternion_from_axis_angle((1, 0, 0), math.pi / 2)
    assert rotate_vector(quaternion_multiply(quarter, roll), (0, 1, 0)) == approx((0, 0, 1))
    assert rotate_vector(quaternion_multiply(roll, quarter), (0, 1, 0)) == approx((-1, 0, 0))
    with pytest.raises(ValueError, match='must not be zero'):
        quaternion_from_axis_angle((0, 0, 0), 1.0)


def test_parse_links_joints_and_limits():
    model = parse_urdf(urdf(
        links('base', 'arm', 'slider'),
        joint('shoulder', 'base', 'arm', 'revolute', '0.1 0.2 0.3', '0 0 1.5',
              '<axis xyz="0 0 1"/><limit lower="-1" upper="2" effort="3" velocity="4"/>'),
        joint('rail', 'arm', 'slider', 'prismatic',
              extra='<axis xyz="2 0 0"/><limit upper="0.5" effort="1" velocity="1"/>')))
    assert model.name == 'test' and model.root == 'base'
    shoulder = model.joints['shoulder']
    assert (shoulder.joint_type, shoulder.parent, shoulder.child) == ('revolute', 'base', 'arm')
    assert shoulder.origin_xyz == (0.1, 0.2, 0.3) and shoulder.origin_rpy == (0, 0, 1.5)
    assert (shoulder.lower, shoulder.upper, shoulder.effort, shoulder.velocity) == (-1, 2, 3, 4)
    assert model.joints['rail'].axis == (1.0, 0.0, 0.0)        # normalised
    assert [j.name for j in model.moving_joints()] == ['shoulder', 'rail']


def test_fixed_joint_defaults_and_static_transforms():
    model = parse_urdf(urdf(
        links('a', 'b', 'c'),
        '<joint name="plain" type="fixed"><parent link="a"/><child link="b"/></joint>',
        joint('turned', 'a', 'c', xyz='1 2 3', rpy='0 0 3.141592653589793'),
        ))
    plain, turned = model.fixed_transforms()
    assert (plain.parent, plain.child) == ('a', 'b')
    assert plain.translation == (0, 0, 0) and plain.rotation == (0, 0, 0, 1)
    assert turned.translation == (1, 2, 3)
    assert turned.rotation == approx((0, 0, 1, 0))
    assert model.moving_joints() == []


def test_continuous_joint_rotates_about_its_axis():
    model = parse_urdf(urdf(links('base', 'wheel'), joint(
        'axle', 'base', 'wheel', 'continuous', '0.1 0.2 0', extra='<axis xyz="0 1 0"/>')))
    t = model.joint_transform('axle', math.pi / 2)
    assert (t.parent, t.child) == ('base', 'wheel')
    assert t.translation == approx((0.1, 0.2, 0))
    assert t.rotation == approx((0, H, 0, H))
    # The wheel's top (0, 0, 0.04) turned a quarter about +y is 0.04 ahead of the axle.
    top = model.link_pose('wheel', {'axle': math.pi / 2})
    point = rotate_vector(top.rotation, (0, 0, 0.04))
    assert tuple(a + b for a, b in zip(top.translation, point)) == approx((0.14, 0.2, 0))
    # Position 0 is the origin.
    assert model.joint_transform('axle', 0.0).rotation == (0, 0, 0, 1)


def test_prismatic_joint_moves_along_its_axis_in_the_joint_frame():
    model = parse_urdf(urdf(links('base', 'slider'), joint(
        'rail', 'base', 'slider', 'prismatic', '1 0 0', f'0 0 {math.pi / 2}',
        '<axis xyz="1 0 0"/><limit lower="0" upper="1" effort="1" velocity="1"/>')))
    t = model.joint_transform('rail', 0.3)
    # The joint frame is yawed 90 deg: its x axis is the parent's y.
    assert t.translation == approx((1, 0.3, 0))
    assert t.rotation == approx((0, 0, H, H))


def test_link_pose_chains_joints():
    model = parse_urdf(urdf(
        links('base', 'a', 'b', 'c'),
        joint('j1', 'base', 'a', xyz='1 0 0', rpy=f'0 0 {math.pi / 2}'),
        joint('j2', 'a', 'b', xyz='1 0 0'),
        joint('j3', 'base', 'c', 'revolute', '1 0 0', extra=(
            '<axis xyz="0 0 1"/><limit lower="-4" upper="4" effort="1" velocity="1"/>'))))
    b = model.link_pose('b')
    # a's x axis is base's y: b is 1 along x, then 1 along y.
    assert (b.parent, b.child) == ('base', 'b')
    assert b.translation == approx((1, 1, 0))
    assert b.rotation == approx((0, 0, H, H))
    assert model.link_pose('b', base='a').translation == approx((1, 0, 0))
    # c at the revolute joint, whatever its angle.
    assert model.link_pose('c', {'j3': 1.0}).translation == approx((1, 0, 0))
    with pytest.raises(ValueError, match='not an ancestor'):
        model.link_pose('c', base='a')


def test_mimic_joint_follows_its_leader():
    model = parse_urdf(urdf(
        links('base', 'left', 'right'),
        joint('lead', 'base', 'left', 'continuous'),
        joint('follow', 'base', 'right', 'continuous',
              extra='<mimic joint="lead" multiplier="-2" offset="0.5"/>')))
    assert model.mimic_positions({'lead': 1.0}) == {'follow': -1.5}
    assert model.mimic_positions({}) == {}


def test_inertial_is_parsed():
    model = parse_urdf(urdf(
        '<link name="box"><inertial><origin xyz="0 0 0.02"/><mass value="3.6"/>'
        '<inertia ixx="1" ixy="0.1" ixz="0.2" iyy="2" iyz="0.3" izz="3"/></inertial></link>'))
    inertial = model.links['box'].inertial
    assert inertial.mass_kg == 3.6 and inertial.origin_xyz == (0, 0, 0.02)
    assert inertial.matrix() == ((1, 0.1, 0.2), (0.1, 2, 0.3), (0.2, 0.3, 3))
    assert model.root == 'box' and model.joints == {}


@pytest.mark.parametrize('text, message', [
    ('', 'empty'),
    ('<robot name="r"><link name="a"></robot>', 'not well-formed XML'),
    ('<model name="r"/>', 'root element must be <robot>'),
    ('<robot><link name="a"/></robot>', '<robot> has no name'),
    (urdf(), 'has no links'),
    (urdf(links('a', 'a')), "link 'a' is defined twice"),
    # Two roots.
    (urdf(links('a', 'b')), "exactly one root link, found 2: 'a', 'b'"),
    # A cycle beside the root, and a robot that is only a cycle.
    (urdf(links('root', 'a', 'b'), joint('ab', 'a', 'b'), joint('ba', 'b', 'a')),
     "joints 'ab', 'ba' form a cycle"),
    (urdf(links('a', 'b'), joint('ab', 'a', 'b'), joint('ba', 'b', 'a')), 'form a cycle'),
    (urdf(links('a', 'b', 'c'), joint('ab', 'a', 'b'), joint('cb', 'c', 'b')),
     "link 'b' has two parent joints: 'ab' and 'cb'"),
    (urdf(links('a'), joint('j', 'a', 'ghost')), "joint 'j': child link 'ghost' does not exist"),
    (urdf(links('a'), joint('j', 'nope', 'a')), "joint 'j': parent link 'nope' does not exist"),
    (urdf(links('a'), joint('j', 'a', 'a')), 'its own parent'),
    (urdf(links('a', 'b'), joint('j', 'a', 'b'), joint('j', 'a', 'b')),
     "joint 'j' is defined twice"),
    (urdf(links('a', 'b'), joint('j', 'a', 'b', 'hinge')), "joint 'j': unknown type 'hinge'"),
    (urdf(links('a', 'b'), '<joint name="j" type="fixed"><parent link="a"/></joint>'),
     'needs <child link="..."/>'),
    (urdf(links('a', 'b'), joint('j', 'a', 'b', xyz='1 2')),
     "joint 'j' origin xyz must be 3 finite numbers, got '1 2'"),
    (urdf(links('a', 'b'), joint('j', 'a', 'b', xyz='1 nan 0')), 'origin xyz must be 3 finite'),
    (urdf(links('a', 'b'), joint('j', 'a', 'b', rpy='0 0 inf')), 'origin rpy must be 3 finite'),
    (urdf(links('a', 'b'), joint('j', 'a', 'b', rpy='0 zero 0')), 'origin rpy must be 3 finite'),
    (urdf(links('a', 'b'), joint('j', 'a', 'b', 'continuous', extra='<axis xyz="0 0 0"/>')),
     "joint 'j': axis must not be zero"),
    (urdf(links('a', 'b'), joint('j', 'a', 'b', 'revolute')),
     "joint 'j': a revolute joint needs a <limit>"),
    (urdf(links('a', 'b'), joint('j', 'a', 'b', 'revolute', extra='<limit upper="x"/>')),
     "joint 'j' limit upper must be a finite number, got 'x'"),
    (urdf(links('a', 'b'), joint('j', 'a', 'b', 'continuous', extra='<mimic joint="k"/>')),
     "joint 'j': mimics 'k'"),
    (urdf('<link name="a"><inertial><mass value="heavy"/><inertia ixx="1" ixy="0" ixz="0" '
          'iyy="1" iyz="0" izz="1"/></inertial></link>'),
     "link 'a' mass value must be a finite number"),
    (urdf('<link name="a"><inertial><mass value="-1"/><inertia ixx="1" ixy="0" ixz="0" '
          'iyy="1" iyz="0" izz="1"/></inertial></link>'), 'mass value must be a number >= 0'),
    (urdf('<link name="a"><inertial><mass value="1"/></inertial></link>'),
     'needs <mass> and <inertia>'),
])
def test_malformed_urdf_is_reported(text, message):
    with pytest.raises(UrdfError) as error:
        parse_urdf(text)
    assert message in str(error.value)
