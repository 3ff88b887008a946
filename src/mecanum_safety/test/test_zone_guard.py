"""Tests of mecanum_safety.zone_guard: hand-worked cases and properties."""

import math
import random

from hypothesis import assume, given, HealthCheck, settings, strategies as st
from mecanum_control.kinematics import integrate_pose
from mecanum_safety import zone_guard as guard
from mecanum_safety.zone import make_zone, ZoneError
import numpy as np
import pytest

RADIUS = 0.2     # footprint_radius_m of motor_params.yaml
MARGIN = 0.05
HORIZON = 1.0
SQUARE = make_zone([(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)])
# The square 0..4 without its top-right quarter: a reflex corner at (2, 2).
L_SHAPE = make_zone([(0.0, 0.0), (4.0, 0.0), (4.0, 2.0), (2.0, 2.0), (2.0, 4.0),
                     (0.0, 4.0)])
# A 6 x 4 room with a 1 m square excluded in the middle of its right half.
ROOM_WITH_ISLAND = make_zone([(0.0, 0.0), (6.0, 0.0), (6.0, 4.0), (0.0, 4.0)],
                             [[(3.0, 1.5), (4.0, 1.5), (4.0, 2.5), (3.0, 2.5)]])


def scale_of(zone, pose, twist, radius=RADIUS, margin=MARGIN, horizon=HORIZON):
    """Return the guard's scale and reason."""
    result = guard.guard_scale(zone, pose, twist, radius, margin, horizon)
    return result.scale, result.reason


# --- hand-worked cases ------------------------------------------------------------------


@pytest.mark.parametrize('pose, twist, expected', [
    # 1 m from the right border x = 4: 0.75 m of travel allowed (1 - 0.2 - 0.05).
    ((3.0, 2.0, 0.0), (0.5, 0.0, 0.0), 1.0),            # 0.5 m requested
    ((3.0, 2.0, 0.0), (1.0, 0.0, 0.0), 0.75),           # 1 m requested
    ((3.0, 2.0, 0.0), (2.0, 0.0, 0.0), 0.375),          # 2 m requested
    ((3.0, 2.0, math.pi / 2), (0.0, -1.5, 0.0), 0.5),   # facing north, strafing right (east)
    ((3.0, 2.0, math.pi), (-1.0, 0.0, 0.0), 0.75),      # facing west, backing up
    ((3.0, 2.0, 0.0), (1.2, 1.6, 0.0), 0.625),          # 1.2 m east, 1.6 north: x limits
])
def test_driving_at_a_straight_border_scales_to_the_allowed_travel(pose, twist, expected):
    scale, reason = scale_of(SQUARE, pose, twist)
    assert scale == pytest.approx(expected, abs=1e-9)
    assert reason == (guard.REASON_CLEAR if expected == 1.0 else guard.REASON_APPROACHING)


def test_driving_away_from_the_border_is_not_scaled():
    assert scale_of(SQUARE, (3.0, 2.0, 0.0), (-2.0, 0.0, 0.0)) == (1.0, guard.REASON_CLEAR)
    assert scale_of(SQUARE, (3.5, 2.0, 0.0), (-0.5, 0.4, 0.0)) == (1.0, guard.REASON_CLEAR)


def test_the_whole_twist_is_scaled_on_an_arc_by_hand():
    # From (2, 2) facing east, vx 1 m/s and wz 1 rad/s: the circle of radius 1 about
    # (2, 3); its y = 3 - cos(theta) reaches 4 - 0.25 at theta = acos(-0.75) (x = 2.66).
    pose, twist = (2.0, 2.0, 0.0), (1.0, 0.0, 1.0)
    assert scale_of(SQUARE, pose, twist, horizon=1.0)[0] == 1.0
    scale, reason = scale_of(SQUARE, pose, twist, horizon=3.0)
    assert scale == pytest.approx(math.acos(-0.75) / 3.0, abs=1e-9)
    assert reason == guard.REASON_APPROACHING


def test_at_the_margin_toward_stops_away_and_along_pass():
    at_margin = (4.0 - RADIUS - MARGIN, 2.0, 0.0)      # clearance exactly 0.25
    assert scale_of(SQUARE, at_margin, (0.3, 0.0, 0.0)) == (0.0, guard.REASON_AT_BORDER)
    assert scale_of(SQUARE, at_margin, (0.3, 0.0, 0.5))[0] == 0.0
    assert scale_of(SQUARE, at_margin, (-0.3, 0.0, 0.0)) == (1.0, guard.REASON_CLEAR)
    assert scale_of(SQUARE, at_margin, (0.0, 0.5, 0.0)) == (1.0, guard.REASON_CLEAR)
    assert scale_of(SQUARE, at_margin, (0.0, -0.5, 0.0)) == (1.0, guard.REASON_CLEAR)


def test_inside_the_margin_band_any_motion_that_gets_no_nearer_is_allowed():
    band = (3.78, 2.0, 0.0)          # footprint inside, 0.02 m from the border (< margin)
    assert scale_of(SQUARE, band, (-0.3, 0.0, 0.0)) == (1.0, guard.REASON_CLEAR)
    assert scale_of(SQUARE, band, (0.0, 0.3, 0.0)) == (1.0, guard.REASON_CLEAR)  # along
    assert scale_of(SQUARE, band, (0.1, 0.0, 0.0)) == (0.0, guard.REASON_AT_BORDER)


# Outside the zone (the footprint crosses the border: clearance < RADIUS) the robot may
# only move back in: every step must bring the footprint at least INWARD_MIN_SLOPE (0.1)
# of its travel further in, until it is RADIUS + MARGIN (0.25 m) inside.
OUTSIDE = (4.1, 2.0, 0.0)            # the centre 0.1 m out of the 4 m square (x = 4)


@pytest.mark.parametrize('pose, twist, expected', [
    (OUTSIDE, (-0.5, 0.0, 0.0), (1.0, guard.REASON_BACK_IN)),        # straight in
    (OUTSIDE, (-0.3, 0.4, 0.0), (1.0, guard.REASON_BACK_IN)),        # slope 0.6
    (OUTSIDE, (-0.1, 0.5, 0.0), (1.0, guard.REASON_BACK_IN)),        # slope 0.196
    (OUTSIDE, (0.5, 0.0, 0.0), (0.0, guard.REASON_OUTSIDE)),         # outward
    (OUTSIDE, (0.0, 0.5, 0.0), (0.0, guard.REASON_OUTSIDE)),         # parallel
    (OUTSIDE, (0.0, -0.5, 0.0), (0.0, guard.REASON_OUTSIDE)),        # parallel
    (OUTSIDE, (-0.02, 0.5, 0.0), (0.0, guard.REASON_OUTSIDE)),       # slope 0.04 < 0.1
    ((4.1, 2.0, math.pi / 2), (0.0, 0.5, 0.0), (1.0, guard.REASON_BACK_IN)),  # west
    # The centre inside (x = 3.85) but the footprint 0.05 m over the border: outside too.
    ((3.85, 2.0, 0.0), (-0.3, 0.0, 0.0), (1.0, guard.REASON_BACK_IN)),
    ((3.85, 2.0, 0.0), (0.0, 0.3, 0.0), (0.0, guard.REASON_OUTSIDE)),
    ((3.85, 2.0, 0.0), (0.1, 0.0, 0.0), (0.0, guard.REASON_OUTSIDE)),
    # Inside the excluded square of the room (centre 0.5 m from its edges): out east.
    ((3.5, 2.0, 0.0), (0.5, 0.0, 0.0), (1.0, guard.REASON_BACK_IN)),
])
def test_outside_the_zone_only_motion_back_in_is_allowed(pose, twist, expected):
    zone = ROOM_WITH_ISLAND if pose[:2] == (3.5, 2.0) else SQUARE
    scale, reason = scale_of(zone, pose, twist)
    assert (scale, reason) == (pytest.approx(expected[0], abs=1e-9), expected[1])


def test_outside_an_arc_is_cut_where_it_stops_getting_back_in():
    # From (4.1, 2) facing east, backing at 0.5 m/s while turning at 2 rad/s: the circle
    # x = 4.1 - 0.25 sin(2t), so the clearance is -0.1 + 0.25 sin(2t) (x = 4 the nearest
    # border) and grows by cos(2t) per metre of travel: at least 0.1 until
    # t = acos(0.1) / 2 = 0.7353 s (1 s asked), still 0.05 m over the border there. The
    # rule holds between samples 1 cm (0.02 s) apart: the cut is within one of them.
    scale, reason = scale_of(SQUARE, OUTSIDE, (-0.5, 0.0, 2.0))
    assert scale == pytest.approx(math.acos(0.1) / 2.0, abs=0.02)
    assert reason == guard.REASON_BACK_IN


def test_outside_a_corner_in_then_along_the_border_is_cut():
    # From (4.1, 4.1), 0.1414 m from the corner (4, 4), west: the clearance is
    # -sqrt(u^2 + 0.01) (u = x - 4), then -0.1 along the top edge (parallel, outside).
    # It grows by u / sqrt(u^2 + 0.01) per metre: >= 0.1 while u >= 0.01 / sqrt(0.99),
    # so 0.1 - 0.01005 m of the 0.5 m asked; between samples 1 cm apart (u = 0.02 to
    # 0.01: +0.0015 m, u = 0.01 to 0: +0.0005 m) the last one kept is u = 0.01.
    scale, reason = scale_of(SQUARE, (4.1, 4.1, 0.0), (-0.5, 0.0, 0.0))
    assert 0.1 - 0.01 / math.sqrt(0.99) - 1e-6 <= scale * 0.5 <= 0.09 + 1e-6
    assert reason == guard.REASON_BACK_IN


def test_back_inside_the_motion_continues_to_the_margin_and_stops_there():
    # Straight in from 0.1 m out, 2 m asked: in, then on to the far border (x = 0) until
    # 0.25 m from it: 4.1 - 0.25 = 3.85 m of travel, like any motion from inside.
    scale, reason = scale_of(SQUARE, OUTSIDE, (-4.0, 0.0, 0.0))
    assert scale == pytest.approx(3.85 / 4.0, abs=1e-9)
    assert reason == guard.REASON_BACK_IN


@pytest.mark.parametrize('pose, reason', [
    ((2.0, 2.0, 0.0), guard.REASON_CLEAR), ((3.75, 2.0, 1.0), guard.REASON_CLEAR),
    ((3.9, 3.9, -2.0), guard.REASON_TURNING_OUTSIDE),
    ((4.5, 2.0, 0.0), guard.REASON_TURNING_OUTSIDE)])
def test_pure_rotation_is_always_allowed(pose, reason):
    # The footprint circle about base_link does not move (inside or out).
    assert scale_of(SQUARE, pose, (0.0, 0.0, 2.5)) == (1.0, reason)


def test_a_concave_corner_counts_by_its_vertex():
    # From (1, 1) towards the reflex corner (2, 2), 1.414 m away: the clearance on the
    # diagonal is the distance to that vertex, sqrt(2) - travel.
    scale, _ = scale_of(L_SHAPE, (1.0, 1.0, math.pi / 4), (2.0, 0.0, 0.0))
    assert scale == pytest.approx((math.sqrt(2.0) - 0.25) / 2.0, abs=1e-9)
    # From the lower arm across the notch to the upper arm: stopped at y = 2 - 0.25
    # (the notch's edge), though both ends of the requested motion are inside.
    scale, _ = scale_of(L_SHAPE, (3.0, 1.0, 0.0), (-1.0, 1.0, 0.0), horizon=2.0)
    assert scale == pytest.approx(0.75 / 2.0, abs=1e-9)
    # Along the notch's edge, 0.3 m below it: passes.
    assert scale_of(L_SHAPE, (3.0, 1.7, math.pi), (0.5, 0.0, 0.0))[0] == 1.0


def test_an_exclusion_in_front_is_a_border():
    # 2 m to the excluded square's left edge x = 3; 3 m requested.
    scale, reason = scale_of(ROOM_WITH_ISLAND, (1.0, 2.0, 0.0), (3.0, 0.0, 0.0))
    assert scale == pytest.approx(1.75 / 3.0, abs=1e-9)
    assert reason == guard.REASON_APPROACHING
    assert scale_of(ROOM_WITH_ISLAND, (2.75, 2.0, 0.0), (0.3, 0.0, 0.0)) == (
        0.0, guard.REASON_AT_BORDER)
    # Passing beside it, 0.5 m away (y = 1.0, the island's bottom edge at 1.5): allowed.
    assert scale_of(ROOM_WITH_ISLAND, (1.0, 1.0, 0.0), (3.0, 0.0, 0.0))[0] == 1.0


def test_covariance_widens_the_margin():
    zone_guard = guard.ZoneGuard(SQUARE, RADIUS, horizon_s=1.0, margin_m=0.05,
                                 covariance_factor=2.0, max_margin_m=0.5)
    pose, twist = (3.0, 2.0, 0.0), (1.0, 0.0, 0.0)
    assert zone_guard.step(pose, twist).scale == pytest.approx(0.75)
    # sigma 0.1 m: margin 0.05 + 2 * 0.1 = 0.25, travel 1 - 0.2 - 0.25.
    assert zone_guard.step(pose, twist, 0.1).scale == pytest.approx(0.55)
    # sigma 1 m: the margin is capped at 0.5.
    assert zone_guard.step(pose, twist, 1.0).scale == pytest.approx(0.3)
    assert zone_guard.step(pose, twist, math.nan).scale == pytest.approx(0.3)
    assert zone_guard.margin(0.1) == pytest.approx(0.25)
    assert zone_guard.margin(math.inf) == 0.5


def test_sigma_toward_the_border_is_along_the_normals_of_the_edges_within_reach():
    along_x = [0.1 ** 2, 0.0, 0.0, 0.02 ** 2]   # sure across a corridor along x
    # 0.4 m below the top edge (y = 4), 2 m from every vertex: the top edge's normal is y.
    assert guard.sigma_toward_border(SQUARE, 2.0, 3.6, along_x, 0.6) == pytest.approx(0.02)
    # The same covariance beside the right edge (x = 4): its normal is x.
    assert guard.sigma_toward_border(SQUARE, 3.6, 2.0, along_x, 0.6) == pytest.approx(0.1)
    # Both edges within reach: the larger.
    assert guard.sigma_toward_border(SQUARE, 2.0, 2.0, along_x, 2.5) == pytest.approx(0.1)
    # Correlated: variance along n = (0, 1) is yy; along (1, 0) xx (off-diagonal unused).
    correlated = [0.01, 0.004, 0.004, 0.0025]
    assert guard.sigma_toward_border(SQUARE, 2.0, 3.6, correlated, 0.6) == pytest.approx(0.05)
    # A vertex within reach: the worst direction (eigenvalue 0.01208..., by hand).
    worst = math.sqrt(0.00625 + math.hypot(0.00375, 0.004))
    assert guard.sigma_toward_border(SQUARE, 3.7, 3.7, correlated, 0.6) == pytest.approx(worst)
    # No edge within reach: the worst direction too; unusable covariances as sigma_xy.
    assert guard.sigma_toward_border(SQUARE, 2.0, 2.0, along_x, 0.5) == pytest.approx(0.1)
    assert math.isnan(guard.sigma_toward_border(SQUARE, 2.0, 3.6, [math.nan] * 4, 0.6))
    assert guard.sigma_toward_border(SQUARE, 2.0, 3.6, [-1.0, 0.0, 0.0, 0.0], 0.6) == math.inf


def test_drifting_toward_a_wall_in_a_corridor_along_it_is_slowed_not_stopped():
    """
    The apartment's strip behind the bed, as a sweep found it (amcl sigma 0.047 m along it).

    The zone's north edge is at y = 8; the robot, 0.34 m from it, leaves the strip east
    while turning, drifting 4 cm/s north. With the worst direction's sigma the margin
    band (0.2 + 0.05 + 2 x 0.047 = 0.344 m) covered the strip's middle and every such
    command was stopped (the navigator gave up: STUCK); across the strip amcl's sigma is
    0.028 m, so the band ends at 0.306 m and the command is only slowed.
    """
    flat = make_zone([(0.0, 0.0), (10.0, 0.0), (10.0, 8.0), (0.0, 8.0)])
    zone_guard = guard.ZoneGuard(flat, RADIUS, horizon_s=1.0, margin_m=0.05,
                                 covariance_factor=2.0, max_margin_m=0.5)
    covariance = [0.047 ** 2, 0.0, 0.0, 0.028 ** 2]
    pose, twist = (1.3, 7.66, math.pi / 2), (0.04, -0.04, -0.1)
    assert zone_guard.step(pose, twist, guard.sigma_xy(covariance)).scale == 0.0
    result = zone_guard.step(pose, twist, covariance=covariance)
    assert 0.5 < result.scale < 1.0
    assert zone_guard.sigma(pose, twist, covariance) == pytest.approx(0.028)
    # The allowed motion keeps the band across the strip: 0.2 + 0.05 + 2 x 0.028 m.
    end = guard.integrate_twist(pose, *(result.scale * v for v in twist), 1.0)
    assert 8.0 - end[1] >= 0.306 - 1e-6


def test_sigma_xy_is_the_larger_eigenvalue_of_the_position_block():
    covariance = [0.0] * 36
    covariance[0], covariance[7] = 0.01, 0.04
    covariance[35] = 9.0                             # yaw: not a position
    assert guard.sigma_xy(covariance) == pytest.approx(0.2)
    # [[a, b], [b, a]] has eigenvalues a + b and a - b.
    assert guard.sigma_xy([0.02, 0.01, 0.01, 0.02]) == pytest.approx(math.sqrt(0.03))
    assert guard.sigma_xy([0.0] * 4) == 0.0
    assert math.isnan(guard.sigma_xy([math.nan, 0.0, 0.0, 0.01]))
    assert guard.sigma_xy([-0.01, 0.0, 0.0, 0.01]) == math.inf
    with pytest.raises(ValueError, match='36'):
        guard.sigma_xy([0.0] * 9)
    assert guard.guard_margin(0.05, 2.0, 0.1, 0.5) == pytest.approx(0.25)
    assert guard.guard_margin(0.05, 2.0, math.nan, 0.5) == 0.5


# --- the localisation's health --------------------------------------------------------

MAX_SIGMA = 0.25     # max_position_sigma_m of config/zone_guard.yaml
AT = (2.0, 2.0, 0.0)
UPRIGHT = (0.0, 0.0, 0.0, 1.0)


def covariance36(xx, xy, yx, yy, yaw=0.01):
    """Return a 6x6 row-major pose covariance with this x-y block and yaw variance."""
    values = [0.0] * 36
    values[0], values[1], values[6], values[7], values[35] = xx, xy, yx, yy, yaw
    return values


AMCL_USUAL = covariance36(0.034 ** 2, 0.0001, 0.0001, 0.03 ** 2)


@pytest.mark.parametrize('position, orientation, covariance', [
    (AT, UPRIGHT, AMCL_USUAL),
    (AT, UPRIGHT, [0.0] * 36),                               # SLAM publishes zeros
    (AT, UPRIGHT, covariance36(0.25 ** 2, 0.0, 0.0, 0.01)),  # sigma exactly the limit
    ((1e6, -3.0, 0.0), (0.0, 0.0, 0.7071, 0.7071), AMCL_USUAL),
])
def test_a_usual_localisation_is_healthy(position, orientation, covariance):
    assert guard.localisation_problem(position, orientation, covariance, MAX_SIGMA) is None


@pytest.mark.parametrize('position, orientation, covariance, kind, text', [
    ((math.nan, 2.0, 0.0), UPRIGHT, AMCL_USUAL, 'NaN/inf in the pose',
     'NaN/inf in the pose (position (nan, 2.0, 0.0), orientation (0.0, 0.0, 0.0, 1.0))'),
    (AT, (0.0, 0.0, math.inf, 1.0), AMCL_USUAL, 'NaN/inf in the pose',
     'NaN/inf in the pose (position (2.0, 2.0, 0.0), orientation (0.0, 0.0, inf, 1.0))'),
    (AT, UPRIGHT, covariance36(0.01, 0.0, 0.0, 0.01, math.nan),
     'NaN/inf in the covariance', 'NaN/inf in the covariance (1 of 36 values)'),
    (AT, UPRIGHT, [math.inf] * 36, 'NaN/inf in the covariance',
     'NaN/inf in the covariance (36 of 36 values)'),
    (AT, UPRIGHT, covariance36(0.01, 0.002, 0.0, 0.01), 'covariance not symmetric',
     'covariance not symmetric (largest difference 0.002 between [0][1] and [1][0])'),
    # [[0.01, 0.02], [0.02, 0.01]]: eigenvalues 0.03 and -0.01.
    (AT, UPRIGHT, covariance36(0.01, 0.02, 0.02, 0.01), 'covariance not positive '
     'semi-definite', 'covariance not positive semi-definite (eigenvalue -0.01)'),
    (AT, UPRIGHT, covariance36(-0.0004, 0.0, 0.0, 0.01), 'covariance not positive '
     'semi-definite', 'covariance not positive semi-definite (eigenvalue -0.0004)'),
    (AT, UPRIGHT, covariance36(0.3 ** 2, 0.0, 0.0, 0.01), 'position sigma too large',
     'position sigma 0.30 m > max_position_sigma_m 0.25 m'),
    # Each axis 0.2 m, but correlated: along the diagonal 0.04 + 0.03 = 0.07 m^2.
    (AT, UPRIGHT, covariance36(0.04, 0.03, 0.03, 0.04), 'position sigma too large',
     'position sigma 0.26 m > max_position_sigma_m 0.25 m'),
])
def test_an_unhealthy_localisation_is_named(position, orientation, covariance, kind, text):
    problem = guard.localisation_problem(position, orientation, covariance, MAX_SIGMA)
    assert (problem.kind, problem.text) == (kind, text)


def test_an_unhealthy_localisation_stops_every_motion_but_turning_on_the_spot():
    zone_guard = guard.ZoneGuard(SQUARE, RADIUS, max_position_sigma_m=MAX_SIGMA)
    problem = zone_guard.localisation_problem(AT, UPRIGHT, covariance36(0.16, 0, 0, 0.16))
    assert problem.text == 'position sigma 0.40 m > max_position_sigma_m 0.25 m'
    result = zone_guard.step(AT, (0.3, 0.0, 0.0), localisation=problem)
    assert (result.scale, result.reason, result.detail) == (
        0.0, guard.REASON_LOCALISATION, problem.text)
    assert zone_guard.step(AT, (0.3, 0.0, 1.0), localisation=problem).scale == 0.0
    # Turning on the spot does not move the footprint circle (and lets amcl update).
    result = zone_guard.step(AT, (0.0, 0.0, 1.0), localisation=problem)
    assert (result.scale, result.reason) == (1.0, guard.REASON_TURNING_UNHEALTHY)
    assert not result.rotation_only
    # A ramped spin keeps a decaying translation (0.03 m/s here, under the 0.05 m/s
    # tolerance) while wz ramps up: its rotation alone passes.
    result = zone_guard.step(AT, (0.03, 0.0, 0.4), localisation=problem)
    assert (result.scale, result.reason, result.rotation_only) == (
        1.0, guard.REASON_TURNING_UNHEALTHY, True)
    # 0.06 m/s is driving, not turning on the spot: stopped; so is a translation alone.
    assert zone_guard.step(AT, (0.06, 0.0, 0.4), localisation=problem).scale == 0.0
    assert zone_guard.step(AT, (0.01, 0.0, 0.0), localisation=problem).scale == 0.0
    # Healthy again: the zone's rules only.
    assert zone_guard.step(AT, (0.3, 0.0, 0.0), localisation=None).scale == 1.0
    # Without a zone the localisation does not matter to the guard.
    no_zone = guard.ZoneGuard(None, RADIUS)
    assert no_zone.step(AT, (0.3, 0.0, 0.0), localisation=problem).scale == 1.0


@pytest.mark.parametrize('twist', [(math.nan, 0.0, 0.0), (0.0, math.inf, 0.0),
                                   (0.0, 0.0, -math.inf), (0.1, 0.0)])
def test_an_invalid_twist_stops(twist):
    assert scale_of(SQUARE, (2.0, 2.0, 0.0), twist) == (0.0, guard.REASON_INVALID_COMMAND)
    assert guard.ZoneGuard(None, RADIUS).step((2.0, 2.0, 0.0), twist).scale == 0.0


def test_an_invalid_pose_stops_and_no_zone_passes():
    assert scale_of(SQUARE, (math.nan, 2.0, 0.0), (0.1, 0.0, 0.0)) == (
        0.0, guard.REASON_INVALID_POSE)
    result = guard.ZoneGuard(None, RADIUS).step((math.nan,) * 3, (5.0, 0.0, 1.0))
    assert (result.scale, result.reason) == (1.0, guard.REASON_CLEAR)


def test_the_result_reports_the_clearance():
    result = guard.guard_scale(SQUARE, (3.5, 2.0, 0.0), (1.0, 0.0, 0.0), RADIUS, MARGIN,
                               HORIZON)
    assert result.clearance_m == pytest.approx(0.5)
    assert result.required_m == pytest.approx(0.25)
    assert result.gap_m(RADIUS) == pytest.approx(0.3)
    assert result.scale == pytest.approx(0.25)


@pytest.mark.parametrize('kwargs, message', [
    ({'footprint_radius_m': 0.0}, 'footprint_radius_m must be a finite number > 0'),
    ({'horizon_s': math.inf}, 'horizon_s must be a finite number > 0'),
    ({'margin_m': -0.1}, 'margin_m must be a finite number >= 0'),
    ({'covariance_factor': math.nan}, 'covariance_factor must be'),
    ({'max_margin_m': 0.01}, r'max_margin_m \(0.01\) must be >= margin_m \(0.05\)'),
    ({'margin_m': True}, 'margin_m must be'),
    ({'max_position_sigma_m': 0.0}, 'max_position_sigma_m must be a finite number > 0'),
    ({'max_position_sigma_m': math.nan}, 'max_position_sigma_m must be a finite number > 0'),
])
def test_settings_are_checked_naming_them(kwargs, message):
    settings_ = {'footprint_radius_m': RADIUS, **kwargs}
    with pytest.raises(ValueError, match=message):
        guard.ZoneGuard(SQUARE, **settings_)


def test_guard_scale_rejects_bad_settings():
    with pytest.raises(ValueError, match='horizon_s'):
        guard.guard_scale(SQUARE, (2.0, 2.0, 0.0), (1.0, 0.0, 0.0), RADIUS, MARGIN, 0.0)
    with pytest.raises(ValueError, match='margin_m'):
        guard.guard_scale(SQUARE, (2.0, 2.0, 0.0), (1.0, 0.0, 0.0), RADIUS, math.nan, 1.0)


def test_a_huge_twist_is_still_decided():
    scale, _ = scale_of(SQUARE, (2.0, 2.0, 0.0), (1e6, 0.0, 0.0))
    assert scale * 1e6 == pytest.approx(1.75, abs=1e-6)
    # A tight fast circle (radius 0.1 m) stays inside: one turn is all that is checked.
    assert scale_of(SQUARE, (2.0, 2.0, 0.0), (1e6, 0.0, 1e7))[0] == 1.0


# --- integration ------------------------------------------------------------------------


@pytest.mark.parametrize('twist', [(0.5, 0.0, 0.0), (0.0, -0.4, 0.0), (0.3, 0.2, 1.5),
                                   (0.2, 0.0, -3.0), (0.0, 0.0, 1.0), (0.4, 0.1, 1e-7)])
def test_integrate_twist_is_the_exact_arc(twist):
    pose = (1.0, -2.0, 0.7)
    for t in (0.0, 0.3, 1.0, 4.0):
        expected = integrate_pose(*pose, *twist, t)
        assert guard.integrate_twist(pose, *twist, t) == pytest.approx(expected, abs=1e-9)


def test_integrate_twist_by_hand():
    # A quarter circle of radius 2 / pi: 1 m/s for 1 s turning pi / 2 rad/s.
    x, y, yaw = guard.integrate_twist((0.0, 0.0, 0.0), 1.0, 0.0, math.pi / 2, 1.0)
    assert (x, y, yaw) == pytest.approx((2 / math.pi, 2 / math.pi, math.pi / 2))
    assert guard.integrate_twist((1.0, 1.0, math.pi), 0.5, 0.0, 0.0, 2.0) == \
        pytest.approx((0.0, 1.0, -math.pi))


# --- path_stays_inside --------------------------------------------------------------------


def test_path_stays_inside_by_hand():
    start = (2.0, 2.0, 0.0)
    assert guard.path_stays_inside(SQUARE, start, 1.0, 0.0, 0.0, 1.5, RADIUS, MARGIN) == (
        True, '')
    assert guard.path_stays_inside(SQUARE, start, 1.0, 0.0, 0.0, 1.75, RADIUS, MARGIN)[0]
    inside, reason = guard.path_stays_inside(SQUARE, start, 1.0, 0.0, 0.0, 2.0, RADIUS,
                                             MARGIN)
    assert not inside
    assert reason.startswith('the footprint would come within 0.05 m of the border of the '
                             'authorised zone at (3.76, 2.00) after 1.76 s')
    inside, reason = guard.path_stays_inside(SQUARE, start, 0.0, 1.0, 0.0, 4.0, RADIUS,
                                             MARGIN)
    assert not inside and 'at (2.00, 3.76)' in reason
    # Both ends inside, the middle across the notch of the L.
    inside, reason = guard.path_stays_inside(L_SHAPE, (3.0, 1.0, 0.0), -1.0, 1.0, 0.0, 2.0,
                                             RADIUS, MARGIN)
    end = guard.integrate_twist((3.0, 1.0, 0.0), -1.0, 1.0, 0.0, 2.0)
    assert end == pytest.approx((1.0, 3.0, 0.0))
    assert L_SHAPE.footprint_inside(end[0], end[1], RADIUS + MARGIN)
    assert not inside and 'out of the authorised zone' not in reason
    # An arc that leaves: the circle about (2, 3) of radius 1 reaches y = 4.
    assert not guard.path_stays_inside(SQUARE, start, 1.0, 0.0, 1.0, 3.0, RADIUS, MARGIN)[0]
    assert guard.path_stays_inside(SQUARE, start, 1.0, 0.0, 1.0, 2.0, RADIUS, MARGIN)[0]
    assert guard.path_stays_inside(SQUARE, start, 0.0, 0.0, 3.0, 10.0, RADIUS, MARGIN)[0]


def test_path_stays_inside_from_the_margin_allows_only_what_gets_no_nearer():
    # (3.8, 2.0) in the 4 m square: the footprint touches the border (clearance 0.2 m =
    # the radius, inside the margin). Back inward, along the border and on the spot are
    # allowed (the guard's rule); any motion toward the border is refused.
    assert guard.path_stays_inside(SQUARE, (3.8, 2.0, 0.0), -1.0, 0.0, 0.0, 1.0,
                                   RADIUS, MARGIN) == (True, '')
    assert guard.path_stays_inside(SQUARE, (3.8, 2.0, 0.0), 0.0, 0.5, 0.0, 1.0,
                                   RADIUS, MARGIN) == (True, '')
    assert guard.path_stays_inside(SQUARE, (3.8, 2.0, 0.0), 0.0, 0.0, 1.0, 3.0,
                                   RADIUS, MARGIN) == (True, '')
    inside, reason = guard.path_stays_inside(SQUARE, (3.8, 2.0, 0.0), 0.1, 0.0, 0.0, 1.0,
                                             RADIUS, MARGIN)
    assert not inside
    assert reason.startswith('the footprint would come out of the authorised zone at (3.81')
    # Outside already (4.1): inward is allowed, outward is not.
    assert guard.path_stays_inside(SQUARE, (4.1, 2.0, 0.0), -1.0, 0.0, 0.0, 1.0,
                                   RADIUS, MARGIN)[0]
    assert not guard.path_stays_inside(SQUARE, (4.1, 2.0, 0.0), 1.0, 0.0, 0.0, 1.0,
                                       RADIUS, MARGIN)[0]


def test_path_stays_inside_from_outside_allows_only_motion_back_in():
    # The guard's rule: from outside only what keeps bringing the footprint in (then
    # keeps the margin), or turning on the spot.
    assert guard.path_stays_inside(SQUARE, OUTSIDE, -1.0, 0.0, 0.0, 1.0, RADIUS,
                                   MARGIN) == (True, '')
    assert guard.path_stays_inside(SQUARE, OUTSIDE, 0.0, 0.0, 1.0, 3.0, RADIUS,
                                   MARGIN) == (True, '')
    inside, reason = guard.path_stays_inside(SQUARE, OUTSIDE, 0.0, 0.5, 0.0, 1.0, RADIUS,
                                             MARGIN)
    assert not inside
    assert reason.startswith('the footprint is 0.30 m out of the authorised zone and would '
                             'not be getting back in at (4.10, 2.01) after 0.02 s')
    # In, then on past the far border's margin: refused where it gets within 0.25 m.
    inside, reason = guard.path_stays_inside(SQUARE, OUTSIDE, -1.0, 0.0, 0.0, 4.0, RADIUS,
                                             MARGIN)
    assert not inside and 'within 0.05 m of the border' in reason and '(0.24, 2.00)' in reason


def test_path_stays_inside_refuses_an_invalid_motion():
    assert guard.path_stays_inside(SQUARE, (2.0, 2.0, 0.0), math.nan, 0.0, 0.0, 1.0,
                                   RADIUS, MARGIN)[1].startswith('invalid motion')
    assert not guard.path_stays_inside(SQUARE, (2.0, 2.0, 0.0), 1.0, 0.0, 0.0, -1.0,
                                       RADIUS, MARGIN)[0]
    assert guard.path_stays_inside(SQUARE, (2.0, math.inf, 0.0), 1.0, 0.0, 0.0, 1.0,
                                   RADIUS, MARGIN)[1].startswith('invalid pose')


# --- properties over random concave zones -----------------------------------------------

#: Sampling of the independent check: 1 mm of travel, 0.005 rad of heading.
DENSE_STEP_M = 0.001
DENSE_STEP_RAD = 0.005
#: How far below the required clearance the guard's sampling (1 cm, 0.1 rad) may let a
#: path dip between two samples: an arc grazing the border by its sagitta between them,
#: at most 1.25e-4 m (radius 0.1 m); the distance to a vertex along a line by
#: step^2 / (8 d), 6e-5 m for d = 0.2 m. Random searches found 8e-5 m.
SAMPLING_TOLERANCE_M = 2e-4


@st.composite
def zones(draw):
    """Draw a random star-shaped (so simple, mostly concave) zone, maybe with an exclusion."""
    count = draw(st.integers(5, 12))
    jitter = draw(st.lists(st.floats(-0.3, 0.3), min_size=count, max_size=count))
    radii = draw(st.lists(st.floats(1.0, 4.0), min_size=count, max_size=count))
    angles = [(k + jitter[k]) * 2.0 * math.pi / count for k in range(count)]
    include = [(r * math.cos(a), r * math.sin(a)) for r, a in zip(radii, angles)]
    exclude = []
    if draw(st.booleans()):
        cx, cy = draw(st.floats(-2.0, 2.0)), draw(st.floats(-2.0, 2.0))
        size = draw(st.floats(0.1, 0.5))
        turn = draw(st.floats(0.0, math.pi / 2))
        exclude.append([(cx + size * math.cos(turn + k * math.pi / 2),
                         cy + size * math.sin(turn + k * math.pi / 2)) for k in range(4)])
    try:
        return make_zone(include, exclude)
    except ZoneError:
        return make_zone(include)   # the exclusion was not inside the inclusion


def inside_pose(zone, seed, radius):
    """Return a pose whose footprint is inside the zone (seeded rejection sampling)."""
    rng = random.Random(seed)
    for _ in range(2000):
        x, y = rng.uniform(-4.0, 4.0), rng.uniform(-4.0, 4.0)
        if zone.clearance([x], [y])[0] >= radius:
            return x, y, rng.uniform(-math.pi, math.pi)
    return None


twists = st.tuples(st.one_of(st.just(0.0), st.floats(-1.5, 1.5)),
                   st.one_of(st.just(0.0), st.floats(-1.5, 1.5)),
                   st.one_of(st.just(0.0), st.floats(-3.0, 3.0)))


def dense_clearances(zone, pose, twist, duration_s):
    """Return the clearance along the motion, every 1 mm / 0.005 rad (integrate_pose)."""
    speed, wz = math.hypot(twist[0], twist[1]), abs(twist[2])
    rate = max(speed / DENSE_STEP_M, wz / DENSE_STEP_RAD, 1.0 / duration_s)
    count = int(math.ceil(duration_s * rate))
    points = [integrate_pose(*pose, *twist, duration_s * k / count)[:2]
              for k in range(count + 1)]
    xs, ys = zip(*points)
    return zone.clearance(np.array(xs), np.array(ys))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(zone=zones(), seed=st.integers(0, 2 ** 32 - 1), twist=twists,
       radius=st.floats(0.1, 0.3), margin=st.floats(0.0, 0.2), horizon=st.floats(0.3, 2.0))
def test_the_scaled_motion_keeps_the_required_clearance(zone, seed, twist, radius, margin,
                                                        horizon):
    pose = inside_pose(zone, seed, radius)
    assume(pose is not None)
    result = guard.guard_scale(zone, pose, twist, radius, margin, horizon)
    clearance = float(zone.clearance([pose[0]], [pose[1]])[0])
    required = min(radius + margin, clearance)
    assert result.clearance_m == pytest.approx(clearance)
    assert 0.0 <= result.scale <= 1.0
    scaled = tuple(result.scale * v for v in twist)
    along = dense_clearances(zone, pose, scaled, horizon)
    assert along.min() >= required - SAMPLING_TOLERANCE_M
    if result.scale < 1.0:
        # The largest such scale: the motion ends where it reaches the required
        # clearance (to the last 0.1 mm of travel, under which the guard stops).
        end = guard.integrate_twist(pose, *scaled, horizon)
        end_clearance = float(zone.clearance([end[0]], [end[1]])[0])
        assert end_clearance <= required + 2e-4
        # ... and going any further breaks the rule.
        further = tuple(min(1.0, result.scale + 0.02) * v for v in twist)
        assert dense_clearances(zone, pose, further, horizon).min() < required


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(zone=zones(), seed=st.integers(0, 2 ** 32 - 1), twist=twists,
       margin=st.floats(0.0, 0.2), horizon=st.floats(0.3, 2.0))
def test_a_closed_loop_never_leaves_the_zone(zone, seed, twist, margin, horizon):
    pose = inside_pose(zone, seed, RADIUS)
    assume(pose is not None)
    start = float(zone.clearance([pose[0]], [pose[1]])[0])
    floor = min(RADIUS + margin, start)
    zone_guard = guard.ZoneGuard(zone, RADIUS, horizon_s=horizon, margin_m=margin)
    dt = 0.05
    for _ in range(200):
        result = zone_guard.step(pose, twist)
        scaled = tuple(result.scale * v for v in twist)
        along = dense_clearances(zone, pose, scaled, dt)
        assert along.min() >= RADIUS - SAMPLING_TOLERANCE_M, 'the footprint left the zone'
        assert along.min() >= floor - SAMPLING_TOLERANCE_M
        pose = integrate_pose(*pose, *scaled, dt)


#: How far the clearance can fall back between two samples 1 cm apart that keep the
#: outside rule (gain >= 0.1 x 1 cm): up at slope 1 for 5.5 mm, down for 4.5 mm.
FALL_BACK_M = (1.0 - guard.INWARD_MIN_SLOPE) / 2.0 * guard.SAMPLE_STEP_M + SAMPLING_TOLERANCE_M


def outside_pose(zone, seed, radius):
    """Return a pose whose footprint crosses the border (centre at most 0.5 m out)."""
    rng = random.Random(seed)
    for _ in range(4000):
        x, y = rng.uniform(-4.5, 4.5), rng.uniform(-4.5, 4.5)
        if -0.5 <= zone.clearance([x], [y])[0] < radius:
            return x, y, rng.uniform(-math.pi, math.pi)
    return None


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(zone=zones(), seed=st.integers(0, 2 ** 32 - 1), twist=twists,
       radius=st.floats(0.1, 0.3), margin=st.floats(0.0, 0.2), horizon=st.floats(0.3, 2.0))
def test_from_outside_the_allowed_motion_only_gets_back_in(zone, seed, twist, radius, margin,
                                                           horizon):
    pose = outside_pose(zone, seed, radius)
    assume(pose is not None)
    result = guard.guard_scale(zone, pose, twist, radius, margin, horizon)
    start = float(zone.clearance([pose[0]], [pose[1]])[0])
    moves = twist[0] != 0.0 or twist[1] != 0.0
    if not moves:
        assert result.scale == 1.0     # on the spot (or nothing): the footprint stays
        return
    if result.rotation_only:           # a turn with a leftover translation: rotation alone
        assert guard.turning_on_the_spot(twist) and result.reason == guard.REASON_TURNING_OUTSIDE
        return
    assert result.reason in (guard.REASON_BACK_IN, guard.REASON_OUTSIDE)
    assert (result.scale > 0.0) == (result.reason == guard.REASON_BACK_IN)
    if result.scale == 0.0:
        return
    scaled = tuple(result.scale * v for v in twist)
    along = dense_clearances(zone, pose, scaled, horizon)
    # Never further out than the start, nor than the best so far (until radius + margin
    # in) by more than a path can fall back between two samples 1 cm apart (crossing a
    # ridge of the distance, e.g. the middle of an exclusion: up 5.5 mm, down 4.5 mm);
    # and the end is further in than the start (unless it does not move at all).
    assert along.min() >= start - SAMPLING_TOLERANCE_M
    best = np.maximum.accumulate(along)
    assert np.all(along >= np.minimum(radius + margin, best) - FALL_BACK_M)
    if math.hypot(*scaled[:2]) * horizon > 1e-6:
        assert along[-1] > start


def test_outside_the_zone_a_ramped_turn_passes_as_rotation_alone():
    """Outside the zone a turn with a small leftover translation turns, without moving."""
    outside = (4.1, 2.0, 0.0)   # SQUARE is 0..4 m: the centre 0.1 m over the border
    result = guard.guard_scale(SQUARE, outside, (0.02, 0.0, 0.5), RADIUS, 0.05, 1.0)
    assert (result.scale, result.reason, result.rotation_only) == (
        1.0, guard.REASON_TURNING_OUTSIDE, True)
    result = guard.guard_scale(SQUARE, outside, (0.2, 0.0, 0.5), RADIUS, 0.05, 1.0)
    assert result.scale == 0.0 and not result.rotation_only


def test_a_jump_of_the_localisation_is_latched_until_the_pose_is_set():
    jumps = guard.LocalisationJumps(max_jump_m=0.5, max_jump_rad=0.5, grace_s=5.0)
    assert jumps.update(0.0, (0.5, -0.3, 0.4)) is None            # the first: reference
    # amcl's corrections, a few cm each, add up without ever counting as a jump.
    for step in range(1, 30):
        assert jumps.update(step * 0.1, (0.5 + 0.03 * step, -0.3, 0.4)) is None
    # A restarted amcl: map -> odom 1.2 m away at once (sigma 0.05: limit 0.65 m).
    problem = jumps.update(3.0, (0.5 + 0.87 + 1.2, -0.3, 0.4), sigma_xy_m=0.05)
    assert problem.kind == guard.KIND_JUMP
    assert problem.text.startswith('localisation jumped 1.20 m, 0 deg at once (map -> odom; '
                                   'more than 0.65 m or 29 deg)')
    # Latched, even when map -> odom comes back.
    assert jumps.update(3.1, (1.37, -0.3, 0.4)) is problem
    # The operator sets the pose: cleared, and the jump that follows is expected.
    jumps.initial_pose_set(4.0)
    assert jumps.update(4.5, (-2.0, 1.0, 2.0)) is None
    assert jumps.update(9.5, (-2.0, 1.0, 2.0)) is None               # grace over
    assert jumps.update(9.6, (-2.0, 1.0, 2.0 + 0.6)).kind == guard.KIND_JUMP   # 0.6 rad


def test_a_jump_within_three_sigma_of_an_unsure_estimate_is_convergence():
    jumps = guard.LocalisationJumps()
    jumps.update(0.0, (0.0, 0.0, 0.0))
    # amcl started with a 0.5 m std converging: 0.9 m < 0.5 + 3 x 0.36.
    assert jumps.update(0.1, (0.9, 0.0, 0.0), sigma_xy_m=0.36) is None
    assert jumps.update(0.2, (0.9, 0.0, 0.3), sigma_yaw_rad=0.1) is None
    assert jumps.update(0.3, (0.9, 0.0, 1.2), sigma_yaw_rad=0.1).kind == guard.KIND_JUMP


@pytest.mark.parametrize('arguments, name', [((0.0, 0.5, 5.0), 'max_localisation_jump_m'),
                                             ((0.5, math.nan, 5.0), 'max_localisation_jump_rad'),
                                             ((0.5, 0.5, -1.0), 'initial_pose_grace_s')])
def test_bad_jump_thresholds_are_refused_by_name(arguments, name):
    with pytest.raises(ValueError, match=name):
        guard.LocalisationJumps(*arguments)


def test_the_pose_on_diagnostics_is_written_and_read_back_as_one_contract():
    # The zone guard node writes it; the scenario runner waits until it reads a pose.
    assert guard.pose_diagnostic((2.0, -1.25, 0.5)) == '(2.00, -1.25, 0.50)'
    assert guard.pose_diagnostic_known(guard.pose_diagnostic((0.0, 0.0, 0.0)))
    assert not guard.pose_diagnostic_known('no pose: no transform map -> base_link yet')
    assert not guard.pose_diagnostic_known('')
    assert not guard.pose_diagnostic_known(None)
