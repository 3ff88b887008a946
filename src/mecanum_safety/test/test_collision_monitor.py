"""Hand-worked tests of mecanum_safety.collision_monitor (Nav2's rules)."""

import math

from mecanum_safety.collision_monitor import (
    collision_time, CollisionMonitor, scan_to_points, scan_usable_fraction, ScanRepeats,
    SourceData, Zone)
import numpy as np
import pytest

FOOTPRINT_M = 0.2   # footprint_radius_m of motor_params.yaml
STOP = Zone('stop_box', 'stop', points=[(0.3, 0.3), (-0.3, 0.3), (-0.3, -0.3), (0.3, -0.3)],
            min_points=4)
SLOW = Zone('slow_box', 'slowdown', points=[(0.6, 0.6), (-0.6, 0.6), (-0.6, -0.6),
                                            (0.6, -0.6)], min_points=4, slowdown_ratio=0.4)
APPROACH = Zone('footprint', 'approach', radius=FOOTPRINT_M, min_points=1,
                time_before_collision=1.0)


def scan(points, age_s=0.05):
    """Return one fresh source holding points."""
    return [SourceData('scan', np.array(points, dtype=float).reshape(-1, 2), age_s)]


def cluster(x, y, count=4):
    """Return `count` points within 1 cm of (x, y)."""
    return [(x + 0.01 * math.cos(k), y + 0.01 * math.sin(k)) for k in range(count)]


@pytest.mark.parametrize('kwargs, message', [
    ({'name': 'z', 'action_type': 'brake', 'radius': 0.3}, 'action_type'),
    ({'name': 'z', 'action_type': 'stop'}, 'exactly one'),
    ({'name': 'z', 'action_type': 'stop', 'radius': 0.3, 'points': [(0, 0)] * 3},
     'exactly one'),
    ({'name': 'z', 'action_type': 'stop', 'points': [(0, 0), (1, 0)]}, 'points'),
    ({'name': 'z', 'action_type': 'stop', 'radius': -0.1}, 'radius'),
    ({'name': 'z', 'action_type': 'stop', 'radius': 0.3, 'min_points': 0}, 'min_points'),
    ({'name': 'z', 'action_type': 'slowdown', 'radius': 0.3, 'slowdown_ratio': 1.5},
     'slowdown_ratio'),
    ({'name': 'z', 'action_type': 'approach', 'radius': 0.3, 'time_before_collision': 0.0},
     'time_before_collision'),
    ({'name': '', 'action_type': 'stop', 'radius': 0.3}, 'name'),
])
def test_zone_rejects_bad_definitions(kwargs, message):
    """Each bad field raises ValueError naming it."""
    with pytest.raises(ValueError, match=message):
        Zone(**kwargs)


def test_monitor_rejects_duplicate_names_and_bad_timeout():
    """Zone names are unique; source_timeout > 0."""
    with pytest.raises(ValueError, match='unique'):
        CollisionMonitor([STOP, STOP])
    with pytest.raises(ValueError, match='source_timeout'):
        CollisionMonitor([STOP], source_timeout=0.0)


def test_nothing_near_passes_the_command_through():
    """Points 2 m away: the command is unchanged, action 'none'."""
    result = CollisionMonitor([STOP, SLOW, APPROACH]).process((0.5, 0.1, 0.3),
                                                              scan(cluster(2.0, 0.0)))
    assert (result.twist, result.action, result.zone) == ((0.5, 0.1, 0.3), 'none', '')


def test_stop_needs_min_points_inside():
    """4 points inside the stop box stop the robot; 3 do not (min_points 4)."""
    monitor = CollisionMonitor([STOP])
    result = monitor.process((0.5, 0.0, 0.0), scan(cluster(0.25, 0.0, 4)))
    assert (result.twist, result.action, result.zone) == ((0.0, 0.0, 0.0), 'stop', 'stop_box')
    assert '4 points inside' in result.reason
    result = monitor.process((0.5, 0.0, 0.0), scan(cluster(0.25, 0.0, 3)))
    assert result.action == 'none'


def test_a_stopped_robot_may_back_away_from_what_stopped_it():
    """
    Let a robot stopped by points back away from them, and only that way.

    4 points at (0.25, 0) in the stop box: forward and sideways stop; backward
    (p . v = 0.25 * -0.1 < 0 for each) passes; backward while turning stops (a box turns
    its corners into things); a circle stop zone lets the same turn pass.
    """
    monitor = CollisionMonitor([STOP])
    points = scan(cluster(0.25, 0.0, 4))
    assert monitor.process((0.1, 0.0, 0.0), points).action == 'stop'
    assert monitor.process((0.0, 0.1, 0.0), points).action == 'stop'
    assert monitor.process((0.0, 0.0, 0.5), points).action == 'stop'
    result = monitor.process((-0.1, 0.0, 0.0), points)
    assert (result.twist, result.action) == ((-0.1, 0.0, 0.0), 'none')
    assert monitor.process((-0.1, 0.0, 0.5), points).action == 'stop'
    ring = CollisionMonitor([Zone('ring', 'stop', radius=0.3, min_points=4)])
    assert ring.process((-0.1, 0.0, 0.5), points).twist == (-0.1, 0.0, 0.5)
    # Points ahead and to the left: back-and-right escapes both, back-and-left does not
    # (p = (0, 0.25) . v = (-0.1, 0.1) = +0.025 > 0).
    both = scan(cluster(0.25, 0.0, 4) + cluster(0.0, 0.25, 4))
    assert monitor.process((-0.1, -0.1, 0.0), both).action == 'none'
    assert monitor.process((-0.1, 0.1, 0.0), both).action == 'stop'


def test_approach_lets_a_robot_back_out_of_a_touch():
    """
    Let a robot back out of a touch, scaled by what is behind it.

    A point inside the footprint (0.1 m ahead): forward stops (t_c 0, as in Nav2);
    backward escapes it and is scaled only by the other points: one 0.65 m behind is
    reached when the footprint (0.2 m) has moved 0.45 m, at 0.5 m/s after 0.9 s, so the
    twist is scaled by 0.9 / 1.0.
    """
    touching = scan([(0.1, 0.0)])
    assert CollisionMonitor([APPROACH]).process((0.5, 0.0, 0.0), touching).twist == \
        (0.0, 0.0, 0.0)
    assert CollisionMonitor([APPROACH]).process((-0.5, 0.0, 0.0), touching).action == 'none'
    behind = scan([(0.1, 0.0), (-0.65, 0.0)])
    result = CollisionMonitor([APPROACH]).process((-0.5, 0.0, 0.0), behind)
    assert result.collision_time_s == pytest.approx(0.9, abs=2e-4)
    assert result.twist == pytest.approx((-0.45, 0.0, 0.0), abs=1e-3)


def test_slowdown_scales_the_whole_twist():
    """Points at 0.5 m (in the slow box, not the stop box): twist x 0.4."""
    result = CollisionMonitor([STOP, SLOW]).process((0.5, -0.25, 1.0), scan(cluster(0.5, 0.0)))
    assert result.twist == pytest.approx((0.2, -0.1, 0.4))
    assert (result.action, result.zone) == ('slowdown', 'slow_box')


def test_the_most_restrictive_zone_wins():
    """Points in both boxes: stop beats slowdown whatever the order."""
    points = scan(cluster(0.25, 0.0))
    for zones in ([STOP, SLOW], [SLOW, STOP]):
        result = CollisionMonitor(zones).process((0.5, 0.0, 0.0), points)
        assert (result.twist, result.zone) == ((0.0, 0.0, 0.0), 'stop_box')


def test_limit_caps_translation_speed_and_rotation():
    """(0.6, 0.8) m/s is 1.0 m/s: limited to 0.5 m/s -> (0.3, 0.4); wz 1.0 -> 0.3."""
    zone = Zone('limit', 'limit', radius=1.0, min_points=1, linear_limit=0.5, angular_limit=0.3)
    result = CollisionMonitor([zone]).process((0.6, 0.8, 1.0), scan([(0.8, 0.0)]))
    assert result.twist == pytest.approx((0.3, 0.4, 0.3))


def test_disabled_zones_are_ignored():
    """A disabled stop zone does nothing."""
    zone = Zone('stop', 'stop', radius=1.0, min_points=1, enabled=False)
    assert CollisionMonitor([zone]).process((0.5, 0.0, 0.0), scan([(0.5, 0.0)])).action == 'none'


def test_approach_obstacle_ahead_by_hand():
    """
    Point 0.5 m ahead, 0.5 m/s, footprint 0.2 m, time_before_collision 1.0 s.

    The footprint touches it after 0.5 - 0.2 = 0.3 m, i.e. t_c = 0.6 s; the twist is
    scaled by 0.6 / 1.0: 0.3 m/s, which needs exactly 1.0 s for those 0.3 m.
    """
    result = CollisionMonitor([APPROACH]).process((0.5, 0.0, 0.0), scan([(0.5, 0.0)]))
    assert result.twist == pytest.approx((0.3, 0.0, 0.0), abs=1e-4)
    assert result.collision_time_s == pytest.approx(0.6, abs=1e-4)
    assert (result.action, result.zone) == ('approach', 'footprint')


def test_approach_far_enough_is_not_limited():
    """Point 0.8 m ahead at 0.5 m/s: contact after 1.2 s > 1.0 s, no action."""
    result = CollisionMonitor([APPROACH]).process((0.5, 0.0, 0.0), scan([(0.8, 0.0)]))
    assert result.action == 'none' and result.twist == (0.5, 0.0, 0.0)


def test_approach_sideways_limits_strafing_but_not_driving_forward():
    """
    Point 0.5 m to the left (0, 0.5).

    Strafing left at 0.5 m/s: contact after 0.3 m, 0.6 s -> vy 0.3 m/s. Driving forward
    at 0.5 m/s: the centre moves along x and stays >= 0.5 m from the point, so no limit.
    """
    monitor = CollisionMonitor([APPROACH])
    points = scan([(0.0, 0.5)])
    left = monitor.process((0.0, 0.5, 0.0), points)
    assert left.twist == pytest.approx((0.0, 0.3, 0.0), abs=1e-4)
    assert left.action == 'approach'
    forward = monitor.process((0.5, 0.0, 0.0), points)
    assert forward.action == 'none' and forward.twist == (0.5, 0.0, 0.0)
    right = monitor.process((0.0, -0.5, 0.0), points)   # strafing away from it
    assert right.action == 'none'


def test_approach_follows_the_arc_of_a_turning_twist():
    """
    Twist (0.5, 0, 0.5): an arc of radius 1 m about (0, 1). A point on it at angle 0.8 rad.

    Contact when the centre's chord to the point is 0.2 m: 2 sin(d / 2) = 0.2, d =
    0.20034 rad, so t_c = (0.8 - 0.20034) / 0.5 = 1.19932 s; with 2 s the twist is
    scaled by 0.59966. Driving straight instead, the point (0.717, 0.303) stays 0.303 m
    from the x axis: no contact.
    """
    point = (math.sin(0.8), 1.0 - math.cos(0.8))
    zone = Zone('footprint', 'approach', radius=FOOTPRINT_M, min_points=1,
                time_before_collision=2.0)
    t_c = (0.8 - 2.0 * math.asin(0.1)) / 0.5
    result = CollisionMonitor([zone]).process((0.5, 0.0, 0.5), scan([point]))
    assert result.collision_time_s == pytest.approx(t_c, abs=2e-4)
    assert result.twist == pytest.approx((0.5 * t_c / 2.0, 0.0, 0.5 * t_c / 2.0), abs=1e-4)
    assert CollisionMonitor([zone]).process((0.5, 0.0, 0.0), scan([point])).action == 'none'


def test_approach_with_a_polygon_footprint_and_rotation():
    """
    A 0.4 m x 0.2 m rectangle turning on the spot at 1 rad/s; point at (0, 0.15).

    In the turning body frame the point, 0.15 m from the centre, sits at angle
    pi/2 - t; it is inside |x| <= 0.2, |y| <= 0.1 once 0.15 sin(pi/2 - t) <= 0.1, i.e.
    pi/2 - t <= asin(0.1 / 0.15) = 0.7297 rad: t_c = 0.8411 s.
    """
    zone = Zone('rectangle', 'approach', points=[(0.2, 0.1), (-0.2, 0.1), (-0.2, -0.1),
                                                 (0.2, -0.1)],
                min_points=1, time_before_collision=2.0)
    t_c = collision_time(zone, (0.0, 0.0, 1.0), np.array([[0.0, 0.15]]))
    assert t_c == pytest.approx(math.pi / 2 - math.asin(0.1 / 0.15), abs=2e-4)


def test_approach_needs_min_points_and_stops_when_already_touching():
    """min_points 2 ignores a lone point; a point inside the footprint now gives t_c 0: stop."""
    zone = Zone('footprint', 'approach', radius=FOOTPRINT_M, min_points=2,
                time_before_collision=1.0)
    assert CollisionMonitor([zone]).process((0.5, 0.0, 0.0), scan([(0.5, 0.0)])).action == \
        'none'
    result = CollisionMonitor([APPROACH]).process((0.5, 0.0, 0.0), scan([(0.1, 0.0)]))
    assert result.twist == (0.0, 0.0, 0.0) and result.collision_time_s == 0.0


def test_stale_or_missing_data_stops():
    """Data older than source_timeout (or none at all) stop the robot, naming the source."""
    monitor = CollisionMonitor([APPROACH], source_timeout=0.5)
    stale = monitor.process((0.5, 0.0, 0.0), scan([(3.0, 0.0)], age_s=0.6))
    assert (stale.twist, stale.action) == ((0.0, 0.0, 0.0), 'stop')
    assert "'scan'" in stale.reason and '0.6 s old' in stale.reason
    assert monitor.process((0.5, 0.0, 0.0), scan([(3.0, 0.0)], age_s=0.4)).action == 'none'
    assert monitor.process((0.5, 0.0, 0.0), []).action == 'stop'
    assert monitor.process((0.5, 0.0, 0.0), scan([], age_s=math.nan)).action == 'stop'


def test_bad_command_stops_and_nan_points_are_dropped():
    """A NaN command gives stop; NaN/inf points do not count as obstacles."""
    monitor = CollisionMonitor([STOP])
    result = monitor.process((math.nan, 0.0, 0.0), scan([(3.0, 0.0)]))
    assert (result.twist, result.action) == ((0.0, 0.0, 0.0), 'stop')
    assert 'bad command' in result.reason
    points = cluster(0.25, 0.0, 3) + [(math.nan, 0.0), (0.2, math.inf)]
    assert monitor.process((0.5, 0.0, 0.0), scan(points)).action == 'none'


def test_scan_to_points_by_hand():
    """
    A laser at (0.05, 0.1) turned +pi/2 in base_link, beams every pi/2, 0.1..10 m.

    Ranges [1, inf, nan, 0.05, 2, -inf] from angle_min 0. Beam 0 (laser +x, base +y):
    1 m -> (0.05, 1.1). Beam 4 (2 pi): 2 m -> (0.05, 2.1).
    inf, nan, 0.05 (< range_min) and -inf are dropped; with too_close_as_range_min the
    -inf of beam 5 (5 pi / 2 in the laser, 3 pi in base) sits at 0.1 m: (-0.05, 0.1).
    """
    ranges = [1.0, math.inf, math.nan, 0.05, 2.0, -math.inf]
    mount = (0.05, 0.1, math.pi / 2)
    points = scan_to_points(ranges, 0.0, math.pi / 2, 0.1, 10.0, mount)
    assert points == pytest.approx(np.array([[0.05, 1.1], [0.05, 2.1]]), abs=1e-12)
    points = scan_to_points(ranges, 0.0, math.pi / 2, 0.1, 10.0, mount,
                            too_close_as_range_min=True)
    assert points[-1] == pytest.approx((-0.05, 0.1), abs=1e-12)
    assert scan_to_points([12.0], 0.0, 0.1, 0.1, 10.0).shape == (0, 2)   # beyond range_max
    with pytest.raises(ValueError, match='angle_increment'):
        scan_to_points(ranges, 0.0, math.nan, 0.1, 10.0)


# --- a bad lidar fails safe (issue 31) ------------------------------------------------

def source(age_s=0.05, usable_fraction=1.0, identical_scans=0):
    """Return one source with a point 3 m ahead and the given health."""
    return [SourceData('scan', np.array([[3.0, 0.0]]), age_s,
                       usable_fraction=usable_fraction, identical_scans=identical_scans)]


def test_scan_usable_fraction_by_hand():
    """
    8 beams every pi/4 from 0 (angle_max 7 pi/4), range 0.1..10 m.

    [1, inf, nan, -inf, 0.05, 12.5, 10, 0.1]: 1 m, -inf (too close, REP-117: taken as
    range_min), 10 m and 0.1 m (the limits are included) are usable; +inf (no return),
    NaN (an error), 0.05 m (below range_min) and 12.5 m (above range_max) are not: 4/8.
    """
    ranges = [1.0, math.inf, math.nan, -math.inf, 0.05, 12.5, 10.0, 0.1]
    assert scan_usable_fraction(ranges, 0.0, 7 * math.pi / 4, math.pi / 4, 0.1, 10.0) == 0.5
    assert scan_usable_fraction([math.inf] * 8, 0.0, 7 * math.pi / 4, math.pi / 4, 0.1,
                                10.0) == 0.0
    # Drivers that give angle_max one increment further (the end of the last beam's
    # sector) are accepted; so is a decreasing scan.
    assert scan_usable_fraction(ranges, 0.0, 2 * math.pi, math.pi / 4, 0.1, 10.0) == 0.5
    assert scan_usable_fraction(ranges, 0.0, -7 * math.pi / 4, -math.pi / 4, 0.1,
                                10.0) == 0.5


@pytest.mark.parametrize('ranges, angles, limits, message', [
    ([], (0.0, 0.0, 0.1), (0.1, 10.0), 'no beams'),
    ([1.0] * 8, (0.0, math.pi, math.pi / 4), (0.1, 10.0), 'angle_max'),
    ([1.0] * 8, (0.0, 7 * math.pi / 4, -math.pi / 4), (0.1, 10.0), 'angle_max'),
    ([1.0] * 8, (0.0, 0.0, 0.0), (0.1, 10.0), 'angle_increment'),
    ([1.0] * 8, (math.nan, 7 * math.pi / 4, math.pi / 4), (0.1, 10.0), 'angle_min'),
    ([1.0] * 400, (0.0, 399 * 0.1, 0.1), (0.1, 10.0), 'more than one turn'),
    ([1.0] * 8, (0.0, 7 * math.pi / 4, math.pi / 4), (0.1, 0.1), 'range_max'),
    ([1.0] * 8, (0.0, 7 * math.pi / 4, math.pi / 4), (-0.1, 10.0), 'range_min'),
])
def test_scans_with_no_beams_or_inconsistent_fields_are_invalid(ranges, angles, limits,
                                                                message):
    """Each raises ValueError naming what is wrong."""
    with pytest.raises(ValueError, match=message):
        scan_usable_fraction(ranges, *angles, *limits)


def test_a_blinded_source_stops_until_its_beams_return():
    """
    min_valid_beam_fraction 0.5: below half the beams usable, stop; half passes.

    0.49 of the beams usable stops, naming the source and the fraction; 0.5 (not below
    it) passes; so does the next good scan (no latch).
    """
    monitor = CollisionMonitor([STOP], min_valid_beam_fraction=0.5)
    blind = monitor.process((0.3, 0.0, 0.0), source(usable_fraction=0.0))
    assert (blind.twist, blind.action, blind.fault) == ((0.0, 0.0, 0.0), 'stop',
                                                        'scan blinded')
    assert "'scan'" in blind.reason and '0% of its beams' in blind.reason
    assert monitor.process((0.3, 0.0, 0.0), source(usable_fraction=0.49)).action == 'stop'
    assert '49%' in monitor.process((0.3, 0.0, 0.0), source(usable_fraction=0.49)).reason
    good = monitor.process((0.3, 0.0, 0.0), source(usable_fraction=0.5))
    assert (good.twist, good.action, good.fault) == ((0.3, 0.0, 0.0), 'none', '')
    # 0 turns the check off.
    assert CollisionMonitor([STOP], min_valid_beam_fraction=0.0).process(
        (0.3, 0.0, 0.0), source(usable_fraction=0.0)).action == 'none'


def test_a_frozen_source_stops_until_its_scans_change():
    """max_identical_scans 5: 4 repeats pass, the 5th stops ('frozen'); 0 turns it off."""
    monitor = CollisionMonitor([STOP], max_identical_scans=5)
    assert monitor.process((0.3, 0.0, 0.0), source(identical_scans=4)).action == 'none'
    frozen = monitor.process((0.3, 0.0, 0.0), source(identical_scans=5))
    assert (frozen.twist, frozen.action, frozen.fault) == ((0.0, 0.0, 0.0), 'stop',
                                                           'scan frozen')
    assert "'scan'" in frozen.reason and '5 identical scans' in frozen.reason
    assert monitor.process((0.3, 0.0, 0.0), source(identical_scans=0)).twist == \
        (0.3, 0.0, 0.0)
    assert CollisionMonitor([STOP], max_identical_scans=0).process(
        (0.3, 0.0, 0.0), source(identical_scans=100)).action == 'none'


def test_stamps_are_checked_both_ways():
    """
    source_timeout 0.5 s, max_future_stamp_s 0.1 s; age = now - stamp, signed.

    -0.05 s (a stamp just ahead of our clock) and -0.1 s pass; -0.2 s stops as stamped
    in the future, as 0.6 s stops as stale; a scan stamped now passes again (no latch).
    """
    monitor = CollisionMonitor([STOP], source_timeout=0.5, max_future_stamp_s=0.1)
    assert monitor.process((0.3, 0.0, 0.0), source(age_s=-0.05)).action == 'none'
    assert monitor.process((0.3, 0.0, 0.0), source(age_s=-0.1)).action == 'none'
    future = monitor.process((0.3, 0.0, 0.0), source(age_s=-0.2))
    assert (future.twist, future.action, future.fault) == (
        (0.0, 0.0, 0.0), 'stop', 'scan stamped in the future')
    assert "'scan'" in future.reason and '0.2 s in the future' in future.reason
    stale = monitor.process((0.3, 0.0, 0.0), source(age_s=0.6))
    assert (stale.action, stale.fault) == ('stop', 'scan stale')
    assert monitor.process((0.3, 0.0, 0.0), source(age_s=0.0)).action == 'none'


@pytest.mark.parametrize('kwargs, message', [
    ({'min_valid_beam_fraction': 1.5}, 'min_valid_beam_fraction'),
    ({'min_valid_beam_fraction': -0.1}, 'min_valid_beam_fraction'),
    ({'max_identical_scans': -1}, 'max_identical_scans'),
    ({'max_identical_scans': 2.5}, 'max_identical_scans'),
    ({'max_identical_scans': True}, 'max_identical_scans'),
    ({'max_future_stamp_s': -0.1}, 'max_future_stamp_s'),
    ({'max_future_stamp_s': math.nan}, 'max_future_stamp_s'),
])
def test_monitor_rejects_bad_source_checks(kwargs, message):
    """Each bad setting raises ValueError naming it."""
    with pytest.raises(ValueError, match=message):
        CollisionMonitor([STOP], **kwargs)


BASE = np.full(40, 2.0, dtype=np.float32)
#: 1 cm of alternating noise: the 39 neighbour pairs' differences all change sign.
NOISY = BASE + np.float32(0.01) * np.where(np.arange(40) % 2, 1, -1).astype(np.float32)


def test_scan_repeats_count_identical_scans_of_a_noisy_source():
    """
    A source that has shown noise: each scan equal to the one before counts one.

    BASE then NOISY: the differences alternate in sign (39 of 39 neighbour pairs, >= a
    quarter): noise, the check is armed; NOISY again 5 times: 1, 2, 3, 4, 5; a changed
    scan: 0 again. NaN beams equal to NaN beams count as identical too.
    """
    repeats = ScanRepeats()
    assert repeats.update(BASE) == 0 and not repeats.armed
    assert repeats.update(NOISY) == 0 and repeats.armed
    assert [repeats.update(NOISY.copy()) for _ in range(5)] == [1, 2, 3, 4, 5]
    assert repeats.update(BASE) == 0
    with_nan = BASE.copy()
    with_nan[3] = np.nan
    assert repeats.update(with_nan) == 0
    assert repeats.update(with_nan.copy()) == 1


def test_scan_repeats_of_a_noiseless_source_are_not_counted():
    """
    Repeats of a noiseless lidar are not a frozen driver.

    A noiseless lidar (simulator with sensor_noise_scale 0) repeats itself while the
    robot stands. Motion moves every range the same way
    (BASE + 1 cm: 39 pairs, no sign change) and a walker changes a few neighbouring
    beams (beams 10..14 by -1, -11, +1, -11, +1 cm: 3 sign changes in 4 pairs, but 4
    pairs < 10): neither arms the check, so repeats count 0.
    """
    repeats = ScanRepeats()
    walker = BASE + np.float32(0.01)
    walker[10:15] = [2.0, 1.9, 2.02, 1.9, 2.02]
    for ranges in (BASE, BASE + np.float32(0.01), BASE + np.float32(0.01), walker, walker):
        assert repeats.update(ranges) == 0
    assert not repeats.armed
    # A scan of another length is a new scan, never a repeat.
    assert repeats.update(np.full(20, 2.0)) == 0


@pytest.mark.parametrize('block, armed', [(3, True), (4, False)])
def test_scan_repeats_arm_on_a_quarter_of_sign_changes(block, armed):
    """
    40 beams moved by +-1 cm in blocks of equal sign: 39 neighbour pairs.

    Blocks of 3 change sign 13 times (13 / 39 = 0.33 >= 0.25: noise, armed); blocks of
    4 change it 9 times (9 / 39 = 0.23 < 0.25: not noise, the repeats do not count).
    """
    signs = np.where((np.arange(40) // block) % 2, 1.0, -1.0)
    repeats = ScanRepeats()
    repeats.update(BASE)
    moved = BASE + (0.01 * signs).astype(np.float32)
    repeats.update(moved)
    assert repeats.armed == armed
    assert repeats.update(moved.copy()) == (1 if armed else 0)
