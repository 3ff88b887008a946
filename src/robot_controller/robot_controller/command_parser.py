"""
Parse text commands into timed body-velocity motions (pure, no ROS).

Grammar (case-insensitive, words separated by spaces)::

    stop
    forward|backward [AMOUNT] [at SPEED]
    strafe left|right [AMOUNT] [at SPEED]
    diagonal forward-left|forward-right|backward-left|backward-right [AMOUNT] [at SPEED]
    rotate|turn left|right [AMOUNT] [at SPEED]      (``turn`` alone rotates left)

AMOUNT is a distance (``0.5 m``, ``20 cm``), an angle for rotations
(``90 deg``, ``1.57 rad``) or a duration (``2 s``). SPEED is ``0.3 m/s`` for
moves, ``45 deg/s`` or ``0.8 rad/s`` for rotations. Without AMOUNT the motion
lasts the default duration. Directions follow REP-103: x forward, y left,
positive yaw counter-clockwise.
"""

from dataclasses import dataclass
import math
import re
from typing import Dict, List, Optional, Tuple

_NUMBER = r'[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:e[-+]?\d+)?'
_QUANTITY = re.compile(rf'^({_NUMBER})\s*([a-z/]+)$')

# Unit vectors (vx, vy) of translations and the yaw sign of rotations.
_TRANSLATIONS: Dict[str, Tuple[float, float]] = {
    'forward': (1.0, 0.0),
    'backward': (-1.0, 0.0),
    'strafe left': (0.0, 1.0),
    'strafe right': (0.0, -1.0),
    'diagonal forward-left': (math.sqrt(0.5), math.sqrt(0.5)),
    'diagonal forward-right': (math.sqrt(0.5), -math.sqrt(0.5)),
    'diagonal backward-left': (-math.sqrt(0.5), math.sqrt(0.5)),
    'diagonal backward-right': (-math.sqrt(0.5), -math.sqrt(0.5)),
}
_ROTATIONS: Dict[str, float] = {'rotate left': 1.0, 'rotate right': -1.0}
_ALIASES = {'back': 'backward', 'turn': 'rotate', 'left': 'strafe left',
            'right': 'strafe right'}
_DISTANCE_UNITS = {'m': 1.0, 'cm': 0.01, 'mm': 0.001}
_ANGLE_UNITS = {'rad': 1.0, 'deg': math.pi / 180.0}
_DURATION_UNITS = {'s': 1.0, 'sec': 1.0, 'ms': 0.001}
_LINEAR_SPEED_UNITS = {'m/s': 1.0, 'cm/s': 0.01}
_ANGULAR_SPEED_UNITS = {'rad/s': 1.0, 'deg/s': math.pi / 180.0}

HELP = ('commands: stop | forward|backward [0.5 m|2 s] [at 0.3 m/s] | '
        'strafe left|right [...] | diagonal forward-left|forward-right|backward-left|'
        'backward-right [...] | rotate|turn left|right [90 deg|2 s] [at 45 deg/s]')


class CommandError(ValueError):
    """A text command that cannot be understood or is out of range."""


@dataclass(frozen=True)
class CommandLimits:
    """Speeds used when a command gives none, and the bounds commands must respect."""

    linear_speed_mps: float = 0.2
    angular_speed_radps: float = 0.5
    max_linear_speed_mps: float = 0.5
    max_angular_speed_radps: float = 1.5
    default_duration_s: float = 2.0
    max_duration_s: float = 60.0


@dataclass(frozen=True)
class Motion:
    """A body twist (m/s, m/s, rad/s) held for duration_s seconds; stop has duration 0."""

    name: str
    vx: float
    vy: float
    wz: float
    duration_s: float

    @property
    def is_stop(self) -> bool:
        """Whether this motion is the stop command."""
        return self.name == 'stop'


def _quantity(token: str) -> Tuple[float, str]:
    match = _QUANTITY.match(token)
    if not match:
        raise CommandError(f'cannot read {token!r} as a number with a unit (e.g. 0.5 m)')
    value = float(match.group(1))
    if not math.isfinite(value):
        raise CommandError(f'{token!r} is not a finite number')
    return value, match.group(2)


def _positive(value: float, message: str) -> float:
    if not value > 0.0:
        raise CommandError(message)
    return value


def _join_quantities(words: List[str]) -> List[str]:
    """Glue numbers to their units: ['0.5', 'm', 'at', '0.2', 'm/s'] -> ['0.5m', 'at', ...]."""
    joined: List[str] = []
    for word in words:
        if joined and re.fullmatch(r'[a-z/]+', word) and re.fullmatch(_NUMBER, joined[-1]):
            joined[-1] += word
        else:
            joined.append(word)
    return joined


def _motion_name(words: List[str]) -> Tuple[str, List[str]]:
    """Split the words into the canonical motion name and the remaining words."""
    if not words:
        raise CommandError('empty command; ' + HELP)
    first = _ALIASES.get(words[0], words[0])
    if first in ('strafe left', 'strafe right'):
        return first, words[1:]
    if first in ('strafe', 'rotate', 'diagonal'):
        if len(words) < 2 or f'{first} {words[1]}' not in {**_TRANSLATIONS, **_ROTATIONS}:
            if first == 'rotate' and (len(words) == 1 or not words[1].isalpha()):
                return 'rotate left', words[1:]
            raise CommandError(f'"{first}" needs a direction; ' + HELP)
        return f'{first} {words[1]}', words[2:]
    if first in ('forward', 'backward', 'stop'):
        return first, words[1:]
    raise CommandError(f'unknown command {words[0]!r}; ' + HELP)


def parse_command(text: str, limits: CommandLimits = CommandLimits()) -> Motion:
    """Parse one text command into a Motion, or raise CommandError saying why not."""
    if not isinstance(text, str):
        raise CommandError('command must be text')
    words = _join_quantities(text.strip().lower().split())
    name, rest = _motion_name(words)
    if name == 'stop':
        if rest:
            raise CommandError('"stop" takes no arguments')
        return Motion('stop', 0.0, 0.0, 0.0, 0.0)
    rotation = name in _ROTATIONS
    speed = limits.angular_speed_radps if rotation else limits.linear_speed_mps
    max_speed = limits.max_angular_speed_radps if rotation else limits.max_linear_speed_mps
    speed_units = _ANGULAR_SPEED_UNITS if rotation else _LINEAR_SPEED_UNITS
    amount_units = _ANGLE_UNITS if rotation else _DISTANCE_UNITS
    amount: Optional[float] = None
    duration: Optional[float] = None
    index = 0
    while index < len(rest):
        token = rest[index]
        # "at" only announces a speed: "forward 1 m at 0.3 m/s" == "forward 1 m 0.3 m/s".
        if token == 'at':
            if index + 1 >= len(rest):
                raise CommandError('"at" needs a speed, e.g. "at 0.3 m/s"')
            index += 1
            value, unit = _quantity(rest[index])
            if unit not in speed_units:
                raise CommandError(f'speed unit {unit!r} does not fit "{name}"; use '
                                   + ' or '.join(speed_units))
        else:
            value, unit = _quantity(token)
        if unit in speed_units:
            speed = _positive(value * speed_units[unit], 'speed must be positive')
        elif unit in _DURATION_UNITS or unit in amount_units:
            if duration is not None or amount is not None:
                raise CommandError('give either one distance/angle or one duration')
            if unit in _DURATION_UNITS:
                duration = _positive(value * _DURATION_UNITS[unit], 'duration must be positive')
            else:
                amount = _positive(value * amount_units[unit],
                                   'distance or angle must be positive; '
                                   'use the opposite direction instead of a sign')
        else:
            expected = ', '.join([*amount_units, *_DURATION_UNITS, *speed_units])
            raise CommandError(f'unit {unit!r} does not fit "{name}" (use {expected})')
        index += 1
    if speed > max_speed:
        raise CommandError(f'speed {speed:g} exceeds the limit {max_speed:g} for "{name}"')
    if amount is not None:
        duration = amount / speed
    if duration is None:
        duration = limits.default_duration_s
    if duration > limits.max_duration_s:
        raise CommandError(f'motion would last {duration:.1f} s, over the '
                           f'{limits.max_duration_s:g} s limit')
    if rotation:
        return Motion(name, 0.0, 0.0, _ROTATIONS[name] * speed, duration)
    ux, uy = _TRANSLATIONS[name]
    return Motion(name, ux * speed, uy * speed, 0.0, duration)
