"""
Hand-worked tests of the emulated board: board_model's physics and IMU under the firmware core.

The command timeout tests run the firmware's own core (board_core, through board_sim)
on the model, as the board emulator does.
"""

import math
import os

from mecanum_control.board_emulator import parse_args
from mecanum_control.board_model import (
    BoardModel, MotorModel, STANDARD_GRAVITY_M_S2, to_int32, Wheel)
from mecanum_control.board_params import board_params
from mecanum_control.board_sim import PtyPort, SerialLine, SimulatedBoard
from mecanum_control.esp32_protocol import encode_frame, EncoderTicks, FaultFlags, FrameDecoder
from mecanum_control.kinematics import MecanumGeometry
from mecanum_control.robot_config import default_config_path, load_robot_config
import pytest

# r = 0.05 m, lx = 0.10 m, ly = 0.15 m: lx + ly = 0.25 m.
GEOMETRY = MecanumGeometry(wheel_radius_m=0.05, half_wheelbase_m=0.10, half_track_m=0.15)
# Full duty -> 30 rad/s, time constant 0.1 s, dead band 0.03 (the default).
MOTOR = MotorModel(no_load_speed_rad_s=30.0, time_constant_s=0.1)
RAD_PER_COUNT = 2.0 * math.pi / 1000.0
#: The robot's config: the firmware's fault thresholds.
ROBOT = load_robot_config(default_config_path())


class EmulatedBoard:
    """The board model under the firmware core, as the emulator runs them (no serial line)."""

    def __init__(self, **kwargs):
        self.model = BoardModel(geometry=GEOMETRY, motor=MOTOR, rad_per_count=RAD_PER_COUNT,
                                **kwargs)
        self.board = SimulatedBoard(self.model, board_params(ROBOT))
        self.core = self.board.core

    def step(self, dt_s):
        """Step the model, then run one firmware loop iteration, as the emulator does."""
        self.model.step(dt_s)
        self.board.poll()

    def command(self, efforts, command_timeout_ms, seq):
        """Apply efforts in -1..1, as a MOTOR_EFFORTS frame would."""
        self.board.command(efforts, command_timeout_ms, seq)

    def clear_faults(self, faults):
        """Clear latched faults, as a CLEAR_FAULTS frame would."""
        self.board.clear_faults(faults)

    @property
    def efforts(self):
        """Return the duties the firmware applies."""
        return self.board.efforts

    @property
    def faults(self):
        """Return the firmware's fault bits."""
        return self.board.faults

    @property
    def last_command_seq(self):
        """Return the sequence number of the firmware's last command."""
        return self.board.last_command_seq

    def __getattr__(self, name):
        """Everything else is the model's (wheels, ticks, imu, time_us)."""
        return getattr(self.model, name)


def make_board(**kwargs):
    """Return a board with the test geometry, motor and 1000 counts per wheel turn."""
    return EmulatedBoard(**kwargs)


def run(board, seconds, dt_s=0.01):
    """Step the board by dt_s until seconds have passed (whole steps)."""
    for _ in range(round(seconds / dt_s)):
        board.step(dt_s)


# ------------------------------------------------------------------- Wheel.step


def test_first_order_speed_response_hand_value():
    """
    From rest, duty 0.5 for 0.1 s: speed = 15 * (1 - e^-1).

    0.5 * 30 rad/s = 15 rad/s target; t = tau = 0.1 s, so
    15 * (1 - 0.36787944117) = 15 * 0.63212055883 = 9.48180838...
    """
    wheel = Wheel()
    wheel.step(MOTOR, 0.5, 0.1)
    assert wheel.speed_rad_s == pytest.approx(9.4818083824, abs=1e-9)


def test_first_order_angle_is_the_integral_hand_value():
    """
    The angle is the integral of the speed, worked in closed form.

    integral_0^t 15 (1 - e^(-s/tau)) ds = 15 (t - tau (1 - e^(-t/tau)))
    = 15 (0.1 - 0.1 * 0.63212055883) = 15 * 0.036787944117 = 0.5518191618 rad.
    """
    wheel = Wheel()
    wheel.step(MOTOR, 0.5, 0.1)
    assert wheel.angle_rad == pytest.approx(0.5518191618, abs=1e-9)


@pytest.mark.parametrize('steps', [1, 2, 7, 100, 1000])
def test_result_does_not_depend_on_step_size(steps):
    """One step of 0.1 s and many small steps reach the same speed and angle (exact update)."""
    wheel = Wheel()
    for _ in range(steps):
        wheel.step(MOTOR, 0.5, 0.1 / steps)
    assert wheel.speed_rad_s == pytest.approx(9.4818083824, abs=1e-9)
    assert wheel.angle_rad == pytest.approx(0.5518191618, abs=1e-9)


def test_negative_duty_is_symmetric():
    """Duty -0.5 gives the mirror image of duty 0.5."""
    wheel = Wheel()
    wheel.step(MOTOR, -0.5, 0.1)
    assert wheel.speed_rad_s == pytest.approx(-9.4818083824, abs=1e-9)
    assert wheel.angle_rad == pytest.approx(-0.5518191618, abs=1e-9)


def test_speed_settles_at_duty_times_no_load_speed():
    """After 50 time constants the speed is u * no_load = 0.8 * 30 = 24 rad/s."""
    wheel = Wheel()
    wheel.step(MOTOR, 0.8, 5.0)
    assert wheel.speed_rad_s == pytest.approx(24.0, abs=1e-12)


def test_coasting_decays_from_the_current_speed():
    """
    With zero duty a spinning wheel decays, it does not stop dead.

    From 20 rad/s over tau: speed 20 e^-1 = 7.3575888 rad/s; angle
    20 * tau * (1 - e^-1) = 2 * 0.63212055883 = 1.2642411177 rad.
    """
    wheel = Wheel(speed_rad_s=20.0)
    wheel.step(MOTOR, 0.0, 0.1)
    assert wheel.speed_rad_s == pytest.approx(7.3575888234, abs=1e-9)
    assert wheel.angle_rad == pytest.approx(1.2642411177, abs=1e-9)


@pytest.mark.parametrize('duty', [0.03, -0.03, 0.02, -0.001, 0.0])
def test_dead_band_gives_no_motion(duty):
    """A duty within the dead band (|u| <= 0.03) does not turn a wheel at rest."""
    wheel = Wheel()
    for _ in range(100):
        wheel.step(MOTOR, duty, 0.01)
    assert wheel.speed_rad_s == 0.0
    assert wheel.angle_rad == 0.0


def test_duty_just_outside_dead_band_moves():
    """
    Duty 0.04 is outside the dead band and drives at 0.04 * 30 = 1.2 rad/s in steady state.

    The duty is not shifted by the dead band: the target is the full u * no_load.
    """
    wheel = Wheel()
    wheel.step(MOTOR, 0.04, 5.0)
    assert wheel.speed_rad_s == pytest.approx(1.2, abs=1e-12)


def test_blocked_wheel_never_moves():
    """A blocked wheel stays at rest with full duty, and loses its speed if it was spinning."""
    wheel = Wheel(speed_rad_s=10.0, angle_rad=1.5, blocked=True)
    for _ in range(100):
        wheel.step(MOTOR, 1.0, 0.01)
    assert wheel.speed_rad_s == 0.0
    assert wheel.angle_rad == 1.5


@pytest.mark.parametrize('kwargs', [
    {'no_load_speed_rad_s': 0.0, 'time_constant_s': 0.1},
    {'no_load_speed_rad_s': 30.0, 'time_constant_s': 0.0},
    {'no_load_speed_rad_s': 30.0, 'time_constant_s': 0.1, 'dead_band_effort': 1.0},
    {'no_load_speed_rad_s': 30.0, 'time_constant_s': 0.1, 'dead_band_effort': -0.1},
])
def test_invalid_motor_model_is_rejected(kwargs):
    """Non-positive speed or time constant, or a dead band outside [0, 1), is rejected."""
    with pytest.raises(ValueError):
        MotorModel(**kwargs)


# ------------------------------------------------------- BoardModel: command timeout


def test_command_drives_the_wheels():
    """A command applies its duties: after 0.1 s at duty 0.5 each wheel turns 15(1-e^-1)."""
    board = make_board()
    board.command([0.5, 0.5, 0.5, 0.5], command_timeout_ms=250, seq=1)
    run(board, 0.1)
    for wheel in board.wheels:
        assert wheel.speed_rad_s == pytest.approx(9.4818083824, abs=1e-9)
    assert board.time_us == 100_000
    assert board.last_command_seq == 1
    assert board.faults == FaultFlags(0)


def test_command_clamps_duties():
    """Duties beyond +-1 are clamped to +-1."""
    board = make_board()
    board.command([2.0, -3.0, 0.5, -0.5], command_timeout_ms=250, seq=1)
    assert board.efforts == [1.0, -1.0, 0.5, -0.5]


def test_command_timeout_zeroes_efforts_and_sets_fault():
    """
    100 ms after the last command the duties still hold; beyond it they are zeroed.

    Command at t = 0 with a 100 ms timeout, steps of 10 ms: at t = 100 ms,
    100 ms is not > 100 ms; at t = 110 ms it is.
    """
    board = make_board()
    board.command([0.5, 0.5, 0.5, 0.5], command_timeout_ms=100, seq=1)
    run(board, 0.1)
    assert board.efforts == [0.5, 0.5, 0.5, 0.5]
    assert not board.faults & FaultFlags.COMMAND_TIMEOUT
    board.step(0.01)
    assert board.efforts == [0.0, 0.0, 0.0, 0.0]
    assert board.faults & FaultFlags.COMMAND_TIMEOUT
    # The wheels coast down towards zero and never reverse.
    run(board, 2.0)
    for wheel in board.wheels:
        assert 0.0 <= wheel.speed_rad_s < 1e-6


def test_next_command_clears_command_timeout():
    """A new command clears COMMAND_TIMEOUT and drives again."""
    board = make_board()
    board.command([0.5] * 4, command_timeout_ms=100, seq=1)
    run(board, 0.5)
    assert board.faults & FaultFlags.COMMAND_TIMEOUT
    board.command([-0.5] * 4, command_timeout_ms=100, seq=2)
    assert not board.faults & FaultFlags.COMMAND_TIMEOUT
    board.step(0.01)
    assert board.efforts == [-0.5] * 4
    assert not board.faults & FaultFlags.COMMAND_TIMEOUT


def test_command_keeps_other_faults():
    """A command clears only COMMAND_TIMEOUT; clear_faults clears the latched bits asked."""
    board = make_board()
    other = FaultFlags.ENCODER_FAULT   # latched: only CLEAR_FAULTS clears it
    board.core.faults = int(other | FaultFlags.COMMAND_TIMEOUT)
    board.command([0.0] * 4, command_timeout_ms=100, seq=1)
    assert board.faults == other
    board.clear_faults(FaultFlags.LOW_BATTERY)   # a level bit: ignored
    assert board.faults == other
    board.clear_faults(other)
    assert board.faults == FaultFlags(0)


def test_never_commanded_board_does_not_move_and_reports_the_timeout():
    """Without any command the wheels stay still and COMMAND_TIMEOUT is set, as after boot."""
    board = make_board()
    board.core.commanded = [10000] * 4  # even stale duties are not applied
    run(board, 1.0)
    assert board.faults == FaultFlags.COMMAND_TIMEOUT
    assert board.ticks == (0, 0, 0, 0)
    for wheel in board.wheels:
        assert wheel.speed_rad_s == 0.0


def test_blocked_wheel_on_the_board():
    """A blocked wheel keeps its counter while the others turn."""
    board = make_board()
    board.wheels[0].blocked = True
    board.command([1.0] * 4, command_timeout_ms=1000, seq=1)
    run(board, 0.5)
    fl, fr, rl, rr = board.ticks
    assert fl == 0
    assert fr > 0 and rl > 0 and rr > 0


def test_non_positive_step_does_nothing():
    """step(0) and negative steps do not advance time or move wheels."""
    board = make_board()
    board.command([1.0] * 4, command_timeout_ms=250, seq=1)
    board.step(0.0)
    board.step(-0.1)
    assert board.time_us == 0
    assert board.ticks == (0, 0, 0, 0)


# ------------------------------------------------------------------- ticks


@pytest.mark.parametrize('value, expected', [
    (0, 0),
    (-1, -1),
    (2**31 - 1, 2147483647),
    (2**31, -2147483648),           # one past the top wraps to the bottom
    (2**31 + 3, -2147483645),
    (-2**31, -2147483648),
    (-2**31 - 1, 2147483647),       # one below the bottom wraps to the top
    (2**32, 0),
    (2**32 + 5, 5),
    (-2**32 - 5, -5),
])
def test_to_int32_hand_cases(value, expected):
    """to_int32 wraps like a signed 32-bit hardware counter."""
    assert to_int32(value) == expected


@pytest.mark.parametrize('counts, expected', [
    (0.0, 0),
    (2.5, 2),
    (2.999, 2),
    (3.0001, 3),
    (-0.5, -1),      # floor, not truncation towards zero
    (-2.5, -3),
    (1000.2, 1000),
])
def test_ticks_are_floor_of_angle_over_rad_per_count(counts, expected):
    """A wheel at angle counts * rad_per_count reads floor(counts)."""
    board = make_board()
    for wheel in board.wheels:
        wheel.angle_rad = counts * RAD_PER_COUNT
    assert board.ticks == (expected,) * 4


def test_ticks_per_wheel_order():
    """Each counter reads its own wheel, in the order FL, FR, RL, RR."""
    board = make_board()
    for index, wheel in enumerate(board.wheels):
        wheel.angle_rad = (10 * index + 0.5) * RAD_PER_COUNT
    assert board.ticks == (0, 10, 20, 30)


def test_one_wheel_turn_is_1000_counts():
    """
    Duty 0.5 for 1 s from rest, with a 1000-count encoder.

    Angle = 15 (1 - 0.1 (1 - e^-10)) = 15 * 0.9000045400 = 13.500068 rad,
    / (2 pi / 1000) = 2148.603 counts -> 2148.
    """
    board = make_board()
    board.command([0.5] * 4, command_timeout_ms=2000, seq=1)
    run(board, 1.0)
    assert board.ticks == (2148,) * 4


def test_tick_offset_wraps_into_negative_int32():
    """
    An offset near 2^31 makes the counter wrap like the firmware's int32.

    offset 2^31 - 2 = 2147483646; wheel at 5.5 counts -> 2147483646 + 5 = 2^31 + 3,
    which as int32 is -2^31 + 3 = -2147483645. A wheel at -0.5 counts reads
    2147483646 - 1 = 2147483645 (no wrap).
    """
    board = make_board(tick_offset=2**31 - 2)
    board.wheels[0].angle_rad = 5.5 * RAD_PER_COUNT
    board.wheels[1].angle_rad = -0.5 * RAD_PER_COUNT
    board.wheels[2].angle_rad = 1.5 * RAD_PER_COUNT   # 2147483647, the top
    board.wheels[3].angle_rad = 2.5 * RAD_PER_COUNT   # 2^31 -> -2^31, the bottom
    assert board.ticks == (-2147483645, 2147483645, 2147483647, -2147483648)


# ------------------------------------------------------------------- IMU


def test_imu_at_rest():
    """At rest the accelerometer reads +g on z only and the gyro reads zero."""
    board = make_board()
    run(board, 0.1)
    accel, gyro = board.imu()
    assert accel == (0.0, 0.0, STANDARD_GRAVITY_M_S2)
    assert STANDARD_GRAVITY_M_S2 == 9.80665
    assert gyro == (0.0, 0.0, 0.0)


def test_gyro_z_is_body_yaw_rate_of_pure_rotation():
    """
    Duties (-0.5, 0.5, -0.5, 0.5) turn the robot left (counter-clockwise, +z).

    Each wheel reaches s = 15 (1 - e^-10) = 14.9993190 rad/s after 1 s, so
    wz = r * (s + s + s + s) / (4 (lx + ly)) = 0.05 * s / 0.25 = 0.2 s = 2.9998638 rad/s.
    There is no translation, so vx = vy = 0 and no centripetal acceleration.
    """
    board = make_board()
    board.command([-0.5, 0.5, -0.5, 0.5], command_timeout_ms=2000, seq=1)
    run(board, 1.0)
    accel, gyro = board.imu()
    assert gyro[2] == pytest.approx(2.9998638, abs=1e-6)
    assert gyro[0] == 0.0 and gyro[1] == 0.0
    vx, vy, wz = board.body_velocity
    assert vx == pytest.approx(0.0, abs=1e-12)
    assert vy == pytest.approx(0.0, abs=1e-12)
    assert wz == gyro[2]
    assert accel[0] == pytest.approx(0.0, abs=1e-9)
    assert accel[1] == pytest.approx(0.0, abs=1e-9)
    assert accel[2] == STANDARD_GRAVITY_M_S2


def test_accelerometer_sees_centripetal_acceleration_on_a_circle():
    """
    Driving forward while turning left: the accelerometer reads wz * vx to the left (+y).

    Duties (0.2, 0.6, 0.2, 0.6) settle at wheel speeds (6, 18, 6, 18) rad/s:
    vx = 0.05 * (6 + 18 + 6 + 18) / 4 = 0.6 m/s,
    wz = 0.05 * (-6 + 18 - 6 + 18) / (4 * 0.25) = 1.2 rad/s,
    a_y = wz * vx = 0.72 m/s^2 towards the centre; a_x = 0 at constant speed.
    """
    board = make_board()
    board.command([0.2, 0.6, 0.2, 0.6], command_timeout_ms=10000, seq=1)
    run(board, 5.0)
    accel, gyro = board.imu()
    assert gyro[2] == pytest.approx(1.2, abs=1e-9)
    assert accel[0] == pytest.approx(0.0, abs=1e-9)
    assert accel[1] == pytest.approx(0.72, abs=1e-9)


def test_accelerometer_sees_forward_acceleration():
    """
    Starting forward, the x acceleration is the change of vx over the last step.

    vx = r * s with s = 30 (1 - e^(-t/0.1)) at duty 1; over the step 0.09 -> 0.10 s:
    s(0.10) = 30 * 0.6321205588 = 18.963616764, s(0.09) = 30 * 0.5934303403 = 17.802910208,
    a_x = 0.05 * (18.963616764 - 17.802910208) / 0.01 = 5.8035328 m/s^2.
    """
    board = make_board()
    board.command([1.0] * 4, command_timeout_ms=1000, seq=1)
    run(board, 0.1)
    accel, _ = board.imu()
    assert accel[0] == pytest.approx(5.8035328, abs=1e-6)
    assert accel[1] == pytest.approx(0.0, abs=1e-12)


def imu_series(seed, count=5):
    """Return count IMU readings of a noisy board with the given seed, driving forward."""
    board = make_board(imu_accel_noise_m_s2=0.05, imu_gyro_noise_rad_s=0.01, seed=seed)
    board.command([0.5] * 4, command_timeout_ms=1000, seq=1)
    readings = []
    for _ in range(count):
        board.step(0.01)
        readings.append(board.imu())
    return readings


def test_seeded_imu_noise_is_reproducible():
    """The same seed gives the same noisy readings; another seed gives other readings."""
    first = imu_series(seed=42)
    assert imu_series(seed=42) == first
    assert imu_series(seed=43) != first


def test_imu_noise_is_added_to_every_axis():
    """With noise every axis differs from the noiseless reading, by a plausible amount."""
    noisy = imu_series(seed=1, count=1)[0]
    board = make_board()
    board.command([0.5] * 4, command_timeout_ms=1000, seq=1)
    board.step(0.01)
    clean = board.imu()
    for noisy_axes, clean_axes, sigma in zip(noisy, clean, (0.05, 0.01)):
        for noisy_value, clean_value in zip(noisy_axes, clean_axes):
            assert noisy_value != clean_value
            assert abs(noisy_value - clean_value) < 6 * sigma


def test_emulator_arguments_from_ros2_launch_are_split_like_a_shell():
    """ros2 launch passes '$(var emulator_args)' as one (maybe empty) argument."""
    args = parse_args(['--link', '/tmp/x', '', '--tick-offset 5 --block-wheel FL',
                       '--ros-args', '-r', '__node:=board_emulator'])
    assert (args.tick_offset, args.block_wheel, str(args.link)) == (5, ['FL'], '/tmp/x')


def test_emulator_refuses_to_replace_a_real_file_or_device_link(tmp_path):
    """--link pointing at an existing file or a non-pty symlink is refused, not replaced."""
    real = tmp_path / 'esp32'
    real.write_text('precious')
    with pytest.raises(FileExistsError, match='refusing to replace'):
        PtyPort(real).plug()
    assert real.read_text() == 'precious'
    udev_link = tmp_path / 'udev'
    udev_link.symlink_to('/dev/ttyUSB0')
    with pytest.raises(FileExistsError):
        PtyPort(udev_link).plug()
    assert os.readlink(udev_link) == '/dev/ttyUSB0'
    stale = tmp_path / 'stale'
    stale.symlink_to('/dev/pts/999')  # an emulator's leftover link is replaced
    port = PtyPort(stale)
    port.plug()
    try:
        assert os.readlink(stale).startswith('/dev/pts/')
    finally:
        port.unplug()
    assert not stale.exists() and not stale.is_symlink()


def test_board_link_never_leaves_half_a_frame_on_a_full_line(tmp_path):
    """
    Nobody reads the pty until its buffer is full: frames are dropped whole, never cut.

    The reader then drains the line; every byte decodes into valid frames.
    """
    link_path = tmp_path / 'tty'
    link = SerialLine(PtyPort(link_path))
    link.plug()
    try:
        reader = os.open(link_path, os.O_RDONLY | os.O_NONBLOCK)
        try:
            for k in range(3000):  # about 90 kB: far beyond a pty's buffer
                link.write(encode_frame(EncoderTicks(k, (k, k, k, k)), k))
            decoder = FrameDecoder()
            frames = []
            for _ in range(3):
                while True:
                    try:
                        chunk = os.read(reader, 65536)
                    except BlockingIOError:
                        break
                    frames += decoder.feed(chunk)
                link.write(encode_frame(EncoderTicks(9999, (0, 0, 0, 0)), 0))  # flushes the rest
        finally:
            os.close(reader)
    finally:
        link.port.unplug()
    assert decoder.stats.errors == 0
    assert len(frames) > 100
