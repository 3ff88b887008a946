"""
The ESP32 board's serial protocol, version 1, for both ends: the host and the firmware.

One file, run unchanged by CPython (the host: ``esp32_protocol`` builds its typed
API on it) and by MicroPython on the board (``firmware/``: copied there as
``mecanum_control/esp32_wire.py``). So it keeps to what both run: ``struct``,
bytes and bytearray, plain classes and int constants; no dataclasses, enum, typing
or f-strings. The specification is ``doc/esp32_protocol.md``.

What is here: the message type and fault bit numbers, the payload layouts, the
CRC-16/CCITT-FALSE, COBS, ``encode_frame`` for every message (raw integer fields,
the modular ones wrapped) and the incremental ``FrameDecoder`` (resynchronises at
every 0x00, bounded by ``MAX_FRAME_BYTES``, counts every dropped frame by reason).

Units and order: wheel order FL, FR, RL, RR; efforts are int16 duty x 10000;
``board_time_us`` is the board's microsecond clock (u32, wraps); ticks are
free-running int32 counters; IMU values are float32 m/s^2 and rad/s.
"""

import struct

PROTOCOL_VERSION = 1
#: Full-scale effort: +10000 is full PWM forward, -10000 full PWM backward.
EFFORT_SCALE = 10000
#: Bound on an encoded frame, COBS overhead and 0x00 delimiter included (every version).
MAX_FRAME_BYTES = 64
FRAME_DELIMITER = b'\x00'
HEADER_BYTES = 4
CRC_BYTES = 2
SEQ_MODULUS = 0x10000
U16_MAX = 0xFFFF

# Message types: 0x01-0x7F host -> board, 0x81-0xFF board -> host.
MOTOR_EFFORTS = 0x01
CLEAR_FAULTS = 0x02
ENCODER_TICKS = 0x81
IMU_SAMPLE = 0x82
BOARD_STATUS = 0x83

#: Payload layout of each message type (little-endian struct formats).
#: MOTOR_EFFORTS: effort FL, FR, RL, RR (i16, x10000), command_timeout_ms (u16).
#: CLEAR_FAULTS: fault bits to clear (u16).
#: ENCODER_TICKS: board_time_us (u32), ticks FL, FR, RL, RR (i32).
#: IMU_SAMPLE: board_time_us (u32), accel x, y, z (f32, m/s^2), gyro x, y, z (f32, rad/s).
#: BOARD_STATUS: board_time_us (u32), faults, battery_mv, rx_bad_frames, last_command_seq (u16).
PAYLOAD_FORMATS = {
    MOTOR_EFFORTS: '<4hH',
    CLEAR_FAULTS: '<H',
    ENCODER_TICKS: '<I4i',
    IMU_SAMPLE: '<I6f',
    BOARD_STATUS: '<IHHHH',
}
PAYLOAD_BYTES = {}
for _type in PAYLOAD_FORMATS:
    PAYLOAD_BYTES[_type] = struct.calcsize(PAYLOAD_FORMATS[_type])
del _type
_HEADER_FORMAT = '<BBH'
_CRC_FORMAT = '<H'

# Fault bits of BOARD_STATUS (doc/esp32_protocol.md, 5).
COMMAND_TIMEOUT = 0x0001
ESTOP_INPUT = 0x0002
ENCODER_FAULT = 0x0004
IMU_FAULT = 0x0008
LOW_BATTERY = 0x0010
MOTOR_DRIVER_FAULT = 0x0020
RX_ERRORS = 0x0040
BROWNOUT_RESET = 0x0080
#: (bit, name) of every defined fault bit, lowest first.
FAULT_NAMES = (
    (COMMAND_TIMEOUT, 'COMMAND_TIMEOUT'), (ESTOP_INPUT, 'ESTOP_INPUT'),
    (ENCODER_FAULT, 'ENCODER_FAULT'), (IMU_FAULT, 'IMU_FAULT'),
    (LOW_BATTERY, 'LOW_BATTERY'), (MOTOR_DRIVER_FAULT, 'MOTOR_DRIVER_FAULT'),
    (RX_ERRORS, 'RX_ERRORS'), (BROWNOUT_RESET, 'BROWNOUT_RESET'))
#: Bits that stay set until CLEAR_FAULTS (and their cause has gone).
LATCHED_FAULTS = (ESTOP_INPUT | ENCODER_FAULT | IMU_FAULT | MOTOR_DRIVER_FAULT
                  | BROWNOUT_RESET)


def largest_frame_bytes():
    """Return the size of the largest version 1 frame on the wire, 0x00 included (36)."""
    body = HEADER_BYTES + max(PAYLOAD_BYTES.values()) + CRC_BYTES
    return body + 1 + body // 254 + 1


LARGEST_FRAME_BYTES = largest_frame_bytes()


# --------------------------------------------------------------------------- CRC


def _make_crc_table():
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
        table.append(crc)
    return tuple(table)


_CRC_TABLE = _make_crc_table()


def crc16_ccitt(data):
    """
    Return the CRC-16/CCITT-FALSE of data (bytes-like).

    Polynomial 0x1021, initial value 0xFFFF, no reflection, no final XOR; the
    check value of b'123456789' is 0x29B1.
    """
    crc = 0xFFFF
    table = _CRC_TABLE
    for byte in data:
        crc = ((crc << 8) & 0xFFFF) ^ table[(crc >> 8) ^ byte]
    return crc


# -------------------------------------------------------------------------- COBS


def cobs_encode(data):
    """
    Return the Consistent Overhead Byte Stuffing of data, without the trailing 0x00.

    The result holds no 0x00. A block of 254 non-zero bytes that ends the data is
    not followed by an extra 0x01 code byte. (Works piece by piece between the zeros,
    not byte by byte: it is the hot spot of the board's loop.)
    """
    pieces = bytes(data).split(FRAME_DELIMITER)
    last = len(pieces) - 1
    out = bytearray()
    for index in range(last + 1):
        piece = pieces[index]
        full = False
        while len(piece) >= 254:
            out.append(0xFF)
            out += piece[:254]
            piece = piece[254:]
            full = True
        if index < last or piece or not full:
            out.append(len(piece) + 1)
            out += piece
    return bytes(out)


def cobs_decode(data):
    """
    Undo cobs_encode (input without the 0x00 delimiter); ValueError if malformed.

    Malformed: empty, a 0x00 anywhere, or a code byte whose block runs past the end.
    A redundant empty final block is accepted.
    """
    length = len(data)
    if not length:
        raise ValueError('COBS: empty input')
    if data.find(FRAME_DELIMITER) >= 0:
        raise ValueError('COBS: zero byte in the input')
    out = bytearray()
    index = 0
    while index < length:
        code = data[index]
        end = index + code
        if end > length:
            raise ValueError('COBS: block at offset %d runs past the end' % index)
        out += data[index + 1:end]
        index = end
        if code < 0xFF and index < length:
            out.append(0)
    return bytes(out)


# ------------------------------------------------------------------------ frames


def wrap_int32(value):
    """Wrap an integer into the signed 32-bit range, as a hardware counter does."""
    return ((value + 0x80000000) & 0xFFFFFFFF) - 0x80000000


def encode_frame(msg_type, seq, fields):
    """
    Encode one frame: COBS(header, payload, CRC) and the 0x00 delimiter.

    fields are the payload's raw values in layout order (PAYLOAD_FORMATS). The
    modular ones are wrapped here: seq mod 2^16, board_time_us mod 2^32, ticks into
    int32, last_command_seq mod 2^16. Every other field must already fit its type
    (MicroPython's struct does not check); the host's esp32_protocol checks them.
    KeyError for an unknown msg_type.
    """
    layout = PAYLOAD_FORMATS[msg_type]
    if msg_type == ENCODER_TICKS:
        fields = (fields[0] & 0xFFFFFFFF, wrap_int32(fields[1]), wrap_int32(fields[2]),
                  wrap_int32(fields[3]), wrap_int32(fields[4]))
    elif msg_type == IMU_SAMPLE:
        fields = (fields[0] & 0xFFFFFFFF,) + tuple(fields[1:])
    elif msg_type == BOARD_STATUS:
        fields = (fields[0] & 0xFFFFFFFF, fields[1], fields[2], fields[3],
                  fields[4] & 0xFFFF)
    body = (struct.pack(_HEADER_FORMAT, PROTOCOL_VERSION, msg_type, seq & 0xFFFF)
            + struct.pack(layout, *fields))
    body += struct.pack(_CRC_FORMAT, crc16_ccitt(body))
    return cobs_encode(body) + FRAME_DELIMITER


def fields_valid(msg_type, fields):
    """
    Tell whether decoded fields hold valid values (doc/esp32_protocol.md, 4.1).

    Only MOTOR_EFFORTS has invalid values: an effort outside -10000 .. +10000 or a
    command_timeout_ms of 0.
    """
    if msg_type == MOTOR_EFFORTS:
        for raw in fields[:4]:
            if raw > EFFORT_SCALE or raw < -EFFORT_SCALE:
                return False
        return fields[4] != 0
    return True


class DecoderStats:
    """
    Counters of a FrameDecoder, one per reason a run was dropped.

    bytes_discarded counts the bytes (0x00 not included) of every run that gave no
    frame; last_wrong_version is the version byte of the latest frame of another
    protocol version (None before one).
    """

    def __init__(self):
        self.frames_ok = 0
        self.bad_cobs = 0
        self.bad_crc = 0
        self.bad_length = 0
        self.wrong_version = 0
        self.unknown_type = 0
        self.bad_payload = 0
        self.oversized = 0
        self.bytes_discarded = 0
        self.last_wrong_version = None


def dropped_frames(stats):
    """Return the number of dropped runs in stats, whatever the reason."""
    return (stats.bad_cobs + stats.bad_crc + stats.bad_length + stats.wrong_version
            + stats.unknown_type + stats.bad_payload + stats.oversized)


class FrameDecoder:
    """
    Incremental receiver: bytes in, (msg_type, seq, fields) tuples out.

    Accepts any chunking; feed never raises on any bytes. Checks, in order: run
    length, COBS, body length, CRC, version, type, payload length, payload values;
    a run failing one is counted in stats (a DecoderStats, or any object with its
    attributes) and dropped. Memory is bounded by max_frame_bytes: a run of more
    than max_frame_bytes - 1 bytes without a 0x00 is discarded up to the next 0x00.
    """

    def __init__(self, max_frame_bytes=MAX_FRAME_BYTES, stats=None):
        if max_frame_bytes < LARGEST_FRAME_BYTES:
            raise ValueError('max_frame_bytes must be at least %d, got %d'
                             % (LARGEST_FRAME_BYTES, max_frame_bytes))
        self.max_frame_bytes = max_frame_bytes
        self.stats = DecoderStats() if stats is None else stats
        self._buffer = bytearray()
        self._discarding = False

    def reset(self):
        """Forget a partially received frame (e.g. after reopening the port)."""
        self.stats.bytes_discarded += len(self._buffer)
        self._buffer = bytearray()
        self._discarding = False

    def feed(self, data):
        """Consume received bytes; return the frames they complete, in order."""
        frames = []
        start = 0
        length = len(data)
        while start < length:
            end = data.find(FRAME_DELIMITER, start)
            if end < 0:
                self._collect(data[start:])
                break
            self._collect(data[start:end])
            if self._discarding:
                self._discarding = False
            elif self._buffer:
                run = bytes(self._buffer)
                self._buffer = bytearray()
                frame = self.decode_run(run)
                if frame is None:
                    self.stats.bytes_discarded += len(run)
                else:
                    self.stats.frames_ok += 1
                    frames.append(frame)
            start = end + 1
        return frames

    def _collect(self, run):
        if not run:
            return
        if self._discarding:
            self.stats.bytes_discarded += len(run)
            return
        self._buffer += run
        if len(self._buffer) > self.max_frame_bytes - 1:
            self.stats.oversized += 1
            self.stats.bytes_discarded += len(self._buffer)
            self._buffer = bytearray()
            self._discarding = True

    def decode_run(self, run):
        """Decode one run (bytes between delimiters): (msg_type, seq, fields) or None."""
        stats = self.stats
        try:
            body = cobs_decode(run)
        except ValueError:
            stats.bad_cobs += 1
            return None
        size = len(body)
        if size < HEADER_BYTES + CRC_BYTES:
            stats.bad_length += 1
            return None
        if struct.unpack_from(_CRC_FORMAT, body, size - CRC_BYTES)[0] != crc16_ccitt(
                body[:size - CRC_BYTES]):
            stats.bad_crc += 1
            return None
        version, msg_type, seq = struct.unpack_from(_HEADER_FORMAT, body, 0)
        if version != PROTOCOL_VERSION:
            stats.wrong_version += 1
            stats.last_wrong_version = version
            return None
        layout = PAYLOAD_FORMATS.get(msg_type)
        if layout is None:
            stats.unknown_type += 1
            return None
        if size - HEADER_BYTES - CRC_BYTES != PAYLOAD_BYTES[msg_type]:
            stats.bad_length += 1
            return None
        fields = struct.unpack_from(layout, body, HEADER_BYTES)
        if not fields_valid(msg_type, fields):
            stats.bad_payload += 1
            return None
        return (msg_type, seq, fields)


def seq_delta(previous, current):
    """Return the signed distance from previous to current modulo 2^16, in [-32768, 32767]."""
    return ((current - previous + 0x8000) & 0xFFFF) - 0x8000
