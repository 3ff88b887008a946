"""
ROS parameter helpers shared by the mecanum_control nodes.

The robot's physical parameters are declared read-only on every node that needs
them. Values come from the parameter file given at launch (``motor_params.yaml``);
any that are not given fall back to the installed ``motor_params.yaml``, so the file
stays the single source of truth even for a bare ``ros2 run``.
"""

import math
from typing import Sequence

from mecanum_control.robot_config import (
    default_config_path, PARAMETER_KINDS, parameters_from_yaml, robot_config_from_parameters,
    RobotConfig)
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node


def declare_typed(node: Node, name: str, default, kind: type = None):
    """
    Declare a parameter and return its value checked against the default's type.

    kind (default: the default's type) is float, int, bool, str or list; an integer
    value is taken for a float, a whole float for an int, None for an empty list.
    Raises ValueError naming the parameter.
    """
    kind = kind or type(default)
    value = node.declare_parameter(
        name, default, ParameterDescriptor(dynamic_typing=True)).value
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


def declare_robot_config(node: Node) -> RobotConfig:
    """Declare the motor_params.yaml parameters on node and return them validated."""
    defaults = parameters_from_yaml(default_config_path())
    values = {}
    for name in PARAMETER_KINDS:
        descriptor = ParameterDescriptor(read_only=True, description='see motor_params.yaml')
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
