"""
Serial wire protocol (version 1) between the host and the ESP32 motor/IMU board: typed host API.

Pure Python, no ROS. The full specification for firmware writers is
``doc/esp32_protocol.md`` in this package. The bytes themselves (layouts, CRC, COBS,
the frame decoder) are :mod:`mecanum_control.esp32_wire`, the one module the host
and the board's MicroPython firmware both run; this module puts types on it:
``MessageType`` and ``FaultFlags`` enums, one frozen dataclass per message, field
checks that raise ``ProtocolError``, and the receive-side ``SequenceTracker``.

Conventions:

* Every frame is COBS-encoded and terminated by one 0x00 byte. A receiver
  resynchronises at the next 0x00; two 0x00 in a row (an empty frame) is idle
  line / flush and is not an error. A sender should write one 0x00 after
  opening the port or after an error, so that whatever the receiver holds is
  terminated before the first real frame (``encode_frame`` does not add it).
* Decoded frame body: version (u8), message type (u8), sequence number (u16),
  fixed-size payload, CRC-16/CCITT-FALSE (u16) over everything before it.
  All multi-byte fields are little-endian.
* Wheel order is always FL, FR, RL, RR. Positive effort and positive ticks
  mean the wheel turns so as to roll the robot forward.
* Units are in the field names: ``_us`` microseconds of the board clock
  (u32, wraps), ``_ms`` milliseconds, ``_mv`` millivolts, ``m_s2`` m/s^2,
  ``rad_s`` rad/s. Efforts are duty fractions in [-1, 1], carried as int16
  scaled by ``EFFORT_SCALE`` (+-10000 = full PWM).
* Counters with modular meaning wrap on encoding (sequence numbers mod 2^16,
  board time mod 2^32, encoder ticks into the int32 range); ``rx_bad_frames``
  saturates at 65535; every other field out of range raises ``ProtocolError``.
"""

from dataclasses import dataclass
import enum
import math
import operator
from typing import Callable, Dict, List, Optional, Tuple, Type, Union

from mecanum_control import esp32_wire as wire

PROTOCOL_VERSION = wire.PROTOCOL_VERSION
EFFORT_SCALE = wire.EFFORT_SCALE
MAX_FRAME_BYTES = wire.MAX_FRAME_BYTES
"""
Bound on an encoded frame, COBS overhead and 0x00 delimiter included.

It is part of the framing and holds for every protocol version (the largest
version 1 frame, IMU_SAMPLE, is 36 bytes), so a receiver can always tell a
frame of another version from line noise. ``FrameDecoder`` discards a run of
more than ``MAX_FRAME_BYTES - 1`` bytes without a 0x00.
"""

FRAME_DELIMITER = wire.FRAME_DELIMITER
HEADER_BYTES = wire.HEADER_BYTES
CRC_BYTES = wire.CRC_BYTES
SEQ_MODULUS = wire.SEQ_MODULUS
_TIME_MODULUS = 1 << 32
_U16_MAX = wire.U16_MAX
_FLOAT32_MAX = 3.4028234663852886e38


class MessageType(enum.IntEnum):
    """Message type byte; 0x01-0x7F travel host -> board, 0x81-0xFF board -> host."""

    MOTOR_EFFORTS = wire.MOTOR_EFFORTS
    CLEAR_FAULTS = wire.CLEAR_FAULTS
    ENCODER_TICKS = wire.ENCODER_TICKS
    IMU_SAMPLE = wire.IMU_SAMPLE
    BOARD_STATUS = wire.BOARD_STATUS


class FaultFlags(enum.IntFlag):
    """Fault bits of BOARD_STATUS (and of CLEAR_FAULTS, for the latched ones)."""

    NONE = 0
    COMMAND_TIMEOUT = wire.COMMAND_TIMEOUT
    ESTOP_INPUT = wire.ESTOP_INPUT
    ENCODER_FAULT = wire.ENCODER_FAULT
    IMU_FAULT = wire.IMU_FAULT
    LOW_BATTERY = wire.LOW_BATTERY
    MOTOR_DRIVER_FAULT = wire.MOTOR_DRIVER_FAULT
    RX_ERRORS = wire.RX_ERRORS
    BROWNOUT_RESET = wire.BROWNOUT_RESET


_FAULT_BITS: Tuple[FaultFlags, ...] = tuple(
    flag for flag in sorted(FaultFlags, key=int) if int(flag) != 0)


def describe_faults(flags: int) -> str:
    """
    Name the set fault bits, e.g. ``'COMMAND_TIMEOUT, LOW_BATTERY'``, or ``'none'``.

    Bits without a name are listed as ``UNKNOWN(0x0100)``.
    """
    value = int(flags)
    names = []
    for flag in _FAULT_BITS:
        if value & int(flag):
            names.append(str(flag.name))
            value &= ~int(flag)
    if value:
        names.append(f'UNKNOWN(0x{value:04X})')
    return ', '.join(names) if names else 'none'


class ProtocolError(ValueError):
    """A message cannot be encoded, or bytes are not a valid frame."""


@dataclass(frozen=True)
class MotorEfforts:
    """
    Host -> board: duty per wheel FL, FR, RL, RR in [-1, 1] and the command timeout.

    Encoding rejects NaN/inf, clamps to [-1, 1] and rounds to the 1/EFFORT_SCALE
    grid (nearest, ties to even). ``command_timeout_ms`` must be 1..65535: the
    board stops all motors by itself if no MOTOR_EFFORTS arrives for that long.
    """

    efforts: Tuple[float, float, float, float]
    command_timeout_ms: int


@dataclass(frozen=True)
class ClearFaults:
    """Host -> board: clear these latched fault bits (if their cause is gone)."""

    faults: FaultFlags


@dataclass(frozen=True)
class EncoderTicks:
    """
    Board -> host: free-running quadrature counters FL, FR, RL, RR.

    The counters wrap modulo 2^32 (int32 on the wire); encoding wraps any
    Python int into the int32 range, so differences must be taken modulo 2^32.
    """

    board_time_us: int
    ticks: Tuple[int, int, int, int]


@dataclass(frozen=True)
class ImuSample:
    """Board -> host: accelerometer (m/s^2) and gyro (rad/s) x, y, z in the IMU frame."""

    board_time_us: int
    accel_m_s2: Tuple[float, float, float]
    gyro_rad_s: Tuple[float, float, float]


@dataclass(frozen=True)
class BoardStatus:
    """
    Board -> host heartbeat (about 10 Hz).

    ``rx_bad_frames`` counts frames the board dropped (saturating at 65535);
    ``last_command_seq`` is the sequence number of the last MOTOR_EFFORTS applied.
    """

    board_time_us: int
    faults: FaultFlags
    battery_mv: int
    rx_bad_frames: int
    last_command_seq: int


Message = Union[MotorEfforts, ClearFaults, EncoderTicks, ImuSample, BoardStatus]


@dataclass(frozen=True)
class Frame:
    """A decoded frame: the sender's sequence number and the message."""

    seq: int
    message: Message


# ---------------------------------------------------------------- CRC and COBS


def crc16_ccitt(data: bytes) -> int:
    """
    CRC-16/CCITT-FALSE of ``data``.

    Polynomial 0x1021, initial value 0xFFFF, no input/output reflection, no final
    XOR; the check value of ``b'123456789'`` is 0x29B1.
    """
    return wire.crc16_ccitt(data)


def cobs_encode(data: bytes) -> bytes:
    """
    Consistent Overhead Byte Stuffing of ``data``, without the trailing 0x00.

    The result contains no 0x00 and is ``len(data) + max(1, ceil(len(data) / 254))``
    bytes long at most. A block of 254 non-zero bytes that ends the data is not
    followed by an extra 0x01 code byte.
    """
    return wire.cobs_encode(bytes(data))


def cobs_decode(data: bytes) -> bytes:
    """
    Undo ``cobs_encode`` (input without the 0x00 delimiter).

    Raises ``ProtocolError`` if the input is empty, holds a 0x00, or a code byte
    points past the end. A redundant empty final block is accepted.
    """
    try:
        return wire.cobs_decode(bytes(data))
    except ValueError as exc:
        raise ProtocolError(str(exc)) from None


# ----------------------------------------------------------------- field helpers


def _as_int(value: object, name: str) -> int:
    try:
        return operator.index(value)  # type: ignore[arg-type]
    except TypeError as exc:
        raise ProtocolError(f'{name} must be an integer, got {value!r}') from exc


def _as_float(value: object, name: str) -> float:
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError) as exc:
        raise ProtocolError(f'{name} must be a number, got {value!r}') from exc


def _in_range(value: object, low: int, high: int, name: str) -> int:
    number = _as_int(value, name)
    if not low <= number <= high:
        raise ProtocolError(f'{name} must be in [{low}, {high}], got {number}')
    return number


def _sequence(values: object, count: int, name: str) -> Tuple[object, ...]:
    try:
        items = tuple(values)  # type: ignore[call-overload]
    except TypeError as exc:
        raise ProtocolError(f'{name} must be a sequence of {count} values') from exc
    if len(items) != count:
        raise ProtocolError(f'{name} must have {count} values, got {len(items)}')
    return items


def _wrap_time(value: object, name: str = 'board_time_us') -> int:
    return _as_int(value, name) % _TIME_MODULUS


def _wrap_int32(value: int) -> int:
    return ((value + (1 << 31)) % (1 << 32)) - (1 << 31)


def _effort_to_raw(value: object, index: int) -> int:
    effort = _as_float(value, f'efforts[{index}]')
    if not math.isfinite(effort):
        raise ProtocolError(f'efforts[{index}] must be finite, got {effort!r}')
    return int(round(min(1.0, max(-1.0, effort)) * EFFORT_SCALE))


def _float32(value: object, name: str) -> float:
    number = _as_float(value, name)
    if math.isfinite(number) and abs(number) > _FLOAT32_MAX:
        raise ProtocolError(f'{name} = {number!r} does not fit a float32')
    return number


# ------------------------------------------------------------ payload codecs


def _pack_motor_efforts(message: MotorEfforts) -> Tuple[object, ...]:
    efforts = _sequence(message.efforts, 4, 'efforts')
    raw = tuple(_effort_to_raw(value, index) for index, value in enumerate(efforts))
    timeout = _in_range(message.command_timeout_ms, 1, _U16_MAX, 'command_timeout_ms')
    return raw + (timeout,)


def _unpack_motor_efforts(fields: Tuple) -> MotorEfforts:
    raw, timeout = fields[:4], fields[4]   # esp32_wire.fields_valid checked the range
    efforts = tuple(value / EFFORT_SCALE for value in raw)
    return MotorEfforts(efforts, timeout)  # type: ignore[arg-type]


def _pack_clear_faults(message: ClearFaults) -> Tuple[object, ...]:
    return (_in_range(message.faults, 0, _U16_MAX, 'faults'),)


def _unpack_clear_faults(fields: Tuple) -> ClearFaults:
    return ClearFaults(FaultFlags(fields[0]))


def _pack_encoder_ticks(message: EncoderTicks) -> Tuple[object, ...]:
    ticks = _sequence(message.ticks, 4, 'ticks')
    wrapped = tuple(_wrap_int32(_as_int(value, f'ticks[{index}]'))
                    for index, value in enumerate(ticks))
    return (_wrap_time(message.board_time_us),) + wrapped


def _unpack_encoder_ticks(fields: Tuple) -> EncoderTicks:
    return EncoderTicks(fields[0], tuple(fields[1:5]))  # type: ignore[arg-type]


def _pack_imu_sample(message: ImuSample) -> Tuple[object, ...]:
    accel = _sequence(message.accel_m_s2, 3, 'accel_m_s2')
    gyro = _sequence(message.gyro_rad_s, 3, 'gyro_rad_s')
    values = tuple(_float32(value, f'accel_m_s2[{index}]') for index, value in enumerate(accel))
    values += tuple(_float32(value, f'gyro_rad_s[{index}]') for index, value in enumerate(gyro))
    return (_wrap_time(message.board_time_us),) + values


def _unpack_imu_sample(fields: Tuple) -> ImuSample:
    return ImuSample(fields[0], tuple(fields[1:4]), tuple(fields[4:7]))  # type: ignore[arg-type]


def _pack_board_status(message: BoardStatus) -> Tuple[object, ...]:
    rx_bad = _as_int(message.rx_bad_frames, 'rx_bad_frames')
    if rx_bad < 0:
        raise ProtocolError(f'rx_bad_frames must not be negative, got {rx_bad}')
    return (_wrap_time(message.board_time_us),
            _in_range(message.faults, 0, _U16_MAX, 'faults'),
            _in_range(message.battery_mv, 0, _U16_MAX, 'battery_mv'),
            min(rx_bad, _U16_MAX),
            _as_int(message.last_command_seq, 'last_command_seq') % SEQ_MODULUS)


def _unpack_board_status(fields: Tuple) -> BoardStatus:
    return BoardStatus(fields[0], FaultFlags(fields[1]), fields[2], fields[3], fields[4])


@dataclass(frozen=True)
class _Codec:
    message_type: MessageType
    message_class: Type
    pack: Callable[..., Tuple[object, ...]]
    unpack: Callable[[Tuple], Message]


_CODECS: Tuple[_Codec, ...] = (
    _Codec(MessageType.MOTOR_EFFORTS, MotorEfforts, _pack_motor_efforts, _unpack_motor_efforts),
    _Codec(MessageType.CLEAR_FAULTS, ClearFaults, _pack_clear_faults, _unpack_clear_faults),
    _Codec(MessageType.ENCODER_TICKS, EncoderTicks, _pack_encoder_ticks, _unpack_encoder_ticks),
    _Codec(MessageType.IMU_SAMPLE, ImuSample, _pack_imu_sample, _unpack_imu_sample),
    _Codec(MessageType.BOARD_STATUS, BoardStatus, _pack_board_status, _unpack_board_status),
)
_CODEC_BY_TYPE: Dict[int, _Codec] = {int(codec.message_type): codec for codec in _CODECS}
_CODEC_BY_CLASS: Dict[type, _Codec] = {codec.message_class: codec for codec in _CODECS}

PAYLOAD_BYTES: Dict[MessageType, int] = {
    MessageType(msg_type): size for msg_type, size in wire.PAYLOAD_BYTES.items()}
"""Fixed payload size in bytes of each message type (version 1)."""

LARGEST_FRAME_BYTES = wire.LARGEST_FRAME_BYTES
"""Size of the largest version 1 frame on the wire, delimiter included (36)."""

assert LARGEST_FRAME_BYTES <= MAX_FRAME_BYTES


def message_type_of(message: Message) -> MessageType:
    """Return the message type byte of a message object (ProtocolError if not a message)."""
    codec = _CODEC_BY_CLASS.get(type(message))
    if codec is None:
        raise ProtocolError(f'not a protocol message: {message!r}')
    return codec.message_type


def encode_frame(message: Message, seq: int) -> bytes:
    """
    Encode one message as a complete frame: COBS(body) followed by one 0x00.

    ``seq`` is taken modulo 2^16. Raises ``ProtocolError`` if a field cannot be
    encoded (see the message classes).
    """
    codec = _CODEC_BY_CLASS.get(type(message))
    if codec is None:
        raise ProtocolError(f'not a protocol message: {message!r}')
    return wire.encode_frame(int(codec.message_type), _as_int(seq, 'seq'), codec.pack(message))


# ----------------------------------------------------------------------- decoder


@dataclass
class DecoderStats:
    """
    Counters of a ``FrameDecoder``.

    ``bytes_discarded`` counts the bytes (0x00 delimiters not included) of every
    run that did not yield a frame. ``bad_payload`` counts frames with a good
    CRC whose fields are invalid (MOTOR_EFFORTS with a duty beyond +-10000 or a
    zero timeout). ``last_wrong_version`` is the version byte of the most
    recent frame of another protocol version.
    """

    frames_ok: int = 0
    bad_cobs: int = 0
    bad_crc: int = 0
    bad_length: int = 0
    wrong_version: int = 0
    unknown_type: int = 0
    bad_payload: int = 0
    oversized: int = 0
    bytes_discarded: int = 0
    last_wrong_version: Optional[int] = None

    @property
    def errors(self) -> int:
        """Total number of dropped runs, whatever the reason."""
        return wire.dropped_frames(self)


class FrameDecoder(wire.FrameDecoder):
    """
    Incremental receiver: bytes in, decoded frames out (esp32_wire's decoder, typed).

    Accepts any chunking. Bad frames are counted in ``stats`` and dropped;
    ``feed`` never raises on any bytes. Memory is bounded by ``max_frame_bytes``.
    Checks, in order: run length, COBS, body length, CRC, version, type,
    payload length, payload values.
    """

    def __init__(self, max_frame_bytes: int = MAX_FRAME_BYTES) -> None:
        super().__init__(max_frame_bytes, DecoderStats())
        self.stats: DecoderStats

    def feed(self, data: bytes) -> List[Frame]:  # type: ignore[override]
        """Consume received bytes; return the frames completed by them, in order."""
        return [Frame(seq, _CODEC_BY_TYPE[msg_type].unpack(fields))
                for msg_type, seq, fields in super().feed(bytes(data))]


# ------------------------------------------------------------- sequence numbers


def seq_delta(previous: int, current: int) -> int:
    """Signed distance from ``previous`` to ``current`` modulo 2^16, in [-32768, 32767]."""
    return wire.seq_delta(previous, current)


class SequenceTracker:
    """
    Receive-side sequence bookkeeping for one direction of the link.

    ``update`` classifies each received sequence number: ``'first'``,
    ``'next'``, ``'gap'`` (frames lost, added to ``lost``), ``'duplicate'``
    and ``'stale'`` (the caller should drop the frame), or ``'reset'`` for a
    jump more than ``reset_threshold`` back, taken as a restarted peer: the
    tracker re-baselines on it. A restart that jumps back less than that reads
    as ``'stale'`` until the peer passes its old count, so a receiver that sees
    the peer restart by other means (board clock going back, BROWNOUT_RESET,
    port reopened) should call ``reset``.
    """

    def __init__(self, reset_threshold: int = 1000) -> None:
        self.reset_threshold = reset_threshold
        self.last_seq: Optional[int] = None
        self.lost = 0
        self.duplicates = 0
        self.stale = 0
        self.resets = 0

    def reset(self) -> None:
        """Forget the last sequence number (counters kept): the next update is 'first'."""
        self.last_seq = None

    def update(self, seq: int) -> str:
        """Classify ``seq`` and update the counters; see the class docstring."""
        seq %= SEQ_MODULUS
        if self.last_seq is None:
            self.last_seq = seq
            return 'first'
        delta = seq_delta(self.last_seq, seq)
        if delta == 0:
            self.duplicates += 1
            return 'duplicate'
        if delta < -self.reset_threshold:
            self.resets += 1
            self.last_seq = seq
            return 'reset'
        if delta < 0:
            self.stale += 1
            return 'stale'
        self.last_seq = seq
        if delta == 1:
            return 'next'
        self.lost += delta - 1
        return 'gap'
