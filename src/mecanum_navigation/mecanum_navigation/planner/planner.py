"""
Cost-aware global planner on a Costmap2D for a circular holonomic robot (pure, no ROS).

The job of Nav2's NavFn / Smac 2D planners, for a robot whose footprint is a circle (the
costmap's inflation already grows obstacles by its radius):

- a cell is blocked when its cost is >= INSCRIBED_INFLATED_OBSTACLE (253: the robot's
  centre there puts the footprint into an obstacle); NO_INFORMATION (255) is blocked
  unless allow_unknown, and then counts as cost 252;
- A* on the 8-connected grid (no corner cutting: a diagonal step needs both cells it
  passes by free), octile heuristic (admissible: the result is optimal for the cost);
  a step costs its length times (1 + cost_weight * cost / 252), cost being the cost of
  the cell entered (Smac 2D's cost_travel_multiplier plays this part). cost_weight 0
  gives the shortest grid path; larger values keep the path away from obstacles
  (down the inflation gradient) at the price of length. The grid path is never
  longer than (1 + cost_weight) times the shortest one, since no step costs more
  than (1 + cost_weight) times its length. The default, 1.0, makes the cell next to
  the inscribed ring (cost 252) twice as dear as free space: in the tests' cramped
  random grids paths are at most ~1.3x the shortest, on building-like maps ~1.03x
  (bench/planning.py), and the robot keeps to the middle of corridors and doors;
- the start (x, y) must be in a free cell; the goal too, unless tolerance (m) > 0:
  then the reachable free cell nearest the goal within tolerance is used (Nav2's
  `tolerance`), also when the goal cell is free but unreachable;
- the grid path (cell centres, with the exact start and goal at its ends) is
  shortcut by line of sight: a straight segment may replace a stretch of path when
  it crosses no cell costing more than the most expensive cell of that stretch (so it
  never enters a blocked cell, nor gets closer to obstacles than the path already
  was), then resampled every resolution and, optionally, gently smoothed (Nav2's
  simple smoother update, w_data 0.2, w_smooth 0.3), with the same cost check; a
  smoothed path that fails a check or is longer is dropped for the unsmoothed one.

Output: world (x, y) points in the costmap's frame (REP-103, metres), start first and
goal last, no orientations (the navigator's job), and path lengths.
"""

from dataclasses import dataclass
import math
from typing import List, Sequence, Tuple

from mecanum_navigation.costmap.costmap_2d import (
    Costmap2D, INSCRIBED_INFLATED_OBSTACLE, NO_INFORMATION)
from mecanum_navigation.planner import grid_search
import numpy as np

Point = Tuple[float, float]


class PlanningError(Exception):
    """No plan: the message says why (start/goal outside the map or blocked, no path)."""


@dataclass(frozen=True)
class Plan:
    """
    A planned path in the costmap's frame.

    points: (x, y) m from the start to the goal used, at most one resolution apart.
    length_m: length of the points' polyline.
    grid_length_m: length of the A* path through cell centres (from the start cell's
    centre to the goal cell's centre); length_m <= grid_length_m plus the distances of
    the exact start and goal to their cells' centres.
    cost: the A* path cost (m, weighted by cost_weight).
    waypoints: the corners of the shortcut path (before resampling and smoothing).
    goal: the (x, y) m actually reached (the goal, or a free cell's centre within
    tolerance of it).
    expansions: cells A* expanded (all searches of this plan).
    smoothed: whether the smoothed path was kept.
    cells: the A* path's cells (row, col), start cell first.
    """

    points: List[Point]
    length_m: float
    grid_length_m: float
    cost: float
    waypoints: List[Point]
    goal: Point
    expansions: int
    smoothed: bool
    cells: List[Tuple[int, int]]


class GridPlanner:
    """Plans paths on costmaps; keeps work arrays between plans (not thread-safe)."""

    def __init__(self, cost_weight: float = 1.0, allow_unknown: bool = False,
                 tolerance: float = 0.0, smooth_path: bool = True, w_data: float = 0.2,
                 w_smooth: float = 0.3, smoothing_iterations: int = 30):
        """Check and store the parameters (see the module docstring)."""
        for name, value in (('cost_weight', cost_weight), ('tolerance', tolerance),
                            ('w_data', w_data), ('w_smooth', w_smooth)):
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f'{name} must be a number, not {value!r}')
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f'{name} must be finite and >= 0, not {value!r}')
        if w_smooth > 0.5:
            raise ValueError(f'w_smooth must be <= 0.5 (larger values oscillate), not {w_smooth}')
        if w_data > 1.0:
            raise ValueError(f'w_data must be <= 1, not {w_data}')
        for name, value in (('allow_unknown', allow_unknown), ('smooth_path', smooth_path)):
            if not isinstance(value, bool):
                raise ValueError(f'{name} must be a bool, not {value!r}')
        if (isinstance(smoothing_iterations, bool) or not isinstance(smoothing_iterations, int)
                or smoothing_iterations < 0):
            raise ValueError(f'smoothing_iterations must be an integer >= 0, not '
                             f'{smoothing_iterations!r}')
        self.cost_weight = float(cost_weight)
        self.allow_unknown = allow_unknown
        self.tolerance = float(tolerance)
        self.smooth_path = smooth_path
        self.w_data = float(w_data)
        self.w_smooth = float(w_smooth)
        self.smoothing_iterations = smoothing_iterations
        self._work_size = -1
        self._generation = 0

    def plan(self, costmap: Costmap2D, start: Sequence[float],
             goal: Sequence[float]) -> Plan:
        """Plan from start (x, y) m to goal (x, y) m; raise PlanningError when impossible."""
        if not isinstance(costmap, Costmap2D):
            raise ValueError(f'costmap must be a Costmap2D, not {type(costmap).__name__}')
        start_xy = _point('start', start)
        goal_xy = _point('goal', goal)
        costs = np.ascontiguousarray(costmap.costs, dtype=np.uint8)
        cols = costmap.size_x
        start_cell = costmap.world_to_map(*start_xy)
        if start_cell is None:
            raise PlanningError(f'start is outside the map: ({start_xy[0]:.3f}, '
                                f'{start_xy[1]:.3f}) m is not in {_extent(costmap)}')
        problem = self._blocked_reason(int(costs[start_cell]))
        if problem:
            raise PlanningError(f'start is {problem} at ({start_xy[0]:.3f}, {start_xy[1]:.3f}) '
                                f'm, cell {start_cell}')
        goal_cell = costmap.world_to_map(*goal_xy)
        if goal_cell is None:
            raise PlanningError(f'goal is outside the map: ({goal_xy[0]:.3f}, '
                                f'{goal_xy[1]:.3f}) m is not in {_extent(costmap)}')
        goal_problem = self._blocked_reason(int(costs[goal_cell]))
        if goal_problem and self.tolerance <= 0.0:
            raise PlanningError(f'goal is {goal_problem} at ({goal_xy[0]:.3f}, '
                                f'{goal_xy[1]:.3f}) m, cell {goal_cell} (tolerance is 0)')
        self._prepare(costs.size)
        start_index = start_cell[0] * cols + start_cell[1]
        expansions = 0
        end_xy = goal_xy
        found = False
        if not goal_problem:
            found, count = self._search(costs, start_index, goal_cell[0] * cols + goal_cell[1])
            expansions += count
            goal_index = goal_cell[0] * cols + goal_cell[1]
        if not found:
            if self.tolerance <= 0.0:
                raise PlanningError(
                    f'no path from ({start_xy[0]:.3f}, {start_xy[1]:.3f}) to '
                    f'({goal_xy[0]:.3f}, {goal_xy[1]:.3f}) m: the goal is not reachable')
            candidates = self._candidates(costmap, goal_xy)
            if candidates.size == 0:
                reason = goal_problem or 'not reachable'
                raise PlanningError(
                    f'goal is {reason} at ({goal_xy[0]:.3f}, {goal_xy[1]:.3f}) m and no free '
                    f'cell is within tolerance {self.tolerance:g} m')
            if goal_problem:
                found, count = self._search(costs, start_index, int(candidates[0]))
                expansions += count
                goal_index = int(candidates[0])
            if not found:
                # The failed search closed exactly the cells reachable from the start.
                reachable = candidates[self._expanded(candidates)]
                if reachable.size == 0:
                    raise PlanningError(
                        f'no path from ({start_xy[0]:.3f}, {start_xy[1]:.3f}) m to within '
                        f'{self.tolerance:g} m of the goal ({goal_xy[0]:.3f}, '
                        f'{goal_xy[1]:.3f}) m: no reachable free cell there')
                goal_index = int(reachable[0])
                found, count = self._search(costs, start_index, goal_index)
                expansions += count
            end_xy = costmap.map_to_world(goal_index // cols, goal_index % cols)
        cells = grid_search.trace_back(self._parent, cols, goal_index)
        return self._finish(costmap, cells, start_xy, end_xy, float(self._g[goal_index]),
                            expansions)

    def _blocked_reason(self, cost: int) -> str:
        """Return why a cell of this cost cannot hold the robot, or '' when it can."""
        if cost == NO_INFORMATION and not self.allow_unknown:
            return 'in unknown space (allow_unknown is false)'
        if INSCRIBED_INFLATED_OBSTACLE <= cost < NO_INFORMATION:
            kind = 'lethal' if cost > INSCRIBED_INFLATED_OBSTACLE else 'inscribed'
            return f'in an obstacle (cost {cost}, {kind})'
        return ''

    def _prepare(self, size: int) -> None:
        """Make sure the work arrays fit a grid of size cells."""
        if size != self._work_size:
            self._g = np.zeros(size, dtype=np.float64)
            self._parent = np.zeros(size, dtype=np.uint8)
            self._state = np.zeros(size, dtype=np.uint8)
            self._position = np.zeros(size, dtype=np.int32)
            self._work_size = size
            self._generation = 0

    def _search(self, costs: np.ndarray, start: int, goal: int) -> Tuple[bool, int]:
        """Run A* in a fresh generation of the work arrays."""
        self._generation += 1
        if 2 * self._generation + 1 > 255:
            self._state.fill(0)
            self._generation = 1
        found, expansions = grid_search.astar(
            costs, self.allow_unknown, start, goal, self.cost_weight, self._g, self._parent,
            self._state, self._position, self._generation)
        return bool(found), int(expansions)

    def _expanded(self, cells: np.ndarray) -> np.ndarray:
        """Return a mask of the cells the last search expanded."""
        return self._state[cells] == 2 * self._generation + 1

    def _candidates(self, costmap: Costmap2D, goal_xy: Point) -> np.ndarray:
        """Return the flat indices of free cells within tolerance of the goal, nearest first."""
        res = costmap.resolution_m
        gx, gy = (goal_xy[0] - costmap.origin_x_m) / res, (goal_xy[1] - costmap.origin_y_m) / res
        reach = self.tolerance / res
        c0, c1 = max(int(math.floor(gx - reach)), 0), min(int(math.ceil(gx + reach)),
                                                          costmap.size_x - 1)
        r0, r1 = max(int(math.floor(gy - reach)), 0), min(int(math.ceil(gy + reach)),
                                                          costmap.size_y - 1)
        rows, cols = np.mgrid[r0:r1 + 1, c0:c1 + 1]
        distance = np.hypot(cols + 0.5 - gx, rows + 0.5 - gy) * res
        block = costmap.costs[r0:r1 + 1, c0:c1 + 1]
        free = block < INSCRIBED_INFLATED_OBSTACLE
        if self.allow_unknown:
            free |= block == NO_INFORMATION
        usable = free & (distance <= self.tolerance + 1e-9)
        order = np.argsort(distance[usable], kind='stable')
        flat = rows[usable] * costmap.size_x + cols[usable]
        return flat[order].astype(np.int64)

    def _finish(self, costmap: Costmap2D, cells: np.ndarray, start_xy: Point, end_xy: Point,
                cost_cells: float, expansions: int) -> Plan:
        """Shortcut, resample and smooth the A* cell path; return the Plan."""
        res = costmap.resolution_m
        cols = costmap.size_x
        rows_i, cols_i = cells // cols, cells % cols
        steps = np.hypot(np.diff(rows_i), np.diff(cols_i))
        grid_length_m = float(steps.sum()) * res
        xs = cols_i + 0.5
        ys = rows_i + 0.5
        sx, sy = costmap.world_to_grid(start_xy[0], start_xy[1])
        ex, ey = costmap.world_to_grid(end_xy[0], end_xy[1])
        if cells.size == 1:
            xs, ys = np.array([float(sx), float(ex)]), np.array([float(sy), float(ey)])
        else:
            xs[0], ys[0], xs[-1], ys[-1] = sx, sy, ex, ey
        costs = np.ascontiguousarray(costmap.costs, dtype=np.uint8)
        allow = self.allow_unknown
        caps = grid_search.edge_caps(costs, allow, xs, ys)
        keep = grid_search.shortcut(costs, allow, xs, ys, caps)
        wx, wy = xs[keep], ys[keep]
        # Cap of each shortcut segment: the worst cell of the stretch it replaced.
        segment_caps = np.array([caps[keep[i]:keep[i + 1]].max() for i in range(keep.size - 1)],
                                dtype=np.int64)
        dense_x, dense_y, dense_caps, point_caps = _resample(wx, wy, segment_caps)
        length = _length(dense_x, dense_y)
        smoothed = False
        if self.smooth_path and self.smoothing_iterations > 0 and dense_x.size > 2:
            tx, ty, ok = grid_search.smooth(costs, allow, dense_x, dense_y, point_caps,
                                            dense_caps, self.w_data, self.w_smooth,
                                            self.smoothing_iterations)
            smooth_length = _length(tx, ty)
            if ok and smooth_length <= length:
                dense_x, dense_y, length, smoothed = tx, ty, smooth_length, True
        points = [(costmap.origin_x_m + x * res, costmap.origin_y_m + y * res)
                  for x, y in zip(dense_x.tolist(), dense_y.tolist())]
        points[0], points[-1] = start_xy, end_xy
        waypoints = [(costmap.origin_x_m + x * res, costmap.origin_y_m + y * res)
                     for x, y in zip(wx.tolist(), wy.tolist())]
        return Plan(points=points, length_m=length * res, grid_length_m=grid_length_m,
                    cost=cost_cells * res, waypoints=waypoints, goal=end_xy,
                    expansions=expansions, smoothed=smoothed,
                    cells=list(zip(rows_i.tolist(), cols_i.tolist())))


def path_length(points: Sequence[Point]) -> float:
    """Return the length (m) of a polyline of (x, y) points."""
    if len(points) < 2:
        return 0.0
    array = np.asarray(points, dtype=np.float64)
    return float(np.hypot(*np.diff(array, axis=0).T).sum())


def _resample(xs: np.ndarray, ys: np.ndarray, segment_caps: np.ndarray):
    """
    Return the polyline resampled at most 1 cell apart, with the cost caps of its parts.

    Vertices are kept; segment i of the result gets the cap of the polyline segment it
    lies on, and each point the smallest cap of the segments it touches.
    """
    out_x: List[np.ndarray] = []
    out_y: List[np.ndarray] = []
    out_caps: List[np.ndarray] = []
    for i in range(xs.size - 1):
        pieces = max(1, int(math.ceil(math.hypot(xs[i + 1] - xs[i], ys[i + 1] - ys[i]))))
        t = np.arange(pieces) / pieces
        out_x.append(xs[i] + (xs[i + 1] - xs[i]) * t)
        out_y.append(ys[i] + (ys[i + 1] - ys[i]) * t)
        out_caps.append(np.full(pieces, segment_caps[i], dtype=np.int64))
    dense_x = np.concatenate(out_x + [xs[-1:]])
    dense_y = np.concatenate(out_y + [ys[-1:]])
    dense_caps = np.concatenate(out_caps)
    point_caps = np.empty(dense_x.size, dtype=np.int64)
    point_caps[0] = dense_caps[0]
    point_caps[-1] = dense_caps[-1]
    point_caps[1:-1] = np.minimum(dense_caps[:-1], dense_caps[1:])
    return dense_x, dense_y, dense_caps, point_caps


def _length(xs: np.ndarray, ys: np.ndarray) -> float:
    """Return the length of a polyline given as coordinate arrays."""
    return float(np.hypot(np.diff(xs), np.diff(ys)).sum())


def _point(name: str, value: Sequence[float]) -> Point:
    """Return value as an (x, y) float pair or raise PlanningError naming it."""
    try:
        x, y = (float(v) for v in value)
    except (TypeError, ValueError):
        raise PlanningError(f'{name} must be an (x, y) pair of numbers, not {value!r}') from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise PlanningError(f'{name} is not finite: ({x}, {y})')
    return x, y


def _extent(costmap: Costmap2D) -> str:
    """Describe the costmap's rectangle in metres."""
    return (f'x {costmap.origin_x_m:.3f}..{costmap.origin_x_m + costmap.size_x_m:.3f}, '
            f'y {costmap.origin_y_m:.3f}..{costmap.origin_y_m + costmap.size_y_m:.3f} m')


def blocked_mask(costmap: Costmap2D, allow_unknown: bool = False) -> np.ndarray:
    """Return the cells the planner treats as blocked (True) for this costmap."""
    costs = costmap.costs
    blocked = costs >= INSCRIBED_INFLATED_OBSTACLE
    if allow_unknown:
        blocked &= costs != NO_INFORMATION
    return blocked
