"""Tests of mecanum_localization.transforms: planar transforms and the transform buffer."""

import math

from mecanum_localization.transforms import (
    IDENTITY, PlanarTransform, TransformBuffer, TransformError)
import pytest


def approx(transform, x, y, yaw):
    """Compare a PlanarTransform with expected numbers."""
    assert (transform.x, transform.y, transform.yaw) == pytest.approx((x, y, yaw), abs=1e-12)


def test_compose_inverse_and_apply_by_hand():
    # A frame at (1, 0) turned 90 deg: its point (1, 0) is at (1, 1).
    frame = PlanarTransform(1.0, 0.0, math.pi / 2)
    assert frame.apply(1.0, 0.0) == pytest.approx((1.0, 1.0))
    approx(frame.compose(PlanarTransform(1.0, 0.0, 0.0)), 1.0, 1.0, math.pi / 2)
    approx(frame.inverse(), 0.0, 1.0, -math.pi / 2)
    approx(frame.compose(frame.inverse()), 0.0, 0.0, 0.0)


def test_interpolation_turns_the_short_way_across_pi():
    a, b = PlanarTransform(0.0, 0.0, math.pi - 0.1), PlanarTransform(2.0, 4.0, -math.pi + 0.1)
    mid = a.interpolate(b, 0.5)
    assert (mid.x, mid.y) == pytest.approx((1.0, 2.0))
    assert abs(mid.yaw) == pytest.approx(math.pi)


def test_static_chains_compose_both_ways():
    buffer = TransformBuffer()
    buffer.set_transform('base_link', 'imu_mount', PlanarTransform(0.1, 0.0, math.pi / 2),
                         static=True)
    buffer.set_transform('/imu_mount', 'imu_link', PlanarTransform(0.05, 0.0, 0.0),
                         static=True)
    # imu_link is 0.05 m along imu_mount's x, which points along base_link's y.
    approx(buffer.lookup('base_link', 'imu_link'), 0.1, 0.05, math.pi / 2)
    approx(buffer.lookup('imu_link', 'base_link'), -0.05, 0.1, -math.pi / 2)
    assert buffer.lookup('/base_link', 'base_link') == IDENTITY


def test_siblings_are_looked_up_through_their_common_parent():
    buffer = TransformBuffer()
    buffer.set_transform('base_link', 'laser', PlanarTransform(0.05, 0.0, 0.0), static=True)
    buffer.set_transform('base_link', 'imu_link', PlanarTransform(0.0, 0.1, 0.0), static=True)
    approx(buffer.lookup('laser', 'imu_link'), -0.05, 0.1, 0.0)


def test_timed_transforms_are_interpolated_and_chained_with_static_ones():
    buffer = TransformBuffer()
    buffer.set_transform('map', 'odom', PlanarTransform(1.0, 0.0, 0.0), static=False,
                         time_s=0.0)
    buffer.set_transform('map', 'odom', PlanarTransform(1.0, 0.0, 0.0), time_s=10.0)
    buffer.set_transform('odom', 'base_link', PlanarTransform(0.0, 0.0, 0.0), time_s=1.0)
    buffer.set_transform('odom', 'base_link', PlanarTransform(1.0, 0.0, math.pi / 2),
                         time_s=2.0)
    buffer.set_transform('base_link', 'laser', PlanarTransform(0.1, 0.0, 0.0), static=True)
    # At t = 1.5 base_link is at (0.5, 0) turned 45 deg in odom, odom at (1, 0) in map.
    pose = buffer.lookup('map', 'laser', 1.5)
    h = math.sqrt(0.5)
    approx(pose, 1.5 + 0.1 * h, 0.1 * h, math.pi / 4)
    approx(buffer.lookup('map', 'base_link'), 2.0, 0.0, math.pi / 2)  # latest


def test_lookups_outside_the_known_times_fail_clearly():
    buffer = TransformBuffer()
    buffer.set_transform('odom', 'base_link', IDENTITY, time_s=1.0)
    buffer.set_transform('odom', 'base_link', IDENTITY, time_s=2.0)
    with pytest.raises(TransformError, match='extrapolation into the future'):
        buffer.lookup('odom', 'base_link', 2.5)
    with pytest.raises(TransformError, match='extrapolation into the past'):
        buffer.lookup('odom', 'base_link', 0.5)
    assert buffer.can_transform('odom', 'base_link', 1.5)


def test_lookups_within_a_nanosecond_of_the_ends_are_the_end_transforms():
    # The navigator died of an IndexError here: a time 0.5 ns after the newest stamp.
    buffer = TransformBuffer()
    buffer.set_transform('odom', 'base_link', PlanarTransform(1.0, 0.0, 0.0), 100.1)
    buffer.set_transform('odom', 'base_link', PlanarTransform(2.0, 0.0, 0.0), 100.2)
    assert buffer.lookup('odom', 'base_link', 100.2 + 5e-10).x == 2.0
    assert buffer.lookup('odom', 'base_link', 100.1 - 5e-10).x == 1.0


def test_unconnected_frames_name_what_is_known():
    buffer = TransformBuffer()
    buffer.set_transform('odom', 'base_link', IDENTITY, time_s=1.0)
    with pytest.raises(TransformError, match="between 'map' and 'base_link'.*odom"):
        buffer.lookup('map', 'base_link')
    assert not buffer.can_transform('map', 'base_link')


def test_old_transforms_leave_the_cache():
    buffer = TransformBuffer(cache_time_s=5.0)
    for t in range(20):
        buffer.set_transform('odom', 'base_link', PlanarTransform(float(t), 0.0, 0.0),
                             time_s=float(t))
    approx(buffer.lookup('odom', 'base_link', 14.0), 14.0, 0.0, 0.0)
    with pytest.raises(TransformError, match='past'):
        buffer.lookup('odom', 'base_link', 13.0)


def test_a_newer_parent_replaces_the_old_one_and_loops_are_caught():
    buffer = TransformBuffer()
    buffer.set_transform('base_footprint', 'imu_link', PlanarTransform(0.2, 0.0, 0.0),
                         static=True)
    buffer.set_transform('base_link', 'imu_link', PlanarTransform(0.3, 0.0, 0.0), static=True)
    approx(buffer.lookup('base_link', 'imu_link'), 0.3, 0.0, 0.0)
    buffer.set_transform('imu_link', 'base_link', IDENTITY, static=True)
    with pytest.raises(TransformError, match='loop'):
        buffer.lookup('map', 'imu_link')


def test_bad_transforms_are_refused():
    buffer = TransformBuffer()
    with pytest.raises(ValueError, match='two different frames'):
        buffer.set_transform('odom', 'odom', IDENTITY)
    with pytest.raises(ValueError, match='not finite'):
        buffer.set_transform('odom', 'base_link', PlanarTransform(math.nan, 0.0, 0.0))
    with pytest.raises(ValueError, match='cache_time_s'):
        TransformBuffer(cache_time_s=0.0)
