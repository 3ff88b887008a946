"""
A log-odds occupancy grid that grows as laser scans are inserted (pure, no ROS).

Grid conventions are map_io.OccupancyMap's: cell (row, col) covers x in
[origin_x + col * res, origin_x + (col + 1) * res) and likewise y with rows; row 0 is the
BOTTOM row (lowest y), column 0 the lowest x, and the origin is the lower-left corner of
cell (0, 0), with no rotation (yaw 0). Cell borders always lie on integer multiples of
the resolution in the map frame (the origin is (k * res, l * res)), so growing the grid
only adds cells and never resamples it. Frames and units follow REP-103/REP-105: poses
(x_m, y_m, yaw_rad) in the map frame, yaw counter-clockwise.

Each cell holds the log-odds l = log(p / (1 - p)) of being occupied, 0 (p = 0.5) until
it is observed. Inserting a scan updates each cell at most once: cells holding the end
point of a return get l += logit(hit_probability), the other cells crossed by the beams
(Bresenham lines from the laser's cell, end cell excluded for a return, included for a
beam that only clears) get l += logit(miss_probability); l is then clamped to
[logit(clamp_min_probability), logit(clamp_max_probability)].

Which beams count (scan_to_rays): a range that is not finite (NaN, +-inf) or outside
[range_min, range_max] is ignored; a range equal to range_max (a max-range return) or
beyond max_range_m only clears, up to min(range, max_range_m); any other range is a
return at that distance.

Output (occupancy_grid, to_occupancy_map): -1 for never observed cells; trinary (the
default, as slam_toolbox and map_saver) gives 100 where p >= occupied_probability, 0
where p < free_probability and -1 between; otherwise round(100 p).
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence, Tuple

from mecanum_map_server.map_io import OccupancyMap
from numba import njit
import numpy as np

#: Cells added on each side beyond what a growth strictly needs (fewer reallocations).
GROWTH_MARGIN_CELLS = 64


def _is_number(value) -> bool:
    """Return True for an int or float (not bool)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_))


def _check_positive(name: str, value) -> None:
    """Raise ValueError unless value is a positive finite number."""
    if not (_is_number(value) and math.isfinite(value) and value > 0.0):
        raise ValueError(f'{name} must be a positive finite number, got {value!r}')


def logit(p: float) -> float:
    """Return log(p / (1 - p)) for 0 < p < 1."""
    return math.log(p / (1.0 - p))


@dataclass(frozen=True)
class GridMappingConfig:
    """Resolution and the inverse sensor model; probabilities are of 'occupied'."""

    resolution_m: float = 0.05
    hit_probability: float = 0.7
    miss_probability: float = 0.4
    clamp_min_probability: float = 0.12
    clamp_max_probability: float = 0.97
    occupied_probability: float = 0.65
    free_probability: float = 0.5

    def __post_init__(self) -> None:
        """Validate every field; raise ValueError naming the first bad one."""
        _check_positive('GridMappingConfig.resolution_m', self.resolution_m)
        for name in ('hit_probability', 'miss_probability', 'clamp_min_probability',
                     'clamp_max_probability', 'occupied_probability', 'free_probability'):
            value = getattr(self, name)
            if not (_is_number(value) and 0.0 < value < 1.0):
                raise ValueError(f'GridMappingConfig.{name} must be a number in (0, 1), '
                                 f'got {value!r}')
        if not self.hit_probability > 0.5:
            raise ValueError('GridMappingConfig.hit_probability must be above 0.5, got '
                             f'{self.hit_probability!r}')
        if not self.miss_probability < 0.5:
            raise ValueError('GridMappingConfig.miss_probability must be below 0.5, got '
                             f'{self.miss_probability!r}')
        if not self.clamp_min_probability < 0.5 < self.clamp_max_probability:
            raise ValueError('GridMappingConfig.clamp_min_probability must be below 0.5 and '
                             'clamp_max_probability above it, got '
                             f'{self.clamp_min_probability!r}, {self.clamp_max_probability!r}')
        if not self.free_probability <= self.occupied_probability:
            raise ValueError('GridMappingConfig.free_probability must not exceed '
                             f'occupied_probability, got {self.free_probability!r} > '
                             f'{self.occupied_probability!r}')


def scan_to_rays(ranges, angle_min: float, angle_increment: float, range_min: float,
                 range_max: float, max_range_m: float = math.inf
                 ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return (end_points, is_return) of a scan's usable beams, in the laser frame.

    Beam i is at angle angle_min + i * angle_increment (LaserScan). end_points is a
    (M, 2) float64 array (x_m, y_m); is_return (M,) is True for a return (the end point
    is an obstacle) and False for a beam that only clears (see the module docstring).
    Raises ValueError for a ranges array that is not 1-D numbers or for bad limits.
    """
    values = _ranges_array(ranges)
    for name, value in (('angle_min', angle_min), ('angle_increment', angle_increment)):
        if not (_is_number(value) and math.isfinite(value)):
            raise ValueError(f'{name} must be a finite number, got {value!r}')
    if not (_is_number(range_min) and math.isfinite(range_min) and range_min >= 0.0):
        raise ValueError(f'range_min must be a finite number >= 0, got {range_min!r}')
    if not (_is_number(range_max) and math.isfinite(range_max) and range_max > range_min):
        raise ValueError(f'range_max must be a finite number above range_min ({range_min!r}),'
                         f' got {range_max!r}')
    if not (_is_number(max_range_m) and max_range_m > 0.0):   # inf allowed, NaN not
        raise ValueError(f'max_range_m must be a positive number, got {max_range_m!r}')
    angles = angle_min + np.arange(len(values)) * angle_increment
    with np.errstate(invalid='ignore'):
        usable = np.isfinite(values) & (values >= range_min) & (values <= range_max)
    values, angles = values[usable], angles[usable]
    is_return = (values < range_max) & (values <= max_range_m)
    lengths = np.minimum(values, max_range_m)
    end_points = np.column_stack([lengths * np.cos(angles), lengths * np.sin(angles)])
    return end_points, is_return


class OccupancyGridMapper:
    """A growing log-odds grid (see the module docstring for every convention)."""

    def __init__(self, config: GridMappingConfig = GridMappingConfig()) -> None:
        if not isinstance(config, GridMappingConfig):
            raise ValueError(f'config must be a GridMappingConfig, got {config!r}')
        self._config = config
        self._resolution = float(config.resolution_m)
        self._l_hit = logit(config.hit_probability)
        self._l_miss = logit(config.miss_probability)
        self._l_min = logit(config.clamp_min_probability)
        self._l_max = logit(config.clamp_max_probability)
        self._l_occupied = logit(config.occupied_probability)
        self._l_free = logit(config.free_probability)
        # Global cell index of column 0 / row 0: origin = (col0 * res, row0 * res).
        self._col0 = 0
        self._row0 = 0
        self._log_odds = np.zeros((0, 0), dtype=np.float32)
        # Scan stamp per cell: 0 never observed; 2k (miss) or 2k + 1 (hit) in scan k >= 1.
        self._stamp = np.zeros((0, 0), dtype=np.int64)
        self._scans = 0

    @property
    def config(self) -> GridMappingConfig:
        """Return the configuration."""
        return self._config

    @property
    def resolution_m(self) -> float:
        """Return the cell size in metres."""
        return self._resolution

    @property
    def origin(self) -> Tuple[float, float]:
        """Return (x_m, y_m) of the lower-left corner of cell (0, 0)."""
        return self._col0 * self._resolution, self._row0 * self._resolution

    @property
    def shape(self) -> Tuple[int, int]:
        """Return (rows, cols); (0, 0) before anything is inserted or reserved."""
        return self._log_odds.shape

    @property
    def scans_inserted(self) -> int:
        """Return how many scans (insert_rays calls with at least one ray) went in."""
        return self._scans

    @property
    def log_odds(self) -> np.ndarray:
        """Return the log-odds grid (rows, cols), read-only view (row 0 = bottom)."""
        view = self._log_odds.view()
        view.setflags(write=False)
        return view

    @property
    def observed(self) -> np.ndarray:
        """Return the mask (rows, cols) of cells updated at least once."""
        return self._stamp > 0

    def probabilities(self) -> np.ndarray:
        """Return the occupancy probability of every cell (0.5 where never observed)."""
        return 1.0 / (1.0 + np.exp(-self._log_odds.astype(np.float64)))

    def occupied_mask(self, probability: Optional[float] = None) -> np.ndarray:
        """Return the cells with p >= probability (default: config.occupied_probability)."""
        threshold = self._l_occupied if probability is None else logit(probability)
        return (self._log_odds >= threshold) & (self._stamp > 0)

    def visible_mask(self, x: float, y: float, max_range_m: float,
                     probability: Optional[float] = None) -> np.ndarray:
        """
        Return the occupied cells a lidar at (x, y) would see first (rows, cols), bool.

        Rays every half cell of arc at max_range_m walk the grid (Amanatides-Woo) from
        (x, y) to the first occupied cell (p >= probability, default
        occupied_probability), which is marked with the next cell along the ray when it
        is occupied too (a wall's returns straddle a cell border); cells behind stay
        unmarked: the far face of a thin wall, surfaces hidden behind others.
        """
        for name, value in (('x', x), ('y', y), ('max_range_m', max_range_m)):
            if not (_is_number(value) and math.isfinite(value)):
                raise ValueError(f'{name} must be a finite number, got {value!r}')
        occupied = self.occupied_mask(probability)
        visible = np.zeros(occupied.shape, dtype=np.bool_)
        if occupied.size == 0 or max_range_m <= 0.0:
            return visible
        res = self._resolution
        rays = max(8, int(math.ceil(4.0 * math.pi * max_range_m / res)))
        _first_hits(occupied, visible, (x - self._col0 * res) / res,
                    (y - self._row0 * res) / res, max_range_m / res, rays)
        return visible

    def cell_of(self, x: float, y: float) -> Tuple[int, int]:
        """Return the (row, col) of the cell containing (x, y); may be outside the grid."""
        return (math.floor(y / self._resolution) - self._row0,
                math.floor(x / self._resolution) - self._col0)

    def reserve(self, x_min: float, y_min: float, x_max: float, y_max: float) -> None:
        """Grow the grid (if needed) so that it covers the rectangle, in metres."""
        for name, value in (('x_min', x_min), ('y_min', y_min), ('x_max', x_max),
                            ('y_max', y_max)):
            if not (_is_number(value) and math.isfinite(value)):
                raise ValueError(f'{name} must be a finite number, got {value!r}')
        res = self._resolution
        self._grow(math.floor(y_min / res), math.floor(x_min / res),
                   math.floor(y_max / res), math.floor(x_max / res), margin=0)

    def insert_scan(self, laser_pose: Sequence[float], ranges, angle_min: float,
                    angle_increment: float, range_min: float, range_max: float,
                    max_range_m: float = math.inf) -> int:
        """
        Insert a LaserScan taken from laser_pose (x_m, y_m, yaw_rad of the laser, map frame).

        Returns the number of beams used (see scan_to_rays for which are).
        """
        x, y, yaw = _pose(laser_pose, 'laser_pose')
        end_points, is_return = scan_to_rays(ranges, angle_min, angle_increment, range_min,
                                             range_max, max_range_m)
        cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
        world = np.column_stack([x + cos_yaw * end_points[:, 0] - sin_yaw * end_points[:, 1],
                                 y + sin_yaw * end_points[:, 0] + cos_yaw * end_points[:, 1]])
        self.insert_rays((x, y), world, is_return)
        return len(world)

    def insert_rays(self, origin_xy: Sequence[float], end_points, is_return) -> None:
        """
        Insert rays from origin_xy to each end point (M, 2), map frame, metres.

        is_return (M,) bool: True marks the end cell occupied, False only clears.
        """
        ox, oy = (float(v) for v in origin_xy)
        points = np.asarray(end_points, dtype=np.float64).reshape(-1, 2)
        hits = np.asarray(is_return, dtype=np.bool_).reshape(-1)
        if len(hits) != len(points):
            raise ValueError(f'is_return has {len(hits)} entries for {len(points)} end points')
        if not (math.isfinite(ox) and math.isfinite(oy) and np.all(np.isfinite(points))):
            raise ValueError('origin_xy and end_points must be finite')
        if len(points) == 0:
            return
        res = self._resolution
        cols = np.floor(points[:, 0] / res).astype(np.int64)
        rows = np.floor(points[:, 1] / res).astype(np.int64)
        origin_col, origin_row = math.floor(ox / res), math.floor(oy / res)
        self._grow(min(rows.min(), origin_row), min(cols.min(), origin_col),
                   max(rows.max(), origin_row), max(cols.max(), origin_col),
                   margin=GROWTH_MARGIN_CELLS)
        self._scans += 1
        _update_rays(self._log_odds, self._stamp, 2 * self._scans,
                     origin_row - self._row0, origin_col - self._col0,
                     rows - self._row0, cols - self._col0, hits,
                     self._l_hit, self._l_miss, self._l_min, self._l_max)

    def occupancy_grid(self, trinary: bool = True) -> np.ndarray:
        """Return the int8 OccupancyGrid data (rows, cols), row 0 = bottom (see module)."""
        observed = self._stamp > 0
        out = np.full(self._log_odds.shape, -1, dtype=np.int8)
        if trinary:
            out[observed & (self._log_odds >= self._l_occupied)] = 100
            out[observed & (self._log_odds < self._l_free)] = 0
        else:
            percent = np.rint(100.0 * self.probabilities())
            out[observed] = percent[observed].astype(np.int8)
        return out

    def to_occupancy_map(self, trinary: bool = True) -> OccupancyMap:
        """
        Return the grid as a map_io.OccupancyMap (save it with map_io.save_map).

        An empty mapper gives a single unknown cell at the origin (0, 0).
        """
        if self._log_odds.size == 0:
            return OccupancyMap(self._resolution, (0.0, 0.0, 0.0),
                                np.full((1, 1), -1, dtype=np.int8))
        x0, y0 = self.origin
        return OccupancyMap(self._resolution, (x0, y0, 0.0), self.occupancy_grid(trinary))

    def _grow(self, row_min: int, col_min: int, row_max: int, col_max: int,
              margin: int) -> None:
        """Grow the arrays to hold global cells row_min..row_max x col_min..col_max."""
        rows, cols = self._log_odds.shape
        if rows and cols:
            if (row_min >= self._row0 and col_min >= self._col0
                    and row_max < self._row0 + rows and col_max < self._col0 + cols):
                return
            new_row0 = min(self._row0, row_min - margin) if row_min < self._row0 else self._row0
            new_col0 = min(self._col0, col_min - margin) if col_min < self._col0 else self._col0
            top = self._row0 + rows - 1
            right = self._col0 + cols - 1
            new_top = row_max + margin if row_max > top else top
            new_right = col_max + margin if col_max > right else right
        else:
            new_row0, new_col0 = row_min - margin, col_min - margin
            new_top, new_right = row_max + margin, col_max + margin
        new_rows, new_cols = new_top - new_row0 + 1, new_right - new_col0 + 1
        log_odds = np.zeros((new_rows, new_cols), dtype=np.float32)
        stamp = np.zeros((new_rows, new_cols), dtype=np.int64)
        if rows and cols:
            r, c = self._row0 - new_row0, self._col0 - new_col0
            log_odds[r:r + rows, c:c + cols] = self._log_odds
            stamp[r:r + rows, c:c + cols] = self._stamp
        self._log_odds, self._stamp = log_odds, stamp
        self._row0, self._col0 = new_row0, new_col0


@njit(cache=True)
def _first_hits(occupied, visible, u0, v0, reach, rays):
    """
    Mark in visible the first occupied cell (and the next if occupied) along each ray.

    (u0, v0) is the start in continuous cell coordinates (column, row); reach in cells.
    """
    rows, cols = occupied.shape
    for k in range(rays):
        angle = 2.0 * math.pi * k / rays
        dx, dy = math.cos(angle), math.sin(angle)
        c, r = int(math.floor(u0)), int(math.floor(v0))
        step_c = 1 if dx > 0 else -1
        step_r = 1 if dy > 0 else -1
        t_delta_c = abs(1.0 / dx) if dx != 0.0 else np.inf
        t_delta_r = abs(1.0 / dy) if dy != 0.0 else np.inf
        if dx > 0:
            t_c = (c + 1 - u0) * t_delta_c
        elif dx < 0:
            t_c = (u0 - c) * t_delta_c
        else:
            t_c = np.inf
        if dy > 0:
            t_r = (r + 1 - v0) * t_delta_r
        elif dy < 0:
            t_r = (v0 - r) * t_delta_r
        else:
            t_r = np.inf
        t = 0.0
        found = False
        while t <= reach:
            if 0 <= r < rows and 0 <= c < cols:
                if occupied[r, c]:
                    if found:
                        visible[r, c] = True
                        break
                    visible[r, c] = True
                    found = True
                elif found:
                    break
            elif found:
                break
            if t_c < t_r:
                c += step_c
                t = t_c
                t_c += t_delta_c
            else:
                r += step_r
                t = t_r
                t_r += t_delta_r


@njit(cache=True)
def _update_rays(log_odds, stamp, miss_mark, r0, c0, rows, cols, hits, l_hit, l_miss,
                 l_min, l_max):
    """Apply one scan: each end cell of a return gets one hit, other crossed cells one miss."""
    hit_mark = miss_mark + 1
    for i in range(rows.shape[0]):
        if hits[i]:
            r, c = rows[i], cols[i]
            if stamp[r, c] != hit_mark:
                stamp[r, c] = hit_mark
                v = log_odds[r, c] + l_hit
                log_odds[r, c] = l_max if v > l_max else v
    for i in range(rows.shape[0]):
        r, c = r0, c0
        dr, dc = rows[i] - r0, cols[i] - c0
        step_r = 1 if dr > 0 else -1
        step_c = 1 if dc > 0 else -1
        dr, dc = abs(dr), abs(dc)
        steps = dr if dr > dc else dc
        # Bresenham: `steps` moves; the end cell is visited only for a clearing beam.
        if dc >= dr:
            error = dc // 2
        else:
            error = dr // 2
        last = steps if not hits[i] else steps - 1
        for k in range(last + 1):
            if stamp[r, c] < miss_mark:
                stamp[r, c] = miss_mark
                v = log_odds[r, c] + l_miss
                log_odds[r, c] = l_min if v < l_min else v
            if k == steps:
                break
            if dc >= dr:
                c += step_c
                error -= dr
                if error < 0:
                    r += step_r
                    error += dc
            else:
                r += step_r
                error -= dc
                if error < 0:
                    c += step_c
                    error += dr


def _pose(pose, name: str) -> Tuple[float, float, float]:
    """Return pose as 3 finite floats or raise ValueError naming it."""
    try:
        values = tuple(float(v) for v in pose)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be 3 finite numbers (x, y, yaw), got {pose!r}') from None
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ValueError(f'{name} must be 3 finite numbers (x, y, yaw), got {pose!r}')
    return values


def _ranges_array(ranges) -> np.ndarray:
    """Return ranges as a 1-D float64 array or raise ValueError."""
    try:
        values = np.asarray(ranges, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f'ranges must be a 1-D sequence of numbers, got {ranges!r}') from None
    if values.ndim != 1:
        raise ValueError(f'ranges must be a 1-D sequence of numbers, got shape {values.shape}')
    return values
