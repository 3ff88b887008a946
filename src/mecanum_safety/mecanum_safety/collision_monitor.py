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
restrictive result (lowest translation speed, then lowest |wz|) wins. A source whose
data is older than source_timeout, a missing source and a non-finite command give
'stop' too (with the reason). NaN/inf points are dropped.
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
    """Points (M x 2, base_link, m) of one source and the age of their stamp (s)."""

    name: str
    points: np.ndarray
    age_s: float


@dataclass(frozen=True)
class MonitorResult:
    """
    The allowed twist and what acted.

    action: 'none' or the action of the zone that acted (or 'stop' for stale data and
    bad commands); zone: that zone's name ('' when none acted); reason: a sentence for
    logs ('' when nothing acted); collision_time_s: t_c of an 'approach' that acted.
    """

    twist: Twist2D
    action: str = ACTION_NONE
    zone: str = ''
    reason: str = ''
    collision_time_s: float = math.nan


class CollisionMonitor:
    """Nav2's collision monitor as a plain class (see the module docstring)."""

    def __init__(self, zones: Sequence[Zone], source_timeout: float = 2.0):
        """Check and store the zones (in order) and the data timeout (s)."""
        zones = list(zones)
        for index, zone in enumerate(zones):
            if not isinstance(zone, Zone):
                raise ValueError(f'zones[{index}] must be a Zone, not {type(zone).__name__}')
        names = [zone.name for zone in zones]
        if len(set(names)) != len(names):
            raise ValueError(f'zone names must be unique, got {names}')
        self.zones: List[Zone] = zones
        self.source_timeout = _number('source_timeout', source_timeout, 0.0, low_open=True)

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
            age = float(source.age_s)
            if not math.isfinite(age) or age > self.source_timeout:
                return MonitorResult(ZERO, 'stop', '', f'source {source.name!r} data is '
                                     f'{age:.3g} s old (source_timeout '
                                     f'{self.source_timeout:g} s): stopping')
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
