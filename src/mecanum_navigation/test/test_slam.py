"""Tests of slam.slam: keyframes, frames, bad input, and a full apartment run."""

import math
import time

from mecanum_control.angles import wrap_angle
from mecanum_map_server.map_io import load_map, OccupancyMap, save_map, world_to_cell
from mecanum_navigation.slam.pose_graph import compose, relative
from mecanum_navigation.slam.slam import occupied_overlap, OnlineSlam, SlamConfig, surface_normals
import numpy as np
import pytest

#: An L-shaped room (8 m x 7 m) with a pillar and a cupboard.
ROOM = np.array([
    (0, 0, 8, 0), (8, 0, 8, 5), (8, 5, 4, 5), (4, 5, 4, 7), (4, 7, 0, 7), (0, 7, 0, 0),
    (2.0, 2.0, 2.4, 2.0), (2.4, 2.0, 2.4, 2.4), (2.4, 2.4, 2.0, 2.4), (2.0, 2.4, 2.0, 2.0),
    (6.0, 1.0, 7.0, 1.0), (7.0, 1.0, 7.0, 1.6), (7.0, 1.6, 6.0, 1.6), (6.0, 1.6, 6.0, 1.0),
], dtype=float)
BEAMS = 360
SCAN = {'angle_min': -math.pi, 'angle_increment': 2 * math.pi / BEAMS, 'range_min': 0.1,
        'range_max': 12.0}
MOUNT = (0.1, 0.0, 0.0)


def cast(pose, mount=MOUNT, noise=0.01, seed=0):
    """Return LaserScan ranges (BEAMS,) of the ROOM from base pose, laser at mount."""
    x, y, yaw = compose(pose, mount)
    angles = SCAN['angle_min'] + np.arange(BEAMS) * SCAN['angle_increment'] + yaw
    dx, dy = np.cos(angles)[:, None], np.sin(angles)[:, None]
    x1, y1, x2, y2 = (ROOM[:, k][None, :] for k in range(4))
    ex, ey = x2 - x1, y2 - y1
    wx, wy = x1 - x, y1 - y
    with np.errstate(divide='ignore', invalid='ignore'):
        denom = dx * ey - dy * ex
        t = (wx * ey - wy * ex) / denom
        u = (wx * dy - wy * dx) / denom
        hit = (np.abs(denom) > 1e-12) & (t > 1e-9) & (u >= 0) & (u <= 1)
    ranges = np.where(hit, t, np.inf).min(axis=1)
    return ranges + noise * np.random.default_rng(seed).standard_normal(BEAMS)


def add(slam, odom, ranges):
    """Feed one scan with the test's scan geometry."""
    return slam.add_scan(odom, ranges, SCAN['angle_min'], SCAN['angle_increment'],
                         SCAN['range_min'], SCAN['range_max'], MOUNT)


def path(waypoints, step=0.05):
    """Return poses every `step` metres along straight legs, facing along each leg."""
    poses = []
    for (ax, ay), (bx, by) in zip(waypoints[:-1], waypoints[1:]):
        heading = math.atan2(by - ay, bx - ax)
        count = max(1, int(round(math.hypot(bx - ax, by - ay) / step)))
        for k in range(count):
            poses.append((ax + (bx - ax) * k / count, ay + (by - ay) * k / count, heading))
    return poses


# --- configuration and frames ---------------------------------------------------------

@pytest.mark.parametrize('field, value', [
    ('resolution', 0.0), ('max_laser_range', math.nan), ('minimum_travel_distance', -1.0),
    ('scan_buffer_size', 0), ('scan_buffer_size', 2.5), ('do_loop_closing', 1),
    ('link_match_minimum_response_fine', 1.5), ('coarse_search_angle_offset', 4.0),
    ('loop_closure_kernel_scale', 0.0), ('minimum_scan_returns', True),
    ('correlation_search_space_resolution', math.inf),
    ('loop_match_minimum_travel_distance', -1.0), ('match_maximum_stddev_yaw', 0.0)])
def test_config_errors_name_the_field(field, value):
    with pytest.raises(ValueError, match=f'SlamConfig.{field}'):
        SlamConfig(**{field: value})


def test_first_keyframe_puts_the_map_on_the_odom_frame():
    slam = OnlineSlam()
    assert slam.pose() == (0.0, 0.0, 0.0)
    odom = (3.0, 2.5, 0.3)
    assert add(slam, odom, cast(odom))
    assert slam.keyframe_count == 1
    assert slam.map_to_odom() == pytest.approx((0.0, 0.0, 0.0))
    assert slam.pose() == pytest.approx(odom)
    np.testing.assert_allclose(slam.trajectory(), [odom])


def test_initial_pose_places_the_first_keyframe():
    # The robot starts at (3, 2.5) facing +y in the map; its odometry starts at 0.
    initial = (3.0, 2.5, math.pi / 2)
    slam = OnlineSlam(initial_pose=initial)
    assert slam.pose() == initial
    add(slam, (0.0, 0.0, 0.0), cast(initial))
    assert slam.map_to_odom() == pytest.approx(initial)
    # 0.2 m forward in odom: map_T_base = map_T_odom * odom_T_base.
    assert not add(slam, (0.2, 0.0, 0.0), cast((3.0, 2.7, math.pi / 2)))
    assert slam.pose() == pytest.approx((3.0, 2.7, math.pi / 2))
    # map_to_odom is built with the same algebra: map_T_odom = map_T_base * odom_T_base^-1.
    assert compose(slam.map_to_odom(), (0.2, 0.0, 0.0)) == pytest.approx(slam.pose())


def test_keyframes_follow_the_travel_thresholds():
    slam = OnlineSlam(SlamConfig(minimum_travel_distance=0.5, minimum_travel_heading=0.5))
    start = (3.0, 3.0, 0.0)
    assert add(slam, start, cast(start))
    assert not add(slam, (3.3, 3.0, 0.0), cast((3.3, 3.0, 0.0)))       # 0.3 m
    assert not add(slam, (3.3, 3.0, 0.4), cast((3.3, 3.0, 0.4)))       # 0.3 m, 0.4 rad
    assert add(slam, (3.5, 3.0, 0.0), cast((3.5, 3.0, 0.0)))           # 0.5 m
    assert add(slam, (3.5, 3.0, 0.5), cast((3.5, 3.0, 0.5)))           # 0.5 rad turn
    assert add(slam, (3.5, 3.0, -0.1), cast((3.5, 3.0, -0.1)))         # 0.6 rad back
    assert slam.keyframe_count == 4
    np.testing.assert_allclose(slam.trajectory()[:, :2], [[3, 3], [3.5, 3], [3.5, 3],
                                                          [3.5, 3]], atol=0.01)
    assert slam.last_match_score > 0.9


def test_scan_matching_undoes_drift_and_a_mecanum_slip():
    """
    Odometry with 5 % scale error, yaw drift and one sudden slip of 0.25 m and 12 degrees.

    The matched trajectory stays within 2 cm and 0.01 rad; map_to_odom absorbs the error.
    """
    truth = path([(2.0, 1.0), (5.5, 1.0), (5.5, 3.5), (3.0, 3.5), (3.0, 5.5), (1.0, 5.5)])
    slam = OnlineSlam(SlamConfig(do_loop_closing=False), initial_pose=truth[0])
    odom = (0.0, 0.0, 0.0)
    errors = []
    for k, pose in enumerate(truth):
        if k:
            step = relative(truth[k - 1], pose)
            step = (1.05 * step[0], 1.05 * step[1], step[2] + 0.03 * math.hypot(*step[:2]))
            if k == len(truth) // 2:
                step = (step[0] + 0.25, step[1], step[2] + math.radians(12))   # slip
            odom = compose(odom, step)
        if add(slam, odom, cast(pose, seed=k)):
            estimate = slam.pose()
            errors.append((math.hypot(estimate[0] - pose[0], estimate[1] - pose[1]),
                           abs(wrap_angle(estimate[2] - pose[2]))))
    errors = np.array(errors)
    assert slam.keyframe_count > 15
    assert errors[:, 0].max() < 0.02
    assert errors[:, 1].max() < 0.01
    # Dead reckoning alone ends far away; the correction map_to_odom makes up for it.
    assert math.hypot(*(np.array(compose(truth[0], odom)[:2]) - truth[-1][:2])) > 0.5
    final = compose(slam.map_to_odom(), odom)
    assert math.hypot(final[0] - truth[-1][0], final[1] - truth[-1][1]) < 0.02


def test_occupancy_map_shows_the_walls_and_saves(tmp_path):
    truth = path([(2.0, 1.0), (6.0, 3.0), (2.0, 4.0)])
    slam = OnlineSlam(initial_pose=truth[0])
    for k, pose in enumerate(truth):
        add(slam, relative(truth[0], pose), cast(pose, seed=k))
    occupancy = slam.occupancy_map()
    assert occupancy.resolution_m == 0.05

    def value(x, y):
        return occupancy.data[world_to_cell(occupancy, x, y)]

    # A wall surface on a cell border: its returns fall on either side of it.
    for x, y, dx, dy in ((8.0, 2.5, 0.01, 0), (4.0, 0.0, 0, 0.01), (0.0, 3.0, 0.01, 0),
                         (2.2, 2.0, 0, 0.01)):
        assert max(value(x - dx, y - dy), value(x + dx, y + dy)) == 100, (x, y)
    for x, y in ((3.0, 3.0), (5.0, 1.2)):
        assert value(x, y) == 0, (x, y)
    assert value(2.2, 2.2) == -1       # inside the pillar: never seen
    save_map(occupancy, tmp_path / 'room.yaml')
    np.testing.assert_array_equal(load_map(tmp_path / 'room.yaml').data, occupancy.data)


def test_a_person_in_front_of_the_lidar_puts_the_keyframe_off():
    """
    A scan of a person right in front of the lidar (all beams at 0.3 m) fits anywhere.

    Its match is refused: no keyframe until twice the travel threshold, then one placed
    by odometry; the next real scans match again and the trajectory stays right.
    """
    slam = OnlineSlam(SlamConfig(minimum_travel_distance=0.5), initial_pose=(2.0, 3.0, 0.0))
    truth = path([(2.0, 3.0), (5.5, 3.0)])
    added = []
    for k, pose in enumerate(truth):
        odom = relative(truth[0], pose)
        blocked = 0.5 <= pose[0] - 2.0 < 1.5
        ranges = np.full(BEAMS, 0.3) if blocked else cast(pose, seed=k)
        added.append((pose[0] - 2.0, add(slam, odom, ranges)))
    keyframe_at = [round(x, 2) for x, was_added in added if was_added]
    # The keyframe due at 0.5 m (a blocked scan) is put off until 1.0 m of travel,
    # then placed by odometry; the first clear scan (1.5 m) matches again.
    assert keyframe_at[:3] == [0.0, 1.0, 1.5]
    assert slam.keyframe_count == len(keyframe_at)
    error = slam.trajectory()[:, 0] - (2.0 + np.array(keyframe_at))
    assert np.abs(error).max() < 0.02
    assert np.abs(slam.trajectory()[:, 1] - 3.0).max() < 0.02


def test_surface_normals_by_hand():
    line = np.column_stack([np.linspace(0.0, 1.0, 11), np.ones(11)])
    normals = surface_normals(line)
    np.testing.assert_allclose(np.abs(normals), [[0.0, 1.0]] * 11, atol=1e-12)
    # A depth jump: (5, 0.5) is 3.9 m from its neighbour, beyond 0.15 + 0.05 * 5 m.
    jump = surface_normals([(1.0, 0.0), (1.0, 0.1), (5.0, 0.5)])
    np.testing.assert_allclose(np.abs(jump[:2]), [[1.0, 0.0], [1.0, 0.0]], atol=1e-12)
    assert np.isnan(jump[2]).all()
    assert np.isnan(surface_normals([(1.0, 2.0)])).all()


# --- bad input ------------------------------------------------------------------------

def test_bad_beams_are_ignored_and_empty_scans_skipped():
    slam = OnlineSlam()
    start = (3.0, 3.0, 0.0)
    ranges = cast(start)
    ranges[::3] = np.nan                     # a third of the beams: NaN
    assert add(slam, start, ranges)
    assert not add(slam, (3.6, 3.0, 0.0), np.full(BEAMS, np.inf))       # nothing seen
    assert not add(slam, (3.6, 3.0, 0.0), [])                           # empty scan
    assert not add(slam, (3.6, 3.0, 0.0), np.full(BEAMS, np.nan))
    assert slam.keyframe_count == 1
    assert slam.pose() == pytest.approx((3.6, 3.0, 0.0))                 # odometry only
    assert add(slam, (3.6, 3.0, 0.0), cast((3.6, 3.0, 0.0)))


def test_malformed_calls_raise_and_change_nothing():
    slam = OnlineSlam()
    add(slam, (3.0, 3.0, 0.0), cast((3.0, 3.0, 0.0)))
    ranges = cast((3.6, 3.0, 0.0))
    with pytest.raises(ValueError, match='odom_pose'):
        add(slam, (3.6, 3.0), ranges)
    with pytest.raises(ValueError, match='odom_pose'):
        add(slam, (3.6, math.nan, 0.0), ranges)
    with pytest.raises(ValueError, match='laser_mount'):
        slam.add_scan((3.6, 3.0, 0.0), ranges, -math.pi, 0.01, 0.1, 12.0, (0.1, 0.0, 0.0, 1))
    with pytest.raises(ValueError, match='1-D'):
        add(slam, (3.6, 3.0, 0.0), ranges.reshape(2, -1))
    with pytest.raises(ValueError, match='range_max'):
        slam.add_scan((3.6, 3.0, 0.0), ranges, -math.pi, 0.01, 0.1, 0.05)
    with pytest.raises(ValueError, match='angle_increment'):
        slam.add_scan((3.6, 3.0, 0.0), ranges, -math.pi, math.inf, 0.1, 12.0)
    with pytest.raises(ValueError, match='initial_pose'):
        OnlineSlam(initial_pose=(0.0, 0.0))
    with pytest.raises(ValueError, match='SlamConfig'):
        OnlineSlam(config={'resolution': 0.05})
    assert slam.keyframe_count == 1
    assert slam.pose() == pytest.approx((3.0, 3.0, 0.0))


# --- wall overlap ---------------------------------------------------------------------

def test_occupied_overlap_by_hand():
    # Truth: 6x6 cells of 1 m, a wall in column 3, free elsewhere.
    truth_data = np.zeros((6, 6), np.int8)
    truth_data[:, 3] = 100
    truth = OccupancyMap(1.0, (0.0, 0.0, 0.0), truth_data)
    # Estimate: explored (free) left of the wall only, wall seen in rows 1..4 at column 2
    # (one cell off), plus one spurious wall cell far off at column 0.
    estimate_data = np.full((6, 6), -1, np.int8)
    estimate_data[:, :2] = 0
    estimate_data[1:5, 2] = 100
    estimate_data[0, 0] = 100
    estimate = OccupancyMap(1.0, (0.0, 0.0, 0.0), estimate_data)
    precision, recall = occupied_overlap(estimate, truth)
    assert precision == pytest.approx(4 / 5)
    # Visible truth wall cells border a cell free in truth and in the estimate: none
    # here (columns 2 and 4 are not free in the estimate), so recall is undefined.
    assert math.isnan(recall)
    estimate_data[0, 2] = estimate_data[5, 2] = 0
    precision, recall = occupied_overlap(OccupancyMap(1.0, (0.0, 0.0, 0.0), estimate_data),
                                         truth)
    # Now truth wall cells (0, 3) and (5, 3) are visible; each is within one cell of an
    # estimate wall cell ((1, 2) and (4, 2)).
    assert recall == pytest.approx(1.0)
    assert occupied_overlap(OccupancyMap(1.0, (0.0, 0.0, 0.0), estimate_data), truth,
                            tolerance_cells=0)[0] == pytest.approx(0.0)
    with pytest.raises(ValueError, match='tolerance_cells'):
        occupied_overlap(estimate, truth, tolerance_cells=-1)


def test_occupied_overlap_across_origins_and_resolutions():
    truth_data = np.zeros((20, 20), np.int8)
    truth_data[10, :] = 100                       # a wall at y 1.0..1.1 (0.1 m cells)
    truth = OccupancyMap(0.1, (0.0, 0.0, 0.0), truth_data)
    estimate_data = np.zeros((40, 40), np.int8)
    estimate_data[21, :] = 100                    # y 1.05..1.10 with 0.05 m cells
    estimate = OccupancyMap(0.05, (0.0, 0.0, 0.0), estimate_data)
    assert occupied_overlap(estimate, truth) == pytest.approx((1.0, 1.0))
    shifted = OccupancyMap(0.05, (0.0, 0.5, 0.0), estimate_data)   # 0.5 m off
    assert occupied_overlap(shifted, truth) == pytest.approx((0.0, 0.0))


# --- the apartment --------------------------------------------------------------------

#: A loop through living room, kitchen, hallway, bedroom and back (free space, metres).
APARTMENT_LOOP = [(2.95, 2.0), (4.6, 2.0), (5.2, 3.3), (6.8, 3.3), (8.5, 3.3), (8.5, 4.6),
                  (5.1, 4.6), (5.1, 6.4), (3.2, 6.6), (5.1, 6.4), (5.1, 4.6), (1.5, 4.6),
                  (1.5, 3.2), (2.6, 2.9), (2.95, 2.0), (4.6, 2.0), (5.2, 3.3)]


def drive_apartment(seed=0, speed=0.4, rate_hz=10.0):
    """
    Drive APARTMENT_LOOP in the simulator's apartment with its lidar and walking person.

    Returns (world, lidar, truth poses, odometry poses, scans). The odometry has a 3 %
    scale error, 0.02 rad/m yaw drift and noise; it starts at (0, 0, 0).
    """
    world_module = pytest.importorskip('robot_simulation.world')
    sensors = pytest.importorskip('robot_simulation.sensors')
    world = world_module.load_world(world_module.find_world('apartment'))
    rng = np.random.default_rng(seed)
    lidar = sensors.Lidar(sensors.LidarConfig(beams=360, mount_x_m=0.05), world.segments,
                          seed=seed)
    static = np.array([(c.center[0], c.center[1], c.radius_m)
                       for c in world.circles]).reshape(-1, 3)
    dt = 1.0 / rate_hz
    truth = [world.robot_start]
    for (ax, ay), (bx, by) in zip(APARTMENT_LOOP[:-1], APARTMENT_LOOP[1:]):
        heading = math.atan2(by - ay, bx - ax)
        count = max(1, math.ceil(math.hypot(bx - ax, by - ay) / (speed * dt)))
        for k in range(1, count + 1):
            yaw = truth[-1][2]
            yaw += max(-dt, min(dt, wrap_angle(heading - yaw)))   # turn at 1 rad/s
            truth.append((ax + (bx - ax) * k / count, ay + (by - ay) * k / count,
                          wrap_angle(yaw)))
    odom = [(0.0, 0.0, 0.0)]
    for a, b in zip(truth[:-1], truth[1:]):
        step = relative(a, b)
        distance = math.hypot(step[0], step[1])
        odom.append(compose(odom[-1], (1.03 * step[0] + rng.normal(0, 0.002),
                                       1.03 * step[1] + rng.normal(0, 0.002),
                                       step[2] + 0.02 * distance + rng.normal(0, 0.002))))
    scans = []
    for k, (x, y, yaw) in enumerate(truth):
        people = np.array([(*m.position_at(k * dt), m.radius_m)
                           for m in world.moving_obstacles]).reshape(-1, 3)
        scans.append(lidar.scan(x, y, yaw, np.vstack([static, people])))
    return world, lidar, np.array(truth), np.array(odom), scans


def run_slam(config, world, lidar, truth, odom, scans):
    """Run OnlineSlam over the drive; return (slam, RMS m, keyframe ms, other ms)."""
    slam = OnlineSlam(config, initial_pose=tuple(truth[0]))
    fields = lidar.scan_fields()
    keyframes, keyframe_s, other_s = [], [], []
    for k in range(len(truth)):
        start = time.process_time()
        added = slam.add_scan(odom[k], scans[k], fields['angle_min'],
                              fields['angle_increment'], fields['range_min'],
                              fields['range_max'], (0.05, 0.0, 0.0))
        (keyframe_s if added else other_s).append(time.process_time() - start)
        if added:
            keyframes.append(k)
    error = slam.trajectory()[:, :2] - truth[keyframes, :2]
    rms = math.sqrt(np.mean(np.sum(error ** 2, axis=1)))
    return slam, rms, 1e3 * np.mean(keyframe_s), 1e3 * np.mean(other_s)


def test_apartment_loop_maps_the_walls_and_loop_closure_helps():
    world, lidar, truth, odom, scans = drive_apartment()
    assert all(world.is_free(x, y, clearance_m=0.2) for x, y, _ in truth[::10])
    path_m = float(np.sum(np.hypot(*np.diff(truth[:, :2], axis=0).T)))
    closing, rms_closing, key_ms, other_ms = run_slam(SlamConfig(), world, lidar, truth,
                                                      odom, scans)
    _, rms_open, _, _ = run_slam(SlamConfig(do_loop_closing=False), world, lidar, truth,
                                 odom, scans)
    dead_reckoning = np.array([compose(truth[0], pose) for pose in odom])
    rms_odom = math.sqrt(np.mean(np.sum((dead_reckoning[:, :2] - truth[:, :2]) ** 2, 1)))
    precision, recall = occupied_overlap(closing.occupancy_map(),
                                         world.to_occupancy_map(0.05))
    print(f'\napartment: {path_m:.1f} m, {len(truth)} scans, {closing.keyframe_count} '
          f'keyframes, {closing.loop_closure_count} loop closures; trajectory RMS '
          f'{100 * rms_closing:.2f} cm with loop closure, {100 * rms_open:.2f} cm without, '
          f'odometry {100 * rms_odom:.0f} cm; walls precision {precision:.3f} recall '
          f'{recall:.3f}; CPU {key_ms:.1f} ms per keyframe, {other_ms:.2f} ms per other scan')
    assert rms_odom > 0.3
    assert closing.loop_closure_count > 0
    assert rms_closing < 0.03
    assert rms_open < 0.06
    assert rms_closing < 0.75 * rms_open
    assert precision > 0.97
    assert recall > 0.8
    # The final correction puts the robot where it is.
    final = compose(closing.map_to_odom(), odom[-1])
    assert math.hypot(final[0] - truth[-1][0], final[1] - truth[-1][1]) < 0.05
    assert abs(wrap_angle(final[2] - truth[-1][2])) < 0.02
