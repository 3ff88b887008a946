"""Tests of navigator.navigator: hand-worked cases and closed-loop runs without ROS."""

import math
from pathlib import Path
import re

from mecanum_control.angles import wrap_angle
from mecanum_control.kinematics import integrate_pose
from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_localization.transforms import PlanarTransform
from mecanum_map_server.map_io import find_map_file, load_map, OccupancyMap
from mecanum_navigation.controller.local_controller import (
    ControllerParams, LocalController, ProgressChecker, STATUS_NO_VALID_TRAJECTORY)
from mecanum_navigation.costmap.costmap_2d import (
    Costmap2D, InflationLayer, LayeredCostmap, LETHAL_OBSTACLE, RollingWindow, StaticLayer,
    ZoneLayer)
from mecanum_navigation.navigator import navigator as nav
from mecanum_navigation.navigator.navigator import (
    estimated_time_remaining, map_to_odom_transform, Navigator, NavigatorParams, Outcome,
    path_blocked, project_onto_path, TickInputs, transform_points, ZERO_TWIST)
from mecanum_navigation.navigator.recoveries import backup_clear, backup_direction, lethal_points
from mecanum_navigation.planner.planner import GridPlanner, PlanningError
from mecanum_safety.zone import make_zone
import numpy as np
import pytest
import yaml

ROBOT = load_robot_config(default_config_path())
PARAMS = ControllerParams.from_robot_config(ROBOT)
RES = 0.05
DT = PARAMS.control_period
CONFIG = yaml.safe_load((Path(__file__).resolve().parents[1] / 'config/costmap_common.yaml')
                        .read_text())['navigator']['ros__parameters']
PLANNER = GridPlanner()


def plan_points(costmap, start, goal):
    """Plan with the real planner; return its points."""
    return PLANNER.plan(costmap, start, goal).points


def occupancy(width_m, height_m, boxes=()):
    """Return a walled room (border cells occupied) with occupied boxes (x0, y0, x1, y1 m)."""
    cols, rows = int(round(width_m / RES)), int(round(height_m / RES))
    data = np.zeros((rows, cols), dtype=np.int8)
    data[[0, -1], :] = 100
    data[:, [0, -1]] = 100
    xs = (np.arange(cols) + 0.5) * RES
    ys = (np.arange(rows) + 0.5) * RES
    for x0, y0, x1, y1 in boxes:
        data[np.ix_((ys >= y0) & (ys <= y1), (xs >= x0) & (xs <= x1))] = 100
    return OccupancyMap(RES, (0.0, 0.0, 0.0), data)


def global_costmap(occupancy_map, inflation_radius=0.5, cost_scaling_factor=4.0):
    """Return the node's global costmap of a map: static layer, then inflation (r 0.2 m)."""
    costmap = Costmap2D.like_map(occupancy_map)
    LayeredCostmap(costmap, [StaticLayer(occupancy_map), InflationLayer(
        ROBOT.footprint_radius_m, inflation_radius, cost_scaling_factor)]).update()
    return costmap


# A 4 m x 3 m room: a wall one cell thick at x 2.00..2.05 from the floor up to y 1.8, and a
# closed box (outline x 3.0..3.8, y 1.5..2.3) whose inside is free but unreachable.
WALL = (2.0, 0.0, 2.04, 1.8)
BOX = [(3.0, 1.5, 3.04, 2.3), (3.76, 1.5, 3.8, 2.3), (3.0, 1.5, 3.8, 1.54),
       (3.0, 2.26, 3.8, 2.3)]
ROOM = global_costmap(occupancy(4.0, 3.0, [WALL] + BOX))
ZONE = make_zone([(0.0, 0.0), (3.9, 0.0), (3.9, 2.5), (0.0, 2.5)])


class BoxedInController(LocalController):
    """A controller that never finds a valid trajectory (the robot is boxed in)."""

    def compute_velocity(self, pose, current_twist, path, costmap, pose_age_s=0.0,
                         obstacle_points=None):
        """Brake and report no_valid_trajectory."""
        return ZERO_TWIST, STATUS_NO_VALID_TRAJECTORY


class RecordingController(LocalController):
    """The real controller, remembering the inputs of its last call."""

    def compute_velocity(self, pose, current_twist, path, costmap, pose_age_s=0.0,
                         obstacle_points=None):
        """Record the arguments, then compute as LocalController does."""
        self.seen = (tuple(pose), np.array(path, dtype=float))
        return super().compute_velocity(pose, current_twist, path, costmap, pose_age_s,
                                        obstacle_points=obstacle_points)


class World:
    """
    A robot that follows each command exactly, ticked with the navigator at 20 Hz.

    map -> odom is fixed (not the identity, so frames matter); the local costmap is a
    rolling window in odom, rebuilt every tick, holding what a lidar would see: the
    global costmap's lethal cells (the walls) and the lethal points `obstacles` (odom
    frame), inflated like the node's. clear_on_request forgets the obstacles when the
    navigator asks to clear the local costmap (phantom returns). With move False the
    robot ignores its commands (e.g. slipping wheels).
    """

    def __init__(self, costmap=ROOM, start_in_map=(0.5, 0.5, 0.0),
                 map_to_odom=(0.7, -0.4, 0.5), params=NavigatorParams(), controller=None,
                 checker=None, local_layers=None):
        self.global_costmap = costmap
        self.static_costmap = None   # the map's costmap, when the global one has more
        self.unzoned_costmap = None  # the map's costmap without the zone, when it has one
        self.map_to_odom = PlanarTransform(*map_to_odom)
        odom = self.map_to_odom.inverse().compose(PlanarTransform(*start_in_map))
        self.odom_pose = (odom.x, odom.y, odom.yaw)
        self.twist = ZERO_TWIST
        self.ticks = 0
        self.window = RollingWindow(3.0, 3.0, RES)
        self.inflation = InflationLayer(ROBOT.footprint_radius_m, 0.5, 4.0)
        self.obstacles = np.zeros((0, 2))
        # Layers (in odom) building the local costmap instead of the lethal cells above.
        self.local_layers = None if local_layers is None else LayeredCostmap(
            self.window.costmap, local_layers)
        self.clear_on_request = False
        self.move = True
        self.navigator = Navigator(params, controller or LocalController(PARAMS), plan_points,
                                   checker)

    @property
    def now(self):
        """Return the time of the next tick (s)."""
        return self.ticks * DT

    @property
    def map_pose(self):
        """Return the robot's pose in map."""
        pose = self.map_to_odom.compose(PlanarTransform(*self.odom_pose))
        return (pose.x, pose.y, pose.yaw)

    def local_costmap(self):
        """Return the local costmap around the robot with the walls and obstacles, inflated."""
        self.window.move_to(self.odom_pose[0], self.odom_pose[1])
        if self.local_layers is not None:
            return self.local_layers.update()
        costmap = self.window.costmap
        costmap.reset()
        walls = np.zeros((0, 2)) if self.global_costmap is None else transform_points(
            self.map_to_odom.inverse(), lethal_points(self.global_costmap))
        for x, y in np.concatenate((walls, self.obstacles)):
            cell = costmap.world_to_map(x, y)
            if cell is not None:
                costmap.costs[cell] = LETHAL_OBSTACLE
        self.inflation.update(costmap)
        return costmap

    def tick(self):
        """Run one navigator tick and move the robot by its command; return the output."""
        out = self.navigator.tick(TickInputs(
            self.now, self.map_pose, self.odom_pose, self.local_costmap(),
            self.global_costmap, self.twist, static_costmap=self.static_costmap,
            unzoned_costmap=self.unzoned_costmap))
        if out.clear_local_costmap and self.clear_on_request:
            self.obstacles = np.zeros((0, 2))
        if out.twist is not None:
            self.twist = out.twist
        if self.move:
            self.odom_pose = integrate_pose(*self.odom_pose, *self.twist, DT)
        self.ticks += 1
        return out

    def run(self, seconds, stop_when_idle=True):
        """Tick for up to seconds (until no goal is active); return the outputs."""
        outputs = []
        for _ in range(int(round(seconds / DT))):
            outputs.append(self.tick())
            if stop_when_idle and self.navigator.active_goal_id is None:
                break
        return outputs


def outcomes(outputs):
    """Return every Outcome of a list of tick outputs."""
    return [outcome for out in outputs for outcome in out.outcomes]


def ring(center, inner_m, outer_m):
    """Return points on a RES lattice through center, inner_m..outer_m from it."""
    offsets = np.arange(-20, 21) * RES
    xs, ys = np.meshgrid(center[0] + offsets, center[1] + offsets)
    distance = np.hypot(xs - center[0], ys - center[1])
    keep = (distance >= inner_m) & (distance <= outer_m)
    return np.column_stack((xs[keep], ys[keep]))


# --- parameters and constants ---------------------------------------------------------

@pytest.mark.parametrize('field, value', [
    ('replan_frequency', 0.0), ('failure_tolerance', -0.1), ('max_recoveries', -1),
    ('max_recoveries', 2.0), ('robot_radius_m', math.nan), ('spin_dist', 0.0),
    ('backup_speed', math.inf), ('wait_duration', -1.0),
    ('authorised_zone', ((0, 0), (1, 0), (1, 1))), ('authorised_zone', [0, 0, 1, 0, 1, 1])])
def test_params_reject_bad_values_naming_the_field(field, value):
    """Each bad value raises ValueError naming its field (the zone must be a Zone)."""
    with pytest.raises(ValueError, match=field):
        NavigatorParams(**{field: value})


def test_params_take_a_zone_or_none():
    """No zone by default; a Zone is kept as it is."""
    assert NavigatorParams().authorised_zone is None
    assert NavigatorParams(authorised_zone=ZONE).authorised_zone is ZONE


def test_result_codes_agree_with_nav2_and_are_unique():
    """NONE is nav2_msgs' NONE, Nav2's own codes keep their values, no two codes are equal."""
    action = pytest.importorskip('nav2_msgs.action')
    assert nav.NONE == action.NavigateToPose.Result.NONE == 0
    assert (nav.UNKNOWN, nav.FAILED_TO_LOAD_BEHAVIOR_TREE, nav.TF_ERROR, nav.TIMEOUT) == (
        9000, 9001, 9002, 9003)
    codes = [nav.NONE, nav.UNKNOWN, nav.FAILED_TO_LOAD_BEHAVIOR_TREE, nav.TF_ERROR,
             nav.TIMEOUT, nav.GOAL_OUTSIDE_ZONE, nav.GOAL_IN_OBSTACLE, nav.GOAL_OUTSIDE_MAP,
             nav.NO_VALID_PATH, nav.STUCK, nav.CANCELED, nav.PREEMPTED, nav.INVALID_GOAL]
    assert len(set(codes)) == len(codes)


# --- pure helpers, by hand ------------------------------------------------------------

def test_map_to_odom_and_plan_transform_by_hand():
    """With map -> odom (1, 2, pi/2) the robot at odom (1, 0, 0) is at map (1, 3, pi/2)."""
    transform = map_to_odom_transform((1.0, 3.0, math.pi / 2), (1.0, 0.0, 0.0))
    assert (transform.x, transform.y, transform.yaw) == pytest.approx((1.0, 2.0, math.pi / 2))
    # Map points -> odom: R(-pi/2) (p - (1, 2)): (1, 3) -> (1, 0), (2, 3) -> (1, -1).
    odom = transform_points(transform.inverse(), np.array([[1.0, 3.0], [2.0, 3.0]]))
    assert odom == pytest.approx(np.array([[1.0, 0.0], [1.0, -1.0]]))


def test_projection_on_the_path_by_hand():
    """Path (0,0)-(2,0)-(2,2): (1, 0.3) projects at s 1, (2.4, 1) at s 3, (3, 3) at the end."""
    points = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    cumulative = np.array([0.0, 2.0, 4.0])
    assert project_onto_path(points, cumulative, 1.0, 0.3) == (0, pytest.approx(1.0))
    assert project_onto_path(points, cumulative, 2.4, 1.0) == (1, pytest.approx(3.0))
    assert project_onto_path(points, cumulative, 3.0, 3.0) == (1, pytest.approx(4.0))
    # Searching from segment 1 only, (1, 0.3) projects on (2, 0.3): s = 2 + 0.3.
    assert project_onto_path(points, cumulative, 1.0, 0.3, first_segment=1) == (
        1, pytest.approx(2.3))
    # Within 1 m of path length from segment 0, segment 1 (starting at s 2) is not searched.
    assert project_onto_path(points, cumulative, 2.4, 1.0, 0, 1.0) == (0, pytest.approx(2.0))
    assert project_onto_path(points[:1], cumulative[:1], 5.0, 5.0) == (0, 0.0)


def test_estimated_time_remaining_by_hand():
    """1.5 m to go after 0.5 m in 2 s (0.25 m/s): 6 s; too slow or too near: 0 (unknown)."""
    assert estimated_time_remaining(1.5, 0.5, 2.0) == pytest.approx(6.0)
    assert estimated_time_remaining(1.5, 0.01, 2.0) == 0.0
    assert estimated_time_remaining(0.05, 1.0, 1.0) == 0.0
    assert estimated_time_remaining(1.0, 0.0, 0.0) == 0.0


def test_path_blocked_only_by_lethal_or_off_map_points():
    """ROOM: the wall cell (2.02, 1.0) is lethal; (1.85, 1.0) is only inscribed."""
    assert path_blocked(ROOM, np.array([[1.0, 1.0], [2.02, 1.0]]))
    assert not path_blocked(ROOM, np.array([[1.0, 1.0], [1.85, 1.0]]))
    assert path_blocked(ROOM, np.array([[1.0, 1.0], [4.5, 1.0]]))
    assert not path_blocked(None, np.array([[9.0, 9.0]]))


def test_backup_direction_points_away_from_the_nearest_obstacle():
    """
    One lethal cell with centre (0.325, 0.025), the robot at (0.025, 0.025): straight -x.

    Its clearance is 0.3 m; backing up 0.15 m along -x keeps it; toward +x it does not.
    With no obstacle the robot backs up along its own -x axis.
    """
    costmap = Costmap2D(60, 60, RES, -1.5, -1.5)
    costmap.costs[costmap.world_to_map(0.3, 0.0)] = LETHAL_OBSTACLE
    direction, clearance = backup_direction(costmap, (0.025, 0.025, math.pi / 2))
    assert direction == pytest.approx((-1.0, 0.0))
    assert clearance == pytest.approx(0.3)
    assert backup_clear(costmap, (0.025, 0.025), direction, 0.15, 0.2)
    assert not backup_clear(costmap, (0.025, 0.025), (1.0, 0.0), 0.15, 0.2)
    assert not backup_clear(costmap, (1.4, 0.025), (1.0, 0.0), 0.15, 0.0)  # off the window
    empty = Costmap2D(60, 60, RES, -1.5, -1.5)
    direction, clearance = backup_direction(empty, (0.0, 0.0, math.pi / 2))
    assert direction == pytest.approx((0.0, -1.0))
    assert clearance == math.inf


def test_config_keeps_a_half_metre_gap_open_and_closes_0_4_m():
    """
    costmap_common.yaml's inflation with the 0.2 m footprint radius, a wall with a gap.

    A 0.5 m gap (10 cells) in a one-cell wall: the gap cells 4 cells (0.2 m) or less
    from a wall end are inscribed (253), so the 5th and 6th stay free, each 0.25 m from
    one end and 0.30 m from the other: cost floor(252 exp(-4 (0.25 - 0.2))) = 206.
    A 0.4 m gap (8 cells) has every cell within 0.2 m of an end: closed.
    """
    options = CONFIG['global_costmap']
    inflation = (options['inflation_radius'], options['cost_scaling_factor'])
    assert ROBOT.footprint_radius_m == 0.2
    for gap_cells, passable in ((10, True), (8, False)):
        data = np.zeros((40, 60), dtype=np.int8)
        data[:, 30] = 100
        data[15:15 + gap_cells, 30] = 0
        costmap = global_costmap(OccupancyMap(RES, (0.0, 0.0, 0.0), data), *inflation)
        gap = costmap.costs[15:15 + gap_cells, 30]
        if passable:
            assert gap.tolist() == [253] * 4 + [206, 206] + [253] * 4
            path = plan_points(costmap, (0.5, 1.0), (2.5, 1.0))
            crossing = min(path, key=lambda p: abs(p[0] - 1.525))
            assert 0.95 <= crossing[1] <= 1.05   # through the two free cells (y 0.95..1.05)
        else:
            assert gap.tolist() == [253] * 8
            with pytest.raises(PlanningError):
                plan_points(costmap, (0.5, 1.0), (2.5, 1.0))


# --- goal validation ------------------------------------------------------------------

@pytest.mark.parametrize('goal, code, message', [
    ((math.nan, 1.0, 0.0), nav.INVALID_GOAL, 'goal pose is not finite'),
    ((1.0, 1.0, math.inf), nav.INVALID_GOAL, 'goal pose is not finite'),
    ((4.5, 1.0, 0.0), nav.GOAL_OUTSIDE_MAP,
     r'goal \(4.50, 1.00\) is outside the map \(x 0.00..4.00, y 0.00..3.00 m\)'),
    ((1.0, -0.1, 0.0), nav.GOAL_OUTSIDE_MAP, 'outside the map'),
    ((1.0, 2.7, 0.0), nav.GOAL_OUTSIDE_ZONE, r'goal \(1.00, 2.70\) is outside the authorised'),
    ((2.02, 1.0, 0.0), nav.GOAL_IN_OBSTACLE, 'in an obstacle or keepout zone'),
    # Cell centre 1.875: 0.15 m from the wall's cell centre 2.025: inscribed.
    ((1.85, 1.0, 0.0), nav.GOAL_IN_OBSTACLE, 'too close to an obstacle'),
    # Cell centre 1.825: exactly 0.2 m: still inscribed.
    ((1.80, 1.0, 0.0), nav.GOAL_IN_OBSTACLE, 'inscribed cell'),
    # Diagonally off the wall's top corner (square x 2.00.., y ..1.80): 0.13 m each way,
    # 0.18 m from it, while the cell centres are 0.21 m apart (cost 252, not inscribed).
    # The live apartment accepted (2.0, 5.0), 0.15 m from a wall, likewise.
    ((1.87, 1.93, 0.0), nav.GOAL_IN_OBSTACLE,
     r'goal \(1.87, 1.93\) is 0.18 m from an obstacle: the footprint \(radius 0.2 m\) '
     'cannot be there'),
    ((3.4, 1.9, 0.0), nav.NO_VALID_PATH, r'no valid path to goal \(3.40, 1.90\).*not reachable'),
])
def test_bad_goals_fail_before_moving(goal, code, message):
    """Each bad goal ends in its tick with its code and reason; the robot gets zero."""
    world = World(params=NavigatorParams(authorised_zone=ZONE))
    world.navigator.submit('g', goal)
    out = world.tick()
    assert [(o.goal_id, o.code) for o in out.outcomes] == [('g', code)]
    assert re.search(message, out.outcomes[0].message), out.outcomes[0].message
    assert out.twist == ZERO_TWIST
    assert out.new_plan is None
    assert world.navigator.state == nav.IDLE
    assert world.tick().twist is None   # idle: nothing commanded


@pytest.mark.parametrize('goal', [(1.75, 1.0), (1.85, 1.95)])
def test_a_goal_just_outside_the_inscribed_ring_is_accepted(goal):
    """0.25 m from the wall, or 0.21 m off its corner: the footprint fits; planned to."""
    world = World(params=NavigatorParams(authorised_zone=ZONE))
    world.navigator.submit('g', (*goal, 0.0))
    out = world.tick()
    assert out.outcomes == []
    assert out.new_plan is not None and out.new_plan[-1] == pytest.approx(goal)
    assert world.navigator.state == nav.FOLLOWING


def test_missing_inputs_and_invalid_reasons_fail_the_goal():
    """No map: UNKNOWN; no pose: TF_ERROR; a reason from the node: INVALID_GOAL."""
    world = World(costmap=None)
    world.navigator.submit('a', (1.0, 1.0, 0.0))
    assert [(o.code, o.message) for o in world.tick().outcomes] == [
        (nav.UNKNOWN, 'no map received yet: cannot check or plan to the goal')]
    world = World()
    world.navigator.submit('b', (1.0, 1.0, 0.0))
    out = world.navigator.tick(TickInputs(0.0, None, None, world.local_costmap(), ROOM,
                                          pose_error='map is not connected to base_link'))
    assert [(o.code, o.message) for o in out.outcomes] == [
        (nav.TF_ERROR, 'robot pose unknown: map is not connected to base_link')]
    world.navigator.submit('c', (1.0, 1.0, 0.0), invalid_reason="unknown frame 'nowhere'")
    assert [(o.code, o.message) for o in world.tick().outcomes] == [
        (nav.INVALID_GOAL, "unknown frame 'nowhere'")]


# --- the authorised zone ----------------------------------------------------------------

APARTMENT = load_map(find_map_file('apartment'))
# The apartment (robot_simulation/worlds/apartment.yaml) without the bedroom: an L-shaped
# (concave) inclusion whose top edge, y 5.15, is the hallway's north wall (inner face)
# except over the bathroom (x >= 6.55), less two exclusions. The first is the doorway
# joining the living room and the kitchen (x 5.5..6.5, y 2.5..3.95, round the opening
# y 2.8..3.8 in the wall x = 6.0): the short way between them; the way round is the
# hallway (living room door x 1.0..2.0, kitchen door x 8.0..9.0, both in the wall
# y = 4.0). The second covers the bathroom's door (x 6.9..8.0, y 5.1..5.4, round the
# opening x 7.0..7.9 in the wall y = 5.2), the bathroom's only way in.
APARTMENT_ZONE = make_zone(
    [(0.1, 0.1), (9.9, 0.1), (9.9, 7.9), (6.55, 7.9), (6.55, 5.15), (0.1, 5.15)],
    [[(5.5, 2.5), (6.5, 2.5), (6.5, 3.95), (5.5, 3.95)],
     [(6.9, 5.1), (8.0, 5.1), (8.0, 5.4), (6.9, 5.4)]])
LIVING_ROOM = (4.5, 2.5, 0.0)
KITCHEN = (8.5, 3.2, 0.0)
MAP_TO_ODOM = (0.7, -0.4, 0.5)


def zoned_costmap(occupancy_map, zone):
    """Return the node's global costmap with a zone: static, zone, inflation (r 0.2 m)."""
    costmap = Costmap2D.like_map(occupancy_map)
    LayeredCostmap(costmap, [StaticLayer(occupancy_map), ZoneLayer(zone), InflationLayer(
        ROBOT.footprint_radius_m, 0.5, 4.0)]).update()
    return costmap


APARTMENT_ZONED = zoned_costmap(APARTMENT, APARTMENT_ZONE)
APARTMENT_UNZONED = global_costmap(APARTMENT)


def apartment_world(zone=APARTMENT_ZONE, start=LIVING_ROOM, unzoned=True):
    """
    Return a World on the apartment's map, with the zone as the node has it.

    The global costmap has the zone's layer, unzoned_costmap is the map's without it
    (unzoned False: left out), and the local costmap (odom, 3 m window) is built as the
    node builds it: the map placed in odom, the zone placed with map -> odom, inflation.
    zone None: no zone at all.
    """
    map_to_odom = PlanarTransform(*MAP_TO_ODOM)
    origin = map_to_odom.inverse().compose(PlanarTransform(*APARTMENT.origin))
    in_odom = OccupancyMap(APARTMENT.resolution_m, (origin.x, origin.y, origin.yaw),
                           APARTMENT.data)
    layers = [StaticLayer(in_odom)]
    if zone is not None:
        layers.append(ZoneLayer(zone, frame_pose=MAP_TO_ODOM))
    layers.append(InflationLayer(ROBOT.footprint_radius_m, 0.5, 4.0))
    world = World(APARTMENT_ZONED if zone is not None else APARTMENT_UNZONED,
                  start_in_map=start, map_to_odom=MAP_TO_ODOM,
                  params=NavigatorParams(authorised_zone=zone), local_layers=layers)
    if zone is not None and unzoned:
        world.unzoned_costmap = APARTMENT_UNZONED
    return world


def path_length(points):
    """Return the length (m) of a polyline."""
    return sum(math.dist(a, b) for a, b in zip(points, points[1:]))


def test_the_plan_goes_round_the_excluded_doorway_and_stays_in_the_zone():
    """
    Living room (4.5, 2.5) -> kitchen (8.5, 3.2), with and without the zone.

    Without it the plan takes the doorway: the robot's centre crosses the wall x = 6.0
    at y 3.0..3.6 (0.2 m inside the opening), so the plan is at least |(4.5, 2.5) -
    (6.0, 3.0)| + |(6.0, 3.0) - (8.5, 3.2)| = 1.58 + 2.51 = 4.09 m; through the
    doorway's middle it is about that, well under 5 m, and it enters the exclusion.
    With the zone it must take the hallway: out of the living room's door with its
    centre at x <= 1.8, into the kitchen's at x >= 8.2, so at least |(4.5, 2.5) -
    (1.8, 4.0)| + (8.2 - 1.8) + |(8.2, 4.0) - (8.5, 3.2)| = 3.09 + 6.4 + 0.85 = 10.34 m.
    Every point of it keeps the footprint (0.2 m) inside the zone.
    """
    free = apartment_world(zone=None)
    free.navigator.submit('g', KITCHEN)
    short = np.array(free.tick().new_plan)
    assert path_length(short) < 5.0
    assert not np.all(APARTMENT_ZONE.contains(short[:, 0], short[:, 1]))

    world = apartment_world()
    world.navigator.submit('g', KITCHEN)
    out = world.tick()
    assert out.outcomes == []
    plan = np.array(out.new_plan)
    assert plan[0] == pytest.approx(LIVING_ROOM[:2]) and plan[-1] == pytest.approx(KITCHEN[:2])
    assert path_length(plan) > 10.3
    assert np.max(plan[:, 1]) > 4.05          # in the hallway
    assert np.all(APARTMENT_ZONE.clearance(plan[:, 0], plan[:, 1]) >= ROBOT.footprint_radius_m)


def test_the_robot_drives_round_through_the_hallway_inside_the_zone():
    """
    Closed loop to the kitchen: the goal is reached, the footprint never leaves the zone.

    The local costmap (odom) has the zone placed with map -> odom, like the node's, so
    the controller's trajectories respect it too; the footprint keeps 0.2 m from the
    border less half a cell's diagonal (0.036 m: the zone's cells and the two lattices).
    """
    world = apartment_world()
    world.navigator.submit('g', KITCHEN)
    outputs, clearances = [], []
    while world.navigator.active_goal_id is not None or not outputs:
        assert world.now < 60.0
        outputs.append(world.tick())
        x, y, _ = world.map_pose
        clearances.append(APARTMENT_ZONE.clearance([x], [y])[0])
    assert outcomes(outputs) == [Outcome('g', nav.NONE, 'goal reached')]
    assert min(clearances) >= ROBOT.footprint_radius_m - 0.036
    assert math.dist(world.map_pose[:2], KITCHEN[:2]) <= PARAMS.xy_goal_tolerance + 0.01


@pytest.mark.parametrize('goal, message', [
    # The doorway, in the exclusion; the bedroom, outside the L.
    ((6.0, 3.3, 0.0), r'goal \(6.00, 3.30\) is outside the authorised zone$'),
    ((3.5, 6.3, 0.0), r'goal \(3.50, 6.30\) is outside the authorised zone$'),
    # 0.15 m west of the exclusion's edge x = 5.5: the footprint would cross it.
    ((5.35, 3.0, 0.0),
     r"goal \(5.35, 3.00\) is within 0.2 m of the authorised zone's border \(0.15 m\)"),
    # The bathroom, in the zone, is entered only through its door, in an exclusion.
    ((8.0, 6.5, 0.0), re.escape('no route to (8.00, 6.50) inside the authorised zone (the '
                                'only route leaves it)')),
])
def test_goals_outside_the_zone_or_reached_only_through_its_outside_are_refused(goal, message):
    """Each ends at once with GOAL_OUTSIDE_ZONE and its reason; the robot gets zero."""
    world = apartment_world()
    world.navigator.submit('g', goal)
    out = world.tick()
    assert [(o.goal_id, o.code) for o in out.outcomes] == [('g', nav.GOAL_OUTSIDE_ZONE)]
    assert re.search(message, out.outcomes[0].message), out.outcomes[0].message
    assert out.twist == ZERO_TWIST and out.new_plan is None
    assert world.navigator.state == nav.IDLE


def test_a_goal_a_footprint_from_the_border_is_accepted():
    """(5.25, 3.0) is 0.25 m from the exclusion (x 5.5): planned to, ending there."""
    world = apartment_world()
    world.navigator.submit('g', (5.25, 3.0, 0.0))
    out = world.tick()
    assert out.outcomes == []
    assert out.new_plan[-1] == pytest.approx((5.25, 3.0))


def test_without_the_unzoned_costmap_or_with_the_robot_outside_it_is_no_valid_path():
    """
    The 'only route leaves it' check needs the costmap without the zone, and the robot in.

    Without that costmap the bathroom goal is simply unreachable. With the robot in the
    excluded doorway ((6.0, 3.3): 0.5 m from the exclusion's sides, so no free cell
    within 0.5 m to start from) the plan fails because of the robot, which the message
    says.
    """
    world = apartment_world(unzoned=False)
    world.navigator.submit('g', (8.0, 6.5, 0.0))
    (outcome,) = world.tick().outcomes
    assert outcome.code == nav.NO_VALID_PATH
    assert outcome.message.startswith('no valid path to goal (8.00, 6.50): no path')
    world = apartment_world(start=(6.0, 3.3, 0.0))
    world.navigator.submit('g', KITCHEN)
    (outcome,) = world.tick().outcomes
    assert (outcome.code, outcome.message) == (
        nav.NO_VALID_PATH,
        'no valid path to goal (8.50, 3.20): the robot (6.00, 3.30) is outside the authorised '
        'zone')


def test_zone_goal_checks_on_the_costmaps_cells_and_an_unreachable_goal():
    """
    The small room with zones; the node's costmaps (zone layer, then inflation).

    Zone x <= 3.52: the cells from x 3.50 (centre 3.525) are outside, lethal. The goal
    (3.31, 0.8) is 0.21 m from the border, but its cell's centre 3.325 is 0.2 m from the
    lethal centre 3.525: inscribed, on the costmap's cells because of the zone (without
    it the nearest obstacle is the floor wall 0.8 m away), so GOAL_OUTSIDE_ZONE. The goal
    (3.26, 0.8), cell centre 3.275, 0.25 m away, is accepted. With the zone x <= 3.9,
    the inside of the closed box (3.4, 1.9) has no plan with or without the zone:
    NO_VALID_PATH.
    """
    room = occupancy(4.0, 3.0, [WALL] + BOX)
    narrow = make_zone([(0.0, 0.0), (3.52, 0.0), (3.52, 3.0), (0.0, 3.0)])
    cases = [(narrow, (3.31, 0.8, 0.0), nav.GOAL_OUTSIDE_ZONE,
              r"goal \(3.31, 0.80\) is within 0.2 m of the authorised zone's border on the "
              r"costmap's cells"),
             (narrow, (3.26, 0.8, 0.0), nav.NONE, ''),
             (ZONE, (3.4, 1.9, 0.0), nav.NO_VALID_PATH,
              r'no valid path to goal \(3.40, 1.90\).*not reachable')]
    for zone, goal, code, message in cases:
        world = World(zoned_costmap(room, zone), params=NavigatorParams(authorised_zone=zone))
        world.unzoned_costmap = ROOM
        world.navigator.submit('g', goal)
        out = world.tick()
        if code == nav.NONE:
            assert out.outcomes == [] and out.new_plan[-1] == pytest.approx(goal[:2])
            continue
        assert [o.code for o in out.outcomes] == [code], out.outcomes
        assert re.search(message, out.outcomes[0].message), out.outcomes[0].message


# --- navigating -------------------------------------------------------------------------

def test_reaches_a_goal_behind_the_wall_with_feedback_and_1_hz_replanning():
    """
    The robot goes from (0.5, 0.5) around the wall's end to (3.0, 0.5, pi/2).

    map -> odom is not the identity (the local costmap's lattice is turned 0.5 rad from
    the map's). The robot keeps the footprint radius (0.2 m) from every wall cell's
    centre, less half a cell's diagonal (0.035 m) for the two lattices; it ends within
    the goal checker's tolerances, the distance remaining falls from the first plan's
    length to about 0, and a plan is made at t = 0 and at every whole second after.
    """
    world = World()
    world.navigator.submit('goal', (3.0, 0.5, math.pi / 2))
    walls = lethal_points(ROOM)
    outputs, clearances = [], []
    while world.navigator.active_goal_id is not None or not outputs:
        assert world.now < 40.0
        outputs.append(world.tick())
        x, y, _ = world.map_pose
        clearances.append(np.hypot(walls[:, 0] - x, walls[:, 1] - y).min())
    assert min(clearances) >= 0.2 - 0.036
    assert outcomes(outputs) == [Outcome('goal', nav.NONE, 'goal reached')]
    assert outputs[-1].twist == ZERO_TWIST
    x, y, yaw = world.map_pose
    assert math.hypot(x - 3.0, y - 0.5) <= PARAMS.xy_goal_tolerance + 0.01
    assert abs(wrap_angle(yaw - math.pi / 2)) <= PARAMS.yaw_goal_tolerance + 0.01
    feedback = [out.feedback for out in outputs if out.feedback is not None]
    remaining = [f.distance_remaining_m for f in feedback]
    first_plan = outputs[0].new_plan
    first_length = sum(math.dist(a, b) for a, b in zip(first_plan, first_plan[1:]))
    assert remaining[0] == pytest.approx(first_length, abs=0.05)
    assert first_length > 4.0   # up past the wall's end at y 1.8 + 0.2 and down again
    assert remaining[-1] < 0.1
    assert max(b - a for a, b in zip(remaining, remaining[1:])) < 0.1
    assert all(f.number_of_recoveries == 0 for f in feedback)
    assert feedback[-1].navigation_time_s == pytest.approx((len(outputs) - 2) * DT)
    assert any(f.estimated_time_remaining_s > 0.0 for f in feedback)
    end_time = (len(outputs) - 1) * DT
    plans = sum(out.new_plan is not None for out in outputs)
    assert plans == 1 + math.floor(end_time + 1e-9)


def test_replans_every_second_while_the_robot_stays():
    """Ticks at t = 0 .. 3.0 s: plans at t = 0, 1, 2 and 3 (replan_frequency 1 Hz)."""
    world = World()
    world.move = False
    world.navigator.submit('goal', (1.5, 1.0, 0.0))
    outputs = [world.tick() for _ in range(61)]
    times = [round(i * DT, 6) for i, out in enumerate(outputs) if out.new_plan is not None]
    assert times == [0.0, 1.0, 2.0, 3.0]


def test_the_controller_gets_the_pruned_plan_in_odom_with_the_goal_yaw():
    """
    With map -> odom (1, 2, pi/2), the robot at map (1, 3, pi/2) is at odom (1, 0, 0).

    Goal map (2, 3, pi) is odom (1, -1) with yaw pi - pi/2 = pi/2: the controller's path
    starts at the robot's odom position and ends there.
    """
    costmap = global_costmap(occupancy(6.0, 6.0))
    controller = RecordingController(PARAMS)
    world = World(costmap, start_in_map=(1.0, 3.0, math.pi / 2),
                  map_to_odom=(1.0, 2.0, math.pi / 2), controller=controller)
    world.navigator.submit('goal', (2.0, 3.0, math.pi))
    world.tick()
    pose, path = controller.seen
    # map -> odom is rounded to 1e-6 m and rad for the controller: micrometres here.
    assert pose == pytest.approx((1.0, 0.0, 0.0), abs=1e-9)
    assert path[0, :2] == pytest.approx((1.0, 0.0), abs=1e-5)
    assert path[-1] == pytest.approx((1.0, -1.0, math.pi / 2), abs=1e-5)
    assert np.all(np.isnan(path[:-1, 2]))


def test_replans_at_once_when_the_path_crosses_a_new_obstacle():
    """A wall appears across the straight path at t = 0.1 s: a new plan in that tick."""
    open_room = global_costmap(occupancy(4.0, 3.0))
    world = World(open_room, start_in_map=(0.5, 1.0, 0.0))
    world.navigator.submit('goal', (3.5, 1.0, 0.0))
    first = world.tick().new_plan
    assert max(y for _, y in first) < 1.1   # straight along y 1
    world.tick()
    world.global_costmap = global_costmap(occupancy(4.0, 3.0, [(2.0, 0.0, 2.04, 2.0)]))
    out = world.tick()
    assert out.new_plan is not None
    assert not path_blocked(world.global_costmap, np.array(out.new_plan))
    assert max(y for _, y in out.new_plan) >= 2.2   # over the wall's end (2.0 + 0.2)
    assert out.outcomes == []


def test_what_the_scan_adds_steers_the_plan_but_never_fails_the_goal():
    """
    A person the scan put into the global costmap (not in the map) near the way round ROOM's wall.

    Beside the way (y 2.6..3.0) the plan goes round them; standing in the way (y 1.9..3.0,
    nothing left open) the goal is still accepted, on the map's plan, and a replan that
    finds no way does not end it: the local controller and the recoveries deal with
    people, as the scan's obstacles only steer.
    """
    beside = global_costmap(occupancy(4.0, 3.0, [WALL] + BOX + [(1.9, 2.6, 2.2, 3.0)]))
    world = World(beside, start_in_map=(0.5, 0.5, 0.0))
    world.static_costmap = ROOM
    world.navigator.submit('goal', (2.6, 0.5, 0.0))
    plan = np.array(world.tick().new_plan)
    near_wall = plan[(plan[:, 0] > 1.8) & (plan[:, 0] < 2.3)]
    assert len(near_wall) and near_wall[:, 1].max() < 2.6 - 0.2   # kept off the person
    blocking = global_costmap(occupancy(4.0, 3.0, [WALL] + BOX + [(1.9, 1.8, 2.2, 3.0)]))
    world = World(blocking, start_in_map=(0.5, 0.5, 0.0))
    world.static_costmap = ROOM
    world.move = False
    world.navigator.submit('goal', (2.6, 0.5, 0.0))
    outputs = [world.tick() for _ in range(30)]
    first = np.array(outputs[0].new_plan)
    assert first[:, 1].max() > 1.8 + 0.2   # the map's way round the wall's end
    assert not outcomes(outputs)
    assert world.navigator.state == nav.FOLLOWING
    # Without the map's costmap the same person ends the goal at once.
    world = World(blocking, start_in_map=(0.5, 0.5, 0.0))
    world.navigator.submit('goal', (2.6, 0.5, 0.0))
    assert [o.code for o in outcomes([world.tick()])] == [nav.NO_VALID_PATH]


def test_a_failed_periodic_replan_keeps_a_clear_path():
    """
    A new map narrows the way to a 0.3 m gap: a failed replan keeps the current path.

    The gap is closed to the planner, but the current straight path goes through its
    middle without touching a lethal cell, so it is kept (with a warning).
    """
    world = World(global_costmap(occupancy(4.0, 3.0)), start_in_map=(0.5, 1.5, 0.0))
    world.move = False
    world.navigator.submit('goal', (3.5, 1.5, 0.0))
    world.tick()
    world.global_costmap = global_costmap(occupancy(4.0, 3.0, [
        (2.0, 0.0, 2.04, 1.34), (2.0, 1.66, 2.04, 3.0)]))
    outputs = [world.tick() for _ in range(20)]
    assert outputs[-1].warnings == [
        'replanning failed, keeping the current path: no path from (0.500, 1.500) to '
        '(3.500, 1.500) m: the goal is not reachable']
    assert all(out.new_plan is None and not out.outcomes for out in outputs)
    assert world.navigator.state == nav.FOLLOWING


def test_cancel_stops_at_once():
    """A cancel ends the goal CANCELED with zero velocity in the next tick, then idle."""
    world = World()
    world.navigator.submit('goal', (1.5, 1.0, 0.0))
    world.run(1.0, stop_when_idle=False)
    assert world.twist != ZERO_TWIST
    assert world.navigator.cancel('goal')
    out = world.tick()
    assert out.outcomes == [Outcome('goal', nav.CANCELED, 'canceled')]
    assert out.twist == ZERO_TWIST and out.feedback is None
    assert world.tick().twist is None
    assert not world.navigator.cancel('goal')


def test_cancel_of_a_queued_goal():
    """Cancelled before its first tick: it ends without starting."""
    world = World()
    world.navigator.submit('goal', (1.5, 1.0, 0.0))
    world.navigator.cancel('goal')
    out = world.tick()
    assert out.outcomes == [Outcome('goal', nav.CANCELED, 'canceled before it started')]
    assert world.navigator.state == nav.IDLE


def test_a_new_goal_preempts_the_running_one_and_is_reached():
    """A runs 1 s, B replaces it (A PREEMPTED in that tick), B is reached."""
    world = World()
    world.navigator.submit('A', (1.5, 2.0, 0.0))
    world.run(1.0)
    world.navigator.submit('B', (1.0, 1.0, math.pi))
    out = world.tick()
    assert out.outcomes == [Outcome('A', nav.PREEMPTED, 'preempted by a newer goal')]
    assert world.navigator.active_goal_id == 'B'
    assert out.feedback.goal_id == 'B'
    outputs = world.run(30.0)
    assert outcomes(outputs) == [Outcome('B', nav.NONE, 'goal reached')]
    assert math.dist(world.map_pose[:2], (1.0, 1.0)) <= PARAMS.xy_goal_tolerance + 0.01


def test_preemption_by_a_bad_goal_and_by_several_goals():
    """An invalid newcomer still preempts (then fails); of several only the last runs."""
    world = World()
    world.navigator.submit('A', (1.5, 2.0, 0.0))
    world.run(0.5)
    world.navigator.submit('B', (math.nan, 0.0, 0.0))
    out = world.tick()
    assert [(o.goal_id, o.code) for o in out.outcomes] == [
        ('A', nav.PREEMPTED), ('B', nav.INVALID_GOAL)]
    assert out.twist == ZERO_TWIST
    world.navigator.submit('C', (1.5, 2.0, 0.0))
    world.tick()
    world.navigator.submit('D', (1.0, 1.0, 0.0))
    world.navigator.submit('E', (1.2, 1.0, 0.0))
    out = world.tick()
    assert [(o.goal_id, o.code) for o in out.outcomes] == [
        ('D', nav.PREEMPTED), ('C', nav.PREEMPTED)]
    assert world.navigator.active_goal_id == 'E'


# --- recoveries -----------------------------------------------------------------------

def recovery_events(outputs):
    """Return (time, event) of the recovery starts."""
    return [(round(i * DT, 6), event) for i, out in enumerate(outputs) for event in out.events
            if event.startswith('recovery') and not event.endswith('done')]


def test_boxed_in_robot_runs_six_recoveries_then_gives_up_stuck():
    """
    A controller that never finds a trajectory: six recoveries, then STUCK.

    Each failure (after failure_tolerance 0.3 s) starts the next recovery: clear, spin,
    back up, wait, clear, spin; the 7th failure ends the goal.

    The spin turns 1.57 rad in place; the back up goes 0.15 m straight away from the wall
    (cells x 0.30..0.35 in odom): the robot at odom (0.025, 0.025) ends at x -0.125.
    """
    world = World(global_costmap(occupancy(6.0, 6.0)), start_in_map=(3.025, 3.025, 0.0),
                  map_to_odom=(3.0, 3.0, 0.0), controller=BoxedInController(PARAMS))
    world.obstacles = np.array([[0.325, y] for y in np.arange(-1.0, 1.0, RES) + 0.025])
    world.navigator.submit('goal', (4.5, 3.0, 0.0))
    yaws, poses = [], []
    outputs = []
    for _ in range(int(30.0 / DT)):
        outputs.append(world.tick())
        yaws.append(world.odom_pose[2])
        poses.append(world.odom_pose)
        if world.navigator.active_goal_id is None:
            break
    kinds = [event.split(': ')[1].split(' ')[0] for _, event in recovery_events(outputs)]
    assert kinds == ['clear_local_costmap', 'spin', 'back_up', 'wait', 'clear_local_costmap',
                     'spin']
    counts = [int(event.split(' ')[1].split('/')[0]) for _, event in recovery_events(outputs)]
    assert counts == [1, 2, 3, 4, 5, 6]
    assert outcomes(outputs) == [Outcome(
        'goal', nav.STUCK, 'the controller found no valid trajectory (obstacles all around); '
        'gave up after 6 recoveries')]
    assert outputs[-1].twist == ZERO_TWIST
    assert max(out.feedback.number_of_recoveries for out in outputs if out.feedback) == 6
    # The first failure: no valid trajectory at t = 0 .. 0.3 s -> recovery 1 at t = 0.3.
    assert recovery_events(outputs)[0][0] == pytest.approx(0.3)
    assert any(out.clear_local_costmap for out in outputs)
    start = [i for i, out in enumerate(outputs) if any('spin (' in e for e in out.events)][0]
    end = [i for i, out in enumerate(outputs) if 'recovery spin done' in out.events][0]
    turned = sum(wrap_angle(b - a) for a, b in zip(yaws[start - 1:end], yaws[start:end + 1]))
    assert turned == pytest.approx(1.57, abs=0.04)
    back = [i for i, out in enumerate(outputs) if any('back_up (' in e for e in out.events)][0]
    done = [i for i, out in enumerate(outputs) if 'recovery back_up done' in out.events][0]
    moved = np.subtract(poses[done][:2], poses[back - 1][:2])
    assert moved == pytest.approx((-0.15, 0.0), abs=0.01)


def test_clearing_a_phantom_obstacle_frees_the_robot():
    """A ring of phantom returns boxes the robot in; clearing the local costmap frees it."""
    world = World(global_costmap(occupancy(6.0, 6.0)), start_in_map=(3.025, 3.025, 0.0),
                  map_to_odom=(3.0, 3.0, 0.0))
    world.obstacles = ring((0.025, 0.025), 0.25, 0.30)
    world.clear_on_request = True
    world.navigator.submit('goal', (4.0, 3.0, 0.0))
    outputs = world.run(30.0)
    assert [event for _, event in recovery_events(outputs)] == [
        'recovery 1/6: clear_local_costmap (the controller found no valid trajectory '
        '(obstacles all around))']
    assert outcomes(outputs) == [Outcome('goal', nav.NONE, 'goal reached')]
    assert [out.feedback for out in outputs if out.feedback][-1].number_of_recoveries == 1


def test_no_progress_starts_a_recovery():
    """A robot that does not move: ProgressChecker(0.5 m, 1 s) fails at t = 1.05 s."""
    world = World(checker=ProgressChecker(0.5, 1.0))
    world.move = False
    world.navigator.submit('goal', (1.5, 2.0, 0.0))
    outputs = world.run(1.5)
    assert recovery_events(outputs) == [(1.05, 'recovery 1/6: clear_local_costmap (no progress: '
                                               'the robot stayed within 0.5 m for 1 s)')]


def test_a_blocked_path_without_a_new_one_ends_with_no_valid_path():
    """
    A goal walled in while the robot drives ends with NO_VALID_PATH after 6 recoveries.

    The path is blocked and no new plan exists, so every recovery ends in the same
    failure.
    """
    world = World(global_costmap(occupancy(4.0, 3.0)), start_in_map=(0.5, 1.0, 0.0),
                  params=NavigatorParams(wait_duration=0.5, spin_dist=0.5))
    world.navigator.submit('goal', (3.0, 1.0, 0.0))
    world.run(0.5)
    world.global_costmap = global_costmap(occupancy(4.0, 3.0, [(2.5, 0.0, 2.54, 3.0)]))
    outputs = world.run(30.0)
    assert len(recovery_events(outputs)) == 6
    (outcome,) = outcomes(outputs)
    assert outcome.code == nav.NO_VALID_PATH
    assert outcome.message.startswith('the path is blocked and no new path was found (no path')
    assert outcome.message.endswith('gave up after 6 recoveries')
    assert outputs[-1].twist == ZERO_TWIST
