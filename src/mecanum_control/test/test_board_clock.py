"""Tests of mecanum_control.board_clock: stamps from the board's clock, by hand."""

from mecanum_control.board_clock import BoardClockSync, U32
import pytest


def test_the_median_offset_keeps_the_board_spacing_through_a_late_batch():
    sync = BoardClockSync()
    # Board 1.00, 1.01, 1.02 s received 2, 1 and 3 ms late at host time 100 + board.
    assert sync.stamp(1_000_000, 101.002) == pytest.approx(101.002)   # median 2 ms
    assert sync.stamp(1_010_000, 101.011) == pytest.approx(101.0115)  # median 1.5 ms
    assert sync.stamp(1_020_000, 101.023) == pytest.approx(101.022)   # median 2 ms
    for i in range(3, 30):  # 27 more samples, 2, 1, 3 ms late again: median 2 ms
        board_us = 1_000_000 + 10_000 * i
        sync.stamp(board_us, 100.0 + board_us * 1e-6 + (0.002, 0.001, 0.003)[i % 3])
    # A busy host reads three samples at once, 40, 30 and 20 ms late. Ten offsets each
    # of 1, 2 and 3 ms and these three: the median stays 2 ms, so the stamps keep the
    # board's 10 ms spacing instead of all reading the same receive time.
    batch = (1_300_000, 1_310_000, 1_320_000)
    stamps = [sync.stamp(board_us, 101.34) for board_us in batch]
    assert stamps == pytest.approx([101.302, 101.312, 101.322], abs=1e-9)


def test_a_lagging_host_clock_does_not_pull_the_stamps_early():
    sync = BoardClockSync()
    # Simulated time: board = true time; the node hears /clock 0..60 ms late, mostly
    # on time. The stamps must stay near the true time, not 60 ms early.
    lags = [0.0, 0.0, 0.06, 0.0, 0.03, 0.0, 0.0, 0.05, 0.0, 0.0] * 10
    for i, lag in enumerate(lags):
        true_s = 10.0 + 0.01 * i
        stamp = sync.stamp(int(round(true_s * 1e6)), true_s - lag)
        if i > 10:
            assert stamp == pytest.approx(true_s, abs=1e-9)


def test_old_offsets_leave_the_window_so_drift_is_followed():
    sync = BoardClockSync(window_samples=2)
    sync.stamp(0, 10.000)
    # The host clock runs 100 ppm fast: the offset grows 0.1 ms per second.
    for second in range(1, 6):
        stamp = sync.stamp(second * 1_000_000, 10.0 + second * 1.0001)
    # Only the last two samples (4 s and 5 s) are in the window: median 10.00045.
    assert stamp == pytest.approx(15.00045, abs=1e-9)


def test_the_board_clock_wrap_is_unwrapped():
    sync = BoardClockSync()
    assert sync.stamp(U32 - 5_000, 50.0) == pytest.approx(50.0)  # 5 ms before the wrap
    assert sync.stamp(5_000, 50.010) == pytest.approx(50.010)   # 10 ms later, wrapped
    assert sync.resets == 0


def test_a_board_restart_starts_over():
    sync = BoardClockSync()
    sync.stamp(80_000_000, 100.0)
    assert sync.stamp(20_000, 100.5) == pytest.approx(100.5)  # board clock went back
    assert sync.resets == 1
    assert sync.stamp(30_000, 100.51) == pytest.approx(100.51)


def test_a_host_clock_going_back_starts_over_but_a_late_sample_does_not():
    sync = BoardClockSync(reset_threshold_s=1.0)
    sync.stamp(1_000_000, 10.0)
    sync.stamp(1_010_000, 10.01)
    sync.stamp(1_020_000, 10.02)
    # A sample stuck 3 s in a stalled host: stamped by the board clock, no reset.
    assert sync.stamp(1_030_000, 13.0) == pytest.approx(10.03)
    assert sync.resets == 0
    # Simulated time restarted from 0 while the board ran on.
    assert sync.stamp(1_040_000, 0.5) == pytest.approx(0.5)
    assert sync.resets == 1


@pytest.mark.parametrize('kwargs', [{'window_samples': 0},
                                    {'reset_threshold_s': float('nan')}])
def test_bad_settings_are_refused(kwargs):
    with pytest.raises(ValueError):
        BoardClockSync(**kwargs)


def test_a_board_on_the_host_clock_gets_no_transport_delay():
    """The simulated board counts simulated time: stamps are its clock, wraps included."""
    wrap_s = U32 * 1e-6
    sync = BoardClockSync(same_clock=True)
    # Received 30-70 ms late, with the host clock 2 wraps ahead of the u32 counter.
    for i, late in enumerate((0.03, 0.05, 0.07, 0.04, 0.06)):
        board_s = 10.0 + 0.01 * i
        stamp = sync.stamp(int(round(board_s * 1e6)), 2 * wrap_s + board_s + late)
        assert stamp == pytest.approx(2 * wrap_s + board_s, abs=1e-9)
    # A host clock one step behind the board (/clock heard after the samples): the
    # samples keep their own times, 10 ms apart, not the host's now.
    for board_s in (10.1, 10.11):
        assert sync.stamp(int(round(board_s * 1e6)), 2 * wrap_s + 10.09) == pytest.approx(
            2 * wrap_s + board_s, abs=1e-9)
    median = BoardClockSync()
    assert median.stamp(10_000_000, 10.05) == pytest.approx(10.05)  # the delay stays in


def test_a_board_counting_from_its_own_boot_keeps_the_median_with_same_clock():
    """The flashed firmware in the simulator boots 2 s in: its clock is not the host's."""
    sync = BoardClockSync(same_clock=True)
    # Board time 0 at host 2.0 s (the REPL window), received 1-5 ms late.
    for i, late in enumerate((0.001, 0.005, 0.003)):
        board_s = 0.01 * i
        stamp = sync.stamp(int(round(board_s * 1e6)), 2.0 + board_s + late)
    assert stamp == pytest.approx(2.0 + 0.02 + 0.003, abs=1e-9)   # the median offset
