"""robot_controller's checks of its run-time parameters (plain functions, no ROS)."""

from dataclasses import replace

import pytest
from robot_controller.command_parser import CommandLimits
from robot_controller.robot_control_node import blocked_detector, check_command_limits


def test_the_default_limits_pass():
    assert check_command_limits(CommandLimits()) == CommandLimits()


@pytest.mark.parametrize('changes, message', [
    ({'linear_speed_mps': -1.0}, 'parameter linear_speed_mps must be > 0, got -1.0'),
    ({'max_duration_s': 0.0}, 'parameter max_duration_s must be > 0, got 0.0'),
    ({'angular_speed_radps': float('nan')},
     'parameter angular_speed_radps must be finite, got nan'),
    ({'linear_speed_mps': 0.6},
     r'parameter linear_speed_mps \(0.6\) must be <= max_linear_speed_mps \(0.5\)'),
    ({'max_angular_speed_radps': 0.4},
     r'parameter angular_speed_radps \(0.5\) must be <= max_angular_speed_radps \(0.4\)'),
    ({'default_duration_s': 61.0},
     r'parameter default_duration_s \(61\) must be <= max_duration_s \(60\)'),
])
def test_bad_limits_are_refused_naming_the_parameter(changes, message):
    with pytest.raises(ValueError, match=f'^{message}$'):
        check_command_limits(replace(CommandLimits(), **changes))


def test_the_stop_short_settings_are_checked_together():
    values = {'blocked_speed_ratio': 0.1, 'blocked_time_s': 0.5, 'chain_start_timeout_s': 5.0}
    detector = blocked_detector(values)
    assert (detector.blocked_speed_ratio, detector.blocked_time_s,
            detector.start_timeout_s) == (0.1, 0.5, 5.0)
    with pytest.raises(ValueError, match=r'^parameter blocked_speed_ratio must be within'):
        blocked_detector(dict(values, blocked_speed_ratio=1.5))
    # The detector calls it start_timeout_s; the parameter is chain_start_timeout_s.
    with pytest.raises(ValueError, match=r'^parameter chain_start_timeout_s must be finite '
                                         r'and >= blocked_time_s \(6.0\), got 5.0$'):
        blocked_detector(dict(values, blocked_time_s=6.0))
    assert blocked_detector(dict(values, blocked_time_s=6.0,
                                 chain_start_timeout_s=6.0)).blocked_time_s == 6.0
