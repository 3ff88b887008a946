"""Hand-worked tests of controller.velocity_smoother (Nav2 velocity_smoother rules)."""

import math

from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_navigation.controller.velocity_smoother import (
    SmootherParams, STATUS_OK, STATUS_STOPPED, STATUS_TIMEOUT, STATUS_WAITING,
    VelocitySmoother)
import pytest

# 10 Hz: one step is 0.1 s. x: +1.0 / -2.0 m/s^2 -> 0.1 / 0.2 m/s per step;
# y: +0.5 / -1.0 -> 0.05 / 0.1; wz: +1.0 / -2.0 rad/s^2 -> 0.1 / 0.2 rad/s per step.
PARAMS = SmootherParams(smoothing_frequency=10.0, max_velocity=(0.8, 0.6, 2.5),
                        max_accel=(1.0, 0.5, 1.0), max_decel=(-2.0, -1.0, -2.0),
                        velocity_timeout=0.5)


def run(smoother, start_s, steps, command=None):
    """
    Run `steps` updates 0.1 s apart from start_s; return the published twists.

    With command, it is sent again before each update (a 10 Hz publisher), so the
    velocity timeout does not expire.
    """
    twists = []
    for k in range(steps):
        if command is not None:
            smoother.on_command(command, start_s + 0.1 * k)
        twists.append(smoother.update(start_s + 0.1 * k).twist)
    return twists


def approx(twists):
    """Return twists for comparison with 1e-9 tolerance."""
    return [pytest.approx(t, abs=1e-9) for t in twists]


@pytest.mark.parametrize('field, value, message', [
    ('smoothing_frequency', 0.0, 'smoothing_frequency'),
    ('velocity_timeout', math.nan, 'velocity_timeout'),
    ('feedback', 'BOTH', 'feedback'),
    ('scale_velocities', 'yes', 'scale_velocities'),
    ('max_velocity', (0.5, -0.1, 1.0), 'max_velocity linear.y'),
    ('min_velocity', (-0.5, 0.1, -1.0), 'min_velocity linear.y'),
    ('max_accel', (1.0, 1.0, 0.0), 'max_accel angular.z'),
    ('max_decel', (2.0, -1.0, -1.0), 'max_decel linear.x'),
    ('deadband_velocity', (0.0, 0.0), 'deadband_velocity'),
])
def test_params_reject_bad_values_naming_the_field(field, value, message):
    """Nav2's signs: max_decel negative, max_accel positive; arrays of 3."""
    with pytest.raises(ValueError, match=message):
        SmootherParams(**{field: value})


def test_params_from_robot_config():
    """motor_params.yaml limits; decelerations are the negated accelerations."""
    params = SmootherParams.from_robot_config(load_robot_config(default_config_path()))
    assert params.max_velocity == (0.8, 0.6, 2.5)
    assert params.min_velocity == (-0.8, -0.6, -2.5)
    assert params.max_accel == (1.5, 1.5, 5.0)
    assert params.max_decel == (-1.5, -1.5, -5.0)


def test_nothing_is_published_before_the_first_command():
    """Nav2 publishes nothing until a command arrives."""
    output = VelocitySmoother(PARAMS).update(0.0)
    assert output.twist == (0.0, 0.0, 0.0)
    assert (output.status, output.publish) == (STATUS_WAITING, False)


def test_acceleration_ramp_by_hand():
    """Target vx 0.35 from rest at +0.1 m/s per step: 0.1, 0.2, 0.3, 0.35, 0.35."""
    smoother = VelocitySmoother(PARAMS)
    assert smoother.on_command((0.35, 0.0, 0.0), 0.0) is None
    assert run(smoother, 0.1, 5) == approx([(0.1, 0.0, 0.0), (0.2, 0.0, 0.0), (0.3, 0.0, 0.0),
                                            (0.35, 0.0, 0.0), (0.35, 0.0, 0.0)])


def test_deceleration_uses_max_decel():
    """From 0.5 m/s to 0 at -0.2 m/s per step: 0.3, 0.1, 0.0."""
    smoother = VelocitySmoother(PARAMS)
    smoother.on_command((0.5, 0.0, 0.0), 0.0)
    run(smoother, 0.1, 5)
    smoother.on_command((0.0, 0.0, 0.0), 0.6)
    assert run(smoother, 0.6, 3) == approx([(0.3, 0.0, 0.0), (0.1, 0.0, 0.0), (0.0, 0.0, 0.0)])


def test_reversing_decelerates_through_zero_then_accelerates():
    """0.2 -> -0.2 m/s: a sign change is deceleration (0.2/step) then acceleration (0.1/step)."""
    smoother = VelocitySmoother(PARAMS)
    smoother.on_command((0.2, 0.0, 0.0), 0.0)
    run(smoother, 0.1, 2)
    smoother.on_command((-0.2, 0.0, 0.0), 0.3)
    assert run(smoother, 0.3, 3) == approx([(0.0, 0.0, 0.0), (-0.1, 0.0, 0.0),
                                            (-0.2, 0.0, 0.0)])


def test_scaling_keeps_the_direction_of_motion():
    """
    Target (0.4, 0.4, 0): y allows 0.05 of 0.4 (eta 0.125), x would allow 0.1 (0.25).

    With scale_velocities both move by 0.05 per step (45 degrees kept); without, x
    moves 0.1 and y 0.05 (the direction bends toward x).
    """
    scaled = VelocitySmoother(PARAMS)
    scaled.on_command((0.4, 0.4, 0.0), 0.0)
    twists = run(scaled, 0.1, 8, (0.4, 0.4, 0.0))
    assert twists == approx([(0.05 * k, 0.05 * k, 0.0) for k in range(1, 9)])
    unscaled = VelocitySmoother(SmootherParams(**{**PARAMS.__dict__, 'scale_velocities': False}))
    unscaled.on_command((0.4, 0.4, 0.0), 0.0)
    assert run(unscaled, 0.1, 2) == approx([(0.1, 0.05, 0.0), (0.2, 0.1, 0.0)])


def test_scaling_couples_rotation_and_translation():
    """Target (0.4, 0, 2.0): wz allows 0.1 of 2.0 (eta 0.05) -> (0.02, 0, 0.1) per step."""
    smoother = VelocitySmoother(PARAMS)
    smoother.on_command((0.4, 0.0, 2.0), 0.0)
    assert run(smoother, 0.1, 2) == approx([(0.02, 0.0, 0.1), (0.04, 0.0, 0.2)])


def test_velocity_limits_clamp_the_target():
    """Target vx 2.0 (limit 0.8) and wz -5 (limit -2.5): the output settles on the limits."""
    smoother = VelocitySmoother(SmootherParams(**{**PARAMS.__dict__,
                                                  'scale_velocities': False}))
    smoother.on_command((2.0, 0.0, -5.0), 0.0)
    twists = run(smoother, 0.1, 30, (2.0, 0.0, -5.0))
    assert twists[-1] == pytest.approx((0.8, 0.0, -2.5))
    assert max(t[0] for t in twists) == pytest.approx(0.8)


def test_timeout_ramps_to_zero_then_stops_publishing():
    """velocity_timeout 0.5 s: after it, decelerate to zero, then publish nothing."""
    smoother = VelocitySmoother(PARAMS)
    smoother.on_command((0.3, 0.0, 0.0), 0.0)
    run(smoother, 0.1, 3)                                   # 0.1, 0.2, 0.3 at t 0.1..0.3
    assert smoother.update(0.5).status == STATUS_OK          # 0.5 s: not yet
    outputs = [smoother.update(t) for t in (0.6, 0.7, 0.8)]
    assert [o.twist for o in outputs] == approx([(0.1, 0.0, 0.0), (0.0, 0.0, 0.0),
                                                 (0.0, 0.0, 0.0)])
    assert [o.status for o in outputs] == [STATUS_TIMEOUT, STATUS_TIMEOUT, STATUS_STOPPED]
    assert [o.publish for o in outputs] == [True, True, False]
    smoother.on_command((0.1, 0.0, 0.0), 0.9)                # a new command resumes
    output = smoother.update(0.9)
    assert (output.twist, output.status, output.publish) == ((0.1, 0.0, 0.0), STATUS_OK, True)


@pytest.mark.parametrize('bad, axis', [((math.nan, 0.0, 0.0), 'linear.x is nan'),
                                       ((0.1, math.inf, 0.0), 'linear.y is inf'),
                                       ((0.1, 0.0, -math.inf), 'angular.z is -inf')])
def test_non_finite_commands_are_rejected_as_zero(bad, axis):
    """A NaN/inf command returns its reason and counts as zero: the output ramps down."""
    smoother = VelocitySmoother(PARAMS)
    smoother.on_command((0.3, 0.0, 0.0), 0.0)
    run(smoother, 0.1, 3)
    reason = smoother.on_command(bad, 0.4)
    assert axis in reason
    assert run(smoother, 0.4, 2) == approx([(0.1, 0.0, 0.0), (0.0, 0.0, 0.0)])
    assert 'must be 3 numbers' in smoother.on_command((0.1, 0.2), 0.6)


def test_deadband_zeroes_small_outputs_but_keeps_the_state():
    """Deadband 0.15 on x: 0.1 is published as 0, the next step (0.2) as 0.2."""
    smoother = VelocitySmoother(SmootherParams(**{**PARAMS.__dict__,
                                                  'deadband_velocity': (0.15, 0.0, 0.0)}))
    smoother.on_command((0.5, 0.0, 0.0), 0.0)
    assert run(smoother, 0.1, 2) == approx([(0.0, 0.0, 0.0), (0.2, 0.0, 0.0)])
    assert smoother.last_output == pytest.approx((0.2, 0.0, 0.0))


def test_closed_loop_ramps_from_the_measured_twist():
    """CLOSED_LOOP: from measured 0.05 the next output is 0.15; bad feedback -> last output."""
    smoother = VelocitySmoother(SmootherParams(**{**PARAMS.__dict__,
                                                  'feedback': 'CLOSED_LOOP'}))
    smoother.on_command((0.5, 0.0, 0.0), 0.0)
    assert smoother.update(0.1, (0.05, 0.0, 0.0)).twist == pytest.approx((0.15, 0.0, 0.0))
    assert smoother.update(0.2, (0.05, 0.0, 0.0)).twist == pytest.approx((0.15, 0.0, 0.0))
    output = smoother.update(0.3, (math.nan, 0.0, 0.0))
    assert output.twist == pytest.approx((0.25, 0.0, 0.0))
    assert 'CLOSED_LOOP needs a finite measured twist' in output.warning
