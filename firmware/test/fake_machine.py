"""
A stand-in for MicroPython's machine module, for running hardware_esp32.py off the board.

Only what the hardware layer uses (the ESP32 stubs check the real names): Pin, PWM,
Encoder, I2C, ADC, UART and WDT record what is done to them, so a test under the real
MicroPython interpreter can see which pin levels and duties a set of duties becomes.
Loaded as ``machine`` in a MicroPython session of its own (test_firmware.py).
"""

import io

PINS = {}
PWMS = {}
ENCODERS = {}


class Pin:
    """A GPIO: its mode, pull and level."""

    IN = 1
    OUT = 3
    PULL_UP = 1

    def __init__(self, number, mode=None, pull=None, value=None):
        self.number = number
        self.mode = mode
        self.pull = pull
        self.level = 0 if value is None else value
        PINS[number] = self

    def value(self, level=None):
        """Read or set the level."""
        if level is None:
            return self.level
        self.level = level


class PWM:
    """A PWM output: frequency and duty_u16."""

    def __init__(self, pin, freq=0, duty_u16=0):
        self.pin = pin
        self.freq = freq
        self.level = duty_u16
        PWMS[pin.number] = self

    def duty_u16(self, level=None):
        """Read or set the duty (0..65535)."""
        if level is None:
            return self.level
        self.level = level


class Encoder:
    """A quadrature counter: the test sets its count."""

    def __init__(self, unit, phase_a, phase_b, phases=1, filter_ns=0):
        self.unit = unit
        self.pins = (phase_a.number, phase_b.number)
        self.phases = phases
        self.count = 0
        ENCODERS[unit] = self

    def value(self):
        """Return the count."""
        return self.count


#: Set False to unplug the MPU-6050 of every I2C bus (reads raise OSError ENODEV).
IMU_PRESENT = [True]


class I2C:
    """An I2C bus with an MPU-6050 lying still on it (1 g on z); timeout in us (ESP32)."""

    def __init__(self, bus_id, *, scl=None, sda=None, freq=400000, timeout=50000):
        self.sample = bytes(4) + bytes((0x20, 0x00)) + bytes(8)
        self.timeout = timeout

    def _answer(self):
        if not IMU_PRESENT[0]:
            raise OSError(19)

    def writeto_mem(self, address, register, data):
        """Accept a register write."""
        self._answer()

    def readfrom_mem(self, address, register, nbytes):
        """Answer WHO_AM_I (0x75) as an MPU-6050."""
        self._answer()
        return bytes((0x68,))

    def readfrom_mem_into(self, address, register, buffer):
        """Return the sample."""
        self._answer()
        buffer[:] = self.sample


class ADC:
    """An ADC input (not used by the default configuration)."""

    ATTN_11DB = 3

    def __init__(self, pin, atten=None):
        self.pin = pin

    def read_uv(self):
        """Return 1 V."""
        return 1000000


class UART(io.IOBase):
    """A UART whose received bytes the test supplies; written bytes are kept (pollable)."""

    def __init__(self, uart_id, baudrate=0, tx=None, rx=None, timeout=0, rxbuf=0):
        self.received = b''
        self.sent = b''

    def read(self):
        """Return what arrived (None when nothing did, as the real one)."""
        data, self.received = self.received, b''
        return data or None

    def write(self, data):
        """Keep what the board sends."""
        self.sent += data

    def ioctl(self, request, arg):
        """Answer select.poll (request 3): readable when bytes are pending."""
        if request == 3:
            return arg & 1 if self.received else 0
        return 0


class WDT:
    """The watchdog: counts feeds."""

    def __init__(self, timeout=0):
        self.timeout = timeout
        self.feeds = 0

    def feed(self):
        """Feed it."""
        self.feeds += 1
