"""
Routes: several poses driven to one after the other (pure: no ROS).

The sequencing behind Nav2's NavigateThroughPoses and FollowWaypoints in this
workspace: the navigator drives to one pose at a time (a *leg*), and the route says
which pose comes next once a leg has ended, and how the whole route ended.

- NavigateThroughPoses: the poses in order; the first leg that fails ends the route
  with that leg's error code (``stop_on_failure``).
- FollowWaypoints: from ``start_index``, ``loops`` extra times round the list (Nav2's
  number_of_loops); a failed waypoint is *missed* (its index and error code are kept)
  and, unless ``stop_on_failure`` (Nav2's waypoint_follower default: true), the
  route goes on with the next one.

Error codes are the navigator's (mecanum_navigation.navigator.navigator: NONE = 0 on success).
"""

from dataclasses import dataclass, field
from typing import List, Optional, Tuple

#: The navigator's success code.
NONE = 0


@dataclass
class Route:
    """A route over ``count`` poses; :attr:`index` is the pose of the current leg."""

    count: int
    start_index: int = 0
    loops: int = 0
    stop_on_failure: bool = True
    index: int = field(init=False)
    loops_done: int = field(default=0, init=False)
    #: (pose index, error code, message) of every failed leg, in order.
    missed: List[Tuple[int, int, str]] = field(default_factory=list, init=False)
    #: NONE while running or when the route ended well; else the code that ended it.
    error_code: int = field(default=NONE, init=False)
    error_msg: str = field(default='', init=False)
    done: bool = field(default=False, init=False)

    def __post_init__(self):
        """Check the counts; the first leg is start_index."""
        if self.count < 1:
            raise ValueError('a route needs at least one pose')
        if not 0 <= self.start_index < self.count:
            raise ValueError(f'start index {self.start_index} is not one of the '
                             f'{self.count} poses (0 .. {self.count - 1})')
        if self.loops < 0:
            raise ValueError(f'loops must be >= 0, got {self.loops}')
        self.index = self.start_index

    @property
    def poses_remaining(self) -> int:
        """Poses after the current one in this pass (Nav2's number_of_poses_remaining)."""
        return self.count - 1 - self.index

    def leg_ended(self, code: int, message: str = '') -> Optional[int]:
        """
        Record how the current leg ended; return the next pose's index, None at the end.

        A code other than NONE is a failed leg: it ends the route when stop_on_failure
        (the route's error is then the leg's), else the route goes on.
        """
        if self.done:
            raise RuntimeError('the route has already ended')
        if code != NONE:
            self.missed.append((self.index, code, message))
            if self.stop_on_failure:
                return self._end(code, message)
        self.index += 1
        if self.index == self.count:
            if self.loops_done == self.loops:
                return self._end(NONE, '')
            self.loops_done += 1
            self.index = 0
        return self.index

    def abort(self, code: int, message: str) -> None:
        """End the route from outside (cancelled, preempted) with code."""
        if not self.done:
            self._end(code, message)

    def _end(self, code: int, message: str) -> None:
        self.done = True
        self.error_code, self.error_msg = code, message
        return None
