"""
Sensor message contents -> EKF measurements, robot_localization style (pure, no ROS).

The node extracts the numbers of a message (pose x, y, yaw with its 6x6 covariance; twist
vx, vy, vyaw with its 6x6 covariance; IMU orientation quaternion, yaw rate, accelerations
with their 3x3 covariances; row-major, ROS order) and :class:`SensorFrontEnd` turns them
into :class:`~mecanum_localization.ekf.Measurement` objects for the variables the sensor's
``*_config`` enables, applying:

* the sensor's static mount in base_link (planar: x, y, yaw). Twist: rotated into
  base_link, minus the lever-arm velocity ``vyaw x r``; IMU: accelerations rotated by the
  mount yaw (lever-arm terms neglected), yaw rate unchanged, yaw minus the mount yaw.
* ``*_relative``: the first pose is the origin of the later ones.
* ``*_differential``: consecutive poses are differenced into body velocities
  (x -> vx, y -> vy, yaw -> vyaw), covariance ``(P_previous + P_current) / dt^2``.
* IMU accelerations are measurements of the specific force in base_link, modelled with
  the rotating frame's terms (``Measurement.specific_force``).
* IMU ``remove_gravitational_acceleration``: gravity (from the message's orientation if it
  has one, else a level robot) is taken out of the accelerations.
* REP-145: an IMU covariance whose first element is -1 means "not provided".

Non-finite numbers in the used fields make the whole message unusable (``problem``).
"""

from dataclasses import dataclass, field
import math
from typing import List, Optional, Sequence, Tuple

from mecanum_control.angles import wrap_angle, yaw_from_quaternion
from mecanum_localization.ekf import AX, AY, Measurement, VX, VY, VYAW, X, Y, YAW
from mecanum_localization.ekf_config import SensorConfig
from mecanum_localization.transforms import IDENTITY, PlanarTransform
import numpy as np

#: Indices of x, y and yaw (or of vx, vy and vyaw) in a ROS 6x6 pose (twist) covariance.
COVARIANCE_6_PLANAR = (0, 1, 5)
POSE_NAMES = ('x', 'y', 'yaw')
POSE_INDEX = {'x': X, 'y': Y, 'yaw': YAW}
#: What a differenced pose variable measures.
RATE_INDEX = {'x': VX, 'y': VY, 'yaw': VYAW}


def gravity_in_frame(qx: float, qy: float, qz: float, qw: float,
                     gravity_m_s2: float) -> Tuple[float, float, float]:
    """
    Return what gravity adds to an accelerometer oriented as the quaternion (in world).

    An accelerometer at rest reads +g along the world's up axis, expressed in its frame:
    ``R' (0, 0, g)``, the third row of R times g (R from the normalised quaternion).
    """
    norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    qx, qy, qz, qw = qx / norm, qy / norm, qz / norm, qw / norm
    return (gravity_m_s2 * 2.0 * (qx * qz - qw * qy),
            gravity_m_s2 * 2.0 * (qy * qz + qw * qx),
            gravity_m_s2 * (1.0 - 2.0 * (qx * qx + qy * qy)))


def planar_covariance_6(covariance: Sequence[float]) -> np.ndarray:
    """Return the 3x3 (x, y, yaw) block of a row-major 6x6 ROS covariance."""
    full = np.array(covariance, dtype=float).reshape(6, 6)
    return full[np.ix_(COVARIANCE_6_PLANAR, COVARIANCE_6_PLANAR)]


def _rotate_planar(covariance: np.ndarray, yaw: float) -> np.ndarray:
    """Rotate the x, y block of a 3x3 (x, y, angle) covariance by yaw."""
    c, s = math.cos(yaw), math.sin(yaw)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return rotation @ covariance @ rotation.T


@dataclass
class Conversion:
    """The measurements made from a message, or why none could be (``problem``)."""

    measurements: List[Measurement] = field(default_factory=list)
    problem: str = ''


@dataclass
class _PoseSample:
    time_s: float
    pose: PlanarTransform
    covariance: np.ndarray


def _finite(*arrays) -> bool:
    return all(np.all(np.isfinite(np.asarray(a, dtype=float))) for a in arrays)


class SensorFrontEnd:
    """Turns the contents of one sensor's messages into measurements (keeps its memory)."""

    def __init__(self, config: SensorConfig, gravity_m_s2: float = 9.80665):
        self.config = config
        self.gravity_m_s2 = gravity_m_s2
        self._first_pose: Optional[PlanarTransform] = None
        self._previous_pose: Optional[_PoseSample] = None

    def reset(self) -> None:
        """Forget the relative origin and the previous pose of differential mode."""
        self._first_pose = None
        self._previous_pose = None

    # -- which parts of a message are used -------------------------------------------

    @property
    def uses_pose(self) -> bool:
        """Tell whether the message's pose (x, y or yaw) is used."""
        return self.config.uses('x', 'y', 'yaw')

    @property
    def uses_twist(self) -> bool:
        """Tell whether the message's twist (vx, vy or vyaw) is used."""
        return self.config.uses('vx', 'vy', 'vyaw')

    @property
    def uses_acceleration(self) -> bool:
        """Tell whether the IMU's linear acceleration (ax or ay) is used."""
        return self.config.uses('ax', 'ay')

    # -- conversions ---------------------------------------------------------------------

    def pose(self, time_s: float, x: float, y: float, yaw: float,
             covariance_6: Sequence[float], frame: PlanarTransform = IDENTITY,
             child_mount: PlanarTransform = IDENTITY) -> Conversion:
        """
        Convert a pose of the message's child frame, given in the message's frame.

        ``frame``: the message frame in the world frame; ``child_mount``: the child frame
        in base_link (only used with ``pose_use_child_frame``).
        """
        if not self.uses_pose:
            return Conversion()
        covariance = planar_covariance_6(covariance_6)
        used = [i for i, v in enumerate(('x', 'y', 'yaw')) if self.config.uses(v)]
        if not _finite((time_s, x, y, yaw), covariance[np.ix_(used, used)]):
            return Conversion(problem='non-finite pose or pose covariance')
        covariance = np.nan_to_num(covariance)  # unused entries do not matter
        pose = frame.compose(PlanarTransform(x, y, yaw))
        covariance = _rotate_planar(covariance, frame.yaw)
        if self.config.pose_use_child_frame:
            pose = pose.compose(child_mount.inverse())
        return self._pose_measurements(time_s, pose, covariance, ('x', 'y', 'yaw'))

    def twist(self, time_s: float, vx: float, vy: float, vyaw: float,
              covariance_6: Sequence[float], mount: PlanarTransform = IDENTITY) -> Conversion:
        """Convert a twist given in a frame mounted at ``mount`` in base_link."""
        if not self.uses_twist:
            return Conversion()
        covariance = planar_covariance_6(covariance_6)
        used = [i for i, v in enumerate(('vx', 'vy', 'vyaw')) if self.config.uses(v)]
        if not _finite((time_s, vx, vy, vyaw), covariance[np.ix_(used, used)]):
            return Conversion(problem='non-finite twist or twist covariance')
        covariance = np.nan_to_num(covariance)
        linear = mount.rotation() @ np.array([vx, vy])
        # Velocity of base_link = velocity of the sensor point - vyaw x (its offset).
        values = (linear[0] + vyaw * mount.y, linear[1] - vyaw * mount.x, vyaw)
        covariance = _rotate_planar(covariance, mount.yaw)
        return Conversion(self._select(time_s, ('vx', 'vy', 'vyaw'), (VX, VY, VYAW), values,
                                       covariance, self.config.twist_rejection_threshold,
                                       'twist'))

    def imu(self, time_s: float, orientation: Optional[Sequence[float]],
            orientation_covariance: Sequence[float], angular_velocity_z: float,
            angular_velocity_covariance: Sequence[float],
            linear_acceleration: Sequence[float],
            linear_acceleration_covariance: Sequence[float],
            mount: PlanarTransform = IDENTITY) -> Conversion:
        """
        Convert an IMU sample taken in a frame mounted at ``mount`` in base_link.

        ``orientation`` is the (x, y, z, w) quaternion, or None; a covariance whose first
        element is -1 marks that part as not provided (REP-145).
        """
        orientation_covariance = np.array(orientation_covariance, dtype=float).reshape(3, 3)
        gyro_covariance = np.array(angular_velocity_covariance, dtype=float).reshape(3, 3)
        accel_covariance = np.array(linear_acceleration_covariance, dtype=float).reshape(3, 3)
        acceleration = np.array(linear_acceleration[:2], dtype=float)
        accel_block = accel_covariance[:2, :2]
        has_orientation = (orientation is not None and orientation_covariance[0, 0] != -1.0
                           and any(v != 0.0 for v in orientation))  # all zero: none
        use_yaw = has_orientation and self.config.uses('yaw')
        use_gyro = self.config.uses('vyaw') and gyro_covariance[0, 0] != -1.0
        use_accel = self.uses_acceleration and accel_covariance[0, 0] != -1.0
        use_gravity = (use_accel and has_orientation
                       and self.config.remove_gravitational_acceleration)
        checks = (
            (use_yaw or use_gravity, 'orientation', (orientation,)),
            (use_yaw, 'orientation covariance', (orientation_covariance[2, 2],)),
            (use_gyro, 'angular velocity or its covariance',
             (angular_velocity_z, gyro_covariance[2, 2])),
            (use_accel, 'linear acceleration or its covariance', (acceleration, accel_block)),
            (use_yaw or use_gyro or use_accel, 'stamp', (time_s,)),
        )
        for used, what, arrays in checks:
            if used and not _finite(*arrays):
                return Conversion(problem=f'non-finite {what}')
        measurements: List[Measurement] = []
        if use_yaw:
            covariance = np.zeros((3, 3))
            covariance[2, 2] = orientation_covariance[2, 2]
            # The IMU frame's yaw in the world, minus its mount yaw: base_link's yaw.
            yaw = wrap_angle(yaw_from_quaternion(*orientation) - mount.yaw)
            measurements += self._pose_measurements(
                time_s, PlanarTransform(0.0, 0.0, yaw), covariance, ('yaw',)).measurements
        if use_gyro:
            measurements.append(Measurement(
                time_s, (VYAW,), (angular_velocity_z,), [[gyro_covariance[2, 2]]],
                self.config.twist_rejection_threshold,
                f'{self.config.topic} angular velocity'))
        if use_accel:
            if use_gravity:
                acceleration -= np.array(gravity_in_frame(*orientation, self.gravity_m_s2)[:2])
            # Without an orientation the robot is level: gravity lies along z only.
            rotation = mount.rotation()
            measurements += self._select(
                time_s, ('ax', 'ay'), (AX, AY), rotation @ acceleration,
                rotation @ accel_block @ rotation.T,
                self.config.linear_acceleration_rejection_threshold, 'linear acceleration',
                specific_force=True)
        return Conversion(measurements)

    # -- helpers -------------------------------------------------------------------------

    def _pose_measurements(self, time_s: float, pose: PlanarTransform,
                           covariance: np.ndarray, provided: Tuple[str, ...]) -> Conversion:
        """Make the measurement of a world-frame pose of base_link (differential, relative)."""
        names = [n for n in POSE_NAMES if n in provided and self.config.uses(n)]
        if not names:
            return Conversion()
        positions = [POSE_NAMES.index(n) for n in names]
        block = np.ix_(positions, positions)
        threshold = self.config.pose_rejection_threshold
        if self.config.differential:
            previous = self._previous_pose
            if previous is not None and time_s <= previous.time_s:
                return Conversion()  # not newer than the last pose: nothing to difference
            self._previous_pose = _PoseSample(time_s, pose, covariance)
            if previous is None:
                return Conversion()
            dt = time_s - previous.time_s
            # The displacement in the body frame at the previous pose, per second.
            delta = previous.pose.inverse().compose(pose)
            rates = np.array([delta.x, delta.y, delta.yaw]) / dt
            rates_covariance = _rotate_planar(previous.covariance + covariance,
                                              -previous.pose.yaw) / (dt * dt)
            return Conversion([Measurement(
                time_s, [RATE_INDEX[n] for n in names], rates[positions],
                rates_covariance[block], threshold,
                f'{self.config.topic} differential pose')])
        if self.config.relative:
            if self._first_pose is None:
                self._first_pose = pose
            pose = self._first_pose.inverse().compose(pose)
            covariance = _rotate_planar(covariance, -self._first_pose.yaw)
        values = np.array([pose.x, pose.y, pose.yaw])
        return Conversion([Measurement(
            time_s, [POSE_INDEX[n] for n in names], values[positions], covariance[block],
            threshold, f'{self.config.topic} pose')])

    def _select(self, time_s: float, names: Tuple[str, ...], indices: Tuple[int, ...],
                values: Sequence[float], covariance: np.ndarray, threshold: float,
                part: str, specific_force: bool = False) -> List[Measurement]:
        """Return the measurement of the variables (r_l names) the sensor's config enables."""
        keep = [k for k, name in enumerate(names) if self.config.uses(name)]
        if not keep:
            return []
        covariance = np.asarray(covariance, dtype=float)
        return [Measurement(time_s, [indices[k] for k in keep], [values[k] for k in keep],
                            covariance[np.ix_(keep, keep)], threshold,
                            f'{self.config.topic} {part}', specific_force)]
