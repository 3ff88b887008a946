"""
robot_localization's EKF parameters, parsed and validated (pure, no ROS).

:func:`parse_ekf_config` takes the node's parameters as a name -> value mapping (the
keys of a robot_localization ``ekf.yaml``) and returns an :class:`EkfConfig`, or raises
ValueError naming the offending key. Matrices and update vectors use robot_localization's
15-variable order ``x y z roll pitch yaw vx vy vz vroll vpitch vyaw ax ay az``; this
filter is planar and keeps the 8 rows/columns of ``x y yaw vx vy vyaw ax ay``.
Defaults are robot_localization's.
"""

import array
from dataclasses import dataclass
import math
from typing import Any, Dict, List, Mapping, Optional, Tuple

import numpy as np

#: robot_localization's state variables, in the order of its matrices and update vectors.
RL_VARIABLES = ('x', 'y', 'z', 'roll', 'pitch', 'yaw', 'vx', 'vy', 'vz', 'vroll', 'vpitch',
                'vyaw', 'ax', 'ay', 'az')
RL_SIZE = len(RL_VARIABLES)
#: For each planar state variable (mecanum_localization.ekf order), its r_l index.
PLANAR_FROM_RL = (0, 1, 5, 6, 7, 11, 12, 13)
#: r_l variables that two_d_mode ignores.
NON_PLANAR = ('z', 'roll', 'pitch', 'vz', 'vroll', 'vpitch', 'az')
#: robot_localization's default process noise (diagonal), per second.
DEFAULT_PROCESS_NOISE_DIAGONAL = (0.05, 0.05, 0.06, 0.03, 0.03, 0.06, 0.025, 0.025, 0.04,
                                  0.01, 0.01, 0.02, 0.01, 0.01, 0.015)
#: robot_localization's default initial estimate covariance (diagonal).
DEFAULT_INITIAL_COVARIANCE_DIAGONAL = (1e-9,) * RL_SIZE
#: Variances below this in the initial estimate covariance are raised to it.
MIN_VARIANCE = 1e-9
SENSOR_KINDS = ('odom', 'pose', 'twist', 'imu')
#: Sensors of each kind: odom0 .. odom9 (and so on).
MAX_SENSORS_PER_KIND = 10
#: Which variables each kind of message can carry.
MESSAGE_VARIABLES = {
    'odom': ('x', 'y', 'yaw', 'vx', 'vy', 'vyaw'),
    'pose': ('x', 'y', 'yaw'),
    'twist': ('vx', 'vy', 'vyaw'),
    'imu': ('yaw', 'vyaw', 'ax', 'ay'),
}
#: Per-sensor keys (suffixes after e.g. ``odom0``) each kind accepts, and their kind.
SENSOR_KEYS = {
    'odom': ('_config', '_queue_size', '_differential', '_relative',
             '_pose_rejection_threshold', '_twist_rejection_threshold', '_nodelay',
             '_pose_use_child_frame'),
    'pose': ('_config', '_queue_size', '_differential', '_relative',
             '_pose_rejection_threshold', '_nodelay'),
    'twist': ('_config', '_queue_size', '_twist_rejection_threshold', '_nodelay'),
    'imu': ('_config', '_queue_size', '_differential', '_relative',
            '_pose_rejection_threshold', '_angular_velocity_rejection_threshold',
            '_twist_rejection_threshold', '_linear_acceleration_rejection_threshold',
            '_remove_gravitational_acceleration', '_nodelay'),
}
#: Valid robot_localization keys that this filter accepts and ignores.
IGNORED_KEYS = ('print_diagnostics', 'debug', 'debug_out_file',
                'dynamic_process_noise_covariance', 'permit_corrected_publication',
                'predict_to_current_time', 'transform_timeout', 'use_control',
                'stamped_control', 'control_timeout', 'control_config', 'acceleration_limits',
                'acceleration_gains', 'deceleration_limits', 'deceleration_gains',
                'disabled_at_startup', 'tf_prefix')
#: Keys that change robot_localization's behaviour: ignoring them deserves a warning.
IGNORED_WITH_WARNING = {'use_control': True, 'disabled_at_startup': True,
                        'predict_to_current_time': True,
                        'dynamic_process_noise_covariance': True}
#: Parameters every ROS 2 node may have; not robot_localization keys, not unknown.
ROS_KEYS = ('use_sim_time', 'start_type_description_service')
TOP_LEVEL_KEYS = ('frequency', 'sensor_timeout', 'two_d_mode', 'publish_tf',
                  'publish_acceleration', 'map_frame', 'odom_frame', 'base_link_frame',
                  'world_frame', 'transform_time_offset', 'smooth_lagged_data',
                  'history_length', 'process_noise_covariance', 'initial_estimate_covariance',
                  'initial_state', 'gravitational_acceleration', 'reset_on_time_jump')


@dataclass(frozen=True)
class SensorConfig:
    """
    One configured input, e.g. ``odom0``: its topic and how its messages are used.

    ``update_vector`` is the 15-boolean ``*_config`` (r_l order) with the variables this
    planar filter cannot use (non-planar ones, and those the message type lacks) cleared.
    Thresholds are Mahalanobis distances (inf: no gate).
    """

    name: str
    kind: str
    topic: str
    update_vector: Tuple[bool, ...]
    queue_size: int = 10
    differential: bool = False
    relative: bool = False
    pose_rejection_threshold: float = math.inf
    twist_rejection_threshold: float = math.inf
    linear_acceleration_rejection_threshold: float = math.inf
    remove_gravitational_acceleration: bool = False
    pose_use_child_frame: bool = False

    def uses(self, *variables: str) -> bool:
        """Tell whether any of the named r_l variables is fused from this sensor."""
        return any(self.update_vector[RL_VARIABLES.index(v)] for v in variables)

    @property
    def fused_variables(self) -> Tuple[str, ...]:
        """Names of the fused variables, in r_l order."""
        return tuple(v for v, used in zip(RL_VARIABLES, self.update_vector) if used)


@dataclass(frozen=True)
class EkfConfig:
    """Validated filter configuration (units SI; frames REP-105)."""

    frequency_hz: float
    sensor_timeout_s: float
    publish_tf: bool
    publish_acceleration: bool
    map_frame: str
    odom_frame: str
    base_link_frame: str
    world_frame: str
    transform_time_offset_s: float
    smooth_lagged_data: bool
    history_length_s: float
    process_noise: np.ndarray          # 8x8, planar order
    initial_covariance: np.ndarray     # 8x8, planar order
    initial_state: np.ndarray          # 8, planar order
    gravitational_acceleration_m_s2: float
    reset_on_time_jump: bool
    sensors: Tuple[SensorConfig, ...]
    ignored_keys: Tuple[str, ...]      # valid r_l keys given but not supported
    unknown_keys: Tuple[str, ...]      # keys that are not r_l keys at all (typos?)
    warnings: Tuple[str, ...]          # things worth telling the user at start-up


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_sequence(value: Any) -> bool:
    return isinstance(value, (list, tuple, array.array, np.ndarray))


class _Reader:
    """Reads typed values out of the parameter mapping, remembering which keys it used."""

    def __init__(self, params: Mapping[str, Any]):
        self.params = params
        self.used = set()

    def get(self, key: str, default: Any) -> Any:
        self.used.add(key)
        value = self.params.get(key)
        return default if value is None else value

    def boolean(self, key: str, default: bool) -> bool:
        value = self.get(key, default)
        if not isinstance(value, bool):
            raise ValueError(f'parameter {key} must be true or false, got {value!r}')
        return value

    def number(self, key: str, default: float, minimum: Optional[float] = None,
               strict: bool = False, allow_inf: bool = False) -> float:
        value = self.get(key, default)
        if not _is_number(value):
            raise ValueError(f'parameter {key} must be a number, got {value!r}')
        value = float(value)
        if math.isnan(value) or (math.isinf(value) and not allow_inf):
            raise ValueError(f'parameter {key} must be finite, got {value}')
        if minimum is not None and (value < minimum or (strict and value <= minimum)):
            raise ValueError(f'parameter {key} must be {">" if strict else ">="} {minimum:g}, '
                             f'got {value:g}')
        return value

    def integer(self, key: str, default: int, minimum: int) -> int:
        value = self.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            raise ValueError(f'parameter {key} must be an integer >= {minimum}, got {value!r}')
        return value

    def string(self, key: str, default: str, allow_empty: bool = False,
               frame: bool = True) -> str:
        value = self.get(key, default)
        if not isinstance(value, str):
            raise ValueError(f'parameter {key} must be a string, got {value!r}')
        value = value.strip()
        if frame:
            value = value.lstrip('/')  # tf2 frame ids carry no leading slash
        if not value and not allow_empty:
            raise ValueError(f'parameter {key} must not be empty')
        return value

    def numbers(self, key: str, default: Tuple[float, ...], length: int) -> List[float]:
        value = self.get(key, default)
        if not _is_sequence(value) or len(value) != length or not all(
                _is_number(v) for v in value):
            count = len(value) if _is_sequence(value) else 'not a list'
            raise ValueError(f'parameter {key} must be a list of {length} numbers '
                             f'(robot_localization order), got {count}')
        values = [float(v) for v in value]
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f'parameter {key} must contain finite numbers only')
        return values

    def booleans(self, key: str, length: int) -> Tuple[bool, ...]:
        value = self.get(key, [False] * length)
        if not _is_sequence(value) or len(value) != length or not all(
                isinstance(v, bool) for v in value):
            count = len(value) if _is_sequence(value) else 'not a list'
            raise ValueError(f'parameter {key} must be a list of {length} booleans '
                             f'({" ".join(RL_VARIABLES)}), got {count}: {value!r}')
        return tuple(value)


def planar_matrix(key: str, values: List[float]) -> np.ndarray:
    """Return the 8x8 planar block of a 15x15 row-major r_l matrix (validated)."""
    full = np.array(values, dtype=float).reshape(RL_SIZE, RL_SIZE)
    planar = full[np.ix_(PLANAR_FROM_RL, PLANAR_FROM_RL)]
    if not np.allclose(planar, planar.T, rtol=1e-9, atol=1e-12):
        raise ValueError(f'parameter {key} must be symmetric')
    diagonal = np.diag(planar)
    if np.any(diagonal < 0):
        negative = [RL_VARIABLES[PLANAR_FROM_RL[i]] for i in np.flatnonzero(diagonal < 0)]
        raise ValueError(f'parameter {key} has negative variances ({", ".join(negative)})')
    return 0.5 * (planar + planar.T)


def _diagonal_matrix(diagonal: Tuple[float, ...]) -> List[float]:
    return np.diag(np.array(diagonal, dtype=float)).reshape(-1).tolist()


def _sensor(reader: _Reader, kind: str, name: str, topic: str,
            warnings: List[str]) -> SensorConfig:
    vector = list(reader.booleans(name + '_config', RL_SIZE))
    for variable in NON_PLANAR:  # two_d_mode
        vector[RL_VARIABLES.index(variable)] = False
    unusable = [v for v, used in zip(RL_VARIABLES, vector)
                if used and v not in MESSAGE_VARIABLES[kind]]
    if unusable:
        warnings.append(f'{name}_config enables {", ".join(unusable)}, which {kind} messages '
                        'do not carry: ignored')
        for variable in unusable:
            vector[RL_VARIABLES.index(variable)] = False
    keys = SENSOR_KEYS[kind]
    fields: Dict[str, Any] = {}
    if '_queue_size' in keys:
        fields['queue_size'] = reader.integer(name + '_queue_size', 10, 1)
    for flag in ('differential', 'relative', 'pose_use_child_frame',
                 'remove_gravitational_acceleration'):
        if '_' + flag in keys:
            fields[flag] = reader.boolean(f'{name}_{flag}', False)
    for field, suffix in (('pose_rejection_threshold', '_pose_rejection_threshold'),
                          ('twist_rejection_threshold', '_twist_rejection_threshold'),
                          ('linear_acceleration_rejection_threshold',
                           '_linear_acceleration_rejection_threshold')):
        if suffix in keys:
            fields[field] = reader.number(name + suffix, math.inf, 0.0, strict=True,
                                          allow_inf=True)
    if kind == 'imu':
        # robot_localization names the IMU's yaw-rate gate angular_velocity; the generic
        # twist name is accepted as well.
        key = name + '_angular_velocity_rejection_threshold'
        if reader.params.get(key) is not None:
            fields['twist_rejection_threshold'] = reader.number(key, math.inf, 0.0, True, True)
        reader.used.add(key)
    reader.used.add(name + '_nodelay')
    sensor = SensorConfig(name=name, kind=kind, topic=topic, update_vector=tuple(vector),
                          **fields)
    if not sensor.fused_variables:
        warnings.append(f'{name} ({topic}) fuses no variable this planar filter can use')
    if sensor.differential and sensor.relative:
        warnings.append(f'{name}: differential and relative both set; differential wins')
    return sensor


def parse_ekf_config(params: Mapping[str, Any]) -> EkfConfig:
    """Validate robot_localization parameters; raise ValueError naming a bad key."""
    reader = _Reader(params)
    warnings: List[str] = []
    if params.get('two_d_mode') is None:
        warnings.append('two_d_mode not set: this planar filter runs as with two_d_mode true '
                        "(robot_localization's default is false)")
    if not reader.boolean('two_d_mode', True):
        raise ValueError('parameter two_d_mode must be true: mecanum_localization is a planar '
                         'filter (x, y, yaw and their rates)')
    frequency = reader.number('frequency', 30.0, 0.0, strict=True)
    sensor_timeout = reader.number('sensor_timeout', 1.0 / frequency, 0.0, strict=True)
    map_frame = reader.string('map_frame', 'map')
    odom_frame = reader.string('odom_frame', 'odom')
    base_link_frame = reader.string('base_link_frame', 'base_link')
    world_frame = reader.string('world_frame', odom_frame)
    if len({map_frame, odom_frame, base_link_frame}) != 3:
        raise ValueError('parameters map_frame, odom_frame and base_link_frame must be three '
                         f'different frames, got {map_frame}, {odom_frame}, {base_link_frame}')
    if world_frame not in (map_frame, odom_frame):
        raise ValueError(f'parameter world_frame must be odom_frame ({odom_frame}) or '
                         f'map_frame ({map_frame}), got {world_frame}')
    publish_tf = reader.boolean('publish_tf', True)
    if publish_tf and world_frame == map_frame:
        raise ValueError('parameter world_frame is map_frame with publish_tf true: publishing '
                         f'{map_frame} -> {odom_frame} needs tf2 lookups this filter does not '
                         'do; set publish_tf false')
    smooth = reader.boolean('smooth_lagged_data', False)
    history_length = reader.number('history_length', 0.0, 0.0)
    if smooth and history_length == 0.0:
        warnings.append('smooth_lagged_data is true but history_length is 0: late '
                        'measurements are dropped')
    process_noise = planar_matrix('process_noise_covariance', reader.numbers(
        'process_noise_covariance', _diagonal_matrix(DEFAULT_PROCESS_NOISE_DIAGONAL),
        RL_SIZE * RL_SIZE))
    initial_covariance = planar_matrix('initial_estimate_covariance', reader.numbers(
        'initial_estimate_covariance', _diagonal_matrix(DEFAULT_INITIAL_COVARIANCE_DIAGONAL),
        RL_SIZE * RL_SIZE))
    diagonal = np.diag_indices_from(initial_covariance)
    initial_covariance[diagonal] = np.maximum(initial_covariance[diagonal], MIN_VARIANCE)
    initial_state = np.array(reader.numbers('initial_state', (0.0,) * RL_SIZE, RL_SIZE))[
        list(PLANAR_FROM_RL)]
    publish_acceleration = reader.boolean('publish_acceleration', False)
    transform_time_offset = reader.number('transform_time_offset', 0.0)
    gravity = reader.number('gravitational_acceleration', 9.80665)
    reset_on_time_jump = reader.boolean('reset_on_time_jump', False)

    sensors = []
    for kind in SENSOR_KINDS:
        for index in range(MAX_SENSORS_PER_KIND):
            name = f'{kind}{index}'
            topic = reader.string(name, '', allow_empty=True, frame=False)
            if topic:
                sensors.append(_sensor(reader, kind, name, topic, warnings))
                continue
            orphans = [name + suffix for suffix in SENSOR_KEYS[kind]
                       if params.get(name + suffix) is not None]
            if orphans:
                warnings.append(f'{name} has no topic: {", ".join(orphans)} unused')
            reader.used.update(orphans)
    if not sensors:
        warnings.append('no sensor configured (odom0, imu0, pose0, twist0, ...): the filter '
                        'has nothing to fuse')

    ignored, unknown = [], []
    for key in sorted(params):
        if key in reader.used or key in ROS_KEYS or '.' in key:
            continue
        if key in IGNORED_KEYS:
            ignored.append(key)
            if IGNORED_WITH_WARNING.get(key) and params[key] not in (False, None):
                warnings.append(f'{key} is not supported by this filter: ignored')
        else:
            unknown.append(key)
    return EkfConfig(
        frequency_hz=frequency, sensor_timeout_s=sensor_timeout, publish_tf=publish_tf,
        publish_acceleration=publish_acceleration,
        map_frame=map_frame, odom_frame=odom_frame, base_link_frame=base_link_frame,
        world_frame=world_frame,
        transform_time_offset_s=transform_time_offset,
        smooth_lagged_data=smooth, history_length_s=history_length,
        process_noise=process_noise, initial_covariance=initial_covariance,
        initial_state=initial_state,
        gravitational_acceleration_m_s2=gravity, reset_on_time_jump=reset_on_time_jump,
        sensors=tuple(sensors), ignored_keys=tuple(ignored), unknown_keys=tuple(unknown),
        warnings=tuple(warnings))
