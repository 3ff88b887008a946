"""When play publishes each message and what /clock says: cases worked out by hand."""

import pytest
from ros2bag_mcap.timing import (bag_time_ns, check_rate, clock_period_s, clock_stamp_ns,
                                 due_offset_s, loop_schedule, next_tick_s, NO_LIMIT, pass_schedule,
                                 play_until_ns, playback_start_ns, shall_stop)

S = 10 ** 9
MS = 10 ** 6
#: Recorded log times: 10.0, 10.1, 10.3 and 10.6 s.
STAMPS = [10 * S, 10 * S + 100 * MS, 10 * S + 300 * MS, 10 * S + 600 * MS]


def rounded(schedule):
    """Return a schedule with its wall offsets (float s) rounded to microseconds."""
    return [(*entry[:-1], round(entry[-1], 6)) for entry in schedule]


def test_rate_one_keeps_the_recorded_spacing():
    assert rounded(pass_schedule(STAMPS, 10 * S, 1.0)) == [
        (0, 0.0), (1, 0.1), (2, 0.3), (3, 0.6)]


def test_rate_two_halves_and_rate_half_doubles_the_spacing():
    assert rounded(pass_schedule(STAMPS, 10 * S, 2.0)) == [
        (0, 0.0), (1, 0.05), (2, 0.15), (3, 0.3)]
    assert rounded(pass_schedule(STAMPS, 10 * S, 0.5)) == [
        (0, 0.0), (1, 0.2), (2, 0.6), (3, 1.2)]


def test_start_offset_skips_earlier_messages_and_counts_from_the_offset():
    start = playback_start_ns(10 * S, 0.2)
    assert start == 10 * S + 200 * MS
    # 10.3 s is due 0.1 s after the origin, 10.6 s 0.4 s after; 10.0 and 10.1 are skipped.
    assert rounded(pass_schedule(STAMPS, start, 1.0)) == [(2, 0.1), (3, 0.4)]
    # A message exactly at the start is due at once.
    assert rounded(pass_schedule(STAMPS, playback_start_ns(10 * S, 0.3), 2.0)) == [
        (2, 0.0), (3, 0.15)]
    # Negative offsets are ignored (rosbag2 warns); beyond the end nothing is played.
    assert playback_start_ns(10 * S, -1.0) == 10 * S
    assert pass_schedule(STAMPS, playback_start_ns(10 * S, 0.7), 1.0) == []


def test_loop_starts_the_next_pass_when_the_last_message_was_due():
    # rate 2: a pass lasts 0.3 s; the first message of the next pass goes with the last.
    assert rounded(loop_schedule(STAMPS, 10 * S, 2.0, passes=3)) == [
        (0, 0, 0.0), (0, 1, 0.05), (0, 2, 0.15), (0, 3, 0.3),
        (1, 0, 0.3), (1, 1, 0.35), (1, 2, 0.45), (1, 3, 0.6),
        (2, 0, 0.6), (2, 1, 0.65), (2, 2, 0.75), (2, 3, 0.9)]


def test_loop_with_start_offset_and_delay_restarts_at_the_offset_after_the_delay():
    start = playback_start_ns(10 * S, 0.2)
    # Each pass: wait 0.5 s, then 10.3 s at +0.1 and 10.6 s at +0.4.
    assert rounded(loop_schedule(STAMPS, start, 1.0, passes=2, delay_s=0.5)) == [
        (0, 2, 0.6), (0, 3, 0.9), (1, 2, 1.5), (1, 3, 1.8)]


def test_loop_of_nothing_ends():
    assert loop_schedule(STAMPS, 11 * S, 1.0, passes=5) == []


def test_playback_duration_and_until():
    # 0.25 s from 10.0 s: ends at 10.25 s, so 10.0 and 10.1 play, 10.3 stops the pass.
    until = play_until_ns(10 * S, 0.25, NO_LIMIT)
    assert until == 10 * S + 250 * MS
    assert [i for i, _ in pass_schedule(STAMPS, 10 * S, 1.0, until)] == [0, 1]
    # An absolute end is inclusive: a message at 10.3 s plays when the end is 10.3 s.
    until = play_until_ns(10 * S, -1.0, 10 * S + 300 * MS)
    assert [i for i, _ in pass_schedule(STAMPS, 10 * S, 1.0, until)] == [0, 1, 2]
    # Both given: the later end wins (rosbag2).
    assert play_until_ns(10 * S, 0.5, 10 * S + 100 * MS) == 10 * S + 500 * MS
    # Neither: no limit. A duration of exactly 0 plays nothing.
    assert play_until_ns(10 * S) == NO_LIMIT
    assert not shall_stop(99 * S, NO_LIMIT)
    assert play_until_ns(10 * S, 0.0) == 0
    assert pass_schedule(STAMPS, 10 * S, 1.0, 0) == []


def test_due_offset_and_clock_time_are_inverse():
    start = 10 * S
    assert due_offset_s(10 * S + 600 * MS, start, 2.0) == pytest.approx(0.3)
    # /clock 0.3 wall s after the origin at rate 2 says 10.6 s; before the origin, the start.
    assert bag_time_ns(0.3, start, 2.0) == 10 * S + 600 * MS
    assert bag_time_ns(0.0, start, 0.5) == start
    assert bag_time_ns(-1.0, start, 1.0) == start
    assert bag_time_ns(4.0, start, 0.5) == 12 * S


def test_clock_ticks_stay_on_their_grid_and_skip_missed_ticks():
    assert clock_period_s(40.0) == pytest.approx(0.025)
    assert clock_period_s(4.0) == 0.25
    # On time: the next grid point.
    assert next_tick_s(1.0, 0.25, 1.1) == 1.25
    # Late by 0.85 s: ticks 1.25 .. 1.75 are skipped, 2.0 is due at once, 2.25 next.
    assert next_tick_s(1.0, 0.25, 2.1) == 2.0
    assert next_tick_s(2.0, 0.25, 2.1) == 2.25


@pytest.mark.parametrize('rate', [0, -1.0, float('nan'), float('inf'), True, '2'])
def test_bad_rates_are_refused(rate):
    with pytest.raises(ValueError, match='rate'):
        check_rate(rate)


@pytest.mark.parametrize('hz', [0, -40.0, float('inf')])
def test_bad_clock_frequencies_are_refused(hz):
    with pytest.raises(ValueError, match='clock frequency'):
        clock_period_s(hz)


def test_the_clock_never_passes_the_next_message():
    start = 10 * S
    # On time: the bag time.
    assert clock_stamp_ns(0.3, start, 1.0, start + 700 * MS) == start + 300 * MS
    # Woken 91 ms after the last message (0.7 s) was due: still its time, not past the bag.
    assert clock_stamp_ns(0.791, start, 1.0, start + 700 * MS) == start + 700 * MS
    assert clock_stamp_ns(0.5, start, 2.0, start + 700 * MS) == start + 700 * MS
