"""
Compiled inner loops of the costmaps and the global planner (numba, pure, no ROS).

These kernels are the parts numpy cannot vectorise: the exact Euclidean distance
transform behind inflation, Bresenham raytracing, A* with a binary heap, and the
segment checks of path shortcutting and smoothing. They work on a costmap's uint8
``costs`` array (shape (rows, cols), row 0 the BOTTOM row, as in OccupancyGrid) in cell
units; costmap.py and planner.py hold the conventions, validation and units.

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
SQRT2 = math.sqrt(2.0)
#: Two crossing times closer than this (in units of the segment) are one corner crossing.
CORNER_EPS = 1e-9

# Row, column offsets of the 8 neighbours: 4 straight moves, then 4 diagonals.
_DROWS = np.array([1, -1, 0, 0, 1, 1, -1, -1], dtype=np.int64)
_DCOLS = np.array([0, 0, 1, -1, 1, -1, 1, -1], dtype=np.int64)
# For each diagonal k (4..7), the two straight moves whose cells it passes by.
_SIDE_A = np.array([0, 0, 0, 0, 0, 0, 1, 1], dtype=np.int64)
_SIDE_B = np.array([0, 0, 0, 0, 2, 3, 2, 3], dtype=np.int64)


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
def astar(costs, allow_unknown, start, goal, cost_weight, g, parent, state, position,
          generation):
    """
    Search the cheapest path from cell index start to goal (row * cols + col) with A*.

    A step to a neighbour costs its length (1 or sqrt 2 cells) times
    (1 + cost_weight * planning_cost(neighbour) / 252); a diagonal step needs both cells
    it passes by to be free (no corner cutting). The heuristic is the octile distance,
    admissible and consistent for these costs, so a cell's g is final when it is
    expanded. Ties in f go to the smaller heuristic. The open list is a binary heap
    with decrease-key (position[cell] is the cell's place in it).
    g (float64), parent, state (uint8) and position (int32) are flat work arrays of the
    grid's size kept between calls: in this call a cell has been reached (g, parent
    and position valid) when state[cell] == 2 * generation and expanded when it is
    2 * generation + 1 (generation 1..127), so nothing needs clearing per call; parent
    holds the move (0..7, an index of _DROWS/_DCOLS) that reached the cell, 255 at the
    start. Returns (found, expansions); after a failure, the expanded cells are
    exactly the start's reachable region.
    """
    rows, cols = costs.shape
    flat = costs.reshape(rows * cols)
    reached = np.uint8(2 * generation)
    expanded = np.uint8(2 * generation + 1)
    goal_r, goal_c = goal // cols, goal % cols
    # Each cell is in the heap at most once: room for all (pages untouched stay free).
    heap_f = np.empty(rows * cols, dtype=np.float64)
    heap_h = np.empty(rows * cols, dtype=np.float64)
    heap_n = np.empty(rows * cols, dtype=np.int32)
    g[start] = 0.0
    parent[start] = 255
    state[start] = reached
    h0 = _octile(start // cols, start % cols, goal_r, goal_c)
    heap_f[0], heap_h[0], heap_n[0] = h0, h0, start
    position[start] = 0
    size = 1
    expansions = 0
    weight = cost_weight / MAX_FREE
    free = np.empty(8, dtype=np.bool_)
    step_cost = np.empty(8, dtype=np.float64)
    while size > 0:
        node = heap_n[0]
        # Pop the root: move the last entry to the top and sift it down.
        size -= 1
        if size > 0:
            f, h, n = heap_f[size], heap_h[size], heap_n[size]
            i = 0
            while True:
                child = 2 * i + 1
                if child >= size:
                    break
                other = child + 1
                if other < size and (heap_f[other] < heap_f[child] or (
                        heap_f[other] == heap_f[child] and heap_h[other] < heap_h[child])):
                    child = other
                if heap_f[child] < f or (heap_f[child] == f and heap_h[child] < h):
                    heap_f[i], heap_h[i], heap_n[i] = heap_f[child], heap_h[child], heap_n[child]
                    position[heap_n[i]] = i
                    i = child
                else:
                    break
            heap_f[i], heap_h[i], heap_n[i] = f, h, n
            position[n] = i
        state[node] = expanded
        expansions += 1
        if node == goal:
            return True, expansions
        r = node // cols
        c = node - r * cols
        # Straight neighbours first: the diagonals need both cells they pass by free.
        for k in range(4):
            nr, nc = r + _DROWS[k], c + _DCOLS[k]
            free[k] = False
            if 0 <= nr < rows and 0 <= nc < cols:
                cost = planning_cost(flat[nr * cols + nc], allow_unknown)
                if cost != BLOCKED:
                    free[k] = True
                    step_cost[k] = 1.0 + weight * cost
        for k in range(4, 8):
            free[k] = False
            if free[_SIDE_A[k]] and free[_SIDE_B[k]]:
                cost = planning_cost(flat[(r + _DROWS[k]) * cols + c + _DCOLS[k]],
                                     allow_unknown)
                if cost != BLOCKED:
                    free[k] = True
                    step_cost[k] = SQRT2 * (1.0 + weight * cost)
        g_node = g[node]
        for k in range(8):
            if not free[k]:
                continue
            nr, nc = r + _DROWS[k], c + _DCOLS[k]
            neighbour = nr * cols + nc
            mark = state[neighbour]
            if mark == expanded:
                continue
            tentative = g_node + step_cost[k]
            if mark == reached:
                if tentative >= g[neighbour]:
                    continue
                i = position[neighbour]   # decrease-key: sift up from its place
            else:
                state[neighbour] = reached
                i = size
                size += 1
            g[neighbour] = tentative
            parent[neighbour] = k
            h = _octile(nr, nc, goal_r, goal_c)
            f = tentative + h
            while i > 0:
                up = (i - 1) // 2
                if f < heap_f[up] or (f == heap_f[up] and h < heap_h[up]):
                    heap_f[i], heap_h[i], heap_n[i] = heap_f[up], heap_h[up], heap_n[up]
                    position[heap_n[i]] = i
                    i = up
                else:
                    break
            heap_f[i], heap_h[i], heap_n[i] = f, h, neighbour
            position[neighbour] = i
    return False, expansions


@njit(cache=True)
def _octile(r, c, goal_r, goal_c):
    """Return the octile distance (cells) between two cells."""
    dr = abs(r - goal_r)
    dc = abs(c - goal_c)
    if dr > dc:
        return (dr - dc) + SQRT2 * dc
    return (dc - dr) + SQRT2 * dr


@njit(cache=True)
def trace_back(parent, cols, goal):
    """Return the cell indices of the path astar found to goal, start first."""
    count = 1
    node = goal
    while parent[node] != 255:
        k = parent[node]
        node -= _DROWS[k] * cols + _DCOLS[k]
        count += 1
    path = np.empty(count, dtype=np.int64)
    node = goal
    for i in range(count - 1, -1, -1):
        path[i] = node
        if i > 0:
            k = parent[node]
            node -= _DROWS[k] * cols + _DCOLS[k]
    return path


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


@njit(cache=True)
def edge_caps(costs, allow_unknown, xs, ys):
    """Return segment_cost of each segment (xs[i], ys[i]) -> (xs[i+1], ys[i+1])."""
    caps = np.empty(xs.shape[0] - 1, dtype=np.int64)
    for i in range(xs.shape[0] - 1):
        caps[i] = segment_cost(costs, allow_unknown, xs[i], ys[i], xs[i + 1], ys[i + 1])
    return caps


@njit(cache=True)
def shortcut(costs, allow_unknown, xs, ys, caps):
    """
    Return the indices of the vertices kept by greedy line-of-sight shortcutting.

    From each kept vertex i the path jumps to the furthest vertex j reached by
    extending j one at a time while the straight segment i -> j crosses no cell of a
    higher planning cost than the path it replaces (the largest caps[i..j-1]) and no
    blocked cell; the first failure ends the extension. By the triangle inequality the
    result is never longer than the input.
    """
    n = xs.shape[0]
    keep = np.empty(n, dtype=np.int64)
    keep[0] = 0
    count = 1
    i = 0
    while i < n - 1:
        best = i + 1
        allowed = caps[i]
        for j in range(i + 2, n):
            if caps[j - 1] > allowed:
                allowed = caps[j - 1]
            cost = segment_cost(costs, allow_unknown, xs[i], ys[i], xs[j], ys[j])
            if cost == BLOCKED or cost > allowed:
                break
            best = j
        keep[count] = best
        count += 1
        i = best
    return keep[:count]


@njit(cache=True)
def smooth(costs, allow_unknown, xs, ys, point_caps, segment_caps, w_data, w_smooth,
           iterations):
    """
    Gently smooth a dense path; return (xs, ys, ok) of the smoothed copy.

    Gauss-Seidel iterations of y_i += w_data (x_i - y_i) + w_smooth (y_(i-1) + y_(i+1) -
    2 y_i) with the end points fixed (the update of Nav2's simple smoother). A moved
    point stays where it was when its cell costs more than point_caps[i], or a segment
    to a neighbour, i -> i+1, would cross a cell costing more than segment_caps[i] (or
    a blocked cell). ok is False when a final check of every segment fails (it should
    not): the caller then keeps the unsmoothed path.
    """
    n = xs.shape[0]
    sx = xs.copy()
    sy = ys.copy()
    for _ in range(iterations):
        for i in range(1, n - 1):
            nx = sx[i] + w_data * (xs[i] - sx[i]) + w_smooth * (sx[i - 1] + sx[i + 1] - 2 * sx[i])
            ny = sy[i] + w_data * (ys[i] - sy[i]) + w_smooth * (sy[i - 1] + sy[i + 1] - 2 * sy[i])
            cost = _cell_cost(costs, int(math.floor(ny)), int(math.floor(nx)), allow_unknown)
            if cost == BLOCKED or cost > point_caps[i]:
                continue
            cost = segment_cost(costs, allow_unknown, sx[i - 1], sy[i - 1], nx, ny)
            if cost == BLOCKED or cost > segment_caps[i - 1]:
                continue
            cost = segment_cost(costs, allow_unknown, nx, ny, sx[i + 1], sy[i + 1])
            if cost == BLOCKED or cost > segment_caps[i]:
                continue
            sx[i] = nx
            sy[i] = ny
    for i in range(n - 1):
        cost = segment_cost(costs, allow_unknown, sx[i], sy[i], sx[i + 1], sy[i + 1])
        if cost == BLOCKED or cost > segment_caps[i]:
            return sx, sy, False
    return sx, sy, True
