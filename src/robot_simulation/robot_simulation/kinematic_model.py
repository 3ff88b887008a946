"""
Kinematic mecanum base: the pose follows the commanded body twist exactly (pure, no ROS).

This is the seed's quick-experiment model (``simulation_node``): no mass, motor
lag or slip. Commands are body twists (vx, vy m/s; wz rad/s; REP-103) that hold
until replaced or until ``cmd_timeout_s`` passes without a new one, after which
the base stops, as a real base's watchdog would. Poses are in the odom frame.
"""

from dataclasses import dataclass
import math
from typing import Optional, Tuple

from mecanum_control.kinematics import integrate_pose


@dataclass
class Pose2D:
    """Planar pose: x, y in metres, yaw in radians (counter-clockwise from x)."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0


@dataclass(frozen=True)
class TwistLimits:
    """Largest magnitudes accepted per axis: m/s, m/s, rad/s."""

    max_vx_mps: float = 1.0
    max_vy_mps: float = 1.0
    max_wz_radps: float = 3.0


class KinematicBase:
    """Integrates commanded twists into a pose, with a command timeout."""

    def __init__(self, pose: Pose2D = None, cmd_timeout_s: float = 0.5,
                 limits: TwistLimits = TwistLimits()):
        if not cmd_timeout_s > 0.0:
            raise ValueError('cmd_timeout_s must be positive')
        self.pose = pose if pose is not None else Pose2D()
        self.cmd_timeout_s = cmd_timeout_s
        self.limits = limits
        self.twist: Tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._command_time_s: Optional[float] = None

    def command(self, vx: float, vy: float, wz: float, now_s: float) -> Tuple[float, float, float]:
        """
        Set the body twist from now_s on; return it after clamping to the limits.

        Raises ValueError for NaN or infinite components (the twist is unchanged).
        """
        if not all(math.isfinite(v) for v in (vx, vy, wz)):
            raise ValueError(f'non-finite twist ({vx}, {vy}, {wz})')
        self.twist = (_clamp(vx, self.limits.max_vx_mps), _clamp(vy, self.limits.max_vy_mps),
                      _clamp(wz, self.limits.max_wz_radps))
        self._command_time_s = now_s
        return self.twist

    def step(self, now_s: float, dt_s: float) -> Pose2D:
        """Advance the pose by dt_s seconds ending at now_s; stop on command timeout."""
        if self._command_time_s is None or now_s - self._command_time_s > self.cmd_timeout_s:
            self.twist = (0.0, 0.0, 0.0)
        if dt_s > 0.0:
            vx, vy, wz = self.twist
            self.pose = Pose2D(*integrate_pose(self.pose.x, self.pose.y, self.pose.yaw,
                                               vx, vy, wz, dt_s))
        return self.pose


def _clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))
