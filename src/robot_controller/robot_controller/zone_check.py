"""
Would a text command's motion leave the authorised zone? (pure, no ROS).

A text command is open-loop: a constant body twist held for its duration. The check is
the zone guard's (:func:`mecanum_safety.zone_guard.path_stays_inside`), so
robot_controller refuses exactly what the guard would not let through: the whole path
(the exact arc of the twist from the current pose, sampled every 0.01 m of travel and
0.1 rad of heading, start and end included) must keep the footprint circle
(footprint_radius_m) at least margin_m inside the zone.
"""

from typing import Tuple

from mecanum_safety.zone_guard import path_stays_inside
from robot_controller.command_parser import Motion

Pose = Tuple[float, float, float]


def zone_refusal(zone, pose: Pose, motion: Motion, text: str, footprint_radius_m: float,
                 margin_m: float) -> str:
    """
    Return why motion (the command text) may not run from pose, or '' if it may.

    zone: a :class:`mecanum_safety.zone.Zone`; pose: base_link's (x, y m,
    yaw rad) in the zone's frame. The reason starts with the command: '<text>: the
    footprint would come ... at (x, y) ...' (the zone guard's words).
    """
    inside, why = path_stays_inside(zone, pose, motion.vx, motion.vy, motion.wz,
                                    motion.duration_s, footprint_radius_m, margin_m)
    return '' if inside else f'{text}: {why}'
