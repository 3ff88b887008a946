"""
The navigator's recovery behaviours (Nav2's nav2_behaviors and costmap clearing; pure, no ROS).

:class:`~mecanum_navigation.navigator.navigator.Navigator` decides when to recover (a
failure) and counts the recoveries (STUCK after ``max_recoveries``); this module runs
them. Each failure starts the next behaviour of RECOVERY_SEQUENCE (round robin, as Nav2's
default behaviour tree) with :func:`start_recovery`; each tick :func:`step_recovery`
returns its body twist, or None once it is over:

- CLEAR_LOCAL_COSTMAP: asks the node to clear the local costmap (its obstacle layer) and
  is over at once;
- SPIN: turns in place counter-clockwise by ``spin_dist`` (the odom yaw's wrapped changes
  summed), at up to ``max_rotational_vel``; over within SPIN_TOLERANCE_RAD of the angle.
  Always collision-free for a circular footprint;
- BACK_UP: moves ``backup_dist`` (straight-line distance from its start) at up to
  ``backup_speed``, holonomic: straight away from the nearest lethal cell of the local
  costmap at its start, backwards when there is none; over within BACKUP_TOLERANCE_M of
  the distance. Skipped or stopped (a warning) when the rest of the motion would bring
  the footprint nearer an obstacle than ``min(robot_radius_m, its start clearance)``;
- WAIT: zero twist for ``wait_duration`` s.

Spin and back up stop (a warning) after ``time_allowance`` s. Their speed is the
fastest that still stops on the target with half the controller's deceleration
(:func:`approach_speed`), reached from the current twist within its acceleration
limits. Units: metres, radians, seconds; twists are body twists in base_link (vx
forward, vy left, wz counter-clockwise, REP-103); poses and the costmap in odom.
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence, Tuple

from mecanum_control.angles import wrap_angle
from mecanum_navigation.controller.local_controller import ramp_step
from mecanum_navigation.costmap.costmap_2d import Costmap2D, LETHAL_OBSTACLE
import numpy as np

Pose2D = Tuple[float, float, float]
Twist2D = Tuple[float, float, float]
Point = Tuple[float, float]

CLEAR_LOCAL_COSTMAP = 'clear_local_costmap'
SPIN = 'spin'
BACK_UP = 'back_up'
WAIT = 'wait'
#: The recoveries, tried in turn (round robin, as Nav2's default behaviour tree).
RECOVERY_SEQUENCE = (CLEAR_LOCAL_COSTMAP, SPIN, BACK_UP, WAIT)

ZERO_TWIST: Twist2D = (0.0, 0.0, 0.0)
#: A spin ends this near its angle (rad); a back up this near its distance (m).
SPIN_TOLERANCE_RAD = 0.02
BACKUP_TOLERANCE_M = 0.005


@dataclass
class Recovery:
    """
    The state of the running recovery behaviour.

    kind: one of RECOVERY_SEQUENCE; start_s: when it started; reason: the failure that
    started it; start_pose: the odom pose then; turned_rad / last_yaw: the spin so far
    and the yaw it was last measured at; direction / clearance_m: the back up's unit
    direction (odom) and the distance to the nearest lethal cell at its start.
    """

    kind: str
    start_s: float
    reason: str
    start_pose: Pose2D
    turned_rad: float = 0.0
    last_yaw: float = 0.0
    direction: Tuple[float, float] = (0.0, 0.0)
    clearance_m: float = math.inf


@dataclass(frozen=True)
class RecoveryStep:
    """One tick of a recovery: its twist (None: over), a costmap clear, a warning ('' none)."""

    twist: Optional[Twist2D]
    clear_local_costmap: bool = False
    warning: str = ''

    @property
    def done(self) -> bool:
        """Tell whether the recovery is over (no twist to command)."""
        return self.twist is None


def start_recovery(kind: str, now_s: float, reason: str, odom_pose: Sequence[float],
                   local_costmap: Costmap2D) -> Recovery:
    """Start a recovery of a kind at odom_pose; a back up picks its direction here."""
    start_pose = tuple(float(v) for v in odom_pose)
    recovery = Recovery(kind, now_s, reason, start_pose, last_yaw=start_pose[2])
    if kind == BACK_UP:
        recovery.direction, recovery.clearance_m = backup_direction(local_costmap, start_pose)
    return recovery


def step_recovery(recovery: Recovery, now_s: float, odom_pose: Sequence[float],
                  current_twist: Sequence[float], local_costmap: Costmap2D, params,
                  controller_params) -> RecoveryStep:
    """
    Run the recovery one tick (see the module docstring).

    params: the behaviours' parameters, NavigatorParams' fields robot_radius_m,
    spin_dist, max_rotational_vel, backup_dist, backup_speed, wait_duration and
    time_allowance; controller_params: the ControllerParams whose acceleration limits
    and control period the motions keep.
    """
    if recovery.kind == CLEAR_LOCAL_COSTMAP:
        return RecoveryStep(None, clear_local_costmap=True)
    elapsed = now_s - recovery.start_s
    if recovery.kind == WAIT:
        return wait_step(elapsed, params.wait_duration)
    if elapsed > params.time_allowance:
        return RecoveryStep(None, warning=f'{recovery.kind} did not finish within '
                                          f'{params.time_allowance:g} s')
    pose = tuple(float(v) for v in odom_pose)
    if recovery.kind == SPIN:
        return spin_step(recovery, pose[2], current_twist, params.spin_dist,
                         params.max_rotational_vel, controller_params)
    return backup_step(recovery, pose, current_twist, local_costmap, params.backup_dist,
                       params.backup_speed, params.robot_radius_m, controller_params)


def wait_step(elapsed_s: float, wait_duration: float) -> RecoveryStep:
    """Return zero twist until wait_duration s have elapsed (within 1 ns), then done."""
    return RecoveryStep(ZERO_TWIST if elapsed_s < wait_duration - 1e-9 else None)


def spin_step(recovery: Recovery, yaw: float, current_twist: Sequence[float], spin_dist: float,
              max_rotational_vel: float, controller_params) -> RecoveryStep:
    """
    Add the yaw's change to the spin; return the next turn, or done within the tolerance.

    The turn is counter-clockwise at approach_speed of the angle remaining (acc_lim_theta),
    ramped from current_twist.
    """
    p = controller_params
    recovery.turned_rad += wrap_angle(yaw - recovery.last_yaw)
    recovery.last_yaw = yaw
    remaining = spin_dist - recovery.turned_rad
    if remaining <= SPIN_TOLERANCE_RAD:
        return RecoveryStep(None)
    speed = approach_speed(remaining, max_rotational_vel, p.acc_lim_theta, p.control_period)
    return RecoveryStep(_ramp(current_twist, (0.0, 0.0, speed), p))


def backup_step(recovery: Recovery, pose: Sequence[float], current_twist: Sequence[float],
                costmap: Costmap2D, backup_dist: float, backup_speed: float,
                robot_radius_m: float, controller_params) -> RecoveryStep:
    """
    Return the next back up twist, done at the distance, or stopped when not clear.

    The rest of the distance along recovery.direction must keep min(robot_radius_m,
    recovery.clearance_m) from the costmap's lethal cells (backup_clear); the speed is
    approach_speed of that rest (the smaller of acc_lim_x and acc_lim_y), the direction
    turned into the body frame of pose, ramped from current_twist.
    """
    p = controller_params
    moved = math.hypot(pose[0] - recovery.start_pose[0], pose[1] - recovery.start_pose[1])
    remaining = backup_dist - moved
    if remaining <= BACKUP_TOLERANCE_M:
        return RecoveryStep(None)
    dx, dy = recovery.direction
    if not backup_clear(costmap, pose[:2], (dx, dy), remaining,
                        min(robot_radius_m, recovery.clearance_m)):
        return RecoveryStep(None, warning='back up stopped: it would bring the robot nearer '
                                          'an obstacle')
    limit = min(p.acc_lim_x, p.acc_lim_y)
    speed = approach_speed(remaining, backup_speed, limit, p.control_period)
    cos_yaw, sin_yaw = math.cos(pose[2]), math.sin(pose[2])
    body = (speed * (cos_yaw * dx + sin_yaw * dy), speed * (-sin_yaw * dx + cos_yaw * dy))
    return RecoveryStep(_ramp(current_twist, (body[0], body[1], 0.0), p))


def approach_speed(remaining: float, max_speed: float, acceleration: float,
                   control_period: float) -> float:
    """
    Return the fastest speed toward a target remaining away that still stops on it.

    min(max_speed, sqrt(acceleration * remaining): stopping with half the deceleration,
    remaining / (2 control_period): at most half of it in one period).
    """
    return min(max_speed, math.sqrt(acceleration * remaining),
               remaining / (2.0 * control_period))


def lethal_points(costmap: Costmap2D) -> np.ndarray:
    """Return the (N, 2) centres of the costmap's lethal cells."""
    rows, cols = np.nonzero(costmap.costs == LETHAL_OBSTACLE)
    return np.column_stack((costmap.origin_x_m + (cols + 0.5) * costmap.resolution_m,
                            costmap.origin_y_m + (rows + 0.5) * costmap.resolution_m))


def backup_direction(costmap: Costmap2D, pose: Sequence[float]) -> Tuple[Point, float]:
    """
    Return (unit direction in the costmap frame, clearance m) for backing up from pose.

    The direction points from the nearest lethal cell's centre to the robot; with no
    lethal cell (or the robot on one) it is the robot's backward direction. The
    clearance is the distance to that nearest lethal cell (inf when there is none).
    """
    x, y, yaw = (float(v) for v in pose)
    backward = (-math.cos(yaw), -math.sin(yaw))
    obstacles = lethal_points(costmap)
    if obstacles.shape[0] == 0:
        return backward, math.inf
    distances = np.hypot(obstacles[:, 0] - x, obstacles[:, 1] - y)
    index = int(np.argmin(distances))
    clearance = float(distances[index])
    if clearance < 1e-9:
        return backward, 0.0
    return ((x - obstacles[index, 0]) / clearance, (y - obstacles[index, 1]) / clearance), \
        clearance


def backup_clear(costmap: Costmap2D, xy: Sequence[float], direction: Sequence[float],
                 distance_m: float, clearance_m: float) -> bool:
    """
    Tell whether moving distance_m from xy along direction keeps clearance_m from obstacles.

    The straight motion is sampled every half cell; each sample must be at least
    clearance_m from every lethal cell's centre and on the costmap.
    """
    steps = max(1, int(math.ceil(distance_m / (0.5 * costmap.resolution_m))))
    t = np.linspace(0.0, distance_m, steps + 1)[1:]
    xs = xy[0] + direction[0] * t
    ys = xy[1] + direction[1] * t
    inside = ((xs >= costmap.origin_x_m) & (xs < costmap.origin_x_m + costmap.size_x_m)
              & (ys >= costmap.origin_y_m) & (ys < costmap.origin_y_m + costmap.size_y_m))
    if not np.all(inside):
        return False
    obstacles = lethal_points(costmap)
    if obstacles.shape[0] == 0:
        return True
    d2 = (xs[:, None] - obstacles[None, :, 0]) ** 2 + (ys[:, None] - obstacles[None, :, 1]) ** 2
    return bool(np.sqrt(d2.min()) >= clearance_m - 1e-9)


def _ramp(current: Sequence[float], target: Sequence[float], params) -> Twist2D:
    """Return the twist one control period toward target within the acceleration limits."""
    twist = ramp_step(current, target, params.acceleration, params.control_period)
    return float(twist[0]), float(twist[1]), float(twist[2])
