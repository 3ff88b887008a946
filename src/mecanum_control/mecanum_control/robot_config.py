"""
The robot's physical parameters, read from ``config/motor_params.yaml`` (pure, no ROS).

``motor_params.yaml`` is the single source of truth for geometry, drive train and
limits: nodes get it as a ROS parameter file, the board emulator and the URDF read
the file itself. :func:`robot_config_from_parameters` validates either way.
Units are SI (REP-103); wheel order is FL, FR, RL, RR.
"""

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any, Mapping, Tuple

from mecanum_control.kinematics import MecanumGeometry
import yaml

#: Parameter name -> expected kind: 'float' and 'int' (finite, > 0), 'offset' (any
#: finite number: a mount position in m or yaw in rad), 'names' (4 joint names).
PARAMETER_KINDS = {
    'wheel_radius_m': 'float',
    'half_wheelbase_m': 'float',
    'half_track_m': 'float',
    'wheel_joint_names': 'names',
    'robot_mass_kg': 'float',
    'robot_yaw_inertia_kg_m2': 'float',
    'footprint_radius_m': 'float',
    'wheel_friction_coefficient': 'float',
    'chassis_length_m': 'float',
    'chassis_width_m': 'float',
    'chassis_height_m': 'float',
    'wheel_width_m': 'float',
    'lidar_mount_x_m': 'offset',
    'lidar_mount_y_m': 'offset',
    'lidar_mount_z_m': 'offset',
    'lidar_mount_yaw_rad': 'offset',
    'imu_mount_z_m': 'offset',
    'encoder_counts_per_motor_rev': 'int',
    'gear_ratio': 'float',
    'motor_no_load_speed_rad_s': 'float',
    'motor_time_constant_s': 'float',
    'max_wheel_speed_rad_s': 'float',
    'max_velocity_x_m_s': 'float',
    'max_velocity_y_m_s': 'float',
    'max_angular_velocity_rad_s': 'float',
    'max_acceleration_x_m_s2': 'float',
    'max_acceleration_y_m_s2': 'float',
    'max_angular_acceleration_rad_s2': 'float',
    'board_command_timeout_ms': 'int',
}


class RobotConfigError(ValueError):
    """A robot parameter is missing, of the wrong type or out of range."""


@dataclass(frozen=True)
class RobotConfig:
    """Validated physical parameters of the robot (see motor_params.yaml for meanings)."""

    geometry: MecanumGeometry
    wheel_joint_names: Tuple[str, str, str, str]
    robot_mass_kg: float
    robot_yaw_inertia_kg_m2: float
    footprint_radius_m: float
    wheel_friction_coefficient: float
    chassis_length_m: float
    chassis_width_m: float
    chassis_height_m: float
    wheel_width_m: float
    lidar_mount_x_m: float
    lidar_mount_y_m: float
    lidar_mount_z_m: float
    lidar_mount_yaw_rad: float
    imu_mount_z_m: float
    encoder_counts_per_motor_rev: int
    gear_ratio: float
    motor_no_load_speed_rad_s: float
    motor_time_constant_s: float
    max_wheel_speed_rad_s: float
    max_velocity_x_m_s: float
    max_velocity_y_m_s: float
    max_angular_velocity_rad_s: float
    max_acceleration_x_m_s2: float
    max_acceleration_y_m_s2: float
    max_angular_acceleration_rad_s2: float
    board_command_timeout_ms: int

    @property
    def counts_per_wheel_rev(self) -> float:
        """Return encoder counts per wheel revolution (quadrature counts x gear ratio)."""
        return self.encoder_counts_per_motor_rev * self.gear_ratio

    @property
    def rad_per_count(self) -> float:
        """Wheel angle per encoder count, rad."""
        return 2.0 * math.pi / self.counts_per_wheel_rev


def _check(name: str, kind: str, value: Any) -> Any:
    if value is None:
        raise RobotConfigError(f'robot parameter {name} is not set (see motor_params.yaml)')
    if kind == 'names':
        if (not isinstance(value, (list, tuple)) or len(value) != 4
                or not all(isinstance(item, str) and item for item in value)
                or len(set(value)) != 4):
            raise RobotConfigError(
                f'robot parameter {name} must be 4 distinct joint names (FL, FR, RL, RR), '
                f'got {value!r}')
        return tuple(value)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RobotConfigError(f'robot parameter {name} must be a number, got {value!r}')
    if kind == 'int':
        if not float(value).is_integer():  # also rejects NaN and inf (int() would raise)
            raise RobotConfigError(f'robot parameter {name} must be an integer, got {value!r}')
        value = int(value)
    else:
        value = float(value)
    if kind == 'offset':
        if not math.isfinite(value):
            raise RobotConfigError(f'robot parameter {name} must be finite, got {value!r}')
        return value
    if not (math.isfinite(value) and value > 0):
        raise RobotConfigError(f'robot parameter {name} must be finite and > 0, got {value!r}')
    return value


def robot_config_from_parameters(values: Mapping[str, Any]) -> RobotConfig:
    """Validate a mapping of parameter name -> value and build the config."""
    checked = {name: _check(name, kind, values.get(name))
               for name, kind in PARAMETER_KINDS.items()}
    geometry = MecanumGeometry(checked.pop('wheel_radius_m'), checked.pop('half_wheelbase_m'),
                               checked.pop('half_track_m'))
    config = RobotConfig(geometry=geometry, **checked)
    if abs(config.lidar_mount_yaw_rad) > math.pi:
        raise RobotConfigError('robot parameter lidar_mount_yaw_rad must be within [-pi, pi], '
                               f'got {config.lidar_mount_yaw_rad}')
    if config.board_command_timeout_ms > 65535:
        raise RobotConfigError('robot parameter board_command_timeout_ms must fit 16 bits '
                               f'(<= 65535), got {config.board_command_timeout_ms}')
    return config


def default_config_path() -> Path:
    """Installed motor_params.yaml, or the source tree's when the package is not installed."""
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory('mecanum_control')) / 'config/motor_params.yaml'
    except (ImportError, LookupError):
        return Path(__file__).resolve().parents[1] / 'config/motor_params.yaml'


def parameters_from_yaml(path: Path, node_name: str = '/**') -> dict:
    """Return the ros__parameters of node_name (default the /** wildcard) in a params file."""
    try:
        document = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as error:
        raise RobotConfigError(f'cannot read robot parameters from {path}: {error}') from None
    section = document.get(node_name) if isinstance(document, dict) else None
    params = section.get('ros__parameters') if isinstance(section, dict) else None
    if not isinstance(params, dict):
        raise RobotConfigError(
            f'{path}: expected a ROS parameter file with "{node_name}: ros__parameters:"')
    return params


def load_robot_config(path: Path) -> RobotConfig:
    """Read and validate motor_params.yaml (the /** section)."""
    try:
        return robot_config_from_parameters(parameters_from_yaml(path))
    except RobotConfigError as error:
        if str(path) in str(error):
            raise
        raise RobotConfigError(f'{path}: {error}') from None
