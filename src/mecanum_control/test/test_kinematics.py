"""Hand-worked and property tests of mecanum_control.kinematics."""

import math

from hypothesis import given, strategies as st
from mecanum_control.kinematics import (
    desaturate, forward_kinematics, integrate_pose, inverse_kinematics, MecanumGeometry)
import pytest

# r = 0.05 m, lx = 0.10 m, ly = 0.15 m: lx + ly = 0.25 m, so 1 rad/s of yaw is 5 rad/s
# on each wheel and 0.1 m/s of translation is 2 rad/s.
GEOMETRY = MecanumGeometry(wheel_radius_m=0.05, half_wheelbase_m=0.10, half_track_m=0.15)


@pytest.mark.parametrize('twist, wheels', [
    ((0.2, 0.0, 0.0), (4.0, 4.0, 4.0, 4.0)),          # forward: all wheels forward
    ((-0.1, 0.0, 0.0), (-2.0, -2.0, -2.0, -2.0)),     # backward
    ((0.0, 0.1, 0.0), (-2.0, 2.0, 2.0, -2.0)),        # strafe left: FL and RR backwards
    ((0.0, 0.0, 1.0), (-5.0, 5.0, -5.0, 5.0)),        # rotate left: uses lx + ly = 0.25
    ((0.2, 0.1, 1.0), (-3.0, 11.0, 1.0, 7.0)),        # all three superposed
])
def test_inverse_kinematics_hand_worked(twist, wheels):
    assert inverse_kinematics(GEOMETRY, *twist) == pytest.approx(wheels)


def test_rotation_uses_half_wheelbase_plus_half_track():
    # The seed used only half the wheelbase; with lx + ly one wheel turn of
    # 2*pi*r moves the robot through the angle 2*pi*r / (lx + ly).
    fl, fr, rl, rr = inverse_kinematics(GEOMETRY, 0.0, 0.0, 0.4)
    assert fr == pytest.approx(0.4 * (0.10 + 0.15) / 0.05)


@pytest.mark.parametrize('twist, wheels', [
    ((0.2, 0.0, 0.0), (4.0, 4.0, 4.0, 4.0)),
    ((0.0, 0.1, 0.0), (-2.0, 2.0, 2.0, -2.0)),
    ((0.0, 0.0, 1.0), (-5.0, 5.0, -5.0, 5.0)),
    ((0.2, 0.1, 1.0), (-3.0, 11.0, 1.0, 7.0)),
])
def test_forward_kinematics_hand_worked(twist, wheels):
    assert forward_kinematics(GEOMETRY, wheels) == pytest.approx(twist)


def test_forward_kinematics_is_least_squares_for_inconsistent_wheels():
    # One wheel slipping (FL reads 2 rad/s too fast): the estimate is the average
    # effect, r * 2 / 4 = 0.025 m/s of vx, -0.025 of vy and -0.1 rad/s of yaw rate.
    vx, vy, wz = forward_kinematics(GEOMETRY, (6.0, 4.0, 4.0, 4.0))
    assert (vx, vy, wz) == pytest.approx((0.2 + 0.025, -0.025, -0.1))


finite = st.floats(min_value=-3.0, max_value=3.0, allow_nan=False)


@given(finite, finite, finite)
def test_inverse_then_forward_round_trip(vx, vy, wz):
    wheels = inverse_kinematics(GEOMETRY, vx, vy, wz)
    assert forward_kinematics(GEOMETRY, wheels) == pytest.approx((vx, vy, wz), abs=1e-9)


def test_desaturate_hand_worked():
    assert desaturate((10.0, -20.0, 5.0, 0.0), 10.0) == pytest.approx((5.0, -10.0, 2.5, 0.0))
    assert desaturate((1.0, -2.0, 3.0, 0.5), 10.0) == (1.0, -2.0, 3.0, 0.5)


@given(finite, finite, finite)
def test_desaturate_keeps_direction_and_limit(vx, vy, wz):
    wheels = inverse_kinematics(GEOMETRY, vx, vy, wz)
    limited = desaturate(wheels, 10.0)
    assert max(abs(w) for w in limited) <= 10.0 + 1e-9
    scaled = forward_kinematics(GEOMETRY, limited)
    original = (vx, vy, wz)
    # Same direction: scaled = s * original with 0 < s <= 1.
    norm = math.sqrt(sum(v * v for v in original))
    if norm > 1e-9:
        s = sum(a * b for a, b in zip(scaled, original)) / norm ** 2
        assert 0.0 < s <= 1.0 + 1e-9
        assert scaled == pytest.approx(tuple(s * v for v in original), abs=1e-9)


def test_desaturate_rejects_bad_limit():
    with pytest.raises(ValueError):
        desaturate((1.0, 1.0, 1.0, 1.0), 0.0)


def test_integrate_quarter_circle_exactly():
    # vx = 1 m/s, wz = 1 rad/s: a circle of radius 1 m around (0, 1). After pi/2 s
    # the robot is at (1, 1) facing +y, in one step.
    assert integrate_pose(0.0, 0.0, 0.0, 1.0, 0.0, 1.0, math.pi / 2) == pytest.approx(
        (1.0, 1.0, math.pi / 2))


def test_integrate_full_circle_returns_to_start():
    x, y, yaw = 0.0, 0.0, 0.0
    for _ in range(7):  # 7 uneven steps that add up to 2*pi seconds
        x, y, yaw = integrate_pose(x, y, yaw, 0.5, 0.0, 1.0, 2 * math.pi / 7)
    assert (x, y) == pytest.approx((0.0, 0.0), abs=1e-12)
    assert yaw == pytest.approx(0.0, abs=1e-12)


def test_integrate_strafing_while_rotating():
    # vy = 1 m/s left while turning at 1 rad/s for pi s: a half circle of radius 1 m
    # centred at (-1, 0), ending at (-2, 0) facing backwards.
    x, y, yaw = integrate_pose(0.0, 0.0, 0.0, 0.0, 1.0, 1.0, math.pi)
    assert (x, y) == pytest.approx((-2.0, 0.0), abs=1e-12)
    assert abs(yaw) == pytest.approx(math.pi)


def test_integrate_straight_line_in_rotated_frame():
    # Facing +y (yaw pi/2), driving forward 0.5 m/s for 2 s moves +1 m in y.
    assert integrate_pose(1.0, 2.0, math.pi / 2, 0.5, 0.0, 0.0, 2.0) == pytest.approx(
        (1.0, 3.0, math.pi / 2))


def test_integrate_tiny_rotation_is_continuous():
    straight = integrate_pose(0.0, 0.0, 0.3, 1.0, 0.2, 0.0, 0.1)
    almost = integrate_pose(0.0, 0.0, 0.3, 1.0, 0.2, 1e-9, 0.1)
    assert almost == pytest.approx(straight, abs=1e-9)


@pytest.mark.parametrize('field', ['wheel_radius_m', 'half_wheelbase_m', 'half_track_m'])
@pytest.mark.parametrize('bad', [0.0, -0.1, float('nan'), float('inf')])
def test_geometry_rejects_bad_values(field, bad):
    values = {'wheel_radius_m': 0.05, 'half_wheelbase_m': 0.1, 'half_track_m': 0.1}
    values[field] = bad
    with pytest.raises(ValueError, match=field):
        MecanumGeometry(**values)
