# noqa: A005 (it shadows the built-in time module on purpose)
"""
The simulator's clock for the firmware as flashed, in co-simulation (MicroPython unix port).

Staged as ``time.py`` beside main.py, where it shadows MicroPython's built-in ``time``,
so main.py, the hardware layer and the IMU driver run unchanged on simulated time.
Time moves only when the firmware sleeps: a sleep past the end of the physics step in
progress hands the step back to the simulator (the wheels' drives, the watchdog's last
feed) and waits for the next one. The ticks are the ESP32 port's: microseconds and
milliseconds wrapping at 2^30 (MICROPY_PY_TIME_TICKS_PERIOD), from the simulated time
of the board's boot.

The link: two pipes, their descriptors in MECANUM_COSIM_FDS (``<read> <write>``), one
ASCII line per message (robot_simulation/firmware_board.py is the other end).

* simulator -> board: ``S <end_us> <c0> <c1> <c2> <c3>``: run up to end_us (simulated
  microseconds since the simulation began); the encoders' counts now, forward
  positive, FL FR RL RR. ``A <ax> <ay> <az> <gx> <gy> <gz>`` (m/s^2, rad/s) or
  ``A -`` (no answer: the IMU is silent): the IMU sample asked for.
* board -> simulator: ``I``: an IMU sample, please (an I2C read, now). ``D <d0> <d1>
  <d2> <d3> <fed_us> <wdt_ms>``: reached end_us; each wheel's drive (signed duty_u16
  the pins make, positive rolling the robot forward), the watchdog's last feed
  (simulated us; -1: never) and its timeout (0: not started).
"""

import os

TICKS_PERIOD = 1 << 30
_TICKS_MASK = TICKS_PERIOD - 1
_TICKS_HALF = TICKS_PERIOD // 2


class Link:
    """The co-simulation's end on the board: simulated now, the step's end, the counts."""

    def __init__(self):
        fds = os.getenv('MECANUM_COSIM_FDS').split()
        self._in = open('/dev/fd/' + fds[0], 'rb')
        self._out = open('/dev/fd/' + fds[1], 'wb')
        self.now_us = int(os.getenv('MECANUM_COSIM_BOOT_US') or '0')
        self.end_us = self.now_us
        self.counts = [0, 0, 0, 0]
        self.drives = [0, 0, 0, 0]    # set by machine's wheels
        self.fed_us = -1
        self.wdt_ms = 0
        self._stepping = False         # a step is in progress: its end is answered

    def _line(self):
        line = self._in.readline()
        if not line:
            raise SystemExit(0)   # the simulator closed the link: the board is off
        return line.decode().split()

    def advance(self, target_us):
        """Move simulated now to target_us, handing each step past its end back."""
        while target_us > self.end_us:
            if self._stepping:
                drives = self.drives
                self._out.write(('D %d %d %d %d %d %d\n' % (
                    drives[0], drives[1], drives[2], drives[3], self.fed_us,
                    self.wdt_ms)).encode())
            fields = self._line()
            if fields[0] != 'S':
                raise SystemExit('co-simulation: expected a step, got %r' % (fields,))
            self.end_us = int(fields[1])
            self.counts = [int(value) for value in fields[2:6]]
            self._stepping = True
        self.now_us = target_us

    def imu(self):
        """Return the IMU's sample now (six floats), or None when it does not answer."""
        self._out.write(b'I\n')
        fields = self._line()
        if fields[0] != 'A' or fields[1] == '-':
            return None
        return [float(value) for value in fields[1:7]]


cosim = Link()


def ticks_us():
    """Return simulated microseconds, wrapping at 2^30."""
    return cosim.now_us & _TICKS_MASK


def ticks_ms():
    """Return simulated milliseconds, wrapping at 2^30."""
    return (cosim.now_us // 1000) & _TICKS_MASK


def ticks_cpu():
    """Return ticks_us (the ESP32's ticks_cpu counts microseconds too)."""
    return ticks_us()


def ticks_diff(new, old):
    """Return the signed difference of two tick readings."""
    return ((new - old + _TICKS_HALF) & _TICKS_MASK) - _TICKS_HALF


def ticks_add(ticks, delta):
    """Return the tick reading delta on from ticks."""
    return (ticks + delta) & _TICKS_MASK


def sleep_us(us):
    """Let us microseconds of simulated time pass."""
    if us > 0:
        cosim.advance(cosim.now_us + us)


def sleep_ms(ms):
    """Let ms milliseconds of simulated time pass."""
    if ms > 0:
        cosim.advance(cosim.now_us + ms * 1000)


def sleep(seconds):
    """Let seconds of simulated time pass."""
    if seconds > 0:
        cosim.advance(cosim.now_us + int(seconds * 1000000))


def time():
    """Return whole simulated seconds."""
    return cosim.now_us // 1000000


def time_ns():
    """Return simulated nanoseconds."""
    return cosim.now_us * 1000
