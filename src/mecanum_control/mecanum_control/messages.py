"""
Builders of the ROS messages several nodes publish the same way.

Planar odometry (REP-103/105): pose (x, y m, yaw rad) in ``frame_id``, body twist
(vx, vy m/s, wz rad/s) in ``child_frame_id``; wheel arrays are FL, FR, RL, RR.
"""

from typing import Optional, Sequence

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TransformStamped
from mecanum_control.angles import quaternion_from_yaw
from nav_msgs.msg import Odometry
from std_msgs.msg import Float32MultiArray, MultiArrayDimension


def wheel_array(values: Sequence[float]) -> Float32MultiArray:
    """Return a Float32MultiArray of four wheel values, FL FR RL RR."""
    msg = Float32MultiArray()
    msg.layout.dim = [MultiArrayDimension(label='wheel', size=4, stride=4)]
    msg.data = [float(v) for v in values]
    return msg


def planar_odometry(stamp: Time, frame_id: str, child_frame_id: str,
                    pose: Sequence[float], twist: Sequence[float],
                    pose_covariance: Optional[Sequence[float]] = None,
                    twist_covariance: Optional[Sequence[float]] = None) -> Odometry:
    """Return the Odometry of a planar pose (x, y, yaw) and body twist (vx, vy, wz)."""
    x, y, yaw = pose
    vx, vy, wz = twist
    odom = Odometry()
    odom.header.stamp = stamp
    odom.header.frame_id = frame_id
    odom.child_frame_id = child_frame_id
    odom.pose.pose.position.x = float(x)
    odom.pose.pose.position.y = float(y)
    q = odom.pose.pose.orientation
    q.x, q.y, q.z, q.w = quaternion_from_yaw(yaw)
    odom.twist.twist.linear.x = float(vx)
    odom.twist.twist.linear.y = float(vy)
    odom.twist.twist.angular.z = float(wz)
    if pose_covariance is not None:
        odom.pose.covariance = pose_covariance
    if twist_covariance is not None:
        odom.twist.covariance = twist_covariance
    return odom


def odometry_transform(odom: Odometry) -> TransformStamped:
    """Return the frame_id -> child_frame_id transform of an odometry message's pose."""
    transform = TransformStamped()
    transform.header = odom.header
    transform.child_frame_id = odom.child_frame_id
    position = odom.pose.pose.position
    transform.transform.translation.x = position.x
    transform.transform.translation.y = position.y
    transform.transform.rotation = odom.pose.pose.orientation
    return transform


def diagnostic_array(stamp: Time, name: str, level: bytes, message: str,
                     values: Sequence[KeyValue] = (),
                     hardware_id: str = 'none') -> DiagnosticArray:
    """Return a /diagnostics message of one status (level: DiagnosticStatus.OK, WARN, ...)."""
    array = DiagnosticArray(status=[DiagnosticStatus(
        level=level, name=name, message=message, hardware_id=hardware_id,
        values=list(values))])
    array.header.stamp = stamp
    return array
