"""Tests of navigator.recoveries: the recovery behaviours, worked out by hand."""

import math

from mecanum_navigation.controller.local_controller import ControllerParams
from mecanum_navigation.costmap.costmap_2d import Costmap2D, LETHAL_OBSTACLE
from mecanum_navigation.navigator.navigator import NavigatorParams
from mecanum_navigation.navigator.recoveries import (
    approach_speed, BACK_UP, backup_clear, backup_direction, backup_step, BACKUP_TOLERANCE_M,
    CLEAR_LOCAL_COSTMAP, lethal_points, Recovery, RECOVERY_SEQUENCE, RecoveryStep, SPIN,
    spin_step, SPIN_TOLERANCE_RAD, start_recovery, step_recovery, WAIT, wait_step, ZERO_TWIST)
import numpy as np
import pytest

RES = 0.05
# Acceleration limits 1.5, 1.5, 5.0 (m/s^2, rad/s^2), 20 Hz: one period changes vx or vy
# by up to 0.075 m/s and wz by up to 0.25 rad/s.
CONTROLLER = ControllerParams()
PARAMS = NavigatorParams()   # spin 1.57 rad at <= 1 rad/s, back up 0.15 m at <= 0.1 m/s


def window(*obstacles):
    """Return a 3 m x 3 m odom costmap from (-1.5, -1.5), lethal cells at the given points."""
    costmap = Costmap2D(60, 60, RES, -1.5, -1.5)
    for x, y in obstacles:
        costmap.costs[costmap.world_to_map(x, y)] = LETHAL_OBSTACLE
    return costmap


# The robot sits at the centre of cell (30, 30): (0.025, 0.025). A cell 6 cells away has
# its centre 0.3 m from it.
ROBOT = (0.025, 0.025)
AHEAD = (0.325, 0.025)      # +x of the robot
LEFT = (0.025, 0.325)       # +y of the robot


def test_the_sequence_and_constants():
    """Nav2's default round robin: clear, spin, back up, wait."""
    assert RECOVERY_SEQUENCE == (CLEAR_LOCAL_COSTMAP, SPIN, BACK_UP, WAIT)
    assert RECOVERY_SEQUENCE == ('clear_local_costmap', 'spin', 'back_up', 'wait')
    assert (SPIN_TOLERANCE_RAD, BACKUP_TOLERANCE_M) == (0.02, 0.005)
    assert ZERO_TWIST == (0.0, 0.0, 0.0)


def test_lethal_points_are_the_cell_centres():
    """Cells (row 30, col 36) and (36, 30), row by row: (0.325, 0.025), (0.025, 0.325)."""
    points = lethal_points(window(LEFT, AHEAD))
    assert points == pytest.approx(np.array([AHEAD, LEFT]))
    assert lethal_points(window()).shape == (0, 2)


# --- back up: direction and clearance ----------------------------------------------------

def test_backup_direction_with_an_obstacle_straight_ahead_is_straight_back():
    """Facing +x, the obstacle 0.3 m ahead: back along -x, clearance 0.3 m."""
    direction, clearance = backup_direction(window(AHEAD), (*ROBOT, 0.0))
    assert direction == pytest.approx((-1.0, 0.0))
    assert clearance == pytest.approx(0.3)


def test_backup_direction_with_an_obstacle_to_the_left_is_to_the_right():
    """Facing +x, the obstacle 0.3 m to the left (+y): strafe along -y, not backwards."""
    direction, clearance = backup_direction(window(LEFT), (*ROBOT, 0.0))
    assert direction == pytest.approx((0.0, -1.0))
    assert clearance == pytest.approx(0.3)


def test_backup_direction_diagonal_and_nearest_obstacle():
    """
    An obstacle at (+0.3, +0.3) from the robot: away along (-1, -1) / sqrt(2), 0.3 sqrt(2).

    With one also straight ahead (0.3 m, nearer than 0.42 m) that one decides.
    """
    diagonal = (0.325, 0.325)
    direction, clearance = backup_direction(window(diagonal), (*ROBOT, 1.0))
    assert direction == pytest.approx((-math.sqrt(0.5), -math.sqrt(0.5)))
    assert clearance == pytest.approx(0.3 * math.sqrt(2.0))
    direction, clearance = backup_direction(window(diagonal, AHEAD), (*ROBOT, 1.0))
    assert direction == pytest.approx((-1.0, 0.0))
    assert clearance == pytest.approx(0.3)


def test_backup_direction_without_obstacle_or_on_one_is_backwards():
    """No lethal cell: the robot's own -x (yaw pi/2: world -y), clearance inf; on one: 0."""
    direction, clearance = backup_direction(window(), (*ROBOT, math.pi / 2))
    assert direction == pytest.approx((0.0, -1.0))
    assert clearance == math.inf
    direction, clearance = backup_direction(window(ROBOT), (*ROBOT, math.pi))
    assert direction == pytest.approx((1.0, 0.0))
    assert clearance == 0.0


def test_backup_clear_samples_the_motion():
    """
    The obstacle 0.3 m ahead; samples every 0.025 m, the first one 0.025 m from the start.

    Back along -x 0.15 m: the nearest sample is the first, 0.325 m from the obstacle.
    Toward it along +x 0.15 m: the last, at x 0.175, is 0.15 m from it. Leaving the window
    (x < 1.5) is never clear.
    """
    costmap = window(AHEAD)
    assert backup_clear(costmap, ROBOT, (-1.0, 0.0), 0.15, 0.31)
    assert not backup_clear(costmap, ROBOT, (-1.0, 0.0), 0.15, 0.33)
    assert backup_clear(costmap, ROBOT, (1.0, 0.0), 0.15, 0.14)
    assert not backup_clear(costmap, ROBOT, (1.0, 0.0), 0.15, 0.16)
    assert backup_clear(window(), ROBOT, (1.0, 0.0), 0.15, 0.2)
    assert not backup_clear(window(), (1.4, 0.025), (1.0, 0.0), 0.15, 0.0)
    assert backup_clear(window(), (1.4, 0.025), (1.0, 0.0), 0.05, 0.0)


# --- speeds and steps ------------------------------------------------------------------

@pytest.mark.parametrize('remaining, expected', [
    (1.0, 1.0),                 # min(1, sqrt(5) = 2.24, 10): the top speed
    (0.1, math.sqrt(0.5)),      # min(1, sqrt(0.5) = 0.707, 1.0): braking at half of 5
    (0.01, 0.1),                # min(1, sqrt(0.05) = 0.224, 0.01 / 0.1): one period's half
])
def test_approach_speed(remaining, expected):
    """Top speed 1, acceleration 5, period 0.05 s."""
    assert approach_speed(remaining, 1.0, 5.0, 0.05) == pytest.approx(expected)


def test_wait_is_done_after_its_duration():
    """Zero twist while under wait_duration (2 s), done from 2 s (1 ns early counts)."""
    assert wait_step(0.0, 2.0) == RecoveryStep(ZERO_TWIST)
    assert wait_step(1.99, 2.0) == RecoveryStep(ZERO_TWIST)
    assert wait_step(2.0 - 1e-10, 2.0).done
    assert wait_step(2.0, 2.0).done
    assert wait_step(5.0, 2.0) == RecoveryStep(None)


def spin_from(yaw):
    """Return a spin recovery started at yaw."""
    return start_recovery(SPIN, 0.0, 'test', (*ROBOT, yaw), window())


def test_spin_turns_counter_clockwise_and_ramps():
    """
    At the start 1.57 rad remain: target wz min(1, sqrt(5 * 1.57), 15.7) = 1 rad/s.

    From rest one period reaches 0.25 rad/s; from 1 rad/s it stays there.
    """
    recovery = spin_from(0.0)
    assert spin_step(recovery, 0.0, ZERO_TWIST, 1.57, 1.0, CONTROLLER).twist == \
        pytest.approx((0.0, 0.0, 0.25))
    assert spin_step(recovery, 0.0, (0.0, 0.0, 1.0), 1.57, 1.0, CONTROLLER).twist == \
        pytest.approx((0.0, 0.0, 1.0))


def test_spin_is_done_within_its_tolerance():
    """Turned 1.549 rad (0.021 left) it still turns; 1.551 rad (0.019 left) it is done."""
    recovery = spin_from(0.0)
    step = spin_step(recovery, 1.549, (0.0, 0.0, 0.2), 1.57, 1.0, CONTROLLER)
    # 0.021 left: min(1, sqrt(0.105) = 0.324, 0.021 / 0.1 = 0.21) = 0.21 rad/s.
    assert step.twist == pytest.approx((0.0, 0.0, 0.21))
    assert recovery.turned_rad == pytest.approx(1.549)
    assert spin_step(recovery, 1.551, (0.0, 0.0, 0.21), 1.57, 1.0, CONTROLLER).done


def test_spin_sums_the_wrapped_yaw_changes():
    """
    From yaw 3.0 to -1.8 is a turn of 2 pi - 4.8 = 1.4832 rad (across +-pi), not -4.8.

    0.0868 rad left: min(1, sqrt(0.434) = 0.659, 0.868) = 0.659 rad/s; then yaw -1.73
    adds 0.07 rad: 0.0168 rad left, done.
    """
    recovery = spin_from(3.0)
    step = spin_step(recovery, -1.8, (0.0, 0.0, 0.8), 1.57, 1.0, CONTROLLER)
    assert recovery.turned_rad == pytest.approx(2.0 * math.pi - 4.8)
    assert step.twist == pytest.approx((0.0, 0.0, math.sqrt(5.0 * (1.57 - 2.0 * math.pi + 4.8))))
    assert spin_step(recovery, -1.73, step.twist, 1.57, 1.0, CONTROLLER).done
    assert recovery.turned_rad == pytest.approx(2.0 * math.pi - 4.8 + 0.07)


def backup_from(costmap, yaw=0.0):
    """Return a back-up recovery started at the robot with yaw."""
    return start_recovery(BACK_UP, 0.0, 'test', (*ROBOT, yaw), costmap)


def test_start_recovery_records_the_start():
    """A back up picks its direction at the start; the others keep the defaults."""
    recovery = backup_from(window(AHEAD))
    assert recovery.kind == BACK_UP and recovery.reason == 'test'
    assert recovery.start_pose == (0.025, 0.025, 0.0)
    assert recovery.direction == pytest.approx((-1.0, 0.0))
    assert recovery.clearance_m == pytest.approx(0.3)
    spin = spin_from(0.5)
    assert spin == Recovery(SPIN, 0.0, 'test', (0.025, 0.025, 0.5), last_yaw=0.5)


def test_backup_from_an_obstacle_ahead_drives_backwards():
    """
    0.15 m left: target speed min(0.1, sqrt(1.5 * 0.15) = 0.47, 1.5) = 0.1 m/s along -x.

    Facing +x that is body (-0.1, 0); from rest one period reaches -0.075 m/s.
    """
    costmap = window(AHEAD)
    recovery = backup_from(costmap)
    step = backup_step(recovery, (*ROBOT, 0.0), ZERO_TWIST, costmap, 0.15, 0.1, 0.2, CONTROLLER)
    assert step.twist == pytest.approx((-0.075, 0.0, 0.0))
    step = backup_step(recovery, (*ROBOT, 0.0), (-0.1, 0.0, 0.0), costmap, 0.15, 0.1, 0.2,
                       CONTROLLER)
    assert step.twist == pytest.approx((-0.1, 0.0, 0.0))
    assert step.warning == '' and not step.clear_local_costmap


def test_backup_from_an_obstacle_to_the_left_strafes_right():
    """Facing +x with the obstacle at +y: along -y, body (0, -0.1)."""
    costmap = window(LEFT)
    recovery = backup_from(costmap)
    step = backup_step(recovery, (*ROBOT, 0.0), (0.0, -0.1, 0.0), costmap, 0.15, 0.1, 0.2,
                       CONTROLLER)
    assert step.twist == pytest.approx((0.0, -0.1, 0.0))


def test_backup_direction_is_kept_in_odom_and_turned_into_the_body():
    """
    Facing +y (yaw pi/2) with the obstacle ahead at +y: odom -y is the body's -x.

    The direction stays the one chosen at the start: turned to yaw 0 mid-way, odom -y is
    then the body's -y.
    """
    costmap = window(LEFT)
    recovery = backup_from(costmap, math.pi / 2)
    assert recovery.direction == pytest.approx((0.0, -1.0))
    step = backup_step(recovery, (*ROBOT, math.pi / 2), (-0.1, 0.0, 0.0), costmap, 0.15, 0.1,
                       0.2, CONTROLLER)
    assert step.twist == pytest.approx((-0.1, 0.0, 0.0))
    step = backup_step(recovery, (0.025, -0.025, 0.0), (0.0, -0.1, 0.0), costmap, 0.15, 0.1,
                       0.2, CONTROLLER)
    assert step.twist == pytest.approx((0.0, -0.1, 0.0))


def test_backup_slows_down_and_is_done_within_its_tolerance():
    """
    Moved 0.142 m: 0.008 m left, min(0.1, sqrt(0.012) = 0.11, 0.08) = 0.08 m/s.

    Moved 0.146 m: 0.004 m left <= 0.005 m, done.
    """
    costmap = window(AHEAD)
    recovery = backup_from(costmap)
    step = backup_step(recovery, (ROBOT[0] - 0.142, ROBOT[1], 0.0), (-0.1, 0.0, 0.0), costmap,
                       0.15, 0.1, 0.2, CONTROLLER)
    assert step.twist == pytest.approx((-0.08, 0.0, 0.0))
    assert backup_step(recovery, (ROBOT[0] - 0.146, ROBOT[1], 0.0), (-0.08, 0.0, 0.0), costmap,
                       0.15, 0.1, 0.2, CONTROLLER) == RecoveryStep(None)


def test_backup_stops_when_the_rest_would_come_near_an_obstacle():
    """
    A new obstacle 0.15 m behind the start (centre x -0.125): the motion would reach it.

    The back up stops with a warning (kept clearance min(0.2, 0.3) = 0.2 m).
    """
    recovery = backup_from(window(AHEAD))
    later = window(AHEAD, (-0.125, 0.025))
    step = backup_step(recovery, (*ROBOT, 0.0), ZERO_TWIST, later, 0.15, 0.1, 0.2, CONTROLLER)
    assert step == RecoveryStep(
        None, warning='back up stopped: it would bring the robot nearer an obstacle')


def test_backup_nearer_than_the_radius_may_still_back_away():
    """
    An obstacle 0.1 m ahead (centre x 0.125), nearer than the 0.2 m radius.

    The clearance kept is min(0.2, 0.1) = 0.1 m, which backing away keeps: it moves.
    """
    costmap = window((0.125, 0.025))
    recovery = backup_from(costmap)
    assert recovery.clearance_m == pytest.approx(0.1)
    step = backup_step(recovery, (*ROBOT, 0.0), (-0.1, 0.0, 0.0), costmap, 0.15, 0.1, 0.2,
                       CONTROLLER)
    assert step.twist == pytest.approx((-0.1, 0.0, 0.0))


# --- step_recovery: the dispatch -------------------------------------------------------

def test_step_clear_local_costmap_asks_for_a_clear_and_is_done():
    """Clearing is over at once."""
    recovery = start_recovery(CLEAR_LOCAL_COSTMAP, 0.0, 'test', (*ROBOT, 0.0), window())
    step = step_recovery(recovery, 0.0, (*ROBOT, 0.0), ZERO_TWIST, window(), PARAMS, CONTROLLER)
    assert step == RecoveryStep(None, clear_local_costmap=True)


def test_step_wait_uses_the_elapsed_time_and_ignores_time_allowance():
    """Started at t 10: waits at t 11.9, done at t 12; a 20 s wait outlives the 10 s allowance."""
    recovery = start_recovery(WAIT, 10.0, 'test', (*ROBOT, 0.0), window())
    pose = (*ROBOT, 0.0)
    assert step_recovery(recovery, 11.9, pose, ZERO_TWIST, window(), PARAMS,
                         CONTROLLER) == RecoveryStep(ZERO_TWIST)
    assert step_recovery(recovery, 12.0, pose, ZERO_TWIST, window(), PARAMS, CONTROLLER).done
    long_wait = NavigatorParams(wait_duration=20.0)
    assert step_recovery(recovery, 25.0, pose, ZERO_TWIST, window(), long_wait,
                         CONTROLLER) == RecoveryStep(ZERO_TWIST)


def test_step_spin_and_backup_with_the_params():
    """The dispatch passes NavigatorParams' spin and back-up fields."""
    spin = spin_from(0.0)
    step = step_recovery(spin, 0.0, (*ROBOT, 0.0), (0.0, 0.0, 1.0), window(), PARAMS, CONTROLLER)
    assert step.twist == pytest.approx((0.0, 0.0, 1.0))
    slow = NavigatorParams(max_rotational_vel=0.5)
    step = step_recovery(spin, 0.0, (*ROBOT, 0.0), (0.0, 0.0, 0.5), window(), slow, CONTROLLER)
    assert step.twist == pytest.approx((0.0, 0.0, 0.5))
    costmap = window(AHEAD)
    backup = backup_from(costmap)
    step = step_recovery(backup, 0.0, np.array([*ROBOT, 0.0]), (-0.1, 0.0, 0.0), costmap,
                         PARAMS, CONTROLLER)
    assert step.twist == pytest.approx((-0.1, 0.0, 0.0))


def test_step_spin_or_backup_past_time_allowance_stops_with_a_warning():
    """After time_allowance (10 s) a spin or back up is over, with a warning."""
    spin = spin_from(0.0)
    assert step_recovery(spin, 10.0, (*ROBOT, 0.0), ZERO_TWIST, window(), PARAMS,
                         CONTROLLER).twist is not None
    assert step_recovery(spin, 10.5, (*ROBOT, 0.0), ZERO_TWIST, window(), PARAMS,
                         CONTROLLER) == RecoveryStep(
        None, warning='spin did not finish within 10 s')
    costmap = window(AHEAD)
    backup = backup_from(costmap)
    assert step_recovery(backup, 10.5, (*ROBOT, 0.0), ZERO_TWIST, costmap, PARAMS,
                         CONTROLLER).warning == 'back_up did not finish within 10 s'
