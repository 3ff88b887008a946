"""
Planar polygons: the one copy of the validity, crossing and inside checks (pure, numpy only).

Conventions shared by every function here:

* A polygon is a sequence of (x, y) vertices in metres in one planar frame (the map frame
  for the authorised zone, the world frame for the simulator's furniture; REP-103: x
  east/forward, y north/left). It is closed implicitly: the last vertex joins the first,
  so do not repeat the first vertex at the end. Edge i runs from vertex i to vertex i + 1
  (the last edge from the last vertex back to vertex 0).
* Either winding is accepted; :func:`signed_area` is positive for counter-clockwise
  vertices (the order callers store) and negative for clockwise ones.
* Two segments *touch* when they share any point: a proper crossing, an end point lying
  on the other segment, a shared end point, or a collinear overlap.
* Lengths, cross products and areas within :data:`EPS` (m, m^2) of zero count as zero.

The checks are a few loops of float arithmetic; shapely (``Polygon.is_valid``) would do the
validation but is not a dependency of this workspace, so it is not used.
"""

import math
from typing import Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike

Point = Tuple[float, float]

#: Lengths (m), cross products and areas (m^2) at most this far from zero count as zero.
EPS = 1e-9


def polygon_problem(points: Sequence[Point]) -> Optional[str]:
    """
    Return why points do not form a simple polygon, or None when they do.

    points: the (x, y) vertices in m, either winding, closed implicitly. Refused, in this
    order: fewer than 3 points; two consecutive points (the last and the first included)
    closer than EPS; two adjacent edges that fold back onto each other (collinear and
    reversed: 'edges i and j overlap'); two non-adjacent edges that touch ('edges i and j
    cross', which includes a vertex lying on another edge); zero area. The message is
    the end of a sentence about the polygon, e.g. 'is self-intersecting (edges 0 and 2
    cross)'.
    """
    count = len(points)
    if count < 3:
        return f'needs at least 3 points, got {count}'
    for index in range(count):
        if math.dist(points[index], points[(index + 1) % count]) <= EPS:
            return f'has repeated consecutive points at index {index}'
    edges = [(points[i], points[(i + 1) % count]) for i in range(count)]
    for i in range(count):
        for j in range(i + 1, count):
            if j == i + 1 or (i == 0 and j == count - 1):   # neighbours share a vertex
                first, second = (edges[i], edges[j]) if j == i + 1 else (edges[j], edges[i])
                if _folds_back(first, second):
                    return f'is self-intersecting (edges {i} and {j} overlap)'
            elif segments_touch(*edges[i], *edges[j]):
                return f'is self-intersecting (edges {i} and {j} cross)'
    if abs(signed_area(points)) <= EPS:
        return 'has zero area'
    return None


def signed_area(points: Sequence[Point]) -> float:
    """Return the shoelace area (m^2) of a closed polygon: positive when counter-clockwise."""
    array = np.asarray(points, dtype=np.float64)
    x, y = array[:, 0], array[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def polygon_edges(polygon: ArrayLike) -> np.ndarray:
    """Return the (N, 4) edges x1, y1, x2, y2 (m) of a closed polygon of N vertices."""
    points = np.asarray(polygon, dtype=np.float64).reshape(-1, 2)
    return np.hstack((points, np.roll(points, -1, axis=0)))


def segments_touch(p1: Point, p2: Point, q1: Point, q2: Point) -> bool:
    """
    Return whether segments p1-p2 and q1-q2 (m) touch: share at least one point.

    True for a proper crossing, an end point on the other segment (within EPS), a shared
    end point and a collinear overlap; False for disjoint segments, collinear ones
    included.
    """
    d1, d2 = _cross(q1, q2, p1), _cross(q1, q2, p2)
    d3, d4 = _cross(p1, p2, q1), _cross(p1, p2, q2)
    if ((d1 > EPS and d2 < -EPS) or (d1 < -EPS and d2 > EPS)) and \
            ((d3 > EPS and d4 < -EPS) or (d3 < -EPS and d4 > EPS)):
        return True
    return ((abs(d1) <= EPS and _on_segment(q1, q2, p1))
            or (abs(d2) <= EPS and _on_segment(q1, q2, p2))
            or (abs(d3) <= EPS and _on_segment(p1, p2, q1))
            or (abs(d4) <= EPS and _on_segment(p1, p2, q2)))


def points_in_polygon(xs: np.ndarray, ys: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """
    Return a bool array shaped like xs: which points (xs, ys) are inside polygon.

    polygon: (N, 2) vertices in the points' frame (m), either winding, closed implicitly;
    it may be concave. Even-odd rule on a ray towards +x. A point exactly on the border
    is decided by a half-open rule: of the rectangle [x0, x1] x [y0, y1], the points of
    [x0, x1) x [y0, y1) are inside: the bottom and left edges in, the top and right ones
    out.
    """
    inside = np.zeros(np.shape(xs), dtype=bool)
    x2, y2 = polygon[-1]
    for x1, y1 in polygon:
        if y1 != y2:
            crosses = (y1 > ys) != (y2 > ys)
            x_cross = x1 + (ys - y1) * (x2 - x1) / (y2 - y1)
            inside ^= crosses & (xs < x_cross)
        x2, y2 = x1, y1
    return inside


def point_in_polygon(x: float, y: float, polygon: np.ndarray) -> bool:
    """Return whether one point (m) is inside polygon: points_in_polygon without arrays."""
    inside = False
    x2, y2 = polygon[-1]
    for x1, y1 in polygon:
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
        x2, y2 = x1, y1
    return inside


def _cross(o: Point, a: Point, b: Point) -> float:
    """Return the z component (m^2) of (a - o) x (b - o): > 0 when o, a, b turn left."""
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _on_segment(p: Point, q: Point, r: Point) -> bool:
    """Return whether r, known collinear with p-q, lies within the segment's box (+ EPS)."""
    return (min(p[0], q[0]) - EPS <= r[0] <= max(p[0], q[0]) + EPS
            and min(p[1], q[1]) - EPS <= r[1] <= max(p[1], q[1]) + EPS)


def _folds_back(first: Tuple[Point, Point], second: Tuple[Point, Point]) -> bool:
    """Return whether consecutive edges a -> b -> c are collinear and c heads back to a."""
    (a, b), (_, c) = first, second
    if abs(_cross(a, b, c)) > EPS:
        return False
    return (b[0] - a[0]) * (c[0] - b[0]) + (b[1] - a[1]) * (c[1] - b[1]) < 0.0
