"""
Matching a 2-D laser scan against an occupancy grid (pure numpy + numba, no ROS).

The map is turned into a likelihood field: each cell holds exp(-d^2 / (2 sigma^2)),
d the Euclidean distance (m) from the cell's centre to the map: to the nearest occupied
cell's centre for a grid (the exact distance transform of
:mod:`mecanum_navigation.costmap.distance_transform`), or to the nearest point itself
for a point cloud (LikelihoodField.from_points, no rounding to cells). Grid conventions
are map_io.OccupancyMap's: row 0 is the BOTTOM row, (origin_x, origin_y) the lower-left
corner of cell (0, 0), no rotation; a point lies in the cell containing it.

match_scan() searches the pose (x_m, y_m, yaw_rad, REP-103, in the grid's frame) of the
frame the scan points are given in (e.g. base_link) within a window around a prior:

1. Correlative search by branch and bound (as in Cartographer's fast correlative scan
   matcher): for every yaw on a grid of steps (about one cell of arc at the farthest
   point) and every translation by whole cells within the window, the score is the mean
   field value of the cells the points fall in, minus a small penalty growing with the
   distance from the prior (so that equally good poses, e.g. along a corridor, stay
   near it). Translations are searched coarse to fine on max-pooled copies of the field
   (a 2^h x 2^h block maximum bounds the score of every translation in the block), so
   the result is exactly the best of the whole grid without scoring most of it.
2. Refinement: Gauss-Newton on sum (1 - f(p_i))^2 with f the bilinear interpolation of
   the field, steps damped and kept within one search step of the correlative result.
3. Covariance: from the curvature of the score surface at the optimum. The summed
   field S(pose) is read as a log-likelihood (each point's log exp(-d^2 / 2 sigma^2) is
   about f - 1 near a wall), so the information is -Hessian(S), by central differences
   of one cell and one yaw step; it is regularised by the search window (no direction
   is more uncertain than the window: a corridor's length gets about the window's
   variance) and floored at a quarter of a cell and of a yaw step.

Steps 2 and 3 may run on a second, finer field of the same scene (fine_field): the
search needs the coarse grid to stay fast, the refinement gains from a finer grid and a
narrower sigma (bilinear interpolation of a field sampled at 5 cm blurs it by
millimetres; at 2.5 cm and sigma 2.5 cm consecutive scans match to about 3 mm).

The score reported is the fraction of points whose cell's d is within hit_distance_m
(on the search field) at the final pose: 1.0 is a perfect overlap, and callers reject a
match below their threshold.
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence, Tuple

from mecanum_control.angles import wrap_angle
from mecanum_map_server.map_io import OccupancyMap
from mecanum_navigation.costmap.distance_transform import squared_distance_transform
from numba import njit
import numpy as np

#: Squared distance (cells^2 or m^2) standing for "no occupied cell in reach".
_FAR = 1e18


def _is_number(value) -> bool:
    """Return True for an int or float (not bool)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_))


@dataclass(frozen=True)
class ScanMatcherConfig:
    """
    Search window and scoring; lengths in metres, angles in radians.

    linear_window_m and angular_window_rad are half-widths around the prior;
    angular_step_rad None picks the step giving one cell of arc at the farthest point;
    hit_distance_m None is 1.5 cells; prior_penalty is the score subtracted at the
    window's corner (scaled by the squared offset fraction).
    """

    linear_window_m: float = 0.4
    angular_window_rad: float = 0.35
    angular_step_rad: Optional[float] = None
    hit_distance_m: Optional[float] = None
    prior_penalty: float = 0.02
    refine: bool = True
    minimum_points: int = 10

    def __post_init__(self) -> None:
        """Validate every field; raise ValueError naming the first bad one."""
        for name in ('linear_window_m', 'angular_window_rad', 'prior_penalty'):
            value = getattr(self, name)
            if not (_is_number(value) and math.isfinite(value) and value >= 0.0):
                raise ValueError(f'ScanMatcherConfig.{name} must be a finite number >= 0, '
                                 f'got {value!r}')
        if self.angular_window_rad > math.pi:
            raise ValueError('ScanMatcherConfig.angular_window_rad must be at most pi, got '
                             f'{self.angular_window_rad!r}')
        for name in ('angular_step_rad', 'hit_distance_m'):
            value = getattr(self, name)
            if value is not None and not (_is_number(value) and math.isfinite(value)
                                          and value > 0.0):
                raise ValueError(f'ScanMatcherConfig.{name} must be None or a positive '
                                 f'number, got {value!r}')
        if not isinstance(self.refine, bool):
            raise ValueError(f'ScanMatcherConfig.refine must be a bool, got {self.refine!r}')
        count = self.minimum_points
        if not (isinstance(count, int) and not isinstance(count, bool) and count >= 1):
            raise ValueError('ScanMatcherConfig.minimum_points must be an integer >= 1, got '
                             f'{self.minimum_points!r}')


@dataclass(frozen=True)
class MatchResult:
    """
    The best pose found and how good it is.

    pose (x_m, y_m, yaw_rad); score in [0, 1] (fraction of points that hit); response in
    [0, 1] (mean likelihood-field value); covariance (3, 3) in x, y, yaw (m^2, rad^2);
    num_points used. With fewer points than minimum_points the pose is the prior, score
    and response are 0 and the covariance is the window's.
    """

    pose: Tuple[float, float, float]
    score: float
    response: float
    covariance: np.ndarray
    num_points: int


class LikelihoodField:
    """
    A likelihood field over a grid: field[r, c] = exp(-d^2 / (2 sigma_m^2)) (see module).

    Built from a boolean occupied mask (rows, cols), row 0 = bottom, with resolution_m
    and origin_xy, the lower-left corner of cell (0, 0).
    """

    def __init__(self, occupied: np.ndarray, resolution_m: float,
                 origin_xy: Sequence[float], sigma_m: float) -> None:
        mask = np.asarray(occupied)
        if mask.ndim != 2 or mask.shape[0] < 1 or mask.shape[1] < 1:
            raise ValueError(f'occupied must be a non-empty 2-D array, got shape {mask.shape}')
        for name, value in (('resolution_m', resolution_m), ('sigma_m', sigma_m)):
            if not (_is_number(value) and math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be a positive finite number, got {value!r}')
        origin = tuple(float(v) for v in origin_xy)
        if len(origin) != 2 or not all(math.isfinite(v) for v in origin):
            raise ValueError(f'origin_xy must be 2 finite numbers, got {origin_xy!r}')
        # An empty grid's NO_OBSTACLE becomes _FAR, as for cells out of from_points' reach.
        squared = np.minimum(squared_distance_transform(mask), _FAR) * float(resolution_m) ** 2
        self._set(squared, float(resolution_m), origin, float(sigma_m))

    def _set(self, squared_m2: np.ndarray, resolution_m: float, origin: Tuple[float, float],
             sigma_m: float) -> None:
        """Store the grids computed from squared distances (m^2)."""
        self.resolution_m = resolution_m
        self.origin_xy = origin
        self.sigma_m = sigma_m
        self.distance_m, self.field = _distance_and_field(squared_m2, sigma_m)
        self._pyramid = None

    @classmethod
    def from_points(cls, points, resolution_m: float, sigma_m: float,
                    max_distance_m: Optional[float] = None) -> 'LikelihoodField':
        """
        Build the field of a point cloud (N, 2): d is the distance to the nearest point.

        Distances are exact from each cell centre to the points themselves (no rounding
        of the points to cells), up to max_distance_m (default 3 sigma_m, at least 2
        cells); beyond it the field is 0. The grid covers the points plus that margin,
        its origin on a multiple of resolution_m.
        """
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) == 0:
            raise ValueError(f'points must be a non-empty (N, 2) array, got shape {pts.shape}')
        if not np.all(np.isfinite(pts)):
            raise ValueError('points must be finite')
        for name, value in (('resolution_m', resolution_m), ('sigma_m', sigma_m)):
            if not (_is_number(value) and math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be a positive finite number, got {value!r}')
        reach = 3.0 * sigma_m if max_distance_m is None else float(max_distance_m)
        reach = max(reach, 2.0 * resolution_m)
        margin = int(math.ceil(reach / resolution_m)) + 1
        low = np.floor(pts.min(axis=0) / resolution_m).astype(np.int64) - margin
        high = np.floor(pts.max(axis=0) / resolution_m).astype(np.int64) + margin
        shape = (int(high[1] - low[1] + 1), int(high[0] - low[0] + 1))
        origin = (float(low[0] * resolution_m), float(low[1] * resolution_m))
        squared = _splat(pts, shape[0], shape[1], origin[0], origin[1], float(resolution_m),
                         reach)
        field = cls.__new__(cls)
        field._set(squared, float(resolution_m), origin, float(sigma_m))
        return field

    @classmethod
    def from_probabilities(cls, probabilities: np.ndarray, resolution_m: float,
                           origin_xy: Sequence[float], sigma_m: float,
                           occupied_probability: float = 0.5) -> 'LikelihoodField':
        """
        Build the field of a probability grid (rows, cols), row 0 = bottom.

        Cells with p > occupied_probability are occupied (NaN cells are not).
        """
        values = np.asarray(probabilities, dtype=np.float64)
        with np.errstate(invalid='ignore'):
            occupied = values > occupied_probability
        return cls(occupied, resolution_m, origin_xy, sigma_m)

    @classmethod
    def from_occupancy_map(cls, occupancy_map: OccupancyMap, sigma_m: float,
                           occupied_threshold: int = 65) -> 'LikelihoodField':
        """Build the field of an OccupancyMap (cells >= occupied_threshold are occupied)."""
        if abs(occupancy_map.origin[2]) > 1e-12:
            raise ValueError('only maps with an unrotated origin (yaw 0) can be matched '
                             f'against, got yaw {occupancy_map.origin[2]!r}')
        return cls(occupancy_map.data >= occupied_threshold, occupancy_map.resolution_m,
                   occupancy_map.origin[:2], sigma_m)

    @property
    def shape(self) -> Tuple[int, int]:
        """Return (rows, cols)."""
        return self.field.shape

    def value_at(self, x: float, y: float) -> float:
        """Return the field value of the cell containing (x, y) (0 outside the grid)."""
        col = math.floor((x - self.origin_xy[0]) / self.resolution_m)
        row = math.floor((y - self.origin_xy[1]) / self.resolution_m)
        if 0 <= row < self.field.shape[0] and 0 <= col < self.field.shape[1]:
            return float(self.field[row, col])
        return 0.0

    def pyramid(self, levels: int) -> Tuple[np.ndarray, int]:
        """
        Return (grids, pad): grids[h] holds the maximum of 2^h x 2^h blocks of the field.

        grids has shape (levels + 1, rows + 2 pad, cols + 2 pad), pad = 2^levels; cell
        (r, c) of the field is grids[0][r + pad, c + pad] and grids[h][r + pad, c + pad]
        is the maximum over field cells r..r + 2^h - 1 x c..c + 2^h - 1 (0 outside).
        """
        if self._pyramid is None or self._pyramid[0].shape[0] < levels + 1:
            self._pyramid = _max_pyramid(self.field, levels), 1 << levels
        grids, pad = self._pyramid
        return grids, pad


def match_scan(field: LikelihoodField, points, prior: Sequence[float],
               config: ScanMatcherConfig = ScanMatcherConfig(),
               fine_field: Optional[LikelihoodField] = None) -> MatchResult:
    """
    Find the pose of the points' frame in the field's frame near prior (see the module).

    points is (N, 2) x_m, y_m in the frame whose pose is searched (finite; raises
    ValueError otherwise); prior is (x_m, y_m, yaw_rad). The search runs on field; the
    refinement and covariance on fine_field when given (a finer grid and narrower sigma
    of the same scene give sub-centimetre poses), else on field too.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f'points must be an (N, 2) array, got shape {pts.shape}')
    if not np.all(np.isfinite(pts)):
        raise ValueError('points must be finite (drop NaN / inf ranges before matching)')
    try:
        x0, y0, yaw0 = (float(v) for v in prior)
    except (TypeError, ValueError):
        raise ValueError(f'prior must be 3 finite numbers (x, y, yaw), got {prior!r}') from None
    if not all(math.isfinite(v) for v in (x0, y0, yaw0)):
        raise ValueError(f'prior must be 3 finite numbers (x, y, yaw), got {prior!r}')
    res = field.resolution_m
    window_cells = int(math.floor(config.linear_window_m / res + 1e-9))
    max_range = float(np.sqrt((pts ** 2).sum(axis=1)).max()) if len(pts) else 0.0
    step = config.angular_step_rad
    if step is None:
        reach = max(max_range, res)
        step = math.acos(max(-1.0, 1.0 - res * res / (2.0 * reach * reach)))
    angle_steps = int(math.ceil(config.angular_window_rad / step - 1e-9))
    if angle_steps > 0:
        step = config.angular_window_rad / angle_steps
    window_cov = np.diag([max(window_cells * res, res) ** 2] * 2
                         + [max(config.angular_window_rad, step) ** 2])
    if len(pts) < config.minimum_points:
        return MatchResult((x0, y0, yaw0), 0.0, 0.0, window_cov, len(pts))

    levels = 0
    while (1 << levels) < 2 * window_cells + 1:
        levels += 1
    grids, pad = field.pyramid(levels)
    yaws = yaw0 + step * np.arange(-angle_steps, angle_steps + 1)
    ox, oy = field.origin_xy
    rows, cols = _discretise(pts, yaws, x0, y0, ox, oy, res)
    linear_weight = config.prior_penalty / max(window_cells, 1) ** 2
    angular_weight = config.prior_penalty / max(angle_steps, 1) ** 2
    best_k, best_dx, best_dy, _ = _branch_and_bound(
        grids, pad, levels, rows, cols, window_cells, angle_steps, linear_weight,
        angular_weight)
    pose = np.array([x0 + best_dx * res, y0 + best_dy * res, yaws[best_k]])
    fine = field if fine_field is None else fine_field
    fine_x, fine_y = fine.origin_xy
    if config.refine:
        pose = _refine(fine.field, pts, pose, fine_x, fine_y, fine.resolution_m, res, step)
    fine_step = step * fine.resolution_m / res
    curvature = _curvature(fine.field, pts, pose, fine_x, fine_y, fine.resolution_m,
                           fine_step)
    covariance = _covariance(curvature, window_cov, fine.resolution_m, fine_step)
    hit_distance = 1.5 * res if config.hit_distance_m is None else config.hit_distance_m
    score, response = _score(field.distance_m, field.field, pts, pose, ox, oy, res,
                             hit_distance)
    return MatchResult((float(pose[0]), float(pose[1]), wrap_angle(float(pose[2]))),
                       float(score), float(response), covariance, len(pts))


def voxel_filter(points, cell_m: float) -> np.ndarray:
    """Return one point (the first) per cell_m x cell_m square, in input order."""
    if not (_is_number(cell_m) and math.isfinite(cell_m) and cell_m > 0.0):
        raise ValueError(f'cell_m must be a positive finite number, got {cell_m!r}')
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(pts) == 0:
        return pts
    keys = np.floor(pts / cell_m).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    return pts[np.sort(first)]


def _covariance(curvature: np.ndarray, window_cov: np.ndarray, res: float,
                step: float) -> np.ndarray:
    """
    Return the match covariance from the score surface's curvature (see the module).

    The summed field is read as a log-likelihood (log f ~ f - 1 near a wall), so the
    information is minus its Hessian, with directions of non-negative curvature counted
    as unconstrained; the window covariance is added as prior information, so a
    direction the scan does not constrain (a corridor's length) gets about the window's
    variance; the floor is a quarter of a cell and of a yaw step of the fine field.
    """
    symmetric = -0.5 * (curvature + curvature.T)
    values, vectors = np.linalg.eigh(symmetric)
    information = (vectors * np.maximum(values, 0.0)) @ vectors.T
    information += np.linalg.inv(window_cov)
    covariance = np.linalg.inv(information)
    covariance = 0.5 * (covariance + covariance.T)
    covariance += np.diag([(0.25 * res) ** 2, (0.25 * res) ** 2, (0.25 * step) ** 2])
    return covariance


@njit(cache=True)
def _distance_and_field(squared, sigma):
    """Return (distance, exp(-d^2 / (2 sigma^2))) as float32 grids from squared distances."""
    rows, cols = squared.shape
    distance = np.empty((rows, cols), dtype=np.float32)
    field = np.zeros((rows, cols), dtype=np.float32)
    scale = -0.5 / (sigma * sigma)
    cutoff = 100.0 * sigma * sigma   # exp(-50) is 0 in float32
    for r in range(rows):
        for c in range(cols):
            d2 = squared[r, c]
            distance[r, c] = math.sqrt(d2)
            if d2 < cutoff:
                field[r, c] = math.exp(scale * d2)
    return distance, field


@njit(cache=True)
def _splat(points, rows, cols, ox, oy, res, reach):
    """
    Return the squared distance (m^2) from each cell centre to the nearest point.

    Cells farther than reach from every point get _FAR.
    """
    squared = np.full((rows, cols), _FAR)
    span = int(math.ceil(reach / res))
    reach2 = reach * reach
    for i in range(points.shape[0]):
        px, py = points[i, 0], points[i, 1]
        pc = int(math.floor((px - ox) / res))
        pr = int(math.floor((py - oy) / res))
        for r in range(max(pr - span, 0), min(pr + span + 1, rows)):
            dy = oy + (r + 0.5) * res - py
            for c in range(max(pc - span, 0), min(pc + span + 1, cols)):
                dx = ox + (c + 0.5) * res - px
                d2 = dx * dx + dy * dy
                if d2 <= reach2 and d2 < squared[r, c]:
                    squared[r, c] = d2
    return squared


@njit(cache=True)
def _max_pyramid(field, levels):
    """Return the (levels + 1, rows + 2 pad, cols + 2 pad) block-maximum grids, pad 2^levels."""
    rows, cols = field.shape
    pad = 1 << levels
    height, width = rows + 2 * pad, cols + 2 * pad
    grids = np.zeros((levels + 1, height, width), dtype=np.float32)
    for r in range(rows):
        for c in range(cols):
            grids[0, r + pad, c + pad] = field[r, c]
    for h in range(1, levels + 1):
        half = 1 << (h - 1)
        for r in range(height):
            for c in range(width):
                v = grids[h - 1, r, c]
                if c + half < width and grids[h - 1, r, c + half] > v:
                    v = grids[h - 1, r, c + half]
                if r + half < height:
                    if grids[h - 1, r + half, c] > v:
                        v = grids[h - 1, r + half, c]
                    if c + half < width and grids[h - 1, r + half, c + half] > v:
                        v = grids[h - 1, r + half, c + half]
                grids[h, r, c] = v
    return grids


@njit(cache=True)
def _discretise(points, yaws, x0, y0, ox, oy, res):
    """Return (rows, cols) (K, N): the cell of each point at each yaw, translation x0, y0."""
    k_count = yaws.shape[0]
    n = points.shape[0]
    rows = np.empty((k_count, n), dtype=np.int64)
    cols = np.empty((k_count, n), dtype=np.int64)
    for k in range(k_count):
        c, s = math.cos(yaws[k]), math.sin(yaws[k])
        for i in range(n):
            px = x0 + c * points[i, 0] - s * points[i, 1]
            py = y0 + s * points[i, 0] + c * points[i, 1]
            cols[k, i] = int(math.floor((px - ox) / res))
            rows[k, i] = int(math.floor((py - oy) / res))
    return rows, cols


@njit(cache=True)
def _sum_at(grid, pad, rows_k, cols_k, dx, dy):
    """Return the sum of grid values of the points shifted by (dx, dy) cells (0 outside)."""
    height, width = grid.shape
    total = 0.0
    for i in range(rows_k.shape[0]):
        r = rows_k[i] + dy + pad
        c = cols_k[i] + dx + pad
        if 0 <= r < height and 0 <= c < width:
            total += grid[r, c]
    return total


@njit(cache=True)
def _min_square(low, high):
    """Return the smallest v^2 over integers v in [low, high]."""
    if low <= 0 <= high:
        return 0.0
    v = low if low > 0 else high
    return float(v * v)


@njit(cache=True)
def _branch_and_bound(grids, pad, levels, rows, cols, window, angle_steps, linear_weight,
                      angular_weight):
    """
    Return (k, dx, dy, value) maximising mean field - penalty over the search grid.

    Nodes (k, dx, dy, h) cover translations dx..dx + 2^h - 1 x dy..dy + 2^h - 1 (cells,
    clipped to [-window, window]) at yaw index k; their value on grid h bounds every
    translation they cover. Depth first, best child first, pruning nodes whose bound
    does not beat the best leaf so far.
    """
    k_count, n = rows.shape
    inv_n = 1.0 / n
    capacity = k_count + 4 * (levels + 2)
    stack_k = np.empty(capacity, dtype=np.int64)
    stack_x = np.empty(capacity, dtype=np.int64)
    stack_y = np.empty(capacity, dtype=np.int64)
    stack_h = np.empty(capacity, dtype=np.int64)
    stack_v = np.empty(capacity, dtype=np.float64)
    # Roots: one per yaw, covering the whole translation window; pushed worst first.
    root_values = np.empty(k_count)
    for k in range(k_count):
        da = float(k - angle_steps)
        root_values[k] = (_sum_at(grids[levels], pad, rows[k], cols[k], -window, -window)
                          * inv_n - angular_weight * da * da)
    order = np.argsort(root_values)
    size = 0
    for idx in range(k_count):
        k = order[idx]
        stack_k[size], stack_x[size], stack_y[size] = k, -window, -window
        stack_h[size], stack_v[size] = levels, root_values[k]
        size += 1
    best_value = -np.inf
    best_k, best_x, best_y = angle_steps, 0, 0
    child_k = np.empty(4, dtype=np.int64)
    child_x = np.empty(4, dtype=np.int64)
    child_y = np.empty(4, dtype=np.int64)
    child_v = np.empty(4, dtype=np.float64)
    while size > 0:
        size -= 1
        k, x, y, h, value = stack_k[size], stack_x[size], stack_y[size], stack_h[size], \
            stack_v[size]
        if value <= best_value:
            continue
        if h == 0:
            best_value, best_k, best_x, best_y = value, k, x, y
            continue
        half = 1 << (h - 1)
        da = float(k - angle_steps)
        count = 0
        for a in range(2):
            cx = x + a * half
            if cx > window:
                continue
            for b in range(2):
                cy = y + b * half
                if cy > window:
                    continue
                high_x = min(cx + half - 1, window)
                high_y = min(cy + half - 1, window)
                penalty = (linear_weight * (_min_square(cx, high_x) + _min_square(cy, high_y))
                           + angular_weight * da * da)
                v = _sum_at(grids[h - 1], pad, rows[k], cols[k], cx, cy) * inv_n - penalty
                if v > best_value:
                    # Insert sorted ascending, so the best child is pushed last.
                    j = count
                    while j > 0 and child_v[j - 1] > v:
                        child_k[j], child_x[j] = child_k[j - 1], child_x[j - 1]
                        child_y[j], child_v[j] = child_y[j - 1], child_v[j - 1]
                        j -= 1
                    child_k[j], child_x[j], child_y[j], child_v[j] = k, cx, cy, v
                    count += 1
        for j in range(count):
            stack_k[size], stack_x[size], stack_y[size] = child_k[j], child_x[j], child_y[j]
            stack_h[size], stack_v[size] = h - 1, child_v[j]
            size += 1
    return best_k, best_x, best_y, best_value


@njit(cache=True)
def _bilinear(field, u, v):
    """
    Return (value, d/du, d/dv) of the field bilinearly interpolated at cell coords (u, v).

    u, v are continuous column / row coordinates (cell (r, c) spans [c, c + 1) x
    [r, r + 1)); samples sit at cell centres; outside the grid the field is 0.
    """
    rows, cols = field.shape
    uu, vv = u - 0.5, v - 0.5
    c0, r0 = int(math.floor(uu)), int(math.floor(vv))
    a, b = uu - c0, vv - r0
    f00 = field[r0, c0] if 0 <= r0 < rows and 0 <= c0 < cols else 0.0
    f01 = field[r0, c0 + 1] if 0 <= r0 < rows and 0 <= c0 + 1 < cols else 0.0
    f10 = field[r0 + 1, c0] if 0 <= r0 + 1 < rows and 0 <= c0 < cols else 0.0
    f11 = field[r0 + 1, c0 + 1] if 0 <= r0 + 1 < rows and 0 <= c0 + 1 < cols else 0.0
    value = (1 - a) * (1 - b) * f00 + a * (1 - b) * f01 + (1 - a) * b * f10 + a * b * f11
    du = (1 - b) * (f01 - f00) + b * (f11 - f10)
    dv = (1 - a) * (f10 - f00) + a * (f11 - f01)
    return value, du, dv


@njit(cache=True)
def _normal_equations(field, points, pose, ox, oy, res):
    """Return (cost, H (3, 3), g (3,)) of sum (1 - f)^2 at pose (Gauss-Newton terms)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    hessian = np.zeros((3, 3))
    gradient = np.zeros(3)
    cost = 0.0
    for i in range(points.shape[0]):
        qx, qy = points[i, 0], points[i, 1]
        px = pose[0] + c * qx - s * qy
        py = pose[1] + s * qx + c * qy
        value, du, dv = _bilinear(field, (px - ox) / res, (py - oy) / res)
        residual = 1.0 - value
        cost += residual * residual
        gx, gy = du / res, dv / res
        # Jacobian of the residual: -(grad f) . d p / d (x, y, yaw).
        j0 = -gx
        j1 = -gy
        j2 = -(gx * (-s * qx - c * qy) + gy * (c * qx - s * qy))
        jac = (j0, j1, j2)
        for a in range(3):
            gradient[a] += jac[a] * residual
            for b in range(3):
                hessian[a, b] += jac[a] * jac[b]
    return cost, hessian, gradient


@njit(cache=True)
def _solve3(matrix, rhs):
    """Solve a 3x3 system by Cramer's rule; return (x, ok)."""
    m = matrix
    det = (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
           - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
           + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))
    x = np.zeros(3)
    if not (abs(det) > 1e-300) or not math.isfinite(det):
        return x, False
    for col in range(3):
        t = m.copy()
        for r in range(3):
            t[r, col] = rhs[r]
        x[col] = (t[0, 0] * (t[1, 1] * t[2, 2] - t[1, 2] * t[2, 1])
                  - t[0, 1] * (t[1, 0] * t[2, 2] - t[1, 2] * t[2, 0])
                  + t[0, 2] * (t[1, 0] * t[2, 1] - t[1, 1] * t[2, 0])) / det
    return x, True


@njit(cache=True)
def _refine(field, points, start, ox, oy, res, max_shift, max_turn):
    """Gauss-Newton with LM damping, staying within max_shift / max_turn of start."""
    pose = start.copy()
    cost, hessian, gradient = _normal_equations(field, points, pose, ox, oy, res)
    damping = 1e-3
    for _ in range(30):
        damped = hessian.copy()
        for a in range(3):
            damped[a, a] += damping * hessian[a, a] + 1e-12
        step, ok = _solve3(damped, -gradient)
        if not ok:
            break
        candidate = pose + step
        if (abs(candidate[0] - start[0]) > max_shift or abs(candidate[1] - start[1]) > max_shift
                or abs(candidate[2] - start[2]) > max_turn):
            damping *= 10.0
            if damping > 1e6:
                break
            continue
        new_cost, new_hessian, new_gradient = _normal_equations(field, points, candidate, ox,
                                                                oy, res)
        if new_cost < cost:
            done = cost - new_cost < 1e-10 * (cost + 1e-12)
            pose, cost, hessian, gradient = candidate, new_cost, new_hessian, new_gradient
            damping = max(damping * 0.1, 1e-9)
            if done:
                break
        else:
            damping *= 10.0
            if damping > 1e6:
                break
    return pose


@njit(cache=True)
def _field_sum(field, points, x, y, yaw, ox, oy, res):
    """Return the sum of the bilinear field values of the points at pose (x, y, yaw)."""
    c, s = math.cos(yaw), math.sin(yaw)
    total = 0.0
    for i in range(points.shape[0]):
        px = x + c * points[i, 0] - s * points[i, 1]
        py = y + s * points[i, 0] + c * points[i, 1]
        total += _bilinear(field, (px - ox) / res, (py - oy) / res)[0]
    return total


@njit(cache=True)
def _curvature(field, points, pose, ox, oy, res, step):
    """
    Return the Hessian (3, 3) of the summed field at pose by central differences.

    The steps are one cell (x, y) and one yaw step: the bilinear field is piecewise
    linear, so this averages its curvature over the cell around the optimum.
    """
    h = np.array([res, res, step])
    hessian = np.zeros((3, 3))
    base = _field_sum(field, points, pose[0], pose[1], pose[2], ox, oy, res)
    for a in range(3):
        plus = pose.copy()
        minus = pose.copy()
        plus[a] += h[a]
        minus[a] -= h[a]
        hessian[a, a] = (_field_sum(field, points, plus[0], plus[1], plus[2], ox, oy, res)
                         - 2.0 * base
                         + _field_sum(field, points, minus[0], minus[1], minus[2], ox, oy,
                                      res)) / (h[a] * h[a])
        for b in range(a + 1, 3):
            total = 0.0
            for sa in (-1.0, 1.0):
                for sb in (-1.0, 1.0):
                    q = pose.copy()
                    q[a] += sa * h[a]
                    q[b] += sb * h[b]
                    total += sa * sb * _field_sum(field, points, q[0], q[1], q[2], ox, oy, res)
            hessian[a, b] = hessian[b, a] = total / (4.0 * h[a] * h[b])
    return hessian


@njit(cache=True)
def _score(distance, field, points, pose, ox, oy, res, hit_distance):
    """Return (fraction of points whose cell is within hit_distance, mean field value)."""
    rows, cols = distance.shape
    c, s = math.cos(pose[2]), math.sin(pose[2])
    hits = 0
    total = 0.0
    for i in range(points.shape[0]):
        px = pose[0] + c * points[i, 0] - s * points[i, 1]
        py = pose[1] + s * points[i, 0] + c * points[i, 1]
        col = int(math.floor((px - ox) / res))
        row = int(math.floor((py - oy) / res))
        if 0 <= row < rows and 0 <= col < cols:
            if distance[row, col] <= hit_distance:
                hits += 1
            total += field[row, col]
    n = max(points.shape[0], 1)
    return hits / n, total / n
