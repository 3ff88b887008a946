"""
board_check against the board emulator: two real processes over a real pty (no ROS).

The emulator runs the firmware's own core (board_core) on the emulated robot, so these
runs are what a person sees after flashing: a healthy board, a wheel that spins the
right way, and one that cannot turn (blocked: no counts, then the firmware's own
ENCODER_FAULT).
"""

import contextlib
from pathlib import Path
import subprocess
import sys
import time

import pytest


@contextlib.contextmanager
def emulator(link: Path, *options: str):
    """Run board_emulator on a pty published at link; stop it afterwards."""
    process = subprocess.Popen(
        [sys.executable, '-m', 'mecanum_control.board_emulator', '--link', str(link),
         *options], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 30.0
        while not link.is_symlink():
            assert process.poll() is None, process.stdout.read()
            assert time.monotonic() < deadline, 'the emulator did not plug its pty in'
            time.sleep(0.05)
        yield process
    finally:
        process.terminate()
        process.wait(timeout=10)
        process.log = process.stdout.read()   # what it printed, for the test
        process.stdout.close()


def board_check(link: Path, *options: str) -> subprocess.CompletedProcess:
    """Run board_check on the link and return its result."""
    return subprocess.run(
        [sys.executable, '-m', 'mecanum_control.board_check', '--port', str(link), *options],
        capture_output=True, text=True, timeout=60)


def test_healthy_board_and_a_wheel_that_spins_forward(tmp_path):
    """A healthy board: no faults after zero commands; FL counts forward when spun."""
    link = tmp_path / 'ttyESP32'
    with emulator(link):
        result = board_check(link, '--spin', 'FL', '--duty', '0.3', '--spin-seconds', '1')
    out = result.stdout
    assert result.returncode == 0, out + result.stderr
    assert 'faults: none' in out
    assert 'imu: accel [' in out and '|a| 9.8' in out
    assert 'spin FL: counted the right way' in out
    spun = [line for line in out.splitlines() if line.strip().startswith('spin FL at duty')]
    counts = int(spun[0].split(': ')[1].split()[0])
    assert counts > 1000, spun   # 0.3 x 34.5 rad/s for 1 s is about 2000 counts
    assert 'others: FR 0, RL 0, RR 0' in spun[0]


def test_blocked_wheel_is_reported_and_the_firmware_trips_encoder_fault(tmp_path):
    """A blocked wheel counts nothing; at high duty the firmware stops it (ENCODER_FAULT)."""
    link = tmp_path / 'ttyESP32'
    with emulator(link, '--block-wheel', 'RR') as process:
        result = board_check(link, '--spin', 'RR', '--duty', '0.8', '--spin-seconds', '1.5')
    out = result.stdout
    assert result.returncode == 1, out + result.stderr
    assert 'spin RR: no counts' in out
    assert 'faults after the spin: ENCODER_FAULT' in out
    log = process.log
    assert 'ENCODER_FAULT (RR): motors off until CLEAR_FAULTS' in log, log


def test_nothing_on_the_port(tmp_path):
    """A port nobody answers on (a pty with no board behind it): exit code 2."""
    import os
    import pty
    master, slave = pty.openpty()
    try:
        result = board_check(Path(os.ttyname(slave)), '--seconds', '0.3')
    finally:
        os.close(master)
        os.close(slave)
    assert result.returncode == 2
    assert 'did not answer' in result.stderr


@pytest.mark.parametrize('argv', [['--port', 'x', '--duty', '0'], ['--port', 'x', '--duty', '2']])
def test_bad_arguments_are_refused(argv):
    """A zero or out-of-range duty is refused."""
    from mecanum_control.board_check import parse_args
    with pytest.raises(SystemExit):
        parse_args(argv)
