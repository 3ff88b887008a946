"""
Compiled inner loops of the costmaps (numba, pure, no ROS).

The parts numpy cannot vectorise: the exact Euclidean distance transform behind
inflation, Bresenham raytracing, and the traversal cost of cells and segments that the
planner (:mod:`mecanum_navigation.planner.grid_search`) and the local controller share.
They work on a costmap's uint8 ``costs`` array (shape (rows, cols), row 0 the BOTTOM
row, as in OccupancyGrid) in cell units; costmap_2d.py holds the conventions,
validation and units.

Continuous cell coordinates: a point (x, y) in cell units lies in cell
(row = floor(y), col = floor(x)); cell (r, c) covers [c, c + 1) x [r, r + 1) and its
centre is (c + 0.5, r + 0.5).

Traversal cost of a cell for the planner ("planning cost", 0..252, or BLOCKED): costs
>= 253 (inscribed, lethal) are blocked; NO_INFORMATION (255) is blocked, or counts as
252 (the most expensive free cost) when unknown space is allowed.
"""

import math

from numba import njit
import numpy as np

#: Planning cost of a blocked cell (and of anything outside the grid).
BLOCKED = 255
LETHAL = 254
INSCRIBED = 253
NO_INFORMATION = 255
MAX_FREE = 252
#: Two crossing times closer than this (in units of the segment) are one corner crossing.
CORNER_EPS = 1e-9


@njit(cache=True)
def inflate(costs, lut, inflate_unknown):
    """
    Inflate `costs` in place around its LETHAL cells; lut[d2] is the cost at d2 cells^2.

    d2 is the exact squared Euclidean distance (cells^2, centre to centre) to the nearest
    LETHAL cell; cells with d2 >= len(lut) get no cost. A cell keeps the larger of its
    cost and the inflated one, except NO_INFORMATION, which takes the inflated cost only
    when it is >= INSCRIBED (or > 0 when inflate_unknown), as Nav2's inflation layer does.
    Column distances are capped at cap = ceil(sqrt(len(lut))) cells: capping never turns
    a distance beyond the lut into one inside it (see costmap.InflationLayer).
    """
    rows, cols = costs.shape
    size = lut.shape[0]
    cap = 1
    while cap * cap < size:
        cap += 1
    # Vertical distance (cells, capped) to the nearest lethal cell in the same column,
    # swept over whole rows for cache-friendly access.
    vertical = np.empty((rows, cols), dtype=np.int32)
    for c in range(cols):
        vertical[0, c] = 0 if costs[0, c] == LETHAL else cap
    for r in range(1, rows):
        for c in range(cols):
            if costs[r, c] == LETHAL:
                vertical[r, c] = 0
            else:
                v = vertical[r - 1, c] + 1
                vertical[r, c] = v if v < cap else cap
    for r in range(rows - 2, -1, -1):
        for c in range(cols):
            v = vertical[r + 1, c] + 1
            if v < vertical[r, c]:
                vertical[r, c] = v
    # Per row: lower envelope of the parabolas (c - q)^2 + vertical[q]^2 (Felzenszwalb &
    # Huttenlocher's 1-D squared distance transform), then the cost of each cell.
    hull = np.empty(cols, dtype=np.int64)
    bounds = np.empty(cols + 1, dtype=np.float64)
    for r in range(rows):
        near = False
        for c in range(cols):
            if vertical[r, c] < cap:
                near = True
                break
        if not near:
            continue
        k = 0
        hull[0] = 0
        bounds[0] = -np.inf
        bounds[1] = np.inf
        for q in range(1, cols):
            fq = float(vertical[r, q]) ** 2 + q * q
            while True:
                p = hull[k]
                s = (fq - (float(vertical[r, p]) ** 2 + p * p)) / (2.0 * (q - p))
                if s > bounds[k]:
                    break
                k -= 1  # never below 0: bounds[0] is -inf
            k += 1
            hull[k] = q
            bounds[k] = s
            bounds[k + 1] = np.inf
        k = 0
        for c in range(cols):
            while bounds[k + 1] < c:
                k += 1
            p = hull[k]
            d2 = (c - p) * (c - p) + int(vertical[r, p]) * int(vertical[r, p])
            if d2 >= size:
                continue
            cost = lut[d2]
            old = costs[r, c]
            if old == NO_INFORMATION:
                if cost >= INSCRIBED or (inflate_unknown and cost > 0):
                    costs[r, c] = cost
            elif cost > old:
                costs[r, c] = cost


@njit(cache=True)
def raytrace(grid, rows0, cols0, rows1, cols1, value):
    """
    Set to `value` every cell of the Bresenham lines (row0, col0) -> (row1, col1).

    Both end cells are included; every end cell must be inside `grid`.
    """
    for i in range(rows0.shape[0]):
        r, c = rows0[i], cols0[i]
        dr, dc = rows1[i] - r, cols1[i] - c
        step_r = 1 if dr > 0 else -1
        step_c = 1 if dc > 0 else -1
        dr, dc = abs(dr), abs(dc)
        if dc >= dr:
            error = dc // 2
            for _ in range(dc):
                grid[r, c] = value
                c += step_c
                error -= dr
                if error < 0:
                    r += step_r
                    error += dc
        else:
            error = dr // 2
            for _ in range(dr):
                grid[r, c] = value
                r += step_r
                error -= dc
                if error < 0:
                    c += step_c
                    error += dr
        grid[r, c] = value


@njit(cache=True)
def planning_cost(cost, allow_unknown):
    """Return the planning cost (0..252) of a costmap cost, or BLOCKED."""
    if cost < INSCRIBED:
        return cost
    if cost == NO_INFORMATION and allow_unknown:
        return MAX_FREE
    return BLOCKED


@njit(cache=True)
def _cell_cost(costs, r, c, allow_unknown):
    """Return the planning cost of cell (r, c), BLOCKED outside the grid."""
    if r < 0 or c < 0 or r >= costs.shape[0] or c >= costs.shape[1]:
        return BLOCKED
    return planning_cost(costs[r, c], allow_unknown)


@njit(cache=True)
def segment_cost(costs, allow_unknown, x0, y0, x1, y1):
    """
    Return the highest planning cost of the cells a segment passes through (BLOCKED max).

    (x0, y0), (x1, y1) are in continuous cell coordinates (x along columns). The cells
    are a supercover: where the segment crosses a cell corner exactly, both cells beside
    the corner count, and a segment lying on a grid line counts the cells on both sides.
    A segment leaving the grid is BLOCKED.
    """
    if x0 == x1 and x0 == math.floor(x0):
        return max(_walk(costs, allow_unknown, x0 - 1e-9, y0, x1 - 1e-9, y1),
                   _walk(costs, allow_unknown, x0 + 1e-9, y0, x1 + 1e-9, y1))
    if y0 == y1 and y0 == math.floor(y0):
        return max(_walk(costs, allow_unknown, x0, y0 - 1e-9, x1, y1 - 1e-9),
                   _walk(costs, allow_unknown, x0, y0 + 1e-9, x1, y1 + 1e-9))
    return _walk(costs, allow_unknown, x0, y0, x1, y1)


@njit(cache=True)
def _walk(costs, allow_unknown, x0, y0, x1, y1):
    """Return the highest planning cost along a segment (Amanatides-Woo traversal)."""
    c, r = int(math.floor(x0)), int(math.floor(y0))
    c_end, r_end = int(math.floor(x1)), int(math.floor(y1))
    worst = _cell_cost(costs, r, c, allow_unknown)
    if worst == BLOCKED:
        return BLOCKED
    dx, dy = x1 - x0, y1 - y0
    step_c = 1 if dx > 0 else -1
    step_r = 1 if dy > 0 else -1
    if dx != 0.0:
        delta_x = 1.0 / abs(dx)
        next_x = ((c + 1 - x0) if dx > 0 else (x0 - c)) * delta_x
    else:
        delta_x = np.inf
        next_x = np.inf
    if dy != 0.0:
        delta_y = 1.0 / abs(dy)
        next_y = ((r + 1 - y0) if dy > 0 else (y0 - r)) * delta_y
    else:
        delta_y = np.inf
        next_y = np.inf
    steps = abs(c_end - c) + abs(r_end - r) + 2
    for _ in range(steps):
        if (r == r_end and c == c_end) or (next_x > 1.0 and next_y > 1.0):
            break
        if abs(next_x - next_y) <= CORNER_EPS:
            # Through a corner: both side cells count, then the diagonal one.
            side = max(_cell_cost(costs, r, c + step_c, allow_unknown),
                       _cell_cost(costs, r + step_r, c, allow_unknown))
            if side > worst:
                worst = side
            c += step_c
            r += step_r
            next_x += delta_x
            next_y += delta_y
        elif next_x < next_y:
            c += step_c
            next_x += delta_x
        else:
            r += step_r
            next_y += delta_y
        cost = _cell_cost(costs, r, c, allow_unknown)
        if cost > worst:
            worst = cost
        if worst == BLOCKED:
            return BLOCKED
    return worst
