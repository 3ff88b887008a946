"""
board_emulator: plays the ESP32 motor board on a pseudo-terminal, for tests without hardware.

It runs the ESP32 firmware's own core (:mod:`mecanum_control.board_core`: protocol,
command watchdog, fault checks) on simulated hardware (:mod:`mecanum_control.board_sim`)
that moves four emulated DC gear motors (:mod:`mecanum_control.board_model`) with the
parameters of ``motor_params.yaml``.
The pty's device is published as a symlink (``--link``), like a udev rule's
``/dev/esp32``, so the host opens the same path across re-plugs.

Signals: SIGUSR1 unplugs the board (closes the pty, removes the link), SIGUSR2 plugs it
back in (a new pty behind the same link), SIGINT/SIGTERM stop the program.

``--board firmware`` (or ``--firmware``) plays the board with the firmware as flashed
instead of the firmware's core on a model (``--board core``): firmware/main.py
run by MicroPython's unix port on stand-in machine hardware (wheels without load or
lag: firmware/unix_port/unix_firmware.py), taken from the source tree (symlink install);
SIGINT/SIGTERM stop it, the other options do not apply.

Example::

    ros2 run mecanum_control board_emulator --link /tmp/ttyESP32
"""

import argparse
from pathlib import Path
import select
import shlex
import signal
import sys
import time
from typing import List, Optional

from mecanum_control import esp32_protocol as proto
from mecanum_control.board_model import BoardModel, MotorModel
from mecanum_control.board_params import board_params
from mecanum_control.board_sim import PtyPort, SerialLine, SimulatedBoard
from mecanum_control.robot_config import (
    default_config_path, load_robot_config, RobotConfigError)

WHEELS = ('FL', 'FR', 'RL', 'RR')


class BoardEmulator:
    """Runs the firmware core on the board model in real time (wall clock)."""

    def __init__(self, model: BoardModel, board: SimulatedBoard):
        self.model = model
        self.board = board
        self.line = board.line
        self.port = self.line.port
        self.pending_signals: List[int] = []
        self.running = True
        self._in_timeout = True  # motors are off from boot until the first command
        self._encoder_faults_said = False

    def say(self, text: str) -> None:
        """Log a line on stdout (the launch runner prefixes it with the node's name)."""
        print(f'board_emulator: {text}', flush=True)

    def on_signal(self, signum: int, _frame: object) -> None:
        """Queue the signal; the loop acts on it between steps."""
        self.pending_signals.append(signum)

    def run(self, physics_step_s: float = 0.005) -> None:
        """Run until SIGINT/SIGTERM."""
        self.line.plug()
        self.say(f'plugged in at {self.port.link} ({self.port.device})')
        last = time.monotonic()
        while self.running:
            self._handle_signals()
            now = time.monotonic()
            self.model.step(now - last)
            last = now
            self.board.poll()
            self._report_timeout_changes()
            wait = min(self.board.core.idle_us() * 1e-6, physics_step_s)
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
                self.line.plug()
                self.say(f'plugged in at {self.port.link} ({self.port.device})')

    def _report_timeout_changes(self) -> None:
        in_timeout = bool(self.board.faults & proto.FaultFlags.COMMAND_TIMEOUT)
        if in_timeout != self._in_timeout:
            self._in_timeout = in_timeout
            self.say('no effort command within '
                     f'{self.board.command_timeout_ms} ms: motors stopped' if in_timeout
                     else 'effort commands resumed')
        faults = self.board.core.encoder_fault_wheels
        if faults and not self._encoder_faults_said:
            names = ', '.join(name for index, name in enumerate(WHEELS) if faults & 1 << index)
            self.say(f'ENCODER_FAULT ({names}): motors off until CLEAR_FAULTS')
        self._encoder_faults_said = bool(faults)


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
    parser.add_argument('--board', choices=('core', 'firmware'), default='core',
                        help="core: the firmware's core on a board model (default); "
                        'firmware: firmware/main.py as flashed under MicroPython (unix port)')
    parser.add_argument('--firmware', action='store_true', help='the same as --board firmware')
    args = parser.parse_args(argv)
    args.firmware = args.firmware or args.board == 'firmware'
    if args.firmware and (args.block_wheel or args.drop_rate or args.corrupt_rate
                          or args.imu_noise or args.tick_offset):
        parser.error('--board firmware runs the flashed firmware as it is: no other option')
    for name in ('drop_rate', 'corrupt_rate'):
        if not 0.0 <= getattr(args, name) < 1.0:
            parser.error(f'--{name.replace("_", "-")} must be in [0, 1)')
    return args


def run_firmware(link: Path) -> int:
    """Run firmware/main.py under the unix port at link until SIGINT/SIGTERM."""
    import tempfile
    import threading
    from mecanum_control.firmware_tree import FirmwareUnavailable, unix_port
    try:
        unix = unix_port()
    except FirmwareUnavailable as error:
        print(f'board_emulator: --board firmware: {error}', file=sys.stderr)
        return 2
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    with tempfile.TemporaryDirectory(prefix='mecanum_firmware_') as folder:
        board = unix.UnixFirmwareBoard(Path(folder), link)
        print(f'board_emulator: firmware/main.py under MicroPython (unix port) at {link}',
              flush=True)
        try:
            while not stop.wait(0.5):
                if board.resets:
                    print(f'board_emulator: watchdog resets: {board.resets}', flush=True)
        finally:
            board.close()
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    """Run the emulator until SIGINT/SIGTERM."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    if args.firmware:
        return run_firmware(args.link)
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
        seed=args.seed, tick_offset=args.tick_offset)
    for name in args.block_wheel:
        model.wheels[WHEELS.index(name)].blocked = True
    line = SerialLine(PtyPort(args.link), args.drop_rate, args.corrupt_rate, args.seed)
    board = SimulatedBoard(model, board_params(config), line)
    emulator = BoardEmulator(model, board)
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
