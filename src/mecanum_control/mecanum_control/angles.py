"""
Planar angles and yaw quaternions: the one copy every package uses (pure, no ROS).

Conventions (REP-103): angles in radians, yaw is the rotation about z (counter-clockwise
seen from above), quaternions are (x, y, z, w) as in geometry_msgs/Quaternion. Wrapped
angles lie in [-pi, pi): an angle of exactly +pi (or any odd multiple of pi) wraps to -pi.

``wrap_angle`` is plain arithmetic on a float, so numba compiles it unchanged:
``njit(cache=True)(wrap_angle)`` in a kernel uses this same definition.
"""

import math
from typing import Tuple

import numpy as np
from numpy.typing import ArrayLike

TWO_PI = 2.0 * math.pi


def wrap_angle(angle: float) -> float:
    """
    Wrap an angle in radians to [-pi, pi).

    ``(angle + pi) % 2pi - pi``; the rounding case where that gives +pi (an angle an ulp
    below -pi) is returned as -pi, the same heading. NaN and infinities give NaN.
    """
    wrapped = (angle + math.pi) % TWO_PI - math.pi
    return -math.pi if wrapped >= math.pi else wrapped


def wrap_angles(angles: ArrayLike) -> np.ndarray:
    """Wrap each angle of an array (radians) to [-pi, pi) as wrap_angle; a new float array."""
    wrapped = (np.asarray(angles, dtype=float) + math.pi) % TWO_PI - math.pi
    return np.where(wrapped >= math.pi, -math.pi, wrapped)


def angle_difference(a: float, b: float) -> float:
    """Return a - b wrapped to [-pi, pi) (radians): the shortest turn from b to a."""
    return wrap_angle(a - b)


def quaternion_from_yaw(yaw: float) -> Tuple[float, float, float, float]:
    """Return the unit (x, y, z, w) quaternion of a rotation by yaw radians about z."""
    return 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)


def yaw_from_quaternion(x: float, y: float, z: float, w: float) -> float:
    """
    Return the yaw in radians, in [-pi, pi], of an (x, y, z, w) quaternion.

    The Z angle of its ZYX (yaw-pitch-roll) Euler decomposition, as tf2's getRPY gives.
    """
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
