"""Tests of the authorised-zone check of text commands, cases worked out by hand."""

import math
import re

from mecanum_safety.zone import make_zone
import pytest
from robot_controller.command_parser import CommandLimits, parse_command
from robot_controller.zone_check import zone_refusal

# A 3 m x 3 m room; the robot at (1, 1) facing +x; footprint 0.2 m + margin 0.05 m, so
# base_link must keep 0.25 m from the border along the whole path.
ROOM = make_zone([[0, 0], [3, 0], [3, 3], [0, 3]])
START = (1.0, 1.0, 0.0)
RADIUS, MARGIN = 0.2, 0.05
LIMITS = CommandLimits()   # 0.2 m/s, 0.5 rad/s


def refusal(text, pose=START, zone=ROOM):
    return zone_refusal(zone, pose, parse_command(text, LIMITS), text, RADIUS, MARGIN)


def where(reason):
    """Return the (x, y) a refusal names."""
    match = re.search(r'at \((-?[\d.]+), (-?[\d.]+)\)', reason)
    assert match, reason
    return float(match.group(1)), float(match.group(2))


@pytest.mark.parametrize('text', [
    'forward 1 m',            # ends at (2, 1): clearance 1.0
    'forward 1.74 m',         # ends at (2.74, 1): clearance 0.26
    'rotate left 90 deg',     # stays at (1, 1)
    'rotate right 2 s',
    'strafe left 1.6 m',      # ends at (1, 2.6): clearance 0.4
    'strafe right 0.75 m',    # ends at (1, 0.25): clearance 0.25, exactly enough
    'backward 0.7 m',         # ends at (0.3, 1): clearance 0.3
    'diagonal forward-left 1 m',   # ends at (1.71, 1.71): clearance 1.29
])
def test_motions_that_stay_inside_are_accepted(text):
    assert refusal(text) == ''


@pytest.mark.parametrize('text, point', [
    # Ends at (3, 1), on the border; 0.25 m from it at x = 2.75, the first sample
    # (every 0.01 m) past it is x = 2.76.
    ('forward 2 m', (2.76, 1.00)),
    ('strafe left 1.8 m', (1.00, 2.76)),      # ends at (1, 2.8): clearance 0.2
    ('backward 1 m', (0.24, 1.00)),           # ends at (0, 1)
    ('strafe right 0.8 m', (1.00, 0.24)),     # ends at (1, 0.2)
])
def test_motions_that_leave_are_refused_where_they_leave(text, point):
    reason = refusal(text)
    assert reason.startswith(f'{text}: ') and 'authorised zone' in reason
    assert where(reason) == pytest.approx(point)


def test_the_heading_turns_the_body_twist():
    # Facing +y, "forward 2 m" goes to (1, 3): refused; "strafe right 1 m" to (2, 1).
    assert where(refusal('forward 2 m', pose=(1.0, 1.0, math.pi / 2))) == pytest.approx(
        (1.00, 2.76))
    assert refusal('strafe right 1 m', pose=(1.0, 1.0, math.pi / 2)) == ''
    # Facing -x, "forward 1 m" goes to (0, 1).
    assert where(refusal('forward 1 m', pose=(1.0, 1.0, math.pi))) == pytest.approx(
        (0.24, 1.00))


def test_the_whole_path_is_checked_not_only_its_end():
    # A 1 m x 1 m exclusion in a 6 m x 3 m room: forward 4 m from (1, 1) ends at (5, 1),
    # 1 m from any border, but drives through the exclusion (from x = 2.5): 0.25 m from
    # it at x = 2.25, the first sample past it x = 2.26.
    room = make_zone([[0, 0], [6, 0], [6, 3], [0, 3]],
                     [[[2.5, 0.5], [3.5, 0.5], [3.5, 1.5], [2.5, 1.5]]])
    assert where(refusal('forward 4 m at 0.5 m/s', zone=room)) == pytest.approx((2.26, 1.00))
    assert refusal('forward 1.2 m at 0.5 m/s', zone=room) == ''   # to (2.2, 1)
