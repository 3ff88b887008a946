"""
I2C IMU drivers (no hardware import: each driver gets a ready I2C bus object).

A driver is a class ``Driver(i2c, address)`` that identifies and sets up its chip
(OSError when it does not answer or is another chip) and whose ``read()`` returns
(ax, ay, az in m/s^2, gx, gy, gz in rad/s) in the sensor's axes, or raises OSError
when the chip does not answer; ``DRIVERS`` maps the names board_config.IMU may use to
them. To add a chip: write its class here (the same two methods) and add it to DRIVERS.
:class:`RetryingImu` keeps an IMU that may be absent at boot, or fail later, in use:
it sets the chip up again every ``retry_ms`` while it fails, and not more often.
"""

import struct

STANDARD_GRAVITY_M_S2 = 9.80665
DEG_TO_RAD = 0.017453292519943295


class Mpu6050:
    """
    InvenSense MPU-6050 (and MPU-6500/9250's accelerometer and gyro), over I2C.

    Ranges: accelerometer +-4 g (8192 LSB/g), gyro +-500 deg/s (65.5 LSB per deg/s),
    digital low-pass filter 44 Hz (the board samples at 100 Hz).
    """

    DEFAULT_ADDRESS = 0x68
    _PWR_MGMT_1 = 0x6B
    _CONFIG = 0x1A
    _GYRO_CONFIG = 0x1B
    _ACCEL_CONFIG = 0x1C
    _ACCEL_XOUT_H = 0x3B
    _WHO_AM_I = 0x75
    #: WHO_AM_I answers of the chips with this register map: MPU-6050, MPU-6500,
    #: MPU-9250, MPU-9255.
    WHO_AM_I_VALUES = (0x68, 0x70, 0x71, 0x73)
    ACCEL_LSB_PER_G = 8192.0
    GYRO_LSB_PER_DEG_S = 65.5

    def __init__(self, i2c, address=DEFAULT_ADDRESS):
        self.i2c = i2c
        self.address = address
        self._accel_scale = STANDARD_GRAVITY_M_S2 / self.ACCEL_LSB_PER_G
        self._gyro_scale = DEG_TO_RAD / self.GYRO_LSB_PER_DEG_S
        self._buffer = bytearray(14)
        self.setup()

    def _write(self, register, value):
        self.i2c.writeto_mem(self.address, register, bytes((value,)))

    def setup(self):
        """Identify the chip, wake it, set filter and ranges; OSError if absent or another."""
        who = self.i2c.readfrom_mem(self.address, self._WHO_AM_I, 1)[0]
        if who not in self.WHO_AM_I_VALUES:
            raise OSError('I2C 0x%02x: WHO_AM_I 0x%02x is no MPU-6050/6500/9250'
                          % (self.address, who))
        self._write(self._PWR_MGMT_1, 0x01)
        self._write(self._CONFIG, 0x03)        # DLPF 44 Hz
        self._write(self._GYRO_CONFIG, 0x08)   # +-500 deg/s
        self._write(self._ACCEL_CONFIG, 0x08)  # +-4 g

    def read(self):
        """Return (ax, ay, az m/s^2, gx, gy, gz rad/s); OSError if the chip does not answer."""
        self.i2c.readfrom_mem_into(self.address, self._ACCEL_XOUT_H, self._buffer)
        ax, ay, az, _temp, gx, gy, gz = struct.unpack('>7h', self._buffer)
        a, g = self._accel_scale, self._gyro_scale
        return (ax * a, ay * a, az * a, gx * g, gy * g, gz * g)


DRIVERS = {'MPU6050': Mpu6050}


class RetryingImu:
    """
    An IMU made by ``make()`` (a driver's constructor), set up again after a failure.

    ``read()`` returns the driver's sample, or None while the IMU fails: absent at
    boot, unidentified, or a read that raised OSError (a stuck bus costs one I2C
    timeout). After a failure the next attempt (the driver built again, WHO_AM_I and
    setup included) comes ``retry_ms`` later; reads in between return None at once.
    ``clock`` gives ticks_ms, ticks_diff, ticks_add (MicroPython's time module).
    ``last_error`` keeps the last failure's text for the REPL.
    """

    def __init__(self, make, clock, retry_ms=1000):
        self._make = make
        self._clock = clock
        self.retry_ms = retry_ms
        self.imu = None
        self.last_error = None
        self._retry_at = None   # ticks_ms of the next attempt; None: at once
        self.attempts = 0

    def read(self):
        """Return (ax, ay, az, gx, gy, gz) or None while the IMU fails."""
        clock = self._clock
        if self.imu is None:
            now = clock.ticks_ms()
            if self._retry_at is not None and clock.ticks_diff(now, self._retry_at) < 0:
                return None
            self.attempts += 1
            try:
                self.imu = self._make()
            except OSError as error:
                self._failed(error, now)
                return None
        try:
            return self.imu.read()
        except OSError as error:
            self.imu = None
            self._failed(error, self._clock.ticks_ms())
            return None

    def _failed(self, error, now):
        """Remember the failure and when to try again."""
        self.last_error = str(error)
        self._retry_at = self._clock.ticks_add(now, self.retry_ms)
