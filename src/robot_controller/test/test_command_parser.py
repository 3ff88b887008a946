"""Tests of the text command grammar, cases worked out by hand."""

import math

import pytest
from robot_controller.command_parser import CommandError, CommandLimits, parse_command

LIMITS = CommandLimits(linear_speed_mps=0.2, angular_speed_radps=0.5, max_linear_speed_mps=0.5,
                       max_angular_speed_radps=1.5, default_duration_s=2.0,
                       max_duration_s=60.0)
H = math.sqrt(0.5)


@pytest.mark.parametrize('text, twist, duration', [
    ('forward', (0.2, 0.0, 0.0), 2.0),                       # default speed and duration
    ('forward 0.5 m', (0.2, 0.0, 0.0), 2.5),                 # 0.5 m at 0.2 m/s
    ('FORWARD 50 cm at 0.25 m/s', (0.25, 0.0, 0.0), 2.0),
    ('backward 1s', (-0.2, 0.0, 0.0), 1.0),
    ('back 0.1 m', (-0.2, 0.0, 0.0), 0.5),
    ('strafe left 2 s', (0.0, 0.2, 0.0), 2.0),
    ('strafe right 0.4 m at 0.4 m/s', (0.0, -0.4, 0.0), 1.0),
    ('left 0.2 m', (0.0, 0.2, 0.0), 1.0),
    ('diagonal forward-left 0.2 m', (0.2 * H, 0.2 * H, 0.0), 1.0),
    ('diagonal backward-right 1 s', (-0.2 * H, -0.2 * H, 0.0), 1.0),
    ('rotate left 90 deg', (0.0, 0.0, 0.5), math.pi),      # pi/2 rad at 0.5 rad/s
    ('rotate right 1.5 rad at 0.75 rad/s', (0.0, 0.0, -0.75), 2.0),
    ('turn', (0.0, 0.0, 0.5), 2.0),                          # the seed's "turn"
    ('turn right 90 deg at 45 deg/s', (0.0, 0.0, -math.pi / 4), 2.0),
    ('rotate 180 deg', (0.0, 0.0, 0.5), 2 * math.pi),
    ('forward 0.3 m 0.3 m/s', (0.3, 0.0, 0.0), 1.0),         # "at" is optional
])
def test_parses_motions(text, twist, duration):
    motion = parse_command(text, LIMITS)
    assert (motion.vx, motion.vy, motion.wz) == pytest.approx(twist)
    assert motion.duration_s == pytest.approx(duration)
    assert not motion.is_stop


def test_stop():
    motion = parse_command('  Stop ', LIMITS)
    assert motion.is_stop and motion.duration_s == 0.0
    assert (motion.vx, motion.vy, motion.wz) == (0.0, 0.0, 0.0)


@pytest.mark.parametrize('text, reason', [
    ('', 'empty'),
    ('fly 2 m', 'unknown command'),
    ('strafe', 'needs a direction'),
    ('strafe up 1 m', 'needs a direction'),
    ('forward two metres', 'number with a unit'),
    ('forward 1 furlong', 'does not fit'),
    ('forward 90 deg', 'does not fit'),
    ('rotate left 1 m', 'does not fit'),
    ('forward -1 m', 'must be positive'),
    ('forward 0 s', 'must be positive'),
    ('forward 1 m 2 s', 'either one'),
    ('forward 1 m at', 'needs a speed'),
    ('forward 1 m at 2 m/s', 'exceeds the limit'),
    ('rotate left at 10 rad/s', 'exceeds the limit'),
    ('forward nan m', 'number with a unit'),
    ('forward inf m', 'number with a unit'),
    ('forward 1e400 m', 'finite'),
    ('forward 100 m', 'over the 60 s limit'),
    ('stop now', 'takes no arguments'),
])
def test_rejects_with_reason(text, reason):
    with pytest.raises(CommandError, match=reason):
        parse_command(text, LIMITS)


def test_rejects_non_text():
    with pytest.raises(CommandError):
        parse_command(None, LIMITS)
