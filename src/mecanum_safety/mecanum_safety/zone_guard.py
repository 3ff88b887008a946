"""
Zone guard (pure core, no ROS): keep the commanded motion inside the authorised zone.

The last stage of the command chain scales every commanded body twist (vx, vy, wz;
base_link, REP-103: m/s, rad/s) by one factor s in [0, 1] so that the robot's footprint
(a circle of ``footprint_radius_m`` about base_link) stays in the authorised zone
(:mod:`mecanum_safety.zone`, map frame) with a margin.

The rule (:func:`guard_scale`): the footprint centre is predicted along the scaled twist,
held constant for ``horizon_s`` (the exact arc of a constant body twist,
:func:`integrate_twist`), sampled every ``SAMPLE_STEP_M`` of travel and every
``SAMPLE_STEP_RAD`` of heading. The motion is admissible when every sampled centre keeps
a clearance (:meth:`Zone.clearance`, signed distance to the border) of at least
``min(footprint_radius_m + margin_m, current clearance)``: so motion that keeps or
increases the clearance is always allowed (back inward from the margin band, or even
from outside the zone; along the border at the margin; pure rotation, which does not
move a circle about base_link). The largest admissible s is returned: the robot slows
down as it nears the border (speed about gap / horizon_s) and stops at radius + margin
from it (a twist that would move less than ``MIN_TRAVEL_M`` over the horizon is a stop).
s = 0 is always admissible, and the returned s is checked admissible again before it is
returned. Between two samples a path can dip below the required clearance by at most
about 1e-4 m (an arc of radius 0.1 m grazing the border, by its sagitta; a line passing
a vertex 0.2 m away, by 6e-5 m): a few thousandths of the usual margin.

Scaling a constant twist by s only changes the speed along the same path: the pose at
time t under s * twist is the pose at s * t under the twist. So the paths of all the
scales are prefixes of the unscaled one; it is sampled once (on a grid of its own path
parameter, the same for every scale) up to the first sample that breaks the rule, and
the end point is refined between that sample and the one before (on finer and finer
grids, a search like a bisection but vectorised). The path of a turning twist repeats
after one turn, so at most one turn is sampled.

The margin widens with the localisation's uncertainty (:func:`guard_margin`):
``margin_m + covariance_factor * sigma``, capped at ``max_margin_m``, where sigma is the
standard deviation of the x-y position covariance along the normals of the border edges
within reach (:func:`sigma_toward_border`; along the worst direction, :func:`sigma_xy`,
near a vertex). In a corridor along a wall the localisation is unsure along it and sure
across it: the worst direction's sigma put the margin band over the corridor's middle,
where the guard then stopped every command with the least drift toward the wall.

robot_controller checks a whole open-loop motion with :func:`path_stays_inside` (every
sampled pose's footprint inside with the margin), whose end pose is
:func:`integrate_twist` of the same motion.
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence, Tuple, Union

from mecanum_control.angles import wrap_angle
from mecanum_safety.zone import Zone
import numpy as np

Pose = Tuple[float, float, float]
Twist2D = Tuple[float, float, float]

#: Largest travel (m) of the footprint centre between two samples of a predicted path.
SAMPLE_STEP_M = 0.01
#: Largest heading change (rad) between two samples (tight arcs bend between samples).
SAMPLE_STEP_RAD = 0.1
#: Clearances (m) this much below the required one still count as keeping it (rounding).
TOLERANCE_M = 1e-9
#: Samples evaluated at once (a path is sampled chunk by chunk up to its first violation).
CHUNK_SAMPLES = 512
#: Samples after which a path not yet decided is cut there. Unreachable in practice: a
#: path leaves a zone, or closes its one turn, within about pi times the zone's size of
#: travel (6,000 samples for a 20 m zone).
MAX_SAMPLES = 200_000
#: Where a path first breaks the rule is refined between two samples on grids of
#: REFINE_POINTS, REFINE_ROUNDS times (to 65^-4 of one sample: under 1e-9 m).
REFINE_POINTS = 64
REFINE_ROUNDS = 4
#: Travel (m) over the horizon below which a scaled command is a stop (no creeping).
MIN_TRAVEL_M = 1e-4

REASON_CLEAR = 'clear'
REASON_APPROACHING = 'approaching the border'
REASON_AT_BORDER = 'at the border'
REASON_OUTSIDE = 'outside the zone'
REASON_INVALID_COMMAND = 'invalid command'
REASON_INVALID_POSE = 'invalid pose'


@dataclass(frozen=True)
class GuardResult:
    """
    What the guard decided for one command.

    scale: the factor (in [0, 1]) for the whole twist. reason: REASON_CLEAR (scale 1),
    REASON_APPROACHING (0 < scale < 1), REASON_AT_BORDER or REASON_OUTSIDE (scale 0, the
    centre inside or outside the zone), REASON_INVALID_COMMAND or REASON_INVALID_POSE
    (scale 0). clearance_m: the centre's current signed distance to the border (m; nan
    when unknown). required_m: the clearance every predicted pose keeps (m).
    """

    scale: float
    reason: str
    clearance_m: float = math.nan
    required_m: float = math.nan

    def gap_m(self, footprint_radius_m: float) -> float:
        """Return the footprint's distance to the border now (m; < 0: it overlaps it)."""
        return self.clearance_m - footprint_radius_m


def integrate_twists(pose: Pose, vx: float, vy: float, wz: float,
                     times_s: Union[Sequence[float], np.ndarray]
                     ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return (xs, ys, yaws) of the poses reached from pose under a constant body twist.

    The exact arc (REP-103; pose x, y in m, yaw in rad; twist m/s, rad/s), at each time
    of times_s (s, array). Yaws are not wrapped.
    """
    x0, y0, yaw0 = (float(v) for v in pose)
    t = np.asarray(times_s, dtype=np.float64)
    theta = wz * t
    small = np.abs(theta) < 1e-4
    safe = np.where(small, 1.0, theta)
    theta2 = theta * theta
    # sin(theta)/theta and (1 - cos(theta))/theta, with their series near 0.
    sin_term = np.where(small, 1.0 - theta2 / 6.0 + theta2 * theta2 / 120.0,
                        np.sin(safe) / safe)
    cos_term = np.where(small, theta / 2.0 - theta * theta2 / 24.0,
                        2.0 * np.sin(0.5 * safe) ** 2 / safe)
    dx = (vx * sin_term - vy * cos_term) * t
    dy = (vx * cos_term + vy * sin_term) * t
    cos_yaw, sin_yaw = math.cos(yaw0), math.sin(yaw0)
    return (x0 + cos_yaw * dx - sin_yaw * dy, y0 + sin_yaw * dx + cos_yaw * dy,
            yaw0 + theta)


def integrate_twist(pose: Pose, vx: float, vy: float, wz: float, t: float) -> Pose:
    """
    Return the pose (x, y, yaw; yaw wrapped to [-pi, pi)) after t s of a constant twist.

    The exact arc of the body twist (vx, vy, wz) from pose (map frame; m, rad), as the
    guard and :func:`path_stays_inside` predict it.
    """
    xs, ys, yaws = integrate_twists(pose, vx, vy, wz, np.array([float(t)]))
    yaw = wrap_angle(float(yaws[0]))
    return float(xs[0]), float(ys[0]), yaw


def xy_block(covariance: Sequence[float]) -> Tuple[float, float, float]:
    """
    Return (xx, xy, yy) of the x-y position covariance (m^2), symmetrised.

    covariance: a row-major 6x6 pose covariance (36 values, x y z roll pitch yaw, as in
    geometry_msgs/PoseWithCovariance) or a 2x2 x-y block (4 values); ValueError else.
    """
    values = np.asarray(covariance, dtype=np.float64).ravel()
    if values.size == 36:
        xx, xy, yx, yy = values[0], values[1], values[6], values[7]
    elif values.size == 4:
        xx, xy, yx, yy = values
    else:
        raise ValueError(f'covariance must have 36 (6x6) or 4 (2x2) values, got {values.size}')
    return float(xx), float(0.5 * (xy + yx)), float(yy)


def sigma_xy(covariance: Sequence[float]) -> float:
    """
    Return the position standard deviation (m) along the worst direction.

    covariance: as :func:`xy_block`. The result is the square root of the larger
    eigenvalue of the x-y block; nan if it is not finite, inf if the block is not a
    covariance (negative variance).
    """
    xx, off, yy = xy_block(covariance)
    if not all(math.isfinite(v) for v in (xx, off, yy)):
        return math.nan
    largest = 0.5 * (xx + yy) + math.hypot(0.5 * (xx - yy), off)
    if xx < 0.0 or yy < 0.0 or largest < 0.0:
        return math.inf
    return math.sqrt(largest)


def sigma_toward_border(zone: Zone, x: float, y: float, covariance: Sequence[float],
                        reach_m: float) -> float:
    """
    Return the position standard deviation (m) in the directions that matter at (x, y).

    What brings the footprint nearer a straight border edge is the position error along
    that edge's normal, sqrt(n^T C n), not along the worst direction: in a corridor
    along a wall the localisation is often unsure along the corridor and sure across
    it. The result is the largest of those over the border edges within reach_m of
    (x, y) (m, map frame; the guard passes the travel over its horizon plus the
    footprint radius plus the margin of the worst direction, so no other edge can come
    within the required clearance). Where a vertex is within reach_m (the error toward a
    corner has no one direction), or no edge is, it is :func:`sigma_xy`, the worst
    direction. nan / inf as sigma_xy for an unusable covariance.
    """
    worst = sigma_xy(covariance)
    if not math.isfinite(worst) or not (math.isfinite(x) and math.isfinite(y)):
        return worst
    edges = zone.edges()
    x1, y1, x2, y2 = edges[:, 0], edges[:, 1], edges[:, 2], edges[:, 3]
    dx, dy = x2 - x1, y2 - y1
    length = np.hypot(dx, dy)
    vertex_distance = np.hypot(x1 - x, y1 - y)
    if np.any(vertex_distance <= reach_m):
        return worst
    t = np.clip(((x - x1) * dx + (y - y1) * dy) / np.maximum(length * length, 1e-18),
                0.0, 1.0)
    near = np.hypot(x1 + t * dx - x, y1 + t * dy - y) <= reach_m
    if not np.any(near):
        return worst
    nx, ny = -dy[near] / length[near], dx[near] / length[near]
    xx, off, yy = xy_block(covariance)
    variance = float(np.max(nx * nx * xx + 2.0 * nx * ny * off + ny * ny * yy))
    return math.sqrt(max(variance, 0.0))


def guard_margin(margin_m: float, covariance_factor: float, sigma_xy_m: float,
                 max_margin_m: float) -> float:
    """
    Return the margin (m): margin_m + covariance_factor * sigma_xy_m, at most max_margin_m.

    An unknown (nan) or infinite sigma_xy_m gives max_margin_m; never less than margin_m
    (unless max_margin_m is).
    """
    if not math.isfinite(sigma_xy_m):
        return float(max_margin_m)
    return float(min(margin_m + covariance_factor * max(sigma_xy_m, 0.0), max_margin_m))


def _finite(*values: float) -> bool:
    return all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
               and math.isfinite(v) for v in values)


def _check_number(name: str, value: float, minimum: float = 0.0) -> float:
    if not _finite(value) or value < minimum:
        raise ValueError(f'{name} must be a finite number >= {minimum:g}, got {value!r}')
    return float(value)


def _parameter_step(vx: float, vy: float, wz: float) -> float:
    """Return the path parameter (s of the unscaled twist) between two samples; inf: one."""
    speed = math.hypot(vx, vy)
    step = math.inf
    if speed > 0.0:
        step = SAMPLE_STEP_M / speed
    if wz != 0.0:
        step = min(step, SAMPLE_STEP_RAD / abs(wz))
    return step


def _path_end(wz: float, end_s: float) -> float:
    """Return the path parameter past which a path only repeats (one turn at most)."""
    if wz == 0.0:
        return end_s
    return min(end_s, 2.0 * math.pi / abs(wz))


class _Path:
    """The samples of one constant-twist path from a pose: clearance by path parameter."""

    def __init__(self, zone: Zone, pose: Pose, twist: Twist2D):
        self.zone = zone
        self.pose = pose
        self.twist = twist
        self.step = _parameter_step(*twist)

    def clearance_at(self, times_s: np.ndarray) -> np.ndarray:
        xs, ys, _ = integrate_twists(self.pose, *self.twist, times_s)
        return self.zone.clearance(xs, ys)

    def first_violation(self, end_s: float,
                        required_m: float) -> Optional[Tuple[float, float]]:
        """
        Return (last good, first bad) path parameters, or None if the path keeps the rule.

        The samples are k * step for k * step < end_s, then end_s itself.
        A sample breaks the rule when its clearance is below required_m - TOLERANCE_M.
        """
        threshold = required_m - TOLERANCE_M
        previous = 0.0
        start = 0
        while True:
            if start >= MAX_SAMPLES:
                return previous, previous   # undecided so far: cut the path here
            if self.step >= end_s:   # (inf for a path that does not move)
                times = np.array([0.0])
                last_chunk = True
            else:
                indices = np.arange(start, start + CHUNK_SAMPLES, dtype=np.float64)
                times = indices * self.step
                inside = times < end_s
                last_chunk = not bool(inside[-1])
                times = times[inside]
            if last_chunk:
                times = np.append(times, end_s)
            if times.size:
                bad = np.flatnonzero(self.clearance_at(times) < threshold)
                if bad.size:
                    index = int(bad[0])
                    return (float(times[index - 1]) if index else previous,
                            float(times[index]))
                previous = float(times[-1])
            if last_chunk:
                return None
            start += CHUNK_SAMPLES


def _admissible(zone: Zone, pose: Pose, twist: Twist2D, scale: float, horizon_s: float,
                required_m: float) -> bool:
    """Check the path of scale * twist over horizon_s on its own (the result's proof)."""
    if scale == 0.0:
        return True
    scaled = (scale * twist[0], scale * twist[1], scale * twist[2])
    path = _Path(zone, pose, scaled)
    return path.first_violation(_path_end(scaled[2], horizon_s), required_m) is None


def guard_scale(zone: Zone, pose: Pose, twist: Twist2D, footprint_radius_m: float,
                margin_m: float, horizon_s: float) -> GuardResult:
    """
    Return the largest admissible scale for twist at pose, and why (see the module doc).

    zone: the authorised zone (map frame). pose: (x, y, yaw) of base_link in the map
    frame (m, rad). twist: the commanded body twist (vx, vy, wz; m/s, rad/s).
    footprint_radius_m (> 0), margin_m (>= 0): the footprint circle and the distance
    (m) kept from the border. horizon_s (> 0): how far ahead (s) the motion is checked.
    A non-finite twist gives scale 0 (REASON_INVALID_COMMAND), a non-finite pose
    scale 0 (REASON_INVALID_POSE). Raises ValueError for bad radius, margin or horizon.
    """
    radius = _check_number('footprint_radius_m', footprint_radius_m)
    margin = _check_number('margin_m', margin_m)
    horizon = _check_number('horizon_s', horizon_s)
    if radius <= 0.0 or horizon <= 0.0:
        raise ValueError(f'footprint_radius_m and horizon_s must be > 0, got {radius!r} and '
                         f'{horizon!r}')
    if len(twist) != 3 or not _finite(*twist):
        return GuardResult(0.0, REASON_INVALID_COMMAND)
    if len(pose) != 3 or not _finite(*pose):
        return GuardResult(0.0, REASON_INVALID_POSE)
    twist = (float(twist[0]), float(twist[1]), float(twist[2]))
    pose = (float(pose[0]), float(pose[1]), float(pose[2]))
    clearance = float(zone.clearance(np.array([pose[0]]), np.array([pose[1]]))[0])
    required = min(radius + margin, clearance)

    def result(scale: float) -> GuardResult:
        if scale >= 1.0:
            return GuardResult(1.0, REASON_CLEAR, clearance, required)
        if scale > 0.0:
            return GuardResult(scale, REASON_APPROACHING, clearance, required)
        return GuardResult(0.0, REASON_AT_BORDER if clearance >= 0.0 else REASON_OUTSIDE,
                           clearance, required)

    if twist[0] == 0.0 and twist[1] == 0.0:
        return result(1.0)   # rotation (or nothing): the footprint circle does not move
    path = _Path(zone, pose, twist)
    violation = path.first_violation(_path_end(twist[2], horizon), required)
    if violation is None:
        return result(1.0)
    good, bad = violation
    candidates = []
    if bad > good:
        # Refine the end between the last good sample and the first bad one, a grid of
        # REFINE_POINTS at a time (exactly the required clearance here: the tolerance is
        # for rounding, not to be used up).
        low, high = good, bad
        for _ in range(REFINE_ROUNDS):
            grid = np.linspace(low, high, REFINE_POINTS + 2)[1:-1]
            below = np.flatnonzero(path.clearance_at(grid) < required)
            first = int(below[0]) if below.size else grid.size
            low, high = (grid[first - 1] if first else low), (
                grid[first] if first < grid.size else high)
            low, high = float(low), float(high)
        candidates.append(low)
    candidates.append(good)
    speed = math.hypot(twist[0], twist[1])
    for end in candidates:
        if end * speed < MIN_TRAVEL_M:
            break
        scale = min(max(end / horizon, 0.0), 1.0)
        if _admissible(zone, pose, twist, scale, horizon, required):
            return result(scale)
    return result(0.0)


def path_stays_inside(zone: Zone, pose: Pose, vx: float, vy: float, wz: float,
                      duration_s: float, radius_m: float,
                      margin_m: float) -> Tuple[bool, str]:
    """
    Return whether a whole open-loop motion keeps the footprint inside the zone, and why.

    The motion: the body twist (vx, vy, wz; m/s, rad/s) held for duration_s from pose
    (x, y, yaw in the map frame), on the exact arc (its end pose is
    :func:`integrate_twist` (pose, vx, vy, wz, duration_s)). Every sampled pose
    (every SAMPLE_STEP_M of travel and SAMPLE_STEP_RAD of heading, the start and the
    end included) must keep its footprint circle (radius_m) margin_m inside the zone:
    clearance >= radius_m + margin_m, or, from a start nearer the border than that, no
    nearer than at the start (the guard's rule: back inward, along the border and on the
    spot are always allowed). Returns (True, '') or (False, a sentence saying
    where the footprint would leave it); raises ValueError for a bad radius_m or margin_m.
    """
    if not _finite(vx, vy, wz, duration_s) or duration_s < 0.0:
        return False, (f'invalid motion: twist ({vx}, {vy}, {wz}) for {duration_s} s '
                       '(must be finite, duration >= 0)')
    if len(pose) != 3 or not _finite(*pose):
        return False, f'invalid pose {tuple(pose)}'
    radius = _check_number('radius_m', radius_m)
    margin = _check_number('margin_m', margin_m)
    twist = (float(vx), float(vy), float(wz))
    pose = (float(pose[0]), float(pose[1]), float(pose[2]))
    start = float(zone.clearance(np.array([pose[0]]), np.array([pose[1]]))[0])
    # The guard's rule: a robot already nearer than radius + margin (the guard stopped it
    # there, with some overshoot) may still move in any way that gets no nearer.
    required = min(radius + margin, start)
    if twist[0] == 0.0 and twist[1] == 0.0:
        return True, ''
    path = _Path(zone, pose, twist)
    violation = path.first_violation(_path_end(twist[2], float(duration_s)), required)
    if violation is None:
        return True, ''
    bad_s = violation[1]
    x, y, _ = integrate_twist(pose, *twist, bad_s)
    clearance = float(zone.clearance(np.array([x]), np.array([y]))[0])
    where = ('out of the authorised zone' if clearance < radius
             else f'within {margin:.2f} m of the border of the authorised zone')
    return False, (f'the footprint would come {where} at ({x:.2f}, {y:.2f}) after '
                   f'{bad_s:.2f} s of the {float(duration_s):.2f} s motion')


@dataclass(frozen=True)
class ZoneGuard:
    """
    The guard's settings: one call per command (:meth:`step`).

    zone: the authorised zone, None for none (every command passes). The others are the
    node's parameters of the same names (m, s; see config/zone_guard.yaml); ValueError
    names the wrong one.
    """

    zone: Optional[Zone]
    footprint_radius_m: float
    horizon_s: float = 1.0
    margin_m: float = 0.05
    covariance_factor: float = 2.0
    max_margin_m: float = 0.5

    def __post_init__(self):
        """Check every setting (ValueError naming it)."""
        for name in ('footprint_radius_m', 'horizon_s'):
            value = getattr(self, name)
            if not _finite(value) or value <= 0.0:
                raise ValueError(f'{name} must be a finite number > 0, got {value!r}')
        for name in ('margin_m', 'covariance_factor', 'max_margin_m'):
            _check_number(name, getattr(self, name))
        if self.max_margin_m < self.margin_m:
            raise ValueError(f'max_margin_m ({self.max_margin_m!r}) must be >= margin_m '
                             f'({self.margin_m!r})')

    def margin(self, sigma_xy_m: float) -> float:
        """Return the distance (m) kept from the border for a localisation sigma_xy_m (m)."""
        return guard_margin(self.margin_m, self.covariance_factor, sigma_xy_m,
                            self.max_margin_m)

    def sigma(self, pose: Pose, twist: Twist2D, covariance: Sequence[float]) -> float:
        """
        Return the localisation's standard deviation (m) the margin uses at pose.

        :func:`sigma_toward_border` of the covariance within the reach of this step:
        the travel over horizon_s, the footprint radius and the worst direction's margin.
        """
        worst = sigma_xy(covariance)
        if self.zone is None or len(twist) != 3 or not _finite(*twist) or len(pose) != 3 \
                or not _finite(*pose) or not math.isfinite(worst):
            return worst
        reach = (math.hypot(twist[0], twist[1]) * self.horizon_s + self.footprint_radius_m
                 + self.margin(worst))
        return sigma_toward_border(self.zone, float(pose[0]), float(pose[1]), covariance,
                                   reach)

    def step(self, pose: Pose, twist: Twist2D, sigma_xy_m: float = 0.0,
             covariance: Optional[Sequence[float]] = None) -> GuardResult:
        """
        Return the decision for twist at pose.

        The margin grows with the localisation's uncertainty: sigma_xy_m (m), or, when
        the position covariance is given (36 or 4 values, see :func:`xy_block`), its
        sigma toward the border (:meth:`sigma`), which then replaces sigma_xy_m.
        """
        if self.zone is None:
            if len(twist) != 3 or not _finite(*twist):
                return GuardResult(0.0, REASON_INVALID_COMMAND)
            return GuardResult(1.0, REASON_CLEAR)
        if covariance is not None:
            sigma_xy_m = self.sigma(pose, twist, covariance)
        return guard_scale(self.zone, pose, twist, self.footprint_radius_m,
                           self.margin(sigma_xy_m), self.horizon_s)
