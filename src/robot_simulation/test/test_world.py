"""Tests of the world files: the shipped worlds, geometry, moving obstacles, validation."""

import copy
import math
import textwrap

from mecanum_map_server.map_io import OccupancyMap, save_map
import numpy as np
import pytest
from robot_simulation.world import (available_worlds, find_world, load_world, MovingObstacle,
                                    World, WorldError)
import yaml

# The apartment's measurable facts, from the plan in worlds/apartment.yaml.
APARTMENT_START = (2.95, 2.0, 0.0)
APARTMENT_EAST_WALL_DISTANCE_M = 3.0        # inner face x = 5.95, start x = 2.95
# Doorway centre and the direction (unit vector) of a straight line through it.
APARTMENT_DOORWAYS = {
    'living room <-> hallway': ((1.5, 4.0), (0.0, 1.0)),
    'kitchen <-> hallway': ((8.5, 4.0), (0.0, 1.0)),
    'living room <-> kitchen': ((6.0, 3.3), (1.0, 0.0)),
    'bedroom <-> hallway': ((5.1, 5.2), (0.0, 1.0)),
    'bathroom <-> hallway': ((7.45, 5.2), (0.0, 1.0)),
}
ROOM_POINTS = {
    'living room': (3.5, 2.5), 'kitchen': (8.6, 3.4), 'hallway': (5.0, 4.6),
    'bedroom': (3.5, 6.5), 'bathroom': (8.0, 6.5),
}
ROBOT_HALF_WIDTH_M = 0.2


@pytest.fixture(scope='module')
def apartment():
    """Return the shipped apartment world (source-tree fallback of find_world)."""
    return load_world(find_world('apartment'))


@pytest.fixture(scope='module')
def lab():
    """Return the shipped lab world."""
    return load_world(find_world('lab'))


def cast_ray(segments, x, y, yaw):
    """
    Return the distance from (x, y) along yaw to the first segment hit (inf if none).

    Solves (x, y) + t (cos, sin) = p1 + u (p2 - p1) with t > 0, 0 <= u <= 1.
    """
    dx, dy = math.cos(yaw), math.sin(yaw)
    best = math.inf
    for x1, y1, x2, y2 in segments:
        ex, ey = x2 - x1, y2 - y1
        denominator = dx * ey - dy * ex
        if abs(denominator) < 1e-12:
            continue
        wx, wy = x1 - x, y1 - y
        t = (wx * ey - wy * ex) / denominator
        u = (wx * dy - wy * dx) / denominator
        if t > 1e-9 and -1e-9 <= u <= 1.0 + 1e-9:
            best = min(best, t)
    return best


def line_points(center, direction, half_length=0.6, step=0.02):
    """Return points every `step` m on the line through center along direction."""
    count = int(round(2 * half_length / step))
    return [(center[0] + direction[0] * (-half_length + i * step),
             center[1] + direction[1] * (-half_length + i * step)) for i in range(count + 1)]


def reachable_cells(world, start_xy, clearance_m, resolution_m=0.05):
    """
    Flood-fill the rasterised world, inflated by clearance_m, from start_xy.

    Returns (raster, reached mask); cells that are not free (0) are obstacles.
    """
    raster = world.to_occupancy_map(resolution_m)
    blocked = raster.data != 0
    radius = int(math.ceil(clearance_m / resolution_m))
    height, width = blocked.shape
    padded = np.pad(blocked, radius, constant_values=True)
    inflated = np.zeros_like(blocked)
    for di in range(-radius, radius + 1):
        for dj in range(-radius, radius + 1):
            if di * di + dj * dj <= radius * radius:
                inflated |= padded[radius + di:radius + di + height,
                                   radius + dj:radius + dj + width]
    free = ~inflated
    reached = np.zeros_like(free)
    col = int((start_xy[0] - raster.origin[0]) / resolution_m)
    row = int((start_xy[1] - raster.origin[1]) / resolution_m)
    reached[row, col] = free[row, col]
    while True:
        grown = reached.copy()
        grown[1:, :] |= reached[:-1, :]
        grown[:-1, :] |= reached[1:, :]
        grown[:, 1:] |= reached[:, :-1]
        grown[:, :-1] |= reached[:, 1:]
        grown &= free
        if np.array_equal(grown, reached):
            return raster, reached
        reached = grown


# --- the shipped worlds -----------------------------------------------------------------

def test_shipped_worlds_load_and_start_free(apartment, lab):
    """Both worlds load, and robot_start is free with the required 0.25 m clearance."""
    assert apartment.name == 'apartment'
    assert lab.name == 'lab'
    for world in (apartment, lab):
        x, y, _ = world.robot_start
        assert world.is_free(x, y, clearance_m=0.25)
        assert world.in_test_zone(x, y)
        assert world.segments.dtype == np.float64
        assert world.segments.shape[1] == 4
        assert len(world.segment_names) == len(world.segments)
    assert apartment.robot_start == APARTMENT_START
    assert lab.occupancy is not None and lab.occupancy.data.shape == (120, 140)


def test_apartment_has_the_declared_content(apartment):
    """Rooms' furniture, the L-shaped counter, the circles and the walking person."""
    names = {o.name for o in apartment.obstacles}
    for name in ('sofa', 'coffee_table', 'dining_table', 'chair_1', 'bed', 'wardrobe',
                 'kitchen_counter', 'bathtub'):
        assert name in names
    counter = next(o for o in apartment.obstacles if o.name == 'kitchen_counter')
    assert len(counter.polygon) == 6
    assert {c.name for c in apartment.circles} == {'coffee_table', 'coat_rack'}
    assert [m.name for m in apartment.moving_obstacles] == ['person']
    assert apartment.moving_obstacles[0].loop
    assert apartment.test_zone is not None
    xmin, ymin, xmax, ymax = apartment.bounds
    assert 9.0 <= xmax - xmin <= 12.0 and 7.0 <= ymax - ymin <= 10.0


def test_apartment_start_faces_the_east_wall_at_distance_d(apartment):
    """A ray from robot_start along its yaw hits the living room's east wall 3.0 m away."""
    x, y, yaw = apartment.robot_start
    distance = cast_ray(apartment.segments, x, y, yaw)
    assert distance == pytest.approx(APARTMENT_EAST_WALL_DISTANCE_M, abs=1e-9)
    # The ray does not pass near a circle either.
    for circle in apartment.circles:
        assert abs(circle.center[1] - y) > circle.radius_m or circle.center[0] < x


def test_lab_start_faces_the_east_wall_at_5_m(lab):
    """In the lab (map-based) the beam from robot_start hits the east wall at x = 6.0."""
    x, y, yaw = lab.robot_start
    assert cast_ray(lab.segments, x, y, yaw) == pytest.approx(5.0, abs=1e-9)


@pytest.mark.parametrize('doorway', sorted(APARTMENT_DOORWAYS))
def test_apartment_doorways_are_passable(apartment, doorway):
    """Every point of a straight line through each doorway has 0.2 m clearance."""
    center, direction = APARTMENT_DOORWAYS[doorway]
    blocked = [p for p in line_points(center, direction)
               if not apartment.is_free(p[0], p[1], clearance_m=ROBOT_HALF_WIDTH_M)]
    assert blocked == []


def test_apartment_walls_block_away_from_doorways(apartment):
    """A line through the hallway wall away from the doors is blocked."""
    points = line_points((3.5, 4.0), (0.0, 1.0))
    assert not all(apartment.is_free(x, y) for x, y in points)
    assert apartment.obstacle_at(3.5, 4.0) == 'hallway_south_mid'


def test_apartment_every_room_reachable_from_start(apartment):
    """With the robot's half width as clearance, all rooms connect to robot_start."""
    raster, reached = reachable_cells(apartment, APARTMENT_START[:2], ROBOT_HALF_WIDTH_M)
    for room, (x, y) in ROOM_POINTS.items():
        col = int((x - raster.origin[0]) / raster.resolution_m)
        row = int((y - raster.origin[1]) / raster.resolution_m)
        assert reached[row, col], room
    # ...and nothing outside the apartment is reached.
    outside_col = int((-0.3 - raster.origin[0]) / raster.resolution_m)
    assert not reached[:, outside_col].any()


def test_apartment_person_path_stays_clear_of_furniture(apartment):
    """The person's disc never overlaps static geometry along its loop."""
    person = apartment.moving_obstacles[0]
    lap_s = person.lap_length_m / person.speed_m_s
    for i in range(200):
        x, y = person.position_at(lap_s * i / 200)
        assert apartment.obstacle_at(x, y) is None
        assert apartment.nearest_obstacle(x, y)[1] >= person.radius_m
        assert apartment.in_test_zone(x, y)


def test_obstacle_queries(apartment):
    """obstacle_at, nearest_obstacle, is_free clearance, in_test_zone, bounds."""
    assert apartment.obstacle_at(0.6, 2.0) == 'sofa'
    assert apartment.obstacle_at(1.75, 2.0) == 'coffee_table'    # exact circle
    assert apartment.obstacle_at(8.0, 0.5) == 'kitchen_counter'
    assert apartment.obstacle_at(9.0, 2.0) is None               # inside the L's corner
    assert apartment.obstacle_at(2.95, 2.0) is None
    # Nearest to the start: the coffee table, 2.95 - 1.75 - 0.35 = 0.85 m.
    name, distance = apartment.nearest_obstacle(2.95, 2.0)
    assert name == 'coffee_table' and distance == pytest.approx(0.85)
    assert apartment.is_free(2.95, 2.0, clearance_m=0.84)
    assert not apartment.is_free(2.95, 2.0, clearance_m=0.86)
    assert not apartment.is_free(11.0, 2.0)
    assert apartment.in_test_zone(5.0, 4.6)
    assert not apartment.in_test_zone(-0.3, 4.0)


def test_find_world(tmp_path):
    """Names resolve to the worlds directory, paths are returned as is, unknown names fail."""
    path = find_world('apartment')
    assert path.name == 'apartment.yaml' and path.is_file()
    assert find_world('lab.yaml').name == 'lab.yaml'
    assert find_world(str(path)) == path
    own = tmp_path / 'mine.yaml'
    own.write_text('world: {}\n')
    assert find_world(own) == own
    assert 'lab_map' not in available_worlds()
    assert {'apartment', 'lab'} <= set(available_worlds())
    with pytest.raises(WorldError) as caught:
        find_world('moon')
    message = str(caught.value)
    assert "unknown world 'moon'" in message
    assert 'apartment' in message and 'lab' in message
    with pytest.raises(WorldError, match='lab_map'):
        find_world('lab_map')


# --- moving obstacles -------------------------------------------------------------------

def test_position_at_loop():
    """A closed loop round a 2 m square at 0.5 m/s: 16 s a lap, back to the start."""
    square = MovingObstacle('p', 0.2, 0.5, ((0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)),
                            loop=True)
    assert square.lap_length_m == pytest.approx(8.0)
    cases = {0.0: (0.0, 0.0), 2.0: (1.0, 0.0), 4.0: (2.0, 0.0), 6.0: (2.0, 1.0),
             10.0: (1.0, 2.0), 14.0: (0.0, 1.0),          # on the closing leg back to start
             16.0: (0.0, 0.0), 18.0: (1.0, 0.0), 35.0: (1.5, 0.0)}   # 35 s = 2 laps + 3 s
    for t, expected in cases.items():
        assert square.position_at(t) == pytest.approx(expected), t


def test_position_at_ping_pong():
    """An open path of 4 m at 1 m/s is walked there (4 s) and back (4 s), repeatedly."""
    walker = MovingObstacle('p', 0.2, 1.0, ((0.0, 0.0), (3.0, 0.0), (3.0, 1.0)), loop=False)
    assert walker.lap_length_m == pytest.approx(8.0)
    cases = {0.0: (0.0, 0.0), 2.0: (2.0, 0.0), 3.5: (3.0, 0.5), 4.0: (3.0, 1.0),
             5.0: (3.0, 0.0), 6.0: (2.0, 0.0), 8.0: (0.0, 0.0), 9.0: (1.0, 0.0),
             13.5: (2.5, 0.0)}    # 13.5 s = 1 lap + 5.5 s: 2.5 m back from the far end
    for t, expected in cases.items():
        assert walker.position_at(t) == pytest.approx(expected), t


def test_two_point_loop_is_back_and_forth():
    """A two-point loop closes onto itself: there and back along the same segment."""
    shuttle = MovingObstacle('p', 0.2, 1.0, ((0.0, 0.0), (2.0, 0.0)), loop=True)
    assert shuttle.position_at(1.0) == pytest.approx((1.0, 0.0))
    assert shuttle.position_at(3.0) == pytest.approx((1.0, 0.0))
    assert shuttle.position_at(3.5) == pytest.approx((0.5, 0.0))


# --- map-based geometry and rasterisation ----------------------------------------------

def write_map_world(directory, cells, origin=(0.0, 0.0, 0.0), start=(0.5, 0.5)):
    """Save a 1 m/cell map (rows bottom first) and a world using it; return the World."""
    save_map(OccupancyMap(1.0, origin, np.array(cells, dtype=np.int8)), directory / 'm.yaml')
    doc = {'world': {'name': 'grid', 'map': 'm.yaml',
                     'robot_start': {'x_m': start[0], 'y_m': start[1]}}}
    (directory / 'w.yaml').write_text(yaml.safe_dump(doc))
    return load_world(directory / 'w.yaml')


def edge_set(segments):
    """Return segments as a set of rounded, direction-independent tuples."""
    result = set()
    for x1, y1, x2, y2 in np.round(np.asarray(segments), 9).tolist():
        result.add(tuple(sorted([(x1 + 0.0, y1 + 0.0), (x2 + 0.0, y2 + 0.0)])))
    return result


def test_map_segments_single_centre_cell(tmp_path):
    """A 3x3 map with one occupied centre cell: its 4 edges plus the 4 bounds edges."""
    world = write_map_world(tmp_path, [[0, 0, 0], [0, 100, 0], [0, 0, 0]])
    assert world.bounds == (0.0, 0.0, 3.0, 3.0)          # defaulted to the map's extent
    assert len(world.segments) == 8
    assert edge_set(world.segments) == {
        ((1, 1), (2, 1)), ((1, 2), (2, 2)), ((1, 1), (1, 2)), ((2, 1), (2, 2)),
        ((0, 0), (3, 0)), ((0, 3), (3, 3)), ((0, 0), (0, 3)), ((3, 0), (3, 3))}
    assert world.segment_names.count('map') == 4
    assert world.obstacle_at(1.5, 1.5) == 'map'
    assert world.is_free(0.5, 1.5) and not world.is_free(0.5, 1.5, clearance_m=0.6)


def test_map_segments_are_merged_into_runs(tmp_path):
    """Two cells side by side give one box of 4 edges; unknown cells are not obstacles."""
    world = write_map_world(tmp_path, [[-1, 0, 0, 0], [0, 100, 100, 0], [0, 0, 0, -1]])
    map_edges = world.segments[[n == 'map' for n in world.segment_names]]
    assert edge_set(map_edges) == {((1, 1), (3, 1)), ((1, 2), (3, 2)), ((1, 1), (1, 2)),
                                   ((3, 1), (3, 2))}
    assert world.obstacle_at(0.5, 0.5) is None              # unknown cell


def test_map_segments_follow_origin_yaw(tmp_path):
    """A map rotated by 90 degrees about its origin (2, 0): the cell lands at x 1..2."""
    world = write_map_world(tmp_path, [[100, 0]], origin=(2.0, 0.0, math.pi / 2),
                            start=(1.5, 1.6))
    assert world.bounds == pytest.approx((1.0, 0.0, 2.0, 2.0))
    map_edges = world.segments[[n == 'map' for n in world.segment_names]]
    assert edge_set(map_edges) == {((1, 0), (2, 0)), ((1, 1), (2, 1)), ((1, 0), (1, 1)),
                                   ((2, 0), (2, 1))}


def test_to_occupancy_map_of_a_box_world(tmp_path):
    """A 0.4 x 0.2 box and a 0.15 m circle rasterise to exactly the cells worked by hand."""
    doc = {'world': {
        'bounds_m': [0.0, 0.0, 2.0, 2.0],
        'furniture': [{'name': 'crate', 'box': {'center': [1.0, 1.0], 'size': [0.4, 0.2]}},
                      {'name': 'bin', 'circle': {'center': [1.5, 0.5], 'radius_m': 0.15}}],
        'robot_start': {'x_m': 0.4, 'y_m': 0.4}}}
    (tmp_path / 'box.yaml').write_text(yaml.safe_dump(doc))
    world = load_world(tmp_path / 'box.yaml')
    assert world.name == 'box' and world.in_test_zone(-5.0, -5.0)      # no zone declared
    raster = world.to_occupancy_map(0.1)
    assert raster.origin == (0.0, 0.0, 0.0) and raster.data.shape == (20, 20)
    expected = np.zeros((20, 20), dtype=np.int8)
    expected[9:11, 8:12] = 100      # crate: x 0.8..1.2 -> cols 8..11, y 0.9..1.1 -> rows 9, 10
    expected[4:6, 14:16] = 100      # bin: centres (1.45|1.55, 0.45|0.55) are 0.071 m away
    np.testing.assert_array_equal(raster.data, expected)


def test_to_occupancy_map_of_the_lab_reproduces_its_map(lab):
    """Rasterising the lab at its map's resolution and extent gives the map back."""
    raster = lab.to_occupancy_map(0.05)
    assert raster.origin == (-0.5, -0.5, 0.0)
    np.testing.assert_array_equal(raster.data, lab.occupancy.data)


def test_world_constructed_in_code():
    """World can be built directly; segments are only the bounds without obstacles."""
    world = World(name='empty', bounds=(0.0, 0.0, 2.0, 1.0))
    assert edge_set(world.segments) == {((0, 0), (2, 0)), ((2, 0), (2, 1)),
                                        ((0, 1), (2, 1)), ((0, 0), (0, 1))}
    assert world.is_free(1.0, 0.5, clearance_m=0.5)
    assert not world.is_free(1.0, 0.5, clearance_m=0.51)


# --- validation -------------------------------------------------------------------------

BASE_DOC = {'world': {
    'name': 'small',
    'bounds_m': [0.0, 0.0, 4.0, 3.0],
    'walls': [{'from': [0.0, 1.5], 'to': [1.0, 1.5], 'thickness_m': 0.1}],
    'furniture': [{'name': 'crate', 'box': {'center': [3.0, 2.0], 'size': [0.5, 0.5]}}],
    'robot_start': {'x_m': 1.0, 'y_m': 0.75, 'yaw_deg': 0.0},
}}


def _set(path, value):
    """Return an edit setting doc['world'][path...] to value."""
    def edit(doc):
        target = doc['world']
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value
    return edit


def _delete(path):
    """Return an edit deleting doc['world'][path...]."""
    def edit(doc):
        target = doc['world']
        for key in path[:-1]:
            target = target[key]
        del target[path[-1]]
    return edit


def _add_furniture(item):
    """Return an edit appending a furniture entry."""
    return lambda doc: doc['world']['furniture'].append(item)


def _add_moving(**overrides):
    """Return an edit adding a valid moving obstacle with some fields overridden."""
    item = {'name': 'person', 'radius_m': 0.25, 'speed_m_s': 0.8,
            'path': [[2.0, 0.5], [2.0, 2.5]], 'loop': True}
    item.update(overrides)
    return lambda doc: doc['world'].setdefault('moving_obstacles', []).append(item)


BAD_WORLDS = [
    ('unknown top-level key', lambda doc: doc.update(extra=1),
     'w.yaml: extra: unknown top-level key (only "world:" is allowed)'),
    ('unknown world key', _set(['colour'], 'red'),
     'world.colour: unknown key (allowed: name, bounds_m, walls, furniture, map, test_zone, '
     'moving_obstacles, robot_start)'),
    ('unknown wall key', _set(['walls', 0, 'height_m'], 2.5),
     'walls[0].height_m: unknown key (allowed: from, to, thickness_m, name)'),
    ('missing wall key', _delete(['walls', 0, 'thickness_m']),
     "walls[0]: missing key 'thickness_m'"),
    ('unknown furniture key', _set(['furniture', 0, 'colour'], 'red'),
     "furniture[0] 'crate'.colour: unknown key (allowed: name, box, circle, polygon)"),
    ('unknown box key', _set(['furniture', 0, 'box', 'height'], 1),
     "furniture[0] 'crate'.box.height: unknown key (allowed: center, size, yaw_deg)"),
    ('unknown robot_start key', _set(['robot_start', 'z_m'], 0),
     'robot_start.z_m: unknown key (allowed: x_m, y_m, yaw_deg)'),
    ('nan in bounds', _set(['bounds_m'], [0.0, 0.0, float('nan'), 3.0]),
     'bounds_m: [xmin, ymin, xmax, ymax] must be a finite number, not nan'),
    ('infinite thickness', _set(['walls', 0, 'thickness_m'], float('inf')),
     'walls[0]: thickness_m must be a finite number, not inf'),
    ('text instead of number', _set(['robot_start', 'x_m'], 'one'),
     "robot_start: x_m must be a number, not 'one'"),
    ('bool instead of number', _set(['walls', 0, 'thickness_m'], True),
     'walls[0]: thickness_m must be a number, not True'),
    ('bounds with 3 numbers', _set(['bounds_m'], [0, 0, 4]),
     'bounds_m: [xmin, ymin, xmax, ymax] must be 4 numbers'),
    ('bounds inverted', _set(['bounds_m'], [4.0, 0.0, 0.0, 3.0]),
     'bounds_m: needs xmin < xmax and ymin < ymax'),
    ('missing bounds', _delete(['bounds_m']), "world: missing key 'bounds_m'"),
    ('zero-length wall', _set(['walls', 0, 'to'], [0.0, 1.5]),
     'walls[0]: zero length: from and to are both [0.0, 1.5]'),
    ('zero thickness wall', _set(['walls', 0, 'thickness_m'], 0),
     'walls[0]: thickness_m must be > 0, not 0'),
    ('named wall negative thickness',
     lambda doc: doc['world']['walls'][0].update(name='north', thickness_m=-0.1),
     "walls[0] 'north': thickness_m must be > 0, not -0.1"),
    ('box negative size', _set(['furniture', 0, 'box', 'size'], [0.5, -0.5]),
     "furniture[0] 'crate': size must be 2 positive numbers, not [0.5, -0.5]"),
    ('box size one number', _set(['furniture', 0, 'box', 'size'], [0.5]),
     "furniture[0] 'crate': size must be 2 positive numbers"),
    ('circle zero radius',
     _add_furniture({'name': 'bin', 'circle': {'center': [3.0, 1.0], 'radius_m': 0.0}}),
     "furniture[1] 'bin': radius_m must be > 0, not 0.0"),
    ('polygon with 2 points',
     _add_furniture({'name': 'plank', 'polygon': [[3.0, 0.5], [3.5, 0.5]]}),
     "furniture[1] 'plank': polygon needs at least 3 points, got 2"),
    ('self-intersecting polygon',
     _add_furniture({'name': 'bowtie',
                     'polygon': [[3.0, 0.2], [3.5, 0.8], [3.5, 0.2], [3.0, 0.8]]}),
     "furniture[1] 'bowtie': polygon is self-intersecting"),
    ('polygon folding back',
     _add_furniture({'name': 'spike',
                     'polygon': [[3.0, 0.2], [3.8, 0.2], [3.4, 0.2], [3.4, 0.8]]}),
     "furniture[1] 'spike': polygon is self-intersecting"),
    ('two shapes', _set(['furniture', 0, 'circle'], {'center': [1, 1], 'radius_m': 1}),
     "furniture[0] 'crate': needs exactly one shape of box, circle, polygon"),
    ('no shape', _delete(['furniture', 0, 'box']),
     "furniture[0] 'crate': needs exactly one shape"),
    ('duplicate furniture name',
     _add_furniture({'name': 'crate', 'box': {'center': [3.0, 0.5], 'size': [0.2, 0.2]}}),
     "furniture[1] 'crate': duplicate furniture name 'crate'"),
    ('missing robot_start', _delete(['robot_start']), "world: missing key 'robot_start'"),
    ('robot_start outside bounds', _set(['robot_start', 'x_m'], 5.0),
     'robot_start: (5, 0.75) is outside bounds_m [0, 0, 4, 3]'),
    ('robot_start inside furniture', _set(['robot_start'], {'x_m': 3.1, 'y_m': 2.1}),
     "robot_start: (3.1, 2.1) is inside obstacle 'crate'"),
    ('robot_start too close to furniture', _set(['robot_start'], {'x_m': 3.0, 'y_m': 1.65}),
     "robot_start: (3, 1.65) is only 0.100 m from obstacle 'crate'; it must be at least "
     '0.25 m from every obstacle'),
    ('robot_start too close to a wall', _set(['robot_start'], {'x_m': 0.5, 'y_m': 1.3}),
     "is only 0.150 m from obstacle 'walls[0]'"),
    ('robot_start too close to the bounds', _set(['robot_start'], {'x_m': 2.0, 'y_m': 0.1}),
     "is only 0.100 m from obstacle 'bounds'"),
    ('test zone with 2 points', _set(['test_zone'], [[0.0, 0.0], [4.0, 3.0]]),
     'test_zone: the polygon needs at least 3 points, got 2'),
    ('test zone self-intersecting',
     _set(['test_zone'], [[0.0, 0.0], [4.0, 3.0], [4.0, 0.0], [0.0, 3.0]]),
     'test_zone: the polygon is self-intersecting'),
    ('robot_start outside test zone',
     _set(['test_zone'], [[2.0, 0.0], [4.0, 0.0], [4.0, 3.0], [2.0, 3.0]]),
     'robot_start: (1, 0.75) is outside the test_zone'),
    ('moving path with 1 point', _add_moving(path=[[2.0, 0.5]]),
     "moving_obstacles[0] 'person': path needs at least 2 points, got 1"),
    ('moving speed zero', _add_moving(speed_m_s=0),
     "moving_obstacles[0] 'person': speed_m_s must be > 0, not 0"),
    ('moving negative radius', _add_moving(radius_m=-0.2),
     "moving_obstacles[0] 'person': radius_m must be > 0, not -0.2"),
    ('moving path leaves bounds', _add_moving(path=[[2.0, 0.5], [2.0, 3.5]]),
     "moving_obstacles[0] 'person': path point 1 (2, 3.5) leaves the bounds [0, 0, 4, 3]"),
    ('moving path of zero length', _add_moving(path=[[2.0, 0.5], [2.0, 0.5]]),
     "moving_obstacles[0] 'person': path has zero length"),
    ('moving loop not a bool', _add_moving(loop='yes please'),
     "moving_obstacles[0] 'person': loop must be true or false"),
    ('map file missing', _set(['map'], 'nowhere.yaml'),
     "map 'nowhere.yaml': "),
    ('walls not a list', _set(['walls'], {'from': [0, 0]}), 'walls: must be a list'),
    ('empty name', _set(['name'], ''), 'name: must be a non-empty string'),
]


@pytest.mark.parametrize('edit, message', [case[1:] for case in BAD_WORLDS],
                         ids=[case[0] for case in BAD_WORLDS])
def test_bad_world_raises_world_error(tmp_path, edit, message):
    """Each faulty world file raises WorldError naming the file and the entry."""
    doc = copy.deepcopy(BASE_DOC)
    edit(doc)
    path = tmp_path / 'w.yaml'
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(WorldError) as caught:
        load_world(path)
    text = str(caught.value)
    assert text.startswith('w.yaml: ')
    assert message in text


def test_base_world_of_the_validation_cases_is_valid(tmp_path):
    """The unedited document behind BAD_WORLDS loads, so each case fails for its own edit."""
    path = tmp_path / 'w.yaml'
    path.write_text(yaml.safe_dump(BASE_DOC))
    world = load_world(path)
    assert world.name == 'small' and len(world.obstacles) == 2


@pytest.mark.parametrize('text, message', [
    ('', 'w.yaml: the file is empty'),
    ('# nothing but a comment\n', 'w.yaml: the file is empty'),
    ('world:\n  name: x\n  bounds_m: [0, 0, 1, 1\n  robot_start: {}\n',
     'w.yaml: YAML syntax error at line 4'),
    ('- a\n- b\n', 'w.yaml: expected a top-level "world:" mapping'),
    ('world: 3\n', 'w.yaml: world: must be a mapping'),
], ids=['empty', 'only comments', 'syntax error', 'list', 'world not a mapping'])
def test_bad_world_documents(tmp_path, text, message):
    """Empty files, YAML syntax errors (with the line) and wrong top-level shapes."""
    path = tmp_path / 'w.yaml'
    path.write_text(text)
    with pytest.raises(WorldError) as caught:
        load_world(path)
    assert message in str(caught.value)


def test_bad_map_is_wrapped_with_the_world_file_name(tmp_path):
    """A truncated PGM behind the world's map raises WorldError naming world and map."""
    save_map(OccupancyMap(0.5, (0.0, 0.0, 0.0), np.zeros((4, 4), dtype=np.int8)),
             tmp_path / 'm.yaml')
    (tmp_path / 'm.pgm').write_bytes(b'P5\n4 4\n255\n\x00\x00')
    doc = {'world': {'map': 'm.yaml', 'robot_start': {'x_m': 1.0, 'y_m': 1.0}}}
    (tmp_path / 'w.yaml').write_text(yaml.safe_dump(doc))
    with pytest.raises(WorldError) as caught:
        load_world(tmp_path / 'w.yaml')
    text = str(caught.value)
    assert text.startswith("w.yaml: map 'm.yaml': ")
    assert 'truncated PGM' in text and 'm.pgm' in text


def test_robot_start_on_an_occupied_map_cell(tmp_path):
    """robot_start inside an occupied map cell names the map."""
    with pytest.raises(WorldError, match="robot_start: \\(1.5, 1.5\\) is inside obstacle 'map'"):
        write_map_world(tmp_path, [[0, 0, 0], [0, 100, 0], [0, 0, 0]], start=(1.5, 1.5))


def test_missing_world_file(tmp_path):
    """A missing world file raises WorldError, not OSError."""
    with pytest.raises(WorldError, match='no such world file'):
        load_world(tmp_path / 'absent.yaml')


@pytest.mark.parametrize('path, message', [
    ('[[0.5, 2.5], [3.5, 2.5]]', "path runs into 'sofa' at"),
    ('[[0.5, 0.6], [3.5, 0.6]]', 'path passes through robot_start'),
])
def test_moving_obstacle_paths_must_be_free(tmp_path, path, message):
    """A person walking through furniture or through the robot's start is refused."""
    world = tmp_path / 'walk.yaml'
    world.write_text(textwrap.dedent(f"""
        world:
          bounds_m: [0.0, 0.0, 4.0, 4.0]
          furniture:
          - {{name: sofa, box: {{center: [2.0, 2.5], size: [1.0, 0.5]}}}}
          moving_obstacles:
          - {{name: person, radius_m: 0.25, speed_m_s: 0.8, path: {path}, loop: false}}
          robot_start: {{x_m: 2.0, y_m: 0.6}}
        """))
    with pytest.raises(WorldError, match=message):
        load_world(world)
