"""
ROS parameter helpers shared by the mecanum_control nodes.

The robot's physical parameters are declared read-only on every node that needs
them (``ros2 param describe`` says why: :func:`robot_config_read_only_reason`). Values
come from the parameter file given at launch (``motor_params.yaml``); any that are not
given fall back to the installed ``motor_params.yaml``, so the file stays the single
source of truth even for a bare ``ros2 run``. Parameters a running node takes at once
(``ros2 param set``): :mod:`mecanum_control.runtime_parameters`.
"""

import math
from typing import Sequence

from mecanum_control.robot_config import (
    default_config_path, PARAMETER_KINDS, parameters_from_yaml, robot_config_from_parameters,
    RobotConfig)
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node


#: The limits of motor_params.yaml: the command chain applies them too (see below).
ROBOT_LIMIT_PARAMETERS = (
    'max_wheel_speed_rad_s', 'max_velocity_x_m_s', 'max_velocity_y_m_s',
    'max_angular_velocity_rad_s', 'max_acceleration_x_m_s2', 'max_acceleration_y_m_s2',
    'max_angular_acceleration_rad_s2')
#: What the other motor_params.yaml parameters describe, for the read-only reason.
ROBOT_PARAMETER_GROUPS = {
    'geometry': ('wheel_radius_m', 'half_wheelbase_m', 'half_track_m', 'footprint_radius_m',
                 'chassis_length_m', 'chassis_width_m', 'chassis_height_m', 'wheel_width_m',
                 'wheel_joint_names'),
    'sensor mounts': ('lidar_mount_x_m', 'lidar_mount_y_m', 'lidar_mount_z_m',
                      'lidar_mount_yaw_rad', 'imu_mount_z_m'),
    'drive train': ('encoder_counts_per_motor_rev', 'gear_ratio', 'motor_no_load_speed_rad_s',
                    'motor_time_constant_s', 'board_command_timeout_ms'),
}


def robot_config_read_only_reason(name: str) -> str:
    """Return why the motor_params.yaml parameter name is read-only in every node."""
    if name in ROBOT_LIMIT_PARAMETERS:
        return ("a limit from motor_params.yaml, which the command chain's twist_mux also "
                'applies before the collision monitor and the zone guard judge a twist: '
                'changed in one node only, the motors could run a twist the chain did not '
                'judge; edit the file and restart the system')
    what = next((group for group, names in ROBOT_PARAMETER_GROUPS.items() if name in names),
                'physical parameters')
    return (f"the robot's {what} from motor_params.yaml, shared by the controller, the "
            'simulator and the firmware; edit the file and restart')


def typed_value(name: str, value, kind: type):
    """
    Return value checked against kind (float, int, bool, str or list).

    An integer value is taken for a float, a whole float for an int, None for an empty
    list. Raises ValueError naming the parameter.
    """
    if kind is list:
        return [] if value is None else list(value)
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if kind is int and isinstance(value, float) and value.is_integer():
        value = int(value)
    if not isinstance(value, kind) or (kind is not bool and isinstance(value, bool)):
        kinds = {float: 'a number', int: 'an integer', bool: 'true or false',
                 str: 'a string'}
        raise ValueError(f'parameter {name} must be {kinds[kind]}, got {value!r}')
    return value


def declare_typed(node: Node, name: str, default, kind: type = None):
    """
    Declare a parameter and return its value checked against the default's type.

    kind (default: the default's type) is float, int, bool, str or list; an integer
    value is taken for a float, a whole float for an int, None for an empty list.
    Raises ValueError naming the parameter.
    """
    value = node.declare_parameter(
        name, default, ParameterDescriptor(dynamic_typing=True)).value
    return typed_value(name, value, kind or type(default))


def declare_robot_config(node: Node) -> RobotConfig:
    """Declare the motor_params.yaml parameters on node and return them validated."""
    defaults = parameters_from_yaml(default_config_path())
    values = {}
    for name in PARAMETER_KINDS:
        descriptor = ParameterDescriptor(
            read_only=True, description=f'read-only: {robot_config_read_only_reason(name)}')
        values[name] = node.declare_parameter(name, defaults.get(name), descriptor).value
    return robot_config_from_parameters(values)


def declare_number(node: Node, name: str, default: float) -> float:
    """Declare a numeric parameter that accepts 2 as well as 2.0; return it as float."""
    value = node.declare_parameter(
        name, default, ParameterDescriptor(dynamic_typing=True)).value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f'parameter {name} must be a number, got {value!r}')
    return float(value)


def positive(name: str, value: float) -> float:
    """Return value as float if finite and > 0, else raise ValueError naming the parameter."""
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f'parameter {name} must be finite and > 0, got {value}')
    return value


def covariance_from_diagonal(name: str, diagonal: Sequence[float]) -> list:
    """6x6 row-major covariance (x, y, z, roll, pitch, yaw) from its 6 diagonal entries."""
    values = [float(v) for v in diagonal]
    if len(values) != 6 or not all(math.isfinite(v) and v >= 0 for v in values):
        raise ValueError(f'parameter {name} must be 6 finite values >= 0, got {values}')
    matrix = [0.0] * 36
    for i, value in enumerate(values):
        matrix[i * 7] = value
    return matrix
