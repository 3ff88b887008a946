"""Tests of the pure sensor models: ray casting, lidar and IMU."""

import math

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from robot_simulation.sensors import (
    cast_rays, ideal_imu_reading, ImuConfig, ImuModel, Lidar, LidarConfig, RayCaster,
    STANDARD_GRAVITY_M_S2)

SQRT2 = math.sqrt(2.0)
NO_CIRCLES = np.zeros((0, 3))
# A 4 m x 4 m room centred on the origin.
ROOM = np.array([[-2.0, -2.0, 2.0, -2.0], [2.0, -2.0, 2.0, 2.0],
                 [2.0, 2.0, -2.0, 2.0], [-2.0, 2.0, -2.0, -2.0]])


def cast_one(angle, segments, circles=NO_CIRCLES, origin=(0.0, 0.0), max_range=100.0):
    """Cast a single ray with cast_rays and return its range as a float."""
    segments = np.array(segments, dtype=float).reshape(-1, 4)
    result = cast_rays(origin[0], origin[1], np.array([angle]), segments,
                       np.array(circles, dtype=float).reshape(-1, 3), max_range)
    assert result.shape == (1,) and result.dtype == np.float64
    return float(result[0])


# --------------------------------------------------------------------------- ray casting


def test_ray_along_x_hits_vertical_segment():
    """A +x ray meets the segment x = 3 (y from -1 to 1) at 3 m."""
    assert cast_one(0.0, [3.0, -1.0, 3.0, 1.0]) == pytest.approx(3.0, abs=1e-12)


def test_segment_direction_does_not_matter():
    """Segments are two-sided and their end point order is irrelevant."""
    assert cast_one(0.0, [3.0, 1.0, 3.0, -1.0]) == pytest.approx(3.0, abs=1e-12)
    assert cast_one(math.pi, [-3.0, 1.0, -3.0, -1.0]) == pytest.approx(3.0, abs=1e-12)


def test_parallel_and_collinear_rays_miss():
    """A ray parallel to a segment, or running along it, does not hit it."""
    assert cast_one(0.0, [1.0, 1.0, 5.0, 1.0]) == math.inf
    assert cast_one(0.0, [5.0, 0.0, 8.0, 0.0]) == math.inf
    assert cast_one(math.pi / 4, [1.0, 1.0, 3.0, 3.0]) == math.inf


def test_nearly_parallel_rays_give_no_phantom_hits():
    """Grazing rays along a wall's line return nothing, not an ill-conditioned distance."""
    angles = [0.0, 1e-13, -1e-13, 1e-11, math.pi, math.pi + 1e-12]
    for angle in angles:
        assert cast_one(angle, [5.0, 0.0, 8.0, 0.0]) == math.inf


def test_ray_hits_segment_end_points_exactly():
    """End points belong to the segment; just past an end point is a miss."""
    assert cast_one(0.0, [3.0, 0.0, 3.0, 2.0]) == pytest.approx(3.0, abs=1e-12)
    assert cast_one(0.0, [3.0, -2.0, 3.0, 0.0]) == pytest.approx(3.0, abs=1e-12)
    assert cast_one(math.pi / 4, [2.0, 2.0, 2.0, 5.0]) == pytest.approx(2 * SQRT2, abs=1e-12)
    assert cast_one(0.0, [3.0, 1e-6, 3.0, 2.0]) == math.inf


def test_ray_starting_on_a_segment_ignores_it():
    """Hits closer than 1e-9 m are ignored: a ray leaving a wall sees what lies beyond."""
    wall = [3.0, -1.0, 3.0, 1.0]
    other = [0.0, -1.0, 0.0, 1.0]
    origin = (3.0, 0.5)
    assert cast_one(0.0, [wall], origin=origin) == math.inf
    assert cast_one(0.0, [wall, [5.0, -1.0, 5.0, 1.0]], origin=origin) == pytest.approx(2.0)
    assert cast_one(math.pi, [wall, other], origin=origin) == pytest.approx(3.0)
    assert cast_one(math.pi / 2, [wall], origin=origin) == math.inf  # along it


def test_nearest_of_two_segments_wins():
    """The first hit along the ray is reported, whatever the segment order."""
    near = [3.0, -1.0, 3.0, 1.0]
    far = [5.0, -1.0, 5.0, 1.0]
    assert cast_one(0.0, [near, far]) == pytest.approx(3.0)
    assert cast_one(0.0, [far, near]) == pytest.approx(3.0)
    assert cast_one(math.pi, [far, near]) == math.inf


def test_circle_hit_and_circle_behind():
    """A circle at (5, 0) of radius 1 is hit at 4 m ahead, and not at all behind."""
    circle = [[5.0, 0.0, 1.0]]
    assert cast_one(0.0, [], circle) == pytest.approx(4.0, abs=1e-12)
    assert cast_one(math.pi, [], circle) == math.inf
    assert cast_one(math.pi / 2, [], circle) == math.inf


def test_tangent_ray_touches_circle():
    """A ray grazing a circle counts as a hit at the tangent point."""
    assert cast_one(0.0, [], [[5.0, 1.0, 1.0]]) == pytest.approx(5.0, abs=1e-12)


def test_ray_from_inside_circle_hits_far_side():
    """A ray starting inside a circle reports the distance to its rim ahead."""
    assert cast_one(0.0, [], [[5.0, 0.0, 1.0]], origin=(4.5, 0.0)) == pytest.approx(1.5)
    assert cast_one(math.pi, [], [[5.0, 0.0, 1.0]], origin=(4.5, 0.0)) == pytest.approx(0.5)
    ranges = cast_rays(5.0, 0.0, np.linspace(-3.0, 3.0, 7), np.zeros((0, 4)),
                       np.array([[5.0, 0.0, 1.0]]), 10.0)
    np.testing.assert_allclose(ranges, 1.0, atol=1e-12)


def test_circle_and_segment_nearest_wins():
    """A circle in front of a wall hides it, and a wall in front of a circle hides that."""
    wall = [6.0, -1.0, 6.0, 1.0]
    assert cast_one(0.0, [wall], [[5.0, 0.0, 1.0]]) == pytest.approx(4.0)
    assert cast_one(0.0, [wall], [[9.0, 0.0, 1.0]]) == pytest.approx(6.0)


def test_45_degree_cases():
    """Rays at 45 degrees meet a vertical wall and a diagonal segment at 2*sqrt(2)."""
    assert cast_one(math.pi / 4, [2.0, -10.0, 2.0, 10.0]) == pytest.approx(2 * SQRT2)
    assert cast_one(math.pi / 4, [0.0, 4.0, 4.0, 0.0]) == pytest.approx(2 * SQRT2)
    assert cast_one(-3 * math.pi / 4, [-2.0, -10.0, -2.0, 10.0],
                    origin=(0.0, 0.0)) == pytest.approx(2 * SQRT2)
    assert cast_one(3 * math.pi / 4, [0.0, 1.0, 10.0, 1.0],
                    origin=(1.0, 0.0)) == pytest.approx(SQRT2)


def test_max_range_cutoff():
    """A hit at exactly max range counts; a farther one is inf."""
    wall = [3.0, -1.0, 3.0, 1.0]
    assert cast_one(0.0, [wall], max_range=3.0) == pytest.approx(3.0)
    assert cast_one(0.0, [wall], max_range=2.999) == math.inf
    assert cast_one(0.0, [], [[5.0, 0.0, 1.0]], max_range=3.9) == math.inf


def test_far_segments_are_pruned_without_changing_results():
    """Segments beyond max range do not affect the result, near ones still count."""
    world = np.array([[3.0, -1.0, 3.0, 1.0], [100.0, -50.0, 100.0, 50.0],
                      [-1.0, 200.0, 1.0, 200.0]])
    angles = np.array([0.0, math.pi, math.pi / 2, 0.4])  # 0.4 rad passes above x = 3
    np.testing.assert_allclose(
        cast_rays(0.0, 0.0, angles, world, NO_CIRCLES, 5.0), [3.0, math.inf, math.inf, math.inf])
    far = cast_rays(0.0, 0.0, angles, world, None, 1000.0)
    np.testing.assert_allclose(far, [3.0, math.inf, 200.0, 100.0 / math.cos(0.4)])


def test_closed_room_is_watertight():
    """Rays from inside a closed room, including exactly at its corners, always hit a wall."""
    ox, oy = 0.3, -0.7
    corners = [math.atan2(cy - oy, cx - ox) for cx, cy in ROOM[:, :2]]
    angles = np.concatenate([np.linspace(-math.pi, math.pi, 3601), corners])
    ranges = cast_rays(ox, oy, angles, ROOM, NO_CIRCLES, 10.0)
    dx, dy = np.cos(angles), np.sin(angles)
    with np.errstate(divide='ignore'):
        tx = np.where(dx > 0, (2.0 - ox) / dx, (-2.0 - ox) / dx)
        ty = np.where(dy > 0, (2.0 - oy) / dy, (-2.0 - oy) / dy)
    np.testing.assert_allclose(ranges, np.minimum(np.abs(tx), np.abs(ty)), rtol=1e-12)


def test_empty_inputs():
    """No segments, no circles or no rays give inf ranges or an empty result."""
    empty = np.zeros((0, 4))
    ranges = cast_rays(0.0, 0.0, np.array([0.0, 1.0]), empty, NO_CIRCLES, 10.0)
    assert ranges.tolist() == [math.inf, math.inf]
    assert cast_rays(0.0, 0.0, np.zeros(0), ROOM, None, 10.0).shape == (0,)
    assert RayCaster(empty).cast(0.0, 0.0, [0.0], None, 10.0).tolist() == [math.inf]


@pytest.mark.parametrize('kwargs', [
    {'segments': np.zeros(3)},
    {'segments': np.zeros((2, 3))},
    {'segments': np.array([[0.0, 0.0, math.nan, 1.0]])},
    {'circles': np.zeros((2, 2))},
    {'circles': np.array([[1.0, 1.0, -0.5]])},
    {'max_range_m': 0.0},
    {'max_range_m': math.nan},
    {'angles_rad': np.zeros((2, 2))},
    {'origin_x': math.nan},
])
def test_invalid_ray_inputs_raise(kwargs):
    """Malformed arrays and non-finite or non-positive scalars raise ValueError."""
    args = {'origin_x': 0.0, 'origin_y': 0.0, 'angles_rad': np.zeros(3), 'segments': ROOM,
            'circles': NO_CIRCLES, 'max_range_m': 10.0}
    args.update(kwargs)
    with pytest.raises(ValueError):
        cast_rays(**args)


def test_ray_caster_reuse_matches_cast_rays():
    """A reused RayCaster (buffers, pruning, blocks of any size) matches fresh casts."""
    rng = np.random.default_rng(3)
    world = rng.uniform(-8.0, 8.0, (60, 4))
    circles = np.array([[1.0, 2.0, 0.3], [-3.0, 0.5, 0.25]])
    casters = [RayCaster(world), RayCaster(world, chunk_elements=1),
               RayCaster(world, chunk_elements=100)]
    for count, max_range in ((360, 12.0), (7, 3.0), (1000, 30.0), (1, 0.5), (360, 2.0)):
        ox, oy = rng.uniform(-5.0, 5.0, 2)
        angles = rng.uniform(-4.0, 4.0, count)
        expected = cast_rays(ox, oy, angles, world, circles, max_range)
        for caster in casters:
            got = caster.cast(ox, oy, angles, circles, max_range)
            np.testing.assert_allclose(got, expected, rtol=1e-12)
    assert not casters[0].segments.flags.writeable


def reference_bounds(ox, oy, angle, segments, circles, max_range):
    """
    Bound the first-hit distance of one ray with a slow pure-Python cast.

    Loops over the segments with the parametric intersection o + t d = p1 + s u
    (u the unit direction, s in metres along the segment) and over the circles'
    quadratics. A clear hit lowers both bounds; a numerically ambiguous pair
    (near-parallel, an end point or the 1e-9 m minimum or max range within a
    rounding band, near-tangent) only lowers the lower bound. Without ambiguous
    pairs the bounds are equal: the exact expected value.
    """
    dx, dy = math.cos(angle), math.sin(angle)
    clear = math.inf
    lower = math.inf

    def classify(t, inside, outside, lower_t):
        """Fold one candidate hit into the bounds."""
        nonlocal clear, lower
        if outside or t < 0.5e-9 or t > max_range + 1e-9 * max(1.0, max_range):
            return
        if inside and t >= 2e-9 and t <= max_range - 1e-9 * max(1.0, max_range):
            clear = min(clear, t)
            lower = min(lower, t)
        else:
            lower = min(lower, max(0.0, lower_t))

    for x1, y1, x2, y2 in segments:
        ex, ey = x2 - x1, y2 - y1
        length = math.hypot(ex, ey)
        if length < 1e-12:  # a point: never hit
            continue
        ux, uy = ex / length, ey / length
        wx, wy = x1 - ox, y1 - oy
        sine = dx * uy - dy * ux
        if sine == 0.0:
            continue
        if abs(sine) < 1e-3:  # ill-conditioned: any hit is at least near the segment
            along = min(max(-(wx * ux + wy * uy), 0.0), length)
            distance = math.hypot(wx + along * ux, wy + along * uy)
            if distance <= max_range + 1e-3:
                lower = min(lower, max(0.0, distance - 1e-3))
            continue
        t = (wx * uy - wy * ux) / sine
        s = (wx * dy - wy * dx) / sine
        classify(t, -0.5e-9 <= s <= length + 0.5e-9, s < -1.5e-9 or s > length + 1.5e-9,
                 t - 1e-9)
    for cx, cy, radius in circles:
        fx, fy = ox - cx, oy - cy
        b = fx * dx + fy * dy
        disc = b * b - (fx * fx + fy * fy - radius * radius)
        if disc < -1e-6:
            continue
        if disc <= 1e-6:  # near-tangent: the root is ill-conditioned
            if -b + 1e-3 >= 0.0 and -b - 1e-3 <= max_range:
                lower = min(lower, max(0.0, -b - 1e-3))
            continue
        root = math.sqrt(disc)
        for t in (-b - root, -b + root):
            if t >= 0.5e-9:
                classify(t, t >= 2e-9, False, t - 1e-9)
                if t >= 2e-9:
                    break
    return lower, clear


def tolerance(value):
    """Return the comparison slack for a reference bound: 1e-9, relative past 1 m."""
    return 1e-9 * max(1.0, value) if math.isfinite(value) else 0.0


COORD = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=200, deadline=None)
@given(origin=st.tuples(COORD, COORD),
       segments=st.lists(st.tuples(COORD, COORD, COORD, COORD), max_size=12),
       circles=st.lists(st.tuples(COORD, COORD, st.floats(0.0, 3.0)), max_size=3),
       angles=st.lists(st.floats(-7.0, 7.0), min_size=1, max_size=16),
       max_range=st.floats(0.1, 30.0),
       chunk=st.integers(1, 64))
def test_cast_rays_matches_slow_reference(origin, segments, circles, angles, max_range, chunk):
    """cast_rays and a blocked RayCaster equal the pure-Python reference to 1e-9."""
    seg_array = np.array(segments, dtype=float).reshape(-1, 4)
    circle_array = np.array(circles, dtype=float).reshape(-1, 3)
    fast = cast_rays(origin[0], origin[1], np.array(angles), seg_array, circle_array, max_range)
    blocked = RayCaster(seg_array, chunk_elements=chunk).cast(
        origin[0], origin[1], np.array(angles), circle_array, max_range)
    assert not np.isnan(fast).any()
    for got_fast, got_blocked, angle in zip(fast, blocked, angles):
        lower, upper = reference_bounds(origin[0], origin[1], angle, segments, circles,
                                        max_range)
        for got in (got_fast, got_blocked):
            assert lower - tolerance(lower) <= got <= upper + tolerance(upper), (
                angle, got, lower, upper)


# --------------------------------------------------------------------------------- lidar


def beam_index(lidar, angle):
    """Return the index of the beam at laser-frame ``angle`` (full-circle scans wrap)."""
    index = int(round((angle - lidar.angle_min_rad) / lidar.angle_increment_rad))
    return index % lidar.config.beams


def ideal_config(**overrides):
    """Return a noise-free LidarConfig with the given overrides."""
    return LidarConfig(**{'noise_stddev_m': 0.0, **overrides})


def test_lidar_in_room_centre_reads_hand_worked_ranges():
    """From the centre of a 4 m room: 2 m ahead, left, behind; 2*sqrt(2) m to a corner."""
    lidar = Lidar(ideal_config(), ROOM)
    ranges = lidar.scan(0.0, 0.0, 0.0)
    assert ranges.shape == (360,) and ranges.dtype == np.float32
    assert ranges[beam_index(lidar, 0.0)] == pytest.approx(2.0, abs=1e-6)
    assert ranges[beam_index(lidar, math.pi / 2)] == pytest.approx(2.0, abs=1e-6)
    assert ranges[0] == pytest.approx(2.0, abs=1e-6)  # angle_min = -pi: straight behind
    assert ranges[beam_index(lidar, math.pi / 4)] == pytest.approx(2 * SQRT2, abs=1e-6)
    assert ranges[beam_index(lidar, -3 * math.pi / 4)] == pytest.approx(2 * SQRT2, abs=1e-6)
    assert np.isfinite(ranges).all()
    angles = lidar.beam_angles_rad
    expected = 2.0 / np.maximum(np.abs(np.cos(angles)), np.abs(np.sin(angles)))
    np.testing.assert_allclose(ranges, expected, rtol=1e-6)


@pytest.mark.parametrize('config', [
    LidarConfig(),
    LidarConfig(beams=720, rate_hz=5.5),
    LidarConfig(beams=181, angle_min_rad=-math.pi / 2, angle_max_rad=math.pi / 2),
])
def test_lidar_laser_scan_fields_are_consistent(config):
    """Increment, reported angle_max (last beam) and timing agree with the beam angles."""
    lidar = Lidar(config, ROOM)
    span = config.angle_max_rad - config.angle_min_rad
    assert lidar.angle_increment_rad == pytest.approx(span / config.beams)
    assert lidar.beam_angles_rad.shape == (config.beams,)
    assert lidar.beam_angles_rad[0] == config.angle_min_rad
    assert lidar.last_beam_angle_rad == pytest.approx(
        config.angle_min_rad + (config.beams - 1) * lidar.angle_increment_rad)
    assert lidar.beam_angles_rad[-1] == pytest.approx(lidar.last_beam_angle_rad)
    assert lidar.last_beam_angle_rad == pytest.approx(
        config.angle_max_rad - lidar.angle_increment_rad)
    assert lidar.scan_time_s == pytest.approx(1.0 / config.rate_hz)
    assert lidar.time_increment_s == pytest.approx(1.0 / config.rate_hz / config.beams)
    fields = lidar.scan_fields()
    assert fields == {
        'angle_min': lidar.angle_min_rad, 'angle_max': lidar.last_beam_angle_rad,
        'angle_increment': lidar.angle_increment_rad,
        'time_increment': lidar.time_increment_s, 'scan_time': lidar.scan_time_s,
        'range_min': config.range_min_m, 'range_max': config.range_max_m}
    assert all(isinstance(value, float) for value in fields.values())


def test_lidar_default_full_circle_has_no_duplicate_beam():
    """360 beams of 1 degree from -pi: the last is at pi - 1 degree."""
    lidar = Lidar(LidarConfig(), ROOM)
    assert lidar.angle_increment_rad == pytest.approx(math.radians(1.0))
    assert lidar.last_beam_angle_rad == pytest.approx(math.pi - math.radians(1.0))


def test_lidar_mount_offset_shifts_readings():
    """A laser 0.5 m ahead of base_link sees the front wall at 1.5 m and the back at 2.5 m."""
    lidar = Lidar(ideal_config(mount_x_m=0.5), ROOM)
    ranges = lidar.scan(0.0, 0.0, 0.0)
    assert ranges[beam_index(lidar, 0.0)] == pytest.approx(1.5, abs=1e-6)
    assert ranges[beam_index(lidar, -math.pi)] == pytest.approx(2.5, abs=1e-6)
    assert ranges[beam_index(lidar, math.pi / 2)] == pytest.approx(2.0, abs=1e-6)


def test_lidar_mount_yaw_rotates_beams():
    """Mounted turned left 90 degrees, beam 0 looks along base +y."""
    lidar = Lidar(ideal_config(mount_x_m=0.5, mount_yaw_rad=math.pi / 2), ROOM)
    ranges = lidar.scan(0.0, 0.0, 0.0)
    assert ranges[beam_index(lidar, 0.0)] == pytest.approx(2.0, abs=1e-6)  # world +y
    assert ranges[beam_index(lidar, -math.pi / 2)] == pytest.approx(1.5, abs=1e-6)  # world +x
    assert ranges[beam_index(lidar, math.pi / 2)] == pytest.approx(2.5, abs=1e-6)  # world -x


def test_lidar_base_pose_and_mount_compose():
    """
    Base at (1, -0.5) facing +y; laser at (0.5, 0.2) turned -90 degrees in base_link.

    The laser is then at world (0.8, 0.0) facing +x: 1.2 m ahead, 2.8 m behind.
    """
    config = ideal_config(mount_x_m=0.5, mount_y_m=0.2, mount_yaw_rad=-math.pi / 2)
    lidar = Lidar(config, ROOM)
    ranges = lidar.scan(1.0, -0.5, math.pi / 2)
    assert ranges[beam_index(lidar, 0.0)] == pytest.approx(1.2, abs=1e-6)
    assert ranges[beam_index(lidar, -math.pi)] == pytest.approx(2.8, abs=1e-6)
    assert ranges[beam_index(lidar, math.pi / 2)] == pytest.approx(2.0, abs=1e-6)


def test_lidar_sees_moving_circles():
    """A person (circle) 1 m ahead of the laser, radius 0.25, reads 0.75 m."""
    lidar = Lidar(ideal_config(), ROOM)
    ranges = lidar.scan(0.0, 0.0, 0.0, np.array([[1.0, 0.0, 0.25]]))
    assert ranges[beam_index(lidar, 0.0)] == pytest.approx(0.75, abs=1e-6)
    assert ranges[beam_index(lidar, math.pi / 2)] == pytest.approx(2.0, abs=1e-6)


def test_lidar_range_max_is_inclusive_and_beyond_is_plus_inf():
    """Walls at exactly range_max are valid readings; beyond range_max gives +inf."""
    four = {'beams': 4}
    at_max = Lidar(ideal_config(range_max_m=2.0, **four), ROOM).scan(0.0, 0.0, 0.0)
    assert at_max.tolist() == [2.0, 2.0, 2.0, 2.0]
    beyond = Lidar(ideal_config(range_max_m=1.5, **four), ROOM).scan(0.0, 0.0, 0.0)
    assert beyond.tolist() == [math.inf] * 4
    open_world = Lidar(ideal_config(), np.zeros((0, 4))).scan(0.0, 0.0, 0.0)
    assert np.isposinf(open_world).all()


def test_lidar_returns_closer_than_range_min_read_minus_inf():
    """REP-117: a return closer than range_min reads -inf; one just past it is valid."""
    lidar = Lidar(ideal_config(range_min_m=0.15), ROOM)
    front = beam_index(lidar, 0.0)
    too_close = lidar.scan(0.0, 0.0, 0.0, np.array([[0.3, 0.0, 0.2]]))
    assert too_close[front] == -math.inf
    assert too_close[beam_index(lidar, math.pi)] == pytest.approx(2.0, abs=1e-6)
    measurable = lidar.scan(0.0, 0.0, 0.0, np.array([[0.3, 0.0, 0.1]]))
    assert measurable[front] == pytest.approx(0.2, abs=1e-6)


def test_lidar_same_seed_gives_identical_scans():
    """Seeded noise and dropout repeat exactly; another seed differs."""
    config = LidarConfig(noise_stddev_m=0.02, dropout_probability=0.1)
    first, second, other = (Lidar(config, ROOM, seed=seed) for seed in (7, 7, 8))
    for pose in ((0.0, 0.0, 0.0), (0.5, -0.3, 1.0), (0.5, -0.3, 1.0)):
        a, b, c = first.scan(*pose), second.scan(*pose), other.scan(*pose)
        np.testing.assert_array_equal(a, b)
        assert not np.array_equal(a, c)


def test_lidar_noise_has_configured_spread():
    """Additive gaussian noise: zero mean and stddev within 10% of the configured one."""
    truth = Lidar(ideal_config(), ROOM).scan(0.1, 0.2, 0.3).astype(float)
    noisy = Lidar(LidarConfig(noise_stddev_m=0.05), ROOM, seed=1)
    errors = np.concatenate([noisy.scan(0.1, 0.2, 0.3) - truth for _ in range(20)])
    assert np.isfinite(errors).all()
    assert abs(errors.mean()) < 0.005
    assert errors.std() == pytest.approx(0.05, rel=0.1)


def test_lidar_dropout_fraction():
    """Each beam drops out (+inf) with the configured probability; the others are exact."""
    truth = Lidar(ideal_config(), ROOM).scan(0.0, 0.0, 0.0)
    lidar = Lidar(ideal_config(dropout_probability=0.25), ROOM, seed=2)
    scans = np.stack([lidar.scan(0.0, 0.0, 0.0) for _ in range(20)])
    dropped = np.isposinf(scans)
    assert dropped.mean() == pytest.approx(0.25, abs=0.03)
    np.testing.assert_array_equal(scans[~dropped], np.broadcast_to(truth, scans.shape)[~dropped])


def test_lidar_never_reports_nan():
    """With noise, dropout, close obstacles and open space, ranges are finite or +-inf."""
    world = np.array([[0.0, 1.0, 3.0, 1.0], [0.1, -0.1, 0.1, 0.1]])
    lidar = Lidar(LidarConfig(noise_stddev_m=0.05, dropout_probability=0.2), world, seed=4)
    for _ in range(10):
        ranges = lidar.scan(0.0, 0.0, 0.0, np.array([[0.0, -0.3, 0.2]]))
        assert not np.isnan(ranges).any()
        valid = ranges[np.isfinite(ranges)]
        assert ((valid >= np.float32(0.15)) & (valid <= np.float32(12.0))).all()
        assert np.isneginf(ranges).any() and np.isposinf(ranges).any()


def test_lidar_rejects_non_finite_pose():
    """A NaN pose is a bug upstream: it raises instead of producing a scan."""
    with pytest.raises(ValueError, match='base_yaw'):
        Lidar(LidarConfig(), ROOM).scan(0.0, 0.0, math.nan)


@pytest.mark.parametrize('field, value', [
    ('beams', 0), ('beams', 2.5), ('beams', True), ('range_min_m', -0.1),
    ('range_max_m', 0.1), ('range_max_m', math.inf), ('rate_hz', 0.0),
    ('angle_max_rad', -math.pi), ('angle_max_rad', 2 * math.pi), ('noise_stddev_m', -0.01),
    ('dropout_probability', 1.5), ('mount_x_m', math.nan), ('mount_yaw_rad', 'a'),
])
def test_lidar_config_rejects_bad_fields_by_name(field, value):
    """Invalid LidarConfig fields raise ValueError naming the field."""
    with pytest.raises(ValueError, match=field):
        LidarConfig(**{field: value})


# ----------------------------------------------------------------------------------- IMU

PERFECT_IMU = ImuConfig(gyro_noise_stddev_rad_s=0.0, gyro_bias_stddev_rad_s=0.0,
                        accel_noise_stddev_m_s2=0.0, accel_bias_stddev_m_s2=0.0)


def test_imu_at_rest_reads_plus_g_up():
    """Noise- and bias-free at rest: accel (0, 0, +9.80665), gyro (0, 0, 0)."""
    accel, gyro = ImuModel(PERFECT_IMU).sample((0.0, 0.0, 0.0), (0.0, 0.0), 0.01)
    assert accel.shape == (3,) and gyro.shape == (3,)
    assert accel.tolist() == [0.0, 0.0, 9.80665]
    assert gyro.tolist() == [0.0, 0.0, 0.0]
    assert STANDARD_GRAVITY_M_S2 == 9.80665


def test_imu_rotation_in_place_reads_wz():
    """Turning in place at wz: gyro z = wz, no horizontal acceleration."""
    accel, gyro = ImuModel(PERFECT_IMU).sample((0.0, 0.0, 0.7), (0.0, 0.0), 0.01)
    assert gyro.tolist() == [0.0, 0.0, 0.7]
    assert accel.tolist() == [0.0, 0.0, 9.80665]


def test_imu_adds_centripetal_terms():
    """Driving a circle (vx = 1, wz = 0.5) reads +0.5 m/s^2 to the left (towards the centre)."""
    model = ImuModel(PERFECT_IMU)
    accel, _ = model.sample((1.0, 0.0, 0.5), (0.0, 0.0), 0.01)
    assert accel == pytest.approx([0.0, 0.5, STANDARD_GRAVITY_M_S2])
    accel, _ = model.sample((0.0, 1.0, 0.5), (0.0, 0.0), 0.01)  # strafing left while turning
    assert accel == pytest.approx([-0.5, 0.0, STANDARD_GRAVITY_M_S2])
    accel, _ = model.sample((0.0, 0.0, 0.0), (0.3, -0.2), 0.01)  # speeding up, no rotation
    assert accel == pytest.approx([0.3, -0.2, STANDARD_GRAVITY_M_S2])
    ideal_accel, ideal_gyro = ideal_imu_reading((1.0, 0.0, 0.5), (0.2, 0.0))
    assert ideal_accel == pytest.approx([0.2, 0.5, STANDARD_GRAVITY_M_S2])
    assert ideal_gyro == pytest.approx([0.0, 0.0, 0.5])


def test_imu_same_seed_reproduces():
    """Same seed, same calls: identical biases and samples; another seed differs."""
    first, second, other = (ImuModel(ImuConfig(), seed=seed) for seed in (5, 5, 6))
    np.testing.assert_array_equal(first.gyro_bias_rad_s, second.gyro_bias_rad_s)
    for _ in range(5):
        a, b, c = (model.sample((0.2, 0.0, 0.1), (0.0, 0.0), 0.01)
                   for model in (first, second, other))
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])
        assert not np.array_equal(a[1], c[1])


def test_imu_bias_is_constant_over_a_run():
    """Without noise or walk, every sample is the truth plus the same, reported bias."""
    config = ImuConfig(gyro_noise_stddev_rad_s=0.0, accel_noise_stddev_m_s2=0.0)
    model = ImuModel(config, seed=9)
    gyro_bias, accel_bias = model.gyro_bias_rad_s, model.accel_bias_m_s2
    assert np.abs(gyro_bias).max() > 0.0 and np.abs(accel_bias).max() > 0.0
    for _ in range(100):
        accel, gyro = model.sample((0.0, 0.0, 0.0), (0.0, 0.0), 0.01)
        np.testing.assert_allclose(gyro, gyro_bias, rtol=0, atol=1e-15)
        np.testing.assert_allclose(accel, [0.0, 0.0, STANDARD_GRAVITY_M_S2] + accel_bias,
                                   rtol=0, atol=1e-12)
    np.testing.assert_array_equal(model.gyro_bias_rad_s, gyro_bias)


def test_imu_bias_spread_over_many_seeds():
    """The per-run biases are zero-mean with the configured stddev (within 10%)."""
    config = ImuConfig(gyro_bias_stddev_rad_s=0.002, accel_bias_stddev_m_s2=0.02)
    models = [ImuModel(config, seed=seed) for seed in range(2000)]
    gyro = np.array([model.gyro_bias_rad_s for model in models])
    accel = np.array([model.accel_bias_m_s2 for model in models])
    assert gyro.std() == pytest.approx(0.002, rel=0.1)
    assert accel.std() == pytest.approx(0.02, rel=0.1)
    assert abs(gyro.mean()) < 0.0002 and abs(accel.mean()) < 0.002


def test_imu_noise_spread():
    """Per-sample white noise has the configured stddev on every axis (within 10%)."""
    config = ImuConfig(gyro_bias_stddev_rad_s=0.0, accel_bias_stddev_m_s2=0.0)
    model = ImuModel(config, seed=11)
    samples = [model.sample((0.0, 0.0, 0.0), (0.0, 0.0), 0.01) for _ in range(3000)]
    accel = np.array([sample[0] for sample in samples])
    gyro = np.array([sample[1] for sample in samples])
    np.testing.assert_allclose(gyro.std(axis=0), 0.005, rtol=0.1)
    np.testing.assert_allclose(accel.std(axis=0), 0.05, rtol=0.1)
    np.testing.assert_allclose(accel.mean(axis=0), [0.0, 0.0, STANDARD_GRAVITY_M_S2], atol=0.01)


def test_imu_bias_random_walk_grows_with_sqrt_time():
    """With a walk intensity q, the bias drifts by q * sqrt(T) (stddev) over T seconds."""
    config = ImuConfig(gyro_noise_stddev_rad_s=0.0, gyro_bias_stddev_rad_s=0.0,
                       gyro_bias_walk_rad_s_per_sqrt_s=0.01, accel_bias_stddev_m_s2=0.0,
                       accel_bias_walk_m_s2_per_sqrt_s=0.1)
    gyro_drift, accel_drift = [], []
    for seed in range(300):
        model = ImuModel(config, seed=seed)
        for _ in range(16):
            model.sample((0.0, 0.0, 0.0), (0.0, 0.0), 0.25)  # 4 s in all
        gyro_drift.append(model.gyro_bias_rad_s)
        accel_drift.append(model.accel_bias_m_s2)
    assert np.std(gyro_drift) == pytest.approx(0.01 * 2.0, rel=0.1)
    assert np.std(accel_drift) == pytest.approx(0.1 * 2.0, rel=0.1)
    still = ImuModel(config, seed=1)
    still.sample((0.0, 0.0, 0.0), (0.0, 0.0), 0.0)
    assert still.gyro_bias_rad_s.tolist() == [0.0, 0.0, 0.0]  # no time, no walk


def test_imu_rejects_bad_dt_and_config():
    """A negative or NaN dt, or a bad config field, raises ValueError naming it."""
    model = ImuModel(ImuConfig(), seed=0)
    assert model.period_s == pytest.approx(0.01)
    for dt in (-0.01, math.nan):
        with pytest.raises(ValueError, match='dt_s'):
            model.sample((0.0, 0.0, 0.0), (0.0, 0.0), dt)
    for field, value in (('rate_hz', 0.0), ('gyro_noise_stddev_rad_s', -1.0),
                         ('accel_bias_stddev_m_s2', math.inf),
                         ('gyro_bias_walk_rad_s_per_sqrt_s', -0.1)):
        with pytest.raises(ValueError, match=field):
            ImuConfig(**{field: value})
