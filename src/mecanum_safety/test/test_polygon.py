"""Hand-worked tests of mecanum_safety.polygon (validity, crossings, inside, area)."""

from mecanum_safety.polygon import (
    point_in_polygon, points_in_polygon, polygon_edges, polygon_problem, segments_touch,
    signed_area)
import numpy as np
import pytest

# The square 0..2 x 0..2, counter-clockwise, and the same square clockwise.
SQUARE = [(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)]
SQUARE_CW = [(0.0, 0.0), (0.0, 2.0), (2.0, 2.0), (2.0, 0.0)]
# The square 0..4 without its top-right quarter 2..4 x 2..4: area 16 - 4 = 12 m^2, a reflex
# corner at (2, 2).
L_SHAPE = [(0.0, 0.0), (4.0, 0.0), (4.0, 2.0), (2.0, 2.0), (2.0, 4.0), (0.0, 4.0)]


def test_signed_area_of_a_square_by_winding():
    # Shoelace, counter-clockwise: 0.5 * (0*0 - 2*0 + 2*2 - 2*0 + 2*2 - 0*2 + 0*0 - 0*2) = 4.
    assert signed_area(SQUARE) == pytest.approx(4.0)
    assert signed_area(SQUARE_CW) == pytest.approx(-4.0)
    assert signed_area(L_SHAPE) == pytest.approx(12.0)
    assert signed_area(np.array(L_SHAPE[::-1])) == pytest.approx(-12.0)


def test_simple_polygons_have_no_problem():
    assert polygon_problem(SQUARE) is None
    assert polygon_problem(SQUARE_CW) is None
    assert polygon_problem(L_SHAPE) is None              # concave is allowed
    assert polygon_problem(np.array(L_SHAPE)) is None    # arrays as well as lists
    # A vertex in the middle of a straight side: edges 0 and 1 are collinear but go on the
    # same way ((1, 0) . (1, 0) = 1 > 0), so they do not fold back.
    assert polygon_problem([(0, 0), (1, 0), (2, 0), (2, 1), (0, 1)]) is None


@pytest.mark.parametrize('points, problem', [
    ([(0, 0), (1, 1)], 'needs at least 3 points, got 2'),
    # Repeated points: vertex 1 twice; the first vertex repeated at the end (edge 3 from
    # (0, 0) to (0, 0)).
    ([(0, 0), (1, 0), (1, 0), (1, 1)], 'has repeated consecutive points at index 1'),
    ([(0, 0), (1, 0), (1, 1), (0, 0)], 'has repeated consecutive points at index 3'),
    # Bow-tie: edge 0 (0, 0)-(2, 2) and edge 2 (2, 0)-(0, 2) cross at (1, 1); its signed
    # area is 0 (+1 - 1), but the crossing is found first.
    ([(0, 0), (2, 2), (2, 0), (0, 2)], 'is self-intersecting (edges 0 and 2 cross)'),
    # Collinear touching: vertex 3 (2, 0) lies on edge 0 (0, 0)-(4, 0).
    ([(0, 0), (4, 0), (4, 4), (2, 0), (0, 4)], 'is self-intersecting (edges 0 and 2 cross)'),
    # Fold-back: edge 1 (2, 0) -> (1, 0) runs back over edge 0 (0, 0) -> (2, 0):
    # collinear (cross 0) and opposite ((2, 0) . (-1, 0) = -2 < 0).
    ([(0, 0), (2, 0), (1, 0), (1, 1)], 'is self-intersecting (edges 0 and 1 overlap)'),
    # The same at the closing vertex: edge 3 (2, 0) -> (0, 0), then edge 0 (0, 0) -> (1, 0).
    ([(0, 0), (1, 0), (1, 1), (2, 0)], 'is self-intersecting (edges 0 and 3 overlap)'),
    # Three collinear points fold back at the closing edge (2, 0) -> (0, 0) -> (1, 0).
    ([(0, 0), (1, 0), (2, 0)], 'is self-intersecting (edges 0 and 2 overlap)'),
    # A sliver 1 m long and 1.5e-9 m high: every cross product is 1.5e-9 > EPS (no
    # fold-back) but the area 0.5 * 1 * 1.5e-9 = 7.5e-10 m^2 <= EPS.
    ([(0, 0), (1, 0), (0.5, 1.5e-9)], 'has zero area'),
])
def test_polygon_problems_by_hand(points, problem):
    assert polygon_problem(points) == problem


@pytest.mark.parametrize('p1, p2, q1, q2, touch', [
    ((0, 0), (2, 2), (2, 0), (0, 2), True),     # proper crossing at (1, 1)
    ((0, 0), (2, 0), (1, 0), (1, 1), True),     # T: q1 on p1-p2
    ((0, 0), (1, 0), (1, 0), (1, 1), True),     # shared end point
    ((0, 0), (2, 0), (1, 0), (3, 0), True),     # collinear, overlapping on 1..2
    ((0, 0), (1, 0), (2, 0), (3, 0), False),    # collinear, 1 m apart
    ((0, 0), (1, 0), (0, 1), (1, 1), False),    # parallel
    ((0, 0), (2, 0), (1, 0.5), (1, 2), False),  # would cross if q were longer
])
def test_segments_touch_by_hand(p1, p2, q1, q2, touch):
    assert segments_touch(p1, p2, q1, q2) is touch
    assert segments_touch(q1, q2, p1, p2) is touch
    assert segments_touch(p2, p1, q2, q1) is touch


def test_polygon_edges_close_the_polygon():
    assert polygon_edges(SQUARE).tolist() == [
        [0, 0, 2, 0], [2, 0, 2, 2], [2, 2, 0, 2], [0, 2, 0, 0]]


@pytest.mark.parametrize('x, y, inside', [
    (3.0, 1.0, True), (1.0, 3.0, True), (1.0, 1.0, True),   # both arms and the corner
    (3.0, 3.0, False),                                      # the notch
    (5.0, 1.0, False), (-0.5, 1.0, False), (1.0, 4.5, False),
])
def test_points_in_a_concave_polygon(x, y, inside):
    polygon = np.array(L_SHAPE)
    assert points_in_polygon(np.array([x]), np.array([y]), polygon).tolist() == [inside]
    assert point_in_polygon(x, y, polygon) is inside


@pytest.mark.parametrize('x, y, inside', [
    (0.0, 1.0, True), (1.0, 0.0, True), (0.0, 0.0, True),     # left, bottom edge; corner
    (2.0, 1.0, False), (1.0, 2.0, False),                     # right, top edge
    (2.0, 0.0, False), (0.0, 2.0, False), (2.0, 2.0, False),  # the other corners
])
def test_points_on_the_border_follow_the_half_open_rule(x, y, inside):
    # Of the square [0, 2] x [0, 2], exactly [0, 2) x [0, 2) is inside, in either winding.
    for polygon in (np.array(SQUARE), np.array(SQUARE_CW)):
        assert points_in_polygon(np.array([x]), np.array([y]), polygon).tolist() == [inside]
        assert point_in_polygon(x, y, polygon) is inside


def test_points_in_polygon_keeps_the_shape_of_the_points():
    xs = np.array([[1.0, 3.0, 1.0], [3.0, 5.0, 0.5]])
    ys = np.array([[1.0, 3.0, 3.0], [1.0, 1.0, 0.5]])
    inside = points_in_polygon(xs, ys, np.array(L_SHAPE))
    assert inside.shape == (2, 3)
    assert inside.tolist() == [[True, False, True], [True, False, True]]
