"""Tests of mecanum_control.log_throttle.KeyedThrottle."""

from mecanum_control.log_throttle import KeyedThrottle
import pytest


def test_each_key_has_its_own_period():
    now = [0.0]
    throttle = KeyedThrottle(5.0, clock=lambda: now[0])
    assert throttle.ready('odom') and throttle.ready('imu')
    now[0] = 4.9
    assert not throttle.ready('odom') and not throttle.ready('imu')
    now[0] = 5.0
    assert throttle.ready('odom')
    now[0] = 6.0
    assert throttle.ready('imu') and not throttle.ready('odom')


def test_bad_periods_are_refused():
    for period in (-1.0, float('nan'), float('inf')):
        with pytest.raises(ValueError, match='period_s'):
            KeyedThrottle(period)
