"""
Joint states -> moving joints' transforms, as robot_state_publisher does (pure, no ROS).

:func:`joint_state_transforms` turns one joint state (names, positions in rad or m)
into the parent -> child transforms of the robot's moving joints, including mimic
joints that follow them. Names that are not moving joints of the model and positions
that are NaN or infinite are left out and reported. :class:`PublishThrottle`
publishes each joint at most once per interval of message time.
"""

from dataclasses import dataclass, field
import math
from typing import Dict, List, Optional, Sequence

from mecanum_description.robot_model import RobotModel, Transform


@dataclass
class JointStateUpdate:
    """Transforms of one joint state, and the names that were left out and why."""

    positions: Dict[str, float] = field(default_factory=dict)  # joint -> rad or m
    transforms: List[Transform] = field(default_factory=list)  # same order
    unknown: List[str] = field(default_factory=list)
    not_finite: List[str] = field(default_factory=list)


def joint_state_transforms(model: RobotModel, names: Sequence[str],
                           positions: Sequence[float]) -> JointStateUpdate:
    """
    Return the transforms of the moving joints named in a joint state.

    Raises ValueError when names and positions differ in length (the message is
    unusable: which position belongs to which joint is unknown).
    """
    if len(names) != len(positions):
        raise ValueError(f'joint state has {len(names)} names but {len(positions)} '
                         'positions')
    update = JointStateUpdate()
    valid = update.positions
    for name, position in zip(names, positions):
        joint = model.joints.get(name)
        if joint is None or not joint.moving:
            update.unknown.append(name)
        elif not math.isfinite(position):
            update.not_finite.append(name)
        else:
            valid[name] = float(position)
    for name, position in model.mimic_positions(valid).items():
        valid.setdefault(name, position)
    update.transforms = [model.joint_transform(name, position)
                         for name, position in valid.items()]
    return update


class PublishThrottle:
    """
    Rate limit per joint, in message time (robot_state_publisher's publish_frequency).

    A joint state is published when every joint in it was last published at least
    ``interval_ns`` earlier (or never). Message time going backwards (a restarted
    simulation or bag) starts over.
    """

    def __init__(self, interval_ns: int):
        """Throttle to one publication per joint per interval_ns (>= 0)."""
        if interval_ns < 0:
            raise ValueError(f'interval_ns must be >= 0, got {interval_ns}')
        self.interval_ns = int(interval_ns)
        self._last_ns: Dict[str, int] = {}

    def ready(self, names: Sequence[str], stamp_ns: int) -> bool:
        """Tell whether joints names may be published at stamp_ns; if so, record it."""
        last: Optional[int] = min((self._last_ns[n] for n in names if n in self._last_ns),
                                  default=None)
        if last is not None and stamp_ns < last:
            self._last_ns.clear()
        elif last is not None and stamp_ns - last < self.interval_ns:
            return False
        for name in names:
            self._last_ns[name] = stamp_ns
        return True
