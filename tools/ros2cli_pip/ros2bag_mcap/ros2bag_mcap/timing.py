"""
When ``ros2 bag play`` publishes each message and what /clock says (pure, no rclpy).

Conventions, as rosbag2's player (Jazzy): messages are played in the order of their
log time (the receive time rosbag2 calls ``recv_timestamp``), integers in nanoseconds of
bag time. Playback starts at bag time ``start_ns`` = the bag's starting time (its first
log time) plus ``--start-offset``; a message logged before it is not played. At wall time
``origin`` (seconds, a monotonic clock) playback is at ``start_ns``, and bag time then
advances ``rate`` times as fast as wall time: a message logged at ``t`` is due
``(t - start_ns) / rate`` wall seconds after ``origin``, and /clock published ``e`` wall
seconds after ``origin`` says ``start_ns + e * rate``. With ``--loop`` the next pass
starts as soon as the last message of a pass was published: its origin is that moment,
and bag time jumps back to ``start_ns`` (rosbag2 neither waits nor fills up the rest of
the bag's duration). Wall durations are float seconds; bag times are integer ns.
"""

import math
from typing import List, Sequence, Tuple

#: Nanoseconds per second.
NS_PER_S = 1_000_000_000
#: rosbag2's "no limit" for a playback end (``play_until_timestamp``).
NO_LIMIT = -1


def check_rate(rate: float) -> float:
    """Return a playback rate (> 0, finite: 2.0 plays twice as fast); ValueError otherwise."""
    if not isinstance(rate, (int, float)) or isinstance(rate, bool) \
            or not math.isfinite(rate) or rate <= 0:
        raise ValueError(f'rate must be a finite number > 0, got {rate!r}')
    return float(rate)


def playback_start_ns(bag_start_ns: int, start_offset_s: float = 0.0) -> int:
    """
    Bag time (ns) at which playback starts: the bag's starting time plus an offset (s).

    A negative offset is ignored, as rosbag2 does (it warns).
    """
    if start_offset_s is None or start_offset_s <= 0:
        return int(bag_start_ns)
    return int(bag_start_ns) + int(round(start_offset_s * NS_PER_S))


def play_until_ns(start_ns: int, playback_duration_s: float = -1.0,
                  until_ns: int = NO_LIMIT) -> int:
    """
    Return the last bag time (ns) played, NO_LIMIT (-1) for none; rosbag2's rule.

    ``playback_duration_s`` (< 0: none) counts from ``start_ns``; ``until_ns`` (< 0: none)
    is absolute. With both, the later one wins. A duration of exactly 0 plays nothing:
    it returns 0, and :func:`shall_stop` is then true for every message.
    """
    if playback_duration_s < 0 and until_ns < 0:
        return NO_LIMIT
    from_duration = NO_LIMIT
    if playback_duration_s == 0:
        from_duration = 0
    elif playback_duration_s > 0:
        from_duration = int(start_ns) + int(round(playback_duration_s * NS_PER_S))
    return max(from_duration, int(until_ns))


def shall_stop(log_time_ns: int, until_ns: int) -> bool:
    """Tell whether playback ends before a message logged at log_time_ns (rosbag2's rule)."""
    return until_ns == 0 or (until_ns > NO_LIMIT and log_time_ns > until_ns)


def due_offset_s(log_time_ns: int, start_ns: int, rate: float) -> float:
    """Wall seconds after the pass origin at which a message logged at log_time_ns is due."""
    return (int(log_time_ns) - int(start_ns)) / NS_PER_S / rate


def bag_time_ns(elapsed_s: float, start_ns: int, rate: float) -> int:
    """Bag time (ns, what /clock says) elapsed_s wall seconds after the pass origin."""
    return int(start_ns) + int(round(max(0.0, elapsed_s) * rate * NS_PER_S))


def clock_stamp_ns(elapsed_s: float, start_ns: int, rate: float, next_due_ns: int) -> int:
    """
    Return what /clock says elapsed_s after the pass origin, the next message not out.

    The bag time, but never past the next message's log time: a player that woke late
    (a loaded machine) would otherwise say a time no message of the bag has reached yet,
    past the bag's end before the last one (seen: 91 ms past a 0.7 s bag).
    """
    return min(bag_time_ns(elapsed_s, start_ns, rate), int(next_due_ns))


def pass_schedule(log_times_ns: Sequence[int], start_ns: int, rate: float,
                  until_ns: int = NO_LIMIT) -> List[Tuple[int, float]]:
    """
    Return one pass: (index in log_times_ns, wall offset s after the origin) of each message.

    log_times_ns must be sorted (the bag's log time order). Messages before start_ns are
    skipped; the first message past the end (:func:`shall_stop`) ends the pass.
    """
    check_rate(rate)
    schedule = []
    for index, log_time in enumerate(log_times_ns):
        if log_time < start_ns:
            continue
        if shall_stop(log_time, until_ns):
            break
        schedule.append((index, due_offset_s(log_time, start_ns, rate)))
    return schedule


def loop_schedule(log_times_ns: Sequence[int], start_ns: int, rate: float, passes: int,
                  until_ns: int = NO_LIMIT,
                  delay_s: float = 0.0) -> List[Tuple[int, int, float]]:
    """
    Return ``--loop``'s (pass, index, wall offset s after the first origin), passes passes.

    Each pass begins ``delay_s`` (``--delay``) after the previous pass's last message was
    due, the first one ``delay_s`` after 0; a pass that plays nothing ends the loop (the
    player stops then, where rosbag2 would spin).
    """
    schedule: List[Tuple[int, int, float]] = []
    origin = 0.0
    for number in range(passes):
        one = pass_schedule(log_times_ns, start_ns, rate, until_ns)
        if not one:
            break
        origin += delay_s
        schedule.extend((number, index, origin + offset) for index, offset in one)
        origin += one[-1][1]
    return schedule


def clock_period_s(hz: float) -> float:
    """Wall seconds between two /clock messages at hz (> 0) per second."""
    if not hz > 0 or not math.isfinite(hz):
        raise ValueError(f'clock frequency must be a finite number > 0 (Hz), got {hz!r}')
    return 1.0 / hz


def next_tick_s(previous_tick_s: float, period_s: float, now_s: float) -> float:
    """
    Return the wall time of the /clock tick after previous_tick_s, skipping missed ones.

    Ticks stay on the grid ``previous + k * period``; ticks missed while the player was
    busy are skipped, not sent in a burst: the result is the first grid point after
    previous_tick_s that is later than now_s - period_s.
    """
    tick = previous_tick_s + period_s
    if tick <= now_s - period_s:
        missed = math.floor((now_s - tick) / period_s)
        tick += missed * period_s
        while tick <= now_s - period_s:
            tick += period_s
    return tick
