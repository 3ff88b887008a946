#!/usr/bin/env python3
"""
Copy the firmware to an ESP32 running MicroPython, with mpremote (host side, CPython).

``make firmware-flash PORT=/dev/ttyUSB0`` runs it. What the board gets is
``BOARD_FILES`` (this folder's modules, the shared protocol and board core from the
mecanum_control package, as the package ``mecanum_control/`` on the board) and
``board_params.py``, generated here from the robot config (motor_params.yaml), so the
firmware's thresholds are never typed twice.

A board already running the firmware has taken its serial port (the REPL is off), so
first the script resets it through the USB bridge (RTS) and holds the BOOT pin low
(DTR) during main.py's REPL window, which leaves it at the REPL; ``--no-reset`` skips
that for a board that is at the REPL anyway (fresh MicroPython, or BOOT held by hand).
Afterwards mpremote resets the board into the new firmware.

Usage: flash.py --port /dev/ttyUSB0 [--config motor_params.yaml] [--no-reset] [--dry-run]
"""

import argparse
from pathlib import Path
import shutil
import subprocess
import sys
import tempfile
import time
from typing import Dict, List, Optional

FIRMWARE = Path(__file__).resolve().parent
REPO = FIRMWARE.parent
PACKAGE = REPO / 'src' / 'mecanum_control' / 'mecanum_control'
ROBOT_CONFIG = REPO / 'src' / 'mecanum_control' / 'config' / 'motor_params.yaml'

#: Path on the board -> source file: everything the firmware runs, but board_params.py.
BOARD_FILES: Dict[str, Path] = {
    'main.py': FIRMWARE / 'main.py',
    'board_config.py': FIRMWARE / 'board_config.py',
    'hardware_esp32.py': FIRMWARE / 'hardware_esp32.py',
    'h_bridge.py': FIRMWARE / 'h_bridge.py',
    'imu_drivers.py': FIRMWARE / 'imu_drivers.py',
    'pin_map.py': FIRMWARE / 'pin_map.py',
    'mecanum_control/__init__.py': PACKAGE / '__init__.py',
    'mecanum_control/esp32_wire.py': PACKAGE / 'esp32_wire.py',
    'mecanum_control/board_core.py': PACKAGE / 'board_core.py',
}
#: The board files that import machine or esp32: they run on the board only.
HARDWARE_FILES = ('main.py', 'hardware_esp32.py')
#: The generated file of robot parameters.
PARAMS_FILE = 'board_params.py'


def params_source(config_path: Path) -> str:
    """Return board_params.py for the robot config at config_path."""
    sys.path.insert(0, str(PACKAGE.parent))
    try:
        from mecanum_control.board_params import board_params_source
        from mecanum_control.robot_config import load_robot_config
    finally:
        sys.path.pop(0)
    return board_params_source(load_robot_config(config_path), config_path.name)


def mpremote_commands(port: str, staging: Path) -> List[List[str]]:
    """Return the mpremote command lines that copy the staged files and reset the board."""
    base = ['mpremote', 'connect', port]
    make_package = ("import os\ntry:\n    os.mkdir('mecanum_control')\n"
                    'except OSError:\n    pass\n')
    copy: List[str] = ['exec', make_package]
    for board_path in sorted(list(BOARD_FILES) + [PARAMS_FILE]):
        copy += ['+', 'fs', 'cp', str(staging / board_path), ':' + board_path]
    return [base + copy + ['+', 'reset']]


def enter_repl(port: str, window_s: float = 2.0) -> None:
    """Reset the board (RTS) and hold BOOT low (DTR) through main.py's REPL window."""
    import serial
    with serial.Serial(port, 115200) as line:
        line.dtr, line.rts = False, True     # EN low: reset
        time.sleep(0.1)
        line.rts = False                     # EN high, BOOT high: a normal boot
        time.sleep(0.3)                      # past the ROM's look at the BOOT pin
        line.dtr = True                      # BOOT low: main.py stays at the REPL
        time.sleep(window_s + 1.0)
        line.dtr = False


def main(argv: Optional[List[str]] = None) -> int:
    """Stage the files, reach the REPL, copy them and reset the board."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--port', required=True, help='serial port, e.g. /dev/ttyUSB0')
    parser.add_argument('--config', type=Path, default=ROBOT_CONFIG,
                        help='motor_params.yaml (default: the workspace one)')
    parser.add_argument('--no-reset', action='store_true',
                        help='the board is at the REPL already: do not reset it first')
    parser.add_argument('--dry-run', action='store_true',
                        help='stage the files and print the mpremote commands only')
    args = parser.parse_args(argv)
    staging = Path(tempfile.mkdtemp(prefix='mecanum_firmware_'))
    for board_path, source in BOARD_FILES.items():
        (staging / board_path).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, staging / board_path)
    (staging / PARAMS_FILE).write_text(params_source(args.config))
    commands = mpremote_commands(args.port, staging)
    if args.dry_run:
        print(f'staged in {staging}:')
        for command in commands:
            print(' '.join(command))
        return 0
    if shutil.which('mpremote') is None:
        print('flash.py: mpremote not found (make setup installs it in .venv: run me with '
              './mecanum exec python firmware/flash.py)', file=sys.stderr)
        return 2
    if not args.no_reset:
        print(f'flash.py: resetting the board on {args.port} into its REPL')
        enter_repl(args.port)
    for command in commands:
        print('flash.py: ' + ' '.join(command[:4]) + ' ...')
        if subprocess.run(command).returncode != 0:
            print('flash.py: mpremote failed (is the board at the REPL? hold BOOT, tap EN, '
                  'release BOOT after 1 s, and run again with --no-reset)', file=sys.stderr)
            return 1
    print('flash.py: done; check it with: ./mecanum run mecanum_control board_check '
          f'--port {args.port}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
