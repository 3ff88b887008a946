"""
Fixtures of the firmware tests: a MicroPython 1.27 session with the firmware loaded.

The firmware's portable files (flash.BOARD_FILES but the two that import machine) go
to /lib in the interpreter, as the flash script puts them on the board; core_cases.py
and sim_hardware.py (the simulated hardware) go beside them. Without node or the npm
package the MicroPython tests are skipped, with the reason.
"""

from pathlib import Path
import sys

HERE = Path(__file__).resolve().parent
for path in (HERE, HERE.parent):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

from micropython_session import (  # noqa: E402
    MicroPython, portable_firmware_files, robot_params, unavailable)
import pytest  # noqa: E402


@pytest.fixture(scope='module')
def micropython():
    """Yield a MicroPython session with the firmware, its test cases and the robot's parameters."""
    reason = unavailable()
    if reason:
        pytest.skip(f'MicroPython unavailable: {reason}')
    session = MicroPython()
    try:
        files = portable_firmware_files()
        for name in ('core_cases.py', 'sim_hardware.py'):
            files['/lib/' + name] = (HERE / name).read_text()
        session.write_files(files)
        session.run(f'import core_cases\ncore_cases.PARAMS = {robot_params()!r}')
        yield session
    finally:
        session.close()
