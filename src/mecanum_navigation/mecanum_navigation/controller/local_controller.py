"""
Holonomic local controller of the mecanum base (pure core, no ROS), Nav2 controller style.

``LocalController.compute_velocity(pose, current_twist, path, costmap)`` returns the body
twist to command for the next control period and a status, like a Nav2 controller
plugin's computeVelocityCommands. Conventions: REP-103 / REP-105; the pose (x m, y m,
yaw rad) and the path are in the costmap's frame (odom for the local costmap); twists
are body twists in base_link (vx m/s forward, vy m/s left, wz rad/s counter-clockwise).

How it works (a DWB-like sampler, vectorised with numpy: one array op over all samples):

1. Samples: a grid of vx_samples x vy_samples x vtheta_samples *target* twists over the
   velocities reachable from the current twist within sim_time (DWB's dynamic window,
   clipped to the velocity limits), plus candidates: zero (braking), the current twist,
   the previous cycle's choice, and "reference" twists heading straight for the
   lookahead point at several speeds (fine control near the goal, which a coarse grid
   lacks). With max_wheel_speed_m_s, targets needing a faster wheel (|vx| + |vy| +
   rotation_arm_m |wz| above it) are dropped: the motor controller would scale them
   down, so their trajectories would be wrong. vy is sampled like vx: the robot strafes
   whenever that scores best, and translation never waits for rotation.
2. Trajectories over sim_time: the twist ramps from the current one to the target within
   the acceleration limits (all axes together, direction kept, as the motor
   controller's RateLimiter), as a staircase of commands held for one control period
   each (what this controller really commands, so with perfect tracking the robot moves
   exactly along the start of the chosen trajectory), then holds. Steps (at most
   sim_granularity metres at top speed) are integrated exactly as arcs. The ramp makes a
   braking trajectory as long as a real stop, so the obstacle check is honest at speed.
3. Critics, summed with weights. Obstacle: a trajectory whose centre enters a cell of
   cost >= 253 is invalid (the circular footprint is in the costmap's inflation), every
   cell a step can touch being checked (the two end cells and the two corner cells, so
   no cell is jumped over); NO_INFORMATION (255) and off-map points are invalid unless
   allow_unknown; otherwise the highest cost / 252 is added, less the highest cost the
   path itself crosses within the trajectories' reach (a trajectory is not penalised for
   the cost of the gap the plan goes through: standing still in front of a narrow gap
   would otherwise score best for ever), and not within near_goal_distance of the goal
   (as MPPI, so a goal in an inflated area is reached).
   Goal distance: from the trajectory's point at approach_time to the lookahead point
   (lookahead_dist along the path from the robot's nearest path point, or the goal;
   brought back along the path until the straight line to it stays out of inscribed
   cells, so that around a tight corner the robot first drives to the corner instead
   of stopping in front of the wall between it and a carrot beyond the corner; a path
   point in an inscribed cell of this costmap is moved to the nearest free cell within
   CARROT_SHIFT_M first, as the scan may put a wall a cell nearer than the map did):
   near the goal this makes the speed about distance / approach_time. Path distance:
   end and middle points to the path. Heading: end yaw to the heading target.
   Smoothness: change from the current twist.
4. The command is the first stair of the best valid trajectory: the current twist moved
   toward the chosen target by at most acc_lim / controller_frequency on every axis,
   clamped to the velocity limits (which win if the current twist is beyond them).

heading_mode 'goal' (default) turns toward the goal's yaw while driving, or holds the
heading the robot had when the path was given if the path has no final yaw; 'path'
faces the path direction (the goal yaw near the end); 'none' leaves the heading free.
Goal checking is Nav2's SimpleGoalChecker: within xy_goal_tolerance (latched when
stateful) the robot stops translating and turns in place to the goal yaw until within
yaw_goal_tolerance. If the robot's own cell is already inscribed it may still move out
(only lethal cells invalidate then).

Statuses: 'following', 'rotating_to_goal', 'goal_reached', 'no_valid_trajectory' (no
valid trajectory takes the robot a cell away: boxed in, the navigator should start a
recovery) and 'stale_pose' (pose older than transform_tolerance). With the last three
the twist is a braking step (toward zero within the acceleration limits).
``ProgressChecker`` is Nav2's SimpleProgressChecker, for the navigator to notice a robot
that stays put.
"""

from dataclasses import dataclass, field, fields
import math
from typing import Optional, Sequence, Tuple

from mecanum_control.angles import wrap_angle, wrap_angles
from mecanum_navigation.costmap.costmap_2d import as_xy
from mecanum_navigation.costmap.kernels import BLOCKED, segment_cost
from numba import njit
import numpy as np

Twist2D = Tuple[float, float, float]
Pose2D = Tuple[float, float, float]

#: How far (m) a carrot in an inscribed cell may be moved to a free one.
CARROT_SHIFT_M = 0.1

STATUS_FOLLOWING = 'following'
STATUS_ROTATING = 'rotating_to_goal'
STATUS_GOAL_REACHED = 'goal_reached'
STATUS_NO_VALID_TRAJECTORY = 'no_valid_trajectory'
STATUS_STALE_POSE = 'stale_pose'

HEADING_MODES = ('goal', 'path', 'none')

INSCRIBED_COST = 253
LETHAL_COST = 254
UNKNOWN_COST = 255
FREE_COST = 0
MAX_NON_OBSTACLE = 252


@dataclass(frozen=True)
class ControllerParams:
    """
    Parameters of LocalController; names follow Nav2 (DWB, RPP) where Nav2 has one.

    Velocities m/s and rad/s, accelerations m/s^2 and rad/s^2, times s, lengths m.
    min_vel_x / min_vel_y default to -max_vel_x / -max_vel_y (a mecanum base backs up
    and strafes both ways). max_wheel_speed_m_s (wheel radius x top wheel speed) and
    rotation_arm_m (half wheelbase + half track) together bound the targets by the
    wheels; None disables that bound. *_weight are the critics' weights. robot_radius
    (the footprint circle) and collision_margin switch on the exact check against scan
    points (compute_velocity's obstacle_points): the chosen trajectory keeps the circle
    at least collision_margin from every point; None (no radius) disables it.
    """

    max_vel_x: float = 0.8
    max_vel_y: float = 0.6
    max_vel_theta: float = 2.5
    min_vel_x: Optional[float] = None
    min_vel_y: Optional[float] = None
    acc_lim_x: float = 1.5
    acc_lim_y: float = 1.5
    acc_lim_theta: float = 5.0
    max_wheel_speed_m_s: Optional[float] = None
    rotation_arm_m: Optional[float] = None
    controller_frequency: float = 20.0
    sim_time: float = 1.2
    sim_granularity: float = 0.025
    vx_samples: int = 11
    vy_samples: int = 11
    vtheta_samples: int = 9
    lookahead_dist: float = 1.0
    near_goal_distance: float = 0.5
    approach_time: float = 0.6
    max_robot_pose_search_dist: float = 1.5
    xy_goal_tolerance: float = 0.05
    yaw_goal_tolerance: float = 0.05
    stateful: bool = True
    transform_tolerance: float = 0.1
    allow_unknown: bool = False
    heading_mode: str = 'goal'
    goal_dist_weight: float = 1.0
    path_dist_weight: float = 0.6
    heading_weight: float = 0.4
    obstacle_weight: float = 0.4
    smoothness_weight: float = 0.05
    robot_radius: Optional[float] = None
    collision_margin: float = 0.02

    def __post_init__(self) -> None:
        """Validate every field (ValueError naming it) and fill the min_vel defaults."""
        for name in ('max_vel_x', 'max_vel_y', 'max_vel_theta', 'acc_lim_x', 'acc_lim_y',
                     'acc_lim_theta', 'controller_frequency', 'sim_time', 'sim_granularity',
                     'lookahead_dist', 'near_goal_distance', 'max_robot_pose_search_dist',
                     'xy_goal_tolerance', 'approach_time',
                     'yaw_goal_tolerance', 'transform_tolerance'):
            _check_number(name, getattr(self, name), positive=True)
        for name in ('max_wheel_speed_m_s', 'rotation_arm_m', 'robot_radius'):
            if getattr(self, name) is not None:
                _check_number(name, getattr(self, name), positive=True)
        _check_number('collision_margin', self.collision_margin)
        if self.collision_margin < 0.0:
            raise ValueError(f'collision_margin must be >= 0 m, got {self.collision_margin!r}')
        if (self.max_wheel_speed_m_s is None) != (self.rotation_arm_m is None):
            raise ValueError('max_wheel_speed_m_s and rotation_arm_m must be given together '
                             f'(got {self.max_wheel_speed_m_s!r}, {self.rotation_arm_m!r})')
        for name, maximum in (('min_vel_x', 'max_vel_x'), ('min_vel_y', 'max_vel_y')):
            value = getattr(self, name)
            if value is None:
                object.__setattr__(self, name, -float(getattr(self, maximum)))
                continue
            _check_number(name, value)
            if value > 0.0:
                raise ValueError(f'{name} must be <= 0 (the robot must be able to stop), '
                                 f'got {value}')
            if value >= getattr(self, maximum):
                raise ValueError(f'{name} ({value}) must be below {maximum} '
                                 f'({getattr(self, maximum)})')
        for name in ('vx_samples', 'vy_samples', 'vtheta_samples'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
                    or not 1 <= value <= 101:
                raise ValueError(f'{name} must be an integer in 1..101, got {value!r}')
        for name in ('goal_dist_weight', 'path_dist_weight', 'heading_weight',
                     'obstacle_weight', 'smoothness_weight'):
            _check_number(name, getattr(self, name))
            if getattr(self, name) < 0.0:
                raise ValueError(f'{name} must be >= 0, got {getattr(self, name)!r}')
        for name in ('stateful', 'allow_unknown'):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f'{name} must be a bool, got {getattr(self, name)!r}')
        if self.heading_mode not in HEADING_MODES:
            raise ValueError(f'heading_mode must be one of {HEADING_MODES}, '
                             f'got {self.heading_mode!r}')
        if self.approach_time > self.sim_time:
            raise ValueError(f'approach_time ({self.approach_time} s) must not exceed sim_time '
                             f'({self.sim_time} s)')
        if self.sim_time * self.controller_frequency < 1.0:
            raise ValueError(f'sim_time ({self.sim_time} s) must cover at least one control '
                             f'period (1 / controller_frequency = '
                             f'{1.0 / self.controller_frequency:g} s)')

    @classmethod
    def from_robot_config(cls, config, **overrides) -> 'ControllerParams':
        """Return parameters with the limits of a mecanum_control RobotConfig, then overrides."""
        values = {
            'max_vel_x': config.max_velocity_x_m_s, 'max_vel_y': config.max_velocity_y_m_s,
            'max_vel_theta': config.max_angular_velocity_rad_s,
            'acc_lim_x': config.max_acceleration_x_m_s2,
            'acc_lim_y': config.max_acceleration_y_m_s2,
            'acc_lim_theta': config.max_angular_acceleration_rad_s2,
            'max_wheel_speed_m_s': (config.max_wheel_speed_rad_s
                                    * config.geometry.wheel_radius_m),
            'rotation_arm_m': config.geometry.rotation_arm_m,
            'robot_radius': config.footprint_radius_m}
        unknown = set(overrides) - {f.name for f in fields(cls)}
        if unknown:
            raise ValueError(f'unknown controller parameters: {sorted(unknown)}')
        values.update(overrides)
        return cls(**values)

    @property
    def max_velocity(self) -> np.ndarray:
        """Return the upper velocity limits (vx, vy, wz)."""
        return np.array([self.max_vel_x, self.max_vel_y, self.max_vel_theta])

    @property
    def min_velocity(self) -> np.ndarray:
        """Return the lower velocity limits (vx, vy, wz)."""
        return np.array([self.min_vel_x, self.min_vel_y, -self.max_vel_theta])

    @property
    def acceleration(self) -> np.ndarray:
        """Return the acceleration limits (x, y, theta)."""
        return np.array([self.acc_lim_x, self.acc_lim_y, self.acc_lim_theta])

    @property
    def control_period(self) -> float:
        """Return 1 / controller_frequency, the time a command is held (s)."""
        return 1.0 / self.controller_frequency


@dataclass
class ControllerDiagnostics:
    """
    What the last compute_velocity saw and chose (for a local_plan publisher and logs).

    trajectory: (K, 3) poses (x, y, yaw) of the chosen trajectory in the costmap frame
    (empty when none); target: the chosen target twist; carrot: the lookahead point;
    valid_samples / samples: trajectories that passed the obstacle check / all scored.
    """

    status: str = STATUS_FOLLOWING
    trajectory: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    target: Twist2D = (0.0, 0.0, 0.0)
    carrot: Tuple[float, float] = (math.nan, math.nan)
    distance_to_goal_m: float = math.nan
    valid_samples: int = 0
    samples: int = 0
    best_score: float = math.nan


def ramp_step(current: Sequence[float], target: Sequence[float], acceleration: Sequence[float],
              dt_s: float) -> np.ndarray:
    """
    Move a twist from current toward target for dt_s seconds within per-axis accelerations.

    The whole change vector is scaled by the most limiting axis, so the twist moves on
    the straight line toward the target (direction kept, as the RateLimiter of
    mecanum_control.command_limits). Returns the new (vx, vy, wz) as an array.
    """
    current = np.asarray(current, dtype=np.float64)
    delta = np.asarray(target, dtype=np.float64) - current
    allowed = np.asarray(acceleration, dtype=np.float64) * dt_s
    # np.where evaluates both branches: a tiny |delta| may overflow where it is not used.
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        ratios = np.where(np.abs(delta) > allowed, allowed / np.abs(delta), 1.0)
    return current + float(np.min(ratios)) * delta


class Scratch:
    """
    Reusable work arrays, so a control cycle allocates (and page-faults) no big arrays.

    get(name, shape, dtype) returns a C-contiguous view of a buffer kept under name,
    grown when too small; its content is whatever was left there.
    """

    def __init__(self) -> None:
        """Start with no buffers."""
        self._buffers = {}

    def get(self, name: str, shape: Tuple[int, ...], dtype=np.float32) -> np.ndarray:
        """Return a (garbage-filled) array of shape and dtype kept under name."""
        size = math.prod(shape)
        buffer = self._buffers.get(name)
        if buffer is None or buffer.dtype != np.dtype(dtype) or buffer.size < size:
            buffer = np.empty(max(size, 1), dtype=dtype)
            self._buffers[name] = buffer
        return buffer[:size].reshape(shape)


def simulate_trajectories(pose: Sequence[float], current: Sequence[float], targets: np.ndarray,
                          acceleration: Sequence[float], sim_time: float, steps: int,
                          scratch: Optional[Scratch] = None, period: float = 0.0
                          ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Forward-simulate N target twists from pose over sim_time s in `steps` equal steps.

    The twist ramps from current to each target within the acceleration limits (all
    axes reaching it together) and then holds. With period > 0 the ramp is a staircase
    of commands held for `period` s each (what a controller running every period
    commands: the first stair is exactly ramp_step(current, target, accel, period));
    with period 0 it is continuous (each step takes the ramp's value at its middle).
    Each step is integrated exactly as a circular arc. Returns x, y, yaw arrays of
    shape (N, steps), float32: the poses at the END of each step (the start pose not
    included), yaw unwrapped. float32 (SIMD sin/cos) costs micrometres over a
    trajectory. With a scratch, the arrays returned are its buffers (valid until the
    next call with it).
    """
    f32 = np.float32
    scratch = Scratch() if scratch is None else scratch
    targets = np.asarray(targets, dtype=np.float64).reshape(-1, 3)
    current = np.asarray(current, dtype=np.float64)
    acceleration = np.asarray(acceleration, dtype=np.float64)
    shape = (targets.shape[0], int(steps))
    dt = sim_time / steps
    delta = targets - current
    with np.errstate(divide='ignore', invalid='ignore'):
        ramp_s = np.max(np.where(delta == 0.0, 0.0, np.abs(delta) / acceleration), axis=1)
    t_mid = (np.arange(steps) + 0.5) * dt
    if period > 0.0:
        t_mid = np.ceil(t_mid / period) * period
    t_mid = t_mid.astype(f32)
    rate = (1.0 / np.maximum(ramp_s, 1e-12)).astype(f32)
    fraction = np.multiply(rate[:, None], t_mid[None, :], out=scratch.get('fraction', shape))
    np.minimum(fraction, f32(1.0), out=fraction)
    vx = np.multiply(fraction, delta[:, 0:1].astype(f32), out=scratch.get('vx', shape))
    vx += f32(current[0])
    vy = np.multiply(fraction, delta[:, 1:2].astype(f32), out=scratch.get('vy', shape))
    vy += f32(current[1])
    dtheta = np.multiply(fraction, (delta[:, 2:3] * dt).astype(f32),
                         out=scratch.get('dtheta', shape))
    dtheta += f32(current[2] * dt)
    yaws = np.add.accumulate(dtheta, axis=1, out=scratch.get('yaw', shape))
    # Exact arc of a constant twist over a step: the body velocity rotated to the mean
    # heading of the step, times dt * sin(h) / h with h = dtheta / 2 (a series while
    # |h| < 0.1, error < 1e-10; the fraction buffer is free again and holds it).
    half = np.multiply(dtheta, f32(0.5), out=dtheta)
    scale = fraction
    if float(np.max(np.abs(half))) < 0.1:
        np.multiply(half, half, out=scale)
        scale *= f32(-1.0 / 6.0)
        scale += f32(1.0)
        scale *= f32(dt)
    else:
        np.copyto(scale, dt * np.sinc(half / math.pi), casting='unsafe')
    yaw_mid = np.subtract(yaws, half, out=half)
    yaw_mid += f32(pose[2])
    cos_mid = np.cos(yaw_mid, out=scratch.get('cos', shape))
    cos_mid *= scale
    sin_mid = np.sin(yaw_mid, out=scratch.get('sin', shape))
    sin_mid *= scale
    temporary = yaw_mid
    step = np.multiply(cos_mid, vx, out=scratch.get('step', shape))
    step -= np.multiply(sin_mid, vy, out=temporary)
    xs = np.add.accumulate(step, axis=1, out=scratch.get('x', shape))
    np.multiply(sin_mid, vx, out=step)
    step += np.multiply(cos_mid, vy, out=temporary)
    ys = np.add.accumulate(step, axis=1, out=scratch.get('y', shape))
    xs += f32(pose[0])
    ys += f32(pose[1])
    yaws += f32(pose[2])
    return xs, ys, yaws


def trajectory_costs(costmap, xs: np.ndarray, ys: np.ndarray,
                     start: Optional[Tuple[float, float]] = None,
                     scratch: Optional[Scratch] = None) -> np.ndarray:
    """
    Return the cost (uint8) under each point (same shape); off the costmap: 255.

    With start (x, y), xs and ys are (N, K) trajectories from start and each point gets
    the highest cost of the cells the step to it can touch (see _lookup).
    """
    scratch = Scratch() if scratch is None else scratch
    xs = np.asarray(xs, dtype=np.float64)
    ys = np.asarray(ys, dtype=np.float64)
    if start is not None:
        xs, ys = np.atleast_2d(xs), np.atleast_2d(ys)
    return _lookup(_padded_costs(costmap, np.arange(256, dtype=np.uint8), scratch),
                   costmap, xs, ys, scratch, start).copy()


def _padded_costs(costmap, remap: np.ndarray, scratch: Scratch) -> np.ndarray:
    """Return the costs through remap with a border of remap[255] (off the costmap) around."""
    costs = np.asarray(costmap.costs)
    padded = scratch.get('padded', (costs.shape[0] + 2, costs.shape[1] + 2), np.uint8)
    padded.fill(remap[UNKNOWN_COST])
    np.take(remap, costs, out=padded[1:-1, 1:-1])
    return padded


def _lookup(padded: np.ndarray, costmap, xs: np.ndarray, ys: np.ndarray, scratch: Scratch,
            start: Optional[Tuple[float, float]] = None) -> np.ndarray:
    """
    Return padded's value under each point (x, y); points off the costmap hit its border.

    With start (x, y), xs and ys are (N, K) trajectories from start, and each point
    gets the highest value of the up to four cells that the step from the previous
    point can touch (the cells of both ends and the two corner cells): a step shorter
    than a cell touches no others, so no cell is jumped over between samples.
    """
    shape = np.shape(xs)
    width = padded.shape[1]
    cols = np.subtract(xs, costmap.origin_x_m, out=scratch.get('cols', shape, np.float64))
    cols *= 1.0 / costmap.resolution_m
    np.floor(cols, out=cols)
    np.clip(cols, -1.0, costmap.size_x, out=cols)
    cols += 1.0
    rows = np.subtract(ys, costmap.origin_y_m, out=scratch.get('rows', shape, np.float64))
    rows *= 1.0 / costmap.resolution_m
    np.floor(rows, out=rows)
    np.clip(rows, -1.0, costmap.size_y, out=rows)
    rows += 1.0
    rows *= width
    flat = padded.ravel()
    index = scratch.get('index', shape, np.intp)
    np.copyto(index, np.add(rows, cols, out=scratch.get('sum', shape, np.float64)),
              casting='unsafe')
    costs = np.take(flat, index, out=scratch.get('costs', shape, np.uint8))
    if start is None:
        return costs
    start_col = min(max(math.floor((start[0] - costmap.origin_x_m) / costmap.resolution_m),
                        -1), costmap.size_x) + 1.0
    start_row = (min(max(math.floor((start[1] - costmap.origin_y_m) / costmap.resolution_m),
                         -1), costmap.size_y) + 1.0) * width
    corner = scratch.get('corner', shape, np.uint8)
    previous = scratch.get('previous', shape, np.float64)
    for this, other, other_start in ((rows, cols, start_col), (cols, rows, start_row)):
        # Corner cell: this point's row with the previous point's column, then the
        # other way round (rows are pre-multiplied by the width: index = row + col).
        previous[:, 0] = other_start
        previous[:, 1:] = other[:, :-1]
        previous += this
        np.copyto(index, previous, casting='unsafe')
        np.take(flat, index, out=corner)
        np.maximum(costs, corner, out=costs)
    return costs


class ProgressChecker:
    """
    Nav2's SimpleProgressChecker: fails when the robot stays within a radius too long.

    check(x, y, now_s) is True while progressing: each time the robot is more than
    required_movement_radius (m) from the last baseline, the baseline moves there; it is
    False once movement_time_allowance (s) passes without that.
    """

    def __init__(self, required_movement_radius: float = 0.5,
                 movement_time_allowance: float = 10.0):
        """Check and store the parameters."""
        _check_number('required_movement_radius', required_movement_radius, positive=True)
        _check_number('movement_time_allowance', movement_time_allowance, positive=True)
        self.required_movement_radius = float(required_movement_radius)
        self.movement_time_allowance = float(movement_time_allowance)
        self._baseline: Optional[Tuple[float, float, float]] = None

    def reset(self) -> None:
        """Forget the baseline (the next check starts a new one)."""
        self._baseline = None

    def check(self, x: float, y: float, now_s: float) -> bool:
        """Return False when the robot has not moved enough within the time allowance."""
        for name, value in (('x', x), ('y', y), ('now_s', now_s)):
            _check_number(name, value)
        if self._baseline is None or math.hypot(x - self._baseline[0], y - self._baseline[1]) \
                > self.required_movement_radius:
            self._baseline = (float(x), float(y), float(now_s))
            return True
        return now_s - self._baseline[2] <= self.movement_time_allowance


class LocalController:
    """The holonomic sampling controller (see the module docstring)."""

    def __init__(self, params: Optional[ControllerParams] = None):
        """Create a controller with no path yet (default parameters when params is None)."""
        params = ControllerParams() if params is None else params
        if not isinstance(params, ControllerParams):
            raise ValueError(f'params must be ControllerParams, not {type(params).__name__}')
        self.params = params
        reach = params.sim_time * float(np.hypot(max(params.max_vel_x, -params.min_vel_x),
                                                 max(params.max_vel_y, -params.min_vel_y)))
        # Steps of at most sim_granularity metres at top speed, a whole number of them
        # per control period (so the staircase of commands falls on step boundaries).
        periods = max(1, int(math.ceil(params.sim_time / params.control_period - 1e-9)))
        per_period = max(1, int(math.ceil(reach / params.sim_granularity / periods)))
        self._steps = periods * per_period
        self._reach = reach
        self._approach_step = min(self._steps, max(1, int(round(
            params.approach_time / params.sim_time * self._steps)))) - 1
        self.last = ControllerDiagnostics()
        self._scratch = Scratch()
        self.reset()

    def reset(self) -> None:
        """Forget the path progress, the goal latch and the previous choice."""
        self._path_key: Optional[bytes] = None
        self._segment = 0
        self._s_robot = 0.0
        self._xy_reached = False
        self._hold_yaw = math.nan
        self._previous_target: Optional[np.ndarray] = None

    # --- the cycle ------------------------------------------------------------------

    def compute_velocity(self, pose: Sequence[float], current_twist: Sequence[float],
                         path, costmap, pose_age_s: float = 0.0,
                         obstacle_points=None) -> Tuple[Twist2D, str]:
        """
        Return (twist, status) for the next control period (see the module docstring).

        pose: (x, y, yaw) in the costmap frame; current_twist: (vx, vy, wz) body twist
        (odometry or the last command); path: (M, 2) points (x, y), or (M, 3) with the
        last row's yaw as the goal yaw (NaN: none), starting near the robot as a global
        plan does; costmap: an object with costs (uint8, row 0 = lowest y), origin_x_m,
        origin_y_m, resolution_m, size_x, size_y; pose_age_s: how old the pose is;
        obstacle_points: (P, 2) scan returns (x, y) in the costmap frame, for the exact
        clearance check (see ControllerParams; rows with NaN/inf are ignored).
        Raises ValueError on a malformed or non-finite input.
        """
        p = self.params
        pose = _as_vector('pose', pose)
        current = _as_vector('current_twist', current_twist)
        _check_number('pose_age_s', pose_age_s)
        points, goal_yaw = _as_path(path)
        _check_costmap(costmap)
        if obstacle_points is not None:
            obstacle_points = _as_points('obstacle_points', obstacle_points)
        key = points.tobytes() + (b'' if goal_yaw is None else np.float64(goal_yaw).tobytes())
        if key != self._path_key:
            self.reset()
            self._path_key = key
            self._hold_yaw = float(pose[2])
        goal = points[-1]
        distance_to_goal = float(math.hypot(goal[0] - pose[0], goal[1] - pose[1]))
        self.last = ControllerDiagnostics(distance_to_goal_m=distance_to_goal,
                                          carrot=(float(goal[0]), float(goal[1])))
        if pose_age_s > p.transform_tolerance:
            return self._brake(current, STATUS_STALE_POSE)

        within_xy = distance_to_goal <= p.xy_goal_tolerance
        if within_xy and p.stateful:
            self._xy_reached = True
        if within_xy or self._xy_reached:
            yaw_error = 0.0 if goal_yaw is None else wrap_angle(goal_yaw - pose[2])
            if abs(yaw_error) <= p.yaw_goal_tolerance:
                return self._brake(current, STATUS_GOAL_REACHED)
            return self._rotate_in_place(pose, current, yaw_error, costmap)

        carrot, local_path, heading_target = self._follow_path(pose, points, goal_yaw,
                                                               costmap)
        self.last.carrot = (float(carrot[0]), float(carrot[1]))
        targets = self._sample_targets(pose, current, carrot, heading_target)
        xs, ys, yaws = simulate_trajectories(pose, current, targets, p.acceleration, p.sim_time,
                                             self._steps, self._scratch, p.control_period)
        valid, obstacle = self._obstacle_critic(costmap, pose, xs, ys)
        # The cost the path itself crosses within reach is not held against trajectories:
        # in front of a narrow gap that the plan goes through, standing still would
        # otherwise score best (a local minimum the robot never leaves).
        obstacle = np.maximum(obstacle - self._path_cost(costmap, pose, local_path), 0.0)
        # Near the goal the soft obstacle cost is off (as MPPI's near_goal_distance), so a
        # goal in an inflated area is still reached; collisions stay invalid.
        scores = (0.0 if distance_to_goal < p.near_goal_distance else p.obstacle_weight) * \
            obstacle
        at = self._approach_step
        scores += p.goal_dist_weight * np.hypot(xs[:, at] - carrot[0], ys[:, at] - carrot[1])
        middle = self._steps // 2
        if p.path_dist_weight > 0.0 and local_path.shape[0] > 0:
            scores += p.path_dist_weight * 0.5 * (
                _distance_to_points(xs[:, -1], ys[:, -1], local_path, self._scratch)
                + _distance_to_points(xs[:, middle], ys[:, middle], local_path, self._scratch))
        if p.heading_weight > 0.0 and heading_target is not None:
            errors = np.abs(wrap_angles(yaws[:, -1] - heading_target))
            scores += p.heading_weight * errors
        span = np.maximum(p.max_velocity - p.min_velocity, 1e-9)
        scores += p.smoothness_weight * np.sum(np.abs(targets - current) / span, axis=1)
        self.last.samples = int(targets.shape[0])
        self.last.valid_samples = int(np.count_nonzero(valid))
        # Boxed in: no valid trajectory gets the robot a cell (or 5 cm) away; standing
        # still, or turning on the spot, is always "valid" but leads nowhere.
        travel = np.maximum(np.hypot(xs[:, -1] - pose[0], ys[:, -1] - pose[1]),
                            np.hypot(xs[:, middle] - pose[0], ys[:, middle] - pose[1]))
        if not np.any(valid & (travel >= min(costmap.resolution_m, 0.05))):
            self._previous_target = None
            return self._brake(current, STATUS_NO_VALID_TRAJECTORY)
        scores = np.where(valid, scores, np.inf)
        best = self._best_clear(scores, pose, xs, ys, obstacle_points)
        if best is None:
            self._previous_target = None
            return self._brake(current, STATUS_NO_VALID_TRAJECTORY)
        self._previous_target = targets[best].copy()
        self.last.best_score = float(scores[best])
        self.last.trajectory = np.column_stack((xs[best], ys[best], yaws[best]))
        return self._command(current, targets[best], STATUS_FOLLOWING)

    # --- parts ----------------------------------------------------------------------

    def _command(self, current: np.ndarray, target: np.ndarray,
                 status: str) -> Tuple[Twist2D, str]:
        """Return the first control period's twist toward target, clamped, and the status."""
        p = self.params
        twist = ramp_step(current, target, p.acceleration, p.control_period)
        twist = np.clip(twist, p.min_velocity, p.max_velocity)
        self.last.status = status
        self.last.target = (float(target[0]), float(target[1]), float(target[2]))
        return (float(twist[0]), float(twist[1]), float(twist[2])), status

    def _brake(self, current: np.ndarray, status: str) -> Tuple[Twist2D, str]:
        """Return a braking step (toward zero within the acceleration limits) and status."""
        return self._command(current, np.zeros(3), status)

    def _rotate_in_place(self, pose: np.ndarray, current: np.ndarray, yaw_error: float,
                         costmap) -> Tuple[Twist2D, str]:
        """Stop translating and turn toward the goal yaw, slowing down to stop on it."""
        p = self.params
        # Fastest turn that can still stop at the goal yaw with half the angular
        # acceleration (the other half is margin for the control period's delay).
        speed = min(p.max_vel_theta, math.sqrt(p.acc_lim_theta * abs(yaw_error)),
                    abs(yaw_error) / (2.0 * p.control_period))
        target = np.array([0.0, 0.0, math.copysign(speed, yaw_error)])
        xs, ys, yaws = simulate_trajectories(pose, current, target[None, :], p.acceleration,
                                             p.sim_time, self._steps, self._scratch,
                                             p.control_period)
        valid, _ = self._obstacle_critic(costmap, pose, xs, ys)
        self.last.samples, self.last.valid_samples = 1, int(valid[0])
        if not valid[0]:
            return self._brake(current, STATUS_NO_VALID_TRAJECTORY)
        self.last.trajectory = np.column_stack((xs[0], ys[0], yaws[0]))
        return self._command(current, target, STATUS_ROTATING)

    def _follow_path(self, pose: np.ndarray, points: np.ndarray, goal_yaw: Optional[float],
                     costmap=None):
        """
        Prune the path at the robot and return (carrot, local path points, heading target).

        The carrot is lookahead_dist ahead along the path, or the farthest point before
        it that the robot sees along a straight line free of inscribed cells (costmap;
        see _visible_carrot).

        The robot's nearest point is searched forward from the last one, within
        max_robot_pose_search_dist of path length, so a path that passes the same place
        twice is followed in order. The heading target is None when there is none.
        """
        p = self.params
        starts, ends = points[:-1], points[1:]
        lengths = np.hypot(*(ends - starts).T)
        cumulative = np.concatenate(([0.0], np.cumsum(lengths)))
        total = float(cumulative[-1])
        if starts.shape[0] == 0:
            s_robot = 0.0
        else:
            first = min(self._segment, starts.shape[0] - 1)
            # Segments starting within the search distance ahead of the last projection.
            last = int(np.searchsorted(cumulative[:-1], self._s_robot
                                       + p.max_robot_pose_search_dist, side='right'))
            last = min(max(last, first + 1), starts.shape[0])
            seg_start, seg_vec = starts[first:last], (ends - starts)[first:last]
            seg_len2 = np.maximum(np.sum(seg_vec * seg_vec, axis=1), 1e-18)
            t = np.clip(np.sum((pose[:2] - seg_start) * seg_vec, axis=1) / seg_len2, 0.0, 1.0)
            nearest = seg_start + t[:, None] * seg_vec
            index = int(np.argmin(np.hypot(*(nearest - pose[:2]).T)))
            self._segment = first + index
            s_robot = float(cumulative[self._segment] + t[index] * lengths[self._segment])
            self._s_robot = s_robot
        remaining = total - s_robot
        s_carrot = min(s_robot + p.lookahead_dist, total)
        carrot = _point_at(points, cumulative, s_carrot)
        if costmap is not None:
            visible = self._visible_carrot(pose, points, cumulative, s_robot, s_carrot,
                                           costmap)
            carrot = carrot if visible is None else visible
        reach = p.sim_time * float(max(p.max_vel_x, p.max_vel_y))
        spacing = 0.05
        s_local = np.arange(max(0.0, s_robot - 0.2), min(total, s_carrot + reach) + spacing,
                            spacing)
        s_local = np.minimum(s_local, total)
        local_path = np.column_stack((np.interp(s_local, cumulative, points[:, 0]),
                                      np.interp(s_local, cumulative, points[:, 1])))
        heading = None
        if p.heading_mode == 'goal':
            heading = goal_yaw if goal_yaw is not None else self._hold_yaw
        elif p.heading_mode == 'path':
            if goal_yaw is not None and remaining <= p.lookahead_dist:
                heading = goal_yaw
            elif total > 0.0:
                ahead = _point_at(points, cumulative, min(s_carrot + 0.05, total))
                behind = _point_at(points, cumulative, max(s_carrot - 0.05, 0.0))
                heading = math.atan2(ahead[1] - behind[1], ahead[0] - behind[0])
        return carrot, local_path, heading

    def _visible_carrot(self, pose: np.ndarray, points: np.ndarray, cumulative: np.ndarray,
                        s_robot: float, s_carrot: float, costmap) -> Optional[np.ndarray]:
        """
        Return the farthest path point up to s_carrot that the robot sees, or None.

        Seen: the straight segment from the robot to the point crosses no cell of cost
        >= 253 (nor unknown, unless allow_unknown). A point in such a cell (the global
        plan hugs a corner the scan shows a cell nearer) is first moved to the nearest
        cell within CARROT_SHIFT_M that is not and can be seen. Checked every cell length back to
        s_robot; None when nothing is seen (e.g. the robot sits in an inscribed cell:
        the critics then handle it).
        """
        step = float(costmap.resolution_m)
        ox, oy = costmap.origin_x_m, costmap.origin_y_m
        x0, y0 = (float(pose[0]) - ox) / step, (float(pose[1]) - oy) / step
        costs = costmap.costs
        allow_unknown = self.params.allow_unknown
        reach = int(math.ceil(CARROT_SHIFT_M / step))
        offsets = [(dr, dc) for dr in range(-reach, reach + 1) for dc in range(-reach, reach + 1)
                   if dr * dr + dc * dc <= reach * reach]
        offsets.sort(key=lambda o: o[0] * o[0] + o[1] * o[1])
        # A robot inside an inscribed cell (the scan shows a wall nearer than the map)
        # sees past the blocked cells around it, then must have a free line.
        start_blocked = segment_cost(costs, allow_unknown, x0, y0, x0, y0) == BLOCKED
        s = s_carrot
        while s > s_robot:
            point = _point_at(points, cumulative, s)
            x1, y1 = (float(point[0]) - ox) / step, (float(point[1]) - oy) / step
            row, col = int(math.floor(y1)), int(math.floor(x1))
            for dr, dc in offsets:
                r, c = row + dr, col + dc
                if not (0 <= r < costs.shape[0] and 0 <= c < costs.shape[1]):
                    continue
                if costs[r, c] >= 253 and not (allow_unknown and costs[r, c] == 255):
                    continue
                tx, ty = (x1, y1) if (dr, dc) == (0, 0) else (c + 0.5, r + 0.5)
                if start_blocked:
                    seen = _seen_leaving(costs, allow_unknown, x0, y0, tx, ty)
                else:
                    seen = segment_cost(costs, allow_unknown, x0, y0, tx, ty) != BLOCKED
                if seen:
                    return np.array([ox + tx * step, oy + ty * step])
                if (dr, dc) == (0, 0):
                    break   # a free path point in plain view or hidden: no shifting
            s -= step
        return None

    def _sample_targets(self, pose: np.ndarray, current: np.ndarray, carrot: np.ndarray,
                        heading_target: Optional[float]) -> np.ndarray:
        """Return the (N, 3) target twists: the dynamic-window grid plus candidates."""
        p = self.params
        low = np.maximum(p.min_velocity, current - p.acceleration * p.sim_time)
        high = np.minimum(p.max_velocity, current + p.acceleration * p.sim_time)
        low, high = np.minimum(low, high), np.maximum(low, high)
        axes = [np.linspace(lo, hi, n) if n > 1 else np.array([0.5 * (lo + hi)])
                for lo, hi, n in zip(low, high, (p.vx_samples, p.vy_samples,
                                                 p.vtheta_samples))]
        grid = np.stack(np.meshgrid(*axes, indexing='ij'), axis=-1).reshape(-1, 3)
        # Reference twists: straight for the carrot at a few speeds, turning toward the
        # heading target so as to reach it at the end of the horizon (or not turning).
        dx, dy = carrot[0] - pose[0], carrot[1] - pose[1]
        cos_yaw, sin_yaw = math.cos(pose[2]), math.sin(pose[2])
        body = np.array([cos_yaw * dx + sin_yaw * dy, -sin_yaw * dx + cos_yaw * dy])
        distance = float(np.hypot(*body))
        wz_ref = 0.0
        if heading_target is not None:
            wz_ref = float(np.clip(wrap_angle(heading_target - pose[2]) / p.sim_time,
                                   -p.max_vel_theta, p.max_vel_theta))
        candidates = [np.zeros(3), current]
        if self._previous_target is not None:
            candidates.append(self._previous_target)
        if distance > 1e-9:
            direction = body / distance
            top = self._top_speed(direction)
            for speed in (top, 0.75 * top, 0.5 * top, 0.25 * top,
                          min(top, distance / p.sim_time)):
                for wz in (wz_ref, 0.0):
                    candidates.append(np.array([speed * direction[0], speed * direction[1],
                                                wz]))
        elif wz_ref != 0.0:
            candidates.append(np.array([0.0, 0.0, wz_ref]))
        targets = np.vstack([grid, np.clip(np.array(candidates), p.min_velocity,
                                           p.max_velocity)])
        if p.max_wheel_speed_m_s is not None:
            wheel = (np.abs(targets[:, 0]) + np.abs(targets[:, 1])
                     + p.rotation_arm_m * np.abs(targets[:, 2]))
            keep = wheel <= p.max_wheel_speed_m_s * (1.0 + 1e-9)
            keep[grid.shape[0]:grid.shape[0] + 2] = True  # zero and current always stay
            targets = targets[keep]
        return targets

    def _top_speed(self, direction: np.ndarray) -> float:
        """Return the highest translation speed (m/s) along a body direction (unit)."""
        p = self.params
        limits = []
        for component, low, high in ((direction[0], p.min_vel_x, p.max_vel_x),
                                     (direction[1], p.min_vel_y, p.max_vel_y)):
            if component > 1e-12:
                limits.append(high / component)
            elif component < -1e-12:
                limits.append(low / component)
        if p.max_wheel_speed_m_s is not None:
            limits.append(p.max_wheel_speed_m_s / (abs(direction[0]) + abs(direction[1])))
        return min(limits)

    def _best_clear(self, scores: np.ndarray, pose: np.ndarray, xs: np.ndarray,
                    ys: np.ndarray, points: Optional[np.ndarray]) -> Optional[int]:
        """
        Return the best-scored trajectory that keeps its clearance from points, or None.

        The costmap check is only as exact as its cells (a cell centre 0.2 m from an
        obstacle cell's centre may be 0.17 m from the obstacle itself). Here the
        footprint circle (robot_radius) at every step must stay collision_margin from
        every point (scan returns); a robot already nearer than that may move but not
        get nearer. Trajectories are checked in score order (compiled, stopping at a
        trajectory's first point too near), so the usual cost is the best one alone.
        Without points or robot_radius: the best score.
        """
        p = self.params
        finite = np.isfinite(scores)
        if not np.any(finite):
            return None
        if points is None or p.robot_radius is None:
            return int(np.argmin(scores))
        offsets = points - pose[:2]
        distances = np.hypot(offsets[:, 0], offsets[:, 1])
        within = distances <= self._reach + p.robot_radius + p.collision_margin
        if not np.any(within):
            return int(np.argmin(scores))
        required = min(p.collision_margin, float(np.min(distances)) - p.robot_radius - 1e-3)
        limit = max(p.robot_radius + required, 0.0) ** 2
        # Nearest points first: a trajectory that hits something usually hits them.
        near = points[within][np.argsort(distances[within])]
        order = np.argsort(scores, kind='stable')[:int(np.count_nonzero(finite))]
        best = _first_clear(order.astype(np.int64), xs, ys,
                            np.ascontiguousarray(near[:, 0], dtype=np.float32),
                            np.ascontiguousarray(near[:, 1], dtype=np.float32), limit)
        return None if best < 0 else int(best)

    def _path_cost(self, costmap, pose: np.ndarray, local_path: np.ndarray) -> float:
        """
        Return the highest cost / 252 of the local path's points within reach of the robot.

        Reach: the farthest a trajectory goes (sim_time at top speed). Inscribed and
        lethal cells count as 252 (a path through them is the planner's, made on another
        costmap); unknown and off-map points count as free. 0.0 without path points.
        """
        if local_path.shape[0] == 0:
            return 0.0
        near = local_path[np.hypot(local_path[:, 0] - pose[0], local_path[:, 1] - pose[1])
                          <= self._reach]
        cols = np.floor((near[:, 0] - costmap.origin_x_m) / costmap.resolution_m).astype(int)
        rows = np.floor((near[:, 1] - costmap.origin_y_m) / costmap.resolution_m).astype(int)
        inside = (cols >= 0) & (cols < costmap.size_x) & (rows >= 0) & (rows < costmap.size_y)
        if not np.any(inside):
            return 0.0
        costs = np.asarray(costmap.costs)[rows[inside], cols[inside]].astype(np.int64)
        costs[costs == UNKNOWN_COST] = FREE_COST
        return float(min(int(np.max(costs)), MAX_NON_OBSTACLE)) / MAX_NON_OBSTACLE

    def _obstacle_critic(self, costmap, pose: np.ndarray, xs: np.ndarray,
                         ys: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """
        Return (valid, score) per trajectory: validity and highest cost along it / 252.

        Costs go through a table first: off-map points are NO_INFORMATION; unknown is
        free when allow_unknown, else invalid. When the robot's own cell is already in
        collision (inscribed, or invalid unknown), only lethal cells invalidate, inscribed
        ones count as 252 and the score is the mean cost, so the robot can move out
        instead of freezing.
        """
        p = self.params
        remap = np.arange(256, dtype=np.uint8)
        remap[UNKNOWN_COST] = FREE_COST if p.allow_unknown else UNKNOWN_COST
        col = math.floor((pose[0] - costmap.origin_x_m) / costmap.resolution_m)
        row = math.floor((pose[1] - costmap.origin_y_m) / costmap.resolution_m)
        on_map = 0 <= col < costmap.size_x and 0 <= row < costmap.size_y
        start_cost = int(remap[np.asarray(costmap.costs)[row, col] if on_map else UNKNOWN_COST])
        escape = start_cost >= INSCRIBED_COST
        if escape:
            remap[INSCRIBED_COST] = MAX_NON_OBSTACLE
            remap[UNKNOWN_COST] = remap[UNKNOWN_COST] and LETHAL_COST
        costs = _lookup(_padded_costs(costmap, remap, self._scratch), costmap, xs, ys,
                        self._scratch, start=(pose[0], pose[1]))
        worst = np.max(costs, axis=1)
        valid = worst < INSCRIBED_COST
        if escape:
            return valid, np.mean(costs, axis=1) / MAX_NON_OBSTACLE
        return valid, worst / MAX_NON_OBSTACLE


# --- helpers ------------------------------------------------------------------------

@njit(cache=True)
def _first_clear(order, xs, ys, px, py, limit2):   # pragma: no cover - compiled
    """
    Return the first trajectory in order whose every point is >= sqrt(limit2) from all points.

    xs, ys: (N, K) trajectories; px, py: the points. -1 when none is. A trajectory stops
    being checked at its first point too near (usually a near one), so rejecting costs
    little and accepting costs K x P distances.
    """
    steps = xs.shape[1]
    for candidate in order:
        clear = True
        for k in range(steps):
            x, y = xs[candidate, k], ys[candidate, k]
            for j in range(px.shape[0]):
                dx, dy = x - px[j], y - py[j]
                if dx * dx + dy * dy < limit2:
                    clear = False
                    break
            if not clear:
                break
        if clear:
            return candidate
    return -1


def _distance_to_points(xs: np.ndarray, ys: np.ndarray, points: np.ndarray,
                        scratch: Scratch) -> np.ndarray:
    """Return, for each (x, y), the distance to the nearest of points (P, 2)."""
    shape = (np.shape(xs)[0], points.shape[0])
    d2 = np.subtract(xs[:, None], points[None, :, 0].astype(np.float32),
                     out=scratch.get('d2', shape))
    d2 *= d2
    dy = np.subtract(ys[:, None], points[None, :, 1].astype(np.float32),
                     out=scratch.get('dy', shape))
    dy *= dy
    d2 += dy
    return np.sqrt(np.min(d2, axis=1))


def _seen_leaving(costs: np.ndarray, allow_unknown: bool, x0: float, y0: float, x1: float,
                  y1: float) -> bool:
    """
    Tell whether a segment (cell coordinates) is free once it has left its blocked start.

    Sampled every quarter cell: blocked cells at the start are skipped, then any blocked
    (or off-grid) sample hides the end.
    """
    count = max(2, int(math.ceil(4.0 * math.hypot(x1 - x0, y1 - y0))) + 1)
    xs = np.linspace(x0, x1, count)
    ys = np.linspace(y0, y1, count)
    cols, rows = np.floor(xs).astype(np.int64), np.floor(ys).astype(np.int64)
    inside = (rows >= 0) & (cols >= 0) & (rows < costs.shape[0]) & (cols < costs.shape[1])
    values = np.full(count, 255, dtype=np.int64)
    values[inside] = costs[rows[inside], cols[inside]]
    blocked = (values >= 253) & ~(allow_unknown & (values == 255)) | ~inside
    free = np.flatnonzero(~blocked)
    if free.size == 0:
        return False
    return not blocked[free[0]:].any()


def _point_at(points: np.ndarray, cumulative: np.ndarray, s: float) -> np.ndarray:
    """Return the point at arc length s (m) along the polyline."""
    if cumulative[-1] <= 0.0:
        return points[-1].copy()
    return np.array([np.interp(s, cumulative, points[:, 0]),
                     np.interp(s, cumulative, points[:, 1])])


def _check_number(name: str, value, positive: bool = False) -> None:
    """Raise ValueError naming the value unless it is a finite number (> 0 if positive)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f'{name} must be a number, got {value!r}')
    if not math.isfinite(value):
        raise ValueError(f'{name} must be finite, got {value!r}')
    if positive and value <= 0:
        raise ValueError(f'{name} must be > 0, got {value!r}')


def _as_vector(name: str, values) -> np.ndarray:
    """Return 3 finite floats as an array, or raise ValueError naming them."""
    try:
        array = np.asarray(values, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be 3 numbers, got {values!r}') from None
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise ValueError(f'{name} must be 3 finite numbers, got {values!r}')
    return array


def _as_points(name: str, values) -> np.ndarray:
    """Return (P, 2) float64 points without the rows holding NaN/inf, or raise ValueError."""
    array = as_xy(name, values)
    return array[np.all(np.isfinite(array), axis=1)]


def _as_path(path) -> Tuple[np.ndarray, Optional[float]]:
    """
    Return the path's (M, 2) points without repeats and its goal yaw (None if absent).

    Accepts an (M, 2) or (M, 3) array, or a list of (x, y) / (x, y, yaw) points of mixed
    lengths; only the last point's yaw counts (NaN: no goal yaw).
    """
    if isinstance(path, np.ndarray):
        rows = path if path.ndim == 2 else None
    else:
        try:
            rows = list(path)
        except TypeError:
            rows = None
    if rows is None or len(rows) == 0:
        raise ValueError('path must be a non-empty list of (x, y) or (x, y, yaw) points')
    points = np.empty((len(rows), 2))
    try:   # fast path: all points but the last as one array
        body = np.asarray(rows[:-1], dtype=np.float64).reshape(len(rows) - 1, -1)
        uniform = body.shape[1] in (2, 3) and bool(np.all(np.isfinite(body[:, :2])))
    except (TypeError, ValueError):
        uniform = False
    if uniform:
        points[:-1] = body[:, :2]
    else:
        for index, row in enumerate(rows[:-1]):
            points[index] = _path_point(index, row)[:2]
    values = _path_point(len(rows) - 1, rows[-1])
    points[-1] = values[:2]
    goal_yaw = None
    if values.size == 3:
        yaw = float(values[2])
        if math.isinf(yaw):
            raise ValueError(f'path goal yaw must be finite or NaN (none), got {yaw}')
        goal_yaw = None if math.isnan(yaw) else wrap_angle(yaw)
    keep = np.concatenate(([True], np.any(np.diff(points, axis=0) != 0.0, axis=1)))
    return np.ascontiguousarray(points[keep]), goal_yaw


def _path_point(index: int, row) -> np.ndarray:
    """Return one path point as 2 or 3 floats with a finite x and y, or raise ValueError."""
    try:
        values = np.asarray(row, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        values = np.empty(0)
    if values.size not in (2, 3):
        raise ValueError(f'path[{index}] must be (x, y) or (x, y, yaw), got {row!r}')
    if not np.all(np.isfinite(values[:2])):
        raise ValueError(f'path[{index}] has a non-finite x or y: {row!r}')
    return values


def _check_costmap(costmap) -> None:
    """Raise ValueError unless costmap has the attributes of a Costmap2D."""
    for name in ('costs', 'origin_x_m', 'origin_y_m', 'resolution_m', 'size_x', 'size_y'):
        if not hasattr(costmap, name):
            raise ValueError(f'costmap has no attribute {name!r} (expected a Costmap2D)')
    costs = np.asarray(costmap.costs)
    if costs.shape != (costmap.size_y, costmap.size_x):
        raise ValueError(f'costmap.costs has shape {costs.shape}, expected '
                         f'({costmap.size_y}, {costmap.size_x})')
    _check_number('costmap.resolution_m', costmap.resolution_m, positive=True)
    _check_number('costmap.origin_x_m', costmap.origin_x_m)
    _check_number('costmap.origin_y_m', costmap.origin_y_m)
