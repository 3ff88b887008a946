"""
IMU bias calibration at rest (pure, no ROS).

A MEMS gyro's bias (e.g. 0.002 rad/s, 7 deg/min) integrates into a heading error
that grows without bound, so IMU drivers remove it when the robot is known to stand
still. Here "at rest" means: no motor is driven and no encoder has counted for
``rest_time_s``, with encoder reports still arriving (a silent encoder proves
nothing), and the gyro stays within ``motion_threshold_rad_s`` of the bias (a robot
pushed by hand turns before its encoders count). During each rest, after that
settling time, the gyro's mean on all three axes is the gyro bias, and, assuming a
LEVEL floor, the accelerometer's x and y means are its bias (z carries gravity and
is left alone). The estimate of the latest
rest that lasted at least ``min_samples`` samples is subtracted from every sample.
Units: rad/s, m/s^2, s; axes of the IMU frame.
"""

import math
from typing import Optional, Sequence, Tuple

Vector3 = Tuple[float, float, float]


class ImuRestCalibrator:
    """Estimates and removes IMU biases from samples taken while the robot rests."""

    def __init__(self, rest_time_s: float = 1.0, min_samples: int = 50,
                 encoder_timeout_s: float = 0.25, motion_threshold_rad_s: float = 0.05) -> None:
        for name, value in (('rest_time_s', rest_time_s),
                            ('encoder_timeout_s', encoder_timeout_s),
                            ('motion_threshold_rad_s', motion_threshold_rad_s)):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be finite and > 0, got {value}')
        if min_samples < 1:
            raise ValueError(f'min_samples must be >= 1, got {min_samples}')
        self.rest_time_s = float(rest_time_s)
        self.min_samples = int(min_samples)
        self.encoder_timeout_s = float(encoder_timeout_s)
        self.motion_threshold_rad_s = float(motion_threshold_rad_s)
        self.gyro_bias: Vector3 = (0.0, 0.0, 0.0)
        self.accel_bias: Vector3 = (0.0, 0.0, 0.0)
        self.calibrations = 0  # rests long enough to set the biases
        self._last_ticks: Optional[Tuple[int, ...]] = None
        self._last_ticks_s = -math.inf
        self._moving_until_s = -math.inf  # rest starts counting after this time
        self._sums = [0.0] * 5  # gyro x, y, z, accel x, y of the current rest
        self._count = 0

    @property
    def calibrated(self) -> bool:
        """Tell whether a rest has set the biases yet."""
        return self.calibrations > 0

    def on_ticks(self, ticks: Sequence[int], driven: bool, now_s: float) -> None:
        """Note an encoder report and whether any motor is being driven now."""
        ticks = tuple(int(t) for t in ticks)
        if driven or ticks != self._last_ticks:
            self._moving_until_s = now_s
            self._end_rest()
        self._last_ticks = ticks
        self._last_ticks_s = now_s

    def at_rest(self, now_s: float) -> bool:
        """Tell whether the robot has rested for rest_time_s, by fresh encoder reports."""
        return (now_s - self._last_ticks_s <= self.encoder_timeout_s
                and now_s - self._moving_until_s >= self.rest_time_s)

    def on_sample(self, accel: Sequence[float], gyro: Sequence[float],
                  now_s: float) -> Tuple[Vector3, Vector3]:
        """Use one sample (accel m/s^2, gyro rad/s) if at rest; return it bias-corrected."""
        values = [float(v) for v in (*gyro, accel[0], accel[1])]
        # Compare with this rest's mean, else the last bias (none before the first rest:
        # an uncalibrated gyro's bias may itself exceed the threshold).
        reference = ([s / self._count for s in self._sums[:3]] if self._count
                     else self.gyro_bias if self.calibrated else None)
        if reference is not None and any(abs(v - r) > self.motion_threshold_rad_s
                                         for v, r in zip(values[:3], reference)):
            self._moving_until_s = now_s
        if not self.at_rest(now_s):
            self._end_rest()
        elif all(math.isfinite(v) for v in values):
            self._sums = [s + v for s, v in zip(self._sums, values)]
            self._count += 1
            if self._count == self.min_samples:
                self.calibrations += 1
            if self._count >= self.min_samples:
                means = [s / self._count for s in self._sums]
                self.gyro_bias = (means[0], means[1], means[2])
                self.accel_bias = (means[3], means[4], 0.0)
        corrected_gyro = tuple(float(g) - b for g, b in zip(gyro, self.gyro_bias))
        corrected_accel = tuple(float(a) - b for a, b in zip(accel, self.accel_bias))
        return corrected_accel, corrected_gyro

    def _end_rest(self) -> None:
        self._sums = [0.0] * 5
        self._count = 0

    def rest_samples(self) -> int:
        """Return the number of samples taken in the current rest so far."""
        return self._count
