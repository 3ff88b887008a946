"""Hand-worked, property and fuzz tests of mecanum_control.esp32_protocol (no ROS)."""

import binascii
import math
import struct
from typing import List

from hypothesis import given, settings, strategies as st
from mecanum_control.esp32_protocol import (
    BoardStatus, ClearFaults, cobs_decode, cobs_encode, crc16_ccitt, DecoderStats,
    describe_faults, EFFORT_SCALE, encode_frame, EncoderTicks, FaultFlags, Frame, FrameDecoder,
    ImuSample, LARGEST_FRAME_BYTES, MAX_FRAME_BYTES, message_type_of, MessageType,
    MotorEfforts, PAYLOAD_BYTES, PROTOCOL_VERSION, ProtocolError, seq_delta, SequenceTracker)
import pytest

FAST = settings(max_examples=60, deadline=None)


def reference_crc(data: bytes) -> int:
    """CRC-16/CCITT-FALSE from the standard library (independent of the module)."""
    return binascii.crc_hqx(data, 0xFFFF)


def raw_frame(version: int, type_byte: int, seq: int, payload: bytes) -> bytes:
    """Build an encoded frame by hand: header + payload + CRC, COBS, delimiter."""
    body = struct.pack('<BBH', version, type_byte, seq) + payload
    body += struct.pack('<H', reference_crc(body))
    return cobs_encode(body) + b'\x00'


# ---------------------------------------------------------------------- strategies

u16 = st.integers(0, 0xFFFF)
u32 = st.integers(0, 0xFFFFFFFF)
int32 = st.integers(-(1 << 31), (1 << 31) - 1)
float32 = st.floats(width=32, allow_nan=False)
fault_flags = u16.map(FaultFlags)

motor_efforts = st.builds(
    MotorEfforts,
    st.tuples(*[st.integers(-EFFORT_SCALE, EFFORT_SCALE).map(lambda r: r / EFFORT_SCALE)] * 4),
    st.integers(1, 0xFFFF))
clear_faults = st.builds(ClearFaults, fault_flags)
encoder_ticks = st.builds(EncoderTicks, u32, st.tuples(int32, int32, int32, int32))
imu_samples = st.builds(ImuSample, u32, st.tuples(float32, float32, float32),
                        st.tuples(float32, float32, float32))
board_status = st.builds(BoardStatus, u32, fault_flags, u16, u16, u16)
messages = st.one_of(motor_efforts, clear_faults, encoder_ticks, imu_samples, board_status)
frames = st.builds(Frame, u16, messages)

# One representative frame of every message type, for the exhaustive tests.
SAMPLE_FRAMES = [
    Frame(7, MotorEfforts((0.5, -0.25, 1.0, 0.0), 200)),
    Frame(1, ClearFaults(FaultFlags.COMMAND_TIMEOUT)),
    Frame(300, EncoderTicks(123456789, (1000, -1000, 2 ** 31 - 1, -(2 ** 31)))),
    Frame(65535, ImuSample(42, (0.125, -9.8125, 0.5), (0.0, 0.25, -3.0))),
    Frame(0, BoardStatus(1, FaultFlags.LOW_BATTERY | FaultFlags.RX_ERRORS, 11800, 3, 65535)),
]
NEXT_FRAME = Frame(8, EncoderTicks(5, (1, 2, 3, 4)))


def encode(frame: Frame) -> bytes:
    """Encode a Frame object."""
    return encode_frame(frame.message, frame.seq)


def decode_all(data: bytes) -> List[Frame]:
    """Feed everything to a fresh decoder at once."""
    return FrameDecoder().feed(data)


# ----------------------------------------------------------------------------- CRC


def test_crc_check_value():
    """CRC-16/CCITT-FALSE catalogue check value."""
    assert crc16_ccitt(b'123456789') == 0x29B1
    assert crc16_ccitt(b'') == 0xFFFF


@FAST
@given(st.binary(max_size=100))
def test_crc_matches_stdlib(data):
    """The table-driven CRC equals binascii.crc_hqx with init 0xFFFF."""
    assert crc16_ccitt(data) == reference_crc(data)


# ---------------------------------------------------------------------------- COBS

COBS_VECTORS = [
    (b'', b'\x01'),
    (b'\x00', b'\x01\x01'),
    (b'\x00\x00', b'\x01\x01\x01'),
    (b'\x00\x11\x00', b'\x01\x02\x11\x01'),
    (b'\x11\x22\x00\x33', b'\x03\x11\x22\x02\x33'),
    (b'\x11\x22\x33\x44', b'\x05\x11\x22\x33\x44'),
    (b'\x11\x00\x00\x00', b'\x02\x11\x01\x01\x01'),
    (bytes(range(1, 255)), b'\xff' + bytes(range(1, 255))),                  # 254 non-zero
    (bytes(range(0, 255)), b'\x01\xff' + bytes(range(1, 255))),
    (bytes(range(1, 256)), b'\xff' + bytes(range(1, 255)) + b'\x02\xff'),   # 255 non-zero
    (bytes(range(2, 256)) + b'\x00', b'\xff' + bytes(range(2, 256)) + b'\x01\x01'),
    (bytes(range(3, 256)) + b'\x00\x01', b'\xfe' + bytes(range(3, 256)) + b'\x02\x01'),
]


@pytest.mark.parametrize('plain, encoded', COBS_VECTORS)
def test_cobs_vectors(plain, encoded):
    """Worked examples of the COBS paper / Wikipedia, both directions."""
    assert cobs_encode(plain) == encoded
    assert cobs_decode(encoded) == plain


def test_cobs_decode_accepts_redundant_final_block():
    """A full 0xFF block followed by an empty 0x01 block decodes the same."""
    assert cobs_decode(b'\xff' + bytes(range(1, 255)) + b'\x01') == bytes(range(1, 255))


@FAST
@given(st.binary(max_size=1000))
def test_cobs_round_trip(data):
    """COBS output has no zero byte, bounded overhead, and decodes back."""
    encoded = cobs_encode(data)
    assert 0 not in encoded
    assert len(encoded) <= len(data) + max(1, math.ceil(len(data) / 254))
    assert cobs_decode(encoded) == data


@pytest.mark.parametrize('bad', [b'', b'\x00', b'\x05\x11\x22', b'\x02', b'\x03\x11\x00',
                                 b'\x02\x11\x00\x01'])
def test_cobs_decode_rejects_malformed(bad):
    """Empty input, zero bytes and blocks running past the end are errors."""
    with pytest.raises(ProtocolError):
        cobs_decode(bad)


@FAST
@given(st.binary(max_size=300))
def test_cobs_decode_random_raises_only_protocol_error(data):
    """cobs_decode on anything either succeeds or raises ProtocolError."""
    try:
        cobs_decode(data)
    except ProtocolError:
        pass


# --------------------------------------------------------------- pinned wire format


def test_hand_worked_clear_faults_frame():
    """CLEAR_FAULTS(COMMAND_TIMEOUT), seq 1, built independently and byte by byte."""
    body = struct.pack('<BBHH', 1, 0x02, 1, 0x0001)
    assert body == bytes([0x01, 0x02, 0x01, 0x00, 0x01, 0x00])
    assert reference_crc(body) == 0x4AB6
    # Body + CRC: 01 02 01 00 01 00 B6 4A. COBS blocks: [01 02 01] 00 [01] 00 [B6 4A].
    expected = bytes([0x04, 0x01, 0x02, 0x01, 0x02, 0x01, 0x03, 0xB6, 0x4A, 0x00])
    assert encode_frame(ClearFaults(FaultFlags.COMMAND_TIMEOUT), 1) == expected
    assert decode_all(expected) == [Frame(1, ClearFaults(FaultFlags.COMMAND_TIMEOUT))]


def test_hand_worked_motor_efforts_frame():
    """The MOTOR_EFFORTS example of doc/esp32_protocol.md, byte by byte."""
    body = struct.pack('<BBH4hH', 1, 0x01, 7, 5000, -2500, 10000, 0, 200)
    assert body.hex(' ') == '01 01 07 00 88 13 3c f6 10 27 00 00 c8 00'
    assert reference_crc(body) == 0x7C29
    expected = bytes.fromhex('04 01 01 07 07 88 13 3c f6 10 27 01 02 c8 03 29 7c 00')
    assert encode_frame(MotorEfforts((0.5, -0.25, 1.0, 0.0), 200), 7) == expected
    assert decode_all(expected) == [SAMPLE_FRAMES[0]]


@pytest.mark.parametrize('frame', SAMPLE_FRAMES)
def test_layout_matches_struct_formats(frame):
    """Each frame is header + little-endian payload of the documented size + CRC."""
    encoded = encode(frame)
    body = cobs_decode(encoded[:-1])
    message_type = message_type_of(frame.message)
    assert len(body) == 4 + PAYLOAD_BYTES[message_type] + 2
    assert struct.unpack_from('<BBH', body) == (PROTOCOL_VERSION, message_type, frame.seq)
    assert struct.unpack_from('<H', body, len(body) - 2)[0] == reference_crc(body[:-2])
    assert len(encoded) <= LARGEST_FRAME_BYTES <= MAX_FRAME_BYTES


def test_payload_sizes():
    """Payload sizes of the documented byte layout tables."""
    assert PAYLOAD_BYTES == {MessageType.MOTOR_EFFORTS: 10, MessageType.CLEAR_FAULTS: 2,
                             MessageType.ENCODER_TICKS: 20, MessageType.IMU_SAMPLE: 28,
                             MessageType.BOARD_STATUS: 12}
    assert LARGEST_FRAME_BYTES == 36


# ------------------------------------------------------------------ round trips


@FAST
@given(frames)
def test_every_message_round_trips(frame):
    """encode_frame then FrameDecoder gives the same frame back, for every type."""
    assert decode_all(encode(frame)) == [frame]


@FAST
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=4, max_size=4),
       st.integers(1, 0xFFFF), u16)
def test_effort_quantisation_and_clamping(efforts, timeout, seq):
    """Efforts are clamped to [-1, 1] and rounded to the 1e-4 grid; decoded as floats."""
    (frame,) = decode_all(encode_frame(MotorEfforts(tuple(efforts), timeout), seq))
    expected = tuple(round(min(1.0, max(-1.0, e)) * EFFORT_SCALE) / EFFORT_SCALE
                     for e in efforts)
    assert frame.message == MotorEfforts(expected, timeout)
    assert all(isinstance(e, float) for e in frame.message.efforts)
    assert all(abs(d - min(1.0, max(-1.0, e))) <= 0.5 / EFFORT_SCALE + 1e-12
               for d, e in zip(frame.message.efforts, efforts))


def test_effort_examples():
    """Hand-picked quantisation and clamping cases."""
    (frame,) = decode_all(encode_frame(MotorEfforts((1.5, -7.0, 0.12344, -0.00006), 50), 0))
    assert frame.message.efforts == (1.0, -1.0, 0.1234, -0.0001)


@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf])
def test_effort_rejects_non_finite(bad):
    """Refuse NaN and infinities rather than send them to the motors."""
    with pytest.raises(ProtocolError):
        encode_frame(MotorEfforts((0.0, bad, 0.0, 0.0), 100), 0)


@pytest.mark.parametrize('message', [
    MotorEfforts((0.0, 0.0, 0.0, 0.0), 0),
    MotorEfforts((0.0, 0.0, 0.0, 0.0), 65536),
    MotorEfforts((0.0, 0.0, 0.0, 0.0), -5),
    MotorEfforts((0.0, 0.0, 0.0), 100),
    MotorEfforts(('fast', 0.0, 0.0, 0.0), 100),
    ClearFaults(0x10000),
    ClearFaults(-1),
    EncoderTicks(0, (1, 2, 3, 4.5)),
    EncoderTicks(0, (1, 2, 3)),
    ImuSample(0, (1e39, 0.0, 0.0), (0.0, 0.0, 0.0)),
    ImuSample(0, (0.0, 0.0, 0.0), (0.0, 0.0)),
    BoardStatus(0, FaultFlags(0), 70000, 0, 0),
    BoardStatus(0, FaultFlags(0), 12000, -1, 0),
])
def test_invalid_fields_rejected(message):
    """Fields that cannot be represented raise ProtocolError (a ValueError)."""
    with pytest.raises(ProtocolError):
        encode_frame(message, 0)
    assert issubclass(ProtocolError, ValueError)


def test_not_a_message_rejected():
    """encode_frame refuses objects that are not protocol messages."""
    with pytest.raises(ProtocolError):
        encode_frame(Frame(0, ClearFaults(FaultFlags(0))), 0)  # type: ignore[arg-type]


def test_ticks_and_times_wrap():
    """Ticks wrap into int32 (two's complement); board time and seq wrap."""
    message = EncoderTicks(2 ** 32 + 5, (2 ** 31, -(2 ** 31) - 1, 2 ** 40 + 3, -1))
    (frame,) = decode_all(encode_frame(message, 65536 + 9))
    assert frame == Frame(9, EncoderTicks(5, (-(2 ** 31), 2 ** 31 - 1, 3, -1)))


@FAST
@given(st.integers(-(2 ** 70), 2 ** 70), st.integers(-(2 ** 40), 2 ** 40))
def test_ticks_wrap_modulo_2_32(ticks, board_time):
    """Any Python int is sent as its value modulo 2^32, read back as int32."""
    (frame,) = decode_all(encode_frame(EncoderTicks(board_time, (ticks, 0, 0, 0)), 0))
    decoded = frame.message.ticks[0]
    assert -(2 ** 31) <= decoded < 2 ** 31
    assert (decoded - ticks) % 2 ** 32 == 0
    assert frame.message.board_time_us == board_time % 2 ** 32


def test_board_status_counters():
    """rx_bad_frames saturates at 65535; last_command_seq wraps like a seq."""
    (frame,) = decode_all(encode_frame(BoardStatus(0, FaultFlags(0), 12000, 100000, 65537), 0))
    assert frame.message.rx_bad_frames == 65535
    assert frame.message.last_command_seq == 1


def test_imu_passes_non_finite_through():
    """The decoder does not judge IMU values; NaN/inf arrive as sent."""
    (frame,) = decode_all(encode_frame(ImuSample(0, (math.nan, math.inf, 0.0),
                                                 (0.0, 0.0, -math.inf)), 0))
    assert math.isnan(frame.message.accel_m_s2[0])
    assert frame.message.accel_m_s2[1:] == (math.inf, 0.0)
    assert frame.message.gyro_rad_s[2] == -math.inf


def test_decoded_fault_fields_are_flags():
    """Fault fields decode as FaultFlags, unknown bits kept."""
    (frame,) = decode_all(encode_frame(BoardStatus(0, FaultFlags(0x0101), 0, 0, 0), 0))
    assert isinstance(frame.message.faults, FaultFlags)
    assert frame.message.faults & FaultFlags.COMMAND_TIMEOUT
    assert int(frame.message.faults) == 0x0101


# -------------------------------------------------------------------- fault names


def test_describe_faults():
    """Human-readable fault lists, in bit order."""
    assert describe_faults(FaultFlags(0)) == 'none'
    assert describe_faults(0) == 'none'
    assert describe_faults(FaultFlags.LOW_BATTERY | FaultFlags.COMMAND_TIMEOUT) == \
        'COMMAND_TIMEOUT, LOW_BATTERY'
    assert describe_faults(0x0180) == 'BROWNOUT_RESET, UNKNOWN(0x0100)'


def test_fault_bit_values():
    """Fault bit values are part of the wire format."""
    assert [(f.name, int(f)) for f in FaultFlags if int(f)] == [
        ('COMMAND_TIMEOUT', 0x01), ('ESTOP_INPUT', 0x02), ('ENCODER_FAULT', 0x04),
        ('IMU_FAULT', 0x08), ('LOW_BATTERY', 0x10), ('MOTOR_DRIVER_FAULT', 0x20),
        ('RX_ERRORS', 0x40), ('BROWNOUT_RESET', 0x80)]


# ----------------------------------------------------------------- decoder, fuzz


@settings(max_examples=150, deadline=None)
@given(st.lists(st.binary(max_size=120), max_size=6))
def test_random_bytes_never_raise(chunks):
    """Any bytes in any chunking: no exception, stats stay consistent."""
    decoder = FrameDecoder()
    got = []
    for chunk in chunks:
        got += decoder.feed(chunk)
    assert decoder.stats.frames_ok == len(got)
    assert decoder.stats.bytes_discarded <= sum(len(c) for c in chunks)


@FAST
@given(st.lists(st.tuples(st.binary(max_size=150), frames), min_size=1, max_size=5))
def test_garbage_then_delimiter_then_frame_recovers(items):
    """Garbage followed by a 0x00 (the sender's leading delimiter) never costs the frame."""
    stream = b''.join(garbage + b'\x00' + encode(frame) for garbage, frame in items)
    assert decode_all(stream) == [frame for _, frame in items]


def test_garbage_without_delimiter_costs_one_frame():
    """Documented limitation: garbage merges with the next frame's run, which is lost."""
    decoder = FrameDecoder()
    stream = b'\x55\x66' + encode(SAMPLE_FRAMES[0]) + encode(NEXT_FRAME)
    assert decoder.feed(stream) == [NEXT_FRAME]
    assert decoder.stats.errors == 1


@pytest.mark.parametrize('frame', SAMPLE_FRAMES)
def test_truncated_frames_dropped_exhaustive(frame):
    """A frame cut anywhere (sender restarts with a leading 0x00) never decodes."""
    encoded = encode(frame)
    next_encoded = encode(NEXT_FRAME)
    for cut in range(1, len(encoded) - 1):
        decoder = FrameDecoder()
        assert decoder.feed(encoded[:cut] + b'\x00' + next_encoded) == [NEXT_FRAME], cut
        assert decoder.stats.errors == 1


@pytest.mark.parametrize('frame', SAMPLE_FRAMES)
def test_bytes_lost_inside_frame_exhaustive(frame):
    """Any run of bytes lost from a frame whose delimiter survives: only that frame is lost."""
    encoded = encode(frame)
    next_encoded = encode(NEXT_FRAME)
    last = len(encoded) - 1  # index of the delimiter, kept
    for start in range(last):
        for end in range(start + 1, last + 1):
            damaged = encoded[:start] + encoded[end:]
            assert decode_all(damaged + next_encoded) == [NEXT_FRAME], (start, end)


@pytest.mark.parametrize('frame', SAMPLE_FRAMES)
def test_single_bit_flips_detected_exhaustive(frame):
    """Every single-bit error in a frame is detected and only that frame is lost."""
    encoded = encode(frame)
    next_encoded = encode(NEXT_FRAME)
    third = Frame(9, ClearFaults(FaultFlags.ENCODER_FAULT))
    for index in range(len(encoded)):
        for bit in range(8):
            damaged = bytearray(encoded)
            damaged[index] ^= 1 << bit
            decoder = FrameDecoder()
            got = decoder.feed(bytes(damaged) + next_encoded + encode(third))
            if index == len(encoded) - 1:
                # The delimiter itself: the frame merges with the next one, both lost.
                assert got == [third], (index, bit)
            else:
                assert got == [NEXT_FRAME, third], (index, bit)
            assert decoder.stats.errors >= 1


@FAST
@given(st.lists(frames, max_size=12), st.lists(st.integers(0, 500), max_size=20))
def test_any_chunking_gives_same_frames(frame_list, cuts):
    """Splitting a stream at arbitrary points does not change the decoded frames."""
    stream = b''.join(encode(frame) for frame in frame_list)
    points = sorted({min(c, len(stream)) for c in cuts} | {0, len(stream)})
    decoder = FrameDecoder()
    got = []
    for start, end in zip(points, points[1:]):
        got += decoder.feed(stream[start:end])
    assert got == frame_list == decode_all(stream)
    byte_by_byte = FrameDecoder()
    assert [f for i in range(len(stream)) for f in byte_by_byte.feed(stream[i:i + 1])] == got


def test_oversized_run_discarded_and_recovers():
    """A run without 0x00 longer than the bound is dropped once, memory stays bounded."""
    decoder = FrameDecoder()
    for _ in range(10):
        assert decoder.feed(b'\x01' * 1000) == []
    assert decoder.stats.oversized == 1
    assert decoder.stats.bytes_discarded == 10000
    assert len(decoder._buffer) == 0  # noqa: SLF001 - memory bound is the point
    frame = SAMPLE_FRAMES[3]
    assert decoder.feed(b'\x00' + encode(frame)) == [frame]
    assert decoder.stats.oversized == 1
    assert decoder.stats.frames_ok == 1


def test_oversized_boundary():
    """A run of max_frame_bytes - 1 bytes is decoded; one byte more is oversized."""
    decoder = FrameDecoder(max_frame_bytes=40)
    decoder.feed(b'\x27' + b'\x11' * 38 + b'\x00')           # 39 bytes: tried, bad CRC
    assert (decoder.stats.oversized, decoder.stats.bad_crc) == (0, 1)
    decoder.feed(b'\x28' + b'\x11' * 39 + b'\x00')           # 40 bytes: oversized
    assert (decoder.stats.oversized, decoder.stats.bad_crc) == (1, 1)
    with pytest.raises(ValueError):
        FrameDecoder(max_frame_bytes=LARGEST_FRAME_BYTES - 1)


def test_idle_delimiters_are_not_errors():
    """Runs of 0x00 between frames are idle line, not errors."""
    decoder = FrameDecoder()
    frame = SAMPLE_FRAMES[1]
    got = decoder.feed(b'\x00\x00\x00' + encode(frame) + b'\x00\x00' + encode(frame))
    assert got == [frame, frame]
    assert decoder.stats == DecoderStats(frames_ok=2)


def test_wrong_version_counted_and_dropped():
    """A well-formed frame of another version is dropped and its version remembered."""
    decoder = FrameDecoder()
    other = raw_frame(2, 0x83, 5, bytes(12))
    assert decoder.feed(other + encode(NEXT_FRAME)) == [NEXT_FRAME]
    assert decoder.stats.wrong_version == 1
    assert decoder.stats.last_wrong_version == 2
    assert decoder.stats.bytes_discarded == len(other) - 1


def test_unknown_type_and_bad_lengths_counted():
    """Unknown type, wrong payload size and a too-short body are separate counters."""
    decoder = FrameDecoder()
    stream = (raw_frame(1, 0x7F, 0, b'')                       # unknown type
              + raw_frame(1, 0x81, 0, bytes(19))               # ENCODER_TICKS one short
              + cobs_encode(b'\x01\x02\x03') + b'\x00'         # shorter than header + CRC
              + raw_frame(1, 0x81, 0, bytes(20)))              # valid
    assert decoder.feed(stream) == [Frame(0, EncoderTicks(0, (0, 0, 0, 0)))]
    stats = decoder.stats
    assert (stats.unknown_type, stats.bad_length, stats.bad_crc, stats.errors) == (1, 2, 0, 3)


def test_bad_cobs_and_bad_crc_counted():
    """Malformed COBS and a corrupted CRC are counted separately."""
    decoder = FrameDecoder()
    good = encode(SAMPLE_FRAMES[2])
    corrupted = bytearray(good)
    corrupted[-2] ^= 0x01   # a CRC byte (never 0x00 after flipping here)
    assert corrupted[-2] != 0
    decoder.feed(b'\x09\x11\x00' + bytes(corrupted))
    assert (decoder.stats.bad_cobs, decoder.stats.bad_crc) == (1, 1)


@pytest.mark.parametrize('payload', [
    struct.pack('<4hH', 0, 0, 0, 0, 0),                 # timeout 0
    struct.pack('<4hH', 10001, 0, 0, 0, 100),           # duty beyond full scale
    struct.pack('<4hH', 0, 0, 0, -32768, 100),
])
def test_invalid_motor_efforts_rejected_by_decoder(payload):
    """What the board must refuse, the reference decoder refuses too."""
    decoder = FrameDecoder()
    assert decoder.feed(raw_frame(1, 0x01, 3, payload)) == []
    assert decoder.stats.bad_payload == 1


def test_reset_drops_partial_frame():
    """reset() forgets half a frame, as after reopening the port."""
    decoder = FrameDecoder()
    encoded = encode(SAMPLE_FRAMES[3])
    assert decoder.feed(encoded[:10]) == []
    decoder.reset()
    assert decoder.feed(encode(NEXT_FRAME)) == [NEXT_FRAME]
    assert decoder.stats.bytes_discarded == 10


# ---------------------------------------------------------------- sequence numbers


@pytest.mark.parametrize('previous, current, delta', [
    (0, 1, 1), (1, 0, -1), (65535, 0, 1), (0, 65535, -1), (65530, 4, 10),
    (4, 65530, -10), (0, 32767, 32767), (0, 32768, -32768), (100, 100, 0)])
def test_seq_delta(previous, current, delta):
    """Signed modular distance."""
    assert seq_delta(previous, current) == delta


@FAST
@given(u16, u16)
def test_seq_delta_range(previous, current):
    """seq_delta is in [-32768, 32767] and consistent modulo 2^16."""
    delta = seq_delta(previous, current)
    assert -32768 <= delta <= 32767
    assert (previous + delta) % 65536 == current


def test_sequence_tracker():
    """first, next across the wrap, gap, duplicate, stale, reset."""
    tracker = SequenceTracker()
    assert tracker.update(65534) == 'first'
    assert tracker.update(65535) == 'next'
    assert tracker.update(0) == 'next'              # wrap 65535 -> 0
    assert tracker.update(4) == 'gap'               # 1, 2, 3 lost
    assert tracker.lost == 3
    assert tracker.update(4) == 'duplicate'
    assert tracker.update(2) == 'stale'
    assert tracker.update(5) == 'next'
    assert tracker.update((5 - 1000) % 65536) == 'stale'   # exactly 1000 back
    assert tracker.update((5 - 1001) % 65536) == 'reset'   # 1001 back: peer restarted
    assert tracker.update((5 - 1000) % 65536) == 'next'
    assert (tracker.lost, tracker.duplicates, tracker.stale, tracker.resets) == (3, 1, 2, 1)
    tracker.reset()
    assert tracker.update(0) == 'first'


def test_sequence_tracker_gap_across_wrap():
    """Lost frames are counted across the wrap too."""
    tracker = SequenceTracker()
    tracker.update(65530)
    assert tracker.update(3) == 'gap'
    assert tracker.lost == 8
