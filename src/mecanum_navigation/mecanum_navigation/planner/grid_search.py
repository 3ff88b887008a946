"""
Compiled inner loops of the global planner (numba, pure, no ROS): A* and smoothing.

A* with a binary heap over the 8-connected grid, and the shortcutting and smoothing of
its path, on a costmap's uint8 ``costs`` array in cell units (conventions, planning cost
and segment checks: :mod:`mecanum_navigation.costmap.kernels`); planner.py holds the
validation and units.
"""

import math

from mecanum_navigation.costmap.kernels import (
    _cell_cost, BLOCKED, MAX_FREE, planning_cost, segment_cost)
from numba import njit
import numpy as np

SQRT2 = math.sqrt(2.0)

# Row, column offsets of the 8 neighbours: 4 straight moves, then 4 diagonals.
_DROWS = np.array([1, -1, 0, 0, 1, 1, -1, -1], dtype=np.int64)
_DCOLS = np.array([0, 0, 1, -1, 1, -1, 1, -1], dtype=np.int64)
# For each diagonal k (4..7), the two straight moves whose cells it passes by.
_SIDE_A = np.array([0, 0, 0, 0, 0, 0, 1, 1], dtype=np.int64)
_SIDE_B = np.array([0, 0, 0, 0, 2, 3, 2, 3], dtype=np.int64)


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
