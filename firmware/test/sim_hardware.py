"""
A simulated hardware layer for board_core, in the subset MicroPython and CPython share.

The firmware tests run the firmware's core on it under both interpreters. Time only
moves in :meth:`SimHardware.advance`; the serial line is two byte buffers (``rx``: what
the host sent, ``tx``: what the board wrote); each wheel turns at its duty times
``full_speed_counts_s`` (no lag), unless ``blocked``; ``reversed`` flips an encoder as a
miswired one; ``unplugged`` freezes an encoder's count (the wheel still turns);
``drift_counts_s`` turns a wheel without a duty (encoders swapped, a wheel pushed).
``imu_ok``, ``estop`` and ``fault`` are the inputs.
"""

import math

TICKS_PERIOD = 1 << 30
TICKS_MASK = TICKS_PERIOD - 1
TICKS_HALF = TICKS_PERIOD // 2


class SimHardware:
    """board_core's hardware interface over a plain wheel model and byte buffers."""

    def __init__(self, start_us=0, full_speed_counts_s=7248, start_counts=0):
        self.time_us = start_us
        self.rx = bytearray()
        self.tx = bytearray()
        self.duties = [0, 0, 0, 0]
        self.set_duties_calls = 0
        self.full_speed_counts_s = full_speed_counts_s
        self._counts = [start_counts] * 4      # whole counts (ints: no float rounding)
        self._fraction = [0.0] * 4
        self.blocked = [False, False, False, False]
        self.reversed = [False, False, False, False]
        self.unplugged = [False, False, False, False]
        self._frozen = [0, 0, 0, 0]
        self.drift_counts_s = [0, 0, 0, 0]
        self.imu_ok = True
        self.estop = False
        self.fault = False
        self.brownout_reset = False
        self.battery = 12000

    # --- the core's interface ---------------------------------------------------------
    def ticks_us(self):
        """Return the clock, wrapping at 2^30 like MicroPython's time.ticks_us."""
        return self.time_us & TICKS_MASK

    def ticks_diff(self, new, old):
        """Return the signed difference of two tick readings."""
        return ((new - old + TICKS_HALF) & TICKS_MASK) - TICKS_HALF

    def ticks_add(self, ticks, delta):
        """Return the tick reading delta microseconds on."""
        return (ticks + delta) & TICKS_MASK

    def read(self):
        """Return and forget what the host sent."""
        data = bytes(self.rx)
        self.rx = bytearray()
        return data

    def write(self, data):
        """Keep what the board sends."""
        self.tx += data

    def set_duties(self, duties):
        """Apply duties (raw, FL FR RL RR)."""
        self.duties = list(duties)
        self.set_duties_calls += 1

    def read_counts(self):
        """Return the encoder counts (whole counts, as a counter reads them)."""
        out = []
        for index in range(4):
            if self.unplugged[index]:
                out.append(self._frozen[index])
                continue
            value = self._counts[index]
            value = -value if self.reversed[index] else value
            self._frozen[index] = value
            out.append(value)
        return out

    def read_imu(self):
        """Return a board lying still, or None when the IMU is failed."""
        if not self.imu_ok:
            return None
        return (0.0, 0.0, 9.80665, 0.0, 0.0, 0.0)

    def battery_mv(self):
        """Return the battery voltage, mV."""
        return self.battery

    def estop_active(self):
        """Return the e-stop input."""
        return self.estop

    def driver_fault(self):
        """Return the driver's fault output."""
        return self.fault

    # --- the simulation -----------------------------------------------------------------
    def advance(self, us):
        """Let us microseconds pass with the duties held."""
        self.time_us += us
        for index in range(4):
            speed = self.drift_counts_s[index]
            if not self.blocked[index]:
                speed += self.duties[index] * self.full_speed_counts_s / 10000
            fraction = self._fraction[index] + speed * us / 1000000
            whole = int(math.floor(fraction))
            self._counts[index] += whole
            self._fraction[index] = fraction - whole


def run(core, hw, us, step_us=1000):
    """Run the firmware loop for us microseconds: advance step_us, poll, repeat."""
    elapsed = 0
    while elapsed < us:
        hw.advance(step_us)
        core.poll()
        elapsed += step_us
