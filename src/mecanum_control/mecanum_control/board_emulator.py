"""
board_emulator: plays the ESP32 motor board on a pseudo-terminal, for tests without hardware.

It speaks the same protocol code as the hardware_interface node
(:mod:`mecanum_control.esp32_protocol`) and moves four emulated DC gear motors
(:mod:`mecanum_control.board_model`) with the parameters of ``motor_params.yaml``.
The pty's device is published as a symlink (``--link``), like a udev rule's
``/dev/esp32``, so the host opens the same path across re-plugs.

Signals: SIGUSR1 unplugs the board (closes the pty, removes the link), SIGUSR2 plugs it
back in (a new pty behind the same link), SIGINT/SIGTERM stop the program.

Example::

    ros2 run mecanum_control board_emulator --link /tmp/ttyESP32
"""

import argparse
import errno
import os
from pathlib import Path
import random
import select
import shlex
import signal
import sys
import time
import tty
from typing import Dict, List, Optional

from mecanum_control import esp32_protocol as proto
from mecanum_control.board_model import BoardModel, MotorModel
from mecanum_control.robot_config import (
    default_config_path, load_robot_config, RobotConfigError)

WHEELS = ('FL', 'FR', 'RL', 'RR')


class PtyPort:
    """A pseudo-terminal whose device path is published as a symlink."""

    def __init__(self, link: Path):
        self.link = link
        self.master: Optional[int] = None
        self._slave: Optional[int] = None
        self.device = ''

    def plug(self) -> None:
        """Create a new raw pty and point the link at it (atomically)."""
        if self.link.exists() or self.link.is_symlink():
            target = os.readlink(self.link) if self.link.is_symlink() else None
            if target is None or not target.startswith('/dev/pts/'):
                raise FileExistsError(
                    f'{self.link} exists and is not a pseudo-terminal link: refusing to '
                    'replace it (is it a real device?)')
        master, slave = os.openpty()
        try:
            tty.setraw(slave)
            os.set_blocking(master, False)
            device = os.ttyname(slave)
            tmp = self.link.with_name(f'.{self.link.name}.{os.getpid()}')
            if tmp.is_symlink():
                tmp.unlink()
            os.symlink(device, tmp)
            os.replace(tmp, self.link)
        except OSError:
            os.close(master)
            os.close(slave)
            raise
        self.master, self._slave, self.device = master, slave, device
        try:
            os.write(master, b'\x00')  # leading delimiter after boot (protocol doc, 1)
        except OSError:
            pass

    def unplug(self) -> None:
        """Remove the link and close the pty, as pulling the USB cable would."""
        if self.link.is_symlink() and os.readlink(self.link) == self.device:
            self.link.unlink()
        for fd in (self.master, self._slave):
            if fd is not None:
                os.close(fd)
        self.master = self._slave = None

    @property
    def plugged(self) -> bool:
        """Whether the pty exists."""
        return self.master is not None


class BoardLink:
    """
    The firmware's serial side: decodes host frames into the model, sends reports when due.

    Time is whatever the caller passes (``now_s``): the wall clock in the emulator,
    simulated time in the simulator. The model is any object with the interface of
    :class:`mecanum_control.board_model.BoardModel` (``command``, ``clear_faults``,
    ``ticks``, ``imu()``, ``faults``, ``time_us``, ``last_command_seq``).
    """

    def __init__(self, model, port: PtyPort, ticks_rate_hz: float = 50.0,
                 imu_rate_hz: float = 100.0, status_rate_hz: float = 10.0,
                 drop_rate: float = 0.0, corrupt_rate: float = 0.0, seed: Optional[int] = None):
        self.model = model
        self.port = port
        self.periods_s = {proto.MessageType.ENCODER_TICKS: 1.0 / ticks_rate_hz,
                          proto.MessageType.IMU_SAMPLE: 1.0 / imu_rate_hz,
                          proto.MessageType.BOARD_STATUS: 1.0 / status_rate_hz}
        self.drop_rate = drop_rate
        self.corrupt_rate = corrupt_rate
        self._random = random.Random(seed)
        self.decoder = proto.FrameDecoder()
        self.tx_seq: Dict[proto.MessageType, int] = dict.fromkeys(self.periods_s, 0)
        self.rx_bad_frames_reported = 0
        self.due_s: Dict[proto.MessageType, float] = {}
        self._pending = b''
        #: MOTOR_EFFORTS frames taken so far (the simulator's lockstep counts answers).
        self.commands_received = 0

    def plug(self) -> None:
        """Plug the board in: a fresh pty and decoder."""
        self.decoder = proto.FrameDecoder()
        self._pending = b''
        self.port.plug()

    def poll(self, now_s: float) -> None:
        """Take the host's frames, then send every report that is due at now_s."""
        if not self.port.plugged:
            return
        self.receive()
        due = []
        for msg_type, period_s in self.periods_s.items():
            when = self.due_s.setdefault(msg_type, now_s)
            if now_s >= when:
                due.append(self.message(msg_type))
                # Keep the rate; skip beats missed while descheduled.
                self.due_s[msg_type] = max(when + period_s, now_s)
        if due:
            # Reports due together go out in one write, as a UART sends them back to back
            # (and the host's reader wakes once for them, not once per frame).
            self.send(*due)

    def next_due_s(self) -> float:
        """Earliest time a report is due (for the caller's sleep)."""
        return min(self.due_s.values()) if self.due_s else 0.0

    def receive(self) -> None:
        """Read and apply whatever the host sent."""
        try:
            data = os.read(self.port.master, 4096)
        except BlockingIOError:
            return
        except OSError as error:
            if error.errno == errno.EIO:  # no process has the device open
                return
            raise
        for frame in self.decoder.feed(data):
            message = frame.message
            if isinstance(message, proto.MotorEfforts):
                self.model.command(message.efforts, message.command_timeout_ms, frame.seq)
                self.commands_received += 1
            elif isinstance(message, proto.ClearFaults):
                self.model.clear_faults(message.faults)

    def message(self, msg_type: proto.MessageType) -> proto.Message:
        """Build the report of one type from the model's current state."""
        model = self.model
        board_time_us = model.time_us % (1 << 32)
        if msg_type == proto.MessageType.ENCODER_TICKS:
            return proto.EncoderTicks(board_time_us, model.ticks)
        if msg_type == proto.MessageType.IMU_SAMPLE:
            accel, gyro = model.imu()
            return proto.ImuSample(board_time_us, accel, gyro)
        bad = self.decoder.stats.errors
        faults = model.faults
        if bad > self.rx_bad_frames_reported:
            faults |= proto.FaultFlags.RX_ERRORS
            self.rx_bad_frames_reported = bad
        return proto.BoardStatus(board_time_us, faults, 12000, min(bad, 0xFFFF),
                                 model.last_command_seq)

    def send(self, *messages: proto.Message) -> None:
        """Send reports back to back, each numbered per type; the line may drop or corrupt each."""
        data = bytearray()
        for message in messages:
            msg_type = proto.message_type_of(message)
            seq = self.tx_seq[msg_type]
            self.tx_seq[msg_type] = (seq + 1) % (1 << 16)
            frame = bytearray(proto.encode_frame(message, seq))
            if self.drop_rate and self._random.random() < self.drop_rate:
                continue
            if self.corrupt_rate and self._random.random() < self.corrupt_rate:
                index = self._random.randrange(len(frame) - 1)
                frame[index] ^= 1 << self._random.randrange(8)
            data += frame
        if not data:
            return
        if not self._flush_pending():
            return  # the line is still busy with the rest of an earlier frame: drop these
        try:
            written = os.write(self.port.master, bytes(data))
        except (BlockingIOError, OSError):
            return  # nobody reading and the pty buffer is full: the frames are lost, as on a UART
        if written < len(data):
            self._pending = bytes(data[written:])  # never leave half a frame on the line

    def _flush_pending(self) -> bool:
        """Write what is left of a partly written frame; return True when nothing is left."""
        if self._pending:
            try:
                written = os.write(self.port.master, self._pending)
            except (BlockingIOError, OSError):
                return False
            self._pending = self._pending[written:]
        return not self._pending


class BoardEmulator:
    """Runs the board model in real time behind a BoardLink."""

    def __init__(self, model: BoardModel, link: BoardLink):
        self.model = model
        self.link = link
        self.port = link.port
        self.pending_signals: List[int] = []
        self.running = True
        self._in_timeout = True  # motors are off from boot until the first command

    def say(self, text: str) -> None:
        """Log a line on stdout (the launch runner prefixes it with the node's name)."""
        print(f'board_emulator: {text}', flush=True)

    def on_signal(self, signum: int, _frame: object) -> None:
        """Queue the signal; the loop acts on it between steps."""
        self.pending_signals.append(signum)

    def run(self, physics_step_s: float = 0.005) -> None:
        """Run until SIGINT/SIGTERM."""
        self.link.plug()
        self.say(f'plugged in at {self.port.link} ({self.port.device})')
        last = time.monotonic()
        while self.running:
            self._handle_signals()
            now = time.monotonic()
            self.model.step(now - last)
            last = now
            self._report_timeout_changes()
            self.link.poll(now)
            wait = min(self.link.next_due_s() - time.monotonic(), physics_step_s)
            readable = [self.port.master] if self.port.plugged else []
            try:
                select.select(readable, [], [], max(wait, 0.0))
            except InterruptedError:
                pass
        if self.port.plugged:
            self.port.unplug()
        self.say('stopped')

    def _handle_signals(self) -> None:
        while self.pending_signals:
            signum = self.pending_signals.pop(0)
            if signum in (signal.SIGINT, signal.SIGTERM):
                self.running = False
            elif signum == signal.SIGUSR1 and self.port.plugged:
                self.port.unplug()
                self.say('unplugged')
            elif signum == signal.SIGUSR2 and not self.port.plugged:
                self.link.plug()
                self.say(f'plugged in at {self.port.link} ({self.port.device})')

    def _report_timeout_changes(self) -> None:
        in_timeout = bool(self.model.faults & proto.FaultFlags.COMMAND_TIMEOUT)
        if in_timeout != self._in_timeout:
            self._in_timeout = in_timeout
            self.say('no effort command within '
                     f'{self.model.command_timeout_ms} ms: motors stopped' if in_timeout
                     else 'effort commands resumed')


def parse_args(argv: List[str]) -> argparse.Namespace:
    """Parse the command line (anything from --ros-args on is ignored)."""
    if '--ros-args' in argv:
        argv = argv[:argv.index('--ros-args')]
    # ros2 launch passes a substitution such as $(var emulator_args) as ONE argument, even
    # when empty or holding several options: split them as a shell would.
    argv = [part for arg in argv for part in shlex.split(arg)]
    parser = argparse.ArgumentParser(prog='board_emulator', description=__doc__.split('\n')[1])
    parser.add_argument('--link', required=True, type=Path,
                        help='symlink to create for the pty device, e.g. /tmp/ttyESP32')
    parser.add_argument('--config', type=Path, default=None,
                        help='motor_params.yaml (default: the installed one)')
    parser.add_argument('--ticks-rate-hz', type=float, default=50.0)
    parser.add_argument('--imu-rate-hz', type=float, default=100.0)
    parser.add_argument('--status-rate-hz', type=float, default=10.0)
    parser.add_argument('--tick-offset', type=int, default=0,
                        help='initial counter value (e.g. 2147483000 to cross the int32 wrap)')
    parser.add_argument('--imu-noise', action='store_true', help='add IMU sensor noise')
    parser.add_argument('--block-wheel', choices=WHEELS, action='append', default=[],
                        help='emulate a blocked wheel or a disconnected encoder')
    parser.add_argument('--drop-rate', type=float, default=0.0,
                        help='fraction of board frames lost on the line')
    parser.add_argument('--corrupt-rate', type=float, default=0.0,
                        help='fraction of board frames with a flipped bit')
    parser.add_argument('--seed', type=int, default=None)
    args = parser.parse_args(argv)
    for name in ('ticks_rate_hz', 'imu_rate_hz', 'status_rate_hz'):
        if not getattr(args, name) > 0:
            parser.error(f'--{name.replace("_", "-")} must be > 0')
    for name in ('drop_rate', 'corrupt_rate'):
        if not 0.0 <= getattr(args, name) < 1.0:
            parser.error(f'--{name.replace("_", "-")} must be in [0, 1)')
    return args


def main(argv: Optional[List[str]] = None) -> int:
    """Run the emulator until SIGINT/SIGTERM."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    config_path = args.config or default_config_path()
    try:
        config = load_robot_config(config_path)
    except RobotConfigError as error:
        print(f'board_emulator: {error}', file=sys.stderr)
        return 2
    model = BoardModel(
        geometry=config.geometry,
        motor=MotorModel(config.motor_no_load_speed_rad_s, config.motor_time_constant_s),
        rad_per_count=config.rad_per_count,
        imu_accel_noise_m_s2=0.05 if args.imu_noise else 0.0,
        imu_gyro_noise_rad_s=0.005 if args.imu_noise else 0.0,
        seed=args.seed, command_timeout_ms=config.board_command_timeout_ms,
        tick_offset=args.tick_offset)
    for name in args.block_wheel:
        model.wheels[WHEELS.index(name)].blocked = True
    link = BoardLink(model, PtyPort(args.link), args.ticks_rate_hz, args.imu_rate_hz,
                     args.status_rate_hz, args.drop_rate, args.corrupt_rate, args.seed)
    emulator = BoardEmulator(model, link)
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1, signal.SIGUSR2):
        signal.signal(signum, emulator.on_signal)
    try:
        emulator.run()
    except FileExistsError as error:
        print(f'board_emulator: {error}', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
