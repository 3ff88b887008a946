"""
I2C IMU drivers (no hardware import: each driver gets a ready I2C bus object).

A driver is a class ``Driver(i2c, address)`` whose ``read()`` returns
(ax, ay, az in m/s^2, gx, gy, gz in rad/s) in the sensor's axes, or raises OSError
when the chip does not answer; ``DRIVERS`` maps the names board_config.IMU may use to
them. To add a chip: write its class here (the same two methods) and add it to DRIVERS.
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
        """Wake the chip (gyro X clock), set the filter and the ranges; OSError if absent."""
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
