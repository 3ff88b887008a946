"""
Integration: hardware_interface (a real process) against a scripted board on a real pty.

The test plays the ESP32 itself, frame by frame, with the shared protocol code, to
reach the cases the emulator does not produce: a board that stops talking, one that
only echoes, one speaking another protocol version, and the clear-faults request.
"""

import os
from pathlib import Path
import re
import signal
import struct
import subprocess
import threading
import time
import tty

from builtin_interfaces.msg import Time
from mecanum_control import esp32_protocol as proto
from mecanum_interfaces.msg import WheelTicks
import pytest
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float32MultiArray
from std_srvs.srv import Trigger
from tests.conftest import OutputProcess, Recorder

pytestmark = pytest.mark.integration
REPO = Path(__file__).resolve().parents[1]


class ScriptedBoard:
    """The board side of a pty: records every frame the host sends, sends what it is told."""

    def __init__(self, link: Path, plugged: bool = True, talking: bool = True):
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.link = link
        if plugged:
            self.plug()
        self.received = []
        self._lock = threading.Lock()
        self._decoder = proto.FrameDecoder()
        self._seq = {}
        self._running = True
        self.talking = talking
        threading.Thread(target=self._read, daemon=True).start()
        threading.Thread(target=self._heartbeat, daemon=True).start()

    def plug(self):
        """Publish the pty at the link path (plug the board in)."""
        os.symlink(os.ttyname(self._slave), self.link)

    def _read(self):
        while self._running:
            try:
                data = os.read(self.master, 4096)
            except OSError:
                return
            with self._lock:
                self.received += [(time.monotonic(), f) for f in self._decoder.feed(data)]

    def _heartbeat(self):
        """Send status and ticks at 50 Hz while talking."""
        start = time.monotonic()
        while self._running:
            if self.talking:
                board_time_us = int((time.monotonic() - start) * 1e6)
                self.send(proto.BoardStatus(board_time_us, proto.FaultFlags(0), 12000, 0, 0))
                self.send(proto.EncoderTicks(board_time_us, (0, 0, 0, 0)))
            time.sleep(0.02)

    def send(self, message):
        """Send one frame, numbered per message type."""
        msg_type = proto.message_type_of(message)
        seq = self._seq.get(msg_type, 0)
        self._seq[msg_type] = seq + 1
        self.write(proto.encode_frame(message, seq))

    def write(self, data: bytes):
        """Write raw bytes to the host."""
        try:
            os.write(self.master, data)
        except OSError:
            pass

    def frames(self, kind, since=0.0):
        """Frames of one message class received from the host since a monotonic time."""
        with self._lock:
            return [f for t, f in self.received if t >= since and isinstance(f.message, kind)]

    def close(self):
        """Stop the threads and close the pty."""
        self._running = False
        os.close(self.master)
        os.close(self._slave)


class HostProcess(OutputProcess):
    """hardware_interface started with ./mecanum run, its output collected."""

    def __init__(self, env, link: Path, *params: str):
        extra = [arg for param in params for arg in ('-p', param)]
        super().__init__(
            ['./mecanum', 'run', 'mecanum_control', 'hardware_interface', '--ros-args',
             '-p', f'port:={link}', '-p', 'link_timeout_s:=0.4', '-p',
             'first_frame_timeout_s:=0.4', '-p', 'reconnect_period_s:=0.3', *extra], env,
            cwd=REPO)

    def count(self, pattern: str) -> int:
        """Number of output lines matching pattern."""
        return sum(1 for line in self.output().splitlines() if re.search(pattern, line))

    def wait_for(self, pattern: str, count: int = 1, timeout: float = 10.0):
        """Wait until `count` lines match pattern."""
        deadline = time.monotonic() + timeout
        while self.count(pattern) < count:
            assert time.monotonic() < deadline, (
                f'{pattern!r} x{count} not seen; output:\n' + self.output())
            time.sleep(0.05)

    def stop(self) -> int:
        """Ctrl-C the node; return its exit code."""
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGINT)
        try:
            return self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(self.process.pid, signal.SIGKILL)
            raise


@pytest.fixture
def link_setup(ros_env, test_node, tmp_path):
    """A scripted board on a pty and a running hardware_interface connected to it."""
    link = tmp_path / 'ttyESP32'
    board = ScriptedBoard(link)
    host = HostProcess(ros_env, link)
    try:
        host.wait_for('Connected to the board')
        yield board, host, test_node
    finally:
        host.stop()
        board.close()


def wait_until(predicate, timeout=5.0):
    """Poll predicate until true or fail."""
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, 'condition not met in time'
        time.sleep(0.02)


def test_silent_board_gets_a_zero_and_is_retried_without_log_spam(link_setup):
    board, host, test_node = link_setup
    efforts = test_node.node.create_publisher(Float32MultiArray, 'motor_efforts', 10)
    stop_feeding = threading.Event()

    def feed():
        while not stop_feeding.is_set():
            efforts.publish(Float32MultiArray(data=[0.5, -0.5, 0.5, -0.5]))
            time.sleep(0.02)
    threading.Thread(target=feed, daemon=True).start()
    wait_until(lambda: any(f.message.efforts[0] == 0.5
                           for f in board.frames(proto.MotorEfforts)))

    board.talking = False  # the board hangs but still listens
    silent_at = time.monotonic()
    host.wait_for('Link to the board .* lost .*no valid frame')
    # link_timeout_s 0.4 s, checked every 0.1 s: detected well within a second.
    assert time.monotonic() - silent_at < 1.5
    # The last command before the port closed was an explicit zero.
    before_reconnect = board.frames(proto.MotorEfforts, since=silent_at)
    zero_index = next(i for i, f in enumerate(before_reconnect)
                      if f.message.efforts == (0.0, 0.0, 0.0, 0.0))
    assert all(f.message.efforts == (0.5, -0.5, 0.5, -0.5)
               for f in before_reconnect[:zero_index]), (before_reconnect, host.lines)
    time.sleep(3.0)  # ten reconnect attempts to a board that does not answer
    assert host.count('does not answer') == 1
    assert host.count('Link to the board .* lost') == 1
    stop_feeding.set()
    board.talking = True
    host.wait_for('The board at .* answers')


def test_reconnecting_to_a_silent_board_never_blames_another_program(ros_env, tmp_path):
    """
    Each link loss lets go of the port before the next try.

    A real board sits 2 s in its REPL window after a reset, silent. The reader
    thread's select held the closed port's file, and so its exclusive lock, until it
    returned (up to 50 ms): a reconnect meanwhile was refused with 'another program
    holds it (pid <hardware_interface itself>)'. Reconnecting every 10 ms makes that
    window certain to be hit without the fix.
    """
    link = tmp_path / 'ttyESP32'
    board = ScriptedBoard(link, talking=False)
    host = HostProcess(ros_env, link, 'link_timeout_s:=0.1', 'reconnect_period_s:=0.01',
                       'first_frame_timeout_s:=0.1')
    try:
        host.wait_for('does not answer')
        # Each connection writes a zero command when it opens and one when it is lost.
        wait_until(lambda: len(board.frames(proto.MotorEfforts)) >= 24, timeout=20.0)
        assert host.count('another program holds it') == 0, host.output()
        board.talking = True
        host.wait_for('The board at .* answers')
    finally:
        host.stop()
        board.close()


def test_a_board_in_its_repl_window_is_waited_for_without_an_error(ros_env, test_node,
                                                                    tmp_path):
    """
    The port's opening resets a DevKit's ESP32: 2 s at its REPL window, silent.

    The first frame of a connection is waited for first_frame_timeout_s (3 s), not
    link_timeout_s (0.4 s here): a board that starts talking 1.5 s after the connection
    is taken without a 'does not answer' error or a reconnect.
    """
    link = tmp_path / 'ttyESP32'
    board = ScriptedBoard(link, talking=False)
    host = HostProcess(ros_env, link, 'first_frame_timeout_s:=3.0')   # the default
    ticks = Recorder(test_node.node, WheelTicks, 'wheel_ticks')
    try:
        host.wait_for('Connected to the board')
        time.sleep(1.5)   # the board's REPL window, as the test plays it
        board.talking = True
        ticks.wait_for(lambda msg: True)
        assert host.count('does not answer') == 0, host.output()
        assert host.count('lost') == 0 and host.count('Connected to the board') == 1
    finally:
        host.stop()
        board.close()


def test_efforts_received_before_a_connection_are_never_sent_on_it(ros_env, test_node,
                                                                   tmp_path):
    link = tmp_path / 'ttyESP32'
    board = ScriptedBoard(link, plugged=False)
    # A long effort timeout, so only the reconnect rule can keep the old command out.
    host = HostProcess(ros_env, link, 'effort_timeout_s:=3.0')
    try:
        host.wait_for('Cannot open')
        efforts = test_node.node.create_publisher(Float32MultiArray, 'motor_efforts', 10)
        deadline = time.monotonic() + 10
        while efforts.get_subscription_count() == 0:
            assert time.monotonic() < deadline
            time.sleep(0.05)
        for _ in range(25):  # 0.5 s of commands while the board is unplugged
            efforts.publish(Float32MultiArray(data=[0.5, 0.5, 0.5, 0.5]))
            time.sleep(0.02)
        board.plug()
        host.wait_for('Connected to the board')
        time.sleep(1.0)
        sent = board.frames(proto.MotorEfforts)
        assert sent and all(f.message.efforts == (0.0, 0.0, 0.0, 0.0) for f in sent)
    finally:
        host.stop()
        board.close()


def test_echoes_and_other_protocol_versions_do_not_count_as_a_live_board(link_setup):
    board, host, _ = link_setup
    board.talking = False
    stop = threading.Event()

    def babble():
        body = struct.pack('<BBH', 2, proto.MessageType.BOARD_STATUS, 0) + bytes(12)
        alien = proto.cobs_encode(body + struct.pack('<H', proto.crc16_ccitt(body))) + b'\0'
        while not stop.is_set():
            board.write(proto.encode_frame(
                proto.MotorEfforts((0.1, 0.1, 0.1, 0.1), 250), 1))  # our own echo
            board.write(alien)  # a version 2 firmware
            time.sleep(0.02)
    threading.Thread(target=babble, daemon=True).start()
    try:
        host.wait_for(r'The board speaks protocol v2, this node v1')
        # Depending on whether the board had answered since the port opened:
        host.wait_for('(Link to the board .* lost .*no valid frame|does not answer)')
    finally:
        stop.set()


def test_clear_board_faults_service_sends_the_request(link_setup):
    board, host, test_node = link_setup
    client = test_node.node.create_client(Trigger, '/hardware_interface/clear_board_faults')
    response = test_node.call(client, Trigger.Request())
    assert response.success, response.message
    wait_until(lambda: board.frames(proto.ClearFaults))
    assert board.frames(proto.ClearFaults)[0].message.faults == 0xFFFF
    assert host.stop() == 0
    # Shutting down sent a final zero.
    assert board.frames(proto.MotorEfforts)[-1].message.efforts == (0.0, 0.0, 0.0, 0.0)


def test_on_simulated_time_the_board_is_opened_at_the_first_clock(ros_env, test_node,
                                                                  tmp_path):
    """
    The simulator's first /clock messages (0 s, then 0.02 s) open the board at once.

    Not reconnect_period_s (0.3 s here) of simulated time later: until the board
    answers, the simulator runs at real time at most, so each scenario run waited that
    long on the wall clock. No later /clock is sent here: the board opens on these two.
    """
    link = tmp_path / 'ttyESP32'
    board = ScriptedBoard(link)
    host = HostProcess(ros_env, link, 'use_sim_time:=true', 'link_clock:=ros')
    try:
        clock = test_node.node.create_publisher(Clock, '/clock', 10)
        host.wait_for(r'Waiting for the first /clock message .*: 1 publisher\(s\) of /clock')
        deadline = time.monotonic() + 10.0
        while clock.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)    # both ends matched: neither message is lost
        clock.publish(Clock(clock=Time(sec=0)))
        clock.publish(Clock(clock=Time(sec=0, nanosec=20_000_000)))
        host.wait_for('Connected to the board')
    finally:
        host.stop()
        board.close()


def test_on_simulated_time_the_board_is_opened_after_the_first_clock(ros_env, test_node,
                                                                     tmp_path):
    link = tmp_path / 'ttyESP32'
    board = ScriptedBoard(link)
    host = HostProcess(ros_env, link, 'use_sim_time:=true', 'link_clock:=ros')
    try:
        # No /clock yet: the node says what it waits for, and that nobody publishes it.
        host.wait_for(r'Waiting for the first /clock message .*: 0 publisher\(s\) of /clock')
        assert host.count('Connected to the board') == 0
        clock = test_node.node.create_publisher(Clock, '/clock', 10)
        host.wait_for(r'Waiting for the first /clock message .*: 1 publisher\(s\) of /clock')
        clock.publish(Clock(clock=Time(sec=100)))
        host.wait_for('Connected to the board')
        waits = host.count('Waiting for the first /clock')
        for step in range(60):  # 3 s with time running: past the next report's due time
            clock.publish(Clock(clock=Time(sec=100, nanosec=step * 10_000_000)))
            time.sleep(0.05)
        assert host.count('Waiting for the first /clock') == waits
    finally:
        host.stop()
        board.close()
