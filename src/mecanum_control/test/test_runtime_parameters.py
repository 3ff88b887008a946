"""Decisions of mecanum_control.runtime_parameters, without ROS: cases worked out by hand."""

from array import array

from mecanum_control.parameters import positive, robot_config_read_only_reason
from mecanum_control.runtime_parameters import (
    change_text, DEFAULT_REASON, JointRule, plan_update, read_only_reason, reason_text,
    RuntimeParameter)
import pytest

SPEED = RuntimeParameter('speed_mps', float, positive)
COUNT = RuntimeParameter('count', int)
FRAME_REASON = 'wired up at start-up; restart'
READ_ONLY = {'frame': FRAME_REASON}


def low_high(values):
    """Joint rule of the cases: high must be >= low."""
    if values['high'] < values['low']:
        raise ValueError(f"parameter high ({values['high']:g}) must be >= low "
                         f"({values['low']:g})")


LOW, HIGH = RuntimeParameter('low'), RuntimeParameter('high')
BOUNDS = JointRule(('low', 'high'), check=low_high)
PARAMETERS = {p.name: p for p in (SPEED, COUNT, LOW, HIGH)}
VALUES = {'speed_mps': 0.2, 'count': 5, 'low': 1.0, 'high': 2.0}


def plan(*requests):
    return plan_update(list(requests), PARAMETERS, VALUES, READ_ONLY, [BOUNDS])


def test_a_valid_value_is_taken_and_changes_only_it():
    update = plan(('speed_mps', 0.3))
    assert update.successful and update.reason == ''
    assert update.changes == (('speed_mps', 0.2, 0.3),)
    assert update.values == dict(VALUES, speed_mps=0.3)
    assert update.rules == ()
    assert VALUES['speed_mps'] == 0.2   # the current values are not touched


def test_values_are_converted_as_at_start_up():
    # ros2 param set speed_mps 1 sends an integer; count 7.0 a double.
    assert plan(('speed_mps', 1)).changes == (('speed_mps', 0.2, 1.0),)
    assert isinstance(plan(('speed_mps', 1)).values['speed_mps'], float)
    assert plan(('count', 7.0)).changes == (('count', 5, 7),)


@pytest.mark.parametrize('requests, reason', [
    ((('speed_mps', -1.0),), 'speed_mps must be finite and > 0, got -1.0'),
    ((('speed_mps', float('inf')),), 'speed_mps must be finite and > 0, got inf'),
    ((('speed_mps', 'fast'),), "speed_mps must be a number, got 'fast'"),
    ((('speed_mps', True),), 'speed_mps must be a number, got True'),
    ((('count', 2.5),), 'count must be an integer, got 2.5'),
    ((('speed_mps', None),), 'speed_mps cannot be unset'),
    ((('frame', 'odom'),), f'frame is read-only: {FRAME_REASON}'),
    ((('low', 3.0),), 'high (2) must be >= low (3)'),
])
def test_an_invalid_set_is_refused_with_the_reason(requests, reason):
    update = plan(*requests)
    assert not update.successful
    assert update.reason == reason
    assert update.changes == () and update.values == VALUES


def test_one_bad_parameter_refuses_the_whole_set():
    # Valid speed first, then a read-only one, or an invalid count: nothing changes.
    for bad in (('frame', 'odom'), ('count', 'x')):
        update = plan(('speed_mps', 0.3), bad)
        assert not update.successful and update.changes == ()
        assert update.values['speed_mps'] == 0.2


def test_a_joint_rule_judges_the_values_after_the_whole_set():
    # low 3 alone breaks high >= low; with high 4 in the same set it does not.
    update = plan(('low', 3.0), ('high', 4.0))
    assert update.successful
    assert update.changes == (('low', 1.0, 3.0), ('high', 2.0, 4.0))
    assert update.rules == (BOUNDS,)
    # Lowering high below the current low is refused, raising it is fine.
    assert plan(('high', 0.5)).reason == 'high (0.5) must be >= low (1)'
    assert plan(('high', 5.0)).rules == (BOUNDS,)
    # A rule none of whose parameters is set is not asked.
    assert plan(('speed_mps', 0.3)).rules == ()


def test_use_sim_time_and_parameters_declared_later_are_left_to_rclpy():
    update = plan(('use_sim_time', True), ('declared_later', 3))
    assert update.successful and update.changes == () and update.values == VALUES


def test_an_unchanged_value_is_accepted_and_changes_nothing():
    update = plan(('speed_mps', 0.2), ('low', 1))
    assert update.successful and update.changes == () and update.rules == ()


def test_a_parameter_set_twice_in_one_call_takes_the_last_value():
    assert plan(('speed_mps', 0.3), ('speed_mps', 0.4)).changes == (
        ('speed_mps', 0.2, 0.4),)


def test_rclpy_arrays_are_taken_as_lists():
    # rclpy gives a double array as array('d', ...): logged and checked as a list.
    velocity = RuntimeParameter('max_velocity', None)
    update = plan_update([('max_velocity', array('d', [0.3, 0.2, 1.0]))],
                         {'max_velocity': velocity}, {'max_velocity': [0.8, 0.6, 2.5]}, {})
    assert update.changes == (('max_velocity', [0.8, 0.6, 2.5], [0.3, 0.2, 1.0]),)
    assert change_text(update.changes) == 'max_velocity [0.8, 0.6, 2.5] -> [0.3, 0.2, 1.0]'
    assert plan_update([('max_velocity', array('d', [0.8, 0.6, 2.5]))],
                       {'max_velocity': velocity}, {'max_velocity': [0.8, 0.6, 2.5]},
                       {}).changes == ()


def test_validate_at_start_up_and_the_check_s_returned_value():
    # kind None: any value, also none (the check or a joint rule decides).
    assert RuntimeParameter('min_velocity', None).validate(None) is None
    with pytest.raises(ValueError, match='parameter speed_mps must be set'):
        SPEED.validate(None)
    # A check returning a value replaces it; returning None keeps the value.
    assert RuntimeParameter('name', str, lambda n, v: v.strip()).validate(' map ') == 'map'
    assert RuntimeParameter('name', str, lambda n, v: None).validate(' map ') == ' map '


def test_read_only_reasons():
    reasons = (('zone_file', 'restart to change the zone'), ('scan.*', 'a source'),
               ('*.enabled', 'never reached for scan.enabled'))
    assert read_only_reason('zone_file', reasons) == 'restart to change the zone'
    assert read_only_reason('scan.enabled', reasons) == 'a source'   # first match wins
    assert read_only_reason('Stop.enabled', reasons) == 'never reached for scan.enabled'
    assert read_only_reason('wheel_radius_m') == robot_config_read_only_reason(
        'wheel_radius_m')
    assert read_only_reason('wheel_radius_m') == (
        "the robot's geometry from motor_params.yaml, shared by the controller, the "
        'simulator and the firmware; edit the file and restart')
    assert 'twist_mux' in read_only_reason('max_velocity_x_m_s')
    assert 'drive train' in read_only_reason('gear_ratio')
    assert 'rclpy' in read_only_reason('start_type_description_service')
    assert 'rclpy' in read_only_reason('qos_overrides./cmd_vel.publisher.depth')
    assert read_only_reason('something_else', reasons) == DEFAULT_REASON


def test_log_and_reason_texts():
    assert change_text([('linear_speed_mps', 0.2, 0.3)]) == 'linear_speed_mps 0.2 -> 0.3'
    assert change_text([('blocked_time_s', 0.5, 1.0), ('chain_start_timeout_s', 5.0, 6.0),
                        ('frame', 'map', 'odom'), ('flag', False, True)]) == (
        "blocked_time_s 0.5 -> 1.0, chain_start_timeout_s 5.0 -> 6.0, frame 'map' -> 'odom', "
        'flag False -> True')
    assert reason_text(ValueError('parameter x must be > 0, got -1')) == (
        'x must be > 0, got -1')
    assert reason_text(ValueError('PidGains.kp must be >= 0')) == 'PidGains.kp must be >= 0'
