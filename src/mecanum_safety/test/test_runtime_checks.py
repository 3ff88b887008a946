"""The safety nodes' checks of their run-time parameters (plain functions, no ROS)."""

from mecanum_safety.collision_monitor import Zone
from mecanum_safety.collision_monitor_node import source_checks, zone_parameter_error
from mecanum_safety.zone_guard_node import localisation_jumps, pose_timeout
import pytest

CHECKS = {'source_timeout': 1.0, 'min_valid_beam_fraction': 0.5, 'max_identical_scans': 5,
          'max_future_stamp_s': 0.1}


def test_source_checks_are_those_of_the_collision_monitor():
    monitor = source_checks(CHECKS)
    assert (monitor.source_timeout, monitor.min_valid_beam_fraction,
            monitor.max_identical_scans, monitor.max_future_stamp_s) == (1.0, 0.5, 5, 0.1)
    for name, value, message in (
            ('source_timeout', 0.0, 'source_timeout must be finite and > 0, got 0.0'),
            ('min_valid_beam_fraction', 1.5,
             'min_valid_beam_fraction must be finite and >= 0 and <= 1, got 1.5'),
            ('max_identical_scans', -1, 'max_identical_scans must be an integer >= 0'),
            ('max_future_stamp_s', 'x', "max_future_stamp_s must be a number, got 'x'")):
        with pytest.raises(ValueError, match=f'^parameter {message}'):
            source_checks(dict(CHECKS, **{name: value}))


def test_a_zone_error_names_the_parameter():
    with pytest.raises(ValueError) as caught:
        Zone('PolygonLimit', 'limit', radius=0.35, linear_limit=-0.1)
    assert str(zone_parameter_error('PolygonLimit', caught.value)) == (
        'parameter PolygonLimit.linear_limit must be finite and >= 0, got -0.1')


def test_zone_guard_checks():
    assert pose_timeout('pose_timeout_s', 0.5) == 0.5
    with pytest.raises(ValueError, match=r'^parameter pose_timeout_s must be a finite number '
                                         r'> 0, got 0.0$'):
        pose_timeout('pose_timeout_s', 0.0)
    values = {'max_localisation_jump_m': 0.5, 'max_localisation_jump_rad': 0.5,
              'initial_pose_grace_s': 5.0}
    assert localisation_jumps(values).grace_s == 5.0
    with pytest.raises(ValueError, match=r'^parameter max_localisation_jump_m must be > 0'):
        localisation_jumps(dict(values, max_localisation_jump_m=0.0))
