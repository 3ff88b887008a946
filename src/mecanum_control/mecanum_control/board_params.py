"""
The firmware's parameters, derived from the one robot config (pure, no ROS).

The board core (:mod:`mecanum_control.board_core`) judges its encoders in counts per
second and raw duties; the thresholds below are in wheel rad/s and duty fractions,
and the robot config's counts per wheel revolution converts them. The emulator and
the simulator call :func:`board_params`; the flash script writes the same values
to the board as ``board_params.py`` (:func:`board_params_source`), so they are
never typed twice.
"""

import math
from typing import Dict

from mecanum_control.esp32_wire import EFFORT_SCALE
from mecanum_control.robot_config import RobotConfig

#: A wheel driven at this duty or more that turns slower than STALL_SPEED_RAD_S for
#: STALL_TIME_MS is stalled (blocked, or its encoder unplugged). Slower to trip than
#: velocity_controller's own stall check (0.6, 0.5 rad/s, 0.5 s in pid_gains.yaml),
#: which stops the wheel first: the board's check is the last resort.
STALL_DUTY = 0.5
STALL_SPEED_RAD_S = 0.5
STALL_TIME_MS = 1000
#: A wheel driven at DEAD_DUTY or more whose encoder gives not one count is dead
#: (unplugged, or its counter's wires cut), once that has lasted DEAD_FULL_DUTY_MS
#: weighted by the duty up to STALL_DUTY: 1 s at STALL_DUTY or more (never before the
#: stall check), 2 s at 0.25, 5 s at DEAD_DUTY. Any duty
#: that should move the wheel (a free gear motor starts at about 0.05-0.1) trips it;
#: a wheel that creeps still counts, so only a silent counter does.
DEAD_DUTY = 0.1
DEAD_FULL_DUTY_MS = 500
#: A wheel driven at this duty or more that turns against it faster than
#: RUNAWAY_SPEED_RAD_S for RUNAWAY_TIME_MS is a runaway (encoder or motor reversed).
RUNAWAY_DUTY = 0.2
RUNAWAY_SPEED_RAD_S = 2.0
RUNAWAY_TIME_MS = 500
#: A wheel at this duty or less that turns faster than FREE_SPEED_RATIO of the
#: no-load speed for FREE_TIME_MS counts without a cause (encoders swapped).
FREE_DUTY = 0.03
FREE_SPEED_RATIO = 0.5
FREE_TIME_MS = 1000
#: LOW_BATTERY below this; 0 turns the check off (the board measures no battery
#: unless firmware/board_config.py names an ADC pin).
LOW_BATTERY_MV = 0


def board_params(config: RobotConfig) -> Dict[str, int]:
    """Return the board core's parameters (board_core.PARAM_NAMES) for a robot."""
    counts_per_rad = config.counts_per_wheel_rev / (2.0 * math.pi)
    return {
        'stall_duty': round(STALL_DUTY * EFFORT_SCALE),
        'stall_speed_counts_s': round(STALL_SPEED_RAD_S * counts_per_rad),
        'stall_time_ms': STALL_TIME_MS,
        'dead_duty': round(DEAD_DUTY * EFFORT_SCALE),
        'dead_full_duty_ms': DEAD_FULL_DUTY_MS,
        'runaway_duty': round(RUNAWAY_DUTY * EFFORT_SCALE),
        'runaway_speed_counts_s': round(RUNAWAY_SPEED_RAD_S * counts_per_rad),
        'runaway_time_ms': RUNAWAY_TIME_MS,
        'free_duty': round(FREE_DUTY * EFFORT_SCALE),
        'free_speed_counts_s': round(
            FREE_SPEED_RATIO * config.motor_no_load_speed_rad_s * counts_per_rad),
        'free_time_ms': FREE_TIME_MS,
        'low_battery_mv': LOW_BATTERY_MV,
    }


def board_params_source(config: RobotConfig, origin: str) -> str:
    """Return board_params.py for the board: the parameters as a MicroPython module."""
    lines = [f'"""Firmware parameters generated from {origin} (do not edit; reflash)."""', '',
             'PARAMS = {']
    lines += [f'    {name!r}: {value!r},' for name, value in board_params(config).items()]
    lines += ['}', '']
    return '\n'.join(lines)
