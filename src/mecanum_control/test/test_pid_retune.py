"""velocity_controller's run-time gains: checks and the bumpless retune (no ROS)."""

from dataclasses import replace

from mecanum_control.pid import PidGains, StallConfig
from mecanum_control.velocity_controller import (
    GAIN_PARAMETERS, pid_gains, stall_config, TunablePidController, TunableStallDetector)
import pytest

GAINS = PidGains(kp=0.03, ki=0.3, kd=0.0, kf=1.0 / 34.5, static_effort=0.03,
                 max_effort=1.0, derivative_filter_tau_s=0.02, integral_freeze_rate_rad_s2=10.0)
DT = 0.02


def running(gains=GAINS, steps=20):
    """Return a controller that has run steps periods: target 10, measured 8 rad/s."""
    pid = TunablePidController(gains)
    for _ in range(steps):
        pid.update(10.0, 8.0, DT)
    return pid


def test_gain_parameters_are_pid_gains_fields_and_errors_name_the_parameter():
    assert GAIN_PARAMETERS == ('kp', 'ki', 'kd', 'kf', 'static_effort', 'max_effort',
                               'derivative_filter_tau_s', 'integral_freeze_rate_rad_s2')
    values = {name: getattr(GAINS, name) for name in GAIN_PARAMETERS}
    assert pid_gains(values) == GAINS
    with pytest.raises(ValueError, match=r'^parameter kp must be a finite number >= 0, '
                                         r'got -1.0$'):
        pid_gains(dict(values, kp=-1.0))
    with pytest.raises(ValueError, match=r'^parameter max_effort must be in \(0, 1\]'):
        pid_gains(dict(values, max_effort=1.5))


def test_stall_parameters_map_to_stall_config():
    values = {'stall_effort_threshold': 0.6, 'stall_velocity_threshold_rad_s': 0.5,
              'stall_time_s': 0.5, 'stall_target_threshold_rad_s': 3.0}
    assert stall_config(values) == StallConfig()
    with pytest.raises(ValueError, match=r'^parameter stall_time_s must be a finite number '
                                         r'> 0, got 0.0$'):
        stall_config(dict(values, stall_time_s=0.0))


def test_a_new_kp_does_not_step_the_effort():
    pid = running()
    # dt 0: no integration and no D term, the same inputs as the last step.
    before = pid.update(10.0, 8.0, 0.0)
    integral = pid.integral_effort
    pid.retune(replace(GAINS, kp=0.1))
    assert pid.gains.kp == 0.1
    assert pid.update(10.0, 8.0, 0.0) == pytest.approx(before, abs=1e-12)
    # The integrator took the change of the P term, 2 rad/s x (0.1 - 0.03): without
    # the transfer the effort would have stepped up by 0.14 duty.
    assert pid.integral_effort == pytest.approx(integral - 2.0 * 0.07)


def test_feedforward_and_static_effort_changes_do_not_step_the_effort_either():
    pid = running()
    before = pid.update(10.0, 8.0, 0.0)
    pid.retune(replace(GAINS, kf=0.035, static_effort=0.05))
    assert pid.update(10.0, 8.0, 0.0) == pytest.approx(before, abs=1e-12)


def test_a_new_ki_keeps_the_integral_effort():
    pid = running()
    integral = pid.integral_effort
    assert integral > 0.0
    pid.retune(replace(GAINS, ki=0.6))
    assert pid.integral_effort == integral


def test_ki_zero_clears_the_integrator():
    pid = running()
    pid.retune(replace(GAINS, ki=0.0))
    assert pid.integral_effort == 0.0


def test_the_integrator_stays_within_the_new_max_effort():
    pid = running(steps=200)
    pid.retune(replace(GAINS, kp=0.0, kf=0.0, static_effort=0.0, max_effort=0.1))
    assert abs(pid.integral_effort) <= 0.1
    assert abs(pid.update(10.0, 8.0, DT)) <= 0.1


def test_the_derivative_state_scales_with_kd():
    gains = replace(GAINS, kd=0.01)
    pid = TunablePidController(gains)
    for measured in (0.0, 1.0, 2.0, 3.0):
        pid.update(10.0, measured, DT)
    derivative = pid.derivative_effort
    assert derivative < 0.0
    pid.retune(replace(gains, kd=0.02))
    assert pid.derivative_effort == pytest.approx(2.0 * derivative)
    pid.retune(replace(gains, kd=0.0))
    assert pid.derivative_effort == 0.0


def test_a_controller_at_rest_just_takes_the_gains():
    pid = TunablePidController(GAINS)
    pid.retune(replace(GAINS, kp=0.1))
    assert pid.integral_effort == 0.0 and pid.gains.kp == 0.1
    assert pid.update(10.0, 8.0, 0.0) == pytest.approx(
        10.0 / 34.5 + 0.03 + 0.1 * 2.0)


def test_new_stall_thresholds_count_the_time_already_held_and_keep_a_latch():
    stall = TunableStallDetector(StallConfig(time_s=0.5))
    for _ in range(10):   # 0.2 s of a stalled wheel
        assert not stall.update(0.8, 0.0, 5.0, DT)
    stall.reconfigure(StallConfig(time_s=0.25))
    assert stall.config.time_s == 0.25
    assert not stall.update(0.8, 0.0, 5.0, DT)   # 0.22 s
    assert not stall.update(0.8, 0.0, 5.0, DT)   # 0.24 s
    assert stall.update(0.8, 0.0, 5.0, DT)       # 0.26 s >= 0.25 s: latched
    assert stall.condition_time_s == pytest.approx(0.26)
    stall.reconfigure(StallConfig(time_s=5.0))
    assert stall.update(0.0, 0.0, 0.0, DT)   # latched until ~/clear_wheel_faults
