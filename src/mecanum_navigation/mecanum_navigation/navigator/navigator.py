"""
The navigation state machine of NavigateToPose (Nav2 bt_navigator's job; pure, no ROS).

:class:`Navigator` runs one goal at a time, ticked at the control rate with what the
node knows (:class:`TickInputs`): the time, the robot's pose in ``map`` and in ``odom``
(REP-105; map -> odom is derived from the two), its body twist, the latest global
costmap (map frame) and the local costmap (odom frame). It plans with an injected plan
function (``plan_fn(costmap, (x, y), (x, y)) -> [(x, y), ...]`` raising
:class:`~mecanum_navigation.planner.planner.PlanningError`) and follows with an injected
:class:`~mecanum_navigation.controller.local_controller.LocalController`. Each tick returns a
:class:`TickOutput`: the body twist to command (None when idle), the goals that ended
(:class:`Outcome`, with the action's error codes), feedback, a new plan (map frame)
when it replanned, and whether to clear the local costmap. It behaves like Nav2's
default behaviour tree ("navigate w/ replanning and recovery"):

- goal validation before moving, in this order: non-finite pose -> INVALID_GOAL (as
  does an ``invalid_reason`` given by the node, e.g. an unknown frame); no map yet ->
  UNKNOWN; no robot pose -> TF_ERROR; goal off the global costmap -> GOAL_OUTSIDE_MAP;
  outside the ``authorised_zone`` (a :class:`~mecanum_safety.zone.Zone`,
  map frame; None = no zone), or so near its border that the footprint
  (``robot_radius_m``) would cross it -> GOAL_OUTSIDE_ZONE; goal cell lethal (254,
  also keepout zones) or inscribed (253, the footprint would touch an obstacle) on the
  map's costmap, or the footprint nearer than its radius to a lethal cell's square
  (one rule for what cannot be occupied) -> GOAL_IN_OBSTACLE (GOAL_OUTSIDE_ZONE when
  only the zone makes it so: a goal a few cm beyond the exact check, on the costmap's
  cells); no plan on the
  global costmap nor on the map's -> NO_VALID_PATH (the planner's reason, e.g.
  unknown space or unreachable), except that with a zone a plan is then tried once on
  the map's costmap without the zone (TickInputs.unzoned_costmap): when that one
  exists, the only route leaves the zone -> GOAL_OUTSIDE_ZONE (or NO_VALID_PATH when
  the robot itself is outside the zone). The costmaps are the node's: with a zone,
  everything outside it is lethal in both (ZoneLayer, before inflation), so no plan
  or trajectory leaves it. The scan's obstacles (a person) steer plans but
  never fail a goal (see TickInputs.static_costmap). A robot whose own cell is
  blocked (>= 253, e.g. after being pushed against a wall) plans from the nearest free
  cell within 0.5 m, its own position prepended;
- replanning every 1 / ``replan_frequency`` s, and at once when the rest of the path
  crosses a lethal cell of the map's costmap (a new map or keepout). A failed periodic
  replan keeps a still-clear path (warning); a blocked path without a new one is a
  failure (code NO_VALID_PATH if it ends the goal);
- following: the plan is pruned to the robot (kept from the path point behind it, moved
  on every PRUNE_STEP_M of progress, so the controller's path stays the same between
  prunes and replans), transformed into odom with map -> odom each tick, the goal yaw
  as its last point's yaw, and given to the controller with the local costmap;
- failures: the ProgressChecker fails (the robot stays within
  ``required_movement_radius`` for ``movement_time_allowance``), or the controller
  reports ``no_valid_trajectory`` for ``failure_tolerance`` s, or a blocked path cannot
  be replanned. Each failure starts the next recovery of the round robin
  RECOVERY_SEQUENCE, run by :mod:`~mecanum_navigation.navigator.recoveries`: clear the
  local costmap (the node clears its obstacle layer), spin in place by ``spin_dist``
  (always collision-free for a circular footprint), back up ``backup_dist`` (holonomic:
  straight away from the nearest lethal cell of the local costmap, backwards when there
  is none; skipped or stopped when that motion would bring the footprint nearer an
  obstacle than ``min(robot_radius_m, its start clearance)``), wait ``wait_duration``
  s. After a recovery the navigator replans and resumes. The failure after
  ``max_recoveries`` recoveries ends the goal with STUCK (NO_VALID_PATH for a planning
  failure), with the reason;
- success when the controller reports ``goal_reached`` (its goal checker: xy and yaw
  tolerances); a newer goal preempts (the old one ends PREEMPTED, also if the new one
  then fails validation, as in Nav2), cancel ends CANCELED. The tick in which a goal
  ends commands zero velocity;
- feedback every tick: the robot pose in map, the distance remaining along the path
  (from the robot's projection on it), the navigation time, the estimated time
  remaining = distance remaining / mean speed so far (odom distance travelled / time;
  0 = unknown while the mean is below 0.01 m/s or less than 0.1 m remains, as Nav2),
  and the number of recoveries.

Units: metres, radians, seconds, m/s and rad/s; twists are body twists in base_link
(vx forward, vy left, wz counter-clockwise, REP-103).
"""

from dataclasses import dataclass, field
import math
from typing import Callable, Hashable, List, Optional, Sequence, Tuple

from mecanum_control.angles import wrap_angle
from mecanum_localization.transforms import PlanarTransform
from mecanum_navigation.controller.local_controller import (
    LocalController, ProgressChecker, STATUS_GOAL_REACHED, STATUS_NO_VALID_TRAJECTORY,
    STATUS_STALE_POSE)
from mecanum_navigation.costmap.costmap_2d import (
    Costmap2D, INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE)
from mecanum_navigation.navigator.recoveries import (
    Recovery, RECOVERY_SEQUENCE, start_recovery, step_recovery, ZERO_TWIST)
from mecanum_navigation.planner.planner import PlanningError
from mecanum_safety.zone import Zone
import numpy as np

Pose2D = Tuple[float, float, float]
Twist2D = Tuple[float, float, float]
Point = Tuple[float, float]
PlanFunction = Callable[[Costmap2D, Point, Point], Sequence[Point]]

# Result codes (error_code of nav2_msgs' NavigateToPose, NavigateThroughPoses and
# FollowWaypoints results): Nav2's own (NONE, and 9000-9003 as Nav2 defines them from
# Kilted on), then this navigator's from 9100. Every value is unique.
NONE = 0
UNKNOWN = 9000
FAILED_TO_LOAD_BEHAVIOR_TREE = 9001   # never sent: the navigator has one fixed behaviour
TF_ERROR = 9002
TIMEOUT = 9003                        # never sent: goals have no time limit here
GOAL_OUTSIDE_ZONE = 9100
GOAL_IN_OBSTACLE = 9101
GOAL_OUTSIDE_MAP = 9102
NO_VALID_PATH = 9103
STUCK = 9104
CANCELED = 9105
PREEMPTED = 9106
INVALID_GOAL = 9107

IDLE = 'idle'
FOLLOWING = 'following'
RECOVERING = 'recovering'

#: The pruned path's first point moves on after this much progress along it (m).
PRUNE_STEP_M = 0.5
#: How far along the path the robot's projection is searched from the last one (m).
PROJECTION_SEARCH_M = 1.5
#: A robot whose own cell is blocked plans from the nearest free cell this near (m).
START_ESCAPE_RADIUS_M = 0.5


@dataclass(frozen=True)
class NavigatorParams:
    """
    Parameters of the Navigator (Nav2 names where Nav2 has them; see nav2_params.yaml).

    authorised_zone: the Zone (mecanum_safety.zone, map frame) goals must be
    in, footprint and all, or None for no zone (the node loads it from zone_file);
    robot_radius_m: the footprint radius (clearance kept from the zone's border by goals
    and by the back up from obstacles); the spin turns
    by spin_dist rad at up to max_rotational_vel rad/s; the back up moves backup_dist m
    at up to backup_speed m/s; each recovery motion stops after time_allowance s.
    """

    replan_frequency: float = 1.0
    failure_tolerance: float = 0.3
    max_recoveries: int = 6
    authorised_zone: Optional[Zone] = None
    robot_radius_m: float = 0.2
    spin_dist: float = 1.57
    max_rotational_vel: float = 1.0
    backup_dist: float = 0.15
    backup_speed: float = 0.1
    wait_duration: float = 2.0
    time_allowance: float = 10.0

    def __post_init__(self) -> None:
        """Validate every field (ValueError naming it)."""
        for name in ('replan_frequency', 'robot_radius_m', 'spin_dist', 'max_rotational_vel',
                     'backup_dist', 'backup_speed', 'wait_duration', 'time_allowance'):
            _check_number(name, getattr(self, name), minimum=0.0, inclusive=False)
        _check_number('failure_tolerance', self.failure_tolerance, minimum=0.0)
        if (isinstance(self.max_recoveries, bool) or not isinstance(self.max_recoveries, int)
                or self.max_recoveries < 0):
            raise ValueError(f'max_recoveries must be an integer >= 0, got '
                             f'{self.max_recoveries!r}')
        if self.authorised_zone is not None and not isinstance(self.authorised_zone, Zone):
            raise ValueError('authorised_zone must be a Zone (mecanum_safety.zone) '
                             f'or None, got {self.authorised_zone!r}')


@dataclass
class TickInputs:
    """
    What the navigator sees in one tick.

    now_s: time (s); robot_in_map / robot_in_odom: (x, y, yaw) of base_link, None when
    unknown (pose_error says why); twist: the current body twist (None: the last
    command is used); pose_age_s: how old the odom pose is (the controller brakes when
    above its transform_tolerance); global_costmap: map frame, None before a map came;
    local_costmap: odom frame; obstacle_points: (P, 2) returns of the newest scan in the
    odom frame, for the controller's exact clearance check (None: cells only);
    static_costmap: the global costmap without what the scan added (map, keepout,
    inflation; None: global_costmap is that). What the scan sees (a person) steers the
    plans but never fails a goal: goal checks, "path blocked" and the fallback plan
    when the scan's obstacles leave no way use the static costmap. unzoned_costmap:
    the static costmap without the authorised zone's layer (map, keepout, inflation),
    planned on only when a new goal has no plan with the zone, to tell a goal whose
    only route leaves the zone (GOAL_OUTSIDE_ZONE) from an unreachable one (None: no
    such check, NO_VALID_PATH).
    """

    now_s: float
    robot_in_map: Optional[Pose2D]
    robot_in_odom: Optional[Pose2D]
    local_costmap: Costmap2D
    global_costmap: Optional[Costmap2D] = None
    twist: Optional[Twist2D] = None
    pose_age_s: float = 0.0
    pose_error: str = ''
    obstacle_points: Optional[np.ndarray] = None
    static_costmap: Optional[Costmap2D] = None
    unzoned_costmap: Optional[Costmap2D] = None

    @property
    def map_costmap(self) -> Optional[Costmap2D]:
        """Return the static costmap, or the global one when there is no separate one."""
        return self.static_costmap if self.static_costmap is not None else self.global_costmap


@dataclass(frozen=True)
class Outcome:
    """A goal that ended: its id, the result code (NONE on success) and why in words."""

    goal_id: Hashable
    code: int
    message: str


@dataclass(frozen=True)
class Feedback:
    """Progress of the active goal (see the module docstring)."""

    goal_id: Hashable
    pose_in_map: Pose2D
    distance_remaining_m: float
    navigation_time_s: float
    estimated_time_remaining_s: float
    number_of_recoveries: int


@dataclass
class TickOutput:
    """What one tick decided (see the module docstring)."""

    twist: Optional[Twist2D] = None
    outcomes: List[Outcome] = field(default_factory=list)
    feedback: Optional[Feedback] = None
    new_plan: Optional[List[Point]] = None
    clear_local_costmap: bool = False
    events: List[str] = field(default_factory=list)
    warnings: List[str] = field(default_factory=list)
    controller_status: str = ''


@dataclass
class _Goal:
    goal_id: Hashable
    pose: Pose2D
    invalid_reason: str = ''


class _Navigation:
    """The state of the active goal."""

    def __init__(self, goal: _Goal, now_s: float, odom_pose: Pose2D):
        self.goal = goal
        self.start_s = now_s
        self.state = FOLLOWING
        self.points = np.zeros((0, 2))
        self.cumulative = np.zeros(1)
        self.plan_version = 0
        self.plan_time_s = now_s
        self.segment = 0
        self.s_m = 0.0
        self.prune_index = 0
        self.odom_path: Optional[np.ndarray] = None
        self.odom_path_key = None
        self.recoveries = 0
        self.recovery: Optional[Recovery] = None
        self.failing_since_s: Optional[float] = None
        self.travelled_m = 0.0
        self.last_odom_pose = odom_pose

    def set_plan(self, points: Sequence[Point], now_s: float) -> None:
        """Take a new plan (map frame) and restart the progress along it."""
        self.points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        lengths = np.hypot(*np.diff(self.points, axis=0).T) if len(self.points) > 1 \
            else np.zeros(0)
        self.cumulative = np.concatenate(([0.0], np.cumsum(lengths)))
        self.plan_version += 1
        self.plan_time_s = now_s
        self.segment = 0
        self.s_m = 0.0
        self.prune_index = 0

    @property
    def distance_remaining_m(self) -> float:
        """Return the path length from the robot's projection to the goal."""
        return max(0.0, float(self.cumulative[-1]) - self.s_m)


class Navigator:
    """NavigateToPose's state machine (see the module docstring)."""

    def __init__(self, params: NavigatorParams, controller: LocalController,
                 plan_fn: PlanFunction, progress_checker: Optional[ProgressChecker] = None):
        """Store the parts; progress_checker defaults to Nav2's (0.5 m in 10 s)."""
        if not isinstance(params, NavigatorParams):
            raise ValueError(f'params must be NavigatorParams, not {type(params).__name__}')
        if not callable(getattr(controller, 'compute_velocity', None)):
            raise ValueError('controller must have compute_velocity (a LocalController)')
        if not callable(plan_fn):
            raise ValueError('plan_fn must be callable: plan_fn(costmap, start, goal)')
        self.params = params
        self.controller = controller
        self.plan_fn = plan_fn
        self.progress_checker = progress_checker or ProgressChecker()
        self._pending: List[_Goal] = []
        self._cancels: List[Hashable] = []
        self._nav: Optional[_Navigation] = None
        self._last_command: Twist2D = ZERO_TWIST

    # --- requests ------------------------------------------------------------------

    @property
    def active_goal_id(self) -> Optional[Hashable]:
        """Return the id of the goal being navigated to, or None."""
        return None if self._nav is None else self._nav.goal.goal_id

    @property
    def active_goal_pose(self) -> Optional[Pose2D]:
        """Return the (x, y, yaw) in map of the goal being navigated to, or None."""
        return None if self._nav is None else self._nav.goal.pose

    @property
    def state(self) -> str:
        """Return 'idle', 'following' or 'recovering'."""
        return IDLE if self._nav is None else self._nav.state

    def submit(self, goal_id: Hashable, pose_in_map: Sequence[float],
               invalid_reason: str = '') -> None:
        """
        Queue a goal (x, y, yaw in map) for the next tick, which starts it.

        It preempts the active goal. invalid_reason (e.g. an unknown frame) makes it
        fail with INVALID_GOAL there.
        """
        try:
            x, y, yaw = (float(v) for v in pose_in_map)
        except (TypeError, ValueError):
            x = y = yaw = math.nan
            invalid_reason = invalid_reason or f'goal pose must be (x, y, yaw), got ' \
                f'{pose_in_map!r}'
        self._pending.append(_Goal(goal_id, (x, y, yaw), invalid_reason))

    def cancel(self, goal_id: Hashable) -> bool:
        """Ask the next tick to cancel a goal (active or queued); False if unknown."""
        known = goal_id == self.active_goal_id or any(
            goal.goal_id == goal_id for goal in self._pending)
        if known and goal_id not in self._cancels:
            self._cancels.append(goal_id)
        return known

    # --- the tick ------------------------------------------------------------------

    def tick(self, inputs: TickInputs) -> TickOutput:
        """Advance by one control period (see the module docstring)."""
        out = TickOutput()
        for goal_id in self._cancels:
            kept = [goal for goal in self._pending if goal.goal_id != goal_id]
            if len(kept) != len(self._pending):
                self._pending = kept
                out.outcomes.append(Outcome(goal_id, CANCELED, 'canceled before it started'))
            elif goal_id == self.active_goal_id:
                self._end(out, CANCELED, 'canceled')
        self._cancels = []
        pending, self._pending = self._pending, []
        for goal in pending[:-1]:
            out.outcomes.append(Outcome(goal.goal_id, PREEMPTED,
                                        'preempted by a newer goal before it started'))
        if pending:
            if self._nav is not None:
                self._end(out, PREEMPTED, 'preempted by a newer goal')
            self._start(pending[-1], inputs, out)
        if self._nav is not None:
            self._step(inputs, out)
        if out.outcomes and self._nav is None:
            out.twist = ZERO_TWIST
        if out.twist is not None:
            self._last_command = out.twist
        return out

    def _end(self, out: TickOutput, code: int, message: str) -> None:
        """End the active goal with a result code."""
        nav = self._nav
        out.outcomes.append(Outcome(nav.goal.goal_id, code, message))
        out.twist = ZERO_TWIST
        out.feedback = None
        self._nav = None

    def _start(self, goal: _Goal, inputs: TickInputs, out: TickOutput) -> None:
        """Validate a goal and plan to it; it becomes active or ends at once."""
        code, message, points = self._validate(goal, inputs)
        if code != NONE:
            out.outcomes.append(Outcome(goal.goal_id, code, message))
            return
        nav = _Navigation(goal, inputs.now_s, tuple(inputs.robot_in_odom))
        nav.set_plan(points, inputs.now_s)
        self._nav = nav
        self.controller.reset()
        self.progress_checker.reset()
        out.new_plan = [tuple(p) for p in nav.points.tolist()]
        x, y, yaw = goal.pose
        out.events.append(f'navigating to ({x:.2f}, {y:.2f}, {yaw:.2f}): path of '
                          f'{nav.distance_remaining_m:.2f} m')

    def _validate(self, goal: _Goal, inputs: TickInputs):
        """Return (code, message, plan points) for a new goal (code NONE: go)."""
        x, y, yaw = goal.pose
        where = f'({x:.2f}, {y:.2f})'
        if goal.invalid_reason:
            return INVALID_GOAL, goal.invalid_reason, None
        if not all(math.isfinite(v) for v in goal.pose):
            return INVALID_GOAL, f'goal pose is not finite: x={x}, y={y}, yaw={yaw}', None
        costmap = inputs.map_costmap
        if costmap is None or inputs.global_costmap is None:
            return UNKNOWN, 'no map received yet: cannot check or plan to the goal', None
        if inputs.robot_in_map is None or inputs.robot_in_odom is None:
            return TF_ERROR, f'robot pose unknown: {inputs.pose_error or "no transform"}', None
        cell = costmap.world_to_map(x, y)
        if cell is None:
            return GOAL_OUTSIDE_MAP, (f'goal {where} is outside the map (x '
                                      f'{costmap.origin_x_m:.2f}..'
                                      f'{costmap.origin_x_m + costmap.size_x_m:.2f}, y '
                                      f'{costmap.origin_y_m:.2f}..'
                                      f'{costmap.origin_y_m + costmap.size_y_m:.2f} m)'), None
        zone = self.params.authorised_zone
        radius = self.params.robot_radius_m
        if zone is not None:
            if not zone.contains_point(x, y):
                return GOAL_OUTSIDE_ZONE, f'goal {where} is outside the authorised zone', None
            clearance = float(zone.clearance(np.array([x]), np.array([y]))[0])
            if clearance < radius:
                return GOAL_OUTSIDE_ZONE, (
                    f"goal {where} is within {radius:g} m of the authorised zone's border "
                    f'({clearance:.2f} m): the footprint would cross it'), None
        cost = int(costmap.costs[cell])
        unzoned = inputs.unzoned_costmap
        if (zone is not None and cost >= INSCRIBED_INFLATED_OBSTACLE and unzoned is not None
                and unzoned.same_geometry(costmap)
                and int(unzoned.costs[cell]) < INSCRIBED_INFLATED_OBSTACLE):
            return GOAL_OUTSIDE_ZONE, (
                f"goal {where} is within {radius:g} m of the authorised zone's border on the "
                "costmap's cells (a cell outside the zone): the footprint would cross it"), None
        if cost == LETHAL_OBSTACLE:
            return GOAL_IN_OBSTACLE, (f'goal {where} is in an obstacle or keepout zone '
                                      f'(lethal cell)'), None
        if cost == INSCRIBED_INFLATED_OBSTACLE:
            return GOAL_IN_OBSTACLE, (f'goal {where} is too close to an obstacle: the '
                                      f'footprint would touch it (inscribed cell)'), None
        # The inflation measures between cell centres; the footprint against the lethal
        # cells' squares is the one rule (a goal 0.15 m from a wall passed the cells).
        obstacles = unzoned if (unzoned is not None and unzoned.same_geometry(costmap)) \
            else costmap
        clearance = obstacles.lethal_clearance_m(x, y, radius)
        if clearance < radius:
            return GOAL_IN_OBSTACLE, (
                f'goal {where} is {clearance:.2f} m from an obstacle: the footprint (radius '
                f'{radius:g} m) cannot be there'), None
        try:
            points = self._plan_steered(inputs, (x, y))
        except PlanningError as error:
            if zone is not None and unzoned is not None:
                leaves = self._route_leaves_zone(inputs, (x, y))
                if leaves:
                    return leaves
            return NO_VALID_PATH, f'no valid path to goal {where}: {error}', None
        return NONE, '', points

    def _route_leaves_zone(self, inputs: TickInputs, goal: Point):
        """
        Return (code, message, None) when a goal with no plan in the zone has one without it.

        Called only once planning with the zone failed: one more plan, on the map's
        costmap without the zone's layer. None when that fails too (the goal is simply
        unreachable).
        """
        try:
            self._plan(inputs.unzoned_costmap, inputs.robot_in_map, goal)
        except PlanningError:
            return None
        where = f'({goal[0]:.2f}, {goal[1]:.2f})'
        rx, ry = (float(v) for v in inputs.robot_in_map[:2])
        if not self.params.authorised_zone.contains_point(rx, ry):
            return NO_VALID_PATH, (f'no valid path to goal {where}: the robot ({rx:.2f}, '
                                   f'{ry:.2f}) is outside the authorised zone'), None
        return GOAL_OUTSIDE_ZONE, (f'no route to {where} inside the authorised zone (the only '
                                   'route leaves it)'), None

    def _plan_steered(self, inputs: TickInputs, goal: Point) -> List[Point]:
        """Plan on the global costmap; where its scan obstacles leave no way, on the map's."""
        try:
            return self._plan(inputs.global_costmap, inputs.robot_in_map, goal)
        except PlanningError:
            if inputs.map_costmap is inputs.global_costmap:
                raise
            return self._plan(inputs.map_costmap, inputs.robot_in_map, goal)

    def _plan(self, costmap: Costmap2D, robot: Pose2D, goal: Point) -> List[Point]:
        """Plan from the robot (or the nearest free cell, see the docstring) to goal."""
        start = (float(robot[0]), float(robot[1]))
        cell = costmap.world_to_map(*start)
        if cell is None:
            raise PlanningError(f'the robot ({start[0]:.2f}, {start[1]:.2f}) is outside the '
                                'map')
        if int(costmap.costs[cell]) >= INSCRIBED_INFLATED_OBSTACLE:
            free = nearest_free_cell(costmap, start, START_ESCAPE_RADIUS_M)
            if free is None:
                raise PlanningError(f'the robot ({start[0]:.2f}, {start[1]:.2f}) is in an '
                                    f'obstacle with no free cell within '
                                    f'{START_ESCAPE_RADIUS_M} m')
            return [start] + [tuple(p) for p in self.plan_fn(costmap, free, goal)]
        return [tuple(p) for p in self.plan_fn(costmap, start, goal)]

    # --- running -------------------------------------------------------------------

    def _step(self, inputs: TickInputs, out: TickOutput) -> None:
        """Replan, follow or recover for the active goal; fill the twist and feedback."""
        nav = self._nav
        if inputs.robot_in_map is None or inputs.robot_in_odom is None:
            self._end(out, TF_ERROR, f'lost the robot pose: '
                                     f'{inputs.pose_error or "no transform"}')
            return
        odom_pose = tuple(float(v) for v in inputs.robot_in_odom)
        nav.travelled_m += math.hypot(odom_pose[0] - nav.last_odom_pose[0],
                                      odom_pose[1] - nav.last_odom_pose[1])
        nav.last_odom_pose = odom_pose
        self._update_progress(inputs.robot_in_map)
        if nav.state == RECOVERING:
            twist = self._recover(inputs, out)
            if twist is not None:
                out.twist = twist
                self._feedback(inputs, out)
                return
            self._resume(inputs, out)
            if self._nav is None:
                return
        self._follow(inputs, out)
        if self._nav is not None:
            self._feedback(inputs, out)

    def _update_progress(self, robot_in_map: Pose2D) -> None:
        """Project the robot on the plan (forward from the last projection)."""
        nav = self._nav
        nav.segment, nav.s_m = project_onto_path(
            nav.points, nav.cumulative, robot_in_map[0], robot_in_map[1], nav.segment,
            PROJECTION_SEARCH_M)
        if nav.s_m - nav.cumulative[nav.prune_index] >= PRUNE_STEP_M:
            nav.prune_index = nav.segment

    def _follow(self, inputs: TickInputs, out: TickOutput) -> None:
        """Replan when due or blocked, then run the controller on the odom path."""
        nav = self._nav
        blocked = path_blocked(inputs.map_costmap, nav.points[nav.segment + 1:])
        due = inputs.now_s - nav.plan_time_s >= 1.0 / self.params.replan_frequency - 1e-9
        if blocked or due:
            error = self._replan(inputs, out)
            if error and blocked:
                self._failure(inputs, out, NO_VALID_PATH,
                              f'the path is blocked and no new path was found ({error})')
                return
            if error:
                nav.plan_time_s = inputs.now_s
                out.warnings.append(f'replanning failed, keeping the current path: {error}')
        # Rounded to a micrometre / microradian: the same map -> odom, derived from two
        # lookups, gives the same path (the controller keeps its state while it is).
        exact = map_to_odom_transform(inputs.robot_in_map, inputs.robot_in_odom)
        map_to_odom = PlanarTransform(round(exact.x, 6), round(exact.y, 6), round(exact.yaw, 6))
        path = self._odom_path(map_to_odom)
        current = self._last_command if inputs.twist is None else tuple(inputs.twist)
        twist, status = self.controller.compute_velocity(
            inputs.robot_in_odom, current, path, inputs.local_costmap, inputs.pose_age_s,
            obstacle_points=inputs.obstacle_points)
        out.controller_status = status
        if status == STATUS_STALE_POSE:
            out.warnings.append('the robot pose (odom -> base_link) is older than '
                                'transform_tolerance: braking')
        if status == STATUS_GOAL_REACHED:
            self._end(out, NONE, 'goal reached')
            return
        out.twist = twist
        now = inputs.now_s
        if status == STATUS_NO_VALID_TRAJECTORY:
            if nav.failing_since_s is None:
                nav.failing_since_s = now
            if now - nav.failing_since_s >= self.params.failure_tolerance - 1e-9:
                self._failure(inputs, out, STUCK, 'the controller found no valid trajectory '
                              '(obstacles all around)')
                return
        else:
            nav.failing_since_s = None
        if status != STATUS_STALE_POSE and not self.progress_checker.check(
                inputs.robot_in_odom[0], inputs.robot_in_odom[1], now):
            checker = self.progress_checker
            self._failure(inputs, out, STUCK, f'no progress: the robot stayed within '
                          f'{checker.required_movement_radius:g} m for '
                          f'{checker.movement_time_allowance:g} s')

    def _replan(self, inputs: TickInputs, out: TickOutput) -> str:
        """Plan from the robot to the goal; return '' or why it failed."""
        nav = self._nav
        if inputs.global_costmap is None:
            return 'no map'
        x, y, _ = nav.goal.pose
        try:
            points = self._plan_steered(inputs, (x, y))
        except PlanningError as error:
            return str(error)
        nav.set_plan(points, inputs.now_s)
        self._update_progress(inputs.robot_in_map)
        out.new_plan = [tuple(p) for p in nav.points.tolist()]
        return ''

    def _odom_path(self, map_to_odom: PlanarTransform) -> np.ndarray:
        """Return the pruned plan in odom as (M, 3) rows, the goal yaw in the last one."""
        nav = self._nav
        key = (nav.plan_version, nav.prune_index, map_to_odom)
        if key != nav.odom_path_key:
            points = transform_points(map_to_odom.inverse(), nav.points[nav.prune_index:])
            path = np.full((points.shape[0], 3), math.nan)
            path[:, :2] = points
            path[-1, 2] = wrap_angle(nav.goal.pose[2] - map_to_odom.yaw)
            nav.odom_path, nav.odom_path_key = path, key
        return nav.odom_path

    def _failure(self, inputs: TickInputs, out: TickOutput, code: int, reason: str) -> None:
        """Start the next recovery, or end the goal after max_recoveries."""
        nav = self._nav
        limit = self.params.max_recoveries
        if nav.recoveries >= limit:
            self._end(out, code, f'{reason}; gave up after {nav.recoveries} '
                                 f'recover{"y" if nav.recoveries == 1 else "ies"}')
            return
        kind = RECOVERY_SEQUENCE[nav.recoveries % len(RECOVERY_SEQUENCE)]
        nav.recoveries += 1
        nav.recovery = start_recovery(kind, inputs.now_s, reason, inputs.robot_in_odom,
                                      inputs.local_costmap)
        nav.state = RECOVERING
        out.events.append(f'recovery {nav.recoveries}/{limit}: {kind} ({reason})')
        twist = self._recover(inputs, out)
        out.twist = ZERO_TWIST if twist is None else twist

    def _recover(self, inputs: TickInputs, out: TickOutput) -> Optional[Twist2D]:
        """Run the active recovery one tick; return its twist, or None once it is over."""
        current = self._last_command if inputs.twist is None else tuple(inputs.twist)
        step = step_recovery(self._nav.recovery, inputs.now_s, inputs.robot_in_odom, current,
                             inputs.local_costmap, self.params, self.controller.params)
        if step.clear_local_costmap:
            out.clear_local_costmap = True
        if step.warning:
            out.warnings.append(step.warning)
        return step.twist

    def _resume(self, inputs: TickInputs, out: TickOutput) -> None:
        """After a recovery: replan, reset the checkers and follow again."""
        nav = self._nav
        out.events.append(f'recovery {nav.recovery.kind} done')
        nav.state = FOLLOWING
        nav.recovery = None
        nav.failing_since_s = None
        self.controller.reset()
        self.progress_checker.reset()
        nav.plan_time_s = -math.inf  # replan at once

    def _feedback(self, inputs: TickInputs, out: TickOutput) -> None:
        """Fill the feedback of the active goal."""
        nav = self._nav
        elapsed = max(0.0, inputs.now_s - nav.start_s)
        remaining = nav.distance_remaining_m
        out.feedback = Feedback(
            nav.goal.goal_id, tuple(float(v) for v in inputs.robot_in_map), remaining,
            elapsed, estimated_time_remaining(remaining, nav.travelled_m, elapsed),
            nav.recoveries)


# --- pure helpers --------------------------------------------------------------------

def map_to_odom_transform(robot_in_map: Sequence[float],
                          robot_in_odom: Sequence[float]) -> PlanarTransform:
    """Return map -> odom (the pose of odom in map) from the robot's pose in both."""
    return PlanarTransform(*robot_in_map).compose(PlanarTransform(*robot_in_odom).inverse())


def transform_points(transform: PlanarTransform, points: np.ndarray) -> np.ndarray:
    """Return (N, 2) points of transform's child frame expressed in its parent frame."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return points @ transform.rotation().T + (transform.x, transform.y)


def project_onto_path(points: np.ndarray, cumulative: np.ndarray, x: float, y: float,
                      first_segment: int = 0,
                      search_length_m: float = math.inf) -> Tuple[int, float]:
    """
    Return (segment, s): the path's point nearest (x, y) and its arc length s (m).

    Segments from first_segment are searched while they start within search_length_m
    of path length after first_segment's start (so a path passing a place twice is
    followed in order). A single-point path gives (0, 0.0).
    """
    count = points.shape[0] - 1
    if count < 1:
        return 0, 0.0
    first = min(max(first_segment, 0), count - 1)
    last = int(np.searchsorted(cumulative[:-1], cumulative[first] + search_length_m,
                               side='right'))
    last = min(max(last, first + 1), count)
    starts = points[first:last]
    vectors = points[first + 1:last + 1] - starts
    length2 = np.maximum(np.sum(vectors * vectors, axis=1), 1e-18)
    t = np.clip(np.sum(((x, y) - starts) * vectors, axis=1) / length2, 0.0, 1.0)
    nearest = starts + t[:, None] * vectors
    index = int(np.argmin(np.hypot(nearest[:, 0] - x, nearest[:, 1] - y)))
    segment = first + index
    return segment, float(cumulative[segment] + t[index] * np.sqrt(length2[index]))


def estimated_time_remaining(distance_remaining_m: float, travelled_m: float,
                             elapsed_s: float) -> float:
    """Return distance / mean speed so far (s), or 0 (unknown) as the module docstring says."""
    if elapsed_s <= 0.0:
        return 0.0
    mean_speed = travelled_m / elapsed_s
    if mean_speed <= 0.01 or distance_remaining_m <= 0.1:
        return 0.0
    return distance_remaining_m / mean_speed


def path_blocked(costmap: Optional[Costmap2D], points: np.ndarray) -> bool:
    """Tell whether any of the (N, 2) points is on a lethal cell or off the costmap."""
    if costmap is None or len(points) == 0:
        return False
    cols = np.floor((points[:, 0] - costmap.origin_x_m) / costmap.resolution_m)
    rows = np.floor((points[:, 1] - costmap.origin_y_m) / costmap.resolution_m)
    inside = (cols >= 0) & (cols < costmap.size_x) & (rows >= 0) & (rows < costmap.size_y)
    if not np.all(inside):
        return True
    return bool(np.any(costmap.costs[rows.astype(np.int64), cols.astype(np.int64)]
                       == LETHAL_OBSTACLE))


def nearest_free_cell(costmap: Costmap2D, xy: Point, radius_m: float) -> Optional[Point]:
    """Return the centre of the nearest cell costing < 253 within radius_m of xy, or None."""
    xs, ys = costmap.cell_centers()
    distance = np.hypot(xs - xy[0], ys - xy[1])
    usable = (costmap.costs < INSCRIBED_INFLATED_OBSTACLE) & (distance <= radius_m + 1e-9)
    if not np.any(usable):
        return None
    index = np.argmin(np.where(usable, distance, np.inf))
    row, col = np.unravel_index(index, distance.shape)
    return costmap.map_to_world(int(row), int(col))


def _check_number(name: str, value, minimum: float = -math.inf,
                  inclusive: bool = True) -> None:
    """Raise ValueError naming the value unless it is a finite number above the minimum."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f'{name} must be a number, got {value!r}')
    if not math.isfinite(value):
        raise ValueError(f'{name} must be finite, got {value!r}')
    if value < minimum or (not inclusive and value == minimum):
        relation = '>=' if inclusive else '>'
        raise ValueError(f'{name} must be {relation} {minimum:g}, got {value!r}')
