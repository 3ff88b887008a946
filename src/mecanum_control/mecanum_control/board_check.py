"""
board_check: open the ESP32 board's serial port and print what it says (no ROS needed).

For a first run after flashing (firmware/README.md) and for a robot that will not
move: it writes the leading 0x00, asks the board to clear its latched faults, sends
zero efforts at 50 Hz (so the watchdog is fed and COMMAND_TIMEOUT should clear) and
prints the board's status, faults, battery, encoder ticks and IMU. With ``--spin FL``
it then turns that wheel at ``--duty`` for ``--spin-seconds`` and says which way it
counted, in counts and wheel turns (counts per turn from the robot config).

The port is opened for this program alone (:func:`open_exclusive`: an exclusive
flock, which hardware_interface takes too): while the robot's stack holds the board,
board_check is refused with a message naming the program holding it, and the other way
round, so two programs never send efforts to the motors at once.

``--calibrate`` (robot on a stand, wheels free; at a terminal) measures each wheel: you
turn it forward by hand exactly ``--turns`` turns (10) and press Enter, then it spins
each at ``--duty`` for ``--spin-seconds``. From the counts it proposes the robot
config's ``gear_ratio`` (counts per wheel turn over ``encoder_counts_per_motor_rev``)
and which motor and encoder ``invert`` to flip in firmware/board_config.py
(mecanum_control.board_calibration), shows both files' diffs and writes them when you
say yes (``--yes``: without asking); then reflash (``make firmware-flash``).

Exit code: 0 if the board answered in protocol v1 with no fault but those it was told
about, and the spun wheel counted forward (with --calibrate: the calibration was
measured, and written if asked); 1 otherwise; 2 if nothing answered or the port could
not be opened (absent, or held by another program).

Example::

    ros2 run mecanum_control board_check --port /dev/ttyUSB0 --spin FL
    ros2 run mecanum_control board_check --port /dev/ttyUSB0 --calibrate
"""

import argparse
import errno
import os
from pathlib import Path
import select
import sys
import threading
import time
from typing import List, Optional, Tuple

from mecanum_control import esp32_protocol as proto
from mecanum_control.robot_config import (
    default_config_path, load_robot_config, RobotConfig, RobotConfigError)
from mecanum_control.wheel_odometry import wrapped_delta

WHEELS = ('FL', 'FR', 'RL', 'RR')
COMMAND_PERIOD_S = 0.02


class PortInUse(OSError):
    """The serial port is held (exclusive lock) by another program; str() names it."""


def open_exclusive(port: str, baud: int, **options):
    """
    Open the board's serial port for this program alone; return the serial.Serial.

    pyserial's ``exclusive=True`` takes flock(LOCK_EX | LOCK_NB) on the device right
    after open(), before it changes any line setting; the kernel drops the lock when the
    port is closed or the program dies. Raises PortInUse naming the program that holds
    it (from /proc/locks), serial.SerialException or OSError for other failures.
    """
    import serial
    try:
        return serial.Serial(port, baud, exclusive=True, **options)
    except serial.SerialException as error:
        if error.errno not in (errno.EAGAIN, errno.EWOULDBLOCK):
            raise
        holder = lock_holder(port)
        raise PortInUse(f'another program holds it ({holder or "which one is unknown"})'
                        ) from None


def lock_holder(path: str) -> str:
    """Return 'pid N: program' of the process holding a flock on path, or ''."""
    try:
        status = os.stat(path)
        with open('/proc/locks', encoding='ascii', errors='replace') as locks:
            lines = locks.readlines()
    except OSError:
        return ''
    # '1: FLOCK  ADVISORY  WRITE 10560 00:1a:3 0 EOF' (device major:minor in hex,
    # inode); lines of waiting processes read '1: -> FLOCK ...'.
    key = f'{os.major(status.st_dev):02x}:{os.minor(status.st_dev):02x}:{status.st_ino}'
    for line in lines:
        fields = line.split()
        if len(fields) >= 6 and fields[1] == 'FLOCK' and fields[5] == key:
            pid = fields[4]
            if not pid.isdigit() or int(pid) <= 0:
                return 'a process outside this PID namespace'
            return f'pid {pid}: {program_name(int(pid))}'
    return ''


def program_name(pid: int) -> str:
    """Return a short name of a process's program (the script or module, not 'python')."""
    try:
        with open(f'/proc/{pid}/cmdline', 'rb') as cmdline:
            args = [arg.decode(errors='replace') for arg in cmdline.read().split(b'\0') if arg]
    except OSError:
        return 'unknown program'
    if not args:
        return 'unknown program'
    if os.path.basename(args[0]).startswith('python') and len(args) > 1:
        args = args[1:]
        if args[0] == '-m' and len(args) > 1:
            return args[1]
        args = [arg for arg in args if not arg.startswith('-')] or args
    return os.path.basename(args[0])


class BoardSession:
    """The host's end of the link, on a file descriptor: commands out, frames in."""

    def __init__(self, fd: int, command_timeout_ms: int):
        self.fd = fd
        self.command_timeout_ms = command_timeout_ms
        self.decoder = proto.FrameDecoder()
        self.seq = {proto.MessageType.MOTOR_EFFORTS: 0, proto.MessageType.CLEAR_FAULTS: 0}
        self.frames: List[proto.Frame] = []
        self.last_effort_seq = 0
        os.write(fd, proto.FRAME_DELIMITER)   # leading delimiter after opening the port

    def send(self, message: proto.Message) -> None:
        """Send one message, numbered per type."""
        msg_type = proto.message_type_of(message)
        self.seq[msg_type] = (self.seq[msg_type] + 1) % proto.SEQ_MODULUS
        if msg_type == proto.MessageType.MOTOR_EFFORTS:
            self.last_effort_seq = self.seq[msg_type]
        os.write(self.fd, proto.encode_frame(message, self.seq[msg_type]))

    def drive(self, efforts: Tuple[float, float, float, float], seconds: float) -> None:
        """Send efforts (duty -1..1, FL FR RL RR) at 50 Hz for seconds, taking frames."""
        end = time.monotonic() + seconds
        next_command = time.monotonic()
        while True:
            now = time.monotonic()
            if now >= end:
                break
            if now >= next_command:
                self.send(proto.MotorEfforts(efforts, self.command_timeout_ms))
                next_command += COMMAND_PERIOD_S
            self.receive(min(next_command, end) - time.monotonic())

    def receive(self, wait_s: float) -> None:
        """Take what arrives within wait_s."""
        readable, _, _ = select.select([self.fd], [], [], max(0.0, wait_s))
        if readable:
            try:
                data = os.read(self.fd, 4096)
            except BlockingIOError:
                return
            self.frames += self.decoder.feed(data)

    def latest(self, kind: type) -> Optional[proto.Message]:
        """Return the latest message of a class, or None."""
        for frame in reversed(self.frames):
            if isinstance(frame.message, kind):
                return frame.message
        return None

    def count(self, kind: type) -> int:
        """Return how many messages of a class came."""
        return sum(isinstance(frame.message, kind) for frame in self.frames)


def report(session: BoardSession, seconds: float) -> Tuple[List[str], bool]:
    """Return the lines describing what the board sent, and whether it looks healthy."""
    lines = []
    stats = session.decoder.stats
    status = session.latest(proto.BoardStatus)
    healthy = status is not None
    rates = ', '.join(f'{session.count(kind) / seconds:.0f} Hz {kind.__name__}'
                      for kind in (proto.EncoderTicks, proto.ImuSample, proto.BoardStatus))
    lines.append(f'frames: {stats.frames_ok} good, {stats.errors} dropped ({rates})')
    if stats.wrong_version:
        lines.append(f'the board speaks protocol v{stats.last_wrong_version}, this host '
                     f'v{proto.PROTOCOL_VERSION}: flash matching firmware')
        healthy = False
    if status is None:
        lines.append('no BOARD_STATUS: is the firmware running (not the REPL), at 115200 baud?')
        return lines, False
    lines.append(f'faults: {proto.describe_faults(status.faults)}')
    lines.append(f'battery: {status.battery_mv / 1000:.2f} V' if status.battery_mv
                 else 'battery: not measured')
    lines.append(f'board dropped {status.rx_bad_frames} frames of ours; last command applied '
                 f'#{status.last_command_seq} (sent #{session.last_effort_seq})')
    if status.faults:
        healthy = False
    ticks = session.latest(proto.EncoderTicks)
    if ticks is not None:
        lines.append('ticks: ' + ', '.join(f'{w} {t}' for w, t in zip(WHEELS, ticks.ticks)))
    imu = session.latest(proto.ImuSample)
    if imu is None:
        lines.append('imu: no samples')
    else:
        accel = ', '.join(f'{a:.2f}' for a in imu.accel_m_s2)
        gyro = ', '.join(f'{g:.3f}' for g in imu.gyro_rad_s)
        lines.append(f'imu: accel [{accel}] m/s^2 (|a| '
                     f'{sum(a * a for a in imu.accel_m_s2) ** 0.5:.2f}), gyro [{gyro}] rad/s')
    return lines, healthy


def spin(session: BoardSession, wheel: str, duty: float, seconds: float,
         config: RobotConfig) -> Tuple[List[str], bool]:
    """Turn one wheel at duty for seconds; return what it counted and whether forward."""
    index = WHEELS.index(wheel)
    before = session.latest(proto.EncoderTicks)
    efforts = [0.0] * 4
    efforts[index] = duty
    session.drive(tuple(efforts), seconds)
    session.drive((0.0, 0.0, 0.0, 0.0), 0.3)
    after = session.latest(proto.EncoderTicks)
    if before is None or after is None:
        return [f'spin {wheel}: no ENCODER_TICKS'], False
    moved = counts_moved(before, after)
    turns = moved[index] / config.counts_per_wheel_rev
    others = ', '.join(f'{w} {m}' for w, m in zip(WHEELS, moved) if w != wheel)
    line = (f'spin {wheel} at duty {duty:+.2f} for {seconds:.1f} s: {moved[index]:+d} counts '
            f'({turns:+.2f} wheel turns); others: {others}')
    expected = 1 if duty > 0 else -1
    if moved[index] * expected > 0:
        return [line, f'spin {wheel}: counted the right way'], True
    if moved[index] == 0:
        why = 'no counts: motor not turning (wiring, driver, power) or encoder not connected'
    else:
        why = ('counted backwards: flip this wheel\'s motor "invert" or encoder "invert" in '
               'firmware/board_config.py')
    return [line, f'spin {wheel}: {why}'], False


def parse_args(argv: List[str]) -> argparse.Namespace:
    """Parse the command line (anything from --ros-args on is ignored)."""
    if '--ros-args' in argv:
        argv = argv[:argv.index('--ros-args')]
    parser = argparse.ArgumentParser(prog='board_check', description=__doc__.split('\n')[1])
    parser.add_argument('--port', required=True, help='serial port, e.g. /dev/ttyUSB0')
    parser.add_argument('--baud', type=int, default=115200)
    parser.add_argument('--config', type=Path, default=None,
                        help='motor_params.yaml (default: the installed one)')
    parser.add_argument('--seconds', type=float, default=1.0,
                        help='how long to listen (sending zero efforts)')
    parser.add_argument('--spin', choices=WHEELS, help='turn this wheel afterwards')
    parser.add_argument('--duty', type=float, default=0.2, help='duty of the spin, -1..1')
    parser.add_argument('--spin-seconds', type=float, default=2.0)
    parser.add_argument('--calibrate', action='store_true',
                        help="measure counts per wheel turn and each wheel's directions "
                        '(you turn each wheel by hand), then update motor_params.yaml and '
                        'firmware/board_config.py, showing the diff first')
    parser.add_argument('--turns', type=float, default=10.0,
                        help='wheel turns you make by hand per wheel (--calibrate)')
    parser.add_argument('--board-config', type=Path, default=None,
                        help='firmware/board_config.py to update (default: the source '
                        "tree's)")
    parser.add_argument('--yes', action='store_true',
                        help='write the calibration without asking')
    args = parser.parse_args(argv)
    if args.calibrate and ask_user is input and not sys.stdin.isatty():
        parser.error('--calibrate asks you to turn each wheel by hand: run it at a terminal')
    if args.calibrate and args.spin:
        parser.error('--calibrate spins every wheel itself: leave out --spin')
    if args.calibrate and (not args.turns > 0 or args.duty < 0):
        parser.error('--calibrate needs --turns > 0 and a positive --duty')
    if not -1.0 <= args.duty <= 1.0 or args.duty == 0.0:
        parser.error('--duty must be in [-1, 1] and not 0')
    if not args.seconds > 0 or not args.spin_seconds > 0:
        parser.error('--seconds and --spin-seconds must be > 0')
    return args


def main(argv: Optional[List[str]] = None) -> int:
    """Check the board and print the findings."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        config = load_robot_config(args.config or default_config_path())
    except RobotConfigError as error:
        print(f'board_check: {error}', file=sys.stderr)
        return 2
    import serial
    try:
        line = open_exclusive(args.port, args.baud, timeout=0)
    except PortInUse as error:
        print(f'board_check: cannot open {args.port}: {error}; stop it first (the robot '
              'stack, or another board_check): one program at a time drives the board',
              file=sys.stderr)
        return 2
    except (OSError, ValueError, serial.SerialException) as error:
        print(f'board_check: cannot open {args.port}: {error}', file=sys.stderr)
        return 2
    with line:
        session = BoardSession(line.fileno(), config.board_command_timeout_ms)
        if args.calibrate:
            return calibrate_board(session, args, config)
        return check(session, args, config)


def check(session: BoardSession, args: argparse.Namespace, config: RobotConfig) -> int:
    """Run the check on an open session; return the exit code."""
    session.send(proto.ClearFaults(proto.FaultFlags(0xFFFF)))
    session.drive((0.0, 0.0, 0.0, 0.0), args.seconds)
    lines, healthy = report(session, args.seconds)
    print(f'board_check: {args.port}, protocol v{proto.PROTOCOL_VERSION}')
    for line in lines:
        print('  ' + line)
    if not session.frames:
        print('board_check: the board did not answer', file=sys.stderr)
        return 2
    if args.spin:
        lines, forward = spin(session, args.spin, args.duty, args.spin_seconds, config)
        for line in lines:
            print('  ' + line)
        healthy = healthy and forward
        status = session.latest(proto.BoardStatus)
        if status is not None and status.faults:
            print(f'  faults after the spin: {proto.describe_faults(status.faults)}')
            healthy = False
    print('board_check: ' + ('OK' if healthy else 'PROBLEMS (see above)'))
    return 0 if healthy else 1


#: How --calibrate asks the person at the robot (a test replaces it).
ask_user = input


def ask_while_listening(session: BoardSession, prompt: str) -> str:
    """Ask the user (blocking) while a thread keeps taking the board's frames."""
    stop = threading.Event()

    def listen():
        while not stop.is_set():
            session.receive(0.05)
    listener = threading.Thread(target=listen, daemon=True)
    listener.start()
    try:
        return ask_user(prompt)
    finally:
        stop.set()
        listener.join()


def counts_moved(before: proto.EncoderTicks, after: proto.EncoderTicks) -> List[int]:
    """Return each wheel's counts from one report to another (the counters wrap)."""
    return [wrapped_delta(a, b) for a, b in zip(before.ticks, after.ticks)]


def fresh_ticks(session: BoardSession) -> Optional[proto.EncoderTicks]:
    """Return the board's latest ENCODER_TICKS after 0.2 s more of listening."""
    session.drive((0.0, 0.0, 0.0, 0.0), 0.2)
    return session.latest(proto.EncoderTicks)


def calibrate_board(session: BoardSession, args: argparse.Namespace,
                    config: RobotConfig) -> int:
    """Measure the wheels, propose the calibration, show the diffs, write when told to."""
    from mecanum_control.board_calibration import (
        board_config_text, calibrate, CalibrationError, motor_params_text, unified_diff)
    print(f'board_check --calibrate: {args.port}. Put the robot on a stand, wheels off '
          'the ground. Mark each wheel (tape on the tyre) to count its turns.')
    session.send(proto.ClearFaults(proto.FaultFlags(0xFFFF)))
    if fresh_ticks(session) is None:
        print('board_check: no ENCODER_TICKS from the board', file=sys.stderr)
        return 2
    hand = []
    for index, wheel in enumerate(WHEELS):
        before = fresh_ticks(session)
        ask_while_listening(session, f'  {wheel}: turn it FORWARD (the way that rolls the '
                            f'robot forward) by hand exactly {args.turns:g} turns, then '
                            'press Enter ')
        hand.append(counts_moved(before, fresh_ticks(session))[index])
        print(f'  {wheel}: {hand[-1]:+d} counts')
    spins = []
    for index, wheel in enumerate(WHEELS):
        # Turning by hand (or a reversed motor) may trip the runaway check: cleared.
        session.send(proto.ClearFaults(proto.FaultFlags(0xFFFF)))
        before = fresh_ticks(session)
        efforts = [0.0] * 4
        efforts[index] = args.duty
        session.drive(tuple(efforts), args.spin_seconds)
        spins.append(counts_moved(before, fresh_ticks(session))[index])
        print(f'  {wheel}: spun at duty {args.duty:+.2f} for {args.spin_seconds:g} s: '
              f'{spins[-1]:+d} counts')
    session.send(proto.ClearFaults(proto.FaultFlags(0xFFFF)))
    try:
        result = calibrate(hand, args.turns, spins, args.duty,
                           config.encoder_counts_per_motor_rev)
    except CalibrationError as error:
        print(f'board_check: no calibration: {error}', file=sys.stderr)
        return 1
    for line in result.lines():
        print('  ' + line)
    params_path = Path(os.path.realpath(args.config or default_config_path()))
    if args.board_config is not None:
        wiring_path = args.board_config
    else:
        from mecanum_control.firmware_tree import firmware_dir, FirmwareUnavailable
        try:
            wiring_path = firmware_dir() / 'board_config.py'
        except FirmwareUnavailable as error:
            print(f'board_check: {error}; give --board-config', file=sys.stderr)
            return 1
    changes = []
    try:
        for path, edit in ((params_path, lambda text: motor_params_text(
                text, result.gear_ratio)), (wiring_path, lambda text: board_config_text(
                    text, result.flip_motor, result.flip_encoder))):
            before = path.read_text()
            after = edit(before)
            if after != before:
                changes.append((path, after))
                print(unified_diff(before, after, str(path)), end='')
    except (OSError, CalibrationError) as error:
        print(f'board_check: {error}', file=sys.stderr)
        return 1
    if not changes:
        print('board_check: the files already say this: nothing to change')
        return 0
    if not args.yes and ask_user('Write these changes? [y/N] ').strip().lower() not in (
            'y', 'yes'):
        print('board_check: nothing written')
        return 0
    for path, text in changes:
        path.write_text(text)
        print(f'board_check: wrote {path}')
    print('board_check: reflash the board (make firmware-flash PORT=...) for the firmware '
          'to use them, and rebuild if the robot config is installed (colcon build)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
