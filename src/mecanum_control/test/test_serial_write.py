"""hardware_interface.write_all on a real pseudo-terminal (no ROS)."""

import os
import threading
import tty

from mecanum_control.hardware_interface import write_all
import pytest
import serial


@pytest.fixture
def pty_pair():
    """Return (host fd, board fd): a raw pty, the host end non-blocking as pyserial opens it."""
    board, host = os.openpty()
    tty.setraw(host)
    os.set_blocking(host, False)
    yield host, board
    os.close(host)
    os.close(board)


def read_all(fd, count):
    data = b''
    while len(data) < count:
        data += os.read(fd, count - len(data))
    return data


def test_a_complete_write_is_never_a_timeout(pty_pair):
    """
    A deadline that has passed once the frame is written is no timeout.

    pyserial's write(write_timeout=0.1) checks the deadline after a write that took
    everything: a process descheduled for 0.1 s between the two raised 'Write timeout'
    for a frame that had gone out (the link was dropped; the sweeps saw 13 such drops).
    A zero timeout makes that moment certain here.
    """
    host, board = pty_pair
    frame = bytes(range(1, 40)) + b'\x00'
    write_all(host, frame, 0.0)
    assert read_all(board, len(frame)) == frame


def test_a_line_nobody_reads_times_out_naming_what_is_left(pty_pair):
    host, board = pty_pair
    data = bytes(200_000)
    with pytest.raises(serial.SerialTimeoutException,
                       match=r'the line took nothing for 0\.05 s \(\d+ of 200000 bytes left\)'):
        write_all(host, data, 0.05)


def test_a_slow_reader_gets_every_byte_in_order(pty_pair):
    host, board = pty_pair
    data = bytes(i % 251 for i in range(100_000))
    received = []

    def reader():
        received.append(read_all(board, len(data)))
    thread = threading.Thread(target=reader)
    thread.start()
    write_all(host, data, 5.0)
    thread.join(timeout=30.0)
    assert received == [data]
