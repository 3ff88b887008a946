"""
Physics of the robot under the emulated ESP32 motor board (pure, no I/O, no clock).

Each wheel is a DC gear motor reduced to its first-order speed response: at a
constant duty ``u`` (-1..1) the wheel speed tends to ``u * no_load_speed`` with time
constant ``tau``; duties inside the driver's dead band do not turn the wheel. The
update is the exact solution for a duty held over the step, so the step size only
limits the timing resolution. Encoder counts are what a 4x quadrature decoder
counts: the wheel angle in whole counts, as a free-running signed 32-bit counter.

The firmware itself (command watchdog, faults, the serial protocol) is not here: the
emulator runs the real firmware core (:mod:`mecanum_control.board_core`) on this
model through :mod:`mecanum_control.board_sim`. Body motion (for the IMU) follows
from the wheel speeds by forward kinematics; the board's IMU frame is aligned with
base_link. Wheel order FL, FR, RL, RR.
"""

from dataclasses import dataclass, field
import math
import random
from typing import List, Optional, Tuple

from mecanum_control.kinematics import forward_kinematics, MecanumGeometry

STANDARD_GRAVITY_M_S2 = 9.80665
INT32_RANGE = 1 << 32


def to_int32(value: int) -> int:
    """Wrap an integer into the signed 32-bit range, as a hardware counter does."""
    return (value + (1 << 31)) % INT32_RANGE - (1 << 31)


@dataclass(frozen=True)
class MotorModel:
    """First-order wheel speed response of one gear motor with its share of the robot."""

    no_load_speed_rad_s: float
    time_constant_s: float
    dead_band_effort: float = 0.03

    def __post_init__(self) -> None:
        if not (self.no_load_speed_rad_s > 0 and self.time_constant_s > 0
                and 0 <= self.dead_band_effort < 1):
            raise ValueError(f'invalid motor model {self}')


@dataclass
class Wheel:
    """State of one wheel: speed (rad/s), angle (rad) and whether it is blocked."""

    speed_rad_s: float = 0.0
    angle_rad: float = 0.0
    blocked: bool = False

    def step(self, motor: MotorModel, effort: float, dt_s: float) -> None:
        """Advance by dt_s with the duty held constant (exact for the first-order model)."""
        if self.blocked:
            self.speed_rad_s = 0.0
            return
        drive = 0.0 if abs(effort) <= motor.dead_band_effort else effort
        target = drive * motor.no_load_speed_rad_s
        decay = math.exp(-dt_s / motor.time_constant_s)
        start = self.speed_rad_s
        self.speed_rad_s = target + (start - target) * decay
        # Integral of the exponential approach over the step.
        self.angle_rad += target * dt_s + (start - target) * motor.time_constant_s * (1 - decay)


@dataclass
class BoardModel:
    """
    The emulated robot under the board: four wheels, their encoder counters and an IMU.

    ``efforts`` are the duties -1..1 (FL, FR, RL, RR) the firmware applies (set by
    :class:`mecanum_control.board_sim.SimulatedHardware`); ``step`` holds them.
    """

    geometry: MecanumGeometry
    motor: MotorModel
    rad_per_count: float
    imu_accel_noise_m_s2: float = 0.0
    imu_gyro_noise_rad_s: float = 0.0
    seed: Optional[int] = None
    time_us: int = 0
    wheels: List[Wheel] = field(default_factory=lambda: [Wheel() for _ in range(4)])
    efforts: List[float] = field(default_factory=lambda: [0.0] * 4)
    tick_offset: int = 0

    def __post_init__(self) -> None:
        self._random = random.Random(self.seed)
        self._body_velocity = (0.0, 0.0, 0.0)
        self._body_accel = (0.0, 0.0)

    def step(self, dt_s: float) -> None:
        """Advance time by dt_s with the efforts held: motor response, body acceleration."""
        if dt_s <= 0:
            return
        self.time_us += int(round(dt_s * 1e6))
        for wheel, effort in zip(self.wheels, self.efforts):
            wheel.step(self.motor, effort, dt_s)
        velocity = forward_kinematics(self.geometry, [w.speed_rad_s for w in self.wheels])
        self._body_accel = ((velocity[0] - self._body_velocity[0]) / dt_s,
                            (velocity[1] - self._body_velocity[1]) / dt_s)
        self._body_velocity = velocity

    @property
    def ticks(self) -> Tuple[int, int, int, int]:
        """Return the encoder counters (signed 32-bit, wrapping), FL FR RL RR."""
        return tuple(to_int32(math.floor(w.angle_rad / self.rad_per_count) + self.tick_offset)
                     for w in self.wheels)

    @property
    def body_velocity(self) -> Tuple[float, float, float]:
        """Body twist (vx m/s, vy m/s, wz rad/s) implied by the wheel speeds."""
        return self._body_velocity

    def imu(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float]]:
        """Return (accel m/s^2, gyro rad/s) in the IMU frame (aligned with base_link)."""
        vx, vy, wz = self._body_velocity
        ax = self._body_accel[0] - wz * vy
        ay = self._body_accel[1] + wz * vx
        noise_a, noise_g = self.imu_accel_noise_m_s2, self.imu_gyro_noise_rad_s
        gauss = self._random.gauss
        accel = (ax + gauss(0, noise_a) if noise_a else ax,
                 ay + gauss(0, noise_a) if noise_a else ay,
                 STANDARD_GRAVITY_M_S2 + (gauss(0, noise_a) if noise_a else 0.0))
        gyro = (gauss(0, noise_g) if noise_g else 0.0,
                gauss(0, noise_g) if noise_g else 0.0,
                wz + gauss(0, noise_g) if noise_g else wz)
        return accel, gyro
