"""
Pure sensor models for the simulator: 2D ray casting, a scanning lidar and a MEMS IMU.

No ROS here: numpy in, numpy out, so the models are testable and fast. Units and
frames follow REP-103 (x forward, y left, yaw counter-clockwise; metres, radians,
seconds). The world is a set of static line segments (walls, shelves, ...) plus
moving circles (people, other robots), both in the world (map/odom) frame.

Ray casting conventions (shared by every function and class below):

* A ray starts at the origin and runs along its world-frame angle. Its range is
  the distance to the first hit at ``t >= MIN_HIT_DISTANCE_M`` (1e-9 m). Hits
  closer than that are ignored, so a ray that starts ON a segment (or on a
  circle's rim) does not see that surface and continues to whatever is beyond.
* Segments are two-sided and infinitely thin. Their end points count as part of
  them, extended by ``SEGMENT_END_TOLERANCE_M`` (1e-9 m) so that walls sharing a
  corner are watertight in floating point. A ray parallel to a segment (sine of
  the angle between them below ``PARALLEL_TOLERANCE``, 1e-10), including one
  running along it, does not hit it: grazing incidence returns nothing rather
  than an ill-conditioned distance. Segments shorter than 1e-12 m are never hit.
* Circles are their rims: the first crossing of the rim at ``t >= 1e-9`` counts.
  A ray that starts inside a circle therefore hits the far side of that circle
  (as a beam leaving a body it is buried in would); tangent rays count as hits.
* No hit within ``max_range_m`` (a hit at exactly ``max_range_m`` counts) gives
  ``np.inf``. Results are never NaN.

Lidar ranges follow REP-117: a beam with no return within ``range_max`` reads
``+inf``, a return closer than ``range_min`` reads ``-inf`` (the sensor saw
something but too close to measure), a dropped beam reads ``+inf``, and valid
readings satisfy ``range_min <= r <= range_max``. Never NaN.
"""

from dataclasses import dataclass
import math
import numbers
from typing import Optional, Sequence, Tuple

import numpy as np

#: Hits closer than this along a ray are ignored (a ray starting on a surface passes it).
MIN_HIT_DISTANCE_M = 1e-9
#: Segments are extended by this length (m) at both ends (watertight corners).
SEGMENT_END_TOLERANCE_M = 1e-9
#: Segments shorter than this (m) are points, never hit.
MIN_SEGMENT_LENGTH_M = 1e-12
#: Rays whose angle to a segment has a sine below this are parallel to it: they never hit it.
PARALLEL_TOLERANCE = 1e-10
#: Standard gravity (m/s^2); a level accelerometer at rest reads +this on z (REP-145).
STANDARD_GRAVITY_M_S2 = 9.80665
#: RayCaster works on blocks of at most this many ray x segment pairs: bounded memory, and
#: 128 KiB buffers stay cache-friendly and cheap to allocate (a fresh caster stays fast).
DEFAULT_CHUNK_ELEMENTS = 1 << 14
# Segments whose closest point is within max range plus this margin are kept when pruning.
_PRUNE_MARGIN_M = 1e-6
_TWO_PI = 2.0 * math.pi


def _as_segments(segments) -> np.ndarray:
    """Return ``segments`` as a finite (M, 4) float64 array, or raise ValueError."""
    array = np.array(segments, dtype=np.float64)
    if array.size == 0:
        return np.zeros((0, 4))
    if array.ndim != 2 or array.shape[1] != 4:
        raise ValueError(
            f'segments must have shape (M, 4) as x1 y1 x2 y2, got shape {array.shape}')
    if not np.isfinite(array).all():
        raise ValueError('segments must be finite (no NaN or inf coordinates)')
    return array


def _as_circles(circles) -> np.ndarray:
    """Return ``circles`` (None allowed) as a finite (K, 3) float64 array, or raise ValueError."""
    if circles is None:
        return np.zeros((0, 3))
    array = np.asarray(circles, dtype=np.float64)
    if array.size == 0:
        return np.zeros((0, 3))
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(
            f'circles must have shape (K, 3) as x y radius, got shape {array.shape}')
    if not np.isfinite(array).all():
        raise ValueError('circles must be finite (no NaN or inf values)')
    if (array[:, 2] < 0.0).any():
        raise ValueError('circle radii must be >= 0')
    return array


def _as_angles(angles_rad) -> np.ndarray:
    """Return ``angles_rad`` as a 1-D float64 array, or raise ValueError."""
    angles = np.asarray(angles_rad, dtype=np.float64)
    if angles.ndim != 1:
        raise ValueError(f'angles_rad must be 1-D, got shape {angles.shape}')
    return angles


def _cast_circles(origin_x: float, origin_y: float, directions: np.ndarray,
                  circles: np.ndarray) -> np.ndarray:
    """
    Return the distance along each ray to the first circle rim crossed (inf for none).

    ``directions`` is (N, 2) unit vectors; ``circles`` a validated non-empty (K, 3).
    Solves |o + t d - c|^2 = r^2, i.e. t^2 + 2 b t + q = 0 with b = (o - c).d and
    q = |o - c|^2 - r^2: t = -b -/+ sqrt(b^2 - q). The nearer root is taken when it
    is ahead of the origin, else the farther one (origin inside the circle).
    """
    fx = origin_x - circles[:, 0]
    fy = origin_y - circles[:, 1]
    radius = circles[:, 2]
    q = fx * fx + fy * fy - radius * radius
    b = directions @ np.stack([fx, fy])
    disc = b * b - q
    root = np.sqrt(np.maximum(disc, 0.0))
    near = -b - root
    far = -b + root
    t = np.where(near >= MIN_HIT_DISTANCE_M, near, far)
    t = np.where((disc >= 0.0) & (t >= MIN_HIT_DISTANCE_M), t, np.inf)
    return t.min(axis=1)


class RayCaster:
    """
    Casts 2D rays against one static set of segments, plus per-call circles.

    The per-world arrays (segment starts, unit directions, lengths) are computed
    once and the work buffers are reused between calls, which makes this the fast
    way to cast repeatedly in the same world (a lidar). The reused buffers make an
    instance unsafe to share between threads; give each thread its own.

    Per call, segments entirely farther than ``max_range_m`` from the origin are
    dropped first (exact point-to-segment distance), then the remaining rays x
    segments are intersected in vectorised blocks of at most ``chunk_elements``
    pairs, so memory stays bounded in big worlds. See the module docstring for the
    hit conventions.
    """

    def __init__(self, segments: np.ndarray,
                 chunk_elements: int = DEFAULT_CHUNK_ELEMENTS) -> None:
        if isinstance(chunk_elements, bool) or not isinstance(chunk_elements, numbers.Integral) \
                or chunk_elements < 1:
            raise ValueError(f'chunk_elements must be an integer >= 1, got {chunk_elements!r}')
        segs = _as_segments(segments)
        segs.setflags(write=False)
        self._segments = segs
        self._chunk_elements = int(chunk_elements)
        self._x1 = np.ascontiguousarray(segs[:, 0])
        self._y1 = np.ascontiguousarray(segs[:, 1])
        ex = segs[:, 2] - segs[:, 0]
        ey = segs[:, 3] - segs[:, 1]
        self._length = np.hypot(ex, ey)
        # Segments shorter than MIN_SEGMENT_LENGTH_M are points: a zero direction makes
        # them "parallel" to every ray, so they are never hit.
        inv_length = np.divide(1.0, self._length, out=np.zeros_like(self._length),
                               where=self._length >= MIN_SEGMENT_LENGTH_M)
        self._ux = ex * inv_length
        self._uy = ey * inv_length
        # d x u = dx * uy - dy * ux (the sine of the ray-segment angle): one matrix product.
        self._cross_rows = np.stack([self._uy, -self._ux])
        self._end_limit = self._length + SEGMENT_END_TOLERANCE_M
        self._float_a = np.empty(0)
        self._float_b = np.empty(0)
        self._bool_a = np.empty(0, dtype=bool)
        self._bool_b = np.empty(0, dtype=bool)

    @property
    def segments(self) -> np.ndarray:
        """Return the world's segments, (M, 4) x1 y1 x2 y2, read-only."""
        return self._segments

    def cast(self, origin_x: float, origin_y: float, angles_rad: np.ndarray,
             circles: Optional[np.ndarray] = None,
             max_range_m: float = math.inf) -> np.ndarray:
        """
        Return the (N,) float64 distances to the first hit along each ray.

        ``angles_rad`` are world-frame ray angles; ``circles`` is (K, 3) x y radius
        (None or empty for none). Rays with no hit within ``max_range_m`` get np.inf.
        """
        ox = float(origin_x)
        oy = float(origin_y)
        if not (math.isfinite(ox) and math.isfinite(oy)):
            raise ValueError(f'origin must be finite, got ({ox!r}, {oy!r})')
        max_range = float(max_range_m)
        if not max_range > 0.0:
            raise ValueError(f'max_range_m must be > 0, got {max_range!r}')
        angles = _as_angles(angles_rad)
        directions = np.empty((angles.size, 2))
        np.cos(angles, out=directions[:, 0])
        np.sin(angles, out=directions[:, 1])
        hits = self._cast_segments(ox, oy, directions, max_range)
        circle_array = _as_circles(circles)
        if circle_array.shape[0] and angles.size:
            np.minimum(hits, _cast_circles(ox, oy, directions, circle_array), out=hits)
        np.putmask(hits, hits > max_range, np.inf)
        return hits

    def _buffers(self, size: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Return the four flat work buffers, grown to hold at least ``size`` items."""
        if self._float_a.size < size:
            self._float_a = np.empty(size)
            self._float_b = np.empty(size)
            self._bool_a = np.empty(size, dtype=bool)
            self._bool_b = np.empty(size, dtype=bool)
        return self._float_a, self._float_b, self._bool_a, self._bool_b

    def _cast_segments(self, ox: float, oy: float, directions: np.ndarray,
                       max_range: float) -> np.ndarray:
        """
        Return the distance along each ray to the nearest segment hit (inf for none).

        With w = p1 - o, the segment's unit direction u and the ray direction d, the
        ray meets the segment's line at t = (w x u) / (d x u), at s = (w x d) / (d x u)
        metres from p1 along the segment. A hit needs |d x u| >= PARALLEL_TOLERANCE,
        -tol <= s <= length + tol (tol = SEGMENT_END_TOLERANCE_M) and t >= 1e-9.
        """
        rays = directions.shape[0]
        hits = np.full(rays, np.inf)
        wx = self._x1 - ox
        wy = self._y1 - oy
        ux = self._ux
        uy = self._uy
        cross_rows = self._cross_rows
        end_limit = self._end_limit
        if wx.size and math.isfinite(max_range):
            # Closest point of each segment to the origin, relative to the origin.
            along = np.clip(-(wx * ux + wy * uy), 0.0, self._length)
            cx = wx + along * ux
            cy = wy + along * uy
            near = cx * cx + cy * cy <= (max_range + _PRUNE_MARGIN_M) ** 2
            if not near.all():
                keep = np.flatnonzero(near)
                wx = wx[keep]
                wy = wy[keep]
                ux = ux[keep]
                uy = uy[keep]
                cross_rows = cross_rows[:, keep]
                end_limit = end_limit[keep]
        count = wx.size
        if count == 0 or rays == 0:
            return hits
        t_numerator = wx * uy - wy * ux
        s_rows = np.stack([-wy, wx])
        block = max(1, min(rays, self._chunk_elements // count))
        float_a, float_b, bool_a, bool_b = self._buffers(block * count)
        with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
            for start in range(0, rays, block):
                stop = min(start + block, rays)
                shape = (stop - start, count)
                size = shape[0] * count
                t = float_a[:size].reshape(shape)
                s = float_b[:size].reshape(shape)
                miss = bool_a[:size].reshape(shape)
                test = bool_b[:size].reshape(shape)
                ray_block = directions[start:stop]
                np.matmul(ray_block, cross_rows, out=t)  # d x u
                np.less(t, PARALLEL_TOLERANCE, out=miss)
                np.greater(t, -PARALLEL_TOLERANCE, out=test)
                np.logical_and(miss, test, out=miss)  # (nearly) parallel
                np.matmul(ray_block, s_rows, out=s)  # w x d
                np.divide(s, t, out=s)
                np.divide(t_numerator, t, out=t)
                np.less(s, -SEGMENT_END_TOLERANCE_M, out=test)
                np.logical_or(miss, test, out=miss)
                np.greater(s, end_limit, out=test)
                np.logical_or(miss, test, out=miss)
                np.greater_equal(t, MIN_HIT_DISTANCE_M, out=test)  # False for NaN
                # miss = miss or not ahead; on booleans that is miss >= ahead.
                np.greater_equal(miss, test, out=miss)
                np.putmask(t, miss, np.inf)
                np.min(t, axis=1, out=hits[start:stop])
        return hits


def cast_rays(origin_x: float, origin_y: float, angles_rad: np.ndarray,
              segments: np.ndarray, circles: Optional[np.ndarray],
              max_range_m: float) -> np.ndarray:
    """
    Return the (N,) float64 distance to the first hit along each world-frame ray.

    ``segments`` is (M, 4) x1 y1 x2 y2, ``circles`` (K, 3) x y radius (K may be 0,
    or None). Rays with nothing within ``max_range_m`` get np.inf. One-off helper:
    to cast repeatedly in the same world, build a :class:`RayCaster` once.
    """
    return RayCaster(segments).cast(origin_x, origin_y, angles_rad, circles, max_range_m)


def _check(condition: bool, message: str) -> None:
    """Raise ValueError(message) unless ``condition`` holds."""
    if not condition:
        raise ValueError(message)


def _finite(value) -> bool:
    """Return whether ``value`` is a real, finite number (bools excluded)."""
    return (isinstance(value, numbers.Real) and not isinstance(value, bool)
            and math.isfinite(value))


@dataclass(frozen=True)
class LidarConfig:
    """
    A 2D scanning lidar (RPLIDAR A1/A2-like); the defaults are a 360-beam, 10 Hz, 12 m unit.

    Beams are evenly spaced: ``angle_increment = (angle_max - angle_min) / beams``,
    beam i at ``angle_min + i * increment``, so the last beam is at ``angle_max -
    increment``: a full circle without a duplicated beam. The LaserScan
    ``angle_max`` must therefore be reported as ``angle_min + (beams - 1) *
    increment`` (:attr:`Lidar.last_beam_angle_rad`), not this config's
    ``angle_max_rad``. Noise is additive gaussian (not proportional to range);
    each beam is independently dropped (reads +inf) with ``dropout_probability``.
    The mount fields are the pose of the laser frame in base_link.
    """

    beams: int = 360
    range_min_m: float = 0.15
    range_max_m: float = 12.0
    rate_hz: float = 10.0
    angle_min_rad: float = -math.pi
    angle_max_rad: float = math.pi
    noise_stddev_m: float = 0.01
    dropout_probability: float = 0.0
    mount_x_m: float = 0.0
    mount_y_m: float = 0.0
    mount_yaw_rad: float = 0.0

    def __post_init__(self) -> None:
        """Validate every field; raise ValueError naming the first bad one."""
        _check(isinstance(self.beams, numbers.Integral) and not isinstance(self.beams, bool)
               and self.beams >= 1,
               f'LidarConfig.beams must be an integer >= 1, got {self.beams!r}')
        for name in ('range_min_m', 'range_max_m', 'rate_hz', 'angle_min_rad', 'angle_max_rad',
                     'noise_stddev_m', 'dropout_probability', 'mount_x_m', 'mount_y_m',
                     'mount_yaw_rad'):
            value = getattr(self, name)
            _check(_finite(value), f'LidarConfig.{name} must be a finite number, got {value!r}')
        _check(self.range_min_m >= 0.0,
               f'LidarConfig.range_min_m must be >= 0, got {self.range_min_m!r}')
        _check(self.range_max_m > self.range_min_m,
               f'LidarConfig.range_max_m must be > range_min_m ({self.range_min_m!r}), '
               f'got {self.range_max_m!r}')
        _check(self.rate_hz > 0.0, f'LidarConfig.rate_hz must be > 0, got {self.rate_hz!r}')
        span = self.angle_max_rad - self.angle_min_rad
        _check(0.0 < span <= _TWO_PI + 1e-9,
               f'LidarConfig.angle_max_rad must be above angle_min_rad ({self.angle_min_rad!r})'
               f' by at most 2*pi, got {self.angle_max_rad!r}')
        _check(self.noise_stddev_m >= 0.0,
               f'LidarConfig.noise_stddev_m must be >= 0, got {self.noise_stddev_m!r}')
        _check(0.0 <= self.dropout_probability <= 1.0,
               'LidarConfig.dropout_probability must be in [0, 1], got '
               f'{self.dropout_probability!r}')


class Lidar:
    """
    Simulated scans of a :class:`LidarConfig` lidar mounted on the robot's base_link.

    Each scan is taken from a single pose (no motion skew during the sweep, even
    though ``time_increment_s`` is reported). Randomness comes from
    ``np.random.default_rng(seed)``: per scan, ``beams`` standard normals for the
    noise (only when ``noise_stddev_m > 0``) then ``beams`` uniforms for the
    dropout (only when ``dropout_probability > 0``), so the same seed and the same
    calls give identical scans. Rays are cast slightly beyond ``range_max + 4 *
    noise_stddev`` so that noise can move a return across ``range_max`` either
    way; the limits are applied after noise, in float32 (the LaserScan field type),
    so a reading equal to the message's ``range_max`` is valid.
    """

    def __init__(self, config: LidarConfig, segments: np.ndarray,
                 seed: Optional[int] = None) -> None:
        self._config = config
        self._caster = RayCaster(segments)
        self._rng = np.random.default_rng(seed)
        self._angle_increment = (config.angle_max_rad - config.angle_min_rad) / config.beams
        beam_angles = config.angle_min_rad + np.arange(config.beams) * self._angle_increment
        beam_angles.setflags(write=False)
        self._beam_angles = beam_angles
        # A little beyond range_max (noise can bring a return back in; float32 rounding
        # decides the boundary), then the limits are applied in float32.
        self._cast_range = config.range_max_m * (1.0 + 1e-6) + 4.0 * config.noise_stddev_m
        self._range_min32 = np.float32(config.range_min_m)
        self._range_max32 = np.float32(config.range_max_m)

    @property
    def config(self) -> LidarConfig:
        """Return the configuration this lidar was built with."""
        return self._config

    @property
    def beam_angles_rad(self) -> np.ndarray:
        """Return each beam's laser-frame angle in scan order (angle_min upward), read-only."""
        return self._beam_angles

    @property
    def angle_min_rad(self) -> float:
        """Return the first beam's laser-frame angle (LaserScan ``angle_min``)."""
        return float(self._config.angle_min_rad)

    @property
    def last_beam_angle_rad(self) -> float:
        """Return the last beam's angle, angle_min + (beams - 1) * increment (``angle_max``)."""
        return float(self._config.angle_min_rad
                     + (self._config.beams - 1) * self._angle_increment)

    @property
    def angle_increment_rad(self) -> float:
        """Return ``(angle_max_rad - angle_min_rad) / beams`` (LaserScan ``angle_increment``)."""
        return float(self._angle_increment)

    @property
    def scan_time_s(self) -> float:
        """Return one revolution's time, ``1 / rate_hz`` (LaserScan ``scan_time``)."""
        return 1.0 / self._config.rate_hz

    @property
    def time_increment_s(self) -> float:
        """Return ``1 / rate_hz / beams`` (LaserScan ``time_increment``)."""
        return self.scan_time_s / self._config.beams

    def scan_fields(self) -> dict:
        """Return the LaserScan metadata fields (names as in the message) as floats."""
        return {
            'angle_min': self.angle_min_rad,
            'angle_max': self.last_beam_angle_rad,
            'angle_increment': self.angle_increment_rad,
            'time_increment': self.time_increment_s,
            'scan_time': self.scan_time_s,
            'range_min': float(self._config.range_min_m),
            'range_max': float(self._config.range_max_m),
        }

    def scan(self, base_x: float, base_y: float, base_yaw: float,
             circles: Optional[np.ndarray] = None) -> np.ndarray:
        """
        Return one scan: (beams,) float32 ranges in beam order, REP-117 limits applied.

        ``base_x, base_y, base_yaw`` is the base_link pose in the world frame of the
        segments; ``circles`` (K, 3) x y radius are the moving obstacles (or None).
        """
        config = self._config
        for name, value in (('base_x', base_x), ('base_y', base_y), ('base_yaw', base_yaw)):
            if not math.isfinite(value):
                raise ValueError(f'{name} must be finite, got {value!r}')
        cos_yaw = math.cos(base_yaw)
        sin_yaw = math.sin(base_yaw)
        laser_x = base_x + cos_yaw * config.mount_x_m - sin_yaw * config.mount_y_m
        laser_y = base_y + sin_yaw * config.mount_x_m + cos_yaw * config.mount_y_m
        world_angles = self._beam_angles + (base_yaw + config.mount_yaw_rad)
        ranges = self._caster.cast(laser_x, laser_y, world_angles, circles, self._cast_range)
        if config.noise_stddev_m > 0.0:
            ranges += config.noise_stddev_m * self._rng.standard_normal(config.beams)
        out = ranges.astype(np.float32)
        np.putmask(out, out > self._range_max32, np.inf)
        np.putmask(out, out < self._range_min32, -np.inf)
        if config.dropout_probability > 0.0:
            np.putmask(out, self._rng.random(config.beams) < config.dropout_probability, np.inf)
        return out


@dataclass(frozen=True)
class ImuConfig:
    """
    A raw 6-axis MEMS IMU (MPU-6050/BNO055 raw-like) at base_link's origin, axes aligned.

    Noise stddevs are per sample (white, independent per axis). Each axis' bias is
    drawn once per run from N(0, bias_stddev) and then, if the walk intensity is
    non-zero, random-walks: over dt its change has stddev ``walk * sqrt(dt)``
    (so the walk units are rad/s per sqrt(s) and m/s^2 per sqrt(s)).
    """

    rate_hz: float = 100.0
    gyro_noise_stddev_rad_s: float = 0.005
    gyro_bias_stddev_rad_s: float = 0.002
    gyro_bias_walk_rad_s_per_sqrt_s: float = 0.0
    accel_noise_stddev_m_s2: float = 0.05
    accel_bias_stddev_m_s2: float = 0.02
    accel_bias_walk_m_s2_per_sqrt_s: float = 0.0

    def __post_init__(self) -> None:
        """Validate every field; raise ValueError naming the first bad one."""
        for name in ('rate_hz', 'gyro_noise_stddev_rad_s', 'gyro_bias_stddev_rad_s',
                     'gyro_bias_walk_rad_s_per_sqrt_s', 'accel_noise_stddev_m_s2',
                     'accel_bias_stddev_m_s2', 'accel_bias_walk_m_s2_per_sqrt_s'):
            value = getattr(self, name)
            _check(_finite(value), f'ImuConfig.{name} must be a finite number, got {value!r}')
            if name == 'rate_hz':
                _check(value > 0.0, f'ImuConfig.rate_hz must be > 0, got {value!r}')
            else:
                _check(value >= 0.0, f'ImuConfig.{name} must be >= 0, got {value!r}')


def ideal_imu_reading(body_twist: Sequence[float],
                      body_accel: Sequence[float]) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the noise- and bias-free (accel_xyz m/s^2, gyro_xyz rad/s) for planar motion.

    ``body_twist`` is (vx, vy, wz) in base_link; ``body_accel`` is (dvx/dt, dvy/dt),
    the rate of change of the body-frame velocity components (what differencing
    successive body twists gives), WITHOUT the rotational terms: this function adds
    them. The inertial acceleration in the body frame is (dvx/dt - wz * vy,
    dvy/dt + wz * vx) (e.g. +wz * vx is the centripetal term of a turn), and the
    accelerometer reads it minus gravity: z = +g.
    """
    vx, vy, wz = (float(value) for value in body_twist)
    dvx, dvy = (float(value) for value in body_accel)
    accel = np.array([dvx - wz * vy, dvy + wz * vx, STANDARD_GRAVITY_M_S2])
    gyro = np.array([0.0, 0.0, wz])
    return accel, gyro


class ImuModel:
    """
    Noisy, biased IMU samples from the base's planar motion (see :class:`ImuConfig`).

    Randomness comes from ``np.random.default_rng(seed)``: at construction the
    three gyro then the three accel biases; per sample three gyro then three accel
    noise draws, then (only for a non-zero walk intensity and dt > 0) the gyro and
    accel bias steps. The bias properties give the current biases as ground truth.
    """

    def __init__(self, config: ImuConfig = ImuConfig(), seed: Optional[int] = None) -> None:
        self._config = config
        self._rng = np.random.default_rng(seed)
        self._gyro_bias = self._rng.normal(0.0, config.gyro_bias_stddev_rad_s, 3)
        self._accel_bias = self._rng.normal(0.0, config.accel_bias_stddev_m_s2, 3)

    @property
    def config(self) -> ImuConfig:
        """Return the configuration this IMU was built with."""
        return self._config

    @property
    def period_s(self) -> float:
        """Return the nominal sample period, ``1 / rate_hz``."""
        return 1.0 / self._config.rate_hz

    @property
    def gyro_bias_rad_s(self) -> np.ndarray:
        """Return the current gyro bias, x y z (a copy)."""
        return self._gyro_bias.copy()

    @property
    def accel_bias_m_s2(self) -> np.ndarray:
        """Return the current accelerometer bias, x y z (a copy)."""
        return self._accel_bias.copy()

    def sample(self, body_twist: Sequence[float], body_accel: Sequence[float],
               dt_s: float) -> Tuple[np.ndarray, np.ndarray]:
        """
        Return one (accel_xyz m/s^2, gyro_xyz rad/s) sample, each a (3,) float64 array.

        ``body_twist`` (vx, vy, wz) and ``body_accel`` (dvx/dt, dvy/dt, without the
        rotational terms, which are added here) are as in :func:`ideal_imu_reading`.
        ``dt_s`` (>= 0) is the time since the previous sample; it only drives the
        bias random walk. At rest the reading is (0, 0, +9.80665) and (0, 0, 0) plus
        bias and noise.
        """
        dt = float(dt_s)
        if not (math.isfinite(dt) and dt >= 0.0):
            raise ValueError(f'dt_s must be finite and >= 0, got {dt_s!r}')
        config = self._config
        accel, gyro = ideal_imu_reading(body_twist, body_accel)
        gyro_noise = self._rng.normal(0.0, config.gyro_noise_stddev_rad_s, 3)
        accel_noise = self._rng.normal(0.0, config.accel_noise_stddev_m_s2, 3)
        if dt > 0.0:
            if config.gyro_bias_walk_rad_s_per_sqrt_s > 0.0:
                self._gyro_bias += self._rng.normal(
                    0.0, config.gyro_bias_walk_rad_s_per_sqrt_s * math.sqrt(dt), 3)
            if config.accel_bias_walk_m_s2_per_sqrt_s > 0.0:
                self._accel_bias += self._rng.normal(
                    0.0, config.accel_bias_walk_m_s2_per_sqrt_s * math.sqrt(dt), 3)
        return accel + self._accel_bias + accel_noise, gyro + self._gyro_bias + gyro_noise
