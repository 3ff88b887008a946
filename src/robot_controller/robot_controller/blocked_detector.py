"""
Tell when the command chain holds a running motion back (pure, no ROS).

robot_controller sends a motion's constant twist into the command chain (twist_mux ->
collision_monitor -> zone_guard) and watches the chain's output (``cmd_vel_safe``). The
chain holds the robot when that output stays below ``blocked_speed_ratio`` of the
commanded speed, without a break, for ``blocked_time_s``: the linear speed
(hypot(vx, vy)) and the yaw rate are each compared with what the motion commands, a
component commanded as zero does not count, and the output counts as holding the robot
when every counted component is below the ratio. A chain that sends no output for
``blocked_time_s`` after its last output, or none at all for ``start_timeout_s`` after the
motion's start, holds the robot too: motor_controller listens only to the chain, so it is
not moving. The first output is awaited longer because a chain that has just been
started may still be finding its stages (DDS discovery); the caller times the motion from
that first output (``first_output_s``), so a late chain does not shorten it.

The reason given is what the chain's stages said (``collision_monitor_state``,
``zone_guard_state``): among the stages whose latest state is not a pass
(``DO_NOTHING``, ``ALLOW``) the one saying ``STOP``, else the most recent; when every stage
now passes, the most recent non-pass state since the motion started. Times are seconds
of the caller's clock (the node's, so simulated time works).
"""

import math
from typing import Dict, Optional, Tuple

#: States (their first word) that let the command through unchanged.
PASS_STATES = ('DO_NOTHING', 'ALLOW')
#: The reason given when the chain sends nothing.
NO_OUTPUT = 'no output from the command chain'


def is_pass_state(state: str) -> bool:
    """Whether a stage's state lets commands through unchanged ('' counts as a pass)."""
    words = state.split()
    return not words or words[0] in PASS_STATES


class BlockedDetector:
    """Watches the chain's output during one motion and tells when it holds the robot."""

    def __init__(self, blocked_speed_ratio: float = 0.1, blocked_time_s: float = 0.5,
                 start_timeout_s: float = 5.0):
        """Check the settings (ValueError naming the bad one)."""
        if not (math.isfinite(blocked_speed_ratio) and 0.0 < blocked_speed_ratio < 1.0):
            raise ValueError('blocked_speed_ratio must be within (0, 1), got '
                             f'{blocked_speed_ratio}')
        if not (math.isfinite(blocked_time_s) and blocked_time_s > 0.0):
            raise ValueError(f'blocked_time_s must be finite and > 0, got {blocked_time_s}')
        if not (math.isfinite(start_timeout_s) and start_timeout_s >= blocked_time_s):
            raise ValueError('start_timeout_s must be finite and >= blocked_time_s '
                             f'({blocked_time_s}), got {start_timeout_s}')
        self.blocked_speed_ratio = float(blocked_speed_ratio)
        self.blocked_time_s = float(blocked_time_s)
        self.start_timeout_s = float(start_timeout_s)
        self.active = False
        self._commanded = (0.0, 0.0)       # linear speed m/s, |yaw rate| rad/s
        self._start_s = 0.0
        self._first_output_s: Optional[float] = None
        self._last_output_s: Optional[float] = None
        self._held_since_s: Optional[float] = None
        self._sequence = 0
        self._latest: Dict[str, Tuple[int, str]] = {}   # stage -> (sequence, state)
        self._last_problem: Optional[Tuple[int, str, str]] = None

    def start(self, now_s: float, vx: float, vy: float, wz: float) -> None:
        """Start watching a motion commanding the body twist vx, vy (m/s), wz (rad/s)."""
        self.active = True
        self._commanded = (math.hypot(vx, vy), abs(wz))
        self._start_s = now_s
        self._first_output_s = None
        self._last_output_s = None
        self._held_since_s = None
        self._last_problem = None

    def stop(self) -> None:
        """Stop watching (the motion ended)."""
        self.active = False

    @property
    def first_output_s(self) -> Optional[float]:
        """When the chain first sent an output during this motion (None: not yet)."""
        return self._first_output_s

    def holds(self, vx: float, vy: float, wz: float) -> bool:
        """Whether an output twist is below the ratio in every component commanded."""
        linear, angular = self._commanded
        below = []
        if linear > 0.0:
            below.append(math.hypot(vx, vy) < self.blocked_speed_ratio * linear)
        if angular > 0.0:
            below.append(abs(wz) < self.blocked_speed_ratio * angular)
        return bool(below) and all(below)

    def on_output(self, now_s: float, vx: float, vy: float, wz: float) -> None:
        """Take one output twist of the chain, received at now_s."""
        if not self.active:
            return
        if self._first_output_s is None:
            self._first_output_s = now_s
        self._last_output_s = now_s
        if not all(math.isfinite(v) for v in (vx, vy, wz)) or self.holds(vx, vy, wz):
            if self._held_since_s is None:
                self._held_since_s = now_s
        else:
            self._held_since_s = None

    def on_state(self, stage: str, state: str) -> None:
        """Take one state message of a chain stage (kept also while no motion runs)."""
        state = state.strip()
        self._sequence += 1
        self._latest[stage] = (self._sequence, state)
        if not is_pass_state(state):
            self._last_problem = (self._sequence, stage, state)

    def check(self, now_s: float) -> Optional[str]:
        """Return why the motion is blocked at now_s, or None while it is not."""
        if not self.active:
            return None
        if self._held_since_s is not None and now_s - self._held_since_s >= self.blocked_time_s:
            return self.reason()
        if self._last_output_s is None:
            quiet_s, limit_s = now_s - self._start_s, self.start_timeout_s
        else:
            quiet_s, limit_s = now_s - self._last_output_s, self.blocked_time_s
        if quiet_s >= limit_s:
            return NO_OUTPUT
        return None

    def reason(self) -> str:
        """Return the stage and state that hold the robot, as 'stage STATE ...'."""
        current = [(sequence, stage, state) for stage, (sequence, state) in self._latest.items()
                   if not is_pass_state(state)]
        stops = [item for item in current if item[2].split()[0] == 'STOP']
        chosen = max(stops or current, default=None) or self._last_problem
        if chosen is None:
            return (f'the command chain (its output stayed under {self.blocked_speed_ratio:g} '
                    'of the command; no stage reported a limit)')
        return f'{chosen[1]} {chosen[2]}'
