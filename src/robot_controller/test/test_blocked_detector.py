"""Tests of the stop-short rule (robot_controller.blocked_detector), worked by hand."""

import pytest
from robot_controller.blocked_detector import BlockedDetector, is_pass_state, NO_OUTPUT

# blocked_speed_ratio 0.1, blocked_time_s 0.5: a motion at 0.2 m/s is held while the
# chain's output is under 0.02 m/s, and blocked after 0.5 s of that without a break;
# start_timeout_s 2: a chain that sends nothing from the motion's start blocks it after 2 s.
RATIO, TIME_S, START_S = 0.1, 0.5, 2.0


def feed(detector, start_s, end_s, twist, period_s=0.05):
    """Give the detector one output twist every period_s from start_s to end_s."""
    count = round((end_s - start_s) / period_s)
    for index in range(count + 1):
        detector.on_output(start_s + index * period_s, *twist)


def started(vx=0.2, vy=0.0, wz=0.0, now_s=10.0):
    detector = BlockedDetector(RATIO, TIME_S, START_S)
    detector.start(now_s, vx, vy, wz)
    return detector


def test_the_chain_passing_the_command_never_blocks():
    detector = started()
    feed(detector, 10.05, 13.0, (0.2, 0.0, 0.0))
    assert detector.check(13.0) is None


def test_a_slowdown_above_the_ratio_is_not_a_block():
    detector = started()
    feed(detector, 10.05, 13.0, (0.021, 0.0, 0.0))     # 0.021 >= 0.1 * 0.2
    assert detector.check(13.0) is None


def test_output_held_at_zero_blocks_after_blocked_time():
    detector = started()
    detector.on_state('collision_monitor', 'STOP PolygonStop')
    feed(detector, 10.05, 10.5, (0.0, 0.0, 0.0))       # held since 10.05
    assert detector.check(10.5) is None                 # 0.45 s
    detector.on_output(10.55, 0.0, 0.0, 0.0)
    assert detector.check(10.55) == 'collision_monitor STOP PolygonStop'   # 0.5 s


def test_a_speed_just_under_the_ratio_holds():
    detector = started()
    feed(detector, 10.0, 10.5, (0.019, 0.0, 0.0))      # 0.019 < 0.02
    assert detector.check(10.5) is not None


def test_a_break_restarts_the_count():
    detector = started()
    feed(detector, 10.0, 10.3, (0.0, 0.0, 0.0))
    detector.on_output(10.35, 0.2, 0.0, 0.0)            # moving again: not continuous
    feed(detector, 10.4, 10.85, (0.0, 0.0, 0.0))        # held since 10.4
    assert detector.check(10.85) is None                # 0.45 s
    assert detector.check(10.9) is not None             # 0.5 s, the last output holds


def test_no_output_at_all_stops_after_start_timeout():
    detector = started()
    assert detector.check(11.99) is None
    assert detector.first_output_s is None
    assert detector.check(12.0) == NO_OUTPUT


def test_a_late_first_output_is_when_the_motion_starts():
    detector = started()
    detector.on_output(11.5, 0.2, 0.0, 0.0)             # the chain found its stages late
    detector.on_output(11.55, 0.2, 0.0, 0.0)
    assert detector.first_output_s == 11.5
    assert detector.check(12.0) is None                 # past 2 s, but it passes
    assert detector.check(12.05) == NO_OUTPUT           # 0.5 s after its last output
    detector.start(20.0, 0.2, 0.0, 0.0)                 # the next motion waits afresh
    assert detector.first_output_s is None


def test_the_chain_going_silent_mid_motion_stops():
    detector = started()
    feed(detector, 10.05, 11.0, (0.2, 0.0, 0.0))        # last output at 11.0
    assert detector.check(11.45) is None
    assert detector.check(11.5) == NO_OUTPUT


def test_rotations_compare_the_yaw_rate_and_ignore_the_uncommanded_linear_part():
    detector = started(vx=0.0, wz=0.5)                  # held under 0.05 rad/s
    feed(detector, 10.0, 10.5, (0.3, 0.0, 0.06))        # 0.06 rad/s: turning
    assert detector.check(10.5) is None
    feed(detector, 10.55, 11.05, (0.3, 0.0, -0.04))     # |-0.04| < 0.05: held from 10.55
    assert detector.check(11.0) is None
    assert detector.check(11.05) is not None


def test_diagonal_moves_compare_the_linear_speed():
    detector = started(vx=0.2 * 0.5 ** 0.5, vy=0.2 * 0.5 ** 0.5)   # 0.2 m/s
    feed(detector, 10.0, 10.5, (0.015, 0.0, 0.0))       # 0.015 < 0.02
    assert detector.check(10.5) is not None
    detector = started(vx=0.2 * 0.5 ** 0.5, vy=0.2 * 0.5 ** 0.5)
    feed(detector, 10.0, 10.5, (0.015, 0.015, 0.0))     # hypot 0.0212 >= 0.02
    assert detector.check(10.5) is None


def test_a_non_finite_output_counts_as_holding():
    detector = started()
    feed(detector, 10.0, 10.5, (float('nan'), 0.0, 0.0))
    assert detector.check(10.5) is not None


@pytest.mark.parametrize('states, reason', [
    # The stage now saying STOP wins over one now limiting otherwise.
    ([('zone_guard', 'STOP at the border'), ('collision_monitor', 'LIMIT PolygonLimit')],
     'zone_guard STOP at the border'),
    # Only stages not passing count; the collision monitor passes zero on.
    ([('collision_monitor', 'STOP PolygonStop'), ('zone_guard', 'ALLOW')],
     'collision_monitor STOP PolygonStop'),
    # Two stages limiting, none stopping: the most recent.
    ([('collision_monitor', 'APPROACH FootprintApproach'),
      ('zone_guard', 'SCALE 0.05 (0.26 m from the border)')],
     'zone_guard SCALE 0.05 (0.26 m from the border)'),
    # Every stage passes now: the most recent limit seen during the motion.
    ([('collision_monitor', 'STOP invalid source'), ('collision_monitor', 'DO_NOTHING'),
      ('zone_guard', 'ALLOW')], 'collision_monitor STOP invalid source'),
    ([], 'the command chain (its output stayed under 0.1 of the command; '
         'no stage reported a limit)'),
])
def test_reason_names_the_stage_holding_the_robot(states, reason):
    detector = started()
    for stage, state in states:
        detector.on_state(stage, state)
    feed(detector, 10.0, 10.5, (0.0, 0.0, 0.0))
    assert detector.check(10.5) == reason


def test_limits_seen_before_the_motion_are_not_reasons_once_passed():
    detector = BlockedDetector(RATIO, TIME_S)
    detector.on_state('zone_guard', 'STOP at the border')
    detector.on_state('zone_guard', 'ALLOW')
    detector.start(10.0, 0.2, 0.0, 0.0)
    feed(detector, 10.0, 10.5, (0.0, 0.0, 0.0))
    assert detector.check(10.5).startswith('the command chain')


def test_nothing_is_blocked_while_no_motion_runs():
    detector = BlockedDetector(RATIO, TIME_S)
    detector.on_output(1.0, 0.0, 0.0, 0.0)
    assert detector.check(5.0) is None
    detector.start(10.0, 0.2, 0.0, 0.0)
    detector.stop()
    assert detector.check(20.0) is None


def test_a_new_motion_starts_afresh():
    detector = started()
    feed(detector, 10.0, 10.45, (0.0, 0.0, 0.0))
    detector.start(10.45, 0.0, 0.2, 0.0)                # replaced: count from 10.45
    feed(detector, 10.5, 10.9, (0.0, 0.0, 0.0))
    assert detector.check(10.9) is None                 # held since 10.5: 0.4 s
    assert detector.check(11.0) is not None


def test_pass_states():
    assert is_pass_state('DO_NOTHING') and is_pass_state('ALLOW') and is_pass_state('')
    assert not is_pass_state('STOP PolygonStop')
    assert not is_pass_state('SCALE 0.42 (0.31 m from the border)')


@pytest.mark.parametrize('ratio, time_s, message', [
    (0.0, 0.5, 'blocked_speed_ratio'), (1.0, 0.5, 'blocked_speed_ratio'),
    (float('nan'), 0.5, 'blocked_speed_ratio'), (0.1, 0.0, 'blocked_time_s'),
    (0.1, float('inf'), 'blocked_time_s'),
])
def test_bad_settings_are_refused(ratio, time_s, message):
    with pytest.raises(ValueError, match=message):
        BlockedDetector(ratio, time_s)


@pytest.mark.parametrize('start_s', [0.4, float('nan'), float('inf')])
def test_a_start_timeout_shorter_than_blocked_time_or_not_finite_is_refused(start_s):
    with pytest.raises(ValueError, match='start_timeout_s'):
        BlockedDetector(RATIO, TIME_S, start_s)
