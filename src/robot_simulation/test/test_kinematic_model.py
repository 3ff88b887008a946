"""Tests of the kinematic base model behind simulation_node."""

import math

import pytest
from robot_simulation.kinematic_model import KinematicBase, Pose2D, TwistLimits


def drive(model, seconds, dt=0.01, start_s=0.0):
    """Step the model for `seconds` of simulated time, re-sending nothing."""
    steps = int(round(seconds / dt))
    for i in range(1, steps + 1):
        model.step(start_s + i * dt, dt)
    return model.pose


def test_straight_line_until_command_timeout():
    model = KinematicBase(cmd_timeout_s=0.5)
    model.command(0.4, 0.0, 0.0, now_s=0.0)
    # Moves while the command is fresh (0.5 s -> 0.2 m), then stops by itself.
    pose = drive(model, 2.0)
    assert pose.x == pytest.approx(0.2, abs=0.01)
    assert model.twist == (0.0, 0.0, 0.0)


def test_fresh_commands_keep_it_moving_and_strafe_goes_left():
    model = KinematicBase(cmd_timeout_s=0.5)
    for i in range(100):
        model.command(0.0, 0.3, 0.0, now_s=i * 0.01)
        model.step((i + 1) * 0.01, 0.01)
    assert (model.pose.x, model.pose.y) == pytest.approx((0.0, 0.3))


def test_rotation_in_place():
    model = KinematicBase(Pose2D(1.0, 2.0, 0.0), cmd_timeout_s=10.0)
    model.command(0.0, 0.0, math.pi / 2, now_s=0.0)
    pose = drive(model, 1.0)
    assert (pose.x, pose.y, pose.yaw) == pytest.approx((1.0, 2.0, math.pi / 2))


def test_limits_clamp_each_axis():
    model = KinematicBase(limits=TwistLimits(0.5, 0.4, 1.0))
    assert model.command(2.0, -3.0, 9.0, now_s=0.0) == (0.5, -0.4, 1.0)


@pytest.mark.parametrize('bad', [float('nan'), float('inf'), -float('inf')])
def test_non_finite_commands_are_rejected_and_change_nothing(bad):
    model = KinematicBase()
    model.command(0.1, 0.0, 0.0, now_s=0.0)
    with pytest.raises(ValueError):
        model.command(bad, 0.0, 0.0, now_s=0.1)
    assert model.twist == (0.1, 0.0, 0.0)


def test_no_command_no_motion():
    model = KinematicBase()
    assert drive(model, 1.0) == Pose2D(0.0, 0.0, 0.0)
