"""Tests of costmap.costmap_2d: Nav2 cost values, layers, inflation law (by hand)."""

import math

from mecanum_map_server.map_io import OccupancyMap
from mecanum_navigation.costmap.costmap_2d import (
    COST_TRANSLATION_TABLE, Costmap2D, FREE_SPACE, InflationLayer, INSCRIBED_INFLATED_OBSTACLE,
    KeepoutLayer, LayeredCostmap, LETHAL_OBSTACLE, NO_INFORMATION, ObstacleLayer, RollingWindow,
    StaticLayer, ZoneLayer)
from mecanum_safety.zone import make_zone
import numpy as np
import pytest

LETHAL = LETHAL_OBSTACLE
INSCRIBED = INSCRIBED_INFLATED_OBSTACLE


def nav2_law(distance_m, inscribed=0.2, inflation=0.55, scaling=3.0):
    """Return the cost of the inflation law at distance_m (the spec, written out)."""
    if distance_m == 0.0:
        return 254
    if distance_m <= inscribed + 1e-9:
        return 253
    if distance_m > inflation + 1e-9:
        return 0
    return math.floor(252 * math.exp(-scaling * (distance_m - inscribed)))


def brute_force_distances(lethal_mask, resolution):
    """Return each cell's distance (m, centre to centre) to the nearest lethal cell."""
    rows, cols = np.indices(lethal_mask.shape)
    lr, lc = np.nonzero(lethal_mask)
    d2 = ((rows[..., None] - lr) ** 2 + (cols[..., None] - lc) ** 2).min(axis=-1)
    return np.sqrt(d2) * resolution


# --- Costmap2D -----------------------------------------------------------------------

def test_world_map_conversions_follow_map_io_convention():
    costmap = Costmap2D(4, 3, 0.5, origin_x_m=-1.0, origin_y_m=-1.0)
    assert costmap.size_x == 4 and costmap.size_y == 3
    assert costmap.costs.shape == (3, 4) and costmap.costs.dtype == np.uint8
    # x -0.5 is the boundary between columns 0 and 1: it belongs to the right one.
    assert costmap.world_to_map(-0.5, -1.0) == (0, 1)
    assert costmap.world_to_map(0.99, 0.49) == (2, 3)
    assert costmap.world_to_map(1.0, 0.0) is None     # right edge: outside
    assert costmap.world_to_map(-1.01, 0.0) is None
    assert costmap.world_to_map(math.nan, 0.0) is None
    assert costmap.map_to_world(2, 3) == (0.75, 0.25)
    costmap.costs[2, 3] = 77
    assert costmap.cost_at(0.75, 0.25) == 77
    assert costmap.cost_at(5.0, 5.0) is None


@pytest.mark.parametrize('kwargs, name', [
    ({'size_x': 0}, 'size_x'), ({'size_y': 2.5}, 'size_y'),
    ({'resolution_m': 0.0}, 'resolution_m'), ({'resolution_m': math.nan}, 'resolution_m'),
    ({'origin_x_m': math.inf}, 'origin_x_m'), ({'default_value': 256}, 'default_value'),
])
def test_costmap_parameters_are_checked(kwargs, name):
    arguments = {'size_x': 3, 'size_y': 3, 'resolution_m': 0.1}
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=name):
        Costmap2D(**arguments)


def test_occupancy_grid_translation_is_nav2s_table():
    # 1 + 97 * (cost - 1) // 251: 2 -> 1 + 0; 126 -> 1 + 12125 // 251 = 1 + 48;
    # 128 -> 1 + 12319 // 251 = 1 + 49; 251 -> 1 + 24250 // 251 = 1 + 96; 252 -> 98.
    expected = {0: 0, 1: 1, 2: 1, 126: 49, 128: 50, 251: 97, 252: 98, 253: 99, 254: 100,
                255: -1}
    for cost, value in expected.items():
        assert COST_TRANSLATION_TABLE[cost] == value, cost
    assert np.all(np.diff(COST_TRANSLATION_TABLE[1:253].astype(int)) >= 0)
    costmap = Costmap2D(3, 2, 0.25, origin_x_m=1.0, origin_y_m=2.0)
    costmap.costs[:] = [[0, 128, 252], [253, 254, 255]]
    grid = costmap.to_occupancy_map()
    assert grid.origin == (1.0, 2.0, 0.0) and grid.resolution_m == 0.25
    assert grid.data.tolist() == [[0, 50, 98], [99, 100, -1]]


# --- Inflation -----------------------------------------------------------------------

def inflated_single_obstacle(**kwargs):
    """Return a 41 x 41 costmap at 0.05 m with one lethal cell at (20, 20), inflated."""
    costmap = Costmap2D(41, 41, 0.05)
    costmap.costs[20, 20] = LETHAL
    InflationLayer(inscribed_radius=0.2, **kwargs).update(costmap)
    return costmap


def test_inflation_values_by_hand():
    costs = inflated_single_obstacle().costs  # inflation 0.55 m, scaling 3.0, inscribed 0.2
    assert costs[20, 20] == 254                         # d = 0
    assert costs[20, 21] == 253                         # d = 0.05 <= 0.2
    assert costs[20, 24] == 253                         # d = 0.20: exactly inscribed
    # d = 0.25: 252 exp(-3 * 0.05) = 252 * 0.860708 = 216.898 -> 216
    assert costs[20, 25] == 216
    assert costs[23, 24] == 216                         # (3, 4) cells: d = 5 cells too
    # d = 0.30: 252 exp(-0.3) = 252 * 0.740818 = 186.686 -> 186
    assert costs[26, 20] == 186
    # d = 0.50 ((6, 8) cells): 252 exp(-0.9) = 252 * 0.406570 = 102.456 -> 102
    assert costs[26, 28] == 102
    # d = 7 sqrt(2) * 0.05 = 0.494975: 252 exp(-3 * 0.294975) = 252 * 0.412745 = 104.01
    assert costs[27, 27] == 104
    # d = 0.55 = inflation_radius: 252 exp(-1.05) = 252 * 0.349938 = 88.184 -> 88
    assert costs[20, 31] == 88
    assert costs[20, 9] == 88
    assert costs[20, 32] == 0                           # d = 0.60 > inflation_radius
    assert costs[28, 28] == 0                           # d = 0.566 > 0.55


def test_inflation_parameters_change_the_law():
    costs = inflated_single_obstacle(inflation_radius=1.0, cost_scaling_factor=10.0).costs
    # d = 0.25: 252 exp(-10 * 0.05) = 252 * 0.606531 = 152.85 -> 152
    assert costs[20, 25] == 152
    # d = 0.60: 252 exp(-4) = 252 * 0.0183156 = 4.6155 -> 4
    assert costs[20, 32] == 4
    layer = InflationLayer(inscribed_radius=0.2, inflation_radius=1.0, cost_scaling_factor=10.0)
    assert layer.cost_at_distance(0.25) == 152 and layer.cost_at_distance(1.01) == 0


def test_inflation_matches_the_law_on_brute_force_distances():
    rng = np.random.default_rng(3)
    costmap = Costmap2D(70, 55, 0.05)
    lethal = rng.random((55, 70)) < 0.02
    lethal[10:14, 30:50] = True
    costmap.costs[lethal] = LETHAL
    InflationLayer(inscribed_radius=0.2).update(costmap)
    distances = brute_force_distances(lethal, 0.05)
    expected = np.vectorize(nav2_law)(distances)
    assert np.array_equal(costmap.costs, expected)
    assert (costmap.costs == INSCRIBED).sum() > 0 and (costmap.costs == 0).sum() > 0


def test_lethal_block_gets_an_inscribed_ring_of_exact_width():
    # 3 x 3 lethal block; at 0.1 m resolution an inscribed radius of 0.2 m is 2 cells.
    costmap = Costmap2D(15, 15, 0.1)
    costmap.costs[6:9, 6:9] = LETHAL
    InflationLayer(inscribed_radius=0.2, inflation_radius=0.3).update(costmap)
    costs = costmap.costs
    assert np.all(costs[6:9, 6:9] == 254)
    assert np.all(costs[4:6, 6:9] == 253) and np.all(costs[9:11, 6:9] == 253)
    assert np.all(costs[6:9, 4:6] == 253) and np.all(costs[6:9, 9:11] == 253)
    assert costs[5, 5] == 253                  # diagonal: sqrt(2) cells = 0.141 m
    # 2 sqrt(2) cells = 0.28284 m: 252 exp(-3 * 0.08284) = 252 * 0.779950 = 196.55 -> 196
    assert costs[4, 4] == 196
    # 3 cells = 0.3 m: 252 exp(-3 * 0.1) = 186.69 -> 186; 4 cells is past 0.3 m.
    assert costs[7, 3] == 186 and costs[7, 2] == 0


def test_inflation_keeps_higher_costs_and_unknown_cells():
    costmap = Costmap2D(41, 41, 0.05)
    costmap.costs[20, 20] = LETHAL
    costmap.costs[20, 22] = NO_INFORMATION      # d = 0.10 -> inscribed: becomes 253
    costmap.costs[20, 26] = NO_INFORMATION      # d = 0.30 -> 186 < 253: stays unknown
    costmap.costs[26, 20] = 200                 # higher than 186: kept
    costmap.costs[20, 14] = 100                 # lower than 186: raised
    unknown_copy = costmap.copy()
    InflationLayer(inscribed_radius=0.2).update(costmap)
    assert costmap.costs[20, 22] == 253
    assert costmap.costs[20, 26] == NO_INFORMATION
    assert costmap.costs[26, 20] == 200
    assert costmap.costs[20, 14] == 186
    InflationLayer(inscribed_radius=0.2, inflate_unknown=True).update(unknown_copy)
    assert unknown_copy.costs[20, 26] == 186


def test_inflation_without_obstacles_changes_nothing():
    costmap = Costmap2D(30, 20, 0.05)
    costmap.costs[3:6, 3:6] = NO_INFORMATION
    costmap.costs[10, 10] = 17
    before = costmap.costs.copy()
    InflationLayer(inscribed_radius=0.2).update(costmap)
    assert np.array_equal(costmap.costs, before)


@pytest.mark.parametrize('kwargs, name', [
    ({'inscribed_radius': -0.1}, 'inscribed_radius'),
    ({'inscribed_radius': math.nan}, 'inscribed_radius'),
    ({'inflation_radius': -1.0}, 'inflation_radius'),
    ({'cost_scaling_factor': math.inf}, 'cost_scaling_factor'),
    ({'inflate_unknown': 1}, 'inflate_unknown'),
])
def test_inflation_parameters_are_checked(kwargs, name):
    arguments = {'inscribed_radius': 0.2}
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=name):
        InflationLayer(**arguments)


# --- Static layer --------------------------------------------------------------------

def test_static_layer_trinary_conversion_and_unknown():
    data = np.array([[-1, 0, 50], [99, 100, 65]], dtype=np.int8)
    occupancy = OccupancyMap(0.1, (0.0, 0.0, 0.0), data)
    costmap = Costmap2D.like_map(occupancy)
    StaticLayer(occupancy).update(costmap)
    assert costmap.costs.tolist() == [[255, 0, 0], [0, 254, 0]]
    StaticLayer(occupancy, lethal_cost_threshold=65, track_unknown_space=False).update(costmap)
    assert costmap.costs.tolist() == [[0, 0, 0], [254, 254, 254]]
    with pytest.raises(ValueError, match='lethal_cost_threshold'):
        StaticLayer(occupancy, lethal_cost_threshold=101)


def test_static_layer_into_a_window_and_from_a_rotated_map():
    data = np.zeros((10, 10), dtype=np.int8)
    data[4, 7] = 100                      # map cell centre at (7.5 * 0.1 - 1, 4.5 * 0.1 - 1)
    occupancy = OccupancyMap(0.1, (-1.0, -1.0, 0.0), data)
    window = Costmap2D(4, 4, 0.1, origin_x_m=-0.5, origin_y_m=-0.8, default_value=7)
    StaticLayer(occupancy).update(window)
    # Map cell (4, 7) spans x -0.3..-0.2, y -0.6..-0.5: window cell (2, 2).
    assert window.costs[2, 2] == 254 and (window.costs == 254).sum() == 1
    assert (window.costs == 0).sum() == 15
    # The map rotated by +90 deg about its origin: map cell (row 4, col 7) now spans
    # x -1 - 0.5..-1 - 0.4, y -1 + 0.7..-1 + 0.8 (local x -> world y, local y -> -world x).
    rotated = OccupancyMap(0.1, (-1.0, -1.0, math.pi / 2), data)
    costmap = Costmap2D(30, 30, 0.1, origin_x_m=-2.0, origin_y_m=-2.0, default_value=9)
    StaticLayer(rotated).update(costmap)
    assert costmap.cost_at(-1.45, -0.25) == 254 and (costmap.costs == 254).sum() == 1
    assert costmap.cost_at(-1.95, -1.95) == 9          # off the map: untouched


# --- Keepout -------------------------------------------------------------------------

def test_keepout_square_and_triangle_cells():
    costmap = Costmap2D(10, 10, 0.1)
    KeepoutLayer([[(0.2, 0.2), (0.5, 0.2), (0.5, 0.5), (0.2, 0.5)]]).update(costmap)
    # Centres 0.25, 0.35, 0.45 are inside on both axes: rows 2..4, columns 2..4.
    expected = np.zeros((10, 10), dtype=bool)
    expected[2:5, 2:5] = True
    assert np.array_equal(costmap.costs == LETHAL, expected)
    costmap.reset()
    KeepoutLayer([[(0.0, 0.0), (1.05, 0.0), (0.0, 1.05)]]).update(costmap)
    # Centre (c + 0.5, r + 0.5) * 0.1 is inside when r + c + 1 < 10.5, i.e. r + c <= 9:
    # 10 + 9 + ... + 1 = 55 cells.
    rows, cols = np.indices((10, 10))
    assert np.array_equal(costmap.costs == LETHAL, rows + cols <= 9)
    assert (costmap.costs == LETHAL).sum() == 55


def test_keepout_polygon_partly_outside_and_concave():
    costmap = Costmap2D(10, 10, 0.1, origin_x_m=1.0, origin_y_m=1.0)
    # An L shape reaching past the left edge: the columns x < 1.0 are not in the costmap.
    KeepoutLayer([[(0.5, 1.0), (1.3, 1.0), (1.3, 1.2), (1.1, 1.2), (1.1, 1.6),
                   (0.5, 1.6)]]).update(costmap)
    expected = np.zeros((10, 10), dtype=bool)
    expected[0:2, 0:3] = True     # y 1.0..1.2, x 1.0..1.3
    expected[2:6, 0:1] = True     # y 1.2..1.6, x 1.0..1.1
    assert np.array_equal(costmap.costs == LETHAL, expected)


@pytest.mark.parametrize('polygons', [[[(0, 0), (1, 1)]], [[(0, 0), (1, 0), (math.nan, 1)]],
                                      [['ab', 'cd', 'ef']]])
def test_keepout_rejects_bad_polygons(polygons):
    with pytest.raises(ValueError, match=r'polygons\[0\]'):
        KeepoutLayer(polygons)


# --- Zone layer (the authorised zone as a geofence) -----------------------------------

# An L-shaped (concave) zone on a 6 x 5 grid of 1 m cells (centres x 0.5..5.5, y
# 0.5..4.5): the bar y 0.2..2.2 over the whole width, the upright x 0.2..2.2 up to y 4.8,
# and a triangular exclusion (2.8, 0.8), (4.9, 0.8), (2.8, 1.9) in the bar.
L_ZONE = make_zone([(0.2, 0.2), (5.8, 0.2), (5.8, 2.2), (2.2, 2.2), (2.2, 4.8), (0.2, 4.8)],
                   [[(2.8, 0.8), (4.9, 0.8), (2.8, 1.9)]])


def test_zone_layer_l_shape_with_an_exclusion_by_hand():
    """
    Exactly the cells whose centres are outside the L, or inside the triangle, are lethal.

    Rows 2..4 (y 2.5..4.5) are above the bar: only columns 0, 1 (x 0.5, 1.5 < 2.2) are in
    the upright. In the bar, of the centres at y 1.5 the triangle holds those with x
    between 2.8 and its hypotenuse, x = 4.9 - (1.5 - 0.8) * 2.1 / 1.1 = 3.564: only
    (3.5, 1.5), i.e. row 1, column 3. At y 0.5 (below 0.8) none.
    """
    costmap = Costmap2D(6, 5, 1.0)
    costmap.costs[0, 0] = 7          # a cost inside the zone is left alone
    ZoneLayer(L_ZONE).update(costmap)
    L, F = LETHAL, FREE_SPACE
    expected = np.array([[7, F, F, F, F, F],
                         [F, F, F, L, F, F],
                         [F, F, L, L, L, L],
                         [F, F, L, L, L, L],
                         [F, F, L, L, L, L]], dtype=np.uint8)
    assert np.array_equal(costmap.costs, expected)
    # Whatever was there before, a cell outside the zone ends lethal.
    costmap.costs[4, 5] = NO_INFORMATION
    ZoneLayer(L_ZONE).update(costmap)
    assert costmap.costs[4, 5] == LETHAL


def test_zone_layer_agrees_with_zone_contains_on_a_fine_grid():
    """Cell by cell, lethal == not Zone.contains(cell centre) (200 x 160 cells, 2.5 cm)."""
    costmap = Costmap2D(200, 160, 0.025, origin_x_m=0.1, origin_y_m=0.05)
    ZoneLayer(L_ZONE).update(costmap)
    xs, ys = costmap.cell_centers()
    assert np.array_equal(costmap.costs == LETHAL, ~L_ZONE.contains(xs, ys))


def test_zone_layer_before_inflation_keeps_the_footprint_inside():
    """
    A border at x = 0.62 on 0.1 m cells: centres 0.65.. lethal, then Nav2's law.

    Inscribed radius 0.2 m, inflation 0.5 m, scaling 4: the centres 0.55 and 0.45 (0.1
    and 0.2 m from the lethal centre 0.65) are inscribed (253); 0.35 (0.3 m) gets
    floor(252 exp(-0.4)) = 168, 0.25 floor(252 exp(-0.8)) = 113, 0.15 floor(252
    exp(-1.2)) = 75, 0.05 (0.6 m) nothing. The first usable centre, 0.35, is 0.27 m from
    the border: the 0.2 m footprint stays inside.
    """
    zone = make_zone([(-1.0, -1.0), (0.62, -1.0), (0.62, 1.0), (-1.0, 1.0)])
    costmap = Costmap2D(10, 3, 0.1)
    layered = LayeredCostmap(costmap, [ZoneLayer(zone), InflationLayer(0.2, 0.5, 4.0)])
    layered.update()
    row = [0, 75, 113, 168, INSCRIBED, INSCRIBED, LETHAL, LETHAL, LETHAL, LETHAL]
    assert costmap.costs.tolist() == [row] * 3
    assert zone.clearance([0.35], [0.0])[0] == pytest.approx(0.27)


def test_zone_layer_in_the_odom_frame_by_hand():
    """
    The local costmap in odom; odom's pose in map (map -> odom) is (2, 1, pi/2).

    An odom point (u, v) is at map (2 - v, 1 + u). The 4 x 4 grid of 0.5 m cells from
    odom (-1, -1) has centres u, v in -0.75, -0.25, 0.25, 0.75. The zone, map x 0..2.5,
    y 0..1.5: map x < 2.5 needs v > -0.5 (row 0, v -0.75, is out); map y < 1.5 needs
    u < 0.5 (column 3, u 0.75, is out). The exclusion, map x 1.5..2.0, y 0.5..1.0, holds
    map (1.75, 0.75) = odom (-0.25, 0.25): row 2, column 1.
    """
    zone = make_zone([(0.0, 0.0), (2.5, 0.0), (2.5, 1.5), (0.0, 1.5)],
                     [[(1.5, 0.5), (2.0, 0.5), (2.0, 1.0), (1.5, 1.0)]])
    costmap = Costmap2D(4, 4, 0.5, origin_x_m=-1.0, origin_y_m=-1.0)
    layer = ZoneLayer(zone, frame_pose=None)
    layer.update(costmap)                  # map -> odom not known yet: nothing written
    assert np.all(costmap.costs == FREE_SPACE)
    assert layer.outside_mask(costmap) is None
    layer.set_frame_pose(2.0, 1.0, math.pi / 2)
    layer.update(costmap)
    L, F = LETHAL, FREE_SPACE
    assert costmap.costs.tolist() == [[L, L, L, L],
                                      [F, F, F, L],
                                      [F, L, F, L],
                                      [F, F, F, L]]
    # The layer keeps its last pose: a rolled window is masked with it.
    costmap.update_origin(-0.5, -1.0)
    costmap.reset()
    layer.update(costmap)
    assert costmap.costs.tolist() == [[L, L, L, L],
                                      [F, F, L, L],
                                      [L, F, L, L],
                                      [F, F, L, L]]


def test_zone_layer_in_a_rotated_frame_matches_transformed_centres():
    """Any pose: lethal == not contains(cell centre moved into map by the pose)."""
    x, y, yaw = 1.3, -0.7, 0.4
    costmap = Costmap2D(120, 120, 0.025, origin_x_m=1.0, origin_y_m=2.0)
    ZoneLayer(L_ZONE, frame_pose=(x, y, yaw)).update(costmap)
    us, vs = costmap.cell_centers()
    in_map_x = x + math.cos(yaw) * us - math.sin(yaw) * vs
    in_map_y = y + math.sin(yaw) * us + math.cos(yaw) * vs
    outside = ~L_ZONE.contains(in_map_x, in_map_y)
    assert 0 < outside.sum() < outside.size
    assert np.array_equal(costmap.costs == LETHAL, outside)


def test_zone_layer_checks_its_inputs():
    with pytest.raises(ValueError, match='zone must be a Zone'):
        ZoneLayer([(0, 0), (1, 0), (1, 1)])
    layer = ZoneLayer(L_ZONE)
    with pytest.raises(ValueError, match='yaw must be finite'):
        layer.set_frame_pose(0.0, 0.0, math.nan)
    assert layer.frame_pose == (0.0, 0.0, 0.0)


# --- Obstacle layer ------------------------------------------------------------------

def all_marked_layer(costmap, **kwargs):
    """Return an ObstacleLayer whose grid is LETHAL in every cell of costmap."""
    layer = ObstacleLayer(**kwargs)
    for row in range(costmap.size_y):
        for col in range(costmap.size_x):
            centre = costmap.map_to_world(row, col)
            layer.add_points(centre[0], centre[1], [centre])   # a return at the sensor
    layer.update(costmap)
    assert np.all(costmap.costs == LETHAL)
    return layer


def test_obstacle_marking_and_bresenham_clearing_by_hand():
    costmap = Costmap2D(10, 10, 1.0)
    layer = all_marked_layer(costmap, obstacle_max_range=20.0, raytrace_max_range=20.0)
    # Sensor in cell (0, 0), return in cell (2, 4): Bresenham visits (0,0) (0,1) (1,2)
    # (1,3) (2,4); the ray clears them all, then the return re-marks (2, 4).
    layer.add_points(0.5, 0.5, [(4.5, 2.5)])
    costmap.reset()
    layer.update(costmap)
    free = {tuple(cell) for cell in np.argwhere(costmap.costs == FREE_SPACE)}
    assert free == {(0, 0), (0, 1), (1, 2), (1, 3)}
    # Marks persist over updates without observations.
    costmap.reset()
    layer.update(costmap)
    assert {tuple(cell) for cell in np.argwhere(costmap.costs == FREE_SPACE)} == free


def test_obstacle_ranges_limit_marking_and_clearing():
    costmap = Costmap2D(10, 10, 1.0)
    layer = all_marked_layer(costmap, obstacle_max_range=3.0, raytrace_max_range=5.0)
    # A return 8 m away: beyond obstacle_max_range (no mark); the ray clears only the
    # first 5 m, to x = 5.5 (cells (0, 0)..(0, 5)); (0, 6)..(0, 9) stay marked.
    layer.add_points(0.5, 0.5, [(8.5, 0.5)])
    costmap.reset()
    layer.update(costmap)
    assert costmap.costs[0].tolist() == [0] * 6 + [254] * 4
    # A return 2 m away is marked; one 4 m away only clears.
    layer = all_marked_layer(costmap, obstacle_max_range=3.0, raytrace_max_range=5.0)
    layer.add_points(0.5, 0.5, [(0.5, 2.5), (4.5, 0.5)])
    costmap.reset()
    layer.update(costmap)
    assert costmap.costs[:4, 0].tolist() == [0, 0, 254, 254]
    assert costmap.costs[0, :6].tolist() == [0, 0, 0, 0, 0, 254]


def test_latest_points_are_the_newest_scans_marked_returns():
    layer = ObstacleLayer(obstacle_max_range=3.0, obstacle_min_range=0.5)
    assert layer.latest_points.shape == (0, 2)
    layer.add_scan(1.0, 2.0, math.pi / 2, [1.0, 0.2, 4.0, math.inf], 0.0, math.pi / 2)
    # Beams north, west, south, east from (1, 2): 1 m north is marked; 0.2 m (below
    # obstacle_min_range), 4 m (beyond obstacle_max_range) and +inf are not.
    assert np.allclose(layer.latest_points, [(1.0, 3.0)])
    layer.add_points(0.0, 0.0, [(2.0, 0.0), (0.0, -1.5)])
    assert np.allclose(layer.latest_points, [(2.0, 0.0), (0.0, -1.5)])
    layer.clear()
    assert layer.latest_points.shape == (0, 2)


def test_scan_inf_nan_and_invalid_ranges():
    costmap = Costmap2D(10, 10, 1.0)
    layer = all_marked_layer(costmap, obstacle_max_range=2.5, raytrace_max_range=3.0)
    # Beams at 0, 90, 180 and 270 deg from (0.5, 0.5): +inf clears 3 m along +x
    # (cells (0, 0)..(0, 3)); NaN and -inf are ignored; 0.05 is below range_min.
    ignored = layer.add_scan(0.5, 0.5, 0.0, [math.inf, math.nan, -math.inf, 0.05], 0.0,
                             math.pi / 2, range_min=0.1, range_max=12.0)
    assert ignored == 3
    costmap.reset()
    layer.update(costmap)
    assert {tuple(c) for c in np.argwhere(costmap.costs == 0)} == {(0, 0), (0, 1), (0, 2),
                                                                   (0, 3)}
    # +inf with a sensor range_max of 2 m only clears 2 m; a finite range above
    # range_max means no return too; the ray to a return leaving the grid is clipped.
    layer = all_marked_layer(costmap, obstacle_max_range=2.5, raytrace_max_range=3.0)
    ignored = layer.add_scan(0.5, 5.5, 0.0, [math.inf, 2.5], 0.0, math.pi / 2,
                             range_max=2.0)
    assert ignored == 0
    layer.add_points(5.5, 9.5, [(5.5, 11.5)])
    costmap.reset()
    layer.update(costmap)
    assert {tuple(c) for c in np.argwhere(costmap.costs == 0)} == {
        (5, 0), (5, 1), (5, 2), (6, 0), (7, 0), (9, 5)}


def test_obstacle_layer_bad_input():
    layer = ObstacleLayer()
    assert layer.add_points(0.0, 0.0, [(math.nan, 1.0), (1.0, math.inf)]) == 2
    assert layer.add_points(0.0, 0.0, [], free_directions=[(0.0, 0.0)]) == 1
    with pytest.raises(ValueError, match='sensor_x'):
        layer.add_points(math.nan, 0.0, [(1.0, 1.0)])
    with pytest.raises(ValueError, match='points'):
        layer.add_points(0.0, 0.0, [(1.0, 1.0, 1.0)])
    with pytest.raises(ValueError, match='angle_increment'):
        layer.add_scan(0.0, 0.0, 0.0, [1.0], 0.0, math.inf)
    with pytest.raises(ValueError, match='obstacle_max_range'):
        ObstacleLayer(obstacle_max_range=-1.0)
    with pytest.raises(ValueError, match='raytrace_min_range'):
        ObstacleLayer(raytrace_min_range=4.0)


def test_obstacle_layer_tracks_unknown_and_combines_by_maximum():
    costmap = Costmap2D(10, 10, 1.0, default_value=NO_INFORMATION)
    layer = ObstacleLayer(obstacle_max_range=20.0, raytrace_max_range=20.0,
                          track_unknown_space=True)
    layer.add_points(0.5, 0.5, [(3.5, 0.5)])
    layer.update(costmap)
    assert costmap.costs[0, :5].tolist() == [0, 0, 0, 254, 255]
    assert (costmap.costs == NO_INFORMATION).sum() == 96
    # Cleared cells never lower a static obstacle: the layer combines by maximum.
    costmap = Costmap2D(10, 10, 1.0)
    costmap.costs[0, 1] = LETHAL
    layer.update(costmap)
    assert costmap.costs[0, :4].tolist() == [0, 254, 0, 254]


# --- Rolling window and layered costmap ----------------------------------------------

def test_rolling_window_shift_keeps_world_positions():
    window = RollingWindow(2.0, 2.0, 0.1, default_value=NO_INFORMATION)
    costmap = window.costmap
    assert (costmap.size_x, costmap.size_y) == (20, 20)
    assert (costmap.origin_x_m, costmap.origin_y_m) == (-1.0, -1.0)
    costmap.costs[:] = FREE_SPACE
    costmap.costs[costmap.world_to_map(0.33, -0.47)] = LETHAL
    assert window.move_to(0.5, 0.3) == (3, 5)
    assert costmap.origin_x_m == pytest.approx(-0.5, abs=1e-12)
    assert costmap.origin_y_m == pytest.approx(-0.7, abs=1e-12)
    assert costmap.cost_at(0.33, -0.47) == LETHAL
    assert (costmap.costs == LETHAL).sum() == 1
    # Cells that came into the window (x > 1.0 or y > 1.0) are unknown; the rest free.
    assert costmap.cost_at(1.2, 0.0) == NO_INFORMATION
    assert costmap.cost_at(0.0, 1.25) == NO_INFORMATION
    assert (costmap.costs == NO_INFORMATION).sum() == 20 * 20 - 15 * 17
    assert window.move_to(0.51, 0.29) == (0, 0)          # less than half a cell: no shift
    window.move_to(10.0, 10.0)                           # all new
    assert np.all(costmap.costs == NO_INFORMATION)


def test_obstacle_marks_roll_with_the_window_and_layers_run_in_order():
    window = RollingWindow(4.0, 4.0, 0.1)
    obstacles = ObstacleLayer()
    layered = LayeredCostmap(window.costmap, [obstacles, InflationLayer(inscribed_radius=0.2)])
    obstacles.add_points(0.0, 0.0, [(1.05, 0.05)])
    costmap = layered.update()
    assert costmap.cost_at(1.05, 0.05) == LETHAL
    assert costmap.cost_at(1.05, 0.25) == INSCRIBED          # 2 cells above: 0.2 m
    window.move_to(1.0, 1.0)                                 # the layer grid follows
    costmap = layered.update()
    assert costmap.cost_at(1.05, 0.05) == LETHAL
    assert (costmap.costs == LETHAL).sum() == 1
    with pytest.raises(ValueError, match=r'layers\[0\]'):
        LayeredCostmap(costmap, [object()])


def test_the_clearance_to_lethal_cells_is_to_their_squares():
    """A lethal cell (1, 2) at 1 m cells is the square x 2..3, y 1..2."""
    costmap = Costmap2D(8, 4, 1.0)
    costmap.costs[1, 2] = LETHAL_OBSTACLE
    assert costmap.lethal_clearance_m(0.5, 1.5, 3.0) == pytest.approx(1.5)    # left of it
    assert costmap.lethal_clearance_m(2.5, 3.5, 3.0) == pytest.approx(1.5)    # above it
    assert costmap.lethal_clearance_m(0.5, 0.5, 3.0) == pytest.approx(math.hypot(1.5, 0.5))
    assert costmap.lethal_clearance_m(2.5, 1.5, 3.0) == 0.0                   # inside it
    # Out of reach (0.5 m, and the cells around): not looked at.
    assert costmap.lethal_clearance_m(7.9, 3.9, 0.5) == math.inf
    assert Costmap2D(3, 3, 1.0).lethal_clearance_m(1.0, 1.0, 5.0) == math.inf
