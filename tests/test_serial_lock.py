"""
Integration: one program at a time drives the board (the serial port's exclusive lock).

The board emulator plays the ESP32 on a real pty (its own process); hardware_interface
(a real ROS node process) and board_check (a plain process) open the same device. Each
takes pyserial's exclusive lock (flock LOCK_EX | LOCK_NB), so the second one is refused
with a message naming the device and the program holding it, instead of both sending
efforts to the motors at once. hardware_interface keeps retrying, as for an absent
port, and takes the board once the other program has let go.
"""

import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import tty

from mecanum_control.board_check import open_exclusive, PortInUse
import pytest
from tests.conftest import OutputProcess

pytestmark = pytest.mark.integration
REPO = Path(__file__).resolve().parents[1]


def stop(process: OutputProcess, sig=signal.SIGINT) -> int:
    """Signal a process (and its group) and return its exit code."""
    if process.process.poll() is None:
        os.killpg(process.process.pid, sig)
    try:
        return process.process.wait(timeout=15)
    except subprocess.TimeoutExpired:
        os.killpg(process.process.pid, signal.SIGKILL)
        raise


@pytest.fixture
def board(ros_env, tmp_path):
    """Run the board emulator on a pty published at tmp_path/ttyESP32: (link, process)."""
    link = tmp_path / 'ttyESP32'
    emulator = OutputProcess([sys.executable, '-m', 'mecanum_control.board_emulator',
                              '--link', str(link)], ros_env, cwd=REPO)
    try:
        emulator.wait_for_line(r'board_emulator: plugged in at', timeout=30)
        yield link, emulator
    finally:
        stop(emulator)


def start_hardware_interface(env, link: Path) -> OutputProcess:
    """Start hardware_interface (./mecanum run) on link."""
    return OutputProcess(
        ['./mecanum', 'run', 'mecanum_control', 'hardware_interface', '--ros-args',
         '-p', f'port:={link}', '-p', 'reconnect_period_s:=0.3'], env, cwd=REPO)


def test_the_lock_is_per_opening_and_ends_with_it(tmp_path):
    """Two openings in one process conflict too (flock is per open file); close frees it."""
    master, slave = os.openpty()
    tty.setraw(slave)
    link = tmp_path / 'tty'
    os.symlink(os.ttyname(slave), link)
    try:
        first = open_exclusive(str(link), 115200, timeout=0)
        with pytest.raises(PortInUse, match=rf'^another program holds it \(pid {os.getpid()}: '):
            open_exclusive(str(link), 115200, timeout=0)
        first.close()
        open_exclusive(str(link), 115200, timeout=0).close()
        # Other failures stay what they were.
        with pytest.raises(OSError, match='could not open port'):
            open_exclusive(str(tmp_path / 'absent'), 115200, timeout=0)
    finally:
        os.close(master)
        os.close(slave)


def test_board_check_is_refused_while_hardware_interface_holds_the_port(ros_env, board):
    link, _ = board
    host = start_hardware_interface(ros_env, link)
    try:
        host.wait_for_line(r'Connected to the board at')
        result = subprocess.run(
            [sys.executable, '-m', 'mecanum_control.board_check', '--port', str(link),
             '--seconds', '0.5', '--spin', 'FL'],
            env=ros_env, cwd=REPO, capture_output=True, text=True, timeout=60)
        assert result.returncode == 2, result.stdout + result.stderr
        # The device, that another program holds it, and which one (./mecanum run execs
        # the node, so its pid is the Popen's).
        assert re.search(
            rf'board_check: cannot open {re.escape(str(link))}: another program holds it '
            rf'\(pid {host.process.pid}: hardware_interface\b', result.stderr), result.stderr
        assert 'spin' not in result.stdout   # it never got to drive the board
        assert 'Traceback' not in result.stderr
        # The stack kept the board all along.
        assert 'lost' not in host.output() and 'does not answer' not in host.output()
    finally:
        assert stop(host) == 0, host.output()


def test_hardware_interface_waits_while_board_check_holds_the_port(ros_env, board):
    link, emulator = board
    check = OutputProcess([sys.executable, '-m', 'mecanum_control.board_check', '--port',
                           str(link), '--seconds', '120'], ros_env, cwd=REPO)
    host = None
    try:
        # board_check feeds the board's command watchdog: it has the port.
        emulator.wait_for_line(r'effort commands resumed')
        host = start_hardware_interface(ros_env, link)
        host.wait_for_line(
            rf'\[ERROR\].*Cannot open {re.escape(str(link))}: another program holds it '
            rf'\(pid {check.process.pid}: mecanum_control\.board_check\b.*retrying every 0.3 s')
        assert 'Connected to the board' not in host.output()
        stop(check)
        # Retried as for an absent port: the stack takes the board once it is free.
        host.wait_for_line(r'Connected to the board at')
        assert host.output().count('another program holds it') == 1, host.output()
    finally:
        stop(check)
        if host is not None:
            assert stop(host) == 0, host.output()
