"""
Mecanum wheel kinematics and planar odometry (pure functions, no ROS).

Conventions (REP-103): body frame base_link, x forward, y left, z up; twists are
(vx m/s, vy m/s, wz rad/s). Wheel order is always FL, FR, RL, RR; wheel speeds
are angular velocities in rad/s, positive when the wheel rolls the robot
forward. Rollers are in the usual X arrangement seen from above (FL and RR
rollers parallel), so a positive vy (strafe left) turns FL and RR backwards.

``lx`` is half the wheelbase (front-rear axle distance / 2), ``ly`` half the
track (left-right wheel distance / 2); rotation couples through ``lx + ly``.
"""

from dataclasses import dataclass
import math
from typing import Sequence, Tuple

from mecanum_control.angles import wrap_angle

Twist2D = Tuple[float, float, float]
WheelSpeeds = Tuple[float, float, float, float]


@dataclass(frozen=True)
class MecanumGeometry:
    """Wheel radius and wheel placement of a mecanum base, in metres."""

    wheel_radius_m: float
    half_wheelbase_m: float
    half_track_m: float

    def __post_init__(self) -> None:
        for name in ('wheel_radius_m', 'half_wheelbase_m', 'half_track_m'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be a positive finite number, got {value!r}')

    @property
    def rotation_arm_m(self) -> float:
        """Return lx + ly, the lever arm of yaw rate on every wheel."""
        return self.half_wheelbase_m + self.half_track_m


def inverse_kinematics(geometry: MecanumGeometry, vx: float, vy: float,
                       wz: float) -> WheelSpeeds:
    """Body twist (m/s, m/s, rad/s) to wheel angular velocities FL, FR, RL, RR (rad/s)."""
    k = geometry.rotation_arm_m
    r = geometry.wheel_radius_m
    return ((vx - vy - k * wz) / r,
            (vx + vy + k * wz) / r,
            (vx + vy - k * wz) / r,
            (vx - vy + k * wz) / r)


def forward_kinematics(geometry: MecanumGeometry, wheel_speeds: Sequence[float]) -> Twist2D:
    """
    Wheel angular velocities FL, FR, RL, RR (rad/s) to the least-squares body twist.

    The inverse kinematics matrix has orthogonal columns, so its pseudo-inverse
    is a scaled transpose: inconsistent wheel speeds (slip) are averaged out.
    """
    fl, fr, rl, rr = wheel_speeds
    r = geometry.wheel_radius_m
    vx = r * (fl + fr + rl + rr) / 4.0
    vy = r * (-fl + fr + rl - rr) / 4.0
    wz = r * (-fl + fr - rl + rr) / (4.0 * geometry.rotation_arm_m)
    return vx, vy, wz


def desaturate(wheel_speeds: Sequence[float], max_wheel_speed: float) -> WheelSpeeds:
    """
    Scale all wheel speeds by one factor so none exceeds max_wheel_speed.

    Scaling them together keeps the direction of the body twist (and the ratio
    of translation to rotation); clipping wheels one by one would not.
    """
    if not max_wheel_speed > 0.0:
        raise ValueError('max_wheel_speed must be positive')
    peak = max(abs(w) for w in wheel_speeds)
    scale = max_wheel_speed / peak if peak > max_wheel_speed else 1.0
    fl, fr, rl, rr = (w * scale for w in wheel_speeds)
    return fl, fr, rl, rr


def integrate_pose(x: float, y: float, yaw: float, vx: float, vy: float, wz: float,
                   dt: float) -> Tuple[float, float, float]:
    """
    Advance a planar pose by a body twist held constant for dt seconds.

    Exact for a constant twist (the robot moves on a circular arc), not a
    first-order Euler step; the series forms keep it accurate as wz -> 0.
    Returns (x, y, yaw) with yaw wrapped to [-pi, pi).
    """
    dtheta = wz * dt
    if abs(dtheta) < 1e-6:
        sin_term = 1.0 - dtheta * dtheta / 6.0            # sin(d)/d
        cos_term = dtheta / 2.0 - dtheta ** 3 / 24.0      # (1 - cos(d))/d
    else:
        sin_term = math.sin(dtheta) / dtheta
        cos_term = (1.0 - math.cos(dtheta)) / dtheta
    # Displacement in the body frame at the start of the step.
    dx_body = (vx * sin_term - vy * cos_term) * dt
    dy_body = (vx * cos_term + vy * sin_term) * dt
    cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
    return (x + cos_yaw * dx_body - sin_yaw * dy_body,
            y + sin_yaw * dx_body + cos_yaw * dy_body,
            wrap_angle(yaw + dtheta))
