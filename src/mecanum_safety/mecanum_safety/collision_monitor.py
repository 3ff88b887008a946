"""
Collision monitor (pure core, no ROS): Nav2 collision_monitor's job, independent of planning.

Everything is in base_link (REP-103: x forward, y left; metres, m/s, rad/s). Sensor data
arrive as 2-D points (``scan_to_points`` turns a LaserScan into them) with the age of
their stamp; the commanded body twist (vx, vy, wz) is checked against zones around the
robot, each a polygon or a circle centred on base_link with an action:

- 'stop': at least min_points points inside -> zero twist, unless the command moves
  base_link away from every one of those points (its translation has a negative
  component toward each: p . v < 0) and does not turn (a circle zone, centred on
  base_link, may also turn: that moves no part of the footprint nearer). Nav2 stops
  every motion there, which leaves a robot that crept into the zone (a wall pushed by
  teleop) unable to back out; here it can, and only that way;
- 'slowdown': -> the twist times slowdown_ratio;
- 'limit': -> translation speed capped at linear_limit (direction kept), |wz| at
  angular_limit;
- 'approach': the zone (the footprint, usually) is moved along the commanded twist
  (the exact arc of a constant body twist, so sideways and turning motion count as
  they really move the robot) for time_before_collision s; if at least min_points
  points are inside it after t_c s, the twist is scaled by t_c / time_before_collision,
  so at the new speed the robot, on the same path, would need exactly
  time_before_collision s to touch them. t_c is found on a simulation_time_step grid
  and refined by bisection (to ~1e-4 s). Points already inside the zone at t = 0 give
  t_c = 0 (stop), as in Nav2, except for a command that escapes them as 'stop' allows
  below: then only the other points count.

As in Nav2, zones are checked in order, a 'stop' ends the search, and the most
restrictive result (lowest translation speed, then lowest |wz|) wins. A missing source
and a non-finite command give 'stop' too (with the reason). NaN/inf points are dropped.

A source that cannot be trusted gives 'stop' before any zone is looked at (its reason
names the source and what is wrong; ``MonitorResult.fault`` says it in a few words, e.g.
'scan blinded'); nothing is latched, so the next good data lets motion resume:

- stale: its stamp is more than source_timeout old (age = now - stamp > source_timeout);
- stamped in the future: more than max_future_stamp_s ahead of now (age <
  -max_future_stamp_s): such data would never go stale;
- blinded: fewer than min_valid_beam_fraction of its beams are usable
  (:func:`scan_usable_fraction`): a scan of nothing but +inf gives no points, which
  would look like a clear path;
- frozen: max_identical_scans scans in a row equal to the one before
  (:class:`ScanRepeats`): a real lidar's ranges carry noise, so a driver republishing
  one scan with new stamps shows as repeats.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple

from mecanum_safety.polygon import points_in_polygon
import numpy as np

Twist2D = Tuple[float, float, float]
ZERO: Twist2D = (0.0, 0.0, 0.0)
ACTIONS = ('stop', 'slowdown', 'limit', 'approach')
ACTION_NONE = 'none'
#: ScanRepeats: two scans differ by measurement noise, not by motion, when at least this
#: fraction of the neighbouring beams' range differences change sign (white noise: 1/2;
#: measured on the simulator's lidar in the apartment and lab: >= 0.43 standing with
#: noise, <= 0.10 for noiseless scans of any motion, walkers included).
NOISE_SIGN_CHANGE_FRACTION = 0.25
#: ... among at least this many pairs of neighbouring beams that both changed (a real
#: lidar's coarse range steps may leave many beams unchanged at rest).
NOISE_MIN_PAIRS = 10


def _number(name: str, value, low: Optional[float] = None, low_open: bool = False,
            high: Optional[float] = None) -> float:
    """Return value as float if a finite number within the bounds, else raise ValueError."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f'{name} must be a number, got {value!r}')
    value = float(value)
    too_low = low is not None and (value < low or (low_open and value == low))
    too_high = high is not None and value > high
    if not math.isfinite(value) or too_low or too_high:
        bounds = []
        if low is not None:
            bounds.append(('> ' if low_open else '>= ') + f'{low:g}')
        if high is not None:
            bounds.append(f'<= {high:g}')
        raise ValueError(f'{name} must be finite{"".join(" and " + b for b in bounds)}, '
                         f'got {value!r}')
    return value


@dataclass(frozen=True)
class Zone:
    """
    One zone of the monitor (Nav2's "polygon"): a polygon or a circle, and its action.

    points: polygon vertices (x, y) in base_link (>= 3, any orientation), or radius: a
    circle centred on base_link (exactly one of the two). min_points: points inside
    needed to act (Nav2's min_points). slowdown_ratio in [0, 1] for 'slowdown';
    linear_limit (m/s) and angular_limit (rad/s) for 'limit'; time_before_collision
    and simulation_time_step (s) for 'approach'.
    """

    name: str
    action_type: str
    points: Optional[Sequence[Tuple[float, float]]] = None
    radius: Optional[float] = None
    min_points: int = 4
    slowdown_ratio: float = 0.5
    linear_limit: float = 0.5
    angular_limit: float = 0.5
    time_before_collision: float = 2.0
    simulation_time_step: float = 0.05
    enabled: bool = True

    def __post_init__(self) -> None:
        """Validate every field (ValueError naming the zone and the field)."""
        where = f'zone {self.name!r}'
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f'zone name must be a non-empty string, got {self.name!r}')
        if self.action_type not in ACTIONS:
            raise ValueError(f'{where}: action_type must be one of {ACTIONS}, '
                             f'got {self.action_type!r}')
        if (self.points is None) == (self.radius is None):
            raise ValueError(f'{where}: give exactly one of points (a polygon) and radius')
        if self.radius is not None:
            _number(f'{where}: radius', self.radius, 0.0, low_open=True)
        else:
            try:
                vertices = np.asarray(self.points, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f'{where}: points must be a list of (x, y)') from None
            if vertices.ndim != 2 or vertices.shape[1] != 2 or vertices.shape[0] < 3 \
                    or not np.all(np.isfinite(vertices)):
                raise ValueError(f'{where}: points must be >= 3 finite (x, y) vertices, got '
                                 f'{self.points!r}')
            object.__setattr__(self, 'points', tuple(map(tuple, vertices.tolist())))
        if isinstance(self.min_points, bool) or not isinstance(self.min_points,
                                                               (int, np.integer)) \
                or self.min_points < 1:
            raise ValueError(f'{where}: min_points must be an integer >= 1, '
                             f'got {self.min_points!r}')
        _number(f'{where}: slowdown_ratio', self.slowdown_ratio, 0.0, high=1.0)
        _number(f'{where}: linear_limit', self.linear_limit, 0.0)
        _number(f'{where}: angular_limit', self.angular_limit, 0.0)
        _number(f'{where}: time_before_collision', self.time_before_collision, 0.0,
                low_open=True)
        _number(f'{where}: simulation_time_step', self.simulation_time_step, 0.0,
                low_open=True)
        if not isinstance(self.enabled, bool):
            raise ValueError(f'{where}: enabled must be a bool, got {self.enabled!r}')

    def contains(self, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """Return which points (x, y in the zone's frame) are inside (boundary included)."""
        if self.radius is not None:
            return xs * xs + ys * ys <= self.radius * self.radius
        return points_in_polygon(xs, ys, np.asarray(self.points))


@dataclass(frozen=True)
class SourceData:
    """
    One source's latest data: its points and what tells whether to trust them.

    points: (M, 2) in base_link (m). age_s: now - the data's stamp (s), signed: < 0 for
    a stamp ahead of now. usable_fraction: the fraction of its beams that gave a usable
    range (:func:`scan_usable_fraction`). identical_scans: how many scans in a row were
    equal to the one before (:class:`ScanRepeats`).
    """

    name: str
    points: np.ndarray
    age_s: float
    usable_fraction: float = 1.0
    identical_scans: int = 0


@dataclass(frozen=True)
class MonitorResult:
    """
    The allowed twist and what acted.

    action: 'none' or the action of the zone that acted (or 'stop' for untrusted data
    and bad commands); zone: that zone's name ('' when none acted); reason: a sentence
    for logs ('' when nothing acted); collision_time_s: t_c of an 'approach' that acted;
    fault: for a source that stopped the robot, its name and what is wrong ('scan
    stale', 'scan stamped in the future', 'scan blinded', 'scan frozen'), else ''.
    """

    twist: Twist2D
    action: str = ACTION_NONE
    zone: str = ''
    reason: str = ''
    collision_time_s: float = math.nan
    fault: str = ''


class CollisionMonitor:
    """Nav2's collision monitor as a plain class (see the module docstring)."""

    def __init__(self, zones: Sequence[Zone], source_timeout: float = 2.0,
                 min_valid_beam_fraction: float = 0.5, max_identical_scans: int = 5,
                 max_future_stamp_s: float = 0.1):
        """
        Check and store the zones (in order) and the source checks.

        source_timeout (s, > 0) and max_future_stamp_s (s, >= 0): how old and how far
        ahead of now a stamp may be; min_valid_beam_fraction (in [0, 1], 0: no check):
        the least fraction of usable beams; max_identical_scans (integer >= 0, 0: no
        check): the repeats that make a source frozen. Raises ValueError naming the bad one.
        """
        zones = list(zones)
        for index, zone in enumerate(zones):
            if not isinstance(zone, Zone):
                raise ValueError(f'zones[{index}] must be a Zone, not {type(zone).__name__}')
        names = [zone.name for zone in zones]
        if len(set(names)) != len(names):
            raise ValueError(f'zone names must be unique, got {names}')
        self.zones: List[Zone] = zones
        self.source_timeout = _number('source_timeout', source_timeout, 0.0, low_open=True)
        self.max_future_stamp_s = _number('max_future_stamp_s', max_future_stamp_s, 0.0)
        self.min_valid_beam_fraction = _number('min_valid_beam_fraction',
                                               min_valid_beam_fraction, 0.0, high=1.0)
        if isinstance(max_identical_scans, bool) \
                or not isinstance(max_identical_scans, (int, np.integer)) \
                or max_identical_scans < 0:
            raise ValueError('max_identical_scans must be an integer >= 0 (0: no check), '
                             f'got {max_identical_scans!r}')
        self.max_identical_scans = int(max_identical_scans)

    def process(self, twist: Sequence[float], sources: Sequence[SourceData]) -> MonitorResult:
        """Return the allowed twist for the commanded one given the sources' points."""
        try:
            command = tuple(float(v) for v in twist)
        except (TypeError, ValueError):
            command = ()
        if len(command) != 3 or not all(math.isfinite(v) for v in command):
            return MonitorResult(ZERO, 'stop', '', f'bad command {twist!r}: stopping')
        if not sources:
            return MonitorResult(ZERO, 'stop', '', 'no sensor data: stopping')
        clouds = []
        for source in sources:
            problem = self._distrust(source)
            if problem:
                kind, reason = problem
                return MonitorResult(ZERO, 'stop', '', f'{reason}: stopping',
                                     fault=f'{source.name} {kind}')
            clouds.append(_finite_points(source.points))
        points = np.concatenate(clouds) if clouds else np.zeros((0, 2))
        allowed: Twist2D = (command[0], command[1], command[2])
        result = MonitorResult(allowed)
        for zone in self.zones:
            if not zone.enabled:
                continue
            if zone.action_type == 'approach':
                t_c = collision_time(zone, command, points)
                if t_c is None or t_c >= zone.time_before_collision:
                    continue
                ratio = t_c / zone.time_before_collision
                safe = (command[0] * ratio, command[1] * ratio, command[2] * ratio)
                reason = (f'zone {zone.name!r}: collision in {t_c:.3g} s < '
                          f'{zone.time_before_collision:g} s: twist x {ratio:.3g}')
            else:
                inside = int(np.count_nonzero(zone.contains(points[:, 0], points[:, 1])))
                if inside < zone.min_points:
                    continue
                t_c = math.nan
                if zone.action_type == 'stop' and _escapes(zone, command, points):
                    continue
                safe = _zone_twist(zone, command)
                reason = f'zone {zone.name!r}: {inside} points inside: {zone.action_type}'
            if _lower(safe, result.twist):
                result = MonitorResult(safe, zone.action_type, zone.name, reason, t_c)
            if result.action == 'stop':
                break
        return result

    def _distrust(self, source: SourceData) -> Optional[Tuple[str, str]]:
        """Return (what is wrong, a sentence) for a source not to trust, else None."""
        name = source.name
        age = float(source.age_s)
        if not math.isfinite(age) or age > self.source_timeout:
            return 'stale', (f'source {name!r} data is {age:.3g} s old (source_timeout '
                             f'{self.source_timeout:g} s)')
        if age < -self.max_future_stamp_s:
            return 'stamped in the future', (
                f'source {name!r} is stamped {-age:.3g} s in the future '
                f'(max_future_stamp_s {self.max_future_stamp_s:g} s): its clock or '
                'driver is wrong')
        usable = float(source.usable_fraction)
        if not usable >= self.min_valid_beam_fraction:   # NaN too
            return 'blinded', (
                f'source {name!r}: only {_percent(usable)} of its beams are usable '
                f'(min_valid_beam_fraction {_percent(self.min_valid_beam_fraction)}): '
                'blinded, covered or invalid')
        if 0 < self.max_identical_scans <= source.identical_scans:
            return 'frozen', (
                f'source {name!r}: {source.identical_scans} identical scans in a row '
                f'(max_identical_scans {self.max_identical_scans}): its driver is frozen')
        return None


def scan_usable_fraction(ranges, angle_min: float, angle_max: float, angle_increment: float,
                         range_min: float, range_max: float) -> float:
    """
    Return the fraction of a LaserScan's beams that gave a usable range, in [0, 1].

    Usable (REP-117): finite within [range_min, range_max], or -inf (too close to
    measure: the monitor takes it as range_min). +inf (no return within range_max), NaN
    (an error) and finite ranges outside the limits are not. Raises ValueError for a
    scan that is invalid: no beams, non-finite fields, range_min < 0 or range_max <=
    range_min, angle_increment 0, angle_max not angle_min + (beams - 1) *
    angle_increment (within one increment: drivers differ on whether angle_max is the
    last beam or the end of its sector), or beams covering more than one turn.
    """
    try:
        ranges = np.asarray(ranges, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise ValueError('ranges must be a sequence of numbers (m)') from None
    beams = ranges.size
    if beams == 0:
        raise ValueError('the scan has no beams')
    for name, value in (('angle_min', angle_min), ('angle_max', angle_max),
                        ('angle_increment', angle_increment), ('range_min', range_min),
                        ('range_max', range_max)):
        _number(name, value)
    if range_min < 0.0 or range_max <= range_min:
        raise ValueError(f'range_min must be >= 0 and range_max > range_min, got '
                         f'range_min {range_min!r}, range_max {range_max!r}')
    if angle_increment == 0.0:
        raise ValueError('angle_increment is 0')
    last = angle_min + (beams - 1) * angle_increment
    if abs(last - angle_max) > abs(angle_increment) * (1.0 + 1e-6):
        raise ValueError(f'angle_max {angle_max:.6g} rad does not match angle_min '
                         f'{angle_min:.6g} + ({beams} - 1) beams x angle_increment '
                         f'{angle_increment:.6g} = {last:.6g} rad')
    if (beams - 1) * abs(angle_increment) >= 2.0 * math.pi + abs(angle_increment) * 1e-6:
        raise ValueError(f'{beams} beams of {angle_increment:.6g} rad cover more than one '
                         'turn')
    with np.errstate(invalid='ignore'):
        usable = ((ranges >= range_min) & (ranges <= range_max)) | (ranges == -np.inf)
    return float(np.count_nonzero(usable)) / beams


class ScanRepeats:
    """
    Counts one source's scans equal to the one before (a frozen driver), once armed.

    Call update() with every scan's ranges as it arrives. Ranges are compared exactly
    (NaN equal to NaN). A real lidar's ranges carry noise, so consecutive scans differ
    even while the robot stands; a noiseless one (the simulator with
    sensor_noise_scale 0) repeats itself whenever the robot and the world stand still,
    which is no fault. So repeats count only once the source has shown noise (armed,
    for good): two consecutive scans whose differences, from beam to neighbouring beam,
    change sign for at least NOISE_SIGN_CHANGE_FRACTION of the pairs of neighbours that
    both changed (white noise: one half; motion of the robot or of a walker moves runs
    of neighbouring beams the same way), among at least NOISE_MIN_PAIRS pairs. A lidar
    frozen before it ever showed noise is not noticed.
    """

    def __init__(self) -> None:
        """Start with no scan seen, not armed."""
        self.previous: Optional[np.ndarray] = None
        self.armed = False
        self.count = 0

    def update(self, ranges) -> int:
        """Take the next scan's ranges; return how many scans in a row repeat (0 unarmed)."""
        current = np.array(ranges, dtype=np.float64).ravel()
        previous, self.previous = self.previous, current
        if previous is not None and previous.shape == current.shape \
                and np.array_equal(previous, current, equal_nan=True):
            self.count = self.count + 1 if self.armed else 0
            return self.count
        self.count = 0
        if not self.armed and previous is not None and previous.shape == current.shape:
            self.armed = _noise_like(previous, current)
        return 0


def collision_time(zone: Zone, twist: Sequence[float], points: np.ndarray) -> Optional[float]:
    """
    Return when (s) the zone, moved along the body twist, first holds min_points points.

    The zone's motion is the exact arc of the constant twist from base_link at t = 0;
    None when that does not happen within time_before_collision. The first sampled
    time that has enough points inside is refined by bisection against the one before.
    """
    points = _finite_points(points)
    if points.shape[0] < zone.min_points:
        return None
    vx, vy, wz = (float(v) for v in twist)
    horizon = zone.time_before_collision
    count = int(math.ceil(horizon / zone.simulation_time_step - 1e-9))
    times = np.minimum(np.arange(count + 1) * zone.simulation_time_step, horizon)
    hits = _inside_counts(zone, vx, vy, wz, times, points) >= zone.min_points
    if hits[0] and _escapes(zone, (vx, vy, wz), points):
        outside = points[~zone.contains(points[:, 0], points[:, 1])]
        return collision_time(zone, twist, outside)
    if not np.any(hits):
        return None
    first = int(np.argmax(hits))
    if first == 0:
        return 0.0
    low, high = float(times[first - 1]), float(times[first])
    while high - low > 1e-4:
        middle = 0.5 * (low + high)
        if _inside_counts(zone, vx, vy, wz, np.array([middle]), points)[0] >= zone.min_points:
            high = middle
        else:
            low = middle
    return high


def scan_to_points(ranges, angle_min: float, angle_increment: float, range_min: float,
                   range_max: float, mount: Sequence[float] = (0.0, 0.0, 0.0),
                   too_close_as_range_min: bool = False) -> np.ndarray:
    """
    Return a LaserScan's returns as (M, 2) points in base_link (m).

    mount is the laser frame's (x m, y m, yaw rad) in base_link. Ranges that are NaN,
    +inf (REP-117: no return), below range_min or above range_max are dropped; -inf
    (REP-117: too close to measure) is dropped too, unless too_close_as_range_min, which
    puts it at range_min (the safe reading for a monitor). Raises ValueError on
    non-finite angles, range limits or mount.
    """
    for name, value in (('angle_min', angle_min), ('angle_increment', angle_increment),
                        ('range_min', range_min), ('range_max', range_max)):
        _number(name, value)
    try:
        mount_x, mount_y, mount_yaw = (_number('mount', float(v)) for v in mount)
    except (TypeError, ValueError):
        raise ValueError(f'mount must be 3 finite numbers (x, y, yaw), got {mount!r}') from None
    try:
        ranges = np.asarray(ranges, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise ValueError('ranges must be a sequence of numbers (m)') from None
    if too_close_as_range_min:
        ranges = np.where(ranges == -np.inf, range_min, ranges)
    with np.errstate(invalid='ignore'):
        keep = np.isfinite(ranges) & (ranges >= range_min) & (ranges <= range_max)
    angles = mount_yaw + angle_min + angle_increment * np.nonzero(keep)[0]
    kept = ranges[keep]
    return np.column_stack((mount_x + kept * np.cos(angles), mount_y + kept * np.sin(angles)))


# --- helpers ------------------------------------------------------------------------

def _inside_counts(zone: Zone, vx: float, vy: float, wz: float, times: np.ndarray,
                   points: np.ndarray) -> np.ndarray:
    """Return, per time, how many points are inside the zone moved along the twist."""
    theta = wz * times
    half = 0.5 * theta
    # Exact arc: displacement = R(theta / 2) (vx, vy) t sin(h) / h, h = theta / 2.
    scale = times * np.sinc(half / math.pi)
    cos_h, sin_h = np.cos(half), np.sin(half)
    cx = scale * (cos_h * vx - sin_h * vy)
    cy = scale * (sin_h * vx + cos_h * vy)
    # Points in the moved zone's frame: R(-theta) (p - c).
    dx = points[None, :, 0] - cx[:, None]
    dy = points[None, :, 1] - cy[:, None]
    cos_t, sin_t = np.cos(theta)[:, None], np.sin(theta)[:, None]
    local_x = cos_t * dx + sin_t * dy
    local_y = -sin_t * dx + cos_t * dy
    return np.count_nonzero(zone.contains(local_x, local_y), axis=1)


def _zone_twist(zone: Zone, command: Twist2D) -> Twist2D:
    """Return the twist a stop / slowdown / limit zone allows for command."""
    vx, vy, wz = command
    if zone.action_type == 'stop':
        return ZERO
    if zone.action_type == 'slowdown':
        ratio = zone.slowdown_ratio
        return vx * ratio, vy * ratio, wz * ratio
    speed = math.hypot(vx, vy)
    scale = zone.linear_limit / speed if speed > zone.linear_limit else 1.0
    return vx * scale, vy * scale, max(-zone.angular_limit, min(zone.angular_limit, wz))


def _escapes(zone: Zone, command: Twist2D, points: np.ndarray) -> bool:
    """Tell whether command moves base_link away from every point inside zone (see 'stop')."""
    vx, vy, wz = command
    if vx == 0.0 and vy == 0.0:
        return False
    if wz != 0.0 and zone.radius is None:
        return False
    inside = points[zone.contains(points[:, 0], points[:, 1])]
    return bool(np.all(inside[:, 0] * vx + inside[:, 1] * vy < 0.0))


def _lower(candidate: Twist2D, current: Twist2D) -> bool:
    """Tell whether candidate is more restrictive: slower translation, then slower turning."""
    speed_candidate = math.hypot(candidate[0], candidate[1])
    speed_current = math.hypot(current[0], current[1])
    if not math.isclose(speed_candidate, speed_current, rel_tol=0.0, abs_tol=1e-12):
        return speed_candidate < speed_current
    return abs(candidate[2]) < abs(current[2]) - 1e-12


def _percent(fraction: float) -> str:
    """Return a fraction as a percentage for messages ('49%')."""
    return f'{100.0 * fraction:.0f}%' if math.isfinite(fraction) else repr(fraction)


def _noise_like(previous: np.ndarray, current: np.ndarray) -> bool:
    """Tell whether current differs from previous by noise (see ScanRepeats)."""
    with np.errstate(invalid='ignore'):
        change = current - previous
    sign = np.sign(np.where(np.isfinite(change), change, 0.0))
    both = (sign[:-1] != 0.0) & (sign[1:] != 0.0)
    pairs = int(np.count_nonzero(both))
    if pairs < NOISE_MIN_PAIRS:
        return False
    flips = int(np.count_nonzero(both & (sign[:-1] != sign[1:])))
    return flips >= NOISE_SIGN_CHANGE_FRACTION * pairs


def _finite_points(points) -> np.ndarray:
    """Return points as an (M, 2) float array without rows holding NaN or inf."""
    try:
        array = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError('points must be an (M, 2) array of (x, y) in metres') from None
    if array.size == 0:
        return array.reshape(0, 2)
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f'points must be an (M, 2) array of (x, y), got shape {array.shape}')
    return array[np.all(np.isfinite(array), axis=1)]
