"""
The simulator's world files: walls, furniture, an optional Nav2 map and walking people.

Pure Python (numpy, PyYAML; no ROS). All lengths are metres, angles in the file are
degrees (``*_deg``) and radians in the API; frames follow REP-103: x forward/east,
y left/north, yaw counter-clockwise from +x. A world file looks like this::

    world:
      name: apartment                           # optional; default: the file's stem
      bounds_m: [0.0, 0.0, 12.0, 9.0]           # xmin ymin xmax ymax: the simulation area
      walls:                                    # thick straight walls (optional list)
      - {from: [0.0, 0.0], to: [12.0, 0.0], thickness_m: 0.12}   # optional name: ...
      furniture:                                # named solid obstacles (optional list)
      - {name: sofa, box: {center: [3.0, 2.0], size: [2.0, 0.9], yaw_deg: 0}}
      - {name: table, circle: {center: [6.0, 4.0], radius_m: 0.5}}
      - {name: counter, polygon: [[8.0, 0.1], [11.9, 0.1], [11.9, 0.7], [8.0, 0.7]]}
      map: lab_map.yaml    # optional Nav2 map (a path or package://PKG/path); occupied = obstacle
      test_zone: [[0.2, 0.2], [11.8, 0.2], [11.8, 8.8], [0.2, 8.8]]   # optional authorised zone
      moving_obstacles:                         # optional, e.g. a person walking a path
      - {name: person, radius_m: 0.25, speed_m_s: 0.8, path: [[5, 5], [9, 5]], loop: true}
      robot_start: {x_m: 1.0, y_m: 1.0, yaw_deg: 0.0}

Geometry:

* A wall is the rectangle of its centre line from ``from`` to ``to`` widened by
  thickness_m / 2 on each side; its ends are NOT extended, so a doorway between two
  collinear walls is exactly the gap between their end points (extend exterior walls by
  half their thickness yourself to close the corners).
* ``box.size`` is [length along the box's own x axis, width]; yaw_deg turns it CCW.
* Polygons may be given in either winding; they are stored counter-clockwise and must
  have at least 3 points and must not intersect themselves nor fold back (the rules of
  mecanum_safety.polygon.polygon_problem).
* Circles are kept exact (World.circles) and also as 24-gons in World.obstacles
  (kind 'circle'), which World.segments leaves out.
* Map cells with an OccupancyGrid value >= 65 are solid; unknown (-1) cells are not.
* bounds_m may be omitted when a map is given: the map's extent is used.

load_world() checks everything and raises WorldError naming the file and the entry, e.g.
``apartment.yaml: furniture[3] 'sofa': size must be 2 positive numbers``. robot_start must
be inside the bounds (and the test zone), outside every obstacle and at least 0.25 m from
each. find_world('apartment') locates the shipped worlds.
"""

from dataclasses import dataclass, field
import math
from pathlib import Path
import re
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

from mecanum_control.angles import wrap_angle
from mecanum_control.yaml_files import DocumentChecker, load_yaml_file
from mecanum_map_server.map_io import (
    find_map_file, load_map, MapError, OccupancyMap, world_to_cell)
from mecanum_safety.polygon import points_in_polygon, polygon_edges, polygon_problem, signed_area
from mecanum_safety.zone import parse_zone, Zone, ZoneError
import numpy as np

PathLike = Union[str, Path]
Point = Tuple[float, float]
Polygon = Tuple[Point, ...]

#: robot_start must be at least this far (m) from every static obstacle and the bounds.
START_CLEARANCE_M = 0.25
#: Map cells with a value >= this are obstacles (Nav2's default occupied_thresh, in %).
OCCUPIED_MIN = 65
#: Sides of the polygon approximating a circle in World.obstacles.
CIRCLE_SIDES = 24
#: Names of the non-obstacle sources of World.segments.
MAP_NAME = 'map'
BOUNDS_NAME = 'bounds'

_EPS = 1e-12


class WorldError(ValueError):
    """A malformed world file; the message names the file and the entry."""


@dataclass(frozen=True)
class Obstacle:
    """
    A named solid polygon: vertices (x, y) in metres, counter-clockwise, closed implicitly.

    kind is 'wall', 'box', 'polygon' or 'circle' (the 24-gon of a CircleObstacle, which
    World.segments and World.obstacle_at leave to the exact circle).
    """

    name: str
    polygon: Polygon
    kind: str = 'polygon'


@dataclass(frozen=True)
class CircleObstacle:
    """A named solid disc: center (x, y) and radius_m in metres."""

    name: str
    center: Point
    radius_m: float


@dataclass(frozen=True)
class MovingObstacle:
    """
    A disc (e.g. a person) walking a polyline at constant speed.

    radius_m in metres, speed_m_s in m/s, path vertices (x, y) in metres. With loop=True
    the path is closed (last point back to the first) and walked round and round; with
    loop=False it is walked to the end and back again (ping-pong). At t = 0 the obstacle
    is at path[0].
    """

    name: str
    radius_m: float
    speed_m_s: float
    path: Polygon
    loop: bool = True

    @property
    def lap_length_m(self) -> float:
        """Return the length in metres of one lap: the closed loop, or there and back."""
        lengths = [math.dist(a, b) for a, b in _legs(self.path, self.loop)]
        return sum(lengths) if self.loop else 2.0 * sum(lengths)

    def position_at(self, t_s: float) -> Point:
        """Return the (x, y) in metres of the obstacle's centre at time t_s (periodic)."""
        legs = _legs(self.path, self.loop)
        lengths = [math.dist(a, b) for a, b in legs]
        total = sum(lengths)
        if total <= 0.0 or self.speed_m_s <= 0.0:
            return self.path[0]
        travelled = self.speed_m_s * t_s
        if self.loop:
            remaining = travelled % total
        else:
            remaining = travelled % (2.0 * total)
            if remaining > total:
                remaining = 2.0 * total - remaining
        for (start, end), length in zip(legs, lengths):
            if length > 0.0 and remaining <= length:
                fraction = remaining / length
                return (start[0] + fraction * (end[0] - start[0]),
                        start[1] + fraction * (end[1] - start[1]))
            remaining -= length
        return legs[-1][1]


@dataclass(frozen=True, eq=False)
class World:
    """
    A static world plus its moving obstacles, as the simulator and its sensors see it.

    bounds is (xmin, ymin, xmax, ymax) in metres; robot_start is (x_m, y_m, yaw_rad);
    source is the world file. segments (computed) is a float64 array (N, 4) of
    x1, y1, x2, y2 for every static edge: wall and furniture polygon edges, the outline of
    the map's occupied cells (boundaries between occupied and other cells, merged into
    runs along rows and columns) and the four bounds edges; segment_names gives the
    obstacle name of each row ('map', 'bounds' for those two). Circles are not in
    segments: use World.circles, which are exact.
    """

    name: str
    bounds: Tuple[float, float, float, float]
    obstacles: Tuple[Obstacle, ...] = ()
    circles: Tuple[CircleObstacle, ...] = ()
    occupancy: Optional[OccupancyMap] = None
    test_zone: Optional[Zone] = None
    moving_obstacles: Tuple[MovingObstacle, ...] = ()
    robot_start: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    source: Path = Path('<memory>')
    map_file: Optional[Path] = None
    segments: np.ndarray = field(init=False, repr=False)
    segment_names: Tuple[str, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Check the bounds and build the segment and lookup arrays."""
        xmin, ymin, xmax, ymax = (float(v) for v in self.bounds)
        if not (all(math.isfinite(v) for v in (xmin, ymin, xmax, ymax))
                and xmin < xmax and ymin < ymax):
            raise ValueError(f'bounds must be finite with xmin < xmax, ymin < ymax: {self.bounds}')
        solid = [o for o in self.obstacles if o.kind != 'circle']
        edge_rows: List[np.ndarray] = []
        names: List[str] = []
        owners: List[np.ndarray] = []
        for index, obstacle in enumerate(solid):
            edges = polygon_edges(obstacle.polygon)
            edge_rows.append(edges)
            names.extend([obstacle.name] * len(edges))
            owners.append(np.full(len(edges), index, dtype=np.intp))
        solid_edges = np.vstack(edge_rows) if edge_rows else np.zeros((0, 4))
        map_edges = np.zeros((0, 4))
        if self.occupancy is not None:
            map_edges = occupied_outline(self.occupancy)
        names.extend([MAP_NAME] * len(map_edges))
        bounds_edges = polygon_edges(((xmin, ymin), (xmax, ymin), (xmax, ymax), (xmin, ymax)))
        names.extend([BOUNDS_NAME] * 4)
        segments = np.vstack([solid_edges, map_edges, bounds_edges]).astype(np.float64)
        segments.setflags(write=False)
        circle_array = np.array([(c.center[0], c.center[1], c.radius_m) for c in self.circles],
                                dtype=np.float64).reshape(-1, 3)
        setattr_ = object.__setattr__
        setattr_(self, 'bounds', (xmin, ymin, xmax, ymax))
        setattr_(self, 'segments', segments)
        setattr_(self, 'segment_names', tuple(names))
        setattr_(self, '_solid', tuple(solid))
        setattr_(self, '_solid_edges', solid_edges)
        setattr_(self, '_solid_owner',
                 np.concatenate(owners) if owners else np.zeros(0, dtype=np.intp))
        setattr_(self, '_circle_array', circle_array)

    def obstacle_at(self, x: float, y: float) -> Optional[str]:
        """
        Return the name of the static obstacle containing (x, y) in metres, else None.

        Walls, furniture polygons, exact circles and occupied map cells ('map') count;
        the bounds and moving obstacles do not.
        """
        edges = self._solid_edges
        if len(edges):
            y1, y2 = edges[:, 1], edges[:, 3]
            straddle = np.nonzero((y1 > y) != (y2 > y))[0]
            if len(straddle):
                x1, sy1, x2, sy2 = edges[straddle].T
                crossing_x = x1 + (y - sy1) * (x2 - x1) / (sy2 - sy1)
                owners = self._solid_owner[straddle][x < crossing_x]
                counts = np.bincount(owners, minlength=len(self._solid))
                inside = np.nonzero(counts % 2)[0]
                if len(inside):
                    return self._solid[int(inside[0])].name
        if len(self._circle_array):
            cx, cy, radius = self._circle_array.T
            inside = np.nonzero((x - cx) ** 2 + (y - cy) ** 2 < radius ** 2)[0]
            if len(inside):
                return self.circles[int(inside[0])].name
        if self.occupancy is not None:
            cell = world_to_cell(self.occupancy, x, y)
            if cell is not None and self.occupancy.data[cell] >= OCCUPIED_MIN:
                return MAP_NAME
        return None

    def nearest_obstacle(self, x: float, y: float) -> Tuple[str, float]:
        """
        Return (name, distance in metres) of the static edge or circle nearest to (x, y).

        The distance is to the obstacle's boundary (0 on it), whether (x, y) is inside or
        outside; the bounds edges count (name 'bounds').
        """
        distances = point_segment_distances(self.segments, x, y)
        index = int(np.argmin(distances))
        best_name, best = self.segment_names[index], float(distances[index])
        if len(self._circle_array):
            cx, cy, radius = self._circle_array.T
            circle_distances = np.abs(np.hypot(x - cx, y - cy) - radius)
            circle_index = int(np.argmin(circle_distances))
            if circle_distances[circle_index] < best:
                best_name = self.circles[circle_index].name
                best = float(circle_distances[circle_index])
        return best_name, best

    def is_free(self, x: float, y: float, clearance_m: float = 0.0) -> bool:
        """
        Return True if (x, y) in metres is strictly inside the bounds, in no obstacle.

        With clearance_m > 0 the point must also be at least clearance_m from every static
        edge (walls, furniture, map cell outlines, bounds) and circle. Moving obstacles
        are ignored.
        """
        xmin, ymin, xmax, ymax = self.bounds
        if not (xmin < x < xmax and ymin < y < ymax):
            return False
        if self.obstacle_at(x, y) is not None:
            return False
        if clearance_m > 0.0:
            return self.nearest_obstacle(x, y)[1] >= clearance_m
        return True

    def in_test_zone(self, x: float, y: float) -> bool:
        """Return True if (x, y) in metres is inside the test zone, or when none is declared."""
        if self.test_zone is None:
            return True
        return self.test_zone.contains_point(x, y)

    def to_occupancy_map(self, resolution_m: float = 0.05) -> OccupancyMap:
        """
        Rasterise the static world over its bounds (origin at (xmin, ymin), yaw 0).

        A cell is 100 where its centre is inside a wall, furniture or circle; otherwise it
        takes the value of the map cell under its centre (so occupied, free and unknown
        map cells carry over), and 0 (free) where there is no map. Moving obstacles are
        left out. Features thinner than resolution_m may fall between cell centres.
        """
        if not (math.isfinite(resolution_m) and resolution_m > 0.0):
            raise ValueError(f'resolution_m must be positive, not {resolution_m}')
        xmin, ymin, xmax, ymax = self.bounds
        width = max(1, math.ceil((xmax - xmin) / resolution_m - 1e-9))
        height = max(1, math.ceil((ymax - ymin) / resolution_m - 1e-9))
        xs = xmin + (np.arange(width) + 0.5) * resolution_m
        ys = ymin + (np.arange(height) + 0.5) * resolution_m
        grid_x, grid_y = np.meshgrid(xs, ys)
        data = np.zeros((height, width), dtype=np.int8)
        if self.occupancy is not None:
            data = sample_map(self.occupancy, grid_x, grid_y, outside=0)
        for obstacle in self._solid:
            _fill_polygon(data, obstacle.polygon, xmin, ymin, resolution_m, grid_x, grid_y)
        for cx, cy, radius in self._circle_array:
            data[(grid_x - cx) ** 2 + (grid_y - cy) ** 2 < radius ** 2] = 100
        return OccupancyMap(resolution_m, (xmin, ymin, 0.0), data)


def load_world(path: PathLike) -> World:
    """
    Read and check a world file (see the module docstring); return the World.

    Raises WorldError naming the file and the faulty entry.
    """
    path = Path(path)
    label = path.name
    doc = load_yaml_file(path, 'world file', WorldError)
    if doc is None:
        raise WorldError(f'{label}: the file is empty (expected a top-level "world:" mapping)')
    return _Parser(path).parse(doc)


def find_world(name_or_path: PathLike) -> Path:
    """
    Return the world file for a name ('apartment') or an existing path (returned as is).

    Names are looked up as <name>.yaml in the installed share/robot_simulation/worlds
    (ament_index), then in the source tree's worlds/ directory. Raises WorldError
    listing the available worlds when nothing matches.
    """
    candidate = Path(name_or_path).expanduser()
    if candidate.is_file():
        return candidate
    text = str(name_or_path)
    if len(candidate.parts) == 1:
        if candidate.suffix in ('.yaml', '.yml'):
            file_names = [text]
        else:
            file_names = [text + '.yaml', text + '.yml']
        for directory in world_directories():
            for file_name in file_names:
                found = directory / file_name
                if found.is_file() and _looks_like_world(found):
                    return found
    available = ', '.join(available_worlds()) or 'none'
    searched = ', '.join(str(d) for d in world_directories()) or 'no worlds directory found'
    raise WorldError(f'unknown world {text!r}: not a file, and not one of the available '
                     f'worlds: {available} (searched {searched})')


def available_worlds() -> List[str]:
    """Return the sorted names of the world files found by find_world (maps excluded)."""
    names = set()
    for directory in world_directories():
        for path in list(directory.glob('*.yaml')) + list(directory.glob('*.yml')):
            if _looks_like_world(path):
                names.add(path.stem)
    return sorted(names)


def world_directories() -> List[Path]:
    """Return the existing worlds/ directories: the installed share one first, then source."""
    directories: List[Path] = []
    try:
        from ament_index_python.packages import get_package_share_directory
        directories.append(Path(get_package_share_directory('robot_simulation')) / 'worlds')
    except (ImportError, KeyError, ValueError, OSError):
        pass
    here = Path(__file__)
    directories += [here.resolve().parents[1] / 'worlds', here.parents[1] / 'worlds']
    unique: List[Path] = []
    for directory in directories:
        if directory.is_dir() and all(not directory.samefile(d) for d in unique):
            unique.append(directory)
    return unique


def occupied_outline(occupancy: OccupancyMap, occupied_min: int = OCCUPIED_MIN) -> np.ndarray:
    """
    Return the (N, 4) x1, y1, x2, y2 edges (m) between occupied and other cells.

    Cells with value >= occupied_min are occupied; the area outside the grid counts as not
    occupied. Collinear neighbouring edges are merged into one run along each grid row
    boundary and column boundary; the map origin's offset and yaw are applied.
    """
    occupied = occupancy.data >= occupied_min
    height, width = occupied.shape
    padded = np.zeros((height + 2, width + 2), dtype=bool)
    padded[1:-1, 1:-1] = occupied
    # horizontal[r, c]: the edge at grid y = r (cells) below row r, above row r - 1.
    horizontal = padded[1:, 1:-1] != padded[:-1, 1:-1]
    rows, starts, ends = _runs(horizontal)
    horizontal_edges = np.column_stack([starts, rows, ends, rows])
    # vertical[c, r]: the edge at grid x = c left of column c, right of column c - 1.
    vertical = (padded[1:-1, 1:] != padded[1:-1, :-1]).T
    cols, starts, ends = _runs(vertical)
    vertical_edges = np.column_stack([cols, starts, cols, ends])
    cell_edges = np.vstack([horizontal_edges, vertical_edges]).astype(np.float64)
    cell_edges *= occupancy.resolution_m
    origin_x, origin_y, yaw = occupancy.origin
    cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
    result = np.empty_like(cell_edges)
    for column in (0, 2):
        local_x, local_y = cell_edges[:, column], cell_edges[:, column + 1]
        result[:, column] = origin_x + cos_yaw * local_x - sin_yaw * local_y
        result[:, column + 1] = origin_y + sin_yaw * local_x + cos_yaw * local_y
    return result


def sample_map(occupancy: OccupancyMap, xs: np.ndarray, ys: np.ndarray,
               outside: int = -1) -> np.ndarray:
    """Return the int8 map values under the points (xs, ys) in metres; `outside` off the grid."""
    origin_x, origin_y, yaw = occupancy.origin
    dx, dy = np.asarray(xs) - origin_x, np.asarray(ys) - origin_y
    cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
    cols = np.floor((cos_yaw * dx + sin_yaw * dy) / occupancy.resolution_m).astype(np.intp)
    rows = np.floor((-sin_yaw * dx + cos_yaw * dy) / occupancy.resolution_m).astype(np.intp)
    valid = (rows >= 0) & (rows < occupancy.height) & (cols >= 0) & (cols < occupancy.width)
    values = np.full(rows.shape, outside, dtype=np.int8)
    values[valid] = occupancy.data[rows[valid], cols[valid]]
    return values


def point_segment_distances(segments: np.ndarray, x: float, y: float) -> np.ndarray:
    """Return the distance in metres from (x, y) to each x1, y1, x2, y2 row of segments."""
    x1, y1, x2, y2 = np.asarray(segments, dtype=np.float64).T
    dx, dy = x2 - x1, y2 - y1
    length2 = dx * dx + dy * dy
    with np.errstate(divide='ignore', invalid='ignore'):
        t = np.where(length2 > 0.0, ((x - x1) * dx + (y - y1) * dy) / length2, 0.0)
    t = np.clip(t, 0.0, 1.0)
    return np.hypot(x1 + t * dx - x, y1 + t * dy - y)


class _Parser(DocumentChecker):
    """Checks one world document and builds the World; every failure names the entry."""

    WORLD_KEYS = ('name', 'bounds_m', 'walls', 'furniture', 'map', 'test_zone',
                  'moving_obstacles', 'robot_start')

    def __init__(self, path: Path):
        super().__init__(WorldError, path.name)
        self.path = path

    def named(self, raw: Any, where: str) -> str:
        """Return where + " 'name'" for an entry with a name key (which must be a string)."""
        if not isinstance(raw, dict) or 'name' not in raw:
            return where
        name = self.text(raw['name'], where, 'name')
        return f'{where} {name!r}'

    def points(self, value: Any, where: str, what: str, minimum: int) -> Polygon:
        """Return a list of at least `minimum` [x, y] points."""
        if not isinstance(value, (list, tuple)):
            self.fail(where, f'{what} must be a list of [x, y] points, not {value!r}')
        if len(value) < minimum:
            self.fail(where, f'{what} needs at least {minimum} points, got {len(value)}')
        return tuple(self.numbers(p, where, 2, f'{what} point {i}') for i, p in enumerate(value))

    def polygon(self, value: Any, where: str, what: str) -> Polygon:
        """Return a simple polygon, counter-clockwise."""
        points = self.points(value, where, what, 3)
        problem = polygon_problem(points)
        if problem:
            self.fail(where, f'{what} {problem}')
        return points if signed_area(points) > 0.0 else tuple(reversed(points))

    def parse(self, doc: Any) -> World:
        """Check the whole document and return the World."""
        raw = self.mapping(self.document(doc, 'world'), 'world', (), self.WORLD_KEYS)
        name = self.text(raw.get('name', self.path.stem), 'name')
        occupancy, map_file = self.load_map(raw)
        bounds = self.bounds(raw, occupancy)
        obstacles: List[Obstacle] = []
        circles: List[CircleObstacle] = []
        for index, wall in enumerate(self.entries(raw, 'walls')):
            obstacles.append(self.wall(wall, index))
        seen = set()
        for index, item in enumerate(self.entries(raw, 'furniture')):
            obstacle, circle = self.furniture(item, index, seen)
            obstacles.append(obstacle)
            if circle is not None:
                circles.append(circle)
        try:
            test_zone = parse_zone(raw.get('test_zone'), 'test_zone')
        except ZoneError as error:
            self.fail('', str(error))
        moving: List[MovingObstacle] = []
        seen = set()
        for index, item in enumerate(self.entries(raw, 'moving_obstacles')):
            moving.append(self.moving(item, index, bounds, seen))
        if 'robot_start' not in raw:
            self.fail('world', "missing key 'robot_start'")
        start = self.mapping(raw['robot_start'], 'robot_start', ('x_m', 'y_m'), ('yaw_deg',))
        x = self.number(start['x_m'], 'robot_start', 'x_m')
        y = self.number(start['y_m'], 'robot_start', 'y_m')
        yaw_deg = self.number(start.get('yaw_deg', 0.0), 'robot_start', 'yaw_deg')
        yaw = wrap_angle(math.radians(yaw_deg))
        world = World(name=name, bounds=bounds, obstacles=tuple(obstacles),
                      circles=tuple(circles), occupancy=occupancy, test_zone=test_zone,
                      moving_obstacles=tuple(moving), robot_start=(x, y, yaw),
                      source=self.path, map_file=map_file)
        self.check_start(world, x, y)
        self.check_moving_paths(world)
        return world

    def check_moving_paths(self, world: World) -> None:
        """Check that moving obstacles walk free paths and never cross the robot start."""
        sx, sy, _ = world.robot_start
        for index, mover in enumerate(world.moving_obstacles):
            where = f"moving_obstacles[{index}] '{mover.name}'"
            points = list(mover.path) + ([mover.path[0]] if mover.loop else [])
            for (x1, y1), (x2, y2) in zip(points, points[1:]):
                steps = max(1, int(math.ceil(math.hypot(x2 - x1, y2 - y1) / 0.05)))
                for k in range(steps + 1):
                    px, py = x1 + (x2 - x1) * k / steps, y1 + (y2 - y1) * k / steps
                    if not world.is_free(px, py, clearance_m=mover.radius_m):
                        blocker, _ = world.nearest_obstacle(px, py)
                        self.fail(where, f"path runs into '{blocker}' at ({px:.2f}, {py:.2f}) "
                                  f'(radius {mover.radius_m} m)')
                    if math.hypot(px - sx, py - sy) < mover.radius_m + START_CLEARANCE_M:
                        self.fail(where, f'path passes through robot_start at ({px:.2f}, '
                                  f'{py:.2f})')

    def entries(self, raw: Dict[str, Any], key: str) -> List[Any]:
        """Return the list under `key` (empty if absent or null)."""
        value = raw.get(key)
        if value is None:
            return []
        if not isinstance(value, list):
            self.fail(key, f'must be a list, not {value!r}')
        return value

    def load_map(self, raw: Dict[str, Any]) -> Tuple[Optional[OccupancyMap], Optional[Path]]:
        """Load the optional Nav2 map, relative to the world file's directory."""
        value = raw.get('map')
        if value is None:
            return None, None
        if not isinstance(value, str) or not value.strip():
            self.fail('map', f'must be a map YAML file name, not {value!r}')
        try:
            if value.startswith('package://'):
                map_path = find_map_file(value)
            else:
                map_path = Path(value).expanduser()
                if not map_path.is_absolute():
                    map_path = self.path.parent / map_path
            return load_map(map_path), map_path
        except MapError as error:
            self.fail(f'map {value!r}', str(error))

    def bounds(self, raw: Dict[str, Any],
               occupancy: Optional[OccupancyMap]) -> Tuple[float, float, float, float]:
        """Return bounds_m, or the map's extent when bounds_m is absent."""
        if raw.get('bounds_m') is None:
            if occupancy is None:
                self.fail('world', "missing key 'bounds_m' (required when there is no map)")
            return _map_extent(occupancy)
        xmin, ymin, xmax, ymax = self.numbers(raw['bounds_m'], 'bounds_m', 4,
                                              '[xmin, ymin, xmax, ymax]')
        if not (xmin < xmax and ymin < ymax):
            self.fail('bounds_m', f'needs xmin < xmax and ymin < ymax, got {raw["bounds_m"]}')
        return xmin, ymin, xmax, ymax

    def wall(self, raw: Any, index: int) -> Obstacle:
        """Return the rectangle of one wall."""
        where = self.named(raw, f'walls[{index}]')
        wall = self.mapping(raw, where, ('from', 'to', 'thickness_m'), ('name',))
        name = wall.get('name', f'walls[{index}]')
        start = self.numbers(wall['from'], where, 2, 'from')
        end = self.numbers(wall['to'], where, 2, 'to')
        thickness = self.positive(wall['thickness_m'], where, 'thickness_m')
        length = math.dist(start, end)
        if length <= _EPS:
            self.fail(where, f'zero length: from and to are both {list(start)}')
        ux, uy = (end[0] - start[0]) / length, (end[1] - start[1]) / length
        nx, ny = -uy * thickness / 2.0, ux * thickness / 2.0
        polygon = ((start[0] - nx, start[1] - ny), (end[0] - nx, end[1] - ny),
                   (end[0] + nx, end[1] + ny), (start[0] + nx, start[1] + ny))
        return Obstacle(name, polygon, 'wall')

    def furniture(self, raw: Any, index: int,
                  seen: set) -> Tuple[Obstacle, Optional[CircleObstacle]]:
        """Return the polygon (and exact circle, if any) of one furniture entry."""
        where = self.named(raw, f'furniture[{index}]')
        item = self.mapping(raw, where, ('name',), ('box', 'circle', 'polygon'))
        name = item['name']
        if name in seen:
            self.fail(where, f'duplicate furniture name {name!r}')
        seen.add(name)
        shapes = [key for key in ('box', 'circle', 'polygon') if key in item]
        if len(shapes) != 1:
            self.fail(where, f'needs exactly one shape of box, circle, polygon; got {shapes}')
        if 'box' in item:
            box = self.mapping(item['box'], f'{where}.box', ('center', 'size'), ('yaw_deg',))
            cx, cy = self.numbers(box['center'], where, 2, 'center')
            size = box['size']
            if (not isinstance(size, (list, tuple)) or len(size) != 2
                    or not all(_is_number(v) and math.isfinite(v) and v > 0 for v in size)):
                self.fail(where, f'size must be 2 positive numbers, not {size!r}')
            yaw = math.radians(self.number(box.get('yaw_deg', 0.0), where, 'yaw_deg'))
            half_x, half_y = size[0] / 2.0, size[1] / 2.0
            cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
            corners = ((-half_x, -half_y), (half_x, -half_y), (half_x, half_y),
                       (-half_x, half_y))
            polygon = tuple((cx + cos_yaw * px - sin_yaw * py, cy + sin_yaw * px + cos_yaw * py)
                            for px, py in corners)
            return Obstacle(name, polygon, 'box'), None
        if 'circle' in item:
            circle = self.mapping(item['circle'], f'{where}.circle', ('center', 'radius_m'))
            center = self.numbers(circle['center'], where, 2, 'center')
            radius = self.positive(circle['radius_m'], where, 'radius_m')
            polygon = tuple(
                (center[0] + radius * math.cos(2.0 * math.pi * k / CIRCLE_SIDES),
                 center[1] + radius * math.sin(2.0 * math.pi * k / CIRCLE_SIDES))
                for k in range(CIRCLE_SIDES))
            return (Obstacle(name, polygon, 'circle'),
                    CircleObstacle(name, (center[0], center[1]), radius))
        return Obstacle(name, self.polygon(item['polygon'], where, 'polygon'), 'polygon'), None

    def moving(self, raw: Any, index: int, bounds: Tuple[float, float, float, float],
               seen: set) -> MovingObstacle:
        """Return one moving obstacle; its path must stay inside the bounds."""
        where = self.named(raw, f'moving_obstacles[{index}]')
        item = self.mapping(raw, where, ('name', 'radius_m', 'speed_m_s', 'path'), ('loop',))
        name = item['name']
        if name in seen:
            self.fail(where, f'duplicate moving obstacle name {name!r}')
        seen.add(name)
        radius = self.positive(item['radius_m'], where, 'radius_m')
        speed = self.positive(item['speed_m_s'], where, 'speed_m_s')
        path = self.points(item['path'], where, 'path', 2)
        loop = self.boolean(item.get('loop', True), where, 'loop')
        xmin, ymin, xmax, ymax = bounds
        for point_index, (x, y) in enumerate(path):
            if not (xmin <= x <= xmax and ymin <= y <= ymax):
                self.fail(where, f'path point {point_index} ({x:g}, {y:g}) leaves the bounds '
                          f'[{xmin:g}, {ymin:g}, {xmax:g}, {ymax:g}]')
        if sum(math.dist(a, b) for a, b in _legs(path, loop)) <= _EPS:
            self.fail(where, 'path has zero length')
        return MovingObstacle(name, radius, speed, path, loop)

    def check_start(self, world: World, x: float, y: float) -> None:
        """Check robot_start is in the bounds and test zone, clear of every obstacle."""
        xmin, ymin, xmax, ymax = world.bounds
        here = f'({x:g}, {y:g})'
        if not (xmin < x < xmax and ymin < y < ymax):
            self.fail('robot_start', f'{here} is outside bounds_m '
                      f'[{xmin:g}, {ymin:g}, {xmax:g}, {ymax:g}]')
        inside = world.obstacle_at(x, y)
        if inside is not None:
            self.fail('robot_start', f'{here} is inside obstacle {inside!r}')
        name, distance = world.nearest_obstacle(x, y)
        if distance < START_CLEARANCE_M:
            self.fail('robot_start', f'{here} is only {distance:.3f} m from obstacle {name!r}; '
                      f'it must be at least {START_CLEARANCE_M} m from every obstacle')
        if not world.in_test_zone(x, y):
            self.fail('robot_start', f'{here} is outside the test_zone')


def _legs(path: Sequence[Point], loop: bool) -> List[Tuple[Point, Point]]:
    """Return the (start, end) pairs of a path, closing it when loop."""
    points = list(path) + ([path[0]] if loop else [])
    return list(zip(points[:-1], points[1:]))


def _runs(mask: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (line, start, end) of every run of True along axis 1 (end exclusive)."""
    lines, length = mask.shape
    padded = np.zeros((lines, length + 2), dtype=np.int8)
    padded[:, 1:-1] = mask
    change = np.diff(padded, axis=1)
    start_lines, starts = np.nonzero(change == 1)
    _, ends = np.nonzero(change == -1)
    return start_lines, starts, ends


def _map_extent(occupancy: OccupancyMap) -> Tuple[float, float, float, float]:
    """Return the axis-aligned (xmin, ymin, xmax, ymax) in metres covering the whole grid."""
    origin_x, origin_y, yaw = occupancy.origin
    width_m = occupancy.width * occupancy.resolution_m
    height_m = occupancy.height * occupancy.resolution_m
    cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
    xs, ys = [], []
    for local_x, local_y in ((0.0, 0.0), (width_m, 0.0), (width_m, height_m), (0.0, height_m)):
        xs.append(origin_x + cos_yaw * local_x - sin_yaw * local_y)
        ys.append(origin_y + sin_yaw * local_x + cos_yaw * local_y)
    return min(xs), min(ys), max(xs), max(ys)


def _fill_polygon(data: np.ndarray, polygon: Polygon, xmin: float, ymin: float,
                  resolution_m: float, grid_x: np.ndarray, grid_y: np.ndarray) -> None:
    """Set to 100 the cells of data whose centres are inside polygon (bounding box only)."""
    xs = [p[0] for p in polygon]
    ys = [p[1] for p in polygon]
    height, width = data.shape
    col0 = max(0, int(math.floor((min(xs) - xmin) / resolution_m)))
    col1 = min(width, int(math.ceil((max(xs) - xmin) / resolution_m)) + 1)
    row0 = max(0, int(math.floor((min(ys) - ymin) / resolution_m)))
    row1 = min(height, int(math.ceil((max(ys) - ymin) / resolution_m)) + 1)
    if col0 >= col1 or row0 >= row1:
        return
    window = (slice(row0, row1), slice(col0, col1))
    inside = points_in_polygon(grid_x[window], grid_y[window], polygon)
    data[window][inside] = 100


def _is_number(value: Any) -> bool:
    """Return True for int and float values (bool excluded)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _looks_like_world(path: Path) -> bool:
    """Return True if the file has a top-level 'world:' key (map YAMLs do not)."""
    try:
        text = path.read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError):
        return False
    return re.search(r'^world\s*:', text, re.MULTILINE) is not None
