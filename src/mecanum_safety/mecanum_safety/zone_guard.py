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
``min(footprint_radius_m + margin_m, current clearance)``: so, with the footprint inside
the zone, motion that keeps or increases the clearance is always allowed (back inward
from the margin band; along the border at the margin; pure rotation, which does not
move a circle about base_link). The largest admissible s is returned: the robot slows
down as it nears the border (speed about gap / horizon_s) and stops at radius + margin
from it (a twist that would move less than ``MIN_TRAVEL_M`` over the horizon is a stop).
s = 0 is always admissible, and the returned s is checked admissible again before it is
returned. Between two samples a path can dip below the required clearance by at most
about 1e-4 m (an arc of radius 0.1 m grazing the border, by its sagitta; a line passing
a vertex 0.2 m away, by 6e-5 m): a few thousandths of the usual margin.

Outside the zone (the footprint crosses the border: clearance < footprint_radius_m,
whether the centre is out or in) the robot may only move back in (REASON_BACK_IN); a
command that does not bring it in is stopped (REASON_OUTSIDE): outward, parallel to the
border, or in and then along it. The rule, between consecutive samples (1 cm of travel
apart at most): each sample's clearance is at least ``min(footprint_radius_m +
margin_m, the previous sample's + INWARD_MIN_SLOPE * the distance between them)``: the
footprint gets at least 1 mm further in per cm of travel (heading within about 84
degrees of straight in), until it is radius + margin inside, and from there on the
usual rule. Samples keep getting further in; between two of them a path crossing a
ridge of the distance (the middle of an exclusion, say) can fall back from its peak by
at most (1 - INWARD_MIN_SLOPE) / 2 of a sample step, 4.5 mm. Turning on the spot does
not move the footprint circle: allowed, inside or out (REASON_TURNING_OUTSIDE).

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

The localisation's health (:func:`localisation_problem`): a pose with NaN or inf, a pose
covariance with NaN or inf, not symmetric or not positive semi-definite, or a position
standard deviation (worst direction) above ``max_position_sigma_m`` is unhealthy; a
widened margin does not cover a localisation that lost track (the margin is capped).
While it is unhealthy (:meth:`ZoneGuard.step` with ``localisation``) every command that
moves the footprint is stopped (REASON_LOCALISATION); turning on the spot is allowed
(REASON_TURNING_UNHEALTHY): it does not move the footprint circle, and it is what lets
amcl update (it updates after ``update_min_a`` of rotation) and recover.

robot_controller checks a whole open-loop motion with :func:`path_stays_inside` (every
sampled pose's footprint inside with the margin, or from outside the zone back in as
the guard allows), whose end pose is :func:`integrate_twist` of the same motion.
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence, Tuple, Union

from mecanum_control.angles import wrap_angle
from mecanum_safety.zone import Zone
import numpy as np

Pose = Tuple[float, float, float]
Twist2D = Tuple[float, float, float]

#: The zone guard node's /diagnostics status name, and the key of its value saying the
#: pose it guards with: '(x, y, yaw)' in the map frame, or why there is none.
DIAGNOSTIC_NAME = 'zone_guard: Authorised zone'
DIAGNOSTIC_POSE_KEY = 'pose'
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
#: Outside the zone, the clearance each sampled step must gain per metre of its travel:
#: 1 mm per cm (heading within acos(0.1) = 84 degrees of straight in). Parallel motion
#: gains nothing (0, to rounding) and is stopped; any real inward heading passes.
INWARD_MIN_SLOPE = 0.1
#: A command that turns with a translation of at most this (m/s) counts as turning on the
#: spot where only that is allowed (outside the zone, unhealthy localisation): its
#: translation is dropped and the rotation passes alone. Ramped commands (the navigator's
#: spin recovery, the velocity smoother) keep a decaying translation while wz ramps up.
TURNING_LINEAR_TOLERANCE_M_S = 0.05
#: Relative tolerance (times the largest entry, at least 1) of the covariance checks.
COVARIANCE_TOLERANCE = 1e-9

REASON_CLEAR = 'clear'
REASON_APPROACHING = 'approaching the border'
REASON_AT_BORDER = 'at the border'
REASON_OUTSIDE = 'outside the zone'
REASON_INVALID_COMMAND = 'invalid command'
REASON_INVALID_POSE = 'invalid pose'
REASON_BACK_IN = 'back into the zone'
REASON_TURNING_OUTSIDE = 'turning on the spot outside the zone'
REASON_LOCALISATION = 'localisation unhealthy'
REASON_TURNING_UNHEALTHY = 'turning on the spot (localisation unhealthy)'

KIND_POSE = 'NaN/inf in the pose'
KIND_COVARIANCE = 'NaN/inf in the covariance'
KIND_ASYMMETRIC = 'covariance not symmetric'
KIND_NOT_PSD = 'covariance not positive semi-definite'
KIND_SIGMA = 'position sigma too large'
KIND_JUMP = 'localisation jumped'


@dataclass(frozen=True)
class GuardResult:
    """
    What the guard decided for one command.

    scale: the factor (in [0, 1]) for the whole twist. reason: REASON_CLEAR (scale 1),
    REASON_APPROACHING (0 < scale < 1), REASON_AT_BORDER (scale 0, the footprint inside
    the zone); with the footprint outside it, REASON_BACK_IN (scale > 0), REASON_OUTSIDE
    (scale 0) or REASON_TURNING_OUTSIDE (turning on the spot, scale 1);
    REASON_INVALID_COMMAND or REASON_INVALID_POSE (scale 0); REASON_LOCALISATION (scale
    0) or REASON_TURNING_UNHEALTHY (scale 1) while the localisation is unhealthy.
    clearance_m: the centre's current signed distance to the border (m; nan when
    unknown). required_m: the clearance every predicted pose keeps (m; from outside,
    the clearance the motion starts from). detail: what is wrong with the localisation.
    """

    scale: float
    reason: str
    clearance_m: float = math.nan
    required_m: float = math.nan
    detail: str = ''
    #: True when only the command's rotation may pass (its translation dropped).
    rotation_only: bool = False

    def gap_m(self, footprint_radius_m: float) -> float:
        """Return the footprint's distance to the border now (m; < 0: it overlaps it)."""
        return self.clearance_m - footprint_radius_m


def pose_diagnostic(pose: Tuple[float, float, float]) -> str:
    """Return the DIAGNOSTIC_POSE_KEY value of a known pose (x m, y m, yaw rad; map)."""
    return f'({pose[0]:.2f}, {pose[1]:.2f}, {pose[2]:.2f})'


def pose_diagnostic_known(value: Optional[str]) -> bool:
    """Tell whether a DIAGNOSTIC_POSE_KEY value gives a pose (not why there is none)."""
    return bool(value) and value.startswith('(')


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


def turning_on_the_spot(twist: Twist2D) -> bool:
    """Tell whether a twist turns with at most TURNING_LINEAR_TOLERANCE_M_S of translation."""
    return twist[2] != 0.0 and math.hypot(twist[0], twist[1]) <= TURNING_LINEAR_TOLERANCE_M_S


@dataclass(frozen=True)
class LocalisationProblem:
    """Why a localisation is unhealthy: kind (words, one of KIND_*) and text (with numbers)."""

    kind: str
    text: str


class LocalisationJumps:
    """
    Latch a jump of the localisation that nobody asked for (map -> odom, m and rad).

    map -> odom changes slowly in normal operation: amcl's and SLAM's corrections of the
    odometry's drift, a few cm per update. A jump means the localisation changed its mind
    at once: a restarted amcl starting again from its initial pose, a relocalisation after
    a kidnap, a wrong loop closure. Which of the two estimates is right cannot be told
    here, so a jump of more than ``max_jump_m`` (+ 3 position sigma of the estimate
    before it) or ``max_jump_rad`` (+ 3 yaw sigma) is latched as a localisation problem
    until the operator sets the pose (``initial_pose_set``: /initialpose, RViz's 2D Pose
    Estimate); the jump that follows that, within ``grace_s``, is expected.
    Changes below the thresholds move the reference along (slow corrections add up
    without ever counting as a jump).
    """

    def __init__(self, max_jump_m: float = 0.5, max_jump_rad: float = 0.5,
                 grace_s: float = 5.0):
        """Check and keep the thresholds (m, rad) and the grace after /initialpose (s)."""
        for name, value in (('max_localisation_jump_m', max_jump_m),
                            ('max_localisation_jump_rad', max_jump_rad),
                            ('initial_pose_grace_s', grace_s)):
            _check_number(name, value)
            if value <= 0.0:
                raise ValueError(f'{name} must be > 0, got {value!r}')
        self.max_jump_m = float(max_jump_m)
        self.max_jump_rad = float(max_jump_rad)
        self.grace_s = float(grace_s)
        self.reference: Optional[Tuple[float, float, float]] = None
        self.grace_until_s = -math.inf
        self.latched: Optional[LocalisationProblem] = None

    def initial_pose_set(self, now_s: float) -> None:
        """Take the operator's pose: clear a latched jump, expect one for grace_s."""
        self.latched = None
        self.reference = None
        self.grace_until_s = now_s + self.grace_s

    def update(self, now_s: float, map_to_odom: Tuple[float, float, float],
               sigma_xy_m: float = 0.0, sigma_yaw_rad: float = 0.0
               ) -> Optional[LocalisationProblem]:
        """Return the latched jump (or None) after one map -> odom (x, y, yaw) sample."""
        if self.latched is not None:
            return self.latched
        sample = tuple(float(v) for v in map_to_odom)
        if self.reference is None or now_s < self.grace_until_s or not all(
                math.isfinite(v) for v in sample):
            if all(math.isfinite(v) for v in sample):
                self.reference = sample
            return None
        distance = math.hypot(sample[0] - self.reference[0], sample[1] - self.reference[1])
        turn = abs(wrap_angle(sample[2] - self.reference[2]))
        sigma_xy = sigma_xy_m if math.isfinite(sigma_xy_m) else 0.0
        sigma_yaw = sigma_yaw_rad if math.isfinite(sigma_yaw_rad) else 0.0
        limit_m = self.max_jump_m + 3.0 * max(sigma_xy, 0.0)
        limit_rad = self.max_jump_rad + 3.0 * max(sigma_yaw, 0.0)
        if distance > limit_m or turn > limit_rad:
            self.latched = LocalisationProblem(KIND_JUMP, (
                f'{KIND_JUMP} {distance:.2f} m, {math.degrees(turn):.0f} deg at once (map -> '
                f'odom; more than {limit_m:.2f} m or {math.degrees(limit_rad):.0f} deg) and '
                'nobody set the pose: set it on /initialpose (RViz 2D Pose Estimate)'))
            return self.latched
        self.reference = sample
        return None


def localisation_problem(position: Sequence[float], orientation: Sequence[float],
                         covariance: Sequence[float],
                         max_position_sigma_m: float) -> Optional[LocalisationProblem]:
    """
    Return what is wrong with a localisation's pose and covariance, or None if healthy.

    position (x, y, z; m) and orientation (quaternion x, y, z, w) of the pose, covariance
    its row-major 6x6 covariance (36 values, geometry_msgs/PoseWithCovariance), checked
    in this order: NaN/inf in the pose, NaN/inf in the covariance, a covariance not
    symmetric or not positive semi-definite (beyond COVARIANCE_TOLERANCE times its
    largest entry, at least 1: rounding), a position standard deviation along the worst
    direction (:func:`sigma_xy`) above max_position_sigma_m (m). A covariance of zeros
    (SLAM publishes no uncertainty) is healthy.
    """
    pose = tuple(float(v) for v in position), tuple(float(v) for v in orientation)
    if not all(math.isfinite(v) for v in pose[0] + pose[1]):
        return LocalisationProblem(KIND_POSE, f'{KIND_POSE} (position {pose[0]}, '
                                              f'orientation {pose[1]})')
    values = np.asarray(covariance, dtype=np.float64).ravel()
    if values.size != 36:
        raise ValueError(f'covariance must have 36 (6x6) values, got {values.size}')
    bad = int(np.count_nonzero(~np.isfinite(values)))
    if bad:
        return LocalisationProblem(KIND_COVARIANCE,
                                   f'{KIND_COVARIANCE} ({bad} of {values.size} values)')
    matrix = values.reshape(6, 6)
    tolerance = COVARIANCE_TOLERANCE * max(1.0, float(np.max(np.abs(matrix))))
    difference = np.abs(matrix - matrix.T)
    row, col = np.unravel_index(int(np.argmax(difference)), difference.shape)
    if difference[row, col] > tolerance:
        row, col = min(row, col), max(row, col)
        return LocalisationProblem(KIND_ASYMMETRIC, (
            f'{KIND_ASYMMETRIC} (largest difference {float(difference[row, col]):.3g} '
            f'between [{row}][{col}] and [{col}][{row}])'))
    lowest = float(np.min(np.linalg.eigvalsh(0.5 * (matrix + matrix.T))))
    if lowest < -tolerance:
        return LocalisationProblem(KIND_NOT_PSD, f'{KIND_NOT_PSD} (eigenvalue {lowest:.3g})')
    sigma = sigma_xy(values)
    if sigma > max_position_sigma_m:
        return LocalisationProblem(KIND_SIGMA, (
            f'position sigma {sigma:.2f} m > max_position_sigma_m '
            f'{max_position_sigma_m:g} m'))
    return None


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


#: A sample of a path: (x, y, clearance) of the footprint centre (m).
Sample = Tuple[float, float, float]


class _Path:
    """
    The samples of one constant-twist path from a pose, and the rule they must keep.

    required_m: the clearance every sample keeps (m). With inward_cap_m (from outside
    the zone) the rule is instead that each sample's clearance is at least
    min(inward_cap_m, the previous sample's + INWARD_MIN_SLOPE * the distance between
    them): it keeps getting further in until inward_cap_m.
    """

    def __init__(self, zone: Zone, pose: Pose, twist: Twist2D, required_m: float,
                 inward_cap_m: Optional[float] = None):
        self.zone = zone
        self.pose = pose
        self.twist = twist
        self.step = _parameter_step(*twist)
        self.required_m = required_m
        self.inward_cap_m = inward_cap_m
        start = float(zone.clearance(np.array([pose[0]]), np.array([pose[1]]))[0])
        self.start: Sample = (pose[0], pose[1], start)

    def samples_at(self, times_s: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (xs, ys, clearances) of the centre at these path parameters (s)."""
        xs, ys, _ = integrate_twists(self.pose, *self.twist, times_s)
        return xs, ys, self.zone.clearance(xs, ys)

    def breaks(self, previous: Sample, xs: np.ndarray, ys: np.ndarray, clearances: np.ndarray,
               tolerance_m: float, chained: bool = True) -> np.ndarray:
        """
        Return which samples break the rule (bool array).

        previous: the sample before the first. chained: each sample follows the one
        before it (False: each follows previous directly, for end points tried after it).
        """
        if self.inward_cap_m is None:
            return clearances < self.required_m - tolerance_m
        if chained:
            before_x = np.concatenate(([previous[0]], xs[:-1]))
            before_y = np.concatenate(([previous[1]], ys[:-1]))
            before_c = np.concatenate(([previous[2]], clearances[:-1]))
        else:
            before_x, before_y, before_c = previous
        gained = INWARD_MIN_SLOPE * np.hypot(xs - before_x, ys - before_y)
        return clearances < np.minimum(self.inward_cap_m, before_c + gained) - tolerance_m

    def first_violation(self, end_s: float) -> Optional[Tuple[float, float, Sample]]:
        """
        Return (last good, first bad, the last good sample), or None if the path keeps the rule.

        The samples are k * step for k * step < end_s, then end_s itself. A sample
        breaks the rule when its clearance is below what the rule requires - TOLERANCE_M.
        """
        previous = 0.0
        last: Sample = self.start
        start = 0
        while True:
            if start >= MAX_SAMPLES:
                return previous, previous, last   # undecided so far: cut the path here
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
                xs, ys, clearances = self.samples_at(times)
                bad = np.flatnonzero(self.breaks(last, xs, ys, clearances, TOLERANCE_M))
                if bad.size:
                    index = int(bad[0])
                    if index:
                        last = (float(xs[index - 1]), float(ys[index - 1]),
                                float(clearances[index - 1]))
                    return (float(times[index - 1]) if index else previous,
                            float(times[index]), last)
                previous = float(times[-1])
                last = (float(xs[-1]), float(ys[-1]), float(clearances[-1]))
            if last_chunk:
                return None
            start += CHUNK_SAMPLES

    def refine(self, good: float, bad: float, last: Sample) -> float:
        """
        Return the furthest end point (path parameter) kept before bad, from good on.

        Grids of REFINE_POINTS between good (its sample last) and bad, REFINE_ROUNDS
        times; an end point there follows the sample at good, as it does in the scaled
        path's own samples. Exactly the rule here: the tolerance is for rounding, not to
        be used up.
        """
        low, high = good, bad
        for _ in range(REFINE_ROUNDS):
            grid = np.linspace(low, high, REFINE_POINTS + 2)[1:-1]
            xs, ys, clearances = self.samples_at(grid)
            below = np.flatnonzero(self.breaks(last, xs, ys, clearances, 0.0, chained=False))
            first = int(below[0]) if below.size else grid.size
            low, high = (grid[first - 1] if first else low), (
                grid[first] if first < grid.size else high)
            low, high = float(low), float(high)
        return low


def _admissible(zone: Zone, pose: Pose, twist: Twist2D, scale: float, horizon_s: float,
                required_m: float, inward_cap_m: Optional[float]) -> bool:
    """Check the path of scale * twist over horizon_s on its own (the result's proof)."""
    if scale == 0.0:
        return True
    scaled = (scale * twist[0], scale * twist[1], scale * twist[2])
    path = _Path(zone, pose, scaled, required_m, inward_cap_m)
    return path.first_violation(_path_end(scaled[2], horizon_s)) is None


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
    outside = clearance < radius   # the footprint crosses the border
    inward_cap = radius + margin if outside else None

    def result(scale: float) -> GuardResult:
        if outside:
            reason = REASON_BACK_IN if scale > 0.0 else REASON_OUTSIDE
            return GuardResult(min(scale, 1.0), reason, clearance, required)
        if scale >= 1.0:
            return GuardResult(1.0, REASON_CLEAR, clearance, required)
        if scale > 0.0:
            return GuardResult(scale, REASON_APPROACHING, clearance, required)
        return GuardResult(0.0, REASON_AT_BORDER, clearance, required)

    if twist[0] == 0.0 and twist[1] == 0.0:
        # Rotation (or nothing): the footprint circle does not move.
        reason = REASON_TURNING_OUTSIDE if outside and twist[2] != 0.0 else REASON_CLEAR
        return GuardResult(1.0, reason, clearance, required)
    if outside and turning_on_the_spot(twist):
        return GuardResult(1.0, REASON_TURNING_OUTSIDE, clearance, required,
                           rotation_only=True)
    path = _Path(zone, pose, twist, required, inward_cap)
    violation = path.first_violation(_path_end(twist[2], horizon))
    if violation is None:
        return result(1.0)
    good, bad, last = violation
    candidates = []
    if bad > good:
        candidates.append(path.refine(good, bad, last))
    candidates.append(good)
    speed = math.hypot(twist[0], twist[1])
    for end in candidates:
        if end * speed < MIN_TRAVEL_M:
            break
        scale = min(max(end / horizon, 0.0), 1.0)
        if _admissible(zone, pose, twist, scale, horizon, required, inward_cap):
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
    spot are always allowed); from a start outside the zone (the footprint across the
    border), each sample further in than the one before by INWARD_MIN_SLOPE of the
    distance between them until radius_m + margin_m inside, as the guard requires (on
    the spot is allowed). Returns (True, '') or (False, a sentence saying
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
    # there, with some overshoot) may still move in any way that gets no nearer; one
    # outside the zone only back in.
    required = min(radius + margin, start)
    outside = start < radius
    if twist[0] == 0.0 and twist[1] == 0.0:
        return True, ''
    path = _Path(zone, pose, twist, required, radius + margin if outside else None)
    violation = path.first_violation(_path_end(twist[2], float(duration_s)))
    if violation is None:
        return True, ''
    bad_s, last = violation[1], violation[2]
    x, y, _ = integrate_twist(pose, *twist, bad_s)
    clearance = float(zone.clearance(np.array([x]), np.array([y]))[0])
    when = f'at ({x:.2f}, {y:.2f}) after {bad_s:.2f} s of the {float(duration_s):.2f} s motion'
    if outside and last[2] < radius + margin - TOLERANCE_M:   # not in yet
        return False, (f'the footprint is {radius - start:.2f} m out of the authorised zone '
                       f'and would not be getting back in {when}')
    where = ('out of the authorised zone' if clearance < radius
             else f'within {margin:.2f} m of the border of the authorised zone')
    return False, f'the footprint would come {where} {when}'


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
    max_position_sigma_m: float = 0.25

    def __post_init__(self):
        """Check every setting (ValueError naming it)."""
        for name in ('footprint_radius_m', 'horizon_s', 'max_position_sigma_m'):
            value = getattr(self, name)
            if not _finite(value) or value <= 0.0:
                raise ValueError(f'{name} must be a finite number > 0, got {value!r}')
        for name in ('margin_m', 'covariance_factor', 'max_margin_m'):
            _check_number(name, getattr(self, name))
        if self.max_margin_m < self.margin_m:
            raise ValueError(f'max_margin_m ({self.max_margin_m!r}) must be >= margin_m '
                             f'({self.margin_m!r})')

    def localisation_problem(self, position: Sequence[float], orientation: Sequence[float],
                             covariance: Sequence[float]) -> Optional[LocalisationProblem]:
        """Return what is wrong with the localisation (:func:`localisation_problem`), or None."""
        return localisation_problem(position, orientation, covariance,
                                    self.max_position_sigma_m)

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
             covariance: Optional[Sequence[float]] = None,
             localisation: Optional[LocalisationProblem] = None) -> GuardResult:
        """
        Return the decision for twist at pose.

        The margin grows with the localisation's uncertainty: sigma_xy_m (m), or, when
        the position covariance is given (36 or 4 values, see :func:`xy_block`), its
        sigma toward the border (:meth:`sigma`), which then replaces sigma_xy_m. With a
        localisation problem (:meth:`localisation_problem`) only turning on the spot
        passes (REASON_TURNING_UNHEALTHY), anything else is stopped
        (REASON_LOCALISATION); its text is the result's detail. Without a zone neither
        matters: every finite command passes.
        """
        if len(twist) != 3 or not _finite(*twist):
            return GuardResult(0.0, REASON_INVALID_COMMAND)
        if self.zone is None:
            return GuardResult(1.0, REASON_CLEAR)
        if localisation is not None:
            if twist[0] == 0.0 and twist[1] == 0.0:
                return GuardResult(1.0, REASON_TURNING_UNHEALTHY, detail=localisation.text)
            if turning_on_the_spot(twist):
                return GuardResult(1.0, REASON_TURNING_UNHEALTHY, detail=localisation.text,
                                   rotation_only=True)
            return GuardResult(0.0, REASON_LOCALISATION, detail=localisation.text)
        if covariance is not None:
            sigma_xy_m = self.sigma(pose, twist, covariance)
        return guard_scale(self.zone, pose, twist, self.footprint_radius_m,
                           self.margin(sigma_xy_m), self.horizon_s)
