"""
hardware_interface: the serial link to the ESP32 motor board (protocol: doc/esp32_protocol.md).

Subscribes ``motor_efforts`` (std_msgs/Float32MultiArray, PWM duty -1..1, FL FR RL RR)
and sends them to the board at once; when they stop for 1.5 periods of ``command_rate_hz``,
the last command (zero once older than ``effort_timeout_s``) is repeated at that rate as
keep-alive.
Publishes what the board reports: ``wheel_ticks`` (mecanum_interfaces/WheelTicks),
``imu/data_raw`` (sensor_msgs/Imu: angular velocity and linear acceleration with
covariances from the ``imu_*_stddev_*`` parameters, no orientation; with
``imu_rest_calibration`` the gyro bias, and the accelerometer's x/y bias on a level
floor, are measured whenever the robot rests for ``imu_rest_time_s`` and removed; see
mecanum_control.imu_calibration) and
``/diagnostics`` (link state, board faults, frame statistics). With
``stamp_from_board_clock`` (true) samples are stamped with the time the board measured
them (its clock mapped to ROS time, mecanum_control.board_clock), not when they arrived. Service
``~/clear_board_faults`` (std_srvs/Trigger) asks the board to clear latched faults.

Only the nodes named in ``motor_efforts_publishers`` (velocity_controller in
mecanum_controllers.yaml; '' = not checked) may publish ``motor_efforts``: the
topic's publishers are looked up every ``publisher_check_period_s`` (steady clock), and
while another node publishes it (a stray script, a second controller) zero is sent, an
ERROR names it and /diagnostics reports it, until it has gone; then only efforts received
after that are sent (mecanum_control.publisher_check).

Safety: the port is opened for this program alone (an exclusive flock, as board_check
takes it): a second program is refused with a message naming the holder, and while
another program holds it this node logs that once and retries every
``reconnect_period_s``. Efforts older than ``effort_timeout_s`` are replaced by zero;
on link loss (read error, port gone, or no valid frame for ``link_timeout_s``; for
``first_frame_timeout_s``, 3 s, after the port is opened: a board reset by the opening
sits 2 s in its REPL window) the
stored command is zeroed and the node reopens ``port`` every ``reconnect_period_s``;
after a reconnect only efforts received after it are sent. A zero command is written
before the port is closed when it still takes one; the board itself stops the motors
when commands stop for ``board_command_timeout_ms`` (motor_params.yaml). The link's
timers and timeouts run on the steady clock (a real board lives in real time even when
ROS time stalls), or on ROS time with ``link_clock: ros`` (a board inside the simulator).
A board that never answers is retried quietly after one error message.
A reader thread takes the board's frames as they come; in the simulator's lockstep,
:meth:`HardwareInterface.catch_up` (called by node_main.ClockAnswer before each /clock)
takes whatever the board wrote before that /clock, so it is handled in its own period.
"""

import errno
import math
import os
import select
import sys
import threading
import time
from typing import Optional

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from mecanum_control import esp32_protocol as proto
from mecanum_control.board_check import open_exclusive, PortInUse
from mecanum_control.board_clock import BoardClockSync
from mecanum_control.imu_calibration import ImuRestCalibrator
from mecanum_control.node_main import run_node
from mecanum_control.parameters import declare_robot_config, positive
from mecanum_control.publisher_check_node import (
    declare_publisher_check, MatchWatch, poll_publisher_check, start_publisher_checks)
from mecanum_control.runtime_parameters import read_only_parameters
from mecanum_control.wheel_odometry import wrapped_delta
from mecanum_interfaces.msg import WheelTicks
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import Imu
import serial
from std_msgs.msg import Float32MultiArray
from std_srvs.srv import Trigger

ZERO_EFFORTS = (0.0, 0.0, 0.0, 0.0)
#: Wall-clock seconds between warnings while simulated time has not started.
CLOCK_WAIT_REPORT_S = 2.0
#: Period (simulated s) of the one-shot timer that opens the board at the first /clock.
FIRST_CONNECT_PERIOD_S = 0.001
#: Longest wait of the serial reader for data before it looks at its stop flag again (s).
READ_WAIT_S = 0.05
#: Link seconds a lock held by this very process is taken for the last connection still
#: closing (retried quietly) before it is reported like any other holder's.
OWN_LOCK_GRACE_S = 1.0
#: Command periods without motor_efforts after which the keep-alive repeats the command
#: (so the longest gap between two commands is STREAM_GAP_PERIODS + 1 periods).
STREAM_GAP_PERIODS = 1.5
#: A frame the line takes no byte of for this long (s) means the link is stuck.
WRITE_TIMEOUT_S = 0.1
#: Messages only the board sends: receiving them proves the board is alive.
BOARD_MESSAGES = (proto.EncoderTicks, proto.ImuSample, proto.BoardStatus)


class HardwareInterface(Node):
    """Bridges ROS topics and the ESP32's serial protocol."""

    def __init__(self, **node_options):
        super().__init__('hardware_interface', **node_options)
        config = declare_robot_config(self)
        self.board_command_timeout_ms = config.board_command_timeout_ms
        self.port = self.declare_parameter('port', '/dev/esp32').value
        self.baud_rate = int(self.declare_parameter('baud_rate', 115200).value)
        self.reconnect_period_s = positive(
            'reconnect_period_s', self.declare_parameter('reconnect_period_s', 0.5).value)
        self.link_timeout_s = positive(
            'link_timeout_s', self.declare_parameter('link_timeout_s', 0.5).value)
        # A board reset by the port's opening (a DevKit's DTR/RTS) or just powered sits
        # in its REPL window (2 s) before its firmware talks: the first frame of a
        # connection is waited for this long, not link_timeout_s.
        self.first_frame_timeout_s = max(self.link_timeout_s, positive(
            'first_frame_timeout_s', self.declare_parameter('first_frame_timeout_s',
                                                            3.0).value))
        self.effort_timeout_s = positive(
            'effort_timeout_s', self.declare_parameter('effort_timeout_s', 0.2).value)
        command_rate_hz = positive(
            'command_rate_hz', self.declare_parameter('command_rate_hz', 50.0).value)
        self.imu_frame_id = self.declare_parameter('imu_frame_id', 'imu_link').value
        self.base_frame_id = self.declare_parameter('base_frame_id', 'base_link').value
        gyro_stddev = positive('imu_angular_velocity_stddev_rad_s', self.declare_parameter(
            'imu_angular_velocity_stddev_rad_s', 0.005).value)
        accel_stddev = positive('imu_linear_acceleration_stddev_m_s2', self.declare_parameter(
            'imu_linear_acceleration_stddev_m_s2', 0.05).value)
        # Stamps from the board's clock (when each sample was measured), not receipt.
        self.board_clock = (BoardClockSync() if self.declare_parameter(
            'stamp_from_board_clock', True).value else None)
        self.imu_calibrator = None
        if self.declare_parameter('imu_rest_calibration', True).value:
            self.imu_calibrator = ImuRestCalibrator(rest_time_s=positive(
                'imu_rest_time_s', self.declare_parameter('imu_rest_time_s', 1.0).value))
        self.gyro_covariance = [gyro_stddev ** 2, 0.0, 0.0, 0.0, gyro_stddev ** 2, 0.0,
                                0.0, 0.0, gyro_stddev ** 2]
        self.accel_covariance = [accel_stddev ** 2, 0.0, 0.0, 0.0, accel_stddev ** 2, 0.0,
                                 0.0, 0.0, accel_stddev ** 2]
        self.keepalive_s = 1.0 / command_rate_hz
        if (STREAM_GAP_PERIODS + 1.0) * self.keepalive_s * 1000 >= self.board_command_timeout_ms:
            raise ValueError(f'command_rate_hz {command_rate_hz} is too slow for the board '
                             f'timeout of {self.board_command_timeout_ms} ms')

        self._lock = threading.Lock()  # state shared with the serial reader thread
        self._io_lock = threading.Lock()  # one writer at a time; no close during a write
        self._read_lock = threading.Lock()  # one reader of the line at a time (catch_up)
        # Wakes the reader thread out of its select when the port is closed: a select
        # holds the closed port's file (and so its exclusive lock) until it returns, and
        # a reconnect meanwhile was refused as 'another program holds it' (this one).
        self._wake_read, self._wake_write = os.pipe()
        os.set_blocking(self._wake_write, False)
        self._selecting = threading.Condition()   # the port the reader selects on, if any
        self._selected_port = None
        self._own_lock_at: Optional[float] = None   # link time our own lock was first met
        self._serial: Optional[serial.Serial] = None
        self._connected_at = 0.0
        self._last_frame_at = 0.0
        self._last_sent_at = 0.0
        self._frames_this_connection = 0
        self._quiet = False  # the board does not answer: retry without repeating logs
        self._efforts = ZERO_EFFORTS
        self._efforts_at = -math.inf
        self._tx_seq = {}  # one counter per message type (doc/esp32_protocol.md)
        self._decoder = proto.FrameDecoder()
        self._trackers = {}
        self._totals = {'frames_ok': 0, 'frame_errors': 0, 'frames_lost': 0}
        self._reported_wrong_version = 0
        self._ticks_sequence = 0
        self._last_ticks_seq: Optional[int] = None
        self._last_board_time_us: Optional[int] = None
        self._board_status: Optional[proto.BoardStatus] = None
        self._last_faults = proto.FaultFlags(0)
        self._disconnect_reason = 'not connected yet'
        self._link_losses = 0
        self._stop = threading.Event()

        self.ticks_pub = self.create_publisher(WheelTicks, 'wheel_ticks', 50)
        self.imu_pub = self.create_publisher(Imu, 'imu/data_raw', 50)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.match_watch = MatchWatch(self, self.check_publishers,
                                      lambda: self.efforts_check.unknown_seen)
        self.efforts_sub = self.create_subscription(
            Float32MultiArray, 'motor_efforts', self.on_efforts, 10,
            event_callbacks=self.match_watch.event_callbacks())
        # Only the expected node(s) drive the board (publisher_check): zero meanwhile.
        self.efforts_check = declare_publisher_check(
            self, 'motor_efforts_publishers', self.efforts_sub.topic_name,
            'sending zero efforts to the board', 'sending the efforts received from now on')
        self.publisher_timer = start_publisher_checks(self, [self.efforts_check],
                                                      self.check_publishers)
        self.clear_faults_srv = self.create_service(Trigger, '~/clear_board_faults',
                                                    self.on_clear_faults)
        # A real board (or the real-time emulator) lives in real time: the link's timers
        # and timeouts use the steady clock, even if ROS time stalls. A board inside the
        # simulator lives in simulated time (link_clock: ros), which may run faster or
        # slower than the wall clock.
        link_clock = self.declare_parameter('link_clock', 'steady').value
        if link_clock not in ('steady', 'ros'):
            raise ValueError(f"parameter link_clock must be 'steady' or 'ros', got {link_clock!r}")
        self._link_clock = (self.get_clock() if link_clock == 'ros'
                            else Clock(clock_type=ClockType.STEADY_TIME))
        if self.board_clock is not None and link_clock == 'ros':
            # The simulated board counts simulated time, the clock of this node: the
            # offset is whole u32 wraps, so the stamps carry no transport delay.
            self.board_clock.same_clock = True
        self.command_timer = self.create_timer(self.keepalive_s, self.on_command_timer,
                                               clock=self._link_clock)
        self.link_timer = self.create_timer(self.link_timeout_s / 4, self.check_link,
                                            clock=self._link_clock)
        self.connect_timer = self.create_timer(self.reconnect_period_s, self.connect,
                                               clock=self._link_clock)
        self.diag_timer = self.create_timer(1.0, self.publish_diagnostics,
                                            clock=self._link_clock)
        # On simulated time nothing above runs before the first /clock: say so, on the
        # wall clock, if it does not come (and whether anyone publishes /clock at all).
        # The board is opened at the first /clock, not reconnect_period_s later: until
        # the board answers, the simulator runs at real time at most (its lockstep waits
        # for the board), so every run of a scenario waited 0.5 s of wall time for it.
        self.clock_wait_timer = None
        self.first_connect_timer = None
        if link_clock == 'ros':
            self.first_connect_timer = self.create_timer(
                FIRST_CONNECT_PERIOD_S, self._connect_at_first_clock, clock=self._link_clock)
            self.clock_wait_timer = self.create_timer(
                CLOCK_WAIT_REPORT_S, self.report_clock_wait,
                clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._reader = threading.Thread(target=self._read_loop, name='serial_reader',
                                        daemon=True)
        self._reader.start()
        self.get_logger().info(f'Hardware interface started, board at {self.port} '
                               f'(protocol v{proto.PROTOCOL_VERSION})')
        self.connect()
        read_only_parameters(self)

    def _connect_at_first_clock(self) -> None:
        """Open the board once simulated time has started (once; then the reconnect timer)."""
        self.first_connect_timer.cancel()
        self.connect()

    def report_clock_wait(self) -> None:
        """Warn while simulated time has not started (no /clock message yet)."""
        if self._now() != 0.0:
            self.clock_wait_timer.cancel()
            return
        self.get_logger().warning(
            'Waiting for the first /clock message (use_sim_time) before opening the board: '
            f'{self.count_publishers("/clock")} publisher(s) of /clock discovered')

    def _now(self) -> float:
        """Link time in seconds: steady clock, or simulated time with use_sim_time."""
        return self._link_clock.now().nanoseconds * 1e-9

    # Commands to the board -------------------------------------------------------------
    def on_efforts(self, msg: Float32MultiArray) -> None:
        """Take new efforts; reject malformed ones (and command zero instead)."""
        if self.efforts_check.stopped:
            return  # an unexpected node publishes motor_efforts: nobody drives
        values = list(msg.data)
        if len(values) != 4 or not all(math.isfinite(v) for v in values):
            self.get_logger().warning(
                f'Rejecting motor_efforts {values}: need 4 finite duties (FL FR RL RR); '
                'commanding zero', throttle_duration_sec=1.0)
            values = list(ZERO_EFFORTS)
        if any(abs(v) > 1.0 for v in values):
            self.get_logger().warning(f'motor_efforts {values} beyond +-1 clamped',
                                      throttle_duration_sec=5.0)
        with self._lock:
            self._efforts = tuple(max(-1.0, min(1.0, v)) for v in values)
            self._efforts_at = self._now()
        self._send_efforts()

    def on_command_timer(self) -> None:
        """
        Keep the board's command timeout from firing while the link is up.

        While motor_efforts arrive (each is sent at once) this stays quiet, so the board
        gets one command per control period, the one velocity_controller computed for it
        (the simulator's lockstep waits for it). Once they have been missing for
        STREAM_GAP_PERIODS periods, it repeats the last command (zero once stale) every
        period.
        """
        now = self._now()
        since_sent_s = now - self._last_sent_at
        stream_gone = now - self._efforts_at >= STREAM_GAP_PERIODS * self.keepalive_s
        if (since_sent_s >= STREAM_GAP_PERIODS * self.keepalive_s
                or (stream_gone and since_sent_s >= 0.9 * self.keepalive_s)):
            self._send_efforts()

    def check_publishers(self, may_resume: bool = True) -> None:
        """Send zero while a node other than the expected ones publishes motor_efforts."""
        change = poll_publisher_check(self, self.efforts_check, self.diag_pub, may_resume)
        if change is not None:
            with self._lock:  # 'stop': zero now; 'resume': only efforts from now on
                self._efforts = ZERO_EFFORTS
                self._efforts_at = -math.inf
            if change == 'stop':
                self._send_efforts()

    def on_clear_faults(self, _request, response):
        """Ask the board to clear its latched faults (those whose cause has gone)."""
        response.success = self._send(proto.ClearFaults(proto.FaultFlags(0xFFFF)))
        response.message = ('clear request sent; see /diagnostics for the board faults'
                            if response.success else f'not connected to {self.port}')
        self.get_logger().info(f'Clear board faults: {response.message}')
        return response

    def _driven(self) -> bool:
        """Tell whether a non-zero effort is being sent to the board."""
        with self._lock:
            fresh = self._now() - self._efforts_at <= self.effort_timeout_s
            return fresh and any(e != 0.0 for e in self._efforts)

    def _send_efforts(self) -> None:
        now = self._now()
        with self._lock:
            fresh = (now - self._efforts_at <= self.effort_timeout_s
                     and self._efforts_at > self._connected_at)
            efforts = self._efforts if fresh else ZERO_EFFORTS
        if self._send(proto.MotorEfforts(efforts, self.board_command_timeout_ms)):
            self._last_sent_at = now

    def _next_seq(self, message: proto.Message) -> int:
        """Return the next sequence number of this message type (call with _lock held)."""
        msg_type = proto.message_type_of(message)
        seq = self._tx_seq.get(msg_type, 0)
        self._tx_seq[msg_type] = (seq + 1) % (1 << 16)
        return seq

    def _send(self, message: proto.Message) -> bool:
        """Write one frame to the board; return whether it was written."""
        with self._lock:
            port = self._serial
            if port is None:
                return False
            frame = proto.encode_frame(message, self._next_seq(message))
        try:
            with self._io_lock:
                if self._serial is not port:
                    return False  # the link was dropped meanwhile
                write_all(port.fileno(), frame, WRITE_TIMEOUT_S)
        except (serial.SerialException, OSError, TypeError, ValueError) as error:
            self._lose_link(port, f'write failed: {error}')
            return False
        return True

    # Connection management -------------------------------------------------------------
    def connect(self) -> None:
        """Open the port when not connected (reconnect timer)."""
        if self._serial is not None:
            return
        if self._now() == 0.0:
            # On simulated time before the first /clock: the link's clock has not started,
            # so its timeouts and the samples' stamps would count from 0 (a node restarted
            # mid-run saw 'no valid frame for 27 s' at once). The timer retries.
            return
        try:
            # For this program alone: board_check (or a second stack) is refused, and
            # while it holds the board this node is refused and retries as for an
            # absent port (an error, once per holder).
            port = open_exclusive(self.port, self.baud_rate, timeout=0.05, write_timeout=0)
        except (serial.SerialException, OSError, ValueError) as error:
            own = isinstance(error, PortInUse) and f'pid {os.getpid()}:' in str(error)
            if own and self._own_lock_at is None:
                self._own_lock_at = self._now()
            if own and self._now() - self._own_lock_at < OWN_LOCK_GRACE_S:
                # This process's last connection, still held by the reader's select
                # (woken): closed in a moment; the timer retries. Not another program
                # (past the grace: another node of this process holds it; said below).
                self.get_logger().debug(f'{self.port}: the last connection is still '
                                        'closing; retrying')
                return
            if self._disconnect_reason != str(error):
                self._disconnect_reason = str(error)
                log = (self.get_logger().error if isinstance(error, PortInUse)
                       else self.get_logger().warning)
                log(f'Cannot open {self.port}: {error}; retrying every '
                    f'{self.reconnect_period_s} s')
            return
        try:
            port.reset_input_buffer()
            # delimiter: the board starts decoding at a clean frame
            write_all(port.fileno(), b'\x00', WRITE_TIMEOUT_S)
        except (serial.SerialException, OSError) as error:
            port.close()
            self._disconnect_reason = str(error)
            return
        self._own_lock_at = None
        with self._lock:
            self._add_totals()  # and a fresh decoder and trackers for this connection
            self._serial = port
            self._connected_at = self._now()
            self._frames_this_connection = 0
            self._last_board_time_us = None
        log = self.get_logger().debug if self._quiet else self.get_logger().info
        log(f'Connected to the board at {self.port}')
        self._send_efforts()  # zero: nothing was commanded since this connection
        self.publish_diagnostics()

    def check_link(self) -> None:
        """Drop the link when the board has been silent for link_timeout_s."""
        port = self._serial
        if port is None:
            return
        silent_s = self._now() - max(self._last_frame_at, self._connected_at)
        limit_s = (self.link_timeout_s if self._frames_this_connection
                   else self.first_frame_timeout_s)
        if silent_s > limit_s:
            self._lose_link(port, f'no valid frame from the board for {silent_s:.2f} s')

    def _add_totals(self) -> None:
        """Fold the connection's counters into the totals and start fresh (_lock held)."""
        self._totals['frames_ok'] += self._decoder.stats.frames_ok
        self._totals['frame_errors'] += self._decoder.stats.errors
        self._totals['frames_lost'] += sum(t.lost for t in self._trackers.values())
        self._decoder = proto.FrameDecoder()
        self._trackers = {}

    def _lose_link(self, port: serial.Serial, reason: str) -> None:
        with self._lock:
            if self._serial is not port:
                return  # already handled
            self._serial = None
            self._efforts = ZERO_EFFORTS
            self._efforts_at = -math.inf
            self._disconnect_reason = reason
            self._link_losses += 1
            answered = self._frames_this_connection > 0
            stop = proto.MotorEfforts(ZERO_EFFORTS, self.board_command_timeout_ms)
            zero = proto.encode_frame(stop, self._next_seq(stop))
        with self._io_lock:
            try:
                # best effort: the board's own timeout is the guarantee
                write_all(port.fileno(), zero, WRITE_TIMEOUT_S)
            except (serial.SerialException, OSError, TypeError, ValueError):
                pass
            try:
                port.close()
            except (serial.SerialException, OSError, TypeError):
                pass
        self._wake_reader(port)
        if answered:
            self._quiet = False
            self.get_logger().error(
                f'Link to the board at {self.port} lost ({reason}); zero sent if the port '
                'still took it, the board stops by its own timeout; reconnecting')
        elif not self._quiet:
            self._quiet = True
            self.get_logger().error(
                f'The board at {self.port} does not answer ({reason}); retrying every '
                f'{self.reconnect_period_s} s without repeating this message')
        self.publish_diagnostics()

    def _wake_reader(self, port=None) -> None:
        """
        Wake the reader thread from a select (see __init__).

        Given the port just closed, wait (up to READ_WAIT_S) until the reader's select on
        it has returned, so that its lock is gone when this returns.
        """
        try:
            os.write(self._wake_write, b'w')
        except (BlockingIOError, OSError):
            pass   # already woken (the pipe holds unread bytes) or closed
        if port is not None and threading.current_thread() is not self._reader:
            with self._selecting:
                self._selecting.wait_for(lambda: self._selected_port is not port,
                                         timeout=READ_WAIT_S)

    # Board reports -------------------------------------------------------------------
    def _read_loop(self) -> None:
        while not self._stop.is_set():
            port = self._serial
            if port is None:
                time.sleep(0.02)
                continue
            with self._selecting:
                self._selected_port = port
            try:
                readable, _, _ = select.select([port.fd, self._wake_read], [], [],
                                               READ_WAIT_S)
            except (OSError, TypeError, ValueError) as error:
                self._lose_link(port, f'read failed: {error}')
                continue
            finally:
                with self._selecting:
                    self._selected_port = None
                    self._selecting.notify_all()
            if self._wake_read in readable:
                os.read(self._wake_read, 64)
            elif readable:
                self._read_once(port)

    def _read_once(self, port) -> bool:
        """
        Read and handle what the line has now, without waiting; return whether any.

        It selects again (timeout 0) although the reader thread has just selected: on a
        pty, select also pushes the bytes written to the other side through to this one,
        which a bare non-blocking read does not (catch_up then missed frames written just
        before; tests/test_hardware_interface_catch_up.py).
        """
        with self._read_lock:
            try:
                data = read_available(port.fd, 0.0)
            except (OSError, TypeError, ValueError) as error:
                self._lose_link(port, f'read failed: {error}')
                return False
            if not data:
                return False
            try:
                self._receive(data)
            except Exception as error:  # noqa: B902 - never let the reader die silently
                self.get_logger().error(f'Unexpected error handling board data: {error!r}')
                self._lose_link(port, f'internal error: {error!r}')
            return True

    def catch_up(self) -> bool:
        """
        Take in every frame the board has sent so far; return whether there were any.

        On simulated time node_main.ClockAnswer calls it before the process takes the next
        /clock: the simulated board wrote the frames of the period before it published
        that /clock, so they are handled at the time before, whatever the reader thread's
        luck (it may have taken some already).
        """
        port = self._serial
        took = False
        while port is not None and port is self._serial and self._read_once(port):
            took = True
        return took

    def _receive(self, data: bytes) -> None:
        with self._lock:
            frames = self._decoder.feed(data)
            wrong_version = self._decoder.stats.wrong_version
            other_version = self._decoder.stats.last_wrong_version
        if wrong_version > self._reported_wrong_version:
            self._reported_wrong_version = wrong_version
            self.get_logger().error(
                f'The board speaks protocol v{other_version}, this node v'
                f'{proto.PROTOCOL_VERSION}: its frames are dropped; update the firmware or '
                'this package', throttle_duration_sec=5.0)
        for frame in frames:
            if isinstance(frame.message, BOARD_MESSAGES):  # an echo of ours is not life
                if self._quiet:
                    self._quiet = False
                    self.get_logger().info(f'The board at {self.port} answers')
                self._last_frame_at = self._now()
                self._frames_this_connection += 1
                self._handle(frame)

    def _handle(self, frame: proto.Frame) -> None:
        message = frame.message
        board_time_us = message.board_time_us
        with self._lock:
            last = self._last_board_time_us
            if last is not None and wrapped_delta(last, board_time_us) < -1_000_000:
                self.get_logger().warning('Board clock went back: the board restarted')
                self._trackers = {}
            self._last_board_time_us = board_time_us
            # One sequence counter per message type (doc/esp32_protocol.md).
            tracker = self._trackers.setdefault(type(message), proto.SequenceTracker())
            status = tracker.update(frame.seq)
        if status in ('duplicate', 'stale'):
            return
        now_ns = self.get_clock().now().nanoseconds
        if self.board_clock is not None:
            stamp_ns = int(round(self.board_clock.stamp(board_time_us, now_ns * 1e-9) * 1e9))
        else:
            stamp_ns = now_ns
        stamp = Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
        if isinstance(message, proto.EncoderTicks):
            # Unwrap the 16-bit frame counter into WheelTicks' 32-bit one, keeping gaps.
            step = 1
            if status == 'gap' and self._last_ticks_seq is not None:
                step = proto.seq_delta(self._last_ticks_seq, frame.seq)
            self._last_ticks_seq = frame.seq
            self._ticks_sequence = (self._ticks_sequence + step) % (1 << 32)
            msg = WheelTicks()
            msg.header.stamp = stamp
            msg.header.frame_id = self.base_frame_id
            msg.sequence = self._ticks_sequence
            msg.board_time_us = message.board_time_us
            msg.ticks = [int(t) for t in message.ticks]
            self.ticks_pub.publish(msg)
            if self.imu_calibrator is not None:
                self.imu_calibrator.on_ticks(message.ticks, self._driven(), self._now())
        elif isinstance(message, proto.ImuSample):
            msg = Imu()
            msg.header.stamp = stamp
            msg.header.frame_id = self.imu_frame_id
            msg.orientation_covariance[0] = -1.0  # no orientation estimate
            msg.angular_velocity_covariance = self.gyro_covariance
            msg.linear_acceleration_covariance = self.accel_covariance
            accel, gyro = message.accel_m_s2, message.gyro_rad_s
            if self.imu_calibrator is not None:
                calibrations = self.imu_calibrator.calibrations
                accel, gyro = self.imu_calibrator.on_sample(accel, gyro, self._now())
                if self.imu_calibrator.calibrations == 1 and calibrations == 0:
                    bias = self.imu_calibrator.gyro_bias
                    self.get_logger().info(
                        'IMU calibrated at rest: gyro bias '
                        f'({bias[0]:.5f}, {bias[1]:.5f}, {bias[2]:.5f}) rad/s')
            (msg.linear_acceleration.x, msg.linear_acceleration.y,
             msg.linear_acceleration.z) = (float(a) for a in accel)
            (msg.angular_velocity.x, msg.angular_velocity.y,
             msg.angular_velocity.z) = (float(g) for g in gyro)
            self.imu_pub.publish(msg)
        else:
            self._board_status = message
            new_faults = message.faults & ~self._last_faults
            if new_faults:
                self.get_logger().warning(
                    f'Board reports {proto.describe_faults(new_faults)}')
            self._last_faults = message.faults

    def publish_diagnostics(self) -> None:
        """Publish the link and board state on /diagnostics."""
        with self._lock:
            connected = self._serial is not None
            stats = self._decoder.stats
            totals = dict(self._totals)
            totals['frames_ok'] += stats.frames_ok
            totals['frame_errors'] += stats.errors
            totals['frames_lost'] += sum(t.lost for t in self._trackers.values())
        status = DiagnosticStatus(name='mecanum_control: ESP32 link', hardware_id=self.port)
        board = self._board_status
        if not connected:
            status.level = DiagnosticStatus.ERROR
            status.message = f'disconnected: {self._disconnect_reason}'
        elif board is not None and board.faults:
            status.level = DiagnosticStatus.WARN
            status.message = f'board faults: {proto.describe_faults(board.faults)}'
        else:
            status.level = DiagnosticStatus.OK
            status.message = 'connected'
        values = dict({'port': self.port, 'link_losses': self._link_losses}, **totals)
        values['wrong_version_frames'] = self._reported_wrong_version
        if board is not None:
            values.update(battery_mv=board.battery_mv, board_rx_bad_frames=board.rx_bad_frames,
                          board_faults=proto.describe_faults(board.faults))
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(array)

    def close(self) -> None:
        """Command zero, stop the reader and close the port (clean shutdown)."""
        with self._lock:
            self._efforts_at = -math.inf
        self._send_efforts()
        self._stop.set()
        self._wake_reader()
        self._reader.join(timeout=1.0)
        with self._lock:
            port, self._serial = self._serial, None
        if port is not None:
            with self._io_lock:
                port.close()
        for fd in (self._wake_read, self._wake_write):
            try:
                os.close(fd)
            except OSError:
                pass


def read_available(fd: int, timeout_s: float) -> bytes:
    """
    Return what the port has (up to 4 KiB), waiting up to timeout_s for it (b'': nothing).

    One select and one read per burst of frames: pyserial's read(max(1, in_waiting))
    took a byte, then an ioctl and the rest, for every frame (a tenth of a core in
    lockstep at max speed). Like pyserial, readable but empty means the device is gone.
    """
    readable, _, _ = select.select([fd], [], [], timeout_s)
    if not readable:
        return b''
    try:
        data = os.read(fd, 4096)
    except BlockingIOError:
        return b''
    if not data:
        raise OSError(errno.EIO, 'the device reports data but returns none (unplugged?)')
    return data


def write_all(fd: int, data: bytes, timeout_s: float) -> None:
    """
    Write all of data to a non-blocking port (pyserial opens it so), or raise on a stuck line.

    serial.SerialTimeoutException when the line takes no byte for timeout_s (its output
    buffer stays full: nobody reads the other end). pyserial's write(write_timeout=...)
    checks its deadline after each write, also after one that took everything, so a
    process descheduled longer than write_timeout (a loaded machine: 2 simulations on 2
    cores) got 'Write timeout' for a frame that had gone out, and dropped the link.
    """
    view = memoryview(data)
    deadline = None
    while view:
        try:
            written = os.write(fd, view)
        except BlockingIOError:
            written = 0
        view = view[written:]
        if not view:
            return
        now = time.monotonic()
        if written or deadline is None:
            deadline = now + timeout_s
        elif now >= deadline:
            raise serial.SerialTimeoutException(
                f'Write timeout: the line took nothing for {timeout_s:g} s '
                f'({len(view)} of {len(data)} bytes left)')
        select.select([], [fd], [], deadline - now)


def main(args=None) -> int:
    """Run the hardware_interface node until Ctrl-C or SIGTERM."""
    return run_node(HardwareInterface, 'hardware_interface', args)


if __name__ == '__main__':
    sys.exit(main())
