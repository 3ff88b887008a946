"""
The firmware's own core on simulated hardware: the board the emulator and the simulator serve.

:class:`SimulatedBoard` runs :class:`mecanum_control.board_core.BoardCore`, the code
the ESP32 runs, on :class:`SimulatedHardware`: a hardware layer whose clock, motors,
encoders and IMU are a simulated robot (the *plant*) and whose serial port is the
board's end of a pseudo-terminal (:class:`SerialLine` on a :class:`PtyPort`). So every
emulated or simulated run exercises the firmware's watchdog, fault handling and
framing. The plant is any object with ``time_us`` (int, microseconds since boot),
``ticks`` (four encoder counts FL, FR, RL, RR), ``imu()`` ((ax, ay, az) m/s^2,
(gx, gy, gz) rad/s) and ``efforts`` (four duties -1..1 it applies, set here).

Faults of the hardware (the simulator's fault injection sets them at run time; none is
set by default and none costs anything then): :class:`SimulatedHardware` can hold an
encoder counter still (``set_stuck_encoders``), lose the IMU (``imu_silent``: read_imu
returns None, as the firmware's layer does for a failed IMU, so the board raises
IMU_FAULT) or bias it (``imu_bias``); :class:`SerialLine` can lose bytes, flip bits and
delay bytes in both directions (``set_byte_faults``).
"""

from collections import deque
import errno
import os
from pathlib import Path
import random
import tty
from typing import Deque, Iterable, List, Mapping, Optional, Sequence, Tuple

from mecanum_control import esp32_wire as wire
from mecanum_control.board_core import BoardCore
from mecanum_control.esp32_protocol import FaultFlags

#: The ESP32's MicroPython tick counters wrap at 2^30 (time.ticks_us); so do these.
TICKS_PERIOD = 1 << 30
_TICKS_MASK = TICKS_PERIOD - 1
_TICKS_HALF = TICKS_PERIOD // 2


def _int32(value: int) -> int:
    """Return value as a signed 32-bit register holds it (wrapping)."""
    return ((value + 0x80000000) & 0xFFFFFFFF) - 0x80000000


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


class SerialLine:
    """
    The board's end of the serial line: a pty, with line faults if asked.

    Each frame written may be lost (``drop_rate``) or get one flipped bit
    (``corrupt_rate``). A line whose reader lags drops whole frames, never half of
    one, as a UART with a full buffer does.

    Byte faults (:meth:`set_byte_faults`, settable at any time) act on every byte in
    both directions: lost with probability ``byte_drop_rate``, one bit flipped with
    probability ``bit_flip_rate``, delivered ``latency_s`` late (in the plant's time:
    pass ``now_us`` to :meth:`read` and :meth:`write` and call :meth:`deliver` once a
    loop while :attr:`faulty`). The draws come from one random stream per direction,
    seeded from ``seed``, one or two draws per byte: the same bytes in the same order
    meet the same fate, however they are split into reads and writes.
    """

    def __init__(self, port: PtyPort, drop_rate: float = 0.0, corrupt_rate: float = 0.0,
                 seed: Optional[int] = None):
        self.port = port
        self.drop_rate = drop_rate
        self.corrupt_rate = corrupt_rate
        self._random = random.Random(seed)
        self._pending = b''
        self.byte_drop_rate = 0.0
        self.bit_flip_rate = 0.0
        self.latency_s = 0.0
        self._byte_faults = False
        both = (None, None) if seed is None else (f'{seed}/to board', f'{seed}/to host')
        self._to_board_random = random.Random(both[0])
        self._to_host_random = random.Random(both[1])
        # (due time us, bytes), oldest first: bytes on their way (latency).
        self._delayed_in: Deque[Tuple[int, bytes]] = deque()
        self._delayed_out: Deque[Tuple[int, bytes]] = deque()

    def set_byte_faults(self, drop_rate: float = 0.0, flip_rate: float = 0.0,
                        latency_s: float = 0.0) -> None:
        """
        Set the byte faults of both directions (all 0: a clean line).

        drop_rate and flip_rate are probabilities per byte (0..1), latency_s the delay
        of every byte from now on (>= 0). Bytes already on their way keep their delay;
        none ever overtakes an earlier one.
        """
        for name, value, high in (('drop_rate', drop_rate, 1.0), ('flip_rate', flip_rate, 1.0),
                                  ('latency_s', latency_s, float('inf'))):
            if not (isinstance(value, (int, float)) and 0.0 <= value <= high):
                raise ValueError(f'{name} must be a number in [0, {high}], got {value!r}')
        self.byte_drop_rate = float(drop_rate)
        self.bit_flip_rate = float(flip_rate)
        self.latency_s = float(latency_s)
        self._byte_faults = bool(drop_rate or flip_rate or latency_s)

    @property
    def faulty(self) -> bool:
        """Tell whether byte faults are set or delayed bytes are still on their way."""
        return self._byte_faults or bool(self._delayed_in) or bool(self._delayed_out)

    def plug(self) -> None:
        """Plug the cable in: a fresh pty (its first byte is the leading 0x00)."""
        self._pending = b''
        self._delayed_in.clear()
        self._delayed_out.clear()
        self.port.plug()

    @property
    def plugged(self) -> bool:
        """Whether the pty exists."""
        return self.port.plugged

    def read(self, now_us: int = 0) -> bytes:
        """
        Return what reached the board from the host since the last call (b'' if nothing).

        now_us (the plant's time) matters only with byte faults (latency).
        """
        try:
            data = os.read(self.port.master, 4096)
        except BlockingIOError:
            data = b''
        except OSError as error:
            if error.errno == errno.EIO:  # no process has the device open
                data = b''
            else:
                raise
        if self._byte_faults or self._delayed_in:
            if data and (self.byte_drop_rate or self.bit_flip_rate):
                data = self._spoil_bytes(data, self._to_board_random)
            data = self._delay(self._delayed_in, data, now_us)
        return data

    def deliver(self, now_us: int) -> None:
        """Send the delayed bytes to the host that are due at now_us (latency)."""
        if self._delayed_out:
            self._put(self._delay(self._delayed_out, b'', now_us))

    def write(self, data: bytes, now_us: int = 0) -> None:
        """
        Send frames (each ends with 0x00); the line may drop or corrupt each.

        now_us (the plant's time) matters only with byte faults (latency).
        """
        if self.drop_rate or self.corrupt_rate:
            data = self._spoil(data)
        if self._byte_faults or self._delayed_out:
            if data and (self.byte_drop_rate or self.bit_flip_rate):
                data = self._spoil_bytes(data, self._to_host_random)
            data = self._delay(self._delayed_out, data, now_us)
        self._put(data)

    def _put(self, data: bytes) -> None:
        """Write bytes to the host now, keeping the rest of a partly written frame."""
        if not data or not self.port.plugged:
            return
        if not self._flush_pending():
            return  # the line is still busy with the rest of an earlier frame: drop these
        try:
            written = os.write(self.port.master, data)
        except (BlockingIOError, OSError):
            return  # nobody reading and the pty buffer is full: the frames are lost, as on a UART
        if written < len(data):
            self._pending = bytes(data[written:])  # never leave half a frame on the line

    def _spoil(self, data: bytes) -> bytes:
        """Drop or corrupt whole frames of data at the configured rates."""
        out = bytearray()
        for frame in data.split(wire.FRAME_DELIMITER)[:-1]:
            frame = bytearray(frame + wire.FRAME_DELIMITER)
            if self.drop_rate and self._random.random() < self.drop_rate:
                continue
            if self.corrupt_rate and self._random.random() < self.corrupt_rate:
                index = self._random.randrange(len(frame) - 1)
                frame[index] ^= 1 << self._random.randrange(8)
            out += frame
        return bytes(out)

    def _spoil_bytes(self, data: bytes, rng: random.Random) -> bytes:
        """Lose each byte with byte_drop_rate, flip one bit of each with bit_flip_rate."""
        drop, flip = self.byte_drop_rate, self.bit_flip_rate
        draw = rng.random
        out = bytearray()
        for byte in data:
            if drop and draw() < drop:
                continue
            if flip and draw() < flip:
                byte ^= 1 << rng.randrange(8)
            out.append(byte)
        return bytes(out)

    def _delay(self, queue: Deque[Tuple[int, bytes]], data: bytes, now_us: int) -> bytes:
        """
        Queue data for latency_s from now_us; return the bytes of queue due by now_us.

        First in, first out: bytes never overtake earlier ones, even when the latency
        drops meanwhile (they wait behind them).
        """
        if data:
            queue.append((now_us + round(self.latency_s * 1e6), data))
        out = b''
        while queue and queue[0][0] <= now_us:
            out += queue.popleft()[1]
        return out

    def _flush_pending(self) -> bool:
        """Write what is left of a partly written frame; return True when nothing is left."""
        if self._pending:
            try:
                written = os.write(self.port.master, self._pending)
            except (BlockingIOError, OSError):
                return False
            self._pending = self._pending[written:]
        return not self._pending


class SimulatedHardware:
    """
    The firmware's hardware layer (board_core's ``hw``) on a simulated robot.

    The clock is the plant's time (wrapping like MicroPython's ticks_us), duties go to
    the plant's motors (raw -10000..10000 to -1..1), the counters and the IMU are the
    plant's, the serial port is the line (none: nothing is read, writes vanish).

    Hardware faults: ``imu_silent`` (read_imu returns None: the IMU does not answer),
    ``imu_bias`` (None, or six numbers added to (ax, ay, az, gx, gy, gz)) and
    :meth:`set_stuck_encoders`.
    """

    brownout_reset = False

    def __init__(self, plant, line: Optional[SerialLine] = None, battery_mv: int = 12000):
        self.plant = plant
        self.line = line
        self._battery_mv = battery_mv
        self.imu_silent = False
        self.imu_bias: Optional[Tuple[float, ...]] = None
        self._stuck = {}                  # wheel index -> the count it is stuck at
        self._count_offsets = [0, 0, 0, 0]  # pulses lost while stuck, kept after
        self._counts_faulty = False

    def ticks_us(self) -> int:
        """Return the plant's time in microseconds, wrapping at TICKS_PERIOD."""
        return self.plant.time_us & _TICKS_MASK

    @staticmethod
    def ticks_diff(new: int, old: int) -> int:
        """Signed difference of two tick readings (time.ticks_diff)."""
        return ((new - old + _TICKS_HALF) & _TICKS_MASK) - _TICKS_HALF

    @staticmethod
    def ticks_add(ticks: int, delta: int) -> int:
        """Tick reading delta microseconds on (time.ticks_add)."""
        return (ticks + delta) & _TICKS_MASK

    def read(self) -> bytes:
        """Return the host's bytes since the last call (and deliver delayed ones)."""
        line = self.line
        if line is None or not line.plugged:
            return b''
        if line.faulty:
            now_us = self.plant.time_us
            line.deliver(now_us)
            return line.read(now_us)
        return line.read()

    def write(self, data: bytes) -> None:
        """Send bytes to the host (lost when no line is plugged)."""
        line = self.line
        if line is not None:
            if line.faulty:
                line.write(data, self.plant.time_us)
            else:
                line.write(data)

    def set_duties(self, duties: Sequence[int]) -> None:
        """Drive the plant's motors: raw duties FL, FR, RL, RR."""
        scale = wire.EFFORT_SCALE
        self.plant.efforts = [duty / scale for duty in duties]

    def read_counts(self):
        """Return the plant's encoder counts FL, FR, RL, RR (a stuck counter holds still)."""
        counts = self.plant.ticks
        if not self._counts_faulty:
            return counts
        stuck, offsets = self._stuck, self._count_offsets
        return tuple(stuck[i] if i in stuck else _int32(count + offsets[i])
                     for i, count in enumerate(counts))

    def set_stuck_encoders(self, wheels: Iterable[int]) -> None:
        """
        Hold the counters of these wheels (indices 0..3, FL FR RL RR) still from now on.

        A stuck counter reads the count it had when it stuck; the others count on. A
        counter set free counts on from where it stood, as a quadrature counter that
        missed pulses does: it stays behind the wheel by the pulses it missed.
        """
        wheels = set(wheels)
        if not wheels <= {0, 1, 2, 3}:
            raise ValueError(f'wheel indices must be 0..3 (FL FR RL RR), got {sorted(wheels)}')
        reading = self.read_counts()
        true = self.plant.ticks
        for index in range(4):
            if index in wheels and index not in self._stuck:
                self._stuck[index] = reading[index]
            elif index not in wheels and index in self._stuck:
                held = self._stuck.pop(index)
                self._count_offsets[index] = _int32(held - true[index])
        self._counts_faulty = bool(self._stuck) or any(self._count_offsets)

    def read_imu(self):
        """Return (ax, ay, az, gx, gy, gz) of the plant's IMU (None: it does not answer)."""
        accel, gyro = self.plant.imu()   # sampled even when silent: its noise runs on
        if self.imu_silent:
            return None
        sample = tuple(accel) + tuple(gyro)
        bias = self.imu_bias
        if bias is not None:
            sample = tuple(value + offset for value, offset in zip(sample, bias))
        return sample

    def battery_mv(self) -> int:
        """Return the simulated battery voltage (mV)."""
        return self._battery_mv

    @staticmethod
    def estop_active() -> bool:
        """Tell whether the e-stop input is active: never in simulation."""
        return False

    @staticmethod
    def driver_fault() -> bool:
        """Tell whether a motor driver reports a fault: never in simulation."""
        return False


class LineBoard:
    """
    What every simulated board offers: a hardware layer (``hw``) with its serial line.

    The board of the simulator is this one's subclass :class:`SimulatedBoard` (board_core
    in the process) or robot_simulation's FirmwareBoard (main.py in a process of its
    own), which overrides :attr:`reporting`, :attr:`events` and :meth:`close`.
    """

    hw: SimulatedHardware
    #: (simulated s, text) of each reset of the board, oldest first (none here).
    events: Sequence[Tuple[float, str]] = ()

    @property
    def reporting(self) -> bool:
        """Tell whether the board sends its reports (always, in this process)."""
        return True

    def close(self) -> None:
        """Release what the board holds besides its line (nothing, in this process)."""

    @property
    def line(self) -> Optional[SerialLine]:
        """Return the serial port's line, None when the board is connected to nothing."""
        return self.hw.line

    def attach(self, line: SerialLine) -> None:
        """Connect the board's serial port to a line and plug it in."""
        self.hw.line = line
        line.plug()


class SimulatedBoard(LineBoard):
    """
    The firmware core on simulated hardware, with the host's view of its state.

    Call :meth:`poll` after each physics step (one firmware loop iteration at the
    plant's time). ``efforts`` are the applied duties as fractions -1..1 (FL, FR,
    RL, RR), ``faults`` the fault bits.
    """

    def __init__(self, plant, params: Mapping[str, int], line: Optional[SerialLine] = None):
        self.plant = plant
        self.hw = SimulatedHardware(plant, line)
        self.core = BoardCore(self.hw, params)

    def poll(self) -> None:
        """Run one firmware loop iteration; reports go out only on a plugged line."""
        line = self.hw.line
        self.core.poll(report=line is not None and line.plugged)

    def receive(self) -> None:
        """Take the host's frames now, without sending (the lockstep gate's look)."""
        self.core.receive()

    def command(self, efforts: Sequence[float], command_timeout_ms: int, seq: int) -> None:
        """Apply efforts (-1..1, FL FR RL RR) as a MOTOR_EFFORTS frame would, at once."""
        scale = wire.EFFORT_SCALE
        self.core.command([round(max(-1.0, min(1.0, float(e))) * scale) for e in efforts],
                          command_timeout_ms, seq)
        self.core.enforce(self.hw.ticks_us())

    def clear_faults(self, faults: int) -> None:
        """Clear latched faults as a CLEAR_FAULTS frame would."""
        self.core.clear_faults(int(faults))

    @property
    def commands_received(self) -> int:
        """Return the number of MOTOR_EFFORTS taken so far."""
        return self.core.commands_received

    @property
    def efforts(self) -> List[float]:
        """Return the applied duties, -1..1, FL FR RL RR."""
        scale = wire.EFFORT_SCALE
        return [duty / scale for duty in self.core.duties]

    @property
    def faults(self) -> FaultFlags:
        """Return the board's fault bits."""
        return FaultFlags(self.core.faults)

    @property
    def command_timeout_ms(self) -> int:
        """Return the command timeout of the last command (ms; 0 before one)."""
        return self.core.command_timeout_ms

    @property
    def last_command_seq(self) -> int:
        """Return the sequence number of the last command applied."""
        return self.core.last_command_seq

    @property
    def ticks(self):
        """Return the encoder counters FL, FR, RL, RR."""
        return self.plant.ticks
