"""
Time stamps from the board's clock (pure, no ROS).

Every message from the ESP32 carries the board's microsecond clock (u32, wrapping every
71.6 minutes) taken when the sample was measured. Stamping with the host's receive time
instead adds the serial and scheduling delay, and a busy host reads several frames at
once and gives them all the same stamp, which an EKF integrating the gyro turns into
heading error. :class:`BoardClockSync` maps board time to host time by the MEDIAN of
``host_receive_s - board_s`` over the last ``window_samples`` samples (400: about 3 s
of encoder and IMU reports): robust to samples that waited long (a busy host; a stall
only biases it once more than half the window arrives late at once, about 1.3 s of
samples) and to a host clock that itself lags (a node on simulated time hears /clock
late, so the smallest offset would be too small), and it follows the crystals'
drift. The stamps keep the board's exact spacing while the median holds, and move
smoothly when it moves. The price is
the median transport delay (about 1 ms on a serial link), which the stamps include.
A board whose clock counts the host's own time (the simulated board counts simulated
time, ``same_clock``) has an offset of a whole number of u32 wraps: the median is
rounded to it (when within SAME_CLOCK_TOLERANCE_S of it: the flashed firmware in the
simulator counts from its own boot, 2 s in, so its offset is the median's like a real
board's), so stamps carry no transport delay. They may lie up to one /clock step
after the host's now (a node on simulated time hears /clock in steps, and the board's
samples of a step can arrive before its /clock): clamping them to now gave two IMU
samples 10 ms apart the same stamp whenever the serial data won that race.
A board clock that goes back (the board restarted) or an offset that falls by more
than ``reset_threshold_s`` (the host clock went back, e.g. simulated time restarted; a
late sample only ever raises the offset) starts over.
"""

import bisect
from collections import deque
import math
from typing import Deque, List, Optional

U32 = 1 << 32
#: same_clock: a median offset this close (s) to a whole number of u32 wraps is rounded
#: to it (a board counting the host's time, received up to a few /clock steps late);
#: further off, the board counts its own time after all and the median stands.
SAME_CLOCK_TOLERANCE_S = 0.5


class BoardClockSync:
    """Maps board microseconds (u32, wrapping) to host seconds."""

    def __init__(self, window_samples: int = 400, reset_threshold_s: float = 1.0,
                 same_clock: bool = False):
        if not (math.isfinite(reset_threshold_s) and reset_threshold_s > 0.0):
            raise ValueError('reset_threshold_s must be finite and > 0, got '
                             f'{reset_threshold_s}')
        if window_samples < 1:
            raise ValueError(f'window_samples must be >= 1, got {window_samples}')
        self.window_samples = int(window_samples)
        self.reset_threshold_s = float(reset_threshold_s)
        self.same_clock = bool(same_clock)
        self.resets = 0
        self._last_board_us: Optional[int] = None
        self._board_s = 0.0  # unwrapped board time of the last sample, s
        self._window: Deque[float] = deque()  # offsets by arrival
        self._sorted: List[float] = []  # the window's offsets, sorted

    def offset_s(self) -> float:
        """Return the current offset host - board (s): the window's median (0 if empty)."""
        values = self._sorted
        if not values:
            return 0.0
        middle = len(values) // 2
        median = values[middle] if len(values) % 2 else 0.5 * (values[middle - 1]
                                                               + values[middle])
        if self.same_clock:
            wrap_s = U32 * 1e-6
            wraps_s = round(median / wrap_s) * wrap_s
            if abs(median - wraps_s) <= SAME_CLOCK_TOLERANCE_S:
                return wraps_s
        return median

    def stamp(self, board_time_us: int, host_now_s: float) -> float:
        """Return the host time (s) at which a sample taken at board_time_us was measured."""
        board_time_us = int(board_time_us) % U32
        if self._last_board_us is None:
            self._board_s = board_time_us * 1e-6
        else:
            step = (board_time_us - self._last_board_us + U32 // 2) % U32 - U32 // 2
            if step < 0:
                self._restart(board_time_us)
            else:
                self._board_s += step * 1e-6
        self._last_board_us = board_time_us
        offset = host_now_s - self._board_s
        if self._sorted and offset < self.offset_s() - self.reset_threshold_s:
            self._restart(board_time_us)
            offset = host_now_s - self._board_s
        self._window.append(offset)
        bisect.insort(self._sorted, offset)
        if len(self._window) > self.window_samples:
            del self._sorted[bisect.bisect_left(self._sorted, self._window.popleft())]
        return self._board_s + self.offset_s()

    def _restart(self, board_time_us: int) -> None:
        self.resets += 1
        self._window.clear()
        self._sorted.clear()
        self._board_s = board_time_us * 1e-6
