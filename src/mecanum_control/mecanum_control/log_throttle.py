"""
Per-key throttling of log messages (pure, no ROS).

rclpy's ``throttle_duration_sec`` throttles one call site; a node that warns about many
topics or frames from one place needs one throttle per topic or frame, so a warning
about one never hides a warning about another.
"""

import math
import time
from typing import Callable, Dict, Hashable


class KeyedThrottle:
    """Lets a message for each key through at most once per period_s."""

    def __init__(self, period_s: float, clock: Callable[[], float] = time.monotonic):
        if not (math.isfinite(period_s) and period_s >= 0.0):
            raise ValueError(f'period_s must be finite and >= 0, got {period_s}')
        self.period_s = float(period_s)
        self._clock = clock
        self._last: Dict[Hashable, float] = {}

    def ready(self, key: Hashable) -> bool:
        """Return True (and start a new period) if key's last message is period_s old."""
        now = self._clock()
        if now - self._last.get(key, -math.inf) >= self.period_s:
            self._last[key] = now
            return True
        return False
