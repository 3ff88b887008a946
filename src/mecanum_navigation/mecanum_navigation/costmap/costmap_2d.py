"""
2-D costmaps with Nav2's cost values, layers and inflation law (pure, no ROS).

A Costmap2D is a grid of uint8 costs: FREE_SPACE 0, 1..252 inflated (the higher the
nearer an obstacle), INSCRIBED_INFLATED_OBSTACLE 253 (the robot's centre here puts its
circular footprint into an obstacle), LETHAL_OBSTACLE 254 and NO_INFORMATION 255. The
array is in OccupancyGrid order: costs[0] is the BOTTOM row (lowest y), column 0 the
lowest x; origin (x_m, y_m) is the lower-left corner of cell (row 0, col 0), with no
rotation (REP-103 axes, metres, in the costmap's frame: map or odom, REP-105). Cells
are addressed (row, col) and a point on a cell boundary belongs to the cell above / to
the right, as in map_io.

Layers are plain classes with ``update(costmap)``, applied in order on a costmap reset
to its default value each cycle (LayeredCostmap does that), as Nav2's layered costmap:

- StaticLayer: an OccupancyMap (map_server's map) written over the cells it covers;
- ObstacleLayer: laser returns marked LETHAL, cells between sensor and return cleared
  by raytracing; it keeps its own grid, so marks persist until cleared;
- KeepoutLayer: polygons written LETHAL (Nav2's keepout filter; Nav2 applies filters
  after inflation, so put it last for that, or before InflationLayer to keep the whole
  footprint out);
- ZoneLayer: the authorised zone as a geofence: every cell whose centre is outside it
  (outside its inclusion polygon or inside an exclusion) written LETHAL, also into a
  costmap in another frame (the local costmap in odom, given map -> odom);
- InflationLayer: Nav2's exponential cost decay around LETHAL cells.

RollingWindow keeps a costmap centred on the robot (the local costmap). Parameter
names are Nav2's (inflation_radius, cost_scaling_factor, obstacle_max_range, ...);
lengths are in metres.
"""

import math
from typing import List, Optional, Sequence, Tuple

from mecanum_map_server.map_io import OccupancyMap
from mecanum_navigation.costmap import kernels
from mecanum_safety.polygon import points_in_polygon
from mecanum_safety.zone import Zone
import numpy as np

FREE_SPACE = 0
MAX_NON_OBSTACLE = 252
INSCRIBED_INFLATED_OBSTACLE = 253
LETHAL_OBSTACLE = 254
NO_INFORMATION = 255

Point = Tuple[float, float]


def _cost_translation_table() -> np.ndarray:
    """Return Nav2's costmap -> OccupancyGrid value table (256 int8 entries)."""
    table = np.empty(256, dtype=np.int8)
    table[FREE_SPACE] = 0
    # Costs 1..252 map linearly (integer division) onto 1..98.
    table[1:253] = 1 + (97 * (np.arange(1, 253) - 1)) // 251
    table[INSCRIBED_INFLATED_OBSTACLE] = 99
    table[LETHAL_OBSTACLE] = 100
    table[NO_INFORMATION] = -1
    return table


#: Nav2's cost_translation_table: 0 -> 0, 1..252 -> 1..98, 253 -> 99, 254 -> 100, 255 -> -1.
COST_TRANSLATION_TABLE = _cost_translation_table()


class Costmap2D:
    """A grid of uint8 costs over a rectangle of the plane (see the module docstring)."""

    def __init__(self, size_x: int, size_y: int, resolution_m: float,
                 origin_x_m: float = 0.0, origin_y_m: float = 0.0,
                 default_value: int = FREE_SPACE):
        """Make a size_x (columns) by size_y (rows) costmap filled with default_value."""
        for name, value in (('size_x', size_x), ('size_y', size_y)):
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
                raise ValueError(f'{name} must be a positive number of cells, not {value!r}')
        _check_positive('resolution_m', resolution_m)
        _check_finite('origin_x_m', origin_x_m)
        _check_finite('origin_y_m', origin_y_m)
        _check_cost('default_value', default_value)
        self.resolution_m = float(resolution_m)
        self.origin_x_m = float(origin_x_m)
        self.origin_y_m = float(origin_y_m)
        self.default_value = int(default_value)
        self.costs = np.full((int(size_y), int(size_x)), self.default_value, dtype=np.uint8)

    @classmethod
    def like_map(cls, occupancy_map: OccupancyMap,
                 default_value: int = FREE_SPACE) -> 'Costmap2D':
        """Return a costmap with the size, resolution and origin of an unrotated map."""
        if occupancy_map.origin[2] != 0.0:
            raise ValueError('like_map needs a map with yaw 0 (costmaps are not rotated), '
                             f'not {occupancy_map.origin[2]} rad')
        return cls(occupancy_map.width, occupancy_map.height, occupancy_map.resolution_m,
                   occupancy_map.origin[0], occupancy_map.origin[1], default_value)

    @property
    def size_x(self) -> int:
        """Return the number of columns (cells along x)."""
        return int(self.costs.shape[1])

    @property
    def size_y(self) -> int:
        """Return the number of rows (cells along y)."""
        return int(self.costs.shape[0])

    @property
    def size_x_m(self) -> float:
        """Return the width of the costmap in metres."""
        return self.size_x * self.resolution_m

    @property
    def size_y_m(self) -> float:
        """Return the height of the costmap in metres."""
        return self.size_y * self.resolution_m

    def same_geometry(self, other: 'Costmap2D') -> bool:
        """Tell whether other has the same size, resolution and origin."""
        return (self.costs.shape == other.costs.shape
                and self.resolution_m == other.resolution_m
                and self.origin_x_m == other.origin_x_m
                and self.origin_y_m == other.origin_y_m)

    def world_to_map(self, x: float, y: float) -> Optional[Tuple[int, int]]:
        """Return the (row, col) of the cell containing (x, y) m, or None outside."""
        if not (math.isfinite(x) and math.isfinite(y)):
            return None
        col = math.floor((x - self.origin_x_m) / self.resolution_m)
        row = math.floor((y - self.origin_y_m) / self.resolution_m)
        if 0 <= row < self.size_y and 0 <= col < self.size_x:
            return row, col
        return None

    def map_to_world(self, row: int, col: int) -> Point:
        """Return the (x, y) in metres of the centre of cell (row, col)."""
        return (self.origin_x_m + (col + 0.5) * self.resolution_m,
                self.origin_y_m + (row + 0.5) * self.resolution_m)

    def lethal_clearance_m(self, x: float, y: float, reach_m: float) -> float:
        """
        Return the distance (m) from (x, y) to the nearest LETHAL cell's square, or inf.

        Only cells within reach_m (plus a cell) are looked at. A cell's square, not its
        centre: a map marks a cell whose centre lies in an obstacle, so the square is
        within half a cell of the obstacle's face, and the distance to it within half a
        cell of the true clearance (the inflation's cell-centre distances can be a cell
        more optimistic).
        """
        _check_finite('x', x)
        _check_finite('y', y)
        res = self.resolution_m
        span = int(math.ceil(reach_m / res)) + 1
        col0 = math.floor((x - self.origin_x_m) / res)
        row0 = math.floor((y - self.origin_y_m) / res)
        rows = slice(max(row0 - span, 0), max(min(row0 + span + 1, self.size_y), 0))
        cols = slice(max(col0 - span, 0), max(min(col0 + span + 1, self.size_x), 0))
        lethal_rows, lethal_cols = np.nonzero(self.costs[rows, cols] == LETHAL_OBSTACLE)
        if len(lethal_rows) == 0:
            return math.inf
        left = self.origin_x_m + (lethal_cols + cols.start) * res
        bottom = self.origin_y_m + (lethal_rows + rows.start) * res
        dx = np.maximum(np.maximum(left - x, x - (left + res)), 0.0)
        dy = np.maximum(np.maximum(bottom - y, y - (bottom + res)), 0.0)
        return float(np.min(np.hypot(dx, dy)))

    def world_to_grid(self, xs: np.ndarray, ys: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Return continuous cell coordinates (x along columns) of world points (m)."""
        return ((np.asarray(xs, dtype=np.float64) - self.origin_x_m) / self.resolution_m,
                (np.asarray(ys, dtype=np.float64) - self.origin_y_m) / self.resolution_m)

    def cost_at(self, x: float, y: float) -> Optional[int]:
        """Return the cost of the cell containing (x, y) m, or None outside the costmap."""
        cell = self.world_to_map(x, y)
        return None if cell is None else int(self.costs[cell])

    def cell_centers(self) -> Tuple[np.ndarray, np.ndarray]:
        """Return the x and y (m) of all cell centres as two (size_y, size_x) arrays."""
        xs = self.origin_x_m + (np.arange(self.size_x) + 0.5) * self.resolution_m
        ys = self.origin_y_m + (np.arange(self.size_y) + 0.5) * self.resolution_m
        return np.meshgrid(xs, ys)

    def reset(self) -> None:
        """Set every cell to the default value."""
        self.costs.fill(self.default_value)

    def copy(self) -> 'Costmap2D':
        """Return an independent copy."""
        twin = Costmap2D(self.size_x, self.size_y, self.resolution_m, self.origin_x_m,
                         self.origin_y_m, self.default_value)
        twin.costs[...] = self.costs
        return twin

    def update_origin(self, new_origin_x_m: float, new_origin_y_m: float) -> Tuple[int, int]:
        """
        Move the costmap to the cell-aligned origin nearest the requested one.

        The shift is a whole number of cells (rounded), so the cells stay on the same
        world lattice: kept cells are copied to their new indices (they keep their world
        position) and cells new to the window get the default value. Returns the shift
        (rows, cols).
        """
        _check_finite('new_origin_x_m', new_origin_x_m)
        _check_finite('new_origin_y_m', new_origin_y_m)
        shift_c = int(round((new_origin_x_m - self.origin_x_m) / self.resolution_m))
        shift_r = int(round((new_origin_y_m - self.origin_y_m) / self.resolution_m))
        if shift_r == 0 and shift_c == 0:
            return 0, 0
        rows, cols = self.costs.shape
        shifted = np.full_like(self.costs, self.default_value)
        # Old cell (r, c) becomes new cell (r - shift_r, c - shift_c).
        src_r = slice(max(shift_r, 0), min(rows, rows + shift_r))
        src_c = slice(max(shift_c, 0), min(cols, cols + shift_c))
        dst_r = slice(max(-shift_r, 0), min(rows, rows - shift_r))
        dst_c = slice(max(-shift_c, 0), min(cols, cols - shift_c))
        if src_r.start < src_r.stop and src_c.start < src_c.stop:
            shifted[dst_r, dst_c] = self.costs[src_r, src_c]
        self.costs = shifted
        self.origin_x_m += shift_c * self.resolution_m
        self.origin_y_m += shift_r * self.resolution_m
        return shift_r, shift_c

    def to_occupancy_map(self) -> OccupancyMap:
        """Return the costs as OccupancyGrid values (Nav2's cost_translation_table)."""
        return OccupancyMap(self.resolution_m, (self.origin_x_m, self.origin_y_m, 0.0),
                            COST_TRANSLATION_TABLE[self.costs])


class StaticLayer:
    """
    Writes an OccupancyMap into a costmap, as Nav2's static layer (trinary, overwrite).

    Map cells >= lethal_cost_threshold become LETHAL_OBSTACLE; unknown (-1) cells
    NO_INFORMATION when track_unknown_space, else FREE_SPACE; all others FREE_SPACE.
    Each costmap cell takes the map cell under its centre; cells off the map are left
    as they are. The map may be rotated (its yaw); the costmap may be a rolling window.
    """

    def __init__(self, occupancy_map: OccupancyMap, lethal_cost_threshold: int = 100,
                 track_unknown_space: bool = True):
        """Convert the map's cells to costs once."""
        if not isinstance(occupancy_map, OccupancyMap):
            raise ValueError('occupancy_map must be an OccupancyMap, not '
                             f'{type(occupancy_map).__name__}')
        if (not isinstance(lethal_cost_threshold, (int, np.integer))
                or isinstance(lethal_cost_threshold, bool)
                or not 0 <= lethal_cost_threshold <= 100):
            raise ValueError('lethal_cost_threshold must be an integer in 0..100, not '
                             f'{lethal_cost_threshold!r}')
        if not isinstance(track_unknown_space, bool):
            raise ValueError(f'track_unknown_space must be a bool, not {track_unknown_space!r}')
        self.occupancy_map = occupancy_map
        self.lethal_cost_threshold = int(lethal_cost_threshold)
        self.track_unknown_space = track_unknown_space
        data = occupancy_map.data
        unknown_cost = NO_INFORMATION if track_unknown_space else FREE_SPACE
        self.map_costs = np.where(
            data < 0, unknown_cost,
            np.where(data >= self.lethal_cost_threshold, LETHAL_OBSTACLE, FREE_SPACE),
        ).astype(np.uint8)

    def update(self, costmap: Costmap2D) -> None:
        """Overwrite the costmap's cells that the map covers with the map's costs."""
        occupancy = self.occupancy_map
        ox, oy, yaw = occupancy.origin
        if (yaw == 0.0 and costmap.resolution_m == occupancy.resolution_m
                and _is_integer((costmap.origin_x_m - ox) / costmap.resolution_m)
                and _is_integer((costmap.origin_y_m - oy) / costmap.resolution_m)):
            # Same lattice: copy the overlapping block.
            col0 = int(round((costmap.origin_x_m - ox) / costmap.resolution_m))
            row0 = int(round((costmap.origin_y_m - oy) / costmap.resolution_m))
            r0, c0 = max(row0, 0), max(col0, 0)
            r1 = min(row0 + costmap.size_y, occupancy.height)
            c1 = min(col0 + costmap.size_x, occupancy.width)
            if r0 < r1 and c0 < c1:
                costmap.costs[r0 - row0:r1 - row0, c0 - col0:c1 - col0] = \
                    self.map_costs[r0:r1, c0:c1]
            return
        xs, ys = costmap.cell_centers()
        dx, dy = xs - ox, ys - oy
        cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
        cols = np.floor((cos_yaw * dx + sin_yaw * dy) / occupancy.resolution_m).astype(np.int64)
        rows = np.floor((-sin_yaw * dx + cos_yaw * dy) / occupancy.resolution_m).astype(np.int64)
        inside = (rows >= 0) & (rows < occupancy.height) & (cols >= 0) & (cols < occupancy.width)
        costmap.costs[inside] = self.map_costs[rows[inside], cols[inside]]


class KeepoutLayer:
    """
    Writes keepout zones (polygons in the costmap's frame, metres) as LETHAL_OBSTACLE.

    A cell is kept out when its centre is inside a polygon (even-odd rule); polygons
    may be concave and need at least 3 vertices.
    """

    def __init__(self, polygons: Sequence[Sequence[Point]]):
        """Check and store the polygons."""
        self.polygons: List[np.ndarray] = []
        for index, polygon in enumerate(polygons):
            try:
                vertices = np.asarray(polygon, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f'polygons[{index}] must be a list of (x, y) points') from None
            if vertices.ndim != 2 or vertices.shape[1] != 2 or vertices.shape[0] < 3:
                raise ValueError(f'polygons[{index}] must have at least 3 (x, y) points, '
                                 f'not shape {vertices.shape}')
            if not np.all(np.isfinite(vertices)):
                raise ValueError(f'polygons[{index}] has a non-finite coordinate')
            self.polygons.append(vertices)

    def update(self, costmap: Costmap2D) -> None:
        """Set the cells whose centres are inside a keepout polygon to LETHAL_OBSTACLE."""
        for vertices in self.polygons:
            gx, gy = costmap.world_to_grid(vertices[:, 0], vertices[:, 1])
            c0 = max(int(math.floor(gx.min() - 0.5)), 0)
            c1 = min(int(math.ceil(gx.max() - 0.5)) + 1, costmap.size_x)
            r0 = max(int(math.floor(gy.min() - 0.5)), 0)
            r1 = min(int(math.ceil(gy.max() - 0.5)) + 1, costmap.size_y)
            if c0 >= c1 or r0 >= r1:
                continue
            cx, cy = np.meshgrid(np.arange(c0, c1) + 0.5, np.arange(r0, r1) + 0.5)
            inside = points_in_polygon(cx, cy, np.column_stack((gx, gy)))
            block = costmap.costs[r0:r1, c0:c1]
            block[inside] = LETHAL_OBSTACLE


class ZoneLayer:
    """
    Writes everything outside an authorised zone as LETHAL_OBSTACLE (a geofence).

    zone: a :class:`~mecanum_safety.zone.Zone` (an inclusion polygon and
    exclusion polygons, concave allowed, in the zone's frame: map). Every cell whose
    centre is outside the allowed region (outside the inclusion polygon or inside an
    exclusion; the even-odd rule of Zone.contains) becomes LETHAL_OBSTACLE, as Nav2's
    keepout filter does with its mask. Put it before InflationLayer: inflation then keeps
    the whole footprint inside the zone as it keeps it off walls (to within the cells:
    a lethal cell's centre is up to half a cell beyond the border).

    frame_pose: the pose (x m, y m, yaw rad) of the costmap's frame in the zone's frame,
    i.e. the transform taking costmap points into the zone's frame: (0, 0, 0) (the
    default) for a costmap in the zone's frame (the global costmap), map -> odom for the
    local costmap in odom. None: not known yet, update() writes nothing. set_frame_pose
    changes it; the layer keeps the last pose it was given. The polygons are moved into
    the costmap's frame once per pose, then tested row by row against the cell lattice
    (vectorised; each edge touches only the rows it spans).
    """

    def __init__(self, zone: Zone,
                 frame_pose: Optional[Tuple[float, float, float]] = (0.0, 0.0, 0.0)):
        """Store the zone and the pose of the costmap's frame in the zone's frame."""
        if not isinstance(zone, Zone):
            raise ValueError(f'zone must be a Zone (mecanum_safety.zone), not '
                             f'{type(zone).__name__}')
        self.zone = zone
        self.frame_pose: Optional[Tuple[float, float, float]] = None
        self._polygons: List[np.ndarray] = []
        if frame_pose is not None:
            self.set_frame_pose(*frame_pose)

    def set_frame_pose(self, x: float, y: float, yaw: float) -> None:
        """Set the pose (m, m, rad) of the costmap's frame in the zone's frame."""
        for name, value in (('x', x), ('y', y), ('yaw', yaw)):
            _check_finite(name, value)
        pose = (float(x), float(y), float(yaw))
        if pose == self.frame_pose:
            return
        self.frame_pose = pose
        # p_costmap = R(yaw)^T (p_zone - t); for row vectors that is (p_zone - t) R(yaw).
        cos_yaw, sin_yaw = math.cos(pose[2]), math.sin(pose[2])
        rotation = np.array([[cos_yaw, -sin_yaw], [sin_yaw, cos_yaw]])
        self._polygons = [(polygon - pose[:2]) @ rotation for polygon in self.zone.polygons()]

    def outside_mask(self, costmap: Costmap2D) -> Optional[np.ndarray]:
        """Return a (size_y, size_x) bool array: cells whose centre is outside the zone."""
        if self.frame_pose is None:
            return None
        xs = costmap.origin_x_m + (np.arange(costmap.size_x) + 0.5) * costmap.resolution_m
        ys = costmap.origin_y_m + (np.arange(costmap.size_y) + 0.5) * costmap.resolution_m
        include, *exclude = self._polygons
        outside = ~_polygon_mask(xs, ys, include)
        for polygon in exclude:
            c0, c1 = np.searchsorted(xs, (polygon[:, 0].min(), polygon[:, 0].max()))
            r0, r1 = np.searchsorted(ys, (polygon[:, 1].min(), polygon[:, 1].max()))
            if c0 < c1 and r0 < r1:
                outside[r0:r1, c0:c1] |= _polygon_mask(xs[c0:c1], ys[r0:r1], polygon)
        return outside

    def update(self, costmap: Costmap2D) -> None:
        """Set the cells whose centres are outside the zone to LETHAL_OBSTACLE."""
        outside = self.outside_mask(costmap)
        if outside is not None:
            costmap.costs[outside] = LETHAL_OBSTACLE


class ObstacleLayer:
    """
    Marks laser returns and clears free space by raytracing, as Nav2's obstacle layer.

    Observations (add_scan / add_points) are buffered and applied by update(), in the
    costmap's frame: first each ray clears (Bresenham, FREE_SPACE) the cells from the
    sensor to its end, cut at raytrace_max_range (m) and starting at raytrace_min_range;
    then returns between obstacle_min_range and obstacle_max_range (m from the sensor)
    mark their cell LETHAL_OBSTACLE. The layer keeps its own grid, which follows the
    costmap's geometry (it rolls with a rolling window), so marks persist until a ray
    clears them. update() combines it into the costmap by maximum, skipping cells the
    layer never saw (Nav2's updateWithMax). With track_unknown_space, unseen cells are
    NO_INFORMATION in the layer and cleared ones turn NO_INFORMATION costmap cells free.
    """

    def __init__(self, obstacle_max_range: float = 2.5, obstacle_min_range: float = 0.0,
                 raytrace_max_range: float = 3.0, raytrace_min_range: float = 0.0,
                 track_unknown_space: bool = False):
        """Check and store the ranges (m)."""
        for name, value in (('obstacle_max_range', obstacle_max_range),
                            ('raytrace_max_range', raytrace_max_range)):
            _check_positive(name, value)
        for name, value in (('obstacle_min_range', obstacle_min_range),
                            ('raytrace_min_range', raytrace_min_range)):
            _check_finite(name, value)
            if value < 0.0:
                raise ValueError(f'{name} must be >= 0 m, not {value!r}')
        if obstacle_min_range >= obstacle_max_range:
            raise ValueError(f'obstacle_min_range ({obstacle_min_range}) must be below '
                             f'obstacle_max_range ({obstacle_max_range})')
        if raytrace_min_range >= raytrace_max_range:
            raise ValueError(f'raytrace_min_range ({raytrace_min_range}) must be below '
                             f'raytrace_max_range ({raytrace_max_range})')
        if not isinstance(track_unknown_space, bool):
            raise ValueError(f'track_unknown_space must be a bool, not {track_unknown_space!r}')
        self.obstacle_max_range = float(obstacle_max_range)
        self.obstacle_min_range = float(obstacle_min_range)
        self.raytrace_max_range = float(raytrace_max_range)
        self.raytrace_min_range = float(raytrace_min_range)
        self.track_unknown_space = track_unknown_space
        self.grid: Optional[Costmap2D] = None
        self._pending: List[Tuple[float, float, np.ndarray, np.ndarray]] = []
        #: The marked returns (P x 2, this layer's frame) of the newest observation.
        self.latest_points = np.zeros((0, 2))

    def add_points(self, sensor_x: float, sensor_y: float, points: np.ndarray,
                   free_directions: Optional[np.ndarray] = None) -> int:
        """
        Buffer one observation: returns (N x 2, m) seen from the sensor at (x, y) m.

        free_directions (M x 2) are directions of beams that saw nothing: they clear up
        to raytrace_max_range. Rows with a NaN or infinite value (and zero directions)
        are ignored; returns the number of rows ignored (for a throttled warning). A
        non-finite sensor position raises ValueError.
        """
        _check_finite('sensor_x', sensor_x)
        _check_finite('sensor_y', sensor_y)
        points = as_xy('points', points)
        valid = np.all(np.isfinite(points), axis=1)
        ignored = int(points.shape[0] - valid.sum())
        directions = as_xy('free_directions', [] if free_directions is None
                           else free_directions)
        norms = np.hypot(directions[:, 0], directions[:, 1])
        usable = np.all(np.isfinite(directions), axis=1) & (norms > 0.0)
        ignored += int(directions.shape[0] - usable.sum())
        unit = directions[usable] / norms[usable, None]
        self._buffer(sensor_x, sensor_y, points[valid], unit, self.raytrace_max_range)
        return ignored

    def add_scan(self, sensor_x: float, sensor_y: float, sensor_yaw: float,
                 ranges: Sequence[float], angle_min: float, angle_increment: float,
                 range_min: float = 0.0, range_max: float = math.inf) -> int:
        """
        Buffer a LaserScan taken by a sensor at pose (x m, y m, yaw rad) in this frame.

        REP-117: +inf (and finite ranges above range_max) means no return: the beam
        clears to raytrace_max_range, but not beyond range_max; NaN, -inf and ranges
        below range_min are ignored. Returns the number of ignored ranges (for a
        throttled warning). A non-finite pose or angle raises ValueError.
        """
        for name, value in (('sensor_x', sensor_x), ('sensor_y', sensor_y),
                            ('sensor_yaw', sensor_yaw), ('angle_min', angle_min),
                            ('angle_increment', angle_increment)):
            _check_finite(name, value)
        try:
            ranges = np.asarray(ranges, dtype=np.float64).ravel()
        except (TypeError, ValueError):
            raise ValueError('ranges must be a sequence of numbers (m)') from None
        angles = sensor_yaw + angle_min + angle_increment * np.arange(ranges.size)
        directions = np.column_stack((np.cos(angles), np.sin(angles)))
        with np.errstate(invalid='ignore'):
            hit = np.isfinite(ranges) & (ranges >= range_min) & (ranges <= range_max)
            free = (ranges == np.inf) | (np.isfinite(ranges) & (ranges > range_max))
        ignored = int(ranges.size - hit.sum() - free.sum())
        points = (sensor_x, sensor_y) + directions[hit] * ranges[hit, None]
        free_length = min(self.raytrace_max_range, range_max)
        self._buffer(sensor_x, sensor_y, points, directions[free], free_length)
        return ignored

    def _buffer(self, sensor_x: float, sensor_y: float, points: np.ndarray,
                free_units: np.ndarray, free_length: float) -> None:
        """Store the ray ends and the marks of an observation (finite inputs)."""
        offsets = points - (sensor_x, sensor_y)
        distances = np.hypot(offsets[:, 0], offsets[:, 1])
        marks = points[(distances >= self.obstacle_min_range)
                       & (distances <= self.obstacle_max_range)]
        scale = np.minimum(1.0, self.raytrace_max_range / np.maximum(distances, 1e-12))
        ends = np.concatenate(((sensor_x, sensor_y) + offsets * scale[:, None],
                               (sensor_x, sensor_y) + free_units * free_length))
        self._pending.append((float(sensor_x), float(sensor_y), ends, marks))
        self.latest_points = marks

    def clear(self) -> None:
        """Forget every mark and buffered observation."""
        self.grid = None
        self._pending = []
        self.latest_points = np.zeros((0, 2))

    def update(self, costmap: Costmap2D) -> None:
        """Apply the buffered observations to the layer's grid and max it into costmap."""
        self._follow(costmap)
        grid = self.grid
        for sensor_x, sensor_y, ends, marks in self._pending:
            self._clear_rays(grid, sensor_x, sensor_y, ends)
        for sensor_x, sensor_y, ends, marks in self._pending:
            gx, gy = grid.world_to_grid(marks[:, 0], marks[:, 1])
            cols, rows = np.floor(gx).astype(np.int64), np.floor(gy).astype(np.int64)
            inside = (rows >= 0) & (rows < grid.size_y) & (cols >= 0) & (cols < grid.size_x)
            grid.costs[rows[inside], cols[inside]] = LETHAL_OBSTACLE
        self._pending = []
        layer, master = grid.costs, costmap.costs
        take = (layer != NO_INFORMATION) & ((master == NO_INFORMATION) | (master < layer))
        master[take] = layer[take]

    def _follow(self, costmap: Costmap2D) -> None:
        """Make the layer's grid match the costmap (new grid on resize, else roll)."""
        default = NO_INFORMATION if self.track_unknown_space else FREE_SPACE
        grid = self.grid
        if (grid is None or grid.costs.shape != costmap.costs.shape
                or grid.resolution_m != costmap.resolution_m):
            self.grid = Costmap2D(costmap.size_x, costmap.size_y, costmap.resolution_m,
                                  costmap.origin_x_m, costmap.origin_y_m, default)
            return
        grid.update_origin(costmap.origin_x_m, costmap.origin_y_m)
        # Re-anchor exactly on the costmap (the lattices agree to rounding).
        grid.origin_x_m, grid.origin_y_m = costmap.origin_x_m, costmap.origin_y_m

    def _clear_rays(self, grid: Costmap2D, sensor_x: float, sensor_y: float,
                    ends: np.ndarray) -> None:
        """Raytrace FREE_SPACE from the sensor towards each end (clipped to the grid)."""
        if ends.shape[0] == 0:
            return
        x0, y0 = grid.world_to_grid(np.full(ends.shape[0], sensor_x),
                                    np.full(ends.shape[0], sensor_y))
        x1, y1 = grid.world_to_grid(ends[:, 0], ends[:, 1])
        if self.raytrace_min_range > 0.0:
            length = np.hypot(x1 - x0, y1 - y0)
            skip = self.raytrace_min_range / grid.resolution_m
            keep = length > skip
            fraction = skip / np.maximum(length, 1e-12)
            x0, y0 = x0 + (x1 - x0) * fraction, y0 + (y1 - y0) * fraction
            x0, y0, x1, y1 = x0[keep], y0[keep], x1[keep], y1[keep]
        x0, y0, x1, y1, inside = clip_segments(x0, y0, x1, y1, grid.size_x, grid.size_y)
        rows0, cols0 = _cells(y0[inside], grid.size_y), _cells(x0[inside], grid.size_x)
        rows1, cols1 = _cells(y1[inside], grid.size_y), _cells(x1[inside], grid.size_x)
        kernels.raytrace(grid.costs, rows0, cols0, rows1, cols1, FREE_SPACE)


class InflationLayer:
    """
    Nav2's inflation: cost falls off exponentially with the distance to an obstacle.

    With d the Euclidean distance (m, between cell centres) from a cell to the nearest
    LETHAL_OBSTACLE cell: d == 0 -> 254; d <= inscribed_radius -> 253; d <=
    inflation_radius -> floor(252 * exp(-cost_scaling_factor * (d - inscribed_radius)));
    beyond -> 0. A cell keeps the higher of its own and the inflated cost; a
    NO_INFORMATION cell stays unknown unless the inflated cost is >= 253 (or > 0 when
    inflate_unknown), as in Nav2. Distances are exact (a Euclidean distance transform);
    d is compared with the radii with a 1e-9 m tolerance, so a cell exactly at
    inscribed_radius is inscribed.
    """

    def __init__(self, inscribed_radius: float, inflation_radius: float = 0.55,
                 cost_scaling_factor: float = 3.0, inflate_unknown: bool = False):
        """Check and store the parameters (m, 1/m)."""
        _check_finite('inscribed_radius', inscribed_radius)
        if inscribed_radius < 0.0:
            raise ValueError(f'inscribed_radius must be >= 0 m, not {inscribed_radius!r}')
        _check_finite('inflation_radius', inflation_radius)
        if inflation_radius < 0.0:
            raise ValueError(f'inflation_radius must be >= 0 m, not {inflation_radius!r}')
        _check_finite('cost_scaling_factor', cost_scaling_factor)
        if cost_scaling_factor < 0.0:
            raise ValueError(f'cost_scaling_factor must be >= 0 (1/m), not '
                             f'{cost_scaling_factor!r}')
        if not isinstance(inflate_unknown, bool):
            raise ValueError(f'inflate_unknown must be a bool, not {inflate_unknown!r}')
        self.inscribed_radius = float(inscribed_radius)
        self.inflation_radius = float(inflation_radius)
        self.cost_scaling_factor = float(cost_scaling_factor)
        self.inflate_unknown = inflate_unknown
        self._lut: Optional[np.ndarray] = None
        self._lut_resolution = math.nan

    def cost_at_distance(self, distance_m: float) -> int:
        """Return the inflation cost of a cell distance_m from the nearest obstacle."""
        tolerance = 1e-9
        if distance_m <= 0.0:
            return LETHAL_OBSTACLE
        if distance_m <= self.inscribed_radius + tolerance:
            return INSCRIBED_INFLATED_OBSTACLE
        if distance_m > self.inflation_radius + tolerance:
            return FREE_SPACE
        factor = math.exp(-self.cost_scaling_factor * (distance_m - self.inscribed_radius))
        return int(math.floor(MAX_NON_OBSTACLE * factor))

    def lookup_table(self, resolution_m: float) -> np.ndarray:
        """Return the cost at each squared distance d2 = 0, 1, ... (cells^2) in a grid."""
        _check_positive('resolution_m', resolution_m)
        if self._lut is None or self._lut_resolution != resolution_m:
            reach = max(self.inflation_radius, self.inscribed_radius) / resolution_m
            size = int(math.floor(reach * reach + 1e-6)) + 1
            self._lut = np.array([self.cost_at_distance(math.sqrt(d2) * resolution_m)
                                  for d2 in range(size)], dtype=np.uint8)
            self._lut_resolution = resolution_m
        return self._lut

    def update(self, costmap: Costmap2D) -> None:
        """Inflate the costmap in place around its LETHAL_OBSTACLE cells."""
        kernels.inflate(costmap.costs, self.lookup_table(costmap.resolution_m),
                        self.inflate_unknown)


class LayeredCostmap:
    """A costmap and its layers: update() resets it and applies the layers in order."""

    def __init__(self, costmap: Costmap2D, layers: Sequence[object]):
        """Store the costmap and the layers (objects with update(costmap))."""
        for index, layer in enumerate(layers):
            if not callable(getattr(layer, 'update', None)):
                raise ValueError(f'layers[{index}] ({type(layer).__name__}) has no update()')
        self.costmap = costmap
        self.layers = list(layers)

    def update(self) -> Costmap2D:
        """Reset the costmap to its default value, run every layer; return the costmap."""
        self.costmap.reset()
        for layer in self.layers:
            layer.update(self.costmap)
        return self.costmap


class RollingWindow:
    """
    A costmap of fixed size kept centred on the robot (Nav2's rolling_window local costmap).

    move_to(x, y) shifts the window by whole cells so that its centre is as near (x, y)
    as the grid allows; kept cells keep their world position, new ones get the default.
    """

    def __init__(self, width_m: float, height_m: float, resolution_m: float,
                 default_value: int = FREE_SPACE, center_x_m: float = 0.0,
                 center_y_m: float = 0.0):
        """Make the window (sizes rounded to whole cells) centred on (center_x_m, center_y_m)."""
        _check_positive('width_m', width_m)
        _check_positive('height_m', height_m)
        _check_positive('resolution_m', resolution_m)
        _check_finite('center_x_m', center_x_m)
        _check_finite('center_y_m', center_y_m)
        size_x = max(1, int(round(width_m / resolution_m)))
        size_y = max(1, int(round(height_m / resolution_m)))
        half_x, half_y = 0.5 * size_x * resolution_m, 0.5 * size_y * resolution_m
        self.costmap = Costmap2D(size_x, size_y, resolution_m, center_x_m - half_x,
                                 center_y_m - half_y, default_value)

    def move_to(self, x: float, y: float) -> Tuple[int, int]:
        """Centre the window on (x, y) m (to the nearest cell); return the shift (rows, cols)."""
        _check_finite('x', x)
        _check_finite('y', y)
        costmap = self.costmap
        return costmap.update_origin(x - 0.5 * costmap.size_x_m, y - 0.5 * costmap.size_y_m)


def _polygon_mask(xs: np.ndarray, ys: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """
    Return a (len(ys), len(xs)) bool array: which lattice points are inside polygon.

    xs and ys are ascending; the rule is the even-odd one of points_in_polygon (a point
    is inside when a ray towards +x crosses the border an odd number of times), with the
    same arithmetic, but each edge only visits the rows it spans.
    """
    inside = np.zeros((ys.size, xs.size), dtype=bool)
    x2, y2 = polygon[-1]
    for x1, y1 in polygon:
        if y1 != y2:
            # The edge crosses row y when min(y1, y2) <= y < max(y1, y2).
            r0, r1 = np.searchsorted(ys, (min(y1, y2), max(y1, y2)))
            if r0 < r1:
                x_cross = x1 + (ys[r0:r1] - y1) * (x2 - x1) / (y2 - y1)
                inside[r0:r1] ^= xs[None, :] < x_cross[:, None]
        x2, y2 = x1, y1
    return inside


def clip_segments(x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray,
                  width: float, height: float):
    """
    Clip segments to the box [0, width] x [0, height] (Liang-Barsky), vectorised.

    Returns the clipped x0, y0, x1, y1 and a mask of the segments that meet the box.
    """
    x0, y0, x1, y1 = (np.asarray(v, dtype=np.float64) for v in (x0, y0, x1, y1))
    dx, dy = x1 - x0, y1 - y0
    t0 = np.zeros_like(x0)
    t1 = np.ones_like(x0)
    inside = np.ones(x0.shape, dtype=bool)
    for p, q in ((-dx, x0), (dx, width - x0), (-dy, y0), (dy, height - y0)):
        parallel = p == 0.0
        inside &= ~(parallel & (q < 0.0))
        with np.errstate(divide='ignore', invalid='ignore'):
            r = np.where(parallel, 0.0, q / np.where(parallel, 1.0, p))
        entering = ~parallel & (p < 0.0)
        leaving = ~parallel & (p > 0.0)
        t0 = np.where(entering, np.maximum(t0, r), t0)
        t1 = np.where(leaving, np.minimum(t1, r), t1)
    inside &= t0 <= t1
    return x0 + t0 * dx, y0 + t0 * dy, x0 + t1 * dx, y0 + t1 * dy, inside


def _cells(coordinates: np.ndarray, size: int) -> np.ndarray:
    """Return the cell indices of continuous coordinates, clamped into 0..size-1."""
    return np.clip(np.floor(coordinates), 0, size - 1).astype(np.int64)


def as_xy(name: str, points) -> np.ndarray:
    """Return points as an (N, 2) float array or raise ValueError naming them."""
    try:
        array = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be an N x 2 array of (x, y) in metres') from None
    if array.size == 0:
        return array.reshape(0, 2)
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f'{name} must be an N x 2 array of (x, y), not shape {array.shape}')
    return array


def _is_integer(value: float) -> bool:
    """Tell whether value is within 1e-6 of an integer."""
    return abs(value - round(value)) < 1e-6


def _check_finite(name: str, value) -> None:
    """Raise ValueError naming the parameter unless value is a finite number."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f'{name} must be a number, not {value!r}')
    if not math.isfinite(value):
        raise ValueError(f'{name} must be finite, not {value!r}')


def _check_positive(name: str, value) -> None:
    """Raise ValueError naming the parameter unless value is a finite number > 0."""
    _check_finite(name, value)
    if value <= 0.0:
        raise ValueError(f'{name} must be > 0, not {value!r}')


def _check_cost(name: str, value) -> None:
    """Raise ValueError naming the parameter unless value is an integer cost 0..255."""
    if (isinstance(value, bool) or not isinstance(value, (int, np.integer))
            or not 0 <= value <= 255):
        raise ValueError(f'{name} must be an integer cost 0..255, not {value!r}')
