"""Hand-worked and property tests of mecanum_control.command_limits."""

import math

from hypothesis import given, strategies as st
from mecanum_control.command_limits import (
    AxisLimits, CommandRejected, CommandWatchdog, EmergencyStop, limit_scale, limit_twist,
    MotorCommandCore, RateLimiter, TwistLimits, validate_twist)
from mecanum_control.kinematics import forward_kinematics, inverse_kinematics, MecanumGeometry
from mecanum_control.robot_config import default_config_path, load_robot_config
import pytest

# r = 0.05 m, lx = 0.10 m, ly = 0.15 m: 1 rad/s of yaw is (lx + ly) / r = 5 rad/s per wheel,
# 0.1 m/s of translation is 2 rad/s.
GEOMETRY = MecanumGeometry(wheel_radius_m=0.05, half_wheelbase_m=0.10, half_track_m=0.15)
LIMITS = TwistLimits(x=AxisLimits(1.0, 2.0), y=AxisLimits(0.5, 1.0), wz=AxisLimits(2.0, 4.0))
NO_ACCEL_LIMIT = TwistLimits(x=AxisLimits(1.0, math.inf), y=AxisLimits(0.5, math.inf),
                             wz=AxisLimits(2.0, math.inf))
DT = 0.1


def make_core(limits=LIMITS, max_wheel=30.0, timeout=0.5):
    """Return a MotorCommandCore on the test geometry."""
    return MotorCommandCore(GEOMETRY, limits, max_wheel, timeout)


# --- limits validation ------------------------------------------------------------

@pytest.mark.parametrize('velocity, acceleration', [
    (0.0, 1.0), (-1.0, 1.0), (math.inf, 1.0), (math.nan, 1.0),
    (1.0, 0.0), (1.0, -1.0), (1.0, math.nan)])
def test_axis_limits_reject_bad_values(velocity, acceleration):
    """Velocity finite > 0, acceleration > 0 (inf allowed)."""
    with pytest.raises(ValueError):
        AxisLimits(velocity, acceleration)


def test_axis_limits_allow_infinite_acceleration():
    """math.inf means no acceleration limit."""
    assert AxisLimits(1.0, math.inf).max_acceleration == math.inf


@pytest.mark.parametrize('factor', [0.5, math.nan, math.inf])
def test_twist_limits_reject_bad_absurd_factor(factor):
    """absurd_factor must be finite and >= 1."""
    with pytest.raises(ValueError, match='absurd_factor'):
        TwistLimits(LIMITS.x, LIMITS.y, LIMITS.wz, absurd_factor=factor)


# --- validate_twist ---------------------------------------------------------------

@pytest.mark.parametrize('index, name', [(0, 'linear.x'), (1, 'linear.y'), (2, 'angular.z')])
@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf])
def test_validate_rejects_non_finite_naming_axis(index, name, bad):
    """A nan/inf component is rejected with 'cmd_vel <axis> is <value>'."""
    twist = [0.1, 0.1, 0.1]
    twist[index] = bad
    with pytest.raises(CommandRejected, match=f'cmd_vel {name} is {bad}'):
        validate_twist(*twist, LIMITS)


@pytest.mark.parametrize('twist, name, value, bound', [
    ((10.5, 0.0, 0.0), 'linear.x', '10.5 m/s', '10 m/s'),        # 10 x 1.0 m/s
    ((0.0, -5.01, 0.0), 'linear.y', '-5.01 m/s', '5 m/s'),       # 10 x 0.5 m/s
    ((0.0, 0.0, 25.0), 'angular.z', '25 rad/s', '20 rad/s'),     # 10 x 2.0 rad/s
])
def test_validate_rejects_absurd_with_value_and_limit(twist, name, value, bound):
    """Beyond absurd_factor * max_velocity: rejected, message has the value and the bound."""
    with pytest.raises(CommandRejected) as info:
        validate_twist(*twist, LIMITS)
    message = str(info.value)
    assert message.startswith(f'cmd_vel {name} = {value} ')
    assert message.endswith(f'= {bound}')


def test_command_rejected_is_a_value_error():
    """Callers catching ValueError also catch rejections."""
    assert issubclass(CommandRejected, ValueError)


def test_validate_only_checks_and_leaves_limiting_to_limit_twist():
    """
    Accepted commands come back unchanged, over-limit ones too (up to the absurd bound).

    Clamping each axis on its own would turn the direction of motion: limiting is
    limit_twist's job, which scales the twist as a whole.
    """
    assert validate_twist(0.3, -0.2, 1.5, LIMITS) == (0.3, -0.2, 1.5)
    assert validate_twist(3.0, -0.7, 10.0, LIMITS) == (3.0, -0.7, 10.0)
    assert validate_twist(-10.0, 5.0, -20.0, LIMITS) == (-10.0, 5.0, -20.0)  # absurd bound
    assert all(isinstance(v, float) for v in validate_twist(1, 0, 0, LIMITS))


finite_twists = st.tuples(st.floats(-10.0, 10.0), st.floats(-5.0, 5.0), st.floats(-20.0, 20.0))

# --- limit_twist ------------------------------------------------------------------

#: 0.5 m/s on both linear axes, as in the hand-worked example of issue 31.
HALF = TwistLimits(x=AxisLimits(0.5, 1.0), y=AxisLimits(0.5, 1.0), wz=AxisLimits(2.0, 4.0))


def test_limit_twist_hand_worked_diagonal_keeps_45_degrees():
    """
    (0.8, 0.8, 0) with 0.5 m/s per axis: both ratios 0.5 / 0.8 = 0.625 -> (0.5, 0.5, 0).

    Its wheels: FR = RL = (0.5 + 0.5) / 0.05 = 20 rad/s, FL = RR = 0. Within 30 rad/s it
    stays; with 16 rad/s it is scaled by 16 / 20 = 0.8 -> (0.4, 0.4, 0). Per-axis
    clamping with x 1.0 and y 0.5 m/s would give (0.8, 0.5): 32 deg instead of 45.
    """
    assert limit_twist((0.8, 0.8, 0.0), HALF, GEOMETRY, 30.0) == pytest.approx((0.5, 0.5, 0.0))
    assert limit_twist((0.8, 0.8, 0.0), HALF, GEOMETRY, 16.0) == pytest.approx((0.4, 0.4, 0.0))
    assert limit_scale((0.8, 0.8, 0.0), HALF, GEOMETRY, 16.0) == pytest.approx(0.5)
    # LIMITS (x 1.0, y 0.5): y sets the ratio 0.5 / 0.8 for the whole twist.
    assert limit_twist((0.8, 0.8, 0.0), LIMITS, GEOMETRY, 30.0) == pytest.approx(
        (0.5, 0.5, 0.0))


def test_limit_twist_hand_worked_rotation_and_wheel_limit():
    """
    (0.5, 0, 2.5): wz ratio 2 / 2.5 = 0.8 -> (0.4, 0, 2.0); FR = (0.4 + 0.25 * 2) / 0.05 = 18.

    With max wheel 9 rad/s the wheels set the ratio: 0.8 * 9 / 18 = 0.4 -> (0.2, 0, 1.0).
    """
    assert limit_twist((0.5, 0.0, 2.5), LIMITS, GEOMETRY, 30.0) == pytest.approx(
        (0.4, 0.0, 2.0))
    assert limit_twist((0.5, 0.0, 2.5), LIMITS, GEOMETRY, 9.0) == pytest.approx(
        (0.2, 0.0, 1.0))
    # Within every limit: returned exactly, as floats.
    assert limit_twist((0.3, -0.2, 1), LIMITS, GEOMETRY, 30.0) == (0.3, -0.2, 1.0)
    assert limit_scale((0.0, 0.0, 0.0), LIMITS, GEOMETRY, 30.0) == 1.0


def test_limit_twist_the_robots_own_diagonal():
    """
    The robot's limits (motor_params.yaml): (0.8, 0.8, 0) -> (0.56, 0.56, 0).

    0.8 / 0.6 m/s, 28 rad/s, r 0.04 m: the y ratio 0.75 gives (0.6, 0.6, 0), whose
    wheels need 1.2 / 0.04 = 30 rad/s: times 28 / 30.
    """
    config = load_robot_config(default_config_path())
    limits = TwistLimits.from_config(config)
    assert limits.x == AxisLimits(config.max_velocity_x_m_s, config.max_acceleration_x_m_s2)
    assert limits.wz.max_velocity == config.max_angular_velocity_rad_s
    assert limit_twist((0.8, 0.8, 0.0), limits, config.geometry,
                       config.max_wheel_speed_rad_s) == pytest.approx((0.56, 0.56, 0.0))


def test_limit_twist_rejects_what_validate_twist_rejects():
    """Non-finite and absurd twists raise CommandRejected, not a scaled command."""
    with pytest.raises(CommandRejected, match='linear.y is nan'):
        limit_twist((0.1, math.nan, 0.0), LIMITS, GEOMETRY, 30.0)
    with pytest.raises(CommandRejected, match='absurd'):
        limit_scale((0.0, 0.0, 25.0), LIMITS, GEOMETRY, 30.0)
    with pytest.raises(ValueError, match='max_wheel_speed_rad_s'):
        limit_twist((0.1, 0.0, 0.0), LIMITS, GEOMETRY, 0.0)


@given(finite_twists, st.floats(5.0, 40.0))
def test_limit_twist_keeps_direction_within_limits_and_is_idempotent(twist, max_wheel):
    """Output = s * input with 0 < s <= 1, within every limit, unchanged when limited again."""
    out = limit_twist(twist, LIMITS, GEOMETRY, max_wheel)
    s = limit_scale(twist, LIMITS, GEOMETRY, max_wheel)
    assert 0.0 < s <= 1.0
    assert out == tuple(s * v for v in twist)
    for value, axis in zip(out, LIMITS.axes):
        assert abs(value) <= axis.max_velocity * (1.0 + 1e-9)
    assert max(abs(w) for w in inverse_kinematics(GEOMETRY, *out)) <= max_wheel * (1.0 + 1e-9)
    assert limit_twist(out, LIMITS, GEOMETRY, max_wheel) == out


# --- RateLimiter ------------------------------------------------------------------

def test_rate_limiter_hand_worked_ramp():
    """0 -> 1 m/s at 2 m/s^2, dt 0.1: 0.2, 0.4, 0.6, 0.8, 1.0, then stays."""
    limiter = RateLimiter(LIMITS)
    xs = [limiter.step((1.0, 0.0, 0.0), DT)[0] for _ in range(6)]
    assert xs == pytest.approx([0.2, 0.4, 0.6, 0.8, 1.0, 1.0])
    assert limiter.current == (1.0, 0.0, 0.0)
    # Braking to -0.5 m/s: the same 0.2 m/s per step, and lands exactly.
    xs = [limiter.step((-0.5, 0.0, 0.0), DT)[0] for _ in range(8)]
    assert xs == pytest.approx([0.8, 0.6, 0.4, 0.2, 0.0, -0.2, -0.4, -0.5])


def test_rate_limiter_keeps_direction_with_different_axis_limits():
    """
    Target (0.8, 0.5) m/s from rest, dt 0.1: the slower y axis sets the pace.

    x may change 0.2 m/s (ratio 0.2 / 0.8 = 0.25), y 0.1 m/s (ratio 0.1 / 0.5 = 0.2);
    the whole change is scaled by 0.2: step (0.16, 0.1), so vx / vy stays 1.6 all along
    the ramp (per-axis clipping would give (0.2, 0.1), ratio 2).
    """
    limiter = RateLimiter(LIMITS)
    assert limiter.step((0.8, 0.5, 0.0), DT) == pytest.approx((0.16, 0.1, 0.0))
    for _ in range(3):
        vx, vy, wz = limiter.step((0.8, 0.5, 0.0), DT)
        assert vx / vy == pytest.approx(1.6)
    assert (vx, vy) == pytest.approx((0.64, 0.4))
    assert limiter.step((0.8, 0.5, 0.0), DT) == pytest.approx((0.8, 0.5, 0.0))


def test_rate_limiter_ignores_bad_dt_and_resets():
    """A dt <= 0 or nan leaves it unchanged; reset() sets the twist without limiting."""
    limiter = RateLimiter(LIMITS)
    for dt in (0.0, -0.1, math.nan, math.inf):
        assert limiter.step((1.0, 0.5, 2.0), dt) == (0.0, 0.0, 0.0)
    limiter.reset((0.5, 0.1, -1.0))
    assert limiter.current == (0.5, 0.1, -1.0)
    limiter.reset()
    assert limiter.current == (0.0, 0.0, 0.0)
    with pytest.raises(ValueError):
        limiter.step((math.nan, 0.0, 0.0), DT)


@given(st.lists(st.tuples(finite_twists, st.floats(0.0, 0.5)), min_size=1, max_size=20))
def test_rate_limiter_properties(steps):
    """Each step: per-axis change <= a_max * dt, along the change vector, never past target."""
    limiter = RateLimiter(LIMITS)
    for target, dt in steps:
        before = limiter.current
        after = limiter.step(target, dt)
        deltas = [t - b for t, b in zip(target, before)]
        changes = [a - b for a, b in zip(after, before)]
        for change, axis in zip(changes, LIMITS.axes):
            assert abs(change) <= axis.max_acceleration * dt + 1e-9
        # change = s * delta with 0 <= s <= 1 (same direction, no overshoot).
        norm2 = sum(d * d for d in deltas)
        if norm2 > 1e-12:
            s = sum(c * d for c, d in zip(changes, deltas)) / norm2
            assert -1e-9 <= s <= 1.0 + 1e-9
            assert changes == pytest.approx([s * d for d in deltas], abs=1e-9)


# --- EmergencyStop and CommandWatchdog ----------------------------------------------

def test_emergency_stop_latches_and_keeps_first_reason():
    """Engaging latches until release; a second engage keeps the first reason."""
    estop = EmergencyStop()
    assert not estop.engaged and estop.reason == ''
    estop.engage('bumper')
    estop.engage('operator')
    assert estop.engaged and estop.reason == 'bumper'
    estop.release()
    assert not estop.engaged and estop.reason == ''


def test_emergency_stop_release_is_refused_while_its_input_is_pressed():
    """The input true engages; release() refuses until the input is false, then releases."""
    estop = EmergencyStop()
    estop.set_pressed(True, 'emergency_stop topic')
    assert estop.engaged and estop.pressed and estop.reason == 'emergency_stop topic'
    assert estop.release() is False
    assert estop.engaged
    estop.set_pressed(False, 'emergency_stop topic')
    assert estop.engaged and not estop.pressed          # let go: still latched
    assert estop.release() is True
    assert not estop.engaged and estop.reason == ''
    # Engaged another way (a latch file): not pressed, so it can be released.
    estop.engage('latch file')
    assert estop.release() is True


def test_watchdog_hand_worked():
    """Expired before the first feed and when now - last_feed > timeout."""
    with pytest.raises(ValueError):
        CommandWatchdog(0.0)
    dog = CommandWatchdog(0.5)
    assert dog.expired(0.0)
    dog.feed(1.0)
    assert not dog.expired(1.0)
    assert not dog.expired(1.5)
    assert dog.expired(1.51)
    assert not dog.expired(0.9)        # small backward jitter tolerated
    assert dog.expired(0.0)            # clock jumped back by more than the timeout
    dog.feed(2.0)
    assert not dog.expired(2.4)


# --- MotorCommandCore -------------------------------------------------------------

def run(core, start, stop, command=None):
    """Call update at start, start + DT, ... < stop (+ on_command first if given)."""
    outputs = []
    k = 0
    while start + k * DT < stop - 1e-9:
        now = start + k * DT
        if command is not None:
            core.on_command(*command, now)
        outputs.append(core.update(now))
        k += 1
    return outputs


def test_waiting_until_first_command():
    """No command yet: zero wheels, status 'waiting'."""
    core = make_core()
    assert core.status == 'waiting'
    assert core.update(0.0) == (0.0, 0.0, 0.0, 0.0)
    assert core.update(1.0) == (0.0, 0.0, 0.0, 0.0)
    assert core.status == 'waiting'


@pytest.mark.parametrize('twist, wheels', [
    ((0.0, 0.0, 1.0), (-5.0, 5.0, -5.0, 5.0)),        # rotate CCW: left wheels back
    ((0.2, 0.0, 0.0), (4.0, 4.0, 4.0, 4.0)),
    ((0.0, 0.1, 0.0), (-2.0, 2.0, 2.0, -2.0)),        # strafe left: FL, RR back
    ((0.2, 0.1, 1.0), (-3.0, 11.0, 1.0, 7.0)),
])
def test_output_is_inverse_kinematics_hand_worked(twist, wheels):
    """Without acceleration limits the first step gives the hand-worked wheel speeds."""
    core = make_core(NO_ACCEL_LIMIT)
    core.update(0.0)
    core.on_command(*twist, 0.0)
    assert core.update(DT) == pytest.approx(wheels)
    assert core.limited_twist == pytest.approx(twist)
    assert core.status == 'ok'


def test_output_ramps_and_equals_inverse_kinematics_of_limited_twist():
    """Pure rotation wz = 1 at 4 rad/s^2, dt 0.1: wz 0.4, 0.8, 1.0 -> FR 2, 4, 5 rad/s."""
    core = make_core()
    core.update(0.0)
    frs = []
    for k in range(1, 4):
        core.on_command(0.0, 0.0, 1.0, k * DT)
        wheels = core.update(k * DT)
        assert wheels == pytest.approx(inverse_kinematics(GEOMETRY, *core.limited_twist))
        frs.append(wheels[1])
    assert frs == pytest.approx([2.0, 4.0, 5.0])
    assert wheels == pytest.approx((-5.0, 5.0, -5.0, 5.0))


def test_desaturation_keeps_direction():
    """
    (1 m/s, 0, 2 rad/s) needs FR = RR = (1 + 0.25 * 2) / 0.05 = 30 rad/s; limit 15.

    Scaled by 1/2 as a whole: twist (0.5, 0, 1.0), wheels (10, 30, 10, 30) / 2.
    """
    core = make_core(NO_ACCEL_LIMIT, max_wheel=15.0)
    core.update(0.0)
    core.on_command(1.0, 0.0, 2.0, 0.0)
    assert core.update(DT) == pytest.approx((5.0, 15.0, 5.0, 15.0))
    assert core.limited_twist == pytest.approx((0.5, 0.0, 1.0))


@given(finite_twists, st.floats(5.0, 40.0))
def test_core_output_never_exceeds_wheel_limit_and_keeps_direction(twist, max_wheel):
    """After ramping to any command, wheels <= max and the twist is the command scaled."""
    core = make_core(max_wheel=max_wheel)
    for k in range(40):
        core.on_command(*twist, k * DT)
        wheels = core.update(k * DT)
        assert max(abs(w) for w in wheels) <= max_wheel + 1e-9
    out = forward_kinematics(GEOMETRY, wheels)
    norm2 = sum(c * c for c in twist)
    if norm2 > 1e-12:
        s = sum(o * c for o, c in zip(out, twist)) / norm2
        assert 0.0 < s <= 1.0 + 1e-9
        assert out == pytest.approx([s * c for c in twist], abs=1e-9)


def test_core_keeps_the_direction_of_an_over_limit_diagonal():
    """
    (0.8, 0.8, 0) m/s with y limited to 0.5 m/s: the target is (0.5, 0.5, 0), 45 deg.

    Per-axis clamping gave (0.8, 0.5, 0) (32 deg): the wheels ran another twist than
    the one the chain's stages had judged.
    """
    core = make_core(NO_ACCEL_LIMIT)
    core.update(0.0)
    core.on_command(0.8, 0.8, 0.0, 0.0)
    assert core.target_twist == pytest.approx((0.5, 0.5, 0.0))
    core.update(DT)
    assert core.limited_twist == pytest.approx((0.5, 0.5, 0.0))


@given(finite_twists, st.floats(5.0, 40.0))
def test_core_is_a_no_op_on_a_twist_already_limited(twist, max_wheel):
    """A twist that limit_twist already limited (twist_mux's output) is the target as is."""
    limited = limit_twist(twist, LIMITS, GEOMETRY, max_wheel)
    core = make_core(max_wheel=max_wheel)
    core.on_command(*limited, 0.0)
    assert core.target_twist == limited


def test_rejected_command_zeroes_target():
    """Garbage after a good command: CommandRejected, and the robot ramps down to zero."""
    core = make_core()
    run(core, 0.0, 0.6, command=(1.0, 0.0, 0.0))
    assert core.limited_twist == pytest.approx((1.0, 0.0, 0.0))
    with pytest.raises(CommandRejected, match='linear.y is nan'):
        core.on_command(1.0, math.nan, 0.0, 0.6)
    assert core.target_twist == (0.0, 0.0, 0.0)
    xs = [core.update(0.6 + k * DT)[0] / 20.0 for k in range(6)]   # vx = r * omega
    assert xs == pytest.approx([0.8, 0.6, 0.4, 0.2, 0.0, 0.0])
    with pytest.raises(CommandRejected, match='absurd'):
        core.on_command(0.0, 0.0, 100.0, 1.3)


def test_estop_latches_and_does_not_resume_old_command():
    """Engage: zero at once; commands ignored; release: zero until a NEW command."""
    core = make_core()
    moving = run(core, 0.0, 0.6, command=(0.5, 0.0, 0.0))
    assert moving[-1] == pytest.approx((10.0, 10.0, 10.0, 10.0))
    core.engage_estop('bumper hit')
    assert core.status == 'estop'
    assert core.state.estop_reason == 'bumper hit'
    assert core.limited_twist == (0.0, 0.0, 0.0)
    assert core.wheel_speeds == (0.0, 0.0, 0.0, 0.0)
    # Commands while engaged do not move the wheels, however long.
    assert all(w == (0.0,) * 4 for w in run(core, 0.6, 1.2, command=(0.5, 0.0, 0.0)))
    assert core.status == 'estop'
    core.release_estop()
    assert core.status == 'waiting'
    # The last command (0.5 m/s at t = 1.1) is fresh for the watchdog but NOT resumed.
    assert all(w == (0.0,) * 4 for w in run(core, 1.2, 1.5))
    assert core.status == 'waiting'
    ramp = run(core, 1.5, 2.0, command=(0.5, 0.0, 0.0))
    assert [w[0] for w in ramp] == pytest.approx([4.0, 8.0, 10.0, 10.0, 10.0])
    assert core.status == 'ok'


def test_estop_input_latches_until_let_go_and_released():
    """
    The e-stop input latches: true, then false while commands keep coming: still zero.

    A release while the input is still true is refused; after the release the output
    stays zero until a NEW command.
    """
    core = make_core()
    run(core, 0.0, 0.6, command=(0.5, 0.0, 0.0))
    assert core.set_estop_input(True) is True           # engaged just now
    assert core.set_estop_input(True) is False          # already engaged
    assert core.status == 'estop' and core.estop_pressed
    assert core.release_estop() is False                # still pressed: refused
    assert core.status == 'estop'
    assert core.set_estop_input(False) is False
    assert core.estop_engaged and not core.estop_pressed
    assert all(w == (0.0,) * 4 for w in run(core, 0.6, 1.2, command=(0.5, 0.0, 0.0)))
    assert core.status == 'estop'
    assert core.release_estop() is True
    assert core.status == 'waiting'
    assert all(w == (0.0,) * 4 for w in run(core, 1.2, 1.5))
    assert [w[0] for w in run(core, 1.5, 1.8, command=(0.5, 0.0, 0.0))] == pytest.approx(
        [4.0, 8.0, 10.0])


def test_estop_zeroes_output_on_the_very_next_update():
    """No deceleration ramp through the e-stop: the next update at the same time is zero."""
    core = make_core()
    run(core, 0.0, 0.6, command=(1.0, 0.5, 0.0))
    core.engage_estop('operator')
    assert core.update(0.6) == (0.0, 0.0, 0.0, 0.0)


def test_watchdog_timeout_ramps_down_then_fresh_command_resumes():
    """Commands stop at t = 0.5 (timeout 0.55 s): expired from t = 1.1, decel 0.2 m/s/step."""
    core = make_core(timeout=0.55)
    run(core, 0.0, 0.6, command=(1.0, 0.0, 0.0))      # last command at t = 0.5
    assert core.limited_twist == pytest.approx((1.0, 0.0, 0.0))
    held = run(core, 0.6, 1.1)                        # t = 0.6 .. 1.0: age <= 0.5
    assert all(w == pytest.approx((20.0,) * 4) for w in held)
    assert core.status == 'ok'
    ramp = run(core, 1.1, 1.8)                        # t = 1.1 .. 1.7
    assert [w[0] / 20.0 for w in ramp] == pytest.approx([0.8, 0.6, 0.4, 0.2, 0.0, 0.0, 0.0])
    assert core.status == 'timeout'
    assert core.wheel_speeds == (0.0, 0.0, 0.0, 0.0)
    resumed = run(core, 1.8, 2.1, command=(0.0, 0.5, 0.0))
    assert core.status == 'ok'
    assert [w[1] for w in resumed] == pytest.approx([2.0, 4.0, 6.0])   # vy 0.1 m/s per step


def test_core_rejects_bad_construction_and_time():
    """max_wheel_speed and timeout must be > 0; update needs a finite time."""
    with pytest.raises(ValueError):
        make_core(max_wheel=0.0)
    with pytest.raises(ValueError):
        make_core(timeout=0.0)
    with pytest.raises(ValueError):
        make_core().update(math.nan)
