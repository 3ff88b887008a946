"""Unit tests of static_transform: tf2_ros' static_transform_publisher command line."""

import math

from mecanum_description.static_transform import parse_static_transform
import pytest


def test_named_options_with_yaw():
    t = parse_static_transform(['--x', '2.95', '--y', '2.0', '--yaw', str(math.pi / 2),
                                '--frame-id', 'map', '--child-frame-id', 'odom'])
    assert (t.parent, t.child) == ('map', 'odom')
    assert t.translation == (2.95, 2.0, 0.0)
    # A quarter turn about z: (0, 0, sin 45 deg, cos 45 deg).
    assert t.rotation == pytest.approx((0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)))


def test_quaternion_is_normalised_and_defaults_are_identity():
    t = parse_static_transform(['--qz', '2', '--qw', '2', '--frame-id', 'a',
                                '--child-frame-id', 'b'])
    assert t.rotation == pytest.approx((0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)))
    t = parse_static_transform(['--frame-id', 'a', '--child-frame-id', 'b'])
    assert t.translation == (0.0, 0.0, 0.0)
    assert t.rotation == pytest.approx((0.0, 0.0, 0.0, 1.0))


def test_old_positional_form():
    t = parse_static_transform(['1', '2', '3', '0', '0', str(math.pi), 'base_link', 'laser'])
    assert (t.parent, t.child, t.translation) == ('base_link', 'laser', (1.0, 2.0, 3.0))
    # Roll of pi: (1, 0, 0, 0) up to sign.
    assert abs(t.rotation[0]) == pytest.approx(1.0)


@pytest.mark.parametrize('argv, message', [
    (['--x', '1'], 'required'),
    (['--frame-id', 'map', '--child-frame-id', 'map'], 'both'),
    (['--x', 'nan', '--frame-id', 'a', '--child-frame-id', 'b'], 'finite'),
    (['--x', 'one', '--frame-id', 'a', '--child-frame-id', 'b'], 'invalid float'),
    (['--yaw', '1', '--qw', '1', '--frame-id', 'a', '--child-frame-id', 'b'], 'not both'),
    (['--qw', '0', '--frame-id', 'a', '--child-frame-id', 'b'], 'normalised'),
    (['1', '2', '3'], '8 positional'),
    (['--bogus', '1'], 'unrecognized'),
])
def test_bad_arguments_are_refused_with_a_reason(argv, message):
    with pytest.raises(ValueError, match=message):
        parse_static_transform(argv)
