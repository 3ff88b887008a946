"""Tests of mecanum_navigation.planner.planner: hand-worked paths, errors, and optimality."""

import heapq
import math

from mecanum_navigation.costmap.costmap_2d import (
    Costmap2D, InflationLayer, INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, NO_INFORMATION)
from mecanum_navigation.planner.planner import GridPlanner, path_length, PlanningError
import numpy as np
import pytest

LETHAL = LETHAL_OBSTACLE
SQRT2 = math.sqrt(2.0)
#: Random grids of the optimality tests and the bounds asserted on them.
RANDOM_GRIDS = 40
#: With cost_weight 0 the final path is never longer than the optimal grid path
#: (shortcuts obey the triangle inequality; a longer smoothed path is dropped).
SHORTEST_BOUND = 1.0 + 1e-9
#: With the default cost_weight (1.0) the path (grid and final) is at most F times the
#: shortest grid path on these cramped grids (observed worst: grid path 1.18, final
#: path 1.07); the hard limit of the grid path is 1 + cost_weight = 2, since no step
#: costs more than (1 + cost_weight) times its length.
F = 1.25


def blocked_cells(costs, allow_unknown=False):
    """Return the mask of cells a circular robot's centre may not enter."""
    blocked = (costs == LETHAL) | (costs == INSCRIBED_INFLATED_OBSTACLE)
    if not allow_unknown:
        blocked |= costs == NO_INFORMATION
    return blocked


def dijkstra(costs, start, goal, cost_weight):
    """
    Brute-force reference: cheapest 8-connected path (cost, length in cells) or None.

    A step costs its length * (1 + cost_weight * cost(entered cell) / 252); diagonal
    steps need both cells they pass by free. Plain Python, no heuristic.
    """
    rows, cols = costs.shape
    blocked = blocked_cells(costs)
    best = {start: 0.0}
    heap = [(0.0, 0.0, start)]
    done = set()
    while heap:
        cost, length, cell = heapq.heappop(heap)
        if cell in done:
            continue
        done.add(cell)
        if cell == goal:
            return cost, length
        r, c = cell
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                nr, nc = r + dr, c + dc
                if (dr, dc) == (0, 0) or not (0 <= nr < rows and 0 <= nc < cols):
                    continue
                if blocked[nr, nc] or (dr and dc and (blocked[r, nc] or blocked[nr, c])):
                    continue
                step = SQRT2 if dr and dc else 1.0
                new = cost + step * (1.0 + cost_weight * int(costs[nr, nc]) / 252.0)
                if new < best.get((nr, nc), math.inf):
                    best[(nr, nc)] = new
                    heapq.heappush(heap, (new, length + step, (nr, nc)))
    return None


def worst_cost_along(costmap, points, allow_unknown=False):
    """
    Return the highest cost of the cells under densely sampled points of a polyline.

    Samples every 0.01 cell; a blocked cell gives 1000 (any blocked cell fails).
    """
    blocked = blocked_cells(costmap.costs, allow_unknown)
    array = np.asarray(points)
    worst = 0
    for (x0, y0), (x1, y1) in zip(array[:-1], array[1:]):
        count = int(math.hypot(x1 - x0, y1 - y0) / costmap.resolution_m * 100) + 2
        t = np.linspace(0.0, 1.0, count)
        cols = np.floor((x0 + (x1 - x0) * t - costmap.origin_x_m) / costmap.resolution_m)
        rows = np.floor((y0 + (y1 - y0) * t - costmap.origin_y_m) / costmap.resolution_m)
        rows, cols = rows.astype(int), cols.astype(int)
        assert rows.min() >= 0 and cols.min() >= 0
        assert rows.max() < costmap.size_y and cols.max() < costmap.size_x
        if blocked[rows, cols].any():
            return 1000
        worst = max(worst, int(costmap.costs[rows, cols].max()))
    return worst


def grid_path_worst_cost(costmap, cells):
    """Return the highest cost of a grid path's cells and the cells its diagonals pass by."""
    costs = costmap.costs
    worst = max(int(costs[cell]) for cell in cells)
    for (r0, c0), (r1, c1) in zip(cells[:-1], cells[1:]):
        if r0 != r1 and c0 != c1:
            worst = max(worst, int(costs[r0, c1]), int(costs[r1, c0]))
    return worst


def centre(costmap, row, col):
    """Return the world centre of cell (row, col)."""
    return costmap.map_to_world(row, col)


# --- Hand-worked paths ---------------------------------------------------------------

def test_straight_line_in_an_empty_grid():
    costmap = Costmap2D(20, 10, 0.1)
    plan = GridPlanner().plan(costmap, centre(costmap, 5, 2), centre(costmap, 5, 17))
    # 15 straight steps of 0.1 m: 1.5 m, whatever the cost weight (all costs are 0).
    assert plan.grid_length_m == pytest.approx(1.5, abs=1e-12)
    assert plan.length_m == pytest.approx(1.5, abs=1e-12)
    assert plan.cost == pytest.approx(1.5, abs=1e-12)
    assert plan.points[0] == centre(costmap, 5, 2) and plan.points[-1] == centre(costmap, 5, 17)
    assert all(y == pytest.approx(0.55, abs=1e-12) for _, y in plan.points)
    steps = np.hypot(*np.diff(np.asarray(plan.points), axis=0).T)
    assert steps.max() <= 0.1 + 1e-12 and len(plan.points) == 16


def test_knight_move_is_straightened():
    costmap = Costmap2D(10, 10, 0.1)
    plan = GridPlanner(smooth_path=False).plan(costmap, centre(costmap, 0, 0),
                                               centre(costmap, 2, 7))
    # Grid path: 2 diagonal + 5 straight steps = (5 + 2 sqrt 2) * 0.1 = 0.782843 m;
    # line of sight then gives the straight segment sqrt(2^2 + 7^2) * 0.1 = 0.728011 m.
    assert plan.grid_length_m == pytest.approx((5 + 2 * SQRT2) * 0.1, abs=1e-12)
    assert plan.length_m == pytest.approx(math.sqrt(53) * 0.1, abs=1e-12)
    assert plan.waypoints == [centre(costmap, 0, 0), centre(costmap, 2, 7)]


def test_route_around_a_wall():
    # 30 x 30 cells of 0.1 m; a lethal wall in column 15, rows 0..24 (no inflation).
    costmap = Costmap2D(30, 30, 0.1)
    costmap.costs[0:25, 15] = LETHAL
    start, goal = centre(costmap, 5, 5), centre(costmap, 5, 25)
    plan = GridPlanner(cost_weight=0.0).plan(costmap, start, goal)
    # Shortest grid path, no corner cutting: (5,5) -> (25,14): 11 straight + 9 diagonal
    # steps; -> (25,15) -> (25,16): 2 straight; -> (5,25): 11 + 9 diagonal again.
    # 2 * (11 + 9 sqrt 2) + 2 = 24 + 18 sqrt 2 cells = 4.945584 m.
    assert plan.grid_length_m == pytest.approx((24 + 18 * SQRT2) * 0.1, abs=1e-9)
    reference = dijkstra(costmap.costs, (5, 5), (5, 25), 0.0)
    assert plan.cost == pytest.approx(reference[0] * 0.1, abs=1e-9)
    # The taut string around the wall's top (x 1.5..1.6 at y 2.5) is a lower bound:
    # 2 * hypot(0.95, 1.95) + 0.1 = 4.438 m.
    assert 2 * math.hypot(0.95, 1.95) + 0.1 - 1e-9 <= plan.length_m <= plan.grid_length_m
    assert max(y for _, y in plan.points) >= 2.5
    assert worst_cost_along(costmap, plan.points) == 0


def test_cost_weight_keeps_the_path_away_from_an_obstacle():
    # A post in the middle of the straight route from (0.3, 1.0) to (2.7, 1.0).
    costmap = Costmap2D(60, 40, 0.05)
    costmap.costs[19:21, 29:31] = LETHAL
    InflationLayer(inscribed_radius=0.2).update(costmap)
    start, goal = (0.325, 1.025), (2.725, 1.025)
    post = np.array([1.5, 1.0])

    def clearance(plan):
        points = np.asarray(plan.points)
        return np.hypot(*(points - post).T).min()

    shortest = GridPlanner(cost_weight=0.0).plan(costmap, start, goal)
    weighted = GridPlanner().plan(costmap, start, goal)
    # cost_weight 0 grazes the inscribed ring (0.2 m from the post's cells, whose
    # edges are 0.05 m from its centre point): under 0.3 m; weighted keeps further.
    assert clearance(shortest) < 0.3
    assert clearance(weighted) > clearance(shortest) + 0.1
    assert worst_cost_along(costmap, weighted.points) < worst_cost_along(costmap, shortest.points)
    assert weighted.length_m <= F * shortest.length_m


def test_plan_to_own_cell_and_exact_start_goal_points():
    costmap = Costmap2D(10, 10, 0.1)
    plan = GridPlanner().plan(costmap, (0.51, 0.52), (0.58, 0.57))
    assert plan.points == [(0.51, 0.52), (0.58, 0.57)]
    assert plan.grid_length_m == 0.0
    assert plan.length_m == pytest.approx(math.hypot(0.07, 0.05), abs=1e-12)


# --- Errors and tolerance ------------------------------------------------------------

def walled_costmap():
    """Return a 20 x 20 costmap (0.1 m) with a closed lethal box (rows/cols 10..14)."""
    costmap = Costmap2D(20, 20, 0.1)
    costmap.costs[10, 10:15] = LETHAL
    costmap.costs[14, 10:15] = LETHAL
    costmap.costs[10:15, 10] = LETHAL
    costmap.costs[10:15, 14] = LETHAL
    return costmap


@pytest.mark.parametrize('start, goal, message', [
    ((-0.05, 0.5), (0.5, 0.5), 'start is outside the map'),
    ((0.5, 0.5), (0.5, 2.0), 'goal is outside the map'),
    ((1.05, 1.25), (0.5, 0.5), 'start is in an obstacle'),
    ((0.5, 0.5), (1.45, 1.25), 'goal is in an obstacle'),
    ((0.5, 0.5), (1.25, 1.25), 'no path'),
    ((math.nan, 0.5), (0.5, 0.5), 'start is not finite'),
    ((0.5, 0.5), 'xy', 'goal must be an'),
])
def test_planning_errors(start, goal, message):
    with pytest.raises(PlanningError, match=message):
        GridPlanner().plan(walled_costmap(), start, goal)


def test_inscribed_and_unknown_cells():
    costmap = walled_costmap()
    costmap.costs[5, 5] = INSCRIBED_INFLATED_OBSTACLE
    costmap.costs[2, 0:20] = NO_INFORMATION     # an unknown band across the map
    with pytest.raises(PlanningError, match=r'start is in an obstacle \(cost 253, inscribed'):
        GridPlanner().plan(costmap, (0.55, 0.55), (0.05, 0.05))
    with pytest.raises(PlanningError, match='goal is in unknown space'):
        GridPlanner().plan(costmap, (0.05, 0.05), (0.55, 0.25))
    with pytest.raises(PlanningError, match='no path'):
        GridPlanner().plan(costmap, (0.05, 0.05), (0.55, 0.85))
    plan = GridPlanner(allow_unknown=True).plan(costmap, (0.05, 0.05), (0.55, 0.85))
    assert plan.grid_length_m == pytest.approx((3 + 5 * SQRT2) * 0.1, abs=1e-9)
    assert worst_cost_along(costmap, plan.points, allow_unknown=True) == NO_INFORMATION


def test_goal_tolerance():
    costmap = walled_costmap()
    # Goal on the box's right wall (cell (12, 14)): the nearest free cell is (12, 15),
    # 0.1 m away.
    plan = GridPlanner(tolerance=0.15).plan(costmap, (0.05, 0.05), (1.45, 1.25))
    assert plan.goal == pytest.approx((1.55, 1.25), abs=1e-12)
    assert plan.points[-1] == plan.goal
    with pytest.raises(PlanningError, match='goal is in an obstacle .* within tolerance'):
        GridPlanner(tolerance=0.05).plan(costmap, (0.05, 0.05), (1.45, 1.25))
    # Goal free but inside the closed box (cell (12, 13)): cells (12, 11..13) are nearer
    # but unreachable; the nearest reachable is (12, 15), 0.2 m away.
    plan = GridPlanner(tolerance=0.25).plan(costmap, (0.05, 0.05), (1.35, 1.25))
    assert plan.goal == pytest.approx((1.55, 1.25), abs=1e-12)
    with pytest.raises(PlanningError, match='no reachable free cell'):
        GridPlanner(tolerance=0.15).plan(costmap, (0.05, 0.05), (1.35, 1.25))


@pytest.mark.parametrize('kwargs, name', [
    ({'cost_weight': -1.0}, 'cost_weight'), ({'cost_weight': math.nan}, 'cost_weight'),
    ({'tolerance': -0.1}, 'tolerance'), ({'allow_unknown': 'yes'}, 'allow_unknown'),
    ({'w_smooth': 0.7}, 'w_smooth'), ({'smoothing_iterations': -1}, 'smoothing_iterations'),
])
def test_planner_parameters_are_checked(kwargs, name):
    with pytest.raises(ValueError, match=name):
        GridPlanner(**kwargs)


# --- Optimality on random grids ------------------------------------------------------

def random_costmap(seed):
    """Return a seeded 50 x 40 costmap (0.05 m): lethal boxes and specks, inflated."""
    rng = np.random.default_rng(seed)
    costmap = Costmap2D(50, 40, 0.05)
    for _ in range(rng.integers(3, 9)):
        r0, c0 = rng.integers(0, 40), rng.integers(0, 50)
        costmap.costs[r0:r0 + rng.integers(1, 12), c0:c0 + rng.integers(1, 12)] = LETHAL
    costmap.costs[rng.random((40, 50)) < 0.01] = LETHAL
    InflationLayer(inscribed_radius=0.1, inflation_radius=0.4).update(costmap)
    return costmap


def random_cases():
    """Yield (costmap, start cell, goal cell) of the seeded random grids."""
    for seed in range(RANDOM_GRIDS):
        costmap = random_costmap(seed)
        free = np.argwhere(~blocked_cells(costmap.costs))
        rng = np.random.default_rng(1000 + seed)
        start, goal = (tuple(int(v) for v in free[rng.integers(len(free))])
                       for _ in range(2))
        yield costmap, start, goal


def test_astar_is_optimal_and_paths_stay_clear_on_random_grids():
    planned = unreachable = 0
    for costmap, start, goal in random_cases():
        start_xy, goal_xy = centre(costmap, *start), centre(costmap, *goal)
        reference = dijkstra(costmap.costs, start, goal, 0.0)
        if reference is None:
            with pytest.raises(PlanningError, match='no path'):
                GridPlanner().plan(costmap, start_xy, goal_xy)
            unreachable += 1
            continue
        planned += 1
        shortest_m = reference[1] * costmap.resolution_m
        shortest = GridPlanner(cost_weight=0.0).plan(costmap, start_xy, goal_xy)
        assert shortest.grid_length_m == pytest.approx(shortest_m, abs=1e-9)
        assert shortest.length_m <= SHORTEST_BOUND * shortest.grid_length_m
        assert shortest.length_m >= math.dist(start_xy, goal_xy) - 1e-9
        assert shortest.length_m == pytest.approx(path_length(shortest.points), abs=1e-9)
        for cost_weight in (1.0, 3.0):
            weighted_reference = dijkstra(costmap.costs, start, goal, cost_weight)
            planner = GridPlanner(cost_weight=cost_weight)
            plan = planner.plan(costmap, start_xy, goal_xy)
            assert plan.cost == pytest.approx(weighted_reference[0] * 0.05, abs=1e-9)
            assert plan.length_m <= plan.grid_length_m + 1e-9
            assert plan.grid_length_m <= (1.0 + cost_weight) * shortest_m + 1e-9
            if cost_weight == 1.0:
                assert plan.grid_length_m <= F * shortest_m + 1e-9
                assert plan.length_m <= F * shortest_m + 1e-9
        default = GridPlanner().plan(costmap, start_xy, goal_xy)
        for plan in (shortest, default):
            # Never a blocked cell, and never a cell costlier than the grid path allowed.
            assert plan.cells[0] == start and plan.cells[-1] == goal
            assert worst_cost_along(costmap, plan.points) <= grid_path_worst_cost(
                costmap, plan.cells) < INSCRIBED_INFLATED_OBSTACLE
    assert planned >= 30 and unreachable >= 1
