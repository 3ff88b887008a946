"""Tests of mecanum_control.robot_config against the real motor_params.yaml and bad input."""

import math
from pathlib import Path

from mecanum_control.robot_config import (
    load_robot_config, PARAMETER_KINDS, parameters_from_yaml, robot_config_from_parameters,
    RobotConfigError)
import pytest

MOTOR_PARAMS = Path(__file__).resolve().parents[1] / 'config' / 'motor_params.yaml'

NUMERIC_PARAMETERS = sorted(name for name, kind in PARAMETER_KINDS.items()
                            if kind in ('float', 'int'))
OFFSET_PARAMETERS = sorted(name for name, kind in PARAMETER_KINDS.items() if kind == 'offset')

# Bad values for every numeric parameter, and why they are bad.
BAD_NUMBERS = [
    pytest.param(-1.0, id='negative'),
    pytest.param(-3, id='negative-int'),
    pytest.param(0, id='zero-int'),
    pytest.param(0.0, id='zero'),
    pytest.param(float('nan'), id='nan'),
    pytest.param(float('inf'), id='inf'),
    pytest.param(float('-inf'), id='minus-inf'),
    pytest.param(True, id='bool-true'),
    pytest.param(False, id='bool-false'),
    pytest.param('0.5', id='string'),
    pytest.param([1.0], id='list'),
]


def valid_parameters():
    """
    Return a complete, valid parameter mapping written out by hand.

    The values differ from motor_params.yaml on purpose, so the tests do not depend on it.
    """
    return {
        'wheel_radius_m': 0.05,
        'half_wheelbase_m': 0.10,
        'half_track_m': 0.15,
        'wheel_joint_names': ['fl_joint', 'fr_joint', 'rl_joint', 'rr_joint'],
        'robot_mass_kg': 5.0,
        'robot_yaw_inertia_kg_m2': 0.08,
        'footprint_radius_m': 0.25,
        'wheel_friction_coefficient': 0.5,
        'chassis_length_m': 0.35,
        'chassis_width_m': 0.2,
        'chassis_height_m': 0.07,
        'wheel_width_m': 0.04,
        'lidar_mount_x_m': -0.02,
        'lidar_mount_y_m': 0.01,
        'lidar_mount_z_m': 0.15,
        'lidar_mount_yaw_rad': math.pi,
        'imu_mount_z_m': 0.0,
        'encoder_counts_per_motor_rev': 64,
        'gear_ratio': 50.0,
        'motor_no_load_speed_rad_s': 30.0,
        'motor_time_constant_s': 0.1,
        'max_wheel_speed_rad_s': 25.0,
        'max_velocity_x_m_s': 1.0,
        'max_velocity_y_m_s': 0.7,
        'max_angular_velocity_rad_s': 3.0,
        'max_acceleration_x_m_s2': 2.0,
        'max_acceleration_y_m_s2': 2.0,
        'max_angular_acceleration_rad_s2': 6.0,
        'board_command_timeout_ms': 200,
    }


def with_value(name, value):
    """Return the valid parameters with one entry replaced."""
    values = valid_parameters()
    values[name] = value
    return values


# ----------------------------------------------------------------- the real file


def test_real_motor_params_file_loads():
    """The shipped motor_params.yaml is valid and says 44 counts x 30:1 = 1320 counts/rev."""
    config = load_robot_config(MOTOR_PARAMS)
    assert config.encoder_counts_per_motor_rev == 44
    assert isinstance(config.encoder_counts_per_motor_rev, int)
    assert config.gear_ratio == 30.0
    assert config.counts_per_wheel_rev == 1320
    # 2 * pi / 1320 = 6.283185307179586 / 1320 = 0.0047599888690754...
    assert config.rad_per_count == pytest.approx(0.0047599888690754, rel=1e-12)
    assert len(config.wheel_joint_names) == 4
    assert len(set(config.wheel_joint_names)) == 4
    assert config.geometry.wheel_radius_m > 0.0
    assert isinstance(config.board_command_timeout_ms, int)
    assert 0 < config.board_command_timeout_ms <= 65535


def test_real_file_sets_every_parameter():
    """Every known parameter is written in the real file (none relies on a default)."""
    params = parameters_from_yaml(MOTOR_PARAMS)
    assert sorted(PARAMETER_KINDS) == sorted(name for name in params if name in PARAMETER_KINDS)


# ------------------------------------------------------ robot_config_from_parameters


def test_valid_parameters_build_the_config():
    """A hand-written mapping gives the config with the derived values worked by hand."""
    config = robot_config_from_parameters(valid_parameters())
    assert config.geometry.wheel_radius_m == 0.05
    assert config.geometry.half_wheelbase_m == 0.10
    assert config.geometry.half_track_m == 0.15
    assert config.geometry.rotation_arm_m == pytest.approx(0.25)  # 0.10 + 0.15
    assert config.wheel_joint_names == ('fl_joint', 'fr_joint', 'rl_joint', 'rr_joint')
    # 64 counts per motor turn x 50:1 = 3200 counts per wheel turn.
    assert config.counts_per_wheel_rev == 3200
    # 2 * pi / 3200 = 0.0019634954084936...
    assert config.rad_per_count == pytest.approx(0.0019634954084936, rel=1e-12)
    assert config.board_command_timeout_ms == 200
    assert config.max_velocity_y_m_s == 0.7


def test_integer_valued_numbers_are_accepted_for_both_kinds():
    """YAML may give 30 for a float and 64.0 for an int: both are converted."""
    values = valid_parameters()
    values['gear_ratio'] = 30
    values['encoder_counts_per_motor_rev'] = 64.0
    config = robot_config_from_parameters(values)
    assert config.gear_ratio == 30.0 and isinstance(config.gear_ratio, float)
    assert config.encoder_counts_per_motor_rev == 64
    assert isinstance(config.encoder_counts_per_motor_rev, int)


@pytest.mark.parametrize('name', sorted(PARAMETER_KINDS))
def test_missing_parameter_is_named(name):
    """Each parameter left out raises RobotConfigError naming that parameter."""
    values = valid_parameters()
    del values[name]
    with pytest.raises(RobotConfigError, match=name):
        robot_config_from_parameters(values)


@pytest.mark.parametrize('name', sorted(PARAMETER_KINDS))
def test_parameter_set_to_none_is_named(name):
    """A parameter declared but not set (None, as from ROS) is reported like a missing one."""
    with pytest.raises(RobotConfigError, match=name):
        robot_config_from_parameters(with_value(name, None))


@pytest.mark.parametrize('value', BAD_NUMBERS)
@pytest.mark.parametrize('name', NUMERIC_PARAMETERS)
def test_bad_numbers_are_rejected(name, value):
    """Non-positive, non-finite, boolean and non-numeric values are rejected by name."""
    with pytest.raises(RobotConfigError, match=name):
        robot_config_from_parameters(with_value(name, value))


@pytest.mark.parametrize('value', [
    pytest.param(float('nan'), id='nan'), pytest.param(float('inf'), id='inf'),
    pytest.param(True, id='bool'), pytest.param('0.1', id='string'),
    pytest.param(None, id='none')])
@pytest.mark.parametrize('name', OFFSET_PARAMETERS)
def test_bad_offsets_are_rejected(name, value):
    """Mount offsets may be zero or negative but must be finite numbers."""
    with pytest.raises(RobotConfigError, match=name):
        robot_config_from_parameters(with_value(name, value))


@pytest.mark.parametrize('name', OFFSET_PARAMETERS)
def test_offsets_may_be_zero_or_negative(name):
    """A sensor behind, right of or below base_link's origin is valid."""
    for value in (0, 0.0, -0.1):
        config = robot_config_from_parameters(with_value(name, value))
        assert getattr(config, name) == value


@pytest.mark.parametrize('value', [3.2, -3.2])
def test_lidar_yaw_must_be_within_pi(value):
    """A mount yaw beyond +-pi is a typo (degrees?) and is rejected."""
    with pytest.raises(RobotConfigError, match='lidar_mount_yaw_rad'):
        robot_config_from_parameters(with_value('lidar_mount_yaw_rad', value))


@pytest.mark.parametrize('value', [44.5, 0.5, 1e-9])
@pytest.mark.parametrize('name', ['encoder_counts_per_motor_rev', 'board_command_timeout_ms'])
def test_integer_parameters_reject_fractions(name, value):
    """Integer parameters reject non-integer numbers."""
    with pytest.raises(RobotConfigError, match=name):
        robot_config_from_parameters(with_value(name, value))


@pytest.mark.parametrize('names', [
    pytest.param(['a', 'b', 'c'], id='three'),
    pytest.param(['a', 'b', 'c', 'd', 'e'], id='five'),
    pytest.param([], id='empty-list'),
    pytest.param(['a', 'b', 'c', 'a'], id='duplicate'),
    pytest.param(['a', '', 'c', 'd'], id='empty-name'),
    pytest.param(['a', 'b', 'c', 4], id='not-a-string'),
    pytest.param(['a', 'b', 'c', None], id='none-name'),
    pytest.param('abcd', id='string-not-list'),
    pytest.param({'a': 1, 'b': 2, 'c': 3, 'd': 4}, id='mapping'),
    pytest.param(4, id='number'),
])
def test_wheel_joint_names_must_be_four_distinct_names(names):
    """wheel_joint_names must be a list of 4 distinct non-empty strings."""
    with pytest.raises(RobotConfigError, match='wheel_joint_names'):
        robot_config_from_parameters(with_value('wheel_joint_names', names))


def test_wheel_joint_names_tuple_is_accepted():
    """A tuple of names is as good as a list."""
    config = robot_config_from_parameters(with_value('wheel_joint_names', ('a', 'b', 'c', 'd')))
    assert config.wheel_joint_names == ('a', 'b', 'c', 'd')


def test_command_timeout_must_fit_16_bits():
    """board_command_timeout_ms goes into a u16 field: 65535 is the largest allowed."""
    config = robot_config_from_parameters(with_value('board_command_timeout_ms', 65535))
    assert config.board_command_timeout_ms == 65535
    with pytest.raises(RobotConfigError, match='board_command_timeout_ms'):
        robot_config_from_parameters(with_value('board_command_timeout_ms', 65536))


def test_robot_config_error_is_a_value_error():
    """Callers catching ValueError also catch configuration errors."""
    assert issubclass(RobotConfigError, ValueError)


# ------------------------------------------------------------------ YAML files


def write_params_file(directory, parameters):
    """Write a ROS parameter file with a /** section holding parameters; return its path."""
    lines = ['/**:', '  ros__parameters:']
    for name, value in parameters.items():
        if isinstance(value, list):
            lines.append(f'    {name}:')
            lines.extend(f'    - {item}' for item in value)
        else:
            lines.append(f'    {name}: {value}')
    path = directory / 'motor_params.yaml'
    path.write_text('\n'.join(lines) + '\n')
    return path


def test_written_file_round_trips(tmp_path):
    """A valid file written by hand loads with the same values."""
    config = load_robot_config(write_params_file(tmp_path, valid_parameters()))
    assert config == robot_config_from_parameters(valid_parameters())


@pytest.mark.parametrize('text', [
    pytest.param('/**:\n  ros__parameters: [unclosed\n', id='syntax-error'),
    pytest.param('/**:\n\tros__parameters: {}\n', id='tab-indent'),
    pytest.param('- just\n- a list\n', id='not-a-mapping'),
    pytest.param('42\n', id='scalar'),
    pytest.param('', id='empty-file'),
    pytest.param('motor_node:\n  ros__parameters:\n    wheel_radius_m: 0.05\n',
                 id='no-wildcard-section'),
    pytest.param('/**:\n  parameters:\n    wheel_radius_m: 0.05\n', id='no-ros__parameters'),
    pytest.param('/**:\n  ros__parameters:\n', id='empty-ros__parameters'),
    pytest.param('/**:\n  ros__parameters:\n  - wheel_radius_m\n', id='ros__parameters-list'),
    pytest.param('/**: 3\n', id='section-not-mapping'),
])
def test_malformed_yaml_names_the_file(tmp_path, text):
    """Unreadable or wrongly shaped parameter files raise RobotConfigError with the path."""
    path = tmp_path / 'bad_params.yaml'
    path.write_text(text)
    with pytest.raises(RobotConfigError) as info:
        load_robot_config(path)
    assert str(path) in str(info.value)


def test_missing_file_names_the_file(tmp_path):
    """A file that does not exist raises RobotConfigError (not OSError) with the path."""
    path = tmp_path / 'does_not_exist.yaml'
    with pytest.raises(RobotConfigError) as info:
        load_robot_config(path)
    assert str(path) in str(info.value)


def test_directory_instead_of_file_names_the_path(tmp_path):
    """A directory given as the file raises RobotConfigError with the path."""
    with pytest.raises(RobotConfigError) as info:
        load_robot_config(tmp_path)
    assert str(tmp_path) in str(info.value)


@pytest.mark.parametrize('name, text', [
    ('wheel_radius_m', '-0.05'),
    ('half_track_m', '.nan'),
    ('gear_ratio', '.inf'),
    ('encoder_counts_per_motor_rev', '.inf'),
    ('board_command_timeout_ms', '.nan'),
    ('encoder_counts_per_motor_rev', '44.5'),
    ('max_velocity_x_m_s', 'true'),
    ('max_velocity_y_m_s', 'fast'),
    ('board_command_timeout_ms', '70000'),
])
def test_bad_value_in_file_names_file_and_parameter(tmp_path, name, text):
    """A bad value in a file is reported with both the file and the parameter name."""
    values = valid_parameters()
    values[name] = text  # written verbatim into the YAML
    path = write_params_file(tmp_path, values)
    with pytest.raises(RobotConfigError) as info:
        load_robot_config(path)
    assert str(path) in str(info.value)
    assert name in str(info.value)


def test_missing_value_in_file_names_file_and_parameter(tmp_path):
    """A parameter left out of the file is reported with the file and its name."""
    values = valid_parameters()
    del values['motor_time_constant_s']
    path = write_params_file(tmp_path, values)
    with pytest.raises(RobotConfigError) as info:
        load_robot_config(path)
    assert str(path) in str(info.value)
    assert 'motor_time_constant_s' in str(info.value)


def test_rad_per_count_is_one_turn_over_counts():
    """Hand check of the derived property with an easy gear: 100 counts x 10 -> 2*pi/1000."""
    values = valid_parameters()
    values['encoder_counts_per_motor_rev'] = 100
    values['gear_ratio'] = 10.0
    config = robot_config_from_parameters(values)
    assert config.counts_per_wheel_rev == 1000
    # 2 * pi / 1000 = 0.006283185307179586
    assert config.rad_per_count == pytest.approx(0.006283185307179586, rel=1e-12)
    assert 1000 * config.rad_per_count == pytest.approx(2 * math.pi)
