"""
Hand-worked tests of the simulated board's hardware faults (board_sim).

The plant is the board emulator's model (board_model), the line a real pseudo-terminal.
"""

import math
import os

from mecanum_control.board_model import BoardModel, MotorModel, STANDARD_GRAVITY_M_S2
from mecanum_control.board_params import board_params
from mecanum_control.board_sim import PtyPort, SerialLine, SimulatedBoard
from mecanum_control.esp32_protocol import (
    encode_frame, FaultFlags, FrameDecoder, MotorEfforts)
from mecanum_control.kinematics import MecanumGeometry
from mecanum_control.robot_config import default_config_path, load_robot_config
import pytest

GEOMETRY = MecanumGeometry(wheel_radius_m=0.05, half_wheelbase_m=0.10, half_track_m=0.15)
MOTOR = MotorModel(no_load_speed_rad_s=30.0, time_constant_s=0.1)
RAD_PER_COUNT = 2.0 * math.pi / 1000.0
ROBOT = load_robot_config(default_config_path())


def board():
    """Return a board on the emulator's model (no noise), at rest."""
    model = BoardModel(geometry=GEOMETRY, motor=MOTOR, rad_per_count=RAD_PER_COUNT)
    return SimulatedBoard(model, board_params(ROBOT))


def set_counts(model: BoardModel, counts) -> None:
    """Turn the model's wheels to these counts (half a count past each)."""
    for wheel, count in zip(model.wheels, counts):
        wheel.angle_rad = (count + 0.5) * RAD_PER_COUNT


# ---------------------------------------------------------------- encoders


def test_a_stuck_counter_holds_and_counts_on_behind_by_what_it_missed():
    """
    A stuck counter holds; set free, it counts on behind by the pulses it missed.

    FL sticks at 100 while its wheel turns to 250 counts: it reads 100. Set free, it
    counts on from 100: the wheel at 260 reads 110 (150 pulses missed). Wheels not stuck
    read their counts throughout.
    """
    sim = board()
    hw = sim.hw
    set_counts(sim.plant, (100, 200, 300, 400))
    assert hw.read_counts() == (100, 200, 300, 400)
    hw.set_stuck_encoders({0})
    set_counts(sim.plant, (250, 210, 310, 410))
    assert hw.read_counts() == (100, 210, 310, 410)
    hw.set_stuck_encoders({0})   # still stuck: nothing changes
    assert hw.read_counts() == (100, 210, 310, 410)
    hw.set_stuck_encoders(set())
    assert hw.read_counts() == (100, 210, 310, 410)
    set_counts(sim.plant, (260, 220, 320, 420))
    assert hw.read_counts() == (110, 220, 320, 420)
    # FL and RR stuck (at 110 and 420) while their wheels turn on to 300 and 500: FL
    # misses 40 more, 190 in all, and reads 210 at 400; RR 80 behind reads 430 at 510.
    hw.set_stuck_encoders({0, 3})
    set_counts(sim.plant, (300, 230, 330, 500))
    assert hw.read_counts() == (110, 230, 330, 420)
    hw.set_stuck_encoders(set())
    set_counts(sim.plant, (400, 240, 340, 510))
    assert hw.read_counts() == (210, 240, 340, 430)


def test_a_counter_behind_wraps_like_the_32_bit_register():
    sim = board()
    set_counts(sim.plant, (-2 ** 31 + 5, 0, 0, 0))
    sim.hw.set_stuck_encoders([0])
    set_counts(sim.plant, (-2 ** 31 + 25, 0, 0, 0))
    sim.hw.set_stuck_encoders([])   # 20 behind
    # The wheel counts down across the wrap: -2^31 + 3 counts behind is 2^31 - 17.
    set_counts(sim.plant, (-2 ** 31 + 3, 0, 0, 0))
    assert sim.hw.read_counts()[0] == 2 ** 31 - 17


def test_stuck_encoder_indices_are_checked():
    with pytest.raises(ValueError, match='0..3'):
        board().hw.set_stuck_encoders([4])


# ---------------------------------------------------------------- IMU


def test_imu_bias_and_a_silent_imu_that_the_firmware_flags():
    """At rest the model's IMU reads (0, 0, g, 0, 0, 0)."""
    sim = board()
    hw = sim.hw
    assert hw.read_imu() == (0.0, 0.0, STANDARD_GRAVITY_M_S2, 0.0, 0.0, 0.0)
    hw.imu_bias = (0.1, -0.2, 0.0, 0.0, 0.0, 0.03)
    assert hw.read_imu() == pytest.approx((0.1, -0.2, STANDARD_GRAVITY_M_S2, 0.0, 0.0, 0.03))
    hw.imu_bias = None
    hw.imu_silent = True
    assert hw.read_imu() is None
    sim.plant.step(0.01)
    sim.core.poll(report=True)   # a report is due: the IMU does not answer
    assert sim.faults & FaultFlags.IMU_FAULT
    hw.imu_silent = False
    assert hw.read_imu() is not None


# ---------------------------------------------------------------- serial line


@pytest.fixture
def line(tmp_path):
    """Yield (a plugged SerialLine seeded 7, the host's end of its pty)."""
    link = SerialLine(PtyPort(tmp_path / 'tty'), seed=7)
    link.plug()
    host = os.open(tmp_path / 'tty', os.O_RDWR | os.O_NONBLOCK)
    yield link, host
    os.close(host)
    link.port.unplug()


def read_host(host) -> bytes:
    """Return what the host end can read now."""
    out = b''
    while True:
        try:
            chunk = os.read(host, 65536)
        except BlockingIOError:
            return out
        if not chunk:
            return out
        out += chunk


def read_board(link, now_us=0) -> bytes:
    """Return what reaches the board now (the host's bytes pass through the pty first)."""
    out = b''
    for _ in range(3):
        out += link.read(now_us)
    return out


def test_a_clean_line_passes_every_byte_both_ways(line):
    link, host = line
    assert read_host(host) == b'\x00'   # the leading delimiter
    assert not link.faulty
    link.write(bytes(range(1, 200)))
    assert read_host(host) == bytes(range(1, 200))
    os.write(host, bytes(range(50)))
    assert read_board(link) == bytes(range(50))


def test_dropping_every_byte_loses_both_ways(line):
    link, host = line
    read_host(host)
    link.set_byte_faults(drop_rate=1.0)
    assert link.faulty
    link.write(b'\x01\x02\x03\x00')
    os.write(host, b'\x04\x05\x00')
    assert read_host(host) == b'' and read_board(link) == b''
    link.set_byte_faults()
    assert not link.faulty
    link.write(b'\x01\x00')
    assert read_host(host) == b'\x01\x00'


def test_every_flip_changes_exactly_one_bit_both_ways(line):
    link, host = line
    read_host(host)
    link.set_byte_faults(flip_rate=1.0)
    data = bytes(range(256)) * 4
    link.write(data)
    os.write(host, data)
    for got in (read_host(host), read_board(link)):
        assert len(got) == len(data)
        assert all(bin(a ^ b).count('1') == 1 for a, b in zip(got, data))


def test_byte_drops_are_seeded_per_direction_whatever_the_chunks(tmp_path):
    """
    Drop rate 0.3 on 4000 bytes: about 1200 lost, the same for the same seed.

    Binomial sd 29: 1200 +- 145 is 5 sd. The same seed loses the same bytes when they
    come in one write or in 40; another seed loses others.
    """
    data = bytes((index % 255) + 1 for index in range(4000))

    def send(seed, chunk):
        link = SerialLine(PtyPort(tmp_path / f'tty{seed}_{chunk}'), seed=seed)
        link.plug()
        host = os.open(tmp_path / f'tty{seed}_{chunk}', os.O_RDWR | os.O_NONBLOCK)
        try:
            read_host(host)
            link.set_byte_faults(drop_rate=0.3)
            got = b''
            for start in range(0, len(data), chunk):
                link.write(data[start:start + chunk])
                got += read_host(host)
            return got
        finally:
            os.close(host)
            link.port.unplug()
    whole, pieces, other = send(1, 4000), send(1, 100), send(2, 4000)
    assert whole == pieces
    assert whole != other
    assert 1200 - 145 < len(data) - len(whole) < 1200 + 145


def test_latency_delays_both_ways_in_the_plants_time_and_keeps_the_order(line):
    """Latency 0.05 s: bytes sent at 0 arrive at 50 000 us, not before."""
    link, host = line
    read_host(host)
    link.set_byte_faults(latency_s=0.05)
    link.write(b'\x01\x00', now_us=0)
    os.write(host, b'\x02\x00')
    assert read_board(link, 0) == b''
    link.deliver(49_999)
    assert read_host(host) == b'' and read_board(link, 49_999) == b''
    link.deliver(50_000)
    assert read_host(host) == b'\x01\x00'
    assert read_board(link, 50_000) == b'\x02\x00'
    # Latency ends with bytes on their way: later bytes wait behind them.
    link.write(b'\x03\x00', now_us=60_000)
    link.set_byte_faults()
    assert link.faulty   # bytes still on their way
    link.write(b'\x04\x00', now_us=70_000)
    assert read_host(host) == b''
    link.deliver(110_000)
    assert read_host(host) == b'\x03\x00\x04\x00'
    assert not link.faulty


def test_byte_fault_settings_are_checked(line):
    link, _ = line
    for kwargs in ({'drop_rate': 1.5}, {'flip_rate': -0.1}, {'latency_s': -1.0},
                   {'drop_rate': 'x'}):
        with pytest.raises(ValueError):
            link.set_byte_faults(**kwargs)


def test_the_board_takes_a_delayed_command_in_the_plants_time(tmp_path):
    """A MOTOR_EFFORTS frame on a line with 0.03 s latency applies 30 ms after it was sent."""
    link = SerialLine(PtyPort(tmp_path / 'tty'), seed=7)
    sim = board()
    sim.attach(link)
    host_fd = os.open(tmp_path / 'tty', os.O_RDWR | os.O_NONBLOCK)
    try:
        read_host(host_fd)
        link.set_byte_faults(latency_s=0.03)
        os.write(host_fd, encode_frame(MotorEfforts((0.5, 0.5, 0.5, 0.5), 500), 1))
        received, reported = [], []
        decoder = FrameDecoder()
        for _ in range(10):   # 0 .. 45 ms in 5 ms steps
            sim.poll()
            received.append(sim.commands_received)
            reported.append(len(decoder.feed(read_host(host_fd))))
            sim.plant.step(0.005)
        assert received == [0] * 6 + [1] * 4   # taken at 30 ms
        # The board's reports of 0 ms (ticks, IMU, status) wait as long: they reach the
        # host at 30 ms; the next IMU sample (10 ms) at 40 ms.
        assert reported[:6] == [0] * 6 and reported[6] >= 3
        assert decoder.stats.errors == 0
    finally:
        os.close(host_fd)
        link.port.unplug()
