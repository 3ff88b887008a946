"""
A stand-in for the ESP32's machine module, for main.py under MicroPython's unix port.

The firmware runs as flashed (main.py, board_config.py, the hardware layer, the core);
only this module is not the board's. Signatures are the ESP32 port's (the pinned
ESP32 stubs, keyword-only arguments where they have them, positional-only ones
renamed; I2C's ``timeout``, in
microseconds, is the ESP32 port's, absent from the generic stubs). What it simulates:

* four wheels as board_config wires them: each encoder counts what its motor's pins
  drive (sign-magnitude: PWM level, IN1/IN2; brake and coast stop it at once), at
  FULL_SPEED_COUNTS_S for full PWM, through the motor's and the encoder's inverts;
* an MPU-6050 lying still (WHO_AM_I 0x68, 1 g on z);
* input pins read from the file named by the environment's MECANUM_STANDIN_INPUTS
  (lines ``<gpio> <level>``, re-read at most every INPUTS_PERIOD_MS; a pull-up pin
  not listed reads 1);
* events on stderr, one line each, for the test harness: ``W`` (the watchdog fed, at
  most every WDT_REPORT_MS; the harness is the watchdog: it resets the process when
  the feeds stop for the WDT's timeout), ``M <wheel> <signed duty_u16>`` (a wheel's
  drive changed: the level the pins make, positive rolling the robot forward through
  the motor's invert, 0 brake or coast),
  ``WDT <timeout_ms>`` (the watchdog started).

In co-simulation with the physics simulator (the clock of ``time.py`` staged beside
main.py: ``time.cosim``) the wheels are the simulated robot's instead: the drives go
to the simulator at the end of each step, the encoders count what it sends, the
MPU-6050 answers with the simulated body's samples (quantised to its registers:
+-4 g, +-500 deg/s), or not at all while the simulator's IMU is silent, and the
watchdog's feeds go to the simulator, which resets the board. No events on stderr.
"""

import os
import struct
import sys
import time

import board_config

FULL_SPEED_COUNTS_S = 7248      # 34.5 rad/s at 1320 counts per wheel revolution
INPUTS_PERIOD_MS = 5
WDT_REPORT_MS = 100
_PWM_FULL = 65535


def _event(text):
    sys.stderr.write(text + '\n')


#: The co-simulation's link (time.py staged beside main.py), or None.
_COSIM = getattr(time, 'cosim', None)


class _Wheels:
    """The four wheels: positions in counts, integrated at each change and read."""

    def __init__(self):
        self.position = [0.0, 0.0, 0.0, 0.0]
        self.drive = [0, 0, 0, 0]          # signed duty_u16 the pins make (IN1 high: +)
        self.at_us = time.ticks_us()
        self.motor_of_pin = {}
        for index, wiring in enumerate(board_config.MOTORS):
            for key in ('pwm', 'in1', 'in2', 'dir'):
                if key in wiring:
                    self.motor_of_pin[wiring[key]] = index

    def advance(self):
        """Move every wheel by its drive since the last call."""
        now = time.ticks_us()
        seconds = time.ticks_diff(now, self.at_us) / 1000000
        self.at_us = now
        for index in range(4):
            sign = -1 if board_config.MOTORS[index]['invert'] else 1
            self.position[index] += (sign * self.drive[index] / _PWM_FULL
                                     * FULL_SPEED_COUNTS_S * seconds)

    def count(self, index):
        """Return a wheel's count, forward positive."""
        self.advance()
        return int(self.position[index])

    def changed(self, index, drive, forward_drive):
        """Take a wheel's new drive (as the pins make it, and rolling forward)."""
        self.advance()
        self.drive[index] = drive
        _event('M %d %d' % (index, forward_drive))

    def pins_changed(self, pin_number):
        """Recompute the drive of the motor this pin belongs to (if any)."""
        index = self.motor_of_pin.get(pin_number)
        if index is None:
            return
        wiring = board_config.MOTORS[index]
        if 'dir' in wiring:
            level = _PWMS[wiring['pwm']].level if wiring['pwm'] in _PWMS else 0
            forward = _PINS[wiring['dir']].level if wiring['dir'] in _PINS else 0
            drive = level if forward else -level
        elif 'pwm' in wiring:
            level = _PWMS[wiring['pwm']].level if wiring['pwm'] in _PWMS else 0
            in1 = _PINS[wiring['in1']].level if wiring['in1'] in _PINS else 0
            in2 = _PINS[wiring['in2']].level if wiring['in2'] in _PINS else 0
            drive = level if in1 and not in2 else -level if in2 and not in1 else 0
        else:
            first = _PWMS[wiring['in1']].level if wiring['in1'] in _PWMS else 0
            second = _PWMS[wiring['in2']].level if wiring['in2'] in _PWMS else 0
            drive = first - second if not (first and second) else 0
        if drive != self.drive[index]:
            self.changed(index, drive, -drive if wiring['invert'] else drive)


class _SimulatedWheels(_Wheels):
    """The simulated robot's wheels (co-simulation): drives out, counts in."""

    def __init__(self):
        super().__init__()
        self.forward = _COSIM.drives   # the list the link sends at each step's end

    def count(self, index):
        """Return the simulator's count of a wheel, forward positive."""
        return _COSIM.counts[index]

    def changed(self, index, drive, forward_drive):
        """Take a wheel's new drive: the simulator gets it at the step's end."""
        self.drive[index] = drive
        self.forward[index] = forward_drive


_PINS = {}
_PWMS = {}
_WHEELS = _Wheels() if _COSIM is None else _SimulatedWheels()
_inputs = {}
_inputs_at = [None]


def _input_level(number):
    """Return the level the inputs file gives a pin, or None."""
    path = os.getenv('MECANUM_STANDIN_INPUTS')
    if not path:
        return None
    now = time.ticks_ms()
    if _inputs_at[0] is None or time.ticks_diff(now, _inputs_at[0]) >= INPUTS_PERIOD_MS:
        _inputs_at[0] = now
        _inputs.clear()
        try:
            with open(path) as levels:
                for line in levels:
                    parts = line.split()
                    if len(parts) == 2:
                        _inputs[int(parts[0])] = int(parts[1])
        except OSError:
            pass
    return _inputs.get(number)


class Pin:
    """A GPIO: mode, pull, level; inputs read the inputs file."""

    IN = 1
    OUT = 3
    OPEN_DRAIN = 7
    PULL_UP = 2
    PULL_DOWN = 1

    def __init__(self, number, mode=-1, pull=-1, *, value=None, drive=None, alt=None):
        self.number = number
        self.mode = mode
        self.pull = pull
        self.level = 0 if value is None else value
        _PINS[number] = self
        _WHEELS.pins_changed(number)

    def value(self, *level):
        """Read the level, or set it (outputs)."""
        if not level:
            if self.mode == Pin.IN:
                given = _input_level(self.number)
                if given is not None:
                    return given
                return 1 if self.pull == Pin.PULL_UP else 0
            return self.level
        self.level = 1 if level[0] else 0
        _WHEELS.pins_changed(self.number)
        return None


class PWM:
    """A PWM output: frequency and duty_u16."""

    def __init__(self, dest, *, freq=5000, duty_u16=None, duty_ns=None):
        self.pin = dest
        self.freq = freq
        self.level = 0 if duty_u16 is None else duty_u16
        _PWMS[dest.number] = self
        _WHEELS.pins_changed(dest.number)

    def duty_u16(self, *value):
        """Read or set the duty (0..65535)."""
        if not value:
            return self.level
        self.level = value[0]
        _WHEELS.pins_changed(self.pin.number)
        return None


class Encoder:
    """A quadrature counter (the ESP32's PCNT shim): counts its wheel, in 4x."""

    def __init__(self, unit, phase_a=None, phase_b=None, *, phases=1, filter_ns=0,
                 **kwargs):
        self.unit = unit
        self.phases = phases
        pins = (phase_a.number, phase_b.number)
        self.index = None
        for index, wiring in enumerate(board_config.ENCODERS):
            if (wiring['a'], wiring['b']) == pins:
                self.index = index
        self.sign = -1 if board_config.ENCODERS[self.index]['invert'] else 1

    def value(self, value=None):
        """Return the count (as wired: an inverted encoder counts down going forward)."""
        return self.sign * _WHEELS.count(self.index)


#: MPU-6050 register units at the driver's ranges: LSB per m/s^2 (+-4 g), per rad/s
#: (+-500 deg/s).
_ACCEL_LSB = 8192 / 9.80665
_GYRO_LSB = 65.5 * 57.29577951308232
_ENODEV = 19


def _register(value, lsb_per_unit):
    """Return value in a 16-bit register's units, saturated."""
    raw = int(round(value * lsb_per_unit))
    return -32768 if raw < -32768 else 32767 if raw > 32767 else raw


class I2C:
    """An I2C bus with an MPU-6050 on it: lying still (1 g on z), or the simulator's."""

    def __init__(self, bus, *, scl=None, sda=None, freq=400000, timeout=50000):
        self.timeout = timeout
        self._sample = bytes(4) + bytes((0x20, 0x00)) + bytes(8)

    def writeto_mem(self, addr, memaddr, buf, *, addrsize=8):
        """Accept a register write."""

    def readfrom_mem(self, addr, memaddr, nbytes, *, addrsize=8):
        """Answer WHO_AM_I as an MPU-6050 (not while the simulator's IMU is silent)."""
        if _COSIM is not None and _COSIM.imu() is None:
            raise OSError(_ENODEV)
        return bytes((0x68,))

    def readfrom_mem_into(self, addr, memaddr, buf, *, addrsize=8):
        """Return the sample (from ACCEL_XOUT_H: accel, temperature, gyro; big-endian)."""
        if _COSIM is None:
            buf[:] = self._sample
            return
        sample = _COSIM.imu()
        if sample is None:
            raise OSError(_ENODEV)
        words = [_register(value, _ACCEL_LSB) for value in sample[:3]] + [0] + [
            _register(value, _GYRO_LSB) for value in sample[3:]]
        buf[:] = struct.pack('>7h', *words)


class ADC:
    """An ADC input at 1 V."""

    ATTN_11DB = 3

    def __init__(self, pin, *, atten=0):
        self.pin = pin

    def read_uv(self):
        """Return 1 V."""
        return 1000000


class UART:
    """Not simulated: the stand-in board talks over stdio."""

    def __init__(self, bus, baudrate=9600, bits=8, parity=None, stop=1, *, tx=None, rx=None,
                 txbuf=None, rxbuf=None, timeout=0, **kwargs):
        raise OSError('the stand-in board has no UART: use SERIAL = stdio')


class WDT:
    """The watchdog: reports its feeds on stderr; the test harness resets the board."""

    def __init__(self, *, id=0, timeout=5000):   # noqa: A002 (the ESP32's keyword)
        self.timeout = timeout
        self._reported = None
        if _COSIM is not None:
            _COSIM.wdt_ms = timeout
            _COSIM.fed_us = _COSIM.now_us
            return
        _event('WDT %d' % timeout)

    def feed(self):
        """Feed it (reported at most every WDT_REPORT_MS, or to the simulator)."""
        if _COSIM is not None:
            _COSIM.fed_us = _COSIM.now_us
            return
        now = time.ticks_ms()
        if self._reported is None or time.ticks_diff(now, self._reported) >= WDT_REPORT_MS:
            self._reported = now
            _event('W')
