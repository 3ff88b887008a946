"""Hand-worked tests of mecanum_localization.sensor_fusion: mounts, frames, modes, IMU."""

import math

from mecanum_control.angles import quaternion_from_yaw, yaw_from_quaternion
from mecanum_localization.ekf import AX, AY, VX, VY, VYAW, X, Y, YAW
from mecanum_localization.ekf_config import RL_VARIABLES, SensorConfig
from mecanum_localization.sensor_fusion import gravity_in_frame, SensorFrontEnd
from mecanum_localization.transforms import PlanarTransform
import numpy as np
import pytest

G = 9.80665
NO_DATA = [-1.0] + [0.0] * 8   # REP-145: not provided


def front_end(kind, *variables, **options):
    """Return a SensorFrontEnd of a sensor of this kind fusing the named variables."""
    vector = tuple(name in variables for name in RL_VARIABLES)
    return SensorFrontEnd(SensorConfig(name=f'{kind}0', kind=kind, topic=f'{kind}_topic',
                                       update_vector=vector, **options), G)


def covariance_6(*diagonal):
    """Return a row-major 6x6 covariance (x y z roll pitch yaw) with this diagonal."""
    return np.diag(np.array(diagonal, dtype=float)).reshape(-1).tolist()


def covariance_3(*diagonal):
    """Return a row-major 3x3 covariance with this diagonal."""
    return np.diag(np.array(diagonal, dtype=float)).reshape(-1).tolist()


def imu_sample(front, orientation=None, orientation_covariance=NO_DATA, gyro_z=0.0,
               accel=(0.0, 0.0, G), mount=PlanarTransform(), time_s=1.0):
    """Convert an IMU sample with the gyro and accel covariances of hardware_interface."""
    return front.imu(time_s, orientation, orientation_covariance, gyro_z,
                     covariance_3(2.5e-5, 2.5e-5, 2.5e-5), accel,
                     covariance_3(0.0025, 0.0025, 0.0025), mount)


# -- IMU orientation ---------------------------------------------------------------------

def test_yaw_from_quaternion_and_gravity_of_a_tilted_imu():
    assert yaw_from_quaternion(*quaternion_from_yaw(2.5)) == pytest.approx(2.5)
    # Pitched by 0.3 rad about y: R = [[c, 0, s], [0, 1, 0], [-s, 0, c]]; gravity reads
    # as the third row times g: (-g sin 0.3, 0, g cos 0.3).
    pitch = (0.0, math.sin(0.15), 0.0, math.cos(0.15))
    assert gravity_in_frame(*pitch, G) == pytest.approx(
        (-G * math.sin(0.3), 0.0, G * math.cos(0.3)))
    assert gravity_in_frame(*quaternion_from_yaw(1.0), G) == pytest.approx((0.0, 0.0, G))


# -- IMU ------------------------------------------------------------------------------------

def test_imu_accelerations_are_rotated_by_the_mount_yaw_and_yaw_rate_is_not():
    front = front_end('imu', 'vyaw', 'ax', 'ay')
    # IMU turned +90 degrees: its x axis is base_link's y axis.
    covariance = [0.01, 0.0, 0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 0.01]
    conversion = front.imu(1.0, None, NO_DATA, 0.5, covariance_3(2.5e-5, 2.5e-5, 2.5e-5),
                           (1.0, 0.0, G), covariance, PlanarTransform(0.1, 0.0, math.pi / 2))
    assert not conversion.problem
    gyro, accel = conversion.measurements
    assert gyro.indices == (VYAW,) and gyro.values == pytest.approx([0.5])
    assert gyro.covariance == pytest.approx(np.array([[2.5e-5]]))
    assert accel.indices == (AX, AY) and accel.values == pytest.approx([0.0, 1.0])
    assert accel.covariance == pytest.approx(np.array([[0.04, 0.0], [0.0, 0.01]]))


def test_imu_without_orientation_gives_no_yaw():
    front = front_end('imu', 'yaw', 'vyaw')
    conversion = imu_sample(front, orientation=(0.0, 0.0, 0.0, 1.0))
    assert [m.indices for m in conversion.measurements] == [(VYAW,)]


def test_imu_orientation_minus_mount_yaw_is_the_robot_yaw():
    front = front_end('imu', 'yaw')
    conversion = imu_sample(front, quaternion_from_yaw(0.5), covariance_3(0.01, 0.01, 0.02),
                            mount=PlanarTransform(0.0, 0.0, 0.2))
    (yaw,) = conversion.measurements
    assert yaw.indices == (YAW,) and yaw.values == pytest.approx([0.3])
    assert yaw.covariance == pytest.approx(np.array([[0.02]]))


def test_gravity_is_removed_with_the_imus_orientation():
    pitch = (0.0, math.sin(0.15), 0.0, math.cos(0.15))
    reading = (-G * math.sin(0.3) + 0.2, 0.1, G * math.cos(0.3))  # plus a real 0.2, 0.1
    removing = front_end('imu', 'ax', 'ay', remove_gravitational_acceleration=True)
    (accel,) = imu_sample(removing, pitch, covariance_3(0.01, 0.01, 0.01),
                          accel=reading).measurements
    assert accel.values == pytest.approx([0.2, 0.1])
    keeping = front_end('imu', 'ax', 'ay')
    (accel,) = imu_sample(keeping, pitch, covariance_3(0.01, 0.01, 0.01),
                          accel=reading).measurements
    assert accel.values == pytest.approx([reading[0], reading[1]])


def test_non_finite_imu_data_is_a_problem_only_where_used():
    front = front_end('imu', 'vyaw', 'ax', 'ay')
    assert 'angular velocity' in imu_sample(front, gyro_z=math.nan).problem
    assert 'linear acceleration' in imu_sample(front, accel=(math.inf, 0.0, G)).problem
    # An unused orientation and an unused z acceleration may be anything.
    fine = imu_sample(front, orientation=(math.nan,) * 4, accel=(0.0, 0.0, math.nan))
    assert not fine.problem and len(fine.measurements) == 2


# -- odometry twist and pose ----------------------------------------------------------------

def test_twist_in_base_link_is_taken_as_is():
    front = front_end('odom', 'vx', 'vy', 'vyaw', twist_rejection_threshold=5.0)
    covariance = covariance_6(1e-3, 1e-3, 1, 1, 1, 1e-2)
    (twist,) = front.twist(2.0, 0.2, 0.1, 0.3, covariance).measurements
    assert twist.indices == (VX, VY, VYAW) and twist.values == pytest.approx([0.2, 0.1, 0.3])
    assert twist.covariance == pytest.approx(np.diag([1e-3, 1e-3, 1e-2]))
    assert twist.rejection_threshold == 5.0 and twist.time_s == 2.0


def test_twist_of_an_offset_sensor_loses_its_lever_arm_velocity():
    front = front_end('twist', 'vx', 'vy', 'vyaw')
    # Sensor 0.1 m ahead of base_link; the robot spins in place at 1 rad/s: the sensor
    # moves at 0.1 m/s to the left, base_link does not move.
    (twist,) = front.twist(0.0, 0.0, 0.1, 1.0, covariance_6(*[0.01] * 6),
                           PlanarTransform(0.1, 0.0, 0.0)).measurements
    assert twist.values == pytest.approx([0.0, 0.0, 1.0])
    # Sensor turned +90 degrees: its forward is base_link's left.
    (twist,) = front.twist(0.0, 1.0, 0.0, 0.0, covariance_6(0.01, 0.04, 1, 1, 1, 0.01),
                           PlanarTransform(0.0, 0.0, math.pi / 2)).measurements
    assert twist.values == pytest.approx([0.0, 1.0, 0.0])
    assert twist.covariance[:2, :2] == pytest.approx(np.array([[0.04, 0.0], [0.0, 0.01]]))


def test_only_enabled_variables_are_measured():
    front = front_end('odom', 'vx', 'vyaw')
    (twist,) = front.twist(0.0, 0.2, 0.1, 0.3, covariance_6(1, 2, 3, 4, 5, 6)).measurements
    assert twist.indices == (VX, VYAW) and twist.values == pytest.approx([0.2, 0.3])
    assert twist.covariance == pytest.approx(np.array([[1.0, 0.0], [0.0, 6.0]]))
    assert front.pose(0.0, 1.0, 2.0, 0.0, covariance_6(*[1] * 6)).measurements == []


def test_non_finite_twist_is_a_problem_but_unused_covariance_is_not():
    front = front_end('odom', 'vx', 'vy')
    assert front.twist(0.0, math.nan, 0.0, 0.0, covariance_6(*[1] * 6)).problem
    covariance = covariance_6(1, 1, math.nan, 1, 1, math.inf)  # z and yaw rate unused
    conversion = front.twist(0.0, 0.1, 0.0, 0.0, covariance)
    assert not conversion.problem and conversion.measurements[0].indices == (VX, VY)


def test_pose_in_another_frame_is_moved_into_the_world_frame():
    front = front_end('pose', 'x', 'y', 'yaw')
    frame = PlanarTransform(1.0, 0.0, math.pi / 2)
    (pose,) = front.pose(0.0, 1.0, 0.0, 0.0, covariance_6(0.01, 0.04, 1, 1, 1, 0.02),
                         frame).measurements
    assert pose.indices == (X, Y, YAW)
    assert pose.values == pytest.approx([1.0, 1.0, math.pi / 2])
    assert pose.covariance == pytest.approx(np.diag([0.04, 0.01, 0.02]))


def test_pose_of_child_frame_is_moved_to_base_link_when_asked():
    front = front_end('odom', 'x', 'y', 'yaw', pose_use_child_frame=True)
    # The child (a sensor 0.2 m ahead of base_link) is at (1, 0) facing +y: base_link is
    # 0.2 m behind it along -y.
    (pose,) = front.pose(0.0, 1.0, 0.0, math.pi / 2, covariance_6(*[0.01] * 6),
                         child_mount=PlanarTransform(0.2, 0.0, 0.0)).measurements
    assert pose.values == pytest.approx([1.0, -0.2, math.pi / 2])


def test_relative_pose_starts_at_zero():
    front = front_end('odom', 'x', 'y', 'yaw', relative=True)
    first = front.pose(0.0, 1.0, 2.0, math.pi / 2, covariance_6(*[0.01] * 6)).measurements[0]
    assert first.values == pytest.approx([0.0, 0.0, 0.0])
    # 1 m further along +y while facing +y: 1 m forward of the first pose.
    second = front.pose(1.0, 1.0, 3.0, math.pi / 2, covariance_6(*[0.01] * 6)).measurements[0]
    assert second.values == pytest.approx([1.0, 0.0, 0.0], abs=1e-12)


def test_differential_poses_become_body_velocities():
    front = front_end('odom', 'x', 'y', 'yaw', differential=True, pose_rejection_threshold=4.0)
    covariance = covariance_6(0.01, 0.01, 1, 1, 1, 0.02)
    assert front.pose(0.0, 0.0, 0.0, 0.0, covariance).measurements == []  # first: stored
    (rates,) = front.pose(0.5, 0.1, 0.05, 0.2, covariance).measurements
    # 0.1 m, 0.05 m and 0.2 rad in 0.5 s; covariance (0.01 + 0.01) / 0.5^2 = 0.08.
    assert rates.indices == (VX, VY, VYAW)
    assert rates.values == pytest.approx([0.2, 0.1, 0.4])
    assert rates.covariance == pytest.approx(np.diag([0.08, 0.08, 0.16]))
    assert rates.rejection_threshold == 4.0
    # Next, 0.1 m straight ahead of the robot, which now faces 0.2 rad: body vx only.
    ahead = PlanarTransform(0.1, 0.05, 0.2).compose(PlanarTransform(0.1, 0.0, 0.0))
    (rates,) = front.pose(1.0, ahead.x, ahead.y, ahead.yaw, covariance).measurements
    assert rates.values == pytest.approx([0.2, 0.0, 0.0], abs=1e-12)
    # An older or equal stamp cannot be differenced: nothing, and no harm.
    assert front.pose(1.0, 5.0, 5.0, 0.0, covariance).measurements == []
    assert front.pose(0.9, 5.0, 5.0, 0.0, covariance).measurements == []


def test_differential_imu_yaw_becomes_yaw_rate():
    front = front_end('imu', 'yaw', differential=True)
    assert imu_sample(front, quaternion_from_yaw(3.0), covariance_3(0, 0, 0.01),
                      time_s=0.0).measurements == []
    (rate,) = imu_sample(front, quaternion_from_yaw(-3.0), covariance_3(0, 0, 0.01),
                         time_s=0.5).measurements
    # From 3 rad to -3 rad the short way: +(2 pi - 6) rad in 0.5 s.
    assert rate.indices == (VYAW,)
    assert rate.values == pytest.approx([(2 * math.pi - 6.0) / 0.5])
