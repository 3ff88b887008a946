"""Tests of controller.local_controller: hand-worked cases and closed-loop runs."""

from dataclasses import dataclass
import math

from hypothesis import given, settings, strategies as st
from mecanum_control.angles import wrap_angle
from mecanum_control.kinematics import integrate_pose
from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_navigation.controller.local_controller import (
    ControllerParams, LocalController, ProgressChecker, ramp_step, simulate_trajectories,
    STATUS_FOLLOWING, STATUS_GOAL_REACHED, STATUS_NO_VALID_TRAJECTORY, STATUS_ROTATING,
    STATUS_STALE_POSE, trajectory_costs)
import numpy as np
import pytest

ROBOT = load_robot_config(default_config_path())
PARAMS = ControllerParams.from_robot_config(ROBOT)
RES = 0.05


@dataclass
class Grid:
    """The attributes of a Costmap2D that the controller reads (row 0 = lowest y)."""

    costs: np.ndarray
    resolution_m: float = RES
    origin_x_m: float = 0.0
    origin_y_m: float = 0.0

    @property
    def size_x(self):
        """Return the number of columns."""
        return self.costs.shape[1]

    @property
    def size_y(self):
        """Return the number of rows."""
        return self.costs.shape[0]

    def cost_at(self, x, y):
        """Return the cost of the cell holding (x, y) (255 off the grid)."""
        col = math.floor((x - self.origin_x_m) / self.resolution_m)
        row = math.floor((y - self.origin_y_m) / self.resolution_m)
        if 0 <= row < self.size_y and 0 <= col < self.size_x:
            return int(self.costs[row, col])
        return 255


def empty_grid(size_m=6.0, origin=(-3.0, -3.0)):
    """Return a free grid of size_m x size_m centred by default on (0, 0)."""
    cells = int(round(size_m / RES))
    return Grid(np.zeros((cells, cells), dtype=np.uint8), RES, *origin)


def inflate(lethal, inscribed=0.2, inflation=0.55, scaling=3.0):
    """
    Return Nav2 costs around a boolean lethal mask (written out independently of costmap.py).

    Distance d between cell centres to the nearest lethal cell: 0 -> 254, <= inscribed ->
    253, <= inflation -> floor(252 exp(-scaling (d - inscribed))), else 0.
    """
    rows, cols = lethal.shape
    costs = np.zeros(lethal.shape, dtype=np.uint8)
    reach = int(math.ceil(inflation / RES))
    padded = np.zeros((rows + 2 * reach, cols + 2 * reach), dtype=bool)
    padded[reach:reach + rows, reach:reach + cols] = lethal
    for dr in range(-reach, reach + 1):
        for dc in range(-reach, reach + 1):
            d = math.hypot(dr, dc) * RES
            if d > inflation + 1e-9:
                continue
            if d == 0.0:
                cost = 254
            elif d <= inscribed + 1e-9:
                cost = 253
            else:
                cost = int(math.floor(252 * math.exp(-scaling * (d - inscribed))))
            shifted = padded[reach + dr:reach + dr + rows, reach + dc:reach + dc + cols]
            np.maximum(costs, np.where(shifted, cost, 0).astype(np.uint8), out=costs)
    return costs


def box(grid_lethal, x0, y0, x1, y1, origin=(0.0, 0.0)):
    """Mark the cells whose centres are inside [x0, x1] x [y0, y1] (m) lethal."""
    rows, cols = grid_lethal.shape
    xs = origin[0] + (np.arange(cols) + 0.5) * RES
    ys = origin[1] + (np.arange(rows) + 0.5) * RES
    grid_lethal[np.ix_((ys >= y0) & (ys <= y1), (xs >= x0) & (xs <= x1))] = True


def drive(controller, grid, path, pose, twist=(0.0, 0.0, 0.0), cycles=200, substeps=5,
          check=None, points=None):
    """
    Run the controller in closed loop with perfect tracking; return (pose, log).

    Each command is held for one control period, integrated exactly in substeps; check
    (if given) is called with every intermediate pose. log holds (pose, twist, status).
    points: obstacle points given to the controller every cycle.
    """
    dt = controller.params.control_period
    log = []
    for _ in range(cycles):
        new_twist, status = controller.compute_velocity(pose, twist, path, grid,
                                                        obstacle_points=points)
        log.append((pose, new_twist, status))
        twist = new_twist
        if status in (STATUS_GOAL_REACHED, STATUS_NO_VALID_TRAJECTORY):
            break
        for _ in range(substeps):
            pose = integrate_pose(*pose, *twist, dt / substeps)
            if check is not None:
                check(pose)
    return pose, log


# --- parameters --------------------------------------------------------------------

@pytest.mark.parametrize('field, value', [
    ('max_vel_x', -0.1), ('max_vel_y', math.nan), ('acc_lim_theta', 0.0),
    ('sim_time', math.inf), ('vx_samples', 0), ('vtheta_samples', 2.5),
    ('xy_goal_tolerance', -0.01), ('heading_mode', 'sideways'), ('stateful', 1),
    ('obstacle_weight', -1.0), ('min_vel_x', 0.1), ('approach_time', 2.0)])
def test_params_reject_bad_values_naming_the_field(field, value):
    """Each bad value raises ValueError naming its field."""
    with pytest.raises(ValueError, match=field):
        ControllerParams(**{field: value})


def test_params_wheel_limit_needs_both_values():
    """max_wheel_speed_m_s without rotation_arm_m is an error."""
    with pytest.raises(ValueError, match='rotation_arm_m'):
        ControllerParams(max_wheel_speed_m_s=1.0)


def test_params_from_robot_config_take_its_limits():
    """motor_params.yaml: 0.8 / 0.6 m/s, 2.5 rad/s, wheels 28 rad/s x 0.04 m = 1.12 m/s."""
    assert (PARAMS.max_vel_x, PARAMS.max_vel_y, PARAMS.max_vel_theta) == (0.8, 0.6, 2.5)
    assert (PARAMS.min_vel_x, PARAMS.min_vel_y) == (-0.8, -0.6)
    assert (PARAMS.acc_lim_x, PARAMS.acc_lim_y, PARAMS.acc_lim_theta) == (1.5, 1.5, 5.0)
    assert PARAMS.max_wheel_speed_m_s == pytest.approx(1.12)
    assert PARAMS.rotation_arm_m == pytest.approx(0.215)
    with pytest.raises(ValueError, match='unknown controller parameters'):
        ControllerParams.from_robot_config(ROBOT, max_vel_z=1.0)


# --- pure helpers ------------------------------------------------------------------

def test_ramp_step_scales_the_whole_change_by_the_most_limited_axis():
    """From rest toward (1.0, 0.5, 0) at 1.5 m/s^2 for 0.1 s: x allows 0.15 of 1.0 -> 15 %."""
    step = ramp_step((0.0, 0.0, 0.0), (1.0, 0.5, 0.0), (1.5, 1.5, 5.0), 0.1)
    assert step == pytest.approx([0.15, 0.075, 0.0])
    assert ramp_step((0.2, 0.0, 0.0), (0.25, 0.0, 0.1), (1.5, 1.5, 5.0), 0.1) == \
        pytest.approx([0.25, 0.0, 0.1])


@pytest.mark.parametrize('twist', [(0.5, 0.0, 0.0), (0.0, -0.4, 0.0), (0.3, 0.2, 1.5),
                                   (-0.2, 0.1, -2.5), (0.0, 0.0, 2.0)])
def test_constant_twist_trajectory_is_the_exact_arc(twist):
    """With current == target every point is integrate_pose over its time (1.2 s, 48 steps)."""
    pose = (1.0, -2.0, 0.7)
    xs, ys, yaws = simulate_trajectories(pose, twist, np.array([twist]), (1.5, 1.5, 5.0),
                                         1.2, 48)
    for k in (0, 23, 47):
        expected = integrate_pose(*pose, *twist, 1.2 * (k + 1) / 48)
        assert xs[0, k] == pytest.approx(expected[0], abs=1e-5)
        assert ys[0, k] == pytest.approx(expected[1], abs=1e-5)
        assert wrap_angle(float(yaws[0, k]) - expected[2]) == pytest.approx(0.0, abs=1e-5)


def test_ramp_then_hold_distance_by_hand():
    """
    0 -> 1 m/s at 2 m/s^2 along x, 1 s: continuous ramp 0.25 m in 0.5 s + 0.5 m held = 0.75 m.

    As a staircase of 0.1 s commands (0.2, 0.4, ... 1.0 m/s): 0.1 (0.2 + ... + 1.0) =
    0.3 m in the first 0.5 s, then 0.5 m: 0.8 m.
    """
    args = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), np.array([[1.0, 0.0, 0.0]]), (2.0, 2.0, 2.0),
            1.0, 20)
    xs, ys, _ = simulate_trajectories(*args)
    assert xs[0, -1] == pytest.approx(0.75, abs=1e-6)
    assert xs[0, 9] == pytest.approx(0.25, abs=1e-6)
    xs, ys, _ = simulate_trajectories(*args, period=0.1)
    assert xs[0, -1] == pytest.approx(0.8, abs=1e-6)
    assert xs[0, 1] == pytest.approx(0.02, abs=1e-7)   # first 0.1 s at 0.2 m/s
    assert np.all(ys == 0.0)


def test_trajectory_costs_reads_cells_and_marks_off_map_unknown():
    """Cell (row 1, col 2) of a 0.05 m grid at the origin holds (0.12, 0.07); off map -> 255."""
    grid = Grid(np.zeros((4, 4), dtype=np.uint8))
    grid.costs[1, 2] = 77
    costs = trajectory_costs(grid, np.array([[0.12, -0.01, 0.21]]), np.array([[0.07, 0.1, 0.1]]))
    assert costs.tolist() == [[77, 255, 255]]


def test_swept_costs_see_the_corner_cell_a_step_cuts():
    """
    A step from (0.04, 0.09) (cell row 1, col 0) to (0.065, 0.105) (row 2, col 1).

    The chord crosses x = 0.05 at y = 0.096, inside cell (1, 1), which holds 253: the
    end cell alone reads 0, the swept check reads 253.
    """
    grid = Grid(np.zeros((4, 4), dtype=np.uint8))
    grid.costs[1, 1] = 253
    xs, ys = np.array([[0.065]]), np.array([[0.105]])
    assert trajectory_costs(grid, xs, ys).tolist() == [[0]]
    assert trajectory_costs(grid, xs, ys, start=(0.04, 0.09)).tolist() == [[253]]


# --- following ---------------------------------------------------------------------

def test_straight_path_along_x_drives_forward_only():
    """A path along +x in free space: vx > 0 up to the limit, vy and wz stay ~0."""
    controller = LocalController(PARAMS)
    pose, log = drive(controller, empty_grid(), [(0.0, 0.0), (2.0, 0.0)], (0.0, 0.0, 0.0),
                      cycles=20)
    twists = np.array([twist for _, twist, _ in log])
    assert np.all(twists[:, 0] > 0.0)
    assert np.max(np.abs(twists[:, 1])) < 0.01
    assert np.max(np.abs(twists[:, 2])) < 0.01
    assert twists[-1, 0] == pytest.approx(0.8, abs=0.05)   # cruising at max_vel_x after 1 s
    assert abs(pose[1]) < 0.01 and abs(pose[2]) < 0.01


@pytest.mark.parametrize('sign', [1.0, -1.0])
def test_sideways_path_is_followed_by_strafing(sign):
    """A path along +-y from yaw 0: the robot strafes (|vy| -> 0.6) and does not turn."""
    controller = LocalController(PARAMS)
    pose, log = drive(controller, empty_grid(), [(0.0, 0.0), (0.0, sign * 2.0)],
                      (0.0, 0.0, 0.0), cycles=30)
    twists = np.array([twist for _, twist, _ in log])
    assert np.all(sign * twists[:, 1] > 0.0)
    assert np.max(np.abs(twists[:, 1])) == pytest.approx(0.6, abs=0.01)
    assert np.max(np.abs(twists[:, 0])) < 0.01
    assert np.max(np.abs(twists[:, 2])) < 0.01
    assert abs(pose[2]) < 0.01 and abs(pose[0]) < 0.01
    # Full-speed strafe: 8 periods ramping by 0.075 m/s (0.05 s x 0.075 x 36 = 0.135 m),
    # then 22 periods at 0.6 m/s (0.66 m): 0.795 m in 1.5 s.
    assert sign * pose[1] == pytest.approx(0.795, abs=0.005)


def test_heading_mode_path_turns_to_face_the_path():
    """heading_mode 'path' on the same sideways path: the robot turns toward +y as it goes."""
    controller = LocalController(ControllerParams.from_robot_config(ROBOT, heading_mode='path'))
    pose, _ = drive(controller, empty_grid(), [(0.0, 0.0), (0.0, 2.5)], (0.0, 0.0, 0.0),
                    cycles=40)
    assert pose[2] > 1.0


def test_diagonal_targets_respect_the_wheel_speed_limit():
    """Along a 45 degree path every command keeps |vx| + |vy| + 0.215 |wz| <= 1.12 m/s."""
    controller = LocalController(PARAMS)
    _, log = drive(controller, empty_grid(), [(0.0, 0.0), (1.5, 1.5)], (0.0, 0.0, 0.0),
                   cycles=40)
    for _, (vx, vy, wz), _ in log:
        assert abs(vx) + abs(vy) + 0.215 * abs(wz) <= 1.12 + 1e-9
    speeds = [math.hypot(vx, vy) for _, (vx, vy, _), _ in log]
    assert max(speeds) > 0.7   # 0.56 m/s on each axis, close to the wheel limit


def test_pruning_follows_a_path_that_comes_back_in_order():
    """Out along y = 0 and back along y = 0.3: at the start the carrot is 1 m out, not back."""
    controller = LocalController(PARAMS)
    path = [(0.0, 0.0), (2.0, 0.0), (2.0, 0.3), (0.0, 0.3)]
    controller.compute_velocity((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), path, empty_grid())
    assert controller.last.carrot == pytest.approx((1.0, 0.0))


# --- obstacles ---------------------------------------------------------------------

def obstacle_grid():
    """Return a 4 m x 3 m room (origin 0, 0) with a 0.4 m square obstacle at (2.0, 1.5)."""
    lethal = np.zeros((60, 80), dtype=bool)
    box(lethal, 1.8, 1.3, 2.2, 1.7)
    return Grid(inflate(lethal))


def test_path_around_an_obstacle_never_commands_a_trajectory_into_it():
    """Every chosen trajectory stays out of cells >= 253 while others are rejected."""
    grid = obstacle_grid()
    path = [(0.5, 1.5), (1.4, 1.5), (2.0, 2.2), (2.6, 1.5), (3.5, 1.5)]
    controller = LocalController(PARAMS)
    rejected = []

    def check(pose):
        assert grid.cost_at(pose[0], pose[1]) < 253, pose

    dt = PARAMS.control_period
    pose, twist = (0.5, 1.5, 0.0), (0.0, 0.0, 0.0)
    for _ in range(150):
        twist, status = controller.compute_velocity(pose, twist, path, grid)
        if status == STATUS_GOAL_REACHED:
            break
        assert status == STATUS_FOLLOWING
        chosen = controller.last.trajectory
        assert max(grid.cost_at(x, y) for x, y, _ in chosen) < 253
        rejected.append(controller.last.samples - controller.last.valid_samples)
        for _ in range(5):
            pose = integrate_pose(*pose, *twist, dt / 5)
            check(pose)
    assert status == STATUS_GOAL_REACHED
    assert max(rejected) > 50   # the obstacle did invalidate trajectories


def test_boxed_in_reports_no_valid_trajectory():
    """Lethal ring 0.25 m around the robot: every move enters 253 cells -> no valid, stop."""
    lethal = np.zeros((40, 40), dtype=bool)
    xs = (np.arange(40) + 0.5) * RES - 1.0
    gx, gy = np.meshgrid(xs, xs)
    ring = np.hypot(gx - 0.025, gy - 0.025)
    lethal[(ring > 0.25) & (ring < 0.32)] = True
    grid = Grid(inflate(lethal), RES, -1.0, -1.0)
    controller = LocalController(PARAMS)
    twist, status = controller.compute_velocity((0.025, 0.025, 0.0), (0.0, 0.0, 0.0),
                                                [(0.025, 0.025), (2.0, 0.0)], grid)
    assert status == STATUS_NO_VALID_TRAJECTORY
    assert twist == (0.0, 0.0, 0.0)
    # Moving when boxed in: the twist brakes within the acceleration limits.
    twist, status = controller.compute_velocity((0.025, 0.025, 0.0), (0.3, 0.0, 0.0),
                                                [(0.025, 0.025), (2.0, 0.0)], grid)
    assert status == STATUS_NO_VALID_TRAJECTORY
    assert twist == pytest.approx((0.3 - 1.5 * 0.05, 0.0, 0.0))


def test_unknown_cells_are_invalid_unless_allowed():
    """A band of unknown (255) across the path: blocked by default, crossed with allow_unknown."""
    costs = np.zeros((40, 120), dtype=np.uint8)
    costs[:, 30:34] = 255
    grid = Grid(costs, RES, -1.0, -1.0)
    path = [(0.0, 0.0), (4.0, 0.0)]
    blocked = LocalController(PARAMS)
    _, log = drive(blocked, grid, path, (0.0, 0.0, 0.0), cycles=40)
    assert max(p[0] for p, _, _ in log) < 0.5 - 0.0001   # never reaches the band at x 0.5
    allowed = LocalController(ControllerParams.from_robot_config(ROBOT, allow_unknown=True))
    pose, _ = drive(allowed, grid, path, (0.0, 0.0, 0.0), cycles=40)
    assert pose[0] > 1.0


def test_robot_inside_an_inscribed_cell_moves_out():
    """Start 0.15 m from a wall (inscribed cell): trajectories away from it stay valid."""
    lethal = np.zeros((40, 60), dtype=bool)
    box(lethal, 0.0, 0.0, 3.0, 0.2)
    grid = Grid(inflate(lethal))
    start = (1.0, 0.375, 0.0)
    assert grid.cost_at(*start[:2]) == 253
    controller = LocalController(PARAMS)
    pose, log = drive(controller, grid, [(1.0, 0.375), (1.0, 1.5)], start, cycles=30)
    assert log[0][2] == STATUS_FOLLOWING
    assert grid.cost_at(*pose[:2]) < 253


# --- limits ------------------------------------------------------------------------

TWIST = st.tuples(st.floats(-0.8, 0.8), st.floats(-0.6, 0.6), st.floats(-2.5, 2.5))


@settings(max_examples=60, deadline=None)
@given(current=TWIST, yaw=st.floats(-math.pi, math.pi),
       heading=st.floats(-math.pi, math.pi), length=st.floats(0.0, 2.0),
       goal_yaw=st.one_of(st.none(), st.floats(-math.pi, math.pi)))
def test_commands_respect_velocity_and_acceleration_limits(
        current, yaw, heading, length, goal_yaw):
    """Any state: |twist| within the limits and |twist - current| <= acc_lim / 20 Hz."""
    grid = obstacle_grid()
    start = (1.0, 1.0, yaw)
    goal = (1.0 + length * math.cos(heading), 1.0 + length * math.sin(heading))
    path = [start[:2], goal if goal_yaw is None else (*goal, goal_yaw)]
    twist, status = LocalController(PARAMS).compute_velocity(start, current, path, grid)
    limits = (0.8, 0.6, 2.5)
    steps = (1.5 * 0.05, 1.5 * 0.05, 5.0 * 0.05)
    for value, was, limit, step in zip(twist, current, limits, steps):
        assert abs(value) <= limit + 1e-12
        assert abs(value - was) <= step + 1e-9
    assert status in (STATUS_FOLLOWING, STATUS_ROTATING, STATUS_GOAL_REACHED)


# --- goal --------------------------------------------------------------------------

def test_stops_at_the_goal_within_tolerance_and_turns_to_its_yaw():
    """From 1 m away with goal yaw pi/2: goal_reached within 0.05 m and 0.05 rad, then zero."""
    controller = LocalController(PARAMS)
    goal = (1.0, 0.5, math.pi / 2)
    pose, log = drive(controller, empty_grid(), [(0.0, 0.0), goal], (0.0, 0.0, 0.0),
                      cycles=200)
    assert log[-1][2] == STATUS_GOAL_REACHED
    assert math.hypot(pose[0] - 1.0, pose[1] - 0.5) <= 0.05
    assert abs(wrap_angle(pose[2] - math.pi / 2)) <= 0.05
    twist, status = controller.compute_velocity(pose, (0.0, 0.0, 0.0),
                                                [(0.0, 0.0), goal], empty_grid())
    assert (twist, status) == ((0.0, 0.0, 0.0), STATUS_GOAL_REACHED)


def test_at_the_goal_position_it_rotates_in_place():
    """Within xy tolerance, yaw 1 rad off: turn in place (no translation) until within 0.05."""
    controller = LocalController(PARAMS)
    path = [(0.0, 0.0), (0.02, 0.0, 1.0)]
    pose, log = drive(controller, empty_grid(), path, (0.0, 0.0, 0.0), cycles=100)
    statuses = [status for _, _, status in log]
    assert statuses[0] == STATUS_ROTATING and statuses[-1] == STATUS_GOAL_REACHED
    for _, (vx, vy, wz), status in log[:-1]:
        assert (vx, vy) == (0.0, 0.0) and wz > 0.0
    assert abs(pose[2] - 1.0) <= 0.05 and pose[:2] == (0.0, 0.0)


def test_stale_pose_brakes():
    """A pose older than transform_tolerance (0.1 s): status stale_pose, braking step."""
    controller = LocalController(PARAMS)
    twist, status = controller.compute_velocity((0.0, 0.0, 0.0), (0.5, 0.0, 0.0),
                                                [(0.0, 0.0), (2.0, 0.0)], empty_grid(),
                                                pose_age_s=0.5)
    assert status == STATUS_STALE_POSE
    assert twist == pytest.approx((0.5 - 0.075, 0.0, 0.0))


@pytest.mark.parametrize('pose, twist, path, message', [
    ((math.nan, 0.0, 0.0), (0.0, 0.0, 0.0), [(1.0, 0.0)], 'pose'),
    ((0.0, 0.0, 0.0), (0.0, math.inf, 0.0), [(1.0, 0.0)], 'current_twist'),
    ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), [], 'path'),
    ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), [(1.0, math.nan)], r'path\[0\]'),
    ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), [(1.0, 0.0, 0.0, 0.0)], r'path\[0\]'),
])
def test_bad_inputs_raise_clear_errors(pose, twist, path, message):
    """Non-finite poses or twists and malformed paths raise ValueError naming them."""
    with pytest.raises(ValueError, match=message):
        LocalController(PARAMS).compute_velocity(pose, twist, path, empty_grid())


def test_a_costmap_without_costs_is_rejected():
    """An object that is not costmap-like raises ValueError."""
    with pytest.raises(ValueError, match='costs'):
        LocalController(PARAMS).compute_velocity((0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                                 [(1.0, 0.0)], object())


# --- closed loop -------------------------------------------------------------------

def test_closed_loop_l_shaped_corridor_with_an_obstacle():
    """
    L-shaped corridor (1.4 m wide) and a box sticking out of its wall next to the path.

    Perfect tracking of every command (integrated in 1 cm substeps): the robot reaches
    the goal and its centre never enters a cell of cost >= 253.
    """
    lethal = np.ones((120, 120), dtype=bool)
    lethal[10:38, 10:100] = False            # horizontal leg: x 0.5..5.0, y 0.5..1.9
    lethal[10:110, 72:100] = False           # vertical leg: x 3.6..5.0, y 0.5..5.5
    lethal[10:20, 40:46] = True              # box x 2.0..2.3, y 0.5..1.0 off the lower wall
    grid = Grid(inflate(lethal))
    path = [(0.9, 1.2), (4.3, 1.2), (4.3, 5.0, math.pi / 2)]
    assert grid.cost_at(2.15, 1.2) > 200     # the path passes next to the box
    worst = []

    def check(pose):
        worst.append(grid.cost_at(pose[0], pose[1]))
        assert worst[-1] < 253, pose

    pose, log = drive(LocalController(PARAMS), grid, path, (0.9, 1.2, 0.0), cycles=600,
                      check=check)
    assert log[-1][2] == STATUS_GOAL_REACHED
    assert math.hypot(pose[0] - 4.3, pose[1] - 5.0) <= 0.05
    assert abs(wrap_angle(pose[2] - math.pi / 2)) <= 0.05
    assert all(status in (STATUS_FOLLOWING, STATUS_ROTATING, STATUS_GOAL_REACHED)
               for _, _, status in log)
    assert max(worst) > 150   # it did pass close to the box


# --- progress checker --------------------------------------------------------------

def test_progress_checker_fails_after_the_allowance_without_movement():
    """Radius 0.5 m, 10 s: moving 0.6 m resets the clock; staying 10.1 s fails."""
    checker = ProgressChecker(0.5, 10.0)
    assert checker.check(0.0, 0.0, 0.0)
    assert checker.check(0.4, 0.0, 9.0)        # within the radius, within the allowance
    assert checker.check(0.6, 0.0, 9.5)        # moved out: new baseline at t = 9.5
    assert checker.check(0.6, 0.3, 19.5)       # 10.0 s later: still allowed
    assert not checker.check(0.6, 0.3, 19.6)
    checker.reset()
    assert checker.check(0.6, 0.3, 19.7)
    with pytest.raises(ValueError, match='required_movement_radius'):
        ProgressChecker(0.0, 10.0)


def test_a_tight_corner_is_driven_around_not_stopped_at():
    """
    The apartment's 0.6 m strip behind the bed, entered from a 0.55 m column.

    With the carrot 1 m ahead along the path, beyond the corner, every trajectory toward
    it runs into the bed: the controller used to stop in front of the corner (a zero
    twist scored best). The carrot is now the farthest path point in sight, so the
    robot drives to the corner, then strafes west (facing north) through the strip.
    """
    from mecanum_navigation.costmap.costmap_2d import (
        Costmap2D, InflationLayer, LayeredCostmap, StaticLayer)
    from mecanum_map_server.map_io import find_map_file, load_map
    from mecanum_navigation.planner.planner import GridPlanner

    occupancy = load_map(find_map_file('apartment'))
    costmap = Costmap2D.like_map(occupancy)
    LayeredCostmap(costmap, [StaticLayer(occupancy), InflationLayer(0.2, 0.5, 4.0)]).update()
    start, goal = (2.42, 6.6, math.pi / 2), (1.0, 7.6, math.pi / 2)
    points = GridPlanner().plan(costmap, start[:2], goal[:2]).points
    path = np.array([(x, y, goal[2]) for x, y in points])

    def check(pose):
        assert costmap.cost_at(pose[0], pose[1]) < 253, pose
    pose, log = drive(LocalController(PARAMS), costmap, path, start, cycles=400, check=check)
    assert log[-1][2] == STATUS_GOAL_REACHED
    assert math.hypot(pose[0] - goal[0], pose[1] - goal[1]) <= PARAMS.xy_goal_tolerance
    # Through the strip (y > 7.45, x < 2.1) it moved sideways: body vy, heading north.
    in_strip = [twist for p, twist, _ in log if p[1] > 7.45 and p[0] < 2.1]
    assert in_strip and max(abs(t[1]) for t in in_strip) > 0.3
    assert max(abs(t[0]) for t in in_strip) < 0.1


@pytest.mark.parametrize('start', [(2.73, 6.67), (2.9, 6.6), (3.1, 6.55)])
def test_a_robot_stopped_in_front_of_a_narrow_gap_drives_through_it(start):
    """
    From standstill south-east of the 0.55 m gap between the bed and the wardrobe.

    Every trajectory into the gap crosses cells of cost ~220 that standing still does
    not: with the obstacle critic counting the whole cost, a zero twist scored best for
    ever (a sweep of the apartment tour found the robot stopped there until the
    progress checker gave up). The cost the path itself crosses is no longer held
    against trajectories, so the robot drives through without touching inscribed cells.
    """
    from mecanum_navigation.costmap.costmap_2d import (
        Costmap2D, InflationLayer, LayeredCostmap, StaticLayer)
    from mecanum_map_server.map_io import find_map_file, load_map
    from mecanum_navigation.planner.planner import GridPlanner

    occupancy = load_map(find_map_file('apartment'))
    costmap = Costmap2D.like_map(occupancy)
    LayeredCostmap(costmap, [StaticLayer(occupancy), InflationLayer(0.2, 0.5, 4.0)]).update()
    goal = (1.0, 7.6, math.pi / 2)
    points = GridPlanner().plan(costmap, start, goal[:2]).points
    path = np.array([(x, y, goal[2]) for x, y in points])

    def check(pose):
        assert costmap.cost_at(pose[0], pose[1]) < 253, pose
    pose, log = drive(LocalController(PARAMS), costmap, path, (*start, math.pi / 2),
                      cycles=600, check=check)
    assert log[-1][2] == STATUS_GOAL_REACHED, (log[-1], pose)
    assert math.hypot(pose[0] - goal[0], pose[1] - goal[1]) <= PARAMS.xy_goal_tolerance


def lane_around_a_corner():
    """
    Return a 0.6 m lane turning round a block's corner whose edges fall short of cell borders.

    The block is x, y <= 1.049 m; the lane's outer walls are at x, y = 1.649 m. The
    costmap (5 cm cells) marks the cells holding wall points lethal and measures the
    inscribed radius between cell centres, so it thinks the block's edge is 2.4 cm
    farther than it is. Returns (costmap grid, exact wall points (P, 2), path).
    """
    edge, outer, step = 1.049, 1.649, 0.005
    along = np.arange(-1.0, outer + step, step)
    walls = [np.column_stack((along[along <= edge], np.full((along <= edge).sum(), edge))),
             np.column_stack((np.full((along <= edge).sum(), edge), along[along <= edge])),
             np.column_stack((along, np.full(along.size, outer))),
             np.column_stack((np.full(along.size, outer), along))]
    points = np.vstack(walls)
    cells = int(round(3.0 / RES))
    lethal = np.zeros((cells, cells), dtype=bool)
    origin = -1.0
    cols = np.floor((points[:, 0] - origin) / RES).astype(int)
    rows = np.floor((points[:, 1] - origin) / RES).astype(int)
    inside = (rows >= 0) & (rows < cells) & (cols >= 0) & (cols < cells)
    lethal[rows[inside], cols[inside]] = True
    grid = Grid(inflate(lethal), RES, origin, origin)
    lane = 0.5 * (edge + outer)
    path = np.array([(lane, -0.6, math.pi / 2), (lane, lane, math.pi / 2),
                     (-0.6, lane, math.pi / 2)])
    return grid, points, path


@pytest.mark.parametrize('exact', [False, True])
def test_scan_points_keep_the_footprint_clear_where_cells_are_too_coarse(exact):
    """
    With the scan points the footprint keeps collision_margin from the block; without, not.

    Costmap cells alone let the robot cut the corner nearer than robot_radius + margin
    (the case that grazed the bed in the apartment tour): this half of the test shows
    the coarse check is really that coarse, so the other half can fail.
    """
    grid, points, path = lane_around_a_corner()
    params = ControllerParams.from_robot_config(ROBOT, max_vel_x=0.5, max_vel_y=0.4,
                                                max_vel_theta=1.5)
    closest = []

    def check(pose):
        closest.append(float(np.min(np.hypot(points[:, 0] - pose[0],
                                             points[:, 1] - pose[1]))))
    lane = path[1][0]
    pose, log = drive(LocalController(params), grid, path, (lane, -0.6, math.pi / 2),
                      cycles=400, check=check, points=points if exact else None)
    assert log[-1][2] == STATUS_GOAL_REACHED
    clearance = min(closest) - params.robot_radius
    if exact:
        assert clearance >= params.collision_margin - 1e-3, clearance
    else:
        assert clearance < params.collision_margin - 5e-3, clearance


def test_scan_points_let_a_robot_already_too_near_move_away_but_not_nearer():
    """0.005 m from a wall (inside the margin): it may leave, never approach the wall."""
    params = ControllerParams.from_robot_config(ROBOT)
    wall = np.column_stack((np.arange(-2.0, 2.0, 0.005), np.full(800, 0.0)))
    pose = (0.0, params.robot_radius + 0.005, 0.0)
    grid = empty_grid()
    path = np.array([(0.0, pose[1], 0.0), (1.5, pose[1], 0.0)])
    closest = []

    def check(p):
        closest.append(float(np.min(np.abs(wall[:, 1] - p[1]))))
    _, log = drive(LocalController(params), grid, path, pose, cycles=60, check=check,
                   points=wall)
    assert all(status == STATUS_FOLLOWING for _, _, status in log[:10])
    assert min(closest) >= params.robot_radius + 0.005 - 1e-3
    assert log[-1][0][0] > 0.5   # and it did drive along


def test_obstacle_points_must_be_pairs():
    """A malformed points array is a clear ValueError; rows with NaN are dropped."""
    controller = LocalController(PARAMS)
    path = [(0.0, 0.0), (1.0, 0.0)]
    with pytest.raises(ValueError, match='obstacle_points must be an N x 2 array'):
        controller.compute_velocity((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), path, empty_grid(),
                                    obstacle_points=np.zeros((3, 3)))
    twist, status = controller.compute_velocity(
        (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), path, empty_grid(),
        obstacle_points=[(math.nan, 0.1), (5.0, 5.0)])
    assert status == STATUS_FOLLOWING and twist[0] > 0.0
