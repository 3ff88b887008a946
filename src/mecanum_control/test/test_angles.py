"""Hand-worked tests of mecanum_control.angles (wrap to [-pi, pi), yaw quaternions)."""

import math

from mecanum_control.angles import (
    angle_difference, quaternion_from_yaw, wrap_angle, wrap_angles, yaw_from_quaternion)
import numpy as np
import pytest


def test_wrap_angle_hand_worked():
    # 3 pi / 2 is a quarter turn short of a full turn: -pi / 2.
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_angle(-3 * math.pi / 2) == pytest.approx(math.pi / 2)
    assert wrap_angle(4 * math.pi + 0.5) == pytest.approx(0.5)
    assert wrap_angle(0.0) == 0.0
    assert wrap_angle(-0.25) == -0.25


def test_wrap_angle_is_minus_pi_inclusive_pi_exclusive():
    # Exactly -pi stays, exactly pi (and any odd multiple of pi) becomes -pi.
    assert wrap_angle(-math.pi) == -math.pi
    assert wrap_angle(math.pi) == -math.pi
    assert wrap_angle(3 * math.pi) == -math.pi
    assert wrap_angle(-3 * math.pi) == -math.pi
    # An ulp below -pi rounds to +pi in (a + pi) % 2pi - pi: still returned as -pi.
    assert wrap_angle(math.nextafter(-math.pi, -4.0)) == -math.pi
    for angle in np.linspace(-20.0, 20.0, 401):
        assert -math.pi <= wrap_angle(float(angle)) < math.pi


def test_wrap_angle_of_nan_and_infinity_is_nan():
    assert math.isnan(wrap_angle(math.nan))
    assert math.isnan(wrap_angle(math.inf))


def test_wrap_angles_of_an_array():
    angles = [0.0, math.pi, -math.pi, 3 * math.pi / 2, -3 * math.pi / 2, 2 * math.pi + 0.5,
              math.nextafter(-math.pi, -4.0)]
    expected = [0.0, -math.pi, -math.pi, -math.pi / 2, math.pi / 2, 0.5, -math.pi]
    np.testing.assert_allclose(wrap_angles(angles), expected, rtol=0.0, atol=1e-12)
    assert wrap_angles(angles)[1] == -math.pi


def test_wrap_angles_agrees_with_wrap_angle_keeps_shape_and_input():
    angles = np.linspace(-20.0, 20.0, 400).reshape(20, 20)
    original = angles.copy()
    wrapped = wrap_angles(angles)
    assert wrapped.shape == (20, 20)
    assert wrapped.dtype == float
    np.testing.assert_array_equal(angles, original)
    np.testing.assert_array_equal(wrapped.ravel(), [wrap_angle(a) for a in angles.ravel()])
    assert np.isnan(wrap_angles([math.nan])[0])


def test_angle_difference_takes_the_short_way():
    # From pi - 0.1 to -pi + 0.1 is 0.2 rad counter-clockwise across pi, not -2 pi + 0.2.
    assert angle_difference(-math.pi + 0.1, math.pi - 0.1) == pytest.approx(0.2)
    assert angle_difference(math.pi - 0.1, -math.pi + 0.1) == pytest.approx(-0.2)
    assert angle_difference(0.5, 0.25) == pytest.approx(0.25)
    assert angle_difference(math.pi, 0.0) == -math.pi


def test_quaternion_from_yaw_hand_worked():
    # (0, 0, sin(yaw / 2), cos(yaw / 2)).
    assert quaternion_from_yaw(0.0) == (0.0, 0.0, 0.0, 1.0)
    assert quaternion_from_yaw(math.pi / 2) == pytest.approx(
        (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)))
    assert quaternion_from_yaw(math.pi) == pytest.approx((0.0, 0.0, 1.0, 0.0))
    assert quaternion_from_yaw(-math.pi / 2) == pytest.approx(
        (0.0, 0.0, -math.sqrt(0.5), math.sqrt(0.5)))


@pytest.mark.parametrize('yaw', [0.0, math.pi / 2, -3.0, 1.0, -math.pi / 2])
def test_quaternion_round_trip(yaw):
    assert yaw_from_quaternion(*quaternion_from_yaw(yaw)) == pytest.approx(yaw)
    # -q is the same rotation.
    negated = [-value for value in quaternion_from_yaw(yaw)]
    assert yaw_from_quaternion(*negated) == pytest.approx(yaw)


def test_yaw_from_quaternion_hand_worked():
    half = math.sqrt(0.5)
    assert yaw_from_quaternion(0.0, 0.0, half, half) == pytest.approx(math.pi / 2)
    assert yaw_from_quaternion(0.0, 0.0, 0.0, 1.0) == 0.0
    assert abs(yaw_from_quaternion(0.0, 0.0, 1.0, 0.0)) == pytest.approx(math.pi)
    # Yaw pi/2 then roll 0.3 about the new x axis, q = q_yaw * q_roll =
    # (cz sx, sz sx, sz cx, cz cx): the yaw is still pi/2.
    sx, cx = math.sin(0.15), math.cos(0.15)
    assert yaw_from_quaternion(half * sx, half * sx, half * cx, half * cx) == pytest.approx(
        math.pi / 2)


def test_wrap_angle_compiles_with_numba_unchanged():
    numba = pytest.importorskip('numba')
    compiled = numba.njit(wrap_angle)
    for angle in [math.pi, -math.pi, 3 * math.pi, 0.0, -0.25, 1e3, -1e3,
                  math.nextafter(-math.pi, -4.0), math.nextafter(math.pi, 4.0)]:
        assert compiled(angle) == wrap_angle(angle)
