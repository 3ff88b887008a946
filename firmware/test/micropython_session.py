"""
A MicroPython 1.27 session in a node process (WebAssembly), driven from CPython.

:class:`MicroPython` starts ``micropython_runner.mjs`` under node, puts files into the
interpreter's filesystem and runs code in it; globals persist between runs, so a test
can keep a firmware core alive and step it. :func:`unavailable` tells why no session
can start (no node, or the pinned npm package not installed: ``make setup`` runs
``npm ci`` in firmware/ when node and npm exist).
"""

import json
from pathlib import Path
import select
import shutil
import subprocess
from typing import Dict, Mapping, Optional

FIRMWARE = Path(__file__).resolve().parents[1]
RUNNER = FIRMWARE / 'test' / 'micropython_runner.mjs'
PACKAGE = (FIRMWARE / 'node_modules' / '@micropython' / 'micropython-webassembly-pyscript'
           / 'micropython.mjs')
#: Longest wait for one answer (s): a loaded machine, a long run.
ANSWER_TIMEOUT_S = 120.0


class MicroPythonError(RuntimeError):
    """Code run in the session raised (the message is MicroPython's traceback)."""


def unavailable() -> Optional[str]:
    """Return why MicroPython cannot run here, or None when it can."""
    if shutil.which('node') is None:
        return 'node is not installed (MicroPython runs as WebAssembly under node >= 18)'
    if not PACKAGE.exists():
        return (f'{PACKAGE.relative_to(FIRMWARE)} is missing: run `make setup` '
                '(npm ci in firmware/)')
    return None


class MicroPython:
    """One MicroPython interpreter in a node process."""

    def __init__(self):
        reason = unavailable()
        if reason:
            raise RuntimeError(reason)
        self.process = subprocess.Popen(
            ['node', str(RUNNER)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True, bufsize=1)
        ready = self._answer()
        if ready.get('out') != 'ready':
            raise RuntimeError(f'the MicroPython runner did not start: {ready}')

    def _answer(self) -> dict:
        stdout = self.process.stdout
        readable, _, _ = select.select([stdout], [], [], ANSWER_TIMEOUT_S)
        line = stdout.readline() if readable else ''
        if not line:
            self.process.kill()
            error = self.process.stderr.read()
            raise RuntimeError(f'the MicroPython runner died or hung: {error}')
        return json.loads(line)

    def request(self, request: Mapping) -> dict:
        """Send one request, return its answer."""
        self.process.stdin.write(json.dumps(request) + '\n')
        self.process.stdin.flush()
        return self._answer()

    def write_files(self, files: Mapping[str, str]) -> None:
        """Put files (path in the interpreter -> text) into its filesystem."""
        answer = self.request({'write': dict(files)})
        if not answer['ok']:
            raise MicroPythonError(answer['error'])

    def run(self, code: str) -> str:
        """Run code in the session's __main__; return what it printed."""
        answer = self.request({'run': code})
        if not answer['ok']:
            raise MicroPythonError(f"{answer['error']}\n(printed: {answer['out']})")
        return answer['out']

    def close(self) -> None:
        """End the node process."""
        if self.process.poll() is None:
            self.process.stdin.close()
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.process.stdout.close()
        self.process.stderr.close()

    def __enter__(self) -> 'MicroPython':
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def portable_firmware_files() -> Dict[str, str]:
    """Return the firmware's files that run anywhere, as /lib paths -> text."""
    import importlib.util
    spec = importlib.util.spec_from_file_location('firmware_flash', FIRMWARE / 'flash.py')
    flash = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(flash)
    return {'/lib/' + board_path: source.read_text()
            for board_path, source in flash.BOARD_FILES.items()
            if board_path not in flash.HARDWARE_FILES}


def robot_params() -> Dict[str, int]:
    """Return the firmware parameters of the workspace's robot config (board_params)."""
    from mecanum_control.board_params import board_params
    from mecanum_control.robot_config import default_config_path, load_robot_config
    return board_params(load_robot_config(default_config_path()))
