"""
Tests of mecanum_navigation.costmap.distance_transform (the exact EDT), without ROS.

Squared distances are in cells^2 between cell centres; the small cases are worked out
by hand, the random ones against a brute-force minimum over all obstacle cells.
"""

import math

from mecanum_navigation.costmap.distance_transform import (
    NO_OBSTACLE, squared_distance_transform, squared_distance_transform_1d)
import numpy as np
import pytest


def brute_force(obstacles: np.ndarray) -> np.ndarray:
    """Return min over obstacle cells of the squared distance (cells^2), as integers."""
    rows, cols = np.indices(obstacles.shape)
    r, c = np.nonzero(obstacles)
    return ((rows[..., None] - r) ** 2 + (cols[..., None] - c) ** 2).min(axis=-1)


def test_single_obstacle_in_a_5x5_grid_by_hand():
    obstacles = np.zeros((5, 5), dtype=bool)
    obstacles[2, 2] = True
    squared = squared_distance_transform(obstacles)
    assert squared.dtype == np.float64
    np.testing.assert_array_equal(squared, [[8, 5, 4, 5, 8],
                                            [5, 2, 1, 2, 5],
                                            [4, 1, 0, 1, 4],
                                            [5, 2, 1, 2, 5],
                                            [8, 5, 4, 5, 8]])
    # Distances (cells) exactly equal, as floats, to those of the offsets.
    d = np.sqrt(squared)
    assert d[2, 2] == 0.0
    assert d[2, 3] == d[1, 2] == 1.0
    assert d[1, 1] == d[3, 3] == math.sqrt(2.0)
    assert d[0, 2] == d[2, 4] == 2.0
    assert d[0, 1] == d[3, 4] == math.sqrt(5.0)
    assert d[0, 0] == d[4, 4] == d[0, 4] == d[4, 0] == math.sqrt(8.0)


def test_no_obstacle_gives_no_obstacle_everywhere():
    # As amcl's copy did: 1e30 cells^2 (SLAM's field caps it to its 1e18, unchanged).
    assert NO_OBSTACLE == 1e30
    squared = squared_distance_transform(np.zeros((3, 4), dtype=bool))
    assert squared.shape == (3, 4)
    assert (squared == NO_OBSTACLE).all()


def test_obstacles_in_opposite_corners_by_hand():
    obstacles = np.zeros((3, 4), dtype=bool)
    obstacles[0, 0] = obstacles[2, 3] = True
    # min(r^2 + c^2, (2 - r)^2 + (3 - c)^2)
    np.testing.assert_array_equal(squared_distance_transform(obstacles),
                                  [[0, 1, 4, 4],
                                   [1, 2, 2, 1],
                                   [4, 4, 1, 0]])


def test_obstacles_along_a_border():
    obstacles = np.zeros((4, 3), dtype=bool)
    obstacles[0, :] = True      # the whole first row: the distance is the row index
    np.testing.assert_array_equal(squared_distance_transform(obstacles),
                                  np.repeat([[0], [1], [4], [9]], 3, axis=1))
    obstacles = np.zeros((4, 3), dtype=bool)
    obstacles[:, -1] = True     # the whole last column
    np.testing.assert_array_equal(squared_distance_transform(obstacles),
                                  np.tile([4, 1, 0], (4, 1)))


@pytest.mark.parametrize('obstacles, expected', [
    ([[False, False, True, False, False, False]], [[4, 1, 0, 1, 4, 9]]),
    ([[False, False, False, False, False, True]], [[25, 16, 9, 4, 1, 0]]),
    ([[True], [False], [False]], [[0], [1], [4]]),
])
def test_single_row_or_column_by_hand(obstacles, expected):
    np.testing.assert_array_equal(squared_distance_transform(obstacles), expected)


@pytest.mark.parametrize('seed, density', [(0, 0.01), (1, 0.05), (2, 0.2), (3, 0.6)])
def test_random_30x30_grid_equals_brute_force(seed, density):
    obstacles = np.random.default_rng(seed).random((30, 30)) < density
    obstacles[29, 0] = True     # at least one obstacle
    np.testing.assert_array_equal(squared_distance_transform(obstacles),
                                  brute_force(obstacles))


@pytest.mark.parametrize('shape', [(1, 17), (40, 3), (23, 31)])
def test_random_rectangular_grids_equal_brute_force(shape):
    obstacles = np.random.default_rng(7).random(shape) < 0.1
    obstacles[0, 0] = True
    np.testing.assert_array_equal(squared_distance_transform(obstacles),
                                  brute_force(obstacles))


def test_input_types_and_layout():
    obstacles = np.zeros((4, 6), dtype=np.int8)
    obstacles[1, 4] = 100       # any non-zero value is an obstacle
    expected = brute_force(obstacles != 0)
    np.testing.assert_array_equal(squared_distance_transform(obstacles), expected)
    np.testing.assert_array_equal(squared_distance_transform((obstacles != 0).T), expected.T)
    assert obstacles[1, 4] == 100 and np.count_nonzero(obstacles) == 1    # not modified
    for bad in (np.zeros(5, dtype=bool), np.zeros((2, 2, 2), dtype=bool)):
        with pytest.raises(ValueError, match='2-D'):
            squared_distance_transform(bad)


def test_1d_transform_by_hand():
    # Sites at 1 (f = 3) and 4 (f = 0): out[q] = min((q - 1)^2 + 3, (q - 4)^2).
    f = np.array([NO_OBSTACLE, 3.0, NO_OBSTACLE, NO_OBSTACLE, 0.0, NO_OBSTACLE, 0.0])
    out = np.full(7, -1.0)
    hull = np.empty(7, dtype=np.int64)
    bounds = np.empty(8)
    squared_distance_transform_1d(f, 6, out, hull, bounds)   # only the first 6 entries
    np.testing.assert_array_equal(out, [4, 3, 4, 1, 0, 1, -1])
    squared_distance_transform_1d(np.full(7, NO_OBSTACLE), 7, out, hull, bounds)
    assert (out == NO_OBSTACLE).all()
