"""
Calibration of a fresh board's wheels from measured counts (pure: no ROS, no I/O).

``board_check --calibrate`` measures, for each wheel (FL, FR, RL, RR):

* the counts of ``turns`` whole wheel turns FORWARD (the way that rolls the robot
  forward) by hand, motors off: the counts per wheel revolution, and whether the
  encoder counts backwards;
* the counts of a short powered spin at a positive duty (robot on a stand): with the
  encoder's sign known, whether the motor turns backwards.

From them :func:`calibrate` proposes the robot config's ``gear_ratio`` (the median counts
per wheel revolution over ``encoder_counts_per_motor_rev``, the encoder's datasheet
figure, kept) and, for each wheel, whether to flip the motor's and the encoder's
``invert`` in firmware/board_config.py (the wiring lives there: one source of truth for
each). :func:`motor_params_text` and :func:`board_config_text` edit those files' texts
in place, keeping every comment, and :func:`unified_diff` shows the change first.
"""

from dataclasses import dataclass
import difflib
import re
from typing import List, Sequence, Tuple

WHEELS = ('FL', 'FR', 'RL', 'RR')
#: A wheel whose counts per revolution are this far (fraction) from the median is named:
#: a miscounted turn, a different gearbox or a slipping encoder magnet.
SPREAD_WARNING = 0.02
#: A powered spin must count at least this fraction of a wheel turn to show a direction.
MIN_SPIN_TURNS = 0.1


class CalibrationError(ValueError):
    """The measurements cannot give a calibration; the message says why."""


@dataclass(frozen=True)
class Calibration:
    """What the measurements say: the gear ratio and each wheel's flips (FL FR RL RR)."""

    counts_per_wheel_rev: Tuple[float, float, float, float]
    gear_ratio: float
    flip_encoder: Tuple[bool, bool, bool, bool]
    flip_motor: Tuple[bool, bool, bool, bool]
    warnings: Tuple[str, ...] = ()

    def lines(self) -> List[str]:
        """Return the findings, one line per wheel and one for the gear ratio."""
        out = []
        for index, wheel in enumerate(WHEELS):
            changes = [name for name, flip in (('encoder', self.flip_encoder[index]),
                                               ('motor', self.flip_motor[index])) if flip]
            out.append(f'{wheel}: {self.counts_per_wheel_rev[index]:.1f} counts per wheel '
                       f'turn; ' + (f'flip the {" and ".join(changes)} invert'
                                    if changes else 'directions right'))
        out.append(f'gear_ratio: {self.gear_ratio!r} (the median of the four wheels over '
                   'the encoder counts per motor turn)')
        return out + [f'warning: {text}' for text in self.warnings]


def calibrate(hand_counts: Sequence[int], turns: float, spin_counts: Sequence[int],
              spin_duty: float, counts_per_motor_rev: int) -> Calibration:
    """
    Return the calibration from hand turns and powered spins (counts FL FR RL RR).

    hand_counts: counts each wheel made while turned ``turns`` turns forward by hand;
    spin_counts: counts each made in its powered spin at spin_duty (> 0), both as the
    board reported them (its current inverts applied). CalibrationError when a wheel
    did not count, or its spin did not turn it.
    """
    if not turns > 0:
        raise CalibrationError(f'turns must be > 0, got {turns}')
    if not spin_duty > 0:
        raise CalibrationError(f'the spin duty must be > 0, got {spin_duty}')
    if len(hand_counts) != 4 or len(spin_counts) != 4:
        raise CalibrationError('need four counts of each kind (FL, FR, RL, RR)')
    per_rev = tuple(abs(count) / turns for count in hand_counts)
    dead = [wheel for wheel, value in zip(WHEELS, per_rev) if value < 1.0]
    if dead:
        raise CalibrationError(
            f'no counts when turned by hand: {", ".join(dead)} (encoder unplugged, or the '
            'wheel was not turned)')
    flip_encoder = tuple(count < 0 for count in hand_counts)
    flip_motor = []
    for wheel, count, flipped, rev in zip(WHEELS, spin_counts, flip_encoder, per_rev):
        forward_counts = -count if flipped else count
        if abs(forward_counts) < MIN_SPIN_TURNS * rev:
            raise CalibrationError(
                f'{wheel} did not turn in its spin at duty {spin_duty:g} ({count} counts): '
                'motor power, driver wiring, or a duty too low to start it')
        flip_motor.append(forward_counts < 0)
    middle = sorted(per_rev)
    median = (middle[1] + middle[2]) / 2   # one miscounted wheel moves it least
    warnings = tuple(
        f'{wheel} counts {value:.1f} per turn, {100 * (value / median - 1):+.1f} % from the '
        'median: miscounted turns, or another gearbox?'
        for wheel, value in zip(WHEELS, per_rev) if abs(value / median - 1) > SPREAD_WARNING)
    return Calibration(per_rev, round(median / counts_per_motor_rev, 2), flip_encoder,
                       tuple(flip_motor), warnings)


def motor_params_text(text: str, gear_ratio: float) -> str:
    """Return motor_params.yaml's text with gear_ratio set (every other line kept)."""
    pattern = re.compile(r'^(\s*gear_ratio:\s*)([^\s#]+)(.*)$', re.MULTILINE)
    if len(pattern.findall(text)) != 1:
        raise CalibrationError('motor_params.yaml: expected exactly one gear_ratio line')
    return pattern.sub(lambda m: f'{m.group(1)}{float(gear_ratio)!r}{m.group(3)}', text)


def board_config_text(text: str, flip_motor: Sequence[bool],
                      flip_encoder: Sequence[bool]) -> str:
    """
    Return board_config.py's text with the asked inverts flipped (every other line kept).

    The MOTORS and ENCODERS tuples must hold one dict per line, in the order FL, FR,
    RL, RR, each with ``'invert': True`` or ``False`` (as the shipped file does).
    """
    lines = text.splitlines(keepends=True)
    for name, flips in (('MOTORS', flip_motor), ('ENCODERS', flip_encoder)):
        rows = _tuple_rows(lines, name)
        for row, flip in zip(rows, flips):
            if flip:
                lines[row] = _flipped(lines[row])
    return ''.join(lines)


def _flipped(line: str) -> str:
    """Return a wheel's line with its invert flipped, its comment kept in its column."""
    if "'invert': True" in line:
        new = line.replace("'invert': True", "'invert': False", 1)
        return re.sub(r'(\}, ?) ( +#)', r'\1\2', new, count=1)   # one space less
    new = line.replace("'invert': False", "'invert': True", 1)
    return re.sub(r'(\},)( +#)', r'\1 \2', new, count=1)          # one space more


def _tuple_rows(lines: List[str], name: str) -> List[int]:
    """Return the line numbers of the four dict rows of ``NAME = (...)``."""
    start = next((i for i, line in enumerate(lines) if line.startswith(f'{name} = (')), None)
    if start is None:
        raise CalibrationError(f'board_config.py: no "{name} = (" block')
    rows = []
    for index in range(start + 1, len(lines)):
        stripped = lines[index].strip()
        if stripped.startswith(')'):
            break
        if stripped.startswith('{'):
            if not re.search(r"'invert': (True|False)", stripped) or not stripped.rstrip(
                    ',').split('#')[0].rstrip().rstrip(',').endswith('}'):
                raise CalibrationError(
                    f'board_config.py: {name} line {index + 1} is not one dict with '
                    "'invert': True/False: edit the inverts by hand")
            rows.append(index)
    if len(rows) != 4:
        raise CalibrationError(f'board_config.py: {name} has {len(rows)} wheel lines, not 4')
    return rows


def unified_diff(before: str, after: str, path: str) -> str:
    """Return the unified diff of a file's text (empty: no change)."""
    return ''.join(difflib.unified_diff(before.splitlines(keepends=True),
                                        after.splitlines(keepends=True),
                                        f'{path} (now)', f'{path} (calibrated)'))
