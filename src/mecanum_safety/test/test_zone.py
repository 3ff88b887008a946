"""Hand-worked tests of mecanum_safety.zone (the authorised zone)."""

import math

from mecanum_safety.polygon import polygon_problem, signed_area
from mecanum_safety.zone import (
    load_zone_file, make_zone, parse_zone, Zone, zone_file_text, ZoneError)
import numpy as np
import pytest

# An L (the square 0..4 without its top-right quarter 2..4 x 2..4: a reflex corner at
# (2, 2)) with a square hole 0.5..1.5 in its bottom-left part.
L_SHAPE = [(0.0, 0.0), (4.0, 0.0), (4.0, 2.0), (2.0, 2.0), (2.0, 4.0), (0.0, 4.0)]
HOLE = [(0.5, 0.5), (1.5, 0.5), (1.5, 1.5), (0.5, 1.5)]
ZONE = make_zone(L_SHAPE, [HOLE])


@pytest.mark.parametrize('point, inside, clearance', [
    ((3.0, 1.0), True, 1.0),                  # lower arm: 1 m to the bottom, right, notch
    ((1.0, 3.0), True, 1.0),                  # upper arm: 1 m to the left, top, notch
    ((0.2, 1.0), True, 0.2),                  # between the left border and the hole
    ((1.0, 1.8), True, 0.3),                  # 0.3 m above the hole
    ((1.9, 1.9), True, 0.1 * math.sqrt(2)),   # near the reflex corner: its distance
    ((1.0, 1.0), False, -0.5),                # the hole's centre
    ((1.2, 0.7), False, -0.2),                # in the hole, 0.2 m from its bottom edge
    ((3.0, 3.0), False, -1.0),                # in the notch: 1 m to both notch edges
    ((2.5, 2.5), False, -0.5),
    ((-1.0, -1.0), False, -math.sqrt(2)),     # outside, nearest the corner (0, 0)
    ((5.0, 1.0), False, -1.0),
])
def test_contains_and_clearance_by_hand(point, inside, clearance):
    x, y = point
    assert bool(ZONE.contains(np.array([x]), np.array([y]))[0]) is inside
    assert ZONE.contains_point(x, y) is inside
    assert ZONE.clearance(np.array([x]), np.array([y]))[0] == pytest.approx(
        clearance, abs=1e-12)


def test_clearance_is_vectorised_and_zero_on_the_border():
    xs = np.array([[3.0, 4.0], [2.0, 1.5]])
    ys = np.array([[1.0, 1.0], [3.0, 1.0]])
    clearance = ZONE.clearance(xs, ys)
    assert clearance.shape == (2, 2)
    assert clearance[0, 0] == pytest.approx(1.0)
    assert clearance[0, 1] == 0.0 and clearance[1, 0] == 0.0 and clearance[1, 1] == 0.0


def test_footprint_inside_is_clearance_at_least_the_radius():
    assert ZONE.footprint_inside(3.0, 1.0, 1.0)
    assert not ZONE.footprint_inside(3.0, 1.0, 1.01)
    assert ZONE.footprint_inside(0.2, 1.0, 0.2)
    assert not ZONE.footprint_inside(1.0, 1.0, 0.1)   # in the hole


def test_polygons_are_counter_clockwise_and_edges_close_them():
    clockwise = make_zone(list(reversed(L_SHAPE)), [list(reversed(HOLE))])
    assert signed_area(clockwise.include.tolist()) == pytest.approx(12.0)
    assert signed_area(clockwise.exclude[0].tolist()) == pytest.approx(1.0)
    assert clockwise == ZONE and hash(clockwise) == hash(ZONE)
    edges = ZONE.edges()
    assert edges.shape == (6 + 4, 4)
    assert edges[5].tolist() == [0.0, 4.0, 0.0, 0.0]    # the inclusion's closing edge
    assert edges[9].tolist() == [0.5, 1.5, 0.5, 0.5]    # the hole's


def test_the_three_forms_parse_to_the_same_zone_and_round_trip(tmp_path):
    full = parse_zone({'frame_id': 'map', 'include': [list(p) for p in L_SHAPE],
                       'exclude': [[list(p) for p in HOLE]]})
    assert full == ZONE
    short = parse_zone([list(p) for p in L_SHAPE])
    assert short == make_zone(L_SHAPE) and short.exclude == ()
    assert parse_zone(None) is None and parse_zone([]) is None
    path = tmp_path / 'zone.yaml'
    path.write_text(zone_file_text(ZONE))
    assert load_zone_file(path) == ZONE
    path.write_text(zone_file_text(None))
    assert load_zone_file(path) is None
    path.write_text('authorised_zone:\n')
    assert load_zone_file(path) is None
    assert ZONE.to_document()['exclude'] == [[list(p) for p in HOLE]]
    assert isinstance(ZONE, Zone) and ZONE != 'zone'


@pytest.mark.parametrize('raw, message', [
    (42, r'^here: must be a list of \[x, y\] points or a mapping with include'),
    ({'include': L_SHAPE, 'holes': []}, r'^here: unknown key\(s\) holes \(expected include'),
    ({'exclude': []}, r'^here: include \(the inclusion polygon\) is required'),
    ({'include': L_SHAPE, 'exclude': 'none'}, r'^here\.exclude: must be a list of polygons'),
    ({'include': L_SHAPE, 'frame_id': 'odom'},
     r"^here\.frame_id: only the map frame is supported, not 'odom'"),
    ({'include': 'square'}, r'^here\.include: must be a list of \[x, y\] points'),
    ({'include': [[0, 0], [1, 0, 0], [1, 1]]},
     r'^here\.include\[1\]: must be an \[x, y\] pair of numbers'),
    ({'include': [[0, 0], [1, 0], [True, 1]]},
     r'^here\.include\[2\]: must be an \[x, y\] pair of numbers'),
    ({'include': [[0, 0], [1, 0], ['1', 1]]},
     r'^here\.include\[2\]: must be an \[x, y\] pair of numbers'),
    ({'include': [[0, 0], [1, 0], [1, float('nan')]]},
     r'^here\.include\[2\]: coordinates must be finite'),
    ({'include': [[0, 0], [1, 0]]}, r'^here\.include: the polygon needs at least 3 points, '
                                    r'got 2'),
    ({'include': [[0, 0], [1, 0], [1, 0], [1, 1]]},
     r'^here\.include: the polygon has repeated consecutive points at index 1'),
    ({'include': [[0, 0], [1, 1], [1, 0], [0, 1]]},
     r'^here\.include: the polygon is self-intersecting \(edges 0 and 2 cross\)'),
    # Three collinear points: the closing edge (2, 0) -> (0, 0) runs back over edge 0.
    ({'include': [[0, 0], [1, 0], [2, 0]]},
     r'^here\.include: the polygon is self-intersecting \(edges 0 and 2 overlap\)'),
    ({'include': L_SHAPE, 'exclude': [[[1, 1], [3, 1], [3, 3]]]},
     r'^here\.exclude\[0\]: vertex 2 is outside the inclusion polygon'),
    # Every vertex in the L, but an edge across its notch (through (2.5, 2.5)).
    ({'include': L_SHAPE, 'exclude': [[[1.5, 3.5], [1, 1], [3.5, 1.5]]]},
     r'^here\.exclude\[0\]: edge 2 crosses edge 2 of the inclusion polygon'),
    # Touching the inclusion's border counts as crossing it.
    ({'include': L_SHAPE, 'exclude': [[[1, 0], [2, 0.5], [1, 0.5]]]},
     r'^here\.exclude\[0\]: edge 0 crosses edge 0 of the inclusion polygon'),
    ({'include': L_SHAPE, 'exclude': [[[1, 1], [1.5, 1]]]},
     r'^here\.exclude\[0\]: the polygon needs at least 3 points'),
    ([[0, 0], [1, 0]], r'^here: the polygon needs at least 3 points'),
])
def test_parse_errors_name_the_key(raw, message):
    with pytest.raises(ZoneError, match=message):
        parse_zone(raw, 'here')


def test_make_zone_errors_name_the_polygon():
    with pytest.raises(ZoneError, match=r'^authorised_zone\.include: the polygon needs'):
        make_zone([(0, 0), (1, 0)])
    with pytest.raises(ZoneError, match=r'^authorised_zone\.exclude\[1\]: vertex 0 is'):
        make_zone(L_SHAPE, [HOLE, [(3, 3), (3.5, 3), (3.5, 3.5)]])
    with pytest.raises(ZoneError, match=r'^authorised_zone\.frame_id: only the map frame'):
        make_zone(L_SHAPE, frame_id='odom')


@pytest.mark.parametrize('text, message', [
    ('authorised_zone: [[0, 0], [1, 0]\n', r': not valid YAML'),
    ('', r': expected a top-level "authorised_zone:" key'),
    ('- [0, 0]\n', r': expected a top-level "authorised_zone:" key'),
    ('zone: []\n', r': expected a top-level "authorised_zone:" key'),
    ('authorised_zone: []\nextra: 1\n', r': unknown top-level key\(s\) extra'),
    ('authorised_zone: {include: [[0, 0], [1, 0]]}\n',
     r': authorised_zone\.include: the polygon needs at least 3 points'),
])
def test_zone_file_errors_name_the_file_and_key(tmp_path, text, message):
    path = tmp_path / 'home.yaml'
    path.write_text(text)
    with pytest.raises(ZoneError, match='^' + str(path) + message):
        load_zone_file(path)


def test_a_missing_zone_file_is_named(tmp_path):
    path = tmp_path / 'missing.yaml'
    with pytest.raises(ZoneError, match=f'^{path}: cannot read the zone file: No such file'):
        load_zone_file(str(path))


def test_polygon_problem_and_signed_area_by_hand():
    assert polygon_problem([(0, 0), (2, 0), (2, 1), (0, 1)]) is None
    assert signed_area([(0, 0), (2, 0), (2, 1), (0, 1)]) == pytest.approx(2.0)
    assert signed_area([(0, 0), (0, 1), (2, 1), (2, 0)]) == pytest.approx(-2.0)
    # A vertex touching a non-adjacent edge is not a simple polygon either.
    assert polygon_problem([(0, 0), (4, 0), (4, 4), (2, 0), (0, 4)]) == \
        'is self-intersecting (edges 0 and 2 cross)'
    # Nor is an edge running back along the previous one (reported as the fold-back of
    # the adjacent edges 0 and 1, found before vertex 2 touching edge 0).
    assert polygon_problem([(0, 0), (2, 0), (1, 0), (1, 1)]) == \
        'is self-intersecting (edges 0 and 1 overlap)'


def test_a_zone_polygon_that_folds_back_is_refused():
    # (0, 0) -> (3, 0) -> (1, 0): edge 1 runs from (3, 0) back west over edge 0, a spike of
    # zero width; then (1, 0) -> (1, 2) -> (0, 2) -> back to (0, 0). Edges 0 and 1 are
    # collinear (cross product 0) and point opposite ways ((3, 0) . (-2, 0) = -6 < 0), so
    # they overlap; the check of adjacent edges comes first in the pair order (0, 1).
    spike = [[0, 0], [3, 0], [1, 0], [1, 2], [0, 2]]
    with pytest.raises(ZoneError, match=r'^here\.include: the polygon is self-intersecting '
                                        r'\(edges 0 and 1 overlap\)$'):
        parse_zone({'include': spike}, 'here')
    # The same fold-back at the closing vertex: edge 3 (2, 0) -> (0, 0) goes on over
    # edge 0 (0, 0) -> (1, 0) in the opposite direction (pair (0, 3)).
    with pytest.raises(ZoneError, match=r'^authorised_zone\.exclude\[0\]: the polygon is '
                                        r'self-intersecting \(edges 0 and 3 overlap\)$'):
        make_zone([(-1, -1), (3, -1), (3, 3), (-1, 3)], [[(0, 0), (1, 0), (1, 1), (2, 0)]])
