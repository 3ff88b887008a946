"""
Keyboard teleoperation logic of ``teleop_keyboard``, without ROS.

The key bindings are those of teleop_twist_keyboard (ros2/teleop_twist_keyboard),
holonomic mode included, minus its t/b (linear z) keys that a ground robot has no use
for. Directions follow REP-103: x forward, y left, yaw counter-clockwise.

A :class:`TeleopState` holds the current speeds and the direction of motion;
:func:`apply_key` gives the state after a key press and :func:`twist_from_state` the
body twist (vx, vy, wz) to publish. Speeds never leave [1 % of max, max] where the
maxima are fixed when the state is created.
"""

from dataclasses import dataclass, replace
import math
from typing import Dict, Tuple

QUIT_KEY = '\x03'  # Ctrl-C, as the terminal sends it in raw mode

# key -> (x, y, th) direction: +x forward, +y left, +th counter-clockwise.
MOVE_BINDINGS: Dict[str, Tuple[int, int, int]] = {
    'u': (1, 0, 1),     # forward, turning left
    'i': (1, 0, 0),     # forward
    'o': (1, 0, -1),    # forward, turning right
    'j': (0, 0, 1),     # turn left on the spot
    'l': (0, 0, -1),    # turn right on the spot
    'm': (-1, 0, -1),   # backward, as a car reversing with the wheel turned right
    ',': (-1, 0, 0),    # backward
    '.': (-1, 0, 1),    # backward, as a car reversing with the wheel turned left
    # Holonomic mode (shift): translation only.
    'U': (1, 1, 0),     # diagonal forward-left
    'I': (1, 0, 0),     # forward
    'O': (1, -1, 0),    # diagonal forward-right
    'J': (0, 1, 0),     # strafe left
    'L': (0, -1, 0),    # strafe right
    'M': (-1, 1, 0),    # diagonal backward-left
    '<': (-1, 0, 0),    # backward
    '>': (-1, -1, 0),   # diagonal backward-right
}

# key -> (linear factor, angular factor)
SPEED_BINDINGS: Dict[str, Tuple[float, float]] = {
    'q': (1.1, 1.1),
    'z': (0.9, 0.9),
    'w': (1.1, 1.0),
    'x': (0.9, 1.0),
    'e': (1.0, 1.1),
    'c': (1.0, 0.9),
}

STOP_KEYS = frozenset({'k', 'K', ' ', QUIT_KEY})

# The speeds never drop below this fraction of their maxima (z/x/c pressed many times).
MIN_SPEED_FRACTION = 0.01

HELP_TEXT = """
This node takes keypresses from the keyboard and publishes them as
Twist/TwistStamped messages on cmd_vel. It works best with a US keyboard layout.
---------------------------
Moving around:
   u    i    o
   j    k    l
   m    ,    .

For Holonomic mode (strafing), hold down the shift key:
---------------------------
   U    I    O
   J    K    L
   M    <    >

k, K or space : stop
anything else : stop

q/z : increase/decrease max speeds by 10%
w/x : increase/decrease only linear speed by 10%
e/c : increase/decrease only angular speed by 10%

Hold the key down (or keep pressing it): without a key for a moment the robot stops.

CTRL-C to quit
"""


def _check_limit(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f'{name} must be finite and > 0, got {value}')


@dataclass(frozen=True)
class TeleopState:
    """
    Speeds and direction of motion of the teleoperation.

    speed_m_s and turn_rad_s are the current linear and angular speeds, in
    (0, max_speed_m_s] and (0, max_turn_rad_s]; x, y, th are the direction of motion
    in {-1, 0, 1} (x forward, y left, th counter-clockwise).
    """

    speed_m_s: float
    turn_rad_s: float
    max_speed_m_s: float
    max_turn_rad_s: float
    x: int = 0
    y: int = 0
    th: int = 0

    def __post_init__(self):
        """Refuse maxima that are not finite and > 0, speeds outside (0, max]."""
        _check_limit('max_speed_m_s', self.max_speed_m_s)
        _check_limit('max_turn_rad_s', self.max_turn_rad_s)
        for name, limit_name in (('speed_m_s', 'max_speed_m_s'),
                                 ('turn_rad_s', 'max_turn_rad_s')):
            value, limit = getattr(self, name), getattr(self, limit_name)
            if not (math.isfinite(value) and 0 < value <= limit):
                raise ValueError(
                    f'{name} must be finite, > 0 and <= {limit_name} ({limit}), got {value}')
        for name in ('x', 'y', 'th'):
            if getattr(self, name) not in (-1, 0, 1):
                raise ValueError(f'{name} must be -1, 0 or 1, got {getattr(self, name)}')

    @classmethod
    def initial(cls, speed_m_s: float, turn_rad_s: float, max_speed_m_s: float,
                max_turn_rad_s: float) -> 'TeleopState':
        """
        Return a stopped state with the speeds clamped to the maxima.

        Raises ValueError if a value is not finite and > 0.
        """
        _check_limit('speed_m_s', speed_m_s)
        _check_limit('turn_rad_s', turn_rad_s)
        _check_limit('max_speed_m_s', max_speed_m_s)
        _check_limit('max_turn_rad_s', max_turn_rad_s)
        return cls(min(float(speed_m_s), float(max_speed_m_s)),
                   min(float(turn_rad_s), float(max_turn_rad_s)),
                   float(max_speed_m_s), float(max_turn_rad_s))

    @property
    def moving(self) -> bool:
        """Whether the state commands any motion."""
        return (self.x, self.y, self.th) != (0, 0, 0)

    def stopped(self) -> 'TeleopState':
        """Return the state with the same speeds and no motion."""
        return replace(self, x=0, y=0, th=0)


def _scaled(value: float, factor: float, limit: float) -> float:
    return min(max(value * factor, limit * MIN_SPEED_FRACTION), limit)


def apply_key(state: TeleopState, key: str) -> Tuple[TeleopState, bool]:
    """
    Return the state after key is pressed and whether key is bound.

    Movement keys set the direction, speed keys scale the speeds (clamped to the
    maxima) and keep the direction, stop keys (k, K, space, Ctrl-C) stop. Like
    teleop_twist_keyboard, any other key stops too, but is reported as not bound.
    """
    if key in MOVE_BINDINGS:
        x, y, th = MOVE_BINDINGS[key]
        return replace(state, x=x, y=y, th=th), True
    if key in SPEED_BINDINGS:
        linear, angular = SPEED_BINDINGS[key]
        return replace(
            state,
            speed_m_s=_scaled(state.speed_m_s, linear, state.max_speed_m_s),
            turn_rad_s=_scaled(state.turn_rad_s, angular, state.max_turn_rad_s)), True
    return state.stopped(), key in STOP_KEYS


def twist_from_state(state: TeleopState) -> Tuple[float, float, float]:
    """Return the body twist (vx m/s, vy m/s, wz rad/s) the state commands."""
    return (float(state.x * state.speed_m_s), float(state.y * state.speed_m_s),
            float(state.th * state.turn_rad_s))


def speeds_text(state: TeleopState) -> str:
    """One line with the current speeds, like teleop_twist_keyboard's 'currently:' line."""
    speed_note = ' (max)' if state.speed_m_s >= state.max_speed_m_s else ''
    turn_note = ' (max)' if state.turn_rad_s >= state.max_turn_rad_s else ''
    return (f'currently:\tspeed {state.speed_m_s:.3g} m/s{speed_note}'
            f'\tturn {state.turn_rad_s:.3g} rad/s{turn_note}')
