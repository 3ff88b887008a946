"""
Adaptive Monte Carlo localisation on a known map: nav2_amcl's filter (pure, no ROS).

Frames and units (REP-103/105): a particle is a pose (x, y m, yaw rad) of base_link in the
map frame; odometry poses are base_link in the odom frame; the laser pose is the laser
frame in base_link; yaw is counter-clockwise, wrapped to [-pi, pi). Parameter names are
nav2_amcl's (see :class:`AmclConfig`).

* Motion: nav2_amcl::OmniMotionModel, applied to all particles at once. The odometry
  delta (odom frame) since the last filter update is split into a translation
  dt = |(dx, dy)| along the bearing of travel (relative to the old odometry heading),
  a rotation dr and a strafe of 0; each particle gets them with gaussian noise of
  standard deviations sqrt(alpha3 dt^2 + alpha4 dr^2) (translation), sqrt(alpha1 dr^2 +
  alpha2 dt^2) (rotation) and sqrt(alpha4 dr^2 + alpha5 dt^2) (strafe), in its own frame.
* Sensor: the likelihood field. At most ``max_beams`` beams, evenly spread over the scan
  (first and last included), with range_min < r < range_max are used (NaN, +-inf, max
  range and too-close readings are skipped, as nav2). A beam end point at distance d
  from the nearest obstacle cell has ``pz = z_hit exp(-d^2 / (2 sigma_hit^2)) + z_rand /
  range_max``, d capped at ``laser_likelihood_max_dist``; end points off the map or on
  unknown cells count as that cap (the z_rand floor). The distance field is the exact
  Euclidean distance transform (:mod:`mecanum_navigation.costmap.distance_transform`)
  of the map (cells >= ``occupied_threshold``, 65, are obstacles; nav2 takes only 100),
  computed once per map.
* Combining beams: a particle's log-likelihood is the sum of log(pz) over the beams
  (nav2's likelihood_field_prob does this; plain likelihood_field uses an ad hoc
  1 + sum pz^3). Weights are kept as logarithms and normalised by log-sum-exp, so nothing
  underflows whatever the number of beams; each pz is floored at MIN_BEAM_LIKELIHOOD
  (and at z_rand / range_max by the model itself), so one beam that sees something not
  in the map (a person) costs a bounded amount.
  Beams are not independent and the particles are far apart compared with the width of
  this likelihood (a global localisation), so one scan could leave a single particle
  with all the weight. Hence the tempering: when the full likelihood would cut the
  effective sample size below ``update_min_ess_ratio`` (0.3) of its value, the scan's
  log-likelihoods are scaled by the largest beta < 1 that keeps that much (bisection);
  the next scans bring the rest of the evidence.
* Resampling: low-variance (systematic). It runs on every ``resample_interval``-th laser
  update (nav2's rule), and then only if the effective sample size 1 / sum w^2 is below
  half the particle count or recovery particles are due: resampling an even set only
  loses diversity. The new count is KLD-sampling's (Fox 2003, as nav2's pf.c: histogram
  bins of 0.5 m x 0.5 m x 10 deg, ``pf_err``, ``pf_z`` used as the normal quantile as
  nav2 does), between ``min_particles`` and ``max_particles``: the bins are counted on a
  shuffled systematic draw of max_particles, then exactly that many are drawn. One
  occupied bin gives min_particles (nav2: max_particles).
* Recovery (augmented MCL, Probabilistic Robotics' Augmented_MCL): ``w_slow`` and
  ``w_fast`` follow the average likelihood of each update with rates
  ``recovery_alpha_slow`` < ``recovery_alpha_fast``; a fraction max(0, 1 - w_fast /
  w_slow) of the resampled particles are drawn uniformly over the free cells. The
  average likelihood is the per-beam geometric mean of the weighted mean particle
  likelihood: it does not depend on the number of beams or particles, and the well
  placed particles dominate it, so random particles hardly lower it. Unlike nav2 the
  averages are not restarted after injecting (nav2's restart makes w_fast = w_slow at
  once, so it injects at most once per drop, too few to find a kidnapped robot). Off
  (0, 0) by default, as nav2.
* Estimate: the weighted mean of the heaviest cluster (bins connected through their 26
  neighbours, yaw bins wrapping), yaw as a circular mean; covariance of the whole set
  (x, y and the circular variance -2 ln R of yaw, cross terms with yaw 0, as nav2).
* Updates: as nav2, nothing happens until odometry has moved more than ``update_min_d``
  (in x or y of the odom frame) or ``update_min_a`` since the last filter update; the first
  scan after (re)initialisation always updates the weights, without motion.
"""

from dataclasses import dataclass, fields
import math
import numbers
from typing import Optional, Sequence, Tuple

from mecanum_control.angles import wrap_angle, wrap_angles
from mecanum_map_server.map_io import OccupancyMap
from mecanum_navigation.costmap.distance_transform import squared_distance_transform
from numba import njit
import numpy as np

Pose2D = Tuple[float, float, float]

#: OccupancyGrid values at or above this are obstacles of the likelihood field.
OCCUPIED_THRESHOLD = 65
#: Smallest likelihood of one beam (keeps its logarithm finite whatever the parameters).
MIN_BEAM_LIKELIHOOD = 1e-6
#: KLD-sampling histogram bin sizes (nav2's pf_kdtree): x, y (m) and yaw (rad).
BIN_SIZE_M = 0.5
BIN_YAW_RAD = math.radians(10.0)
YAW_BINS = 36
#: Resample only when the effective sample size is below this fraction of the count.
RESAMPLE_ESS_FRACTION = 0.5
#: nav2_amcl's default initial covariance (x, y variances m^2, yaw variance rad^2).
DEFAULT_INITIAL_COVARIANCE = np.diag([0.5 ** 2, 0.5 ** 2, (math.pi / 12.0) ** 2])
_BIN_OFFSET = 1 << 20


@dataclass(frozen=True)
class AmclConfig:
    """nav2_amcl's filter parameters (names and defaults of nav2, units SI)."""

    alpha1: float = 0.2                      # rotation noise from rotation
    alpha2: float = 0.2                      # rotation noise from translation
    alpha3: float = 0.2                      # translation noise from translation
    alpha4: float = 0.2                      # translation and strafe noise from rotation
    alpha5: float = 0.2                      # strafe noise from translation
    min_particles: int = 500
    max_particles: int = 2000
    pf_err: float = 0.05
    pf_z: float = 0.99
    recovery_alpha_slow: float = 0.0
    recovery_alpha_fast: float = 0.0
    resample_interval: int = 1
    update_min_d: float = 0.25               # m
    update_min_a: float = 0.2                # rad
    z_hit: float = 0.5
    z_rand: float = 0.5
    z_max: float = 0.05                      # accepted; max-range readings are skipped
    z_short: float = 0.05                    # accepted; unused by the likelihood field
    sigma_hit: float = 0.2                   # m
    laser_likelihood_max_dist: float = 2.0   # m
    laser_max_range: float = 100.0           # m; <= 0: the scan's range_max
    laser_min_range: float = -1.0            # m; <= 0: the scan's range_min
    max_beams: int = 60
    # Beam skipping (nav2's, for the likelihood field): a beam whose end point is within
    # beam_skip_distance of a mapped obstacle for fewer than beam_skip_threshold of the
    # particles saw something the map lacks (a person) and is left out of the update,
    # unless more than beam_skip_error_threshold of the beams would be (then all count).
    do_beamskip: bool = False
    beam_skip_distance: float = 0.5          # m
    beam_skip_threshold: float = 0.3
    beam_skip_error_threshold: float = 0.9
    # Not nav2's: one scan may cut the effective sample size to no less than this fraction
    # of what it was (the likelihood is tempered, L^beta, when it would cut more); 0: off.
    update_min_ess_ratio: float = 0.3

    def __post_init__(self):
        """Check every field; raise ValueError naming the parameter."""
        for item in fields(self):
            value = getattr(self, item.name)
            if item.type is bool:
                if not isinstance(value, bool):
                    raise ValueError(f'parameter {item.name} must be true or false, '
                                     f'got {value!r}')
            elif item.type is int:
                if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                    raise ValueError(f'parameter {item.name} must be an integer, got {value!r}')
            elif isinstance(value, bool) or not isinstance(value, numbers.Real) \
                    or not math.isfinite(value):
                raise ValueError(f'parameter {item.name} must be a finite number, '
                                 f'got {value!r}')
        for name in ('alpha1', 'alpha2', 'alpha3', 'alpha4', 'alpha5', 'update_min_d',
                     'update_min_a'):
            _require(getattr(self, name) >= 0.0, name, 'must be >= 0', getattr(self, name))
        for name in ('z_hit', 'z_rand', 'z_max', 'z_short', 'recovery_alpha_slow',
                     'recovery_alpha_fast', 'update_min_ess_ratio', 'beam_skip_threshold',
                     'beam_skip_error_threshold'):
            value = getattr(self, name)
            _require(0.0 <= value <= 1.0, name, 'must be in [0, 1]', value)
        _require(self.z_hit + self.z_rand > 0.0, 'z_hit',
                 'and z_rand must not both be 0', self.z_hit)
        for name in ('sigma_hit', 'laser_likelihood_max_dist', 'pf_err', 'pf_z',
                     'beam_skip_distance'):
            _require(getattr(self, name) > 0.0, name, 'must be > 0', getattr(self, name))
        _require(self.pf_err < 1.0, 'pf_err', 'must be < 1', self.pf_err)
        _require(self.min_particles >= 1, 'min_particles', 'must be >= 1', self.min_particles)
        _require(self.max_particles >= self.min_particles, 'max_particles',
                 f'must be >= min_particles ({self.min_particles})', self.max_particles)
        _require(self.resample_interval >= 1, 'resample_interval', 'must be >= 1',
                 self.resample_interval)
        _require(self.max_beams >= 2, 'max_beams', 'must be >= 2', self.max_beams)
        slow, fast = self.recovery_alpha_slow, self.recovery_alpha_fast
        _require((slow == 0.0 and fast == 0.0) or 0.0 < slow < fast, 'recovery_alpha_slow',
                 f'must be below recovery_alpha_fast ({fast}), both > 0 (or both 0: no '
                 'recovery)', slow)
        if self.laser_min_range > 0.0 and self.laser_max_range > 0.0:
            _require(self.laser_min_range < self.laser_max_range, 'laser_min_range',
                     f'must be below laser_max_range ({self.laser_max_range})',
                     self.laser_min_range)

    @property
    def recovery(self) -> bool:
        """Tell whether augmented-MCL recovery particles are enabled."""
        return self.recovery_alpha_fast > 0.0


def _require(condition: bool, name: str, text: str, value) -> None:
    if not condition:
        raise ValueError(f'parameter {name} {text}, got {value!r}')


@dataclass(frozen=True)
class ScanData:
    """
    One laser scan (sensor_msgs/LaserScan fields), ranges in m, angles in the laser frame.

    Beam i is at angle_min + i * angle_increment; readings may be NaN or +-inf (REP-117).
    """

    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float


@dataclass(frozen=True)
class UpdateResult:
    """What an update did: filter updated (motion + weights), resampled, beams used, why."""

    updated: bool
    resampled: bool = False
    beams_used: int = 0
    particle_count: int = 0
    reason: str = ''


@dataclass(frozen=True)
class Estimate:
    """The pose estimate (map frame), its 3x3 covariance (x, y, yaw) and its cluster."""

    pose: Pose2D
    covariance: np.ndarray
    cluster_weight: float
    cluster_count: int


# --- the likelihood field ---------------------------------------------------------------


class LikelihoodField:
    """
    The distance field of a map for the likelihood-field laser model.

    ``distances_m[row, col]``: distance (m, centre to centre) from each cell to the
    nearest obstacle cell (value >= occupied_threshold), capped at max_dist_m; unknown
    cells (values outside 0..100) hold the cap. ``free_cells``: (row, col) of the known,
    non-obstacle cells (where random particles go).
    """

    def __init__(self, occupancy_map: OccupancyMap, max_dist_m: float,
                 occupied_threshold: int = OCCUPIED_THRESHOLD):
        data = np.asarray(occupancy_map.data)
        if data.ndim != 2 or data.size == 0:
            raise ValueError(f'map data must be a non-empty 2-D grid, got shape {data.shape}')
        resolution = float(occupancy_map.resolution_m)
        origin = tuple(float(v) for v in occupancy_map.origin)
        if not (math.isfinite(resolution) and resolution > 0.0):
            raise ValueError(f'map resolution must be finite and > 0, got {resolution}')
        if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
            raise ValueError(f'map origin must be 3 finite numbers, got {origin}')
        if not (math.isfinite(max_dist_m) and max_dist_m > 0.0):
            raise ValueError(f'max_dist_m must be finite and > 0, got {max_dist_m}')
        values = data.astype(np.int16)
        known = (values >= 0) & (values <= 100)
        obstacles = known & (values >= occupied_threshold)
        distances = np.sqrt(squared_distance_transform(obstacles)) * resolution
        distances = np.minimum(distances, max_dist_m)
        distances[~known] = max_dist_m
        self.resolution_m = resolution
        self.origin = origin
        self.max_dist_m = float(max_dist_m)
        self.distances_m = distances
        self.free_cells = np.argwhere(known & ~obstacles)
        self.obstacle_count = int(obstacles.sum())

    @property
    def shape(self) -> Tuple[int, int]:
        """Return (rows, cols)."""
        return self.distances_m.shape

    def to_grid(self, xs, ys) -> Tuple[np.ndarray, np.ndarray]:
        """Return continuous (col, row) cell coordinates of map-frame points (m)."""
        ox, oy, yaw = self.origin
        dx, dy = np.asarray(xs, dtype=float) - ox, np.asarray(ys, dtype=float) - oy
        c, s = math.cos(yaw), math.sin(yaw)
        return (c * dx + s * dy) / self.resolution_m, (-s * dx + c * dy) / self.resolution_m

    def distance_at(self, xs, ys) -> np.ndarray:
        """Return the field's distance (m) at map-frame points; the cap off the map."""
        gx, gy = self.to_grid(xs, ys)
        gx, gy = np.atleast_1d(gx), np.atleast_1d(gy)
        rows, cols = self.shape
        inside = (gx >= 0) & (gy >= 0) & (gx < cols) & (gy < rows)
        out = np.full(gx.shape, self.max_dist_m)
        out[inside] = self.distances_m[gy[inside].astype(np.int64), gx[inside].astype(np.int64)]
        return out

    def random_poses(self, count: int, rng: np.random.Generator) -> np.ndarray:
        """Return (count, 3) poses uniform over the free cells, yaw uniform."""
        if len(self.free_cells) == 0:
            raise ValueError('the map has no free cell to put particles in')
        cells = self.free_cells[rng.integers(0, len(self.free_cells), count)]
        local_x = (cells[:, 1] + rng.random(count)) * self.resolution_m
        local_y = (cells[:, 0] + rng.random(count)) * self.resolution_m
        ox, oy, yaw = self.origin
        c, s = math.cos(yaw), math.sin(yaw)
        poses = np.empty((count, 3))
        poses[:, 0] = ox + c * local_x - s * local_y
        poses[:, 1] = oy + s * local_x + c * local_y
        poses[:, 2] = rng.uniform(-math.pi, math.pi, count)
        return poses


@njit(cache=True)
def _laser_in_map(x, y, yaw, laser_x, laser_y, laser_yaw, origin_x, origin_y):
    """Return the laser of a particle at (x, y, yaw): position from the map origin, cos, sin."""
    c = math.cos(yaw)
    s = math.sin(yaw)
    return (x + c * laser_x - s * laser_y - origin_x, y + s * laser_x + c * laser_y - origin_y,
            math.cos(yaw + laser_yaw), math.sin(yaw + laser_yaw))


@njit(cache=True)
def _beam_end_cell(lx, ly, ca, sa, reach, cos_b, sin_b, cos_o, sin_o, inv_res):
    """Return the (continuous) map cell column, row where a beam of length reach ends."""
    hx = lx + reach * (ca * cos_b - sa * sin_b)
    hy = ly + reach * (sa * cos_b + ca * sin_b)
    return (cos_o * hx + sin_o * hy) * inv_res, (-sin_o * hx + cos_o * hy) * inv_res


@njit(cache=True)
def _scan_log_likelihoods(xs, ys, yaws, laser_x, laser_y, laser_yaw, ranges, cos_b, sin_b,
                          table, off_map, origin_x, origin_y, cos_o, sin_o, inv_res, out):
    """out[i] = sum over beams of the log-likelihood table at particle i's beam end points."""
    rows, cols = table.shape
    for i in range(xs.shape[0]):
        lx, ly, ca, sa = _laser_in_map(xs[i], ys[i], yaws[i], laser_x, laser_y, laser_yaw,
                                       origin_x, origin_y)
        total = 0.0
        for j in range(ranges.shape[0]):
            gx, gy = _beam_end_cell(lx, ly, ca, sa, ranges[j], cos_b[j], sin_b[j], cos_o,
                                    sin_o, inv_res)
            if gx >= 0.0 and gy >= 0.0 and gx < cols and gy < rows:
                total += table[int(gy), int(gx)]
            else:
                total += off_map
        out[i] = total


@njit(cache=True)
def _beam_log_likelihoods(xs, ys, yaws, laser_x, laser_y, laser_yaw, ranges, cos_b, sin_b,
                          table, off_map, distances, skip_distance, origin_x, origin_y,
                          cos_o, sin_o, inv_res, out, agree):
    """
    Fill out[i, j], beam j's log-likelihood for particle i, and agree (beam skipping).

    agree[j] counts the particles whose beam j ends within skip_distance of a mapped
    obstacle (nav2's beam skipping).
    """
    rows, cols = table.shape
    for i in range(xs.shape[0]):
        lx, ly, ca, sa = _laser_in_map(xs[i], ys[i], yaws[i], laser_x, laser_y, laser_yaw,
                                       origin_x, origin_y)
        for j in range(ranges.shape[0]):
            gx, gy = _beam_end_cell(lx, ly, ca, sa, ranges[j], cos_b[j], sin_b[j], cos_o,
                                    sin_o, inv_res)
            if gx >= 0.0 and gy >= 0.0 and gx < cols and gy < rows:
                out[i, j] = table[int(gy), int(gx)]
                if distances[int(gy), int(gx)] < skip_distance:
                    agree[j] += 1
            else:
                out[i, j] = off_map


# --- resampling -------------------------------------------------------------------------


def low_variance_resample(weights: np.ndarray, count: int,
                          rng: np.random.Generator) -> np.ndarray:
    """
    Return ``count`` indices drawn by low-variance (systematic) resampling.

    One uniform offset u in [0, 1/count); index i is taken for every u + k / count (k =
    0..count-1) that falls in its slice of the cumulative weights, so particle i is drawn
    floor or ceil of count * w_i times. weights need not be normalised.
    """
    weights = np.asarray(weights, dtype=float)
    total = weights.sum()
    if not (weights.ndim == 1 and weights.size and np.isfinite(total) and total > 0.0
            and (weights >= 0.0).all()):
        raise ValueError('weights must be a non-empty 1-D array of finite values >= 0 with '
                         'a positive sum')
    cumulative = np.cumsum(weights / total)
    cumulative[-1] = 1.0
    points = (rng.random() + np.arange(count)) / count
    return np.minimum(np.searchsorted(cumulative, points, side='right'), weights.size - 1)


def kld_sample_limit(bins, pf_err: float, pf_z: float, min_particles: int,
                     max_particles: int):
    """
    KLD-sampling's particle count for ``bins`` occupied histogram bins (nav2's pf.c).

    n = ceil((k - 1) / (2 pf_err) * (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) pf_z)^3),
    clamped to [min_particles, max_particles]. k <= 1 gives min_particles (nav2 gives
    max_particles, which keeps a filter converged into one bin at its maximum).
    """
    k = np.asarray(bins, dtype=float)
    km1 = np.maximum(k - 1.0, 1.0)
    b = 2.0 / (9.0 * km1)
    x = 1.0 - b + np.sqrt(b) * pf_z
    n = np.ceil(km1 / (2.0 * pf_err) * x * x * x)
    n = np.clip(n, min_particles, max_particles)
    return np.where(k <= 1.0, min_particles, n).astype(np.int64)


def bin_indices(poses: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the histogram bin (ix, iy, iyaw) of each pose (0.5 m, 0.5 m, 10 deg)."""
    limit = _BIN_OFFSET - 1
    ix = np.clip(np.floor(poses[:, 0] / BIN_SIZE_M), -limit, limit).astype(np.int64)
    iy = np.clip(np.floor(poses[:, 1] / BIN_SIZE_M), -limit, limit).astype(np.int64)
    iyaw = np.floor((wrap_angles(poses[:, 2]) + math.pi) / BIN_YAW_RAD).astype(np.int64)
    return ix, iy, iyaw % YAW_BINS


def _bin_keys(ix, iy, iyaw) -> np.ndarray:
    return ((ix + _BIN_OFFSET) * (2 * _BIN_OFFSET) + (iy + _BIN_OFFSET)) * 64 + iyaw


def cluster_labels(poses: np.ndarray) -> np.ndarray:
    """
    Label each pose with its cluster: histogram bins joined through their 26 neighbours.

    Yaw bins wrap around (-pi and pi are neighbours). Labels are 0..clusters-1.
    """
    ix, iy, iyaw = bin_indices(poses)
    keys, inverse = np.unique(_bin_keys(ix, iy, iyaw), return_inverse=True)
    count = keys.size
    first = np.zeros(count, dtype=np.int64)
    first[inverse[::-1]] = np.arange(len(poses))[::-1]
    bx, by, byaw = ix[first], iy[first], iyaw[first]
    edges_a, edges_b = [], []
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dyaw in (-1, 0, 1):
                if (dx, dy, dyaw) <= (0, 0, 0):
                    continue  # each pair once (and not a bin with itself)
                neighbour = _bin_keys(bx + dx, by + dy, (byaw + dyaw) % YAW_BINS)
                position = np.minimum(np.searchsorted(keys, neighbour), count - 1)
                found = keys[position] == neighbour
                edges_a.append(np.nonzero(found)[0])
                edges_b.append(position[found])
    a, b = np.concatenate(edges_a), np.concatenate(edges_b)
    labels = np.arange(count)
    while a.size:
        before = labels.copy()
        np.minimum.at(labels, a, labels[b])
        np.minimum.at(labels, b, labels[a])
        labels = labels[labels]
        if np.array_equal(labels, before):
            break
    _, compact = np.unique(labels, return_inverse=True)
    return compact[inverse]


# --- the filter -------------------------------------------------------------------------


class ParticleFilter:
    """
    nav2_amcl's adaptive particle filter (see the module docstring for the model).

    Use: ``initialize(pose, covariance)`` (or ``global_localization()``), then
    ``update(odom_pose, scan, laser_pose)`` for every scan, then ``estimate()``.
    ``seed`` makes runs repeatable.
    """

    def __init__(self, config: AmclConfig, field: Optional[LikelihoodField] = None,
                 seed: Optional[int] = None):
        self.config = config
        self.field = field
        self.rng = np.random.default_rng(seed)
        self._poses = np.zeros((0, 3))
        self._log_weights = np.zeros(0)
        self._odom_reference: Optional[np.ndarray] = None
        self._update_count = 0
        self._table_key = None
        self._table = None
        self._off_map = 0.0
        self.w_slow = 0.0
        self.w_fast = 0.0
        self.last_tempering = 1.0
        self.last_beams_skipped = 0

    # -- state ---------------------------------------------------------------------

    @property
    def initialized(self) -> bool:
        """Tell whether the filter has particles."""
        return len(self._poses) > 0

    @property
    def poses(self) -> np.ndarray:
        """Return a copy of the particles, (N, 3) x, y, yaw in the map frame."""
        return self._poses.copy()

    @property
    def weights(self) -> np.ndarray:
        """Return the normalised weights, one per particle."""
        return np.exp(self._log_weights)

    @property
    def effective_sample_size(self) -> float:
        """Return 1 / sum w^2 (N for even weights, 1 when one particle has them all)."""
        weights = self.weights
        return float(1.0 / np.sum(weights * weights)) if weights.size else 0.0

    @property
    def odom_reference(self) -> Optional[Pose2D]:
        """Return the odometry pose of the last filter update (None before the first)."""
        if self._odom_reference is None:
            return None
        return tuple(float(v) for v in self._odom_reference)

    def set_map(self, field: LikelihoodField) -> None:
        """Use a new map (same map frame): the particles stay."""
        self.field = field
        self._table_key = None

    def set_particles(self, poses, weights=None) -> None:
        """Replace the particles (N, 3) and their weights (even if None); restart updates."""
        poses = np.array(poses, dtype=float).reshape(-1, 3)
        if not len(poses) or not np.isfinite(poses).all():
            raise ValueError('particles must be a non-empty (N, 3) array of finite poses')
        if weights is None:
            weights = np.ones(len(poses))
        weights = np.asarray(weights, dtype=float)
        if weights.shape != (len(poses),) or not np.isfinite(weights).all() \
                or (weights < 0.0).any() or weights.sum() <= 0.0:
            raise ValueError('weights must be N finite values >= 0 with a positive sum')
        poses[:, 2] = wrap_angles(poses[:, 2])
        with np.errstate(divide='ignore'):
            self._poses, self._log_weights = poses, np.log(weights / weights.sum())
        self._restart()

    def _restart(self) -> None:
        self._odom_reference = None
        self._update_count = 0
        self.w_slow = self.w_fast = 0.0

    def initialize(self, pose: Sequence[float], covariance) -> None:
        """
        Spread max_particles gaussian particles around pose with a 3x3 covariance.

        covariance (x, y, yaw; m^2, rad^2) must be finite, symmetric and positive
        semi-definite; ValueError otherwise. The next update re-weights without motion.
        """
        pose = np.asarray(pose, dtype=float)
        if pose.shape != (3,) or not np.isfinite(pose).all():
            raise ValueError(f'initial pose must be 3 finite numbers (x, y, yaw), got {pose}')
        cov = np.asarray(covariance, dtype=float)
        if cov.shape != (3, 3) or not np.isfinite(cov).all():
            raise ValueError('initial covariance must be a finite 3x3 matrix (x, y, yaw)')
        scale = max(1.0, float(np.abs(cov).max()))
        if not np.allclose(cov, cov.T, rtol=0.0, atol=1e-9 * scale):
            raise ValueError('initial covariance must be symmetric')
        values, vectors = np.linalg.eigh(cov)
        if values.min() < -1e-9 * scale:
            raise ValueError('initial covariance must be positive semi-definite '
                             f'(eigenvalues {np.round(values, 6).tolist()})')
        count = self.config.max_particles
        normal = self.rng.standard_normal((count, 3)) * np.sqrt(np.maximum(values, 0.0))
        poses = pose + normal @ vectors.T
        poses[:, 2] = wrap_angles(poses[:, 2])
        self._poses = poses
        self._log_weights = np.full(count, -math.log(count))
        self._restart()

    def global_localization(self) -> None:
        """Spread max_particles particles uniformly over the map's free space."""
        if self.field is None:
            raise ValueError('global localization needs a map')
        count = self.config.max_particles
        self._poses = self.field.random_poses(count, self.rng)
        self._log_weights = np.full(count, -math.log(count))
        self._restart()

    # -- updates -------------------------------------------------------------------

    def motion_update(self, old_odom: Sequence[float], new_odom: Sequence[float]) -> None:
        """Move every particle by the odometry change old_odom -> new_odom (OmniMotionModel)."""
        cfg = self.config
        old = np.asarray(old_odom, dtype=float)
        delta = np.asarray(new_odom, dtype=float) - old
        delta[2] = wrap_angle(float(delta[2]))
        trans = math.hypot(delta[0], delta[1])
        rot = delta[2]
        trans_sd = math.sqrt(cfg.alpha3 * trans * trans + cfg.alpha4 * rot * rot)
        rot_sd = math.sqrt(cfg.alpha1 * rot * rot + cfg.alpha2 * trans * trans)
        strafe_sd = math.sqrt(cfg.alpha4 * rot * rot + cfg.alpha5 * trans * trans)
        count = len(self._poses)
        noise = self.rng.standard_normal((count, 3))
        trans_hat = trans + trans_sd * noise[:, 0]
        rot_hat = rot + rot_sd * noise[:, 1]
        strafe_hat = strafe_sd * noise[:, 2]
        bearing = wrap_angle(math.atan2(delta[1], delta[0]) - float(old[2])) \
            + self._poses[:, 2]
        cos_b, sin_b = np.cos(bearing), np.sin(bearing)
        self._poses[:, 0] += trans_hat * cos_b + strafe_hat * sin_b
        self._poses[:, 1] += trans_hat * sin_b - strafe_hat * cos_b
        self._poses[:, 2] = wrap_angles(self._poses[:, 2] + rot_hat)

    def update(self, odom_pose: Sequence[float], scan: ScanData,
               laser_pose: Sequence[float] = (0.0, 0.0, 0.0)) -> UpdateResult:
        """
        Take one scan with the odometry pose of its time (odom frame).

        Moves the particles and weighs them when the odometry moved enough since the
        last filter update (or on the first scan after initialisation), then resamples
        when due. Raises ValueError for non-finite poses or a malformed scan; NaN or
        out-of-range readings are just skipped.
        """
        if not self.initialized:
            raise ValueError('the filter has no particles yet: initialize it first')
        if self.field is None:
            raise ValueError('the filter has no map yet')
        odom = np.asarray(odom_pose, dtype=float)
        laser = np.asarray(laser_pose, dtype=float)
        if odom.shape != (3,) or not np.isfinite(odom).all():
            raise ValueError(f'odometry pose must be 3 finite numbers, got {odom_pose}')
        if laser.shape != (3,) or not np.isfinite(laser).all():
            raise ValueError(f'laser pose must be 3 finite numbers, got {laser_pose}')
        ranges, bearings, range_max = self._select_beams(scan)
        count = len(self._poses)
        if self._odom_reference is not None:
            delta = odom - self._odom_reference
            cfg = self.config
            if not (abs(delta[0]) > cfg.update_min_d or abs(delta[1]) > cfg.update_min_d
                    or abs(wrap_angle(float(delta[2]))) > cfg.update_min_a):
                return UpdateResult(False, particle_count=count, reason='not moved enough')
            self.motion_update(self._odom_reference, odom)
        self._odom_reference = odom.copy()
        if ranges.size == 0:
            return UpdateResult(True, particle_count=count,
                                reason='no usable beam: weights unchanged')
        self._sensor_update(ranges, bearings, range_max, laser)
        self._update_count += 1
        resampled = False
        if self._update_count % self.config.resample_interval == 0:
            resampled = self.resample_if_needed()
        return UpdateResult(True, resampled, int(ranges.size), len(self._poses))

    def _select_beams(self, scan: ScanData) -> Tuple[np.ndarray, np.ndarray, float]:
        """Return the usable subsampled ranges, their bearings and the range_max in use."""
        cfg = self.config
        for name in ('angle_min', 'angle_increment', 'range_min', 'range_max'):
            value = getattr(scan, name)
            if not isinstance(value, numbers.Real) or not math.isfinite(value):
                raise ValueError(f'scan {name} must be a finite number, got {value!r}')
        range_max = float(scan.range_max)
        if cfg.laser_max_range > 0.0:
            range_max = min(range_max, cfg.laser_max_range)
        range_min = float(scan.range_min)
        if cfg.laser_min_range > 0.0:
            range_min = max(range_min, cfg.laser_min_range)
        if not range_max > 0.0:
            raise ValueError(f'scan range_max must be > 0, got {scan.range_max}')
        try:
            ranges = np.asarray(scan.ranges, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError('scan ranges must be numbers') from None
        count = ranges.size
        if count == 0:
            return ranges, ranges, range_max
        index = np.unique(np.round(np.linspace(0, count - 1, min(count, cfg.max_beams)))
                          .astype(np.int64))
        chosen = ranges[index]
        with np.errstate(invalid='ignore'):
            usable = np.isfinite(chosen) & (chosen > range_min) & (chosen < range_max)
        bearings = scan.angle_min + index[usable] * scan.angle_increment
        return chosen[usable], bearings, range_max

    def _log_table(self, range_max: float) -> np.ndarray:
        """Return log(pz) per cell (and off the map) for this range_max, cached."""
        cfg = self.config
        key = (id(self.field), range_max)
        if self._table_key != key:
            floor = cfg.z_rand / range_max
            denom = 2.0 * cfg.sigma_hit * cfg.sigma_hit
            d = self.field.distances_m
            self._table = np.log(np.maximum(cfg.z_hit * np.exp(-d * d / denom) + floor,
                                            MIN_BEAM_LIKELIHOOD))
            cap = self.field.max_dist_m
            self._off_map = math.log(max(cfg.z_hit * math.exp(-cap * cap / denom) + floor,
                                         MIN_BEAM_LIKELIHOOD))
            self._table_key = key
        return self._table

    def log_likelihoods(self, poses: np.ndarray, ranges: np.ndarray, bearings: np.ndarray,
                        range_max: float,
                        laser_pose: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
        """Return each pose's scan log-likelihood (sum over the given beams of log pz)."""
        table = self._log_table(float(range_max))
        poses = np.ascontiguousarray(poses, dtype=float)
        field = self.field
        out = np.empty(len(poses))
        yaw = field.origin[2]
        _scan_log_likelihoods(
            poses[:, 0].copy(), poses[:, 1].copy(), poses[:, 2].copy(),
            float(laser_pose[0]), float(laser_pose[1]), float(laser_pose[2]),
            np.ascontiguousarray(ranges, dtype=float), np.cos(bearings), np.sin(bearings),
            table, self._off_map, field.origin[0], field.origin[1], math.cos(yaw),
            math.sin(yaw), 1.0 / field.resolution_m, out)
        return out

    def beam_skip_log_likelihoods(self, poses: np.ndarray, ranges: np.ndarray,
                                  bearings: np.ndarray, range_max: float,
                                  laser_pose: Sequence[float] = (0.0, 0.0, 0.0)
                                  ) -> Tuple[np.ndarray, np.ndarray]:
        """
        Return each pose's scan log-likelihood over the beams kept, and the kept mask.

        nav2's beam skipping: a beam is kept when more than beam_skip_threshold of the
        poses put its end point within beam_skip_distance of a mapped obstacle; when
        more than beam_skip_error_threshold of the beams would be skipped (the poses
        disagree with the scan: lost, or a map far from the world), every beam is kept.
        """
        cfg = self.config
        table = self._log_table(float(range_max))
        poses = np.ascontiguousarray(poses, dtype=float)
        field = self.field
        per_beam = np.empty((len(poses), ranges.size))
        agree = np.zeros(ranges.size, dtype=np.int64)
        yaw = field.origin[2]
        _beam_log_likelihoods(
            poses[:, 0].copy(), poses[:, 1].copy(), poses[:, 2].copy(),
            float(laser_pose[0]), float(laser_pose[1]), float(laser_pose[2]),
            np.ascontiguousarray(ranges, dtype=float), np.cos(bearings), np.sin(bearings),
            table, self._off_map, field.distances_m, cfg.beam_skip_distance,
            field.origin[0], field.origin[1], math.cos(yaw), math.sin(yaw),
            1.0 / field.resolution_m, per_beam, agree)
        kept = agree > cfg.beam_skip_threshold * len(poses)
        if np.count_nonzero(~kept) > cfg.beam_skip_error_threshold * ranges.size:
            kept[:] = True
        self.last_beams_skipped = int(np.count_nonzero(~kept))
        self._all_beams_log_lik = per_beam.sum(axis=1)
        return per_beam[:, kept].sum(axis=1), kept

    def _sensor_update(self, ranges, bearings, range_max: float, laser: np.ndarray) -> None:
        """Weigh the particles by the scan; track w_slow / w_fast."""
        if self.config.do_beamskip:
            # The weights use the beams kept; the recovery's fit measure all of them, so
            # that a kidnapping (most beams unexplained) is still noticed.
            log_lik, _ = self.beam_skip_log_likelihoods(self._poses, ranges, bearings,
                                                        range_max, laser)
            log_total = _log_sum_exp(self._log_weights + self._all_beams_log_lik)
        else:
            log_lik = self.log_likelihoods(self._poses, ranges, bearings, range_max, laser)
            log_total = _log_sum_exp(self._log_weights + log_lik)
        self.last_tempering = tempering_exponent(self._log_weights, log_lik,
                                                 self.config.update_min_ess_ratio)
        log_w = self._log_weights + self.last_tempering * log_lik
        self._log_weights = log_w - _log_sum_exp(log_w)
        if self.config.recovery:
            # log_total = log of the weighted mean particle likelihood (prior weights sum to
            # 1); per beam, it is a likelihood of one reading, comparable between scans.
            w_avg = math.exp(log_total / ranges.size)
            cfg = self.config
            self.w_slow = w_avg if self.w_slow == 0.0 else \
                self.w_slow + cfg.recovery_alpha_slow * (w_avg - self.w_slow)
            self.w_fast = w_avg if self.w_fast == 0.0 else \
                self.w_fast + cfg.recovery_alpha_fast * (w_avg - self.w_fast)

    def recovery_fraction(self) -> float:
        """Return the fraction of random particles the next resampling draws."""
        if not self.config.recovery or self.w_slow <= 0.0:
            return 0.0
        return max(0.0, 1.0 - self.w_fast / self.w_slow)

    def resample_if_needed(self) -> bool:
        """Resample when the ESS is below half the count or recovery particles are due."""
        if self.effective_sample_size < RESAMPLE_ESS_FRACTION * len(self._poses) \
                or self.recovery_fraction() > 0.0:
            self.resample()
            return True
        return False

    def resample(self) -> None:
        """Low-variance resampling to the KLD count, with recovery particles if due."""
        cfg = self.config
        weights = self.weights
        random_fraction = self.recovery_fraction()
        # KLD count: bins counted along a shuffled draw of max_particles (as nav2 counts
        # its kd-tree leaves while drawing), random particles included.
        draw = self._poses[self.rng.permutation(
            low_variance_resample(weights, cfg.max_particles, self.rng))]
        if random_fraction > 0.0:
            mask = self.rng.random(cfg.max_particles) < random_fraction
            draw[mask] = self.field.random_poses(int(mask.sum()), self.rng)
        keys = _bin_keys(*bin_indices(draw))
        _, first = np.unique(keys, return_index=True)
        new_bin = np.zeros(keys.size, dtype=bool)
        new_bin[first] = True
        limits = kld_sample_limit(np.cumsum(new_bin), cfg.pf_err, cfg.pf_z,
                                  cfg.min_particles, cfg.max_particles)
        over = np.nonzero(np.arange(1, keys.size + 1) > limits)[0]
        count = int(over[0]) + 1 if over.size else cfg.max_particles
        count = min(max(count, cfg.min_particles), cfg.max_particles)
        random_count = min(int(self.rng.binomial(count, random_fraction)), count - 1) \
            if random_fraction else 0
        poses = self._poses[low_variance_resample(weights, count - random_count, self.rng)]
        if random_count:
            poses = np.vstack([poses, self.field.random_poses(random_count, self.rng)])
        self._poses = poses
        self._log_weights = np.full(count, -math.log(count))

    # -- the estimate ---------------------------------------------------------------

    def estimate(self) -> Estimate:
        """Return the weighted mean of the heaviest cluster and the set's covariance."""
        if not self.initialized:
            raise ValueError('the filter has no particles yet: initialize it first')
        poses, weights = self._poses, self.weights
        labels = cluster_labels(poses)
        cluster_weights = np.bincount(labels, weights)
        best = int(np.argmax(cluster_weights))
        member = labels == best
        w = weights[member] / cluster_weights[best]
        p = poses[member]
        x, y = float(w @ p[:, 0]), float(w @ p[:, 1])
        yaw = math.atan2(float(w @ np.sin(p[:, 2])), float(w @ np.cos(p[:, 2])))
        mean_xy = weights @ poses[:, :2]
        centred = poses[:, :2] - mean_xy
        covariance = np.zeros((3, 3))
        covariance[:2, :2] = (centred * weights[:, None]).T @ centred
        resultant = math.hypot(float(weights @ np.cos(poses[:, 2])),
                               float(weights @ np.sin(poses[:, 2])))
        covariance[2, 2] = -2.0 * math.log(min(max(resultant, 1e-12), 1.0))
        return Estimate((x, y, wrap_angle(yaw)), covariance,
                        float(cluster_weights[best]), int(cluster_weights.size))


def _ess_of_log_weights(log_w: np.ndarray) -> float:
    weights = np.exp(log_w - log_w.max())
    return float(weights.sum() ** 2 / (weights * weights).sum())


def tempering_exponent(log_weights: np.ndarray, log_likelihoods: np.ndarray,
                       min_ess_ratio: float, iterations: int = 24) -> float:
    """
    Return the largest beta in [0, 1] with ESS(w * L^beta) >= min_ess_ratio * ESS(w).

    1 when the full likelihood keeps that many effective particles; otherwise found by
    bisection (the ESS falls as beta grows), to within 2^-iterations.
    """
    log_weights = np.asarray(log_weights, dtype=float)
    log_likelihoods = np.asarray(log_likelihoods, dtype=float)
    target = min_ess_ratio * _ess_of_log_weights(log_weights)
    if min_ess_ratio <= 0.0 or _ess_of_log_weights(log_weights + log_likelihoods) >= target:
        return 1.0
    low, high = 0.0, 1.0
    for _ in range(iterations):
        middle = 0.5 * (low + high)
        if _ess_of_log_weights(log_weights + middle * log_likelihoods) >= target:
            low = middle
        else:
            high = middle
    return low


def _log_sum_exp(values: np.ndarray) -> float:
    """Return log(sum(exp(values))) without overflow or underflow."""
    top = float(values.max())
    if not math.isfinite(top):
        raise ValueError('no particle has a finite weight')
    return top + math.log(float(np.exp(values - top).sum()))
