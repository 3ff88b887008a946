"""Tests of mecanum_navigation.slam.scan_matching: distance fields, search, refinement."""

import math

from mecanum_map_server.map_io import OccupancyMap
from mecanum_navigation.slam.scan_matching import (
    LikelihoodField, match_scan, ScanMatcherConfig, voxel_filter)
import numpy as np
import pytest

#: An L-shaped room (8 m x 7 m) with a pillar and a cupboard: no symmetry to confuse.
ROOM = np.array([
    (0, 0, 8, 0), (8, 0, 8, 5), (8, 5, 4, 5), (4, 5, 4, 7), (4, 7, 0, 7), (0, 7, 0, 0),
    (2.0, 2.0, 2.4, 2.0), (2.4, 2.0, 2.4, 2.4), (2.4, 2.4, 2.0, 2.4), (2.0, 2.4, 2.0, 2.0),
    (6.0, 1.0, 7.0, 1.0), (7.0, 1.0, 7.0, 1.6), (7.0, 1.6, 6.0, 1.6), (6.0, 1.6, 6.0, 1.0),
], dtype=float)


def cast(segments, pose, beams=360, max_range=12.0, noise=0.0, seed=0):
    """Return the points (N, 2) a lidar at pose sees, in its own frame (ray casting)."""
    x, y, yaw = pose
    angles = np.arange(beams) * 2 * math.pi / beams
    dx, dy = np.cos(angles + yaw)[:, None], np.sin(angles + yaw)[:, None]
    x1, y1, x2, y2 = (segments[:, k][None, :] for k in range(4))
    ex, ey = x2 - x1, y2 - y1
    wx, wy = x1 - x, y1 - y
    with np.errstate(divide='ignore', invalid='ignore'):
        denom = dx * ey - dy * ex
        t = (wx * ey - wy * ex) / denom
        u = (wx * dy - wy * dx) / denom
        hit = (np.abs(denom) > 1e-12) & (t > 1e-9) & (u >= 0) & (u <= 1)
    ranges = np.where(hit, t, np.inf).min(axis=1)
    ranges = ranges + noise * np.random.default_rng(seed).standard_normal(beams)
    keep = ranges <= max_range
    return np.column_stack([ranges[keep] * np.cos(angles[keep]),
                            ranges[keep] * np.sin(angles[keep])])


def wall_points(segments, spacing=0.01):
    """Return points every `spacing` metres along the segments (the map's walls)."""
    out = []
    for x1, y1, x2, y2 in segments:
        count = max(2, int(math.hypot(x2 - x1, y2 - y1) / spacing) + 1)
        t = np.linspace(0.0, 1.0, count)
        out.append(np.column_stack([x1 + t * (x2 - x1), y1 + t * (y2 - y1)]))
    return np.vstack(out)


@pytest.fixture(scope='module')
def room_fields():
    """Return the (coarse, fine) fields of the room."""
    points = wall_points(ROOM)
    return (LikelihoodField.from_points(points, 0.05, 0.05),
            LikelihoodField.from_points(points, 0.025, 0.025))


# --- distance fields ------------------------------------------------------------------

def test_field_of_an_empty_grid_is_far():
    # No occupied cell: squared distances 1e18 cells^2 (as before the shared transform).
    field = LikelihoodField(np.zeros((4, 5), bool), 0.1, (0.0, 0.0), sigma_m=0.1)
    assert np.all(field.distance_m == np.float32(1e9 * 0.1))
    assert np.all(field.field == 0.0)


def test_field_of_one_occupied_cell_by_hand():
    occupied = np.zeros((5, 5), bool)
    occupied[2, 2] = True
    field = LikelihoodField(occupied, 0.1, (1.0, 2.0), sigma_m=0.1)
    assert field.field[2, 2] == pytest.approx(1.0)
    assert field.field[2, 3] == pytest.approx(math.exp(-0.5))          # d = 1 sigma
    assert field.field[3, 3] == pytest.approx(math.exp(-1.0))          # d^2 = 2 sigma^2
    assert field.distance_m[0, 0] == pytest.approx(0.1 * math.sqrt(8))
    # Cell (2, 2) spans x 1.2..1.3, y 2.2..2.3; outside the grid the field is 0.
    assert field.value_at(1.25, 2.25) == pytest.approx(1.0)
    assert field.value_at(0.99, 2.25) == 0.0


def test_field_from_points_uses_exact_distances():
    # A point at a cell centre, resolution 0.05: cells are on multiples of 0.05.
    field = LikelihoodField.from_points([[0.125, 0.125]], 0.05, sigma_m=0.05)
    assert field.origin_xy[0] / 0.05 == pytest.approx(round(field.origin_xy[0] / 0.05))
    assert field.value_at(0.125, 0.125) == pytest.approx(1.0)
    assert field.value_at(0.175, 0.125) == pytest.approx(math.exp(-0.5))
    # Beyond max_distance_m (3 sigma) the field is 0.
    assert field.value_at(0.125 + 0.2, 0.125) == 0.0
    # Off-centre point: the distance is to the point, not to its cell.
    off = LikelihoodField.from_points([[0.11, 0.125]], 0.05, sigma_m=0.05)
    assert off.value_at(0.125, 0.125) == pytest.approx(math.exp(-0.015 ** 2 / 0.005))


def test_pyramid_holds_block_maxima():
    occupied = np.zeros((3, 3), bool)
    field = LikelihoodField(occupied, 1.0, (0.0, 0.0), 1.0)
    field.field[:] = np.array([[1, 2, 3], [4, 5, 6], [7, 8, 9]], dtype=np.float32) / 10
    grids, pad = field.pyramid(1)
    assert pad == 2 and grids.shape == (2, 7, 7)
    np.testing.assert_allclose(grids[0, pad:pad + 3, pad:pad + 3], field.field)
    # Block maximum over rows r..r+1, cols c..c+1 (0 outside the field).
    np.testing.assert_allclose(grids[1, pad:pad + 3, pad:pad + 3],
                               np.array([[5, 6, 6], [8, 9, 9], [8, 9, 9]]) / 10, atol=1e-7)
    assert grids[1, pad - 1, pad - 1] == pytest.approx(0.1)   # covers only cell (0, 0)
    assert grids[1, 0, 0] == 0.0


def test_field_from_probabilities_thresholds_the_cells():
    probabilities = np.full((4, 6), 0.2)
    probabilities[1, 4] = 0.9
    probabilities[2, 1] = 0.5            # not above 0.5: not occupied
    probabilities[3, 3] = np.nan         # unknown: not occupied
    field = LikelihoodField.from_probabilities(probabilities, 0.1, (-1.0, 0.0), 0.1)
    assert field.field[1, 4] == pytest.approx(1.0)
    assert field.distance_m[2, 1] == pytest.approx(0.1 * math.sqrt(10))
    assert field.distance_m[3, 3] == pytest.approx(0.1 * math.sqrt(5))
    assert field.value_at(-0.55, 0.15) == pytest.approx(1.0)      # cell (1, 4)


def test_field_from_a_rotated_map_is_refused():
    occupancy = OccupancyMap(0.05, (0.0, 0.0, 0.3), np.zeros((3, 3), np.int8))
    with pytest.raises(ValueError, match='unrotated'):
        LikelihoodField.from_occupancy_map(occupancy, 0.05)


# --- matching -------------------------------------------------------------------------

@pytest.mark.parametrize('offset', [
    (0.3, 0.0, math.radians(15)), (-0.3, 0.0, -math.radians(15)),
    (0.0, 0.3, math.radians(15)), (0.21, -0.21, -math.radians(15)),
    (-0.21, 0.21, math.radians(10)), (0.0, 0.0, 0.0)])
def test_match_recovers_a_prior_off_by_0_3_m_and_15_degrees(room_fields, offset):
    coarse, fine = room_fields
    truth = (3.1, 3.3, 0.4)
    points = voxel_filter(cast(ROOM, truth, noise=0.01), 0.05)
    prior = (truth[0] + offset[0], truth[1] + offset[1], truth[2] + offset[2])
    result = match_scan(coarse, points, prior, fine_field=fine)
    assert result.pose[0] == pytest.approx(truth[0], abs=0.01)
    assert result.pose[1] == pytest.approx(truth[1], abs=0.01)
    assert result.pose[2] == pytest.approx(truth[2], abs=0.005)
    assert result.score > 0.95
    assert 0.5 < result.response <= 1.0
    assert result.num_points == len(points)


def test_match_on_an_occupancy_map_field(room_fields):
    # The same room rasterised into a 5 cm OccupancyMap (cells with a wall point).
    points = wall_points(ROOM)
    data = np.zeros((int(7.6 / 0.05), int(8.6 / 0.05)), np.int8)
    cols = np.floor((points[:, 0] + 0.3) / 0.05).astype(int)
    rows = np.floor((points[:, 1] + 0.3) / 0.05).astype(int)
    data[rows, cols] = 100
    field = LikelihoodField.from_occupancy_map(OccupancyMap(0.05, (-0.3, -0.3, 0.0), data),
                                               sigma_m=0.05)
    truth = (5.0, 3.0, -2.0)
    scan = voxel_filter(cast(ROOM, truth), 0.05)
    result = match_scan(field, scan, (5.2, 2.85, -2.2))
    assert result.pose[:2] == pytest.approx(truth[:2], abs=0.03)
    assert result.pose[2] == pytest.approx(truth[2], abs=0.01)
    assert result.score > 0.9


def brute_force_best(field, points, prior, window_cells, yaws):
    """Return the best mean field value over the whole discrete search grid."""
    res = field.resolution_m
    ox, oy = field.origin_xy
    best = -1.0
    for yaw in yaws:
        c, s = math.cos(yaw), math.sin(yaw)
        px = prior[0] + c * points[:, 0] - s * points[:, 1]
        py = prior[1] + s * points[:, 0] + c * points[:, 1]
        cols = np.floor((px - ox) / res).astype(int)
        rows = np.floor((py - oy) / res).astype(int)
        for dx in range(-window_cells, window_cells + 1):
            for dy in range(-window_cells, window_cells + 1):
                r, cc = rows + dy, cols + dx
                inside = (r >= 0) & (r < field.shape[0]) & (cc >= 0) & (cc < field.shape[1])
                total = field.field[r[inside], cc[inside]].astype(float).sum()
                best = max(best, total / len(points))
    return best


def test_branch_and_bound_finds_the_exhaustive_optimum(room_fields):
    coarse, _ = room_fields
    points = voxel_filter(cast(ROOM, (5.5, 2.5, 1.0), noise=0.02, seed=3), 0.05)[::3]
    prior = (5.62, 2.43, 1.04)
    config = ScanMatcherConfig(linear_window_m=0.15, angular_window_rad=0.06,
                               angular_step_rad=0.02, prior_penalty=0.0, refine=False)
    result = match_scan(coarse, points, prior, config)
    yaws = prior[2] + 0.02 * np.arange(-3, 4)
    expected = brute_force_best(coarse, points, prior, 3, yaws)
    assert result.response == pytest.approx(expected, rel=1e-6)
    # The pose is on the search grid: whole cells and yaw steps from the prior.
    assert (result.pose[0] - prior[0]) / 0.05 == pytest.approx(
        round((result.pose[0] - prior[0]) / 0.05), abs=1e-9)
    assert (result.pose[2] - prior[2]) / 0.02 == pytest.approx(
        round((result.pose[2] - prior[2]) / 0.02), abs=1e-9)


def test_covariance_is_long_along_a_corridor():
    corridor = np.array([(-30, -1, 30, -1), (-30, 1, 30, 1)], dtype=float)
    points = wall_points(corridor)
    coarse = LikelihoodField.from_points(points, 0.05, 0.05)
    fine = LikelihoodField.from_points(points, 0.025, 0.025)
    scan = voxel_filter(cast(corridor, (0.0, 0.0, 0.0), max_range=6.0), 0.05)
    result = match_scan(coarse, scan, (0.0, 0.1, 0.05), fine_field=fine)
    covariance = result.covariance
    np.testing.assert_allclose(covariance, covariance.T)
    assert np.all(np.linalg.eigvalsh(covariance) > 0.0)
    assert result.pose[1] == pytest.approx(0.0, abs=0.01)
    assert result.pose[2] == pytest.approx(0.0, abs=0.005)
    # Along the corridor the scan says nothing: about the window's variance.
    assert covariance[0, 0] > 100 * covariance[1, 1]
    assert 0.3 ** 2 < covariance[0, 0] <= 0.4 ** 2 + (0.25 * 0.025) ** 2 + 1e-9


def test_covariance_is_small_in_the_room(room_fields):
    coarse, fine = room_fields
    scan = voxel_filter(cast(ROOM, (3.0, 4.0, 0.0), noise=0.01), 0.05)
    result = match_scan(coarse, scan, (3.1, 4.1, 0.1), fine_field=fine)
    sigmas = np.sqrt(np.diag(result.covariance))
    assert np.all(sigmas[:2] < 0.02) and sigmas[2] < 0.01
    # The floor: a quarter of a fine cell.
    assert np.all(sigmas[:2] >= 0.25 * 0.025)


def test_a_scan_of_another_place_scores_low(room_fields):
    coarse, fine = room_fields
    square = np.array([(0, 0, 3, 0), (3, 0, 3, 3), (3, 3, 0, 3), (0, 3, 0, 0)], dtype=float)
    scan = voxel_filter(cast(square, (1.5, 1.5, 0.0)), 0.05)
    result = match_scan(coarse, scan, (3.0, 3.0, 0.0), fine_field=fine)
    assert result.score < 0.5
    good = match_scan(coarse, voxel_filter(cast(ROOM, (3.0, 3.0, 0.0)), 0.05), (3.0, 3.0, 0.0),
                      fine_field=fine)
    assert good.score > 0.95


def test_too_few_points_return_the_prior_with_score_0(room_fields):
    coarse, _ = room_fields
    result = match_scan(coarse, np.zeros((3, 2)), (1.0, 2.0, 0.5),
                        ScanMatcherConfig(minimum_points=4))
    assert result.pose == (1.0, 2.0, 0.5)
    assert result.score == 0.0 and result.response == 0.0
    assert result.covariance[0, 0] == pytest.approx(0.4 ** 2)
    empty = match_scan(coarse, np.zeros((0, 2)), (1.0, 2.0, 0.5))
    assert empty.score == 0.0 and empty.num_points == 0


def test_bad_input_is_refused(room_fields):
    coarse, _ = room_fields
    with pytest.raises(ValueError, match='finite'):
        match_scan(coarse, [[1.0, math.nan]] * 20, (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match=r'\(N, 2\)'):
        match_scan(coarse, np.zeros((20, 3)), (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match='prior'):
        match_scan(coarse, np.zeros((20, 2)), (0.0, math.inf, 0.0))
    with pytest.raises(ValueError, match='prior'):
        match_scan(coarse, np.zeros((20, 2)), (0.0, 0.0))
    with pytest.raises(ValueError, match='points must be finite'):
        LikelihoodField.from_points([[0.0, math.nan]], 0.05, 0.05)
    with pytest.raises(ValueError, match='sigma_m'):
        LikelihoodField.from_points([[0.0, 0.0]], 0.05, 0.0)
    with pytest.raises(ValueError, match='non-empty'):
        LikelihoodField(np.zeros((0, 3), bool), 0.05, (0.0, 0.0), 0.05)


@pytest.mark.parametrize('field, value', [
    ('linear_window_m', -0.1), ('angular_window_rad', 4.0), ('angular_step_rad', 0.0),
    ('hit_distance_m', math.nan), ('prior_penalty', math.inf), ('refine', 1),
    ('minimum_points', 0)])
def test_config_errors_name_the_field(field, value):
    with pytest.raises(ValueError, match=f'ScanMatcherConfig.{field}'):
        ScanMatcherConfig(**{field: value})


def test_voxel_filter_keeps_the_first_point_of_each_cell():
    points = [(0.01, 0.01), (0.02, 0.03), (0.06, 0.01), (-0.01, 0.0), (0.04, 0.049)]
    np.testing.assert_array_equal(voxel_filter(points, 0.05),
                                  [(0.01, 0.01), (0.06, 0.01), (-0.01, 0.0)])
    assert voxel_filter(np.zeros((0, 2)), 0.05).shape == (0, 2)
    with pytest.raises(ValueError, match='cell_m'):
        voxel_filter(points, 0.0)
