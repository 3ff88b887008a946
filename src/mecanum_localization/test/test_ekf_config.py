"""mecanum_localization.ekf_config: robot_localization keys, defaults, errors, extraction."""

import math
from pathlib import Path

from mecanum_localization.ekf_config import (
    parse_ekf_config, PLANAR_FROM_RL, RL_SIZE, RL_VARIABLES)
import numpy as np
import pytest
import yaml

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'ekf.yaml'


def flags(*names):
    """Return a 15-boolean r_l update vector with the named variables set."""
    return [name in names for name in RL_VARIABLES]


def matrix(diagonal):
    """Return a row-major 15x15 r_l matrix, 225 numbers, with this diagonal."""
    return np.diag(np.array(diagonal, dtype=float)).reshape(-1).tolist()


#: A robot_localization ekf.yaml as its documentation writes it (keys, types, layout).
RL_EXAMPLE = {
    'frequency': 30, 'sensor_timeout': 0.1, 'two_d_mode': True,
    'transform_time_offset': 0.0, 'transform_timeout': 0.0, 'print_diagnostics': True,
    'debug': False, 'debug_out_file': '/path/to/debug/file.txt',
    'permit_corrected_publication': False, 'publish_acceleration': False,
    'publish_tf': True, 'map_frame': 'map', 'odom_frame': 'odom',
    'base_link_frame': 'base_link', 'world_frame': 'odom',
    'odom0': 'example/odom',
    'odom0_config': flags('x', 'y', 'z', 'vx', 'vy', 'vz', 'vyaw'),
    'odom0_queue_size': 2, 'odom0_nodelay': False, 'odom0_differential': False,
    'odom0_relative': False, 'odom0_pose_rejection_threshold': 5.0,
    'odom0_twist_rejection_threshold': 1.0,
    'pose0': 'example/pose', 'pose0_config': flags('x', 'y', 'z', 'roll', 'pitch', 'yaw'),
    'pose0_queue_size': 5, 'pose0_differential': True, 'pose0_relative': False,
    'pose0_pose_rejection_threshold': 2.0,
    'twist0': 'example/twist', 'twist0_config': flags('vx', 'vy', 'vz', 'vyaw'),
    'twist0_queue_size': 3, 'twist0_twist_rejection_threshold': 2.0,
    'imu0': 'example/imu',
    'imu0_config': flags('roll', 'pitch', 'yaw', 'vroll', 'vpitch', 'vyaw', 'ax', 'ay', 'az'),
    'imu0_nodelay': False, 'imu0_differential': False, 'imu0_relative': True,
    'imu0_queue_size': 5, 'imu0_pose_rejection_threshold': 0.8,
    'imu0_angular_velocity_rejection_threshold': 0.8,
    'imu0_linear_acceleration_rejection_threshold': 0.8,
    'imu0_remove_gravitational_acceleration': True,
    'use_control': False, 'stamped_control': False, 'control_timeout': 0.2,
    'control_config': flags('vx', 'vy', 'vyaw'),
    'acceleration_limits': [1.3, 0.0, 0.0, 0.0, 0.0, 3.4],
    'deceleration_limits': [1.3, 0.0, 0.0, 0.0, 0.0, 4.5],
    'acceleration_gains': [0.8, 0.0, 0.0, 0.0, 0.0, 0.9],
    'deceleration_gains': [1.0, 0.0, 0.0, 0.0, 0.0, 1.0],
    'process_noise_covariance': matrix([0.05, 0.05, 0.06, 0.03, 0.03, 0.06, 0.025, 0.025,
                                        0.04, 0.01, 0.01, 0.02, 0.01, 0.01, 0.015]),
    'initial_estimate_covariance': matrix([1e-9] * 15),
    'dynamic_process_noise_covariance': False,
    'use_sim_time': True,
}


def test_defaults_are_robot_localizations():
    config = parse_ekf_config({})
    assert config.frequency_hz == 30.0 and config.sensor_timeout_s == pytest.approx(1 / 30)
    assert config.publish_tf and not config.publish_acceleration
    assert (config.map_frame, config.odom_frame, config.base_link_frame,
            config.world_frame) == ('map', 'odom', 'base_link', 'odom')
    assert not config.smooth_lagged_data and config.history_length_s == 0.0
    # x y yaw vx vy vyaw ax ay of r_l's default process noise.
    assert np.diag(config.process_noise) == pytest.approx(
        [0.05, 0.05, 0.06, 0.025, 0.025, 0.02, 0.01, 0.01])
    assert np.array_equal(config.initial_covariance, np.eye(8) * 1e-9)
    assert config.sensors == ()
    assert any('two_d_mode not set' in w for w in config.warnings)


def test_robot_localization_example_is_accepted():
    config = parse_ekf_config(RL_EXAMPLE)
    assert config.unknown_keys == ()
    assert set(config.ignored_keys) == {
        'transform_timeout', 'print_diagnostics', 'debug', 'debug_out_file',
        'permit_corrected_publication', 'use_control', 'stamped_control', 'control_timeout',
        'control_config', 'acceleration_limits', 'deceleration_limits',
        'acceleration_gains', 'deceleration_gains', 'dynamic_process_noise_covariance'}
    odom, pose, twist, imu = config.sensors
    assert (odom.name, odom.topic, odom.kind) == ('odom0', 'example/odom', 'odom')
    # two_d_mode drops z and vz; the rest is kept.
    assert odom.fused_variables == ('x', 'y', 'vx', 'vy', 'vyaw')
    assert odom.queue_size == 2
    assert (odom.pose_rejection_threshold, odom.twist_rejection_threshold) == (5.0, 1.0)
    assert pose.fused_variables == ('x', 'y', 'yaw') and pose.differential
    assert twist.fused_variables == ('vx', 'vy', 'vyaw') and twist.queue_size == 3
    assert imu.fused_variables == ('yaw', 'vyaw', 'ax', 'ay')
    assert imu.relative and imu.remove_gravitational_acceleration
    assert imu.pose_rejection_threshold == 0.8
    assert imu.twist_rejection_threshold == 0.8  # angular_velocity_rejection_threshold
    assert imu.linear_acceleration_rejection_threshold == 0.8
    assert math.isinf(twist.pose_rejection_threshold)


def test_planar_rows_and_columns_are_taken_from_15x15_matrices():
    # Entry (i, j) = (i + 1) * (j + 1): symmetric, and every entry tells where it came from.
    full = [(i + 1) * (j + 1) * 1e-3 for i in range(RL_SIZE) for j in range(RL_SIZE)]
    config = parse_ekf_config({'two_d_mode': True, 'process_noise_covariance': full})
    for row, rl_row in enumerate(PLANAR_FROM_RL):
        for column, rl_column in enumerate(PLANAR_FROM_RL):
            assert config.process_noise[row, column] == pytest.approx(
                (rl_row + 1) * (rl_column + 1) * 1e-3)
    # yaw is r_l's 6th variable, vyaw its 12th: 6 * 12 / 1000.
    assert config.process_noise[2, 5] == pytest.approx(0.072)


def test_zero_initial_variances_are_floored():
    config = parse_ekf_config({'two_d_mode': True, 'initial_estimate_covariance': [0.0] * 225})
    assert np.array_equal(config.initial_covariance, np.eye(8) * 1e-9)


@pytest.mark.parametrize('key, value, message', [
    ('two_d_mode', False, 'two_d_mode must be true'),
    ('frequency', 'fast', 'frequency must be a number'),
    ('frequency', 0.0, 'frequency must be > 0'),
    ('sensor_timeout', -1.0, 'sensor_timeout must be > 0'),
    ('history_length', math.nan, 'history_length must be finite'),
    ('publish_tf', 1, 'publish_tf must be true or false'),
    ('world_frame', 'earth', 'world_frame must be odom_frame'),
    ('odom_frame', 'base_link', 'must be three different frames'),
    ('base_link_frame', 7, 'base_link_frame must be a string'),
    ('process_noise_covariance', [0.0] * 224, 'process_noise_covariance must be a list of '
     '225 numbers'),
    ('process_noise_covariance', 0.05, 'process_noise_covariance must be a list of 225'),
    ('process_noise_covariance', [-0.1] * 225, 'process_noise_covariance has negative'),
    ('initial_estimate_covariance', ['a'] * 225, 'initial_estimate_covariance must be a list'),
    ('initial_state', [0.0] * 8, 'initial_state must be a list of 15 numbers'),
])
def test_bad_top_level_values_name_the_key(key, value, message):
    with pytest.raises(ValueError, match=message):
        parse_ekf_config({'two_d_mode': True, key: value})


def test_non_symmetric_matrix_is_refused():
    full = np.zeros((RL_SIZE, RL_SIZE))
    full[0, 6] = 0.1  # x - vx, one side only
    with pytest.raises(ValueError, match='process_noise_covariance must be symmetric'):
        parse_ekf_config({'process_noise_covariance': full.reshape(-1).tolist()})


def test_map_world_frame_needs_publish_tf_false():
    with pytest.raises(ValueError, match='publish_tf'):
        parse_ekf_config({'world_frame': 'map'})
    assert parse_ekf_config({'world_frame': 'map', 'publish_tf': False}).world_frame == 'map'


@pytest.mark.parametrize('key, value, message', [
    ('odom0_config', [True] * 14, 'odom0_config must be a list of 15 booleans'),
    ('odom0_config', [1] * 15, 'odom0_config must be a list of 15 booleans'),
    ('odom0_queue_size', 0, 'odom0_queue_size must be an integer >= 1'),
    ('odom0_queue_size', 2.5, 'odom0_queue_size must be an integer'),
    ('odom0_differential', 'yes', 'odom0_differential must be true or false'),
    ('odom0_twist_rejection_threshold', -1.0, 'odom0_twist_rejection_threshold must be > 0'),
    ('odom0', 3, 'odom0 must be a string'),
])
def test_bad_sensor_values_name_the_key(key, value, message):
    params = {'two_d_mode': True, 'odom0': 'odom', 'odom0_config': flags('vx')}
    params[key] = value
    with pytest.raises(ValueError, match=message):
        parse_ekf_config(params)


def test_unusable_and_unknown_keys_are_reported_not_fatal():
    config = parse_ekf_config({
        'two_d_mode': True, 'odom0': 'odom', 'odom0_config': [True] * 15,
        'odom0_confg': [True] * 15, 'twist0_differential': True, 'imu3_config': flags('ax'),
        'odom0_linear_acceleration_rejection_threshold': 1.0,
        'qos_overrides./tf.publisher.depth': 10})
    (odom,) = config.sensors
    # Odometry carries no acceleration; z, roll, pitch, vz, ... are not planar.
    assert odom.fused_variables == ('x', 'y', 'yaw', 'vx', 'vy', 'vyaw')
    assert any('ax, ay' in w and 'odom0_config' in w for w in config.warnings)
    assert any('imu3 has no topic' in w for w in config.warnings)
    assert set(config.unknown_keys) == {'odom0_confg', 'twist0_differential',
                                        'odom0_linear_acceleration_rejection_threshold'}


def test_sensors_up_to_index_9_and_gaps_are_fine():
    config = parse_ekf_config({'two_d_mode': True, 'odom0': '', 'odom9': '/wheels',
                               'odom9_config': flags('vx'), 'imu2': 'imu',
                               'imu2_config': flags('vyaw'),
                               'imu2_twist_rejection_threshold': 3.0})
    # Topics keep their leading slash (absolute names); frames lose it, as in tf2.
    assert [(s.name, s.topic) for s in config.sensors] == [('odom9', '/wheels'), ('imu2', 'imu')]
    assert parse_ekf_config({'base_link_frame': '/base_footprint'}).base_link_frame == (
        'base_footprint')
    assert config.sensors[1].twist_rejection_threshold == 3.0


def test_the_packaged_ekf_yaml_parses_as_this_robot_needs():
    params = yaml.safe_load(CONFIG.read_text())['ekf_filter_node']['ros__parameters']
    config = parse_ekf_config(params)
    assert config.unknown_keys == () and config.ignored_keys == ()
    assert config.warnings == ()
    assert config.frequency_hz == 30.0 and config.world_frame == 'odom' and config.publish_tf
    assert config.smooth_lagged_data and config.history_length_s == 1.0
    odom, imu = config.sensors
    assert (odom.topic, odom.fused_variables) == ('odom', ('vx', 'vy', 'vyaw'))
    assert math.isfinite(odom.twist_rejection_threshold)
    assert (imu.topic, imu.fused_variables) == ('imu/data_raw', ('vyaw', 'ax', 'ay'))
    assert imu.remove_gravitational_acceleration
    assert np.all(np.diag(config.process_noise) > 0)
