#!/usr/bin/env python3
"""
Benchmark: the ESP32 firmware's loop iteration time under MicroPython 1.27 and CPython.

Runs the firmware's own core (mecanum_control/board_core.py, with esp32_wire) on the
simulated hardware of firmware/test/sim_hardware.py, under the WebAssembly MicroPython
1.27 of the firmware tests (node; skipped when missing) and under this CPython, and
times one ``poll`` in four situations:

* idle: nothing due, nothing received (most iterations on the board);
* command: one MOTOR_EFFORTS frame received and applied;
* IMU due: one IMU_SAMPLE encoded and sent (every 10 ms);
* all due: a command received and ENCODER_TICKS, IMU_SAMPLE and BOARD_STATUS sent
  (every 100 ms: the worst regular iteration).

And the load of a second of board time at a 1 kHz loop with the host's 50 Hz commands
(CPU ms per board second: the polls alone, not the simulated hardware). MicroPython is timed with node's performance.now
(its ticks_us counts whole milliseconds in the WebAssembly port). An ESP32 at 240 MHz
runs MicroPython bytecode roughly 10-30 times slower than this machine's WebAssembly
build does: the figures bound the board's loop only after that scaling.

Run:  ./mecanum exec python bench/firmware_loop.py [--repeat 2000] [--json FILE]
"""

import argparse
import ast
import json
from pathlib import Path
import sys
import time

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / 'firmware' / 'test'))

from micropython_session import (  # noqa: E402
    MicroPython, portable_firmware_files, robot_params, unavailable)

#: Runs in both interpreters; ``now()`` is a millisecond clock given by the caller.
MEASURE = '''
from sim_hardware import SimHardware
from mecanum_control import board_core
from mecanum_control import esp32_wire as wire


def measure(params, repeat, now):
    hw = SimHardware()
    core = board_core.BoardCore(hw, params)
    command = wire.encode_frame(wire.MOTOR_EFFORTS, 1, (1000, 1000, 1000, 1000, 150))
    results = {}

    def timed(name, prepare):
        times = []
        for _ in range(repeat):
            prepare()
            start = now()
            core.poll()
            times.append(now() - start)
            hw.tx = bytearray()
        times.sort()
        results[name] = (times[len(times) // 2], times[len(times) * 9 // 10])

    def idle():
        hw.advance(10)

    def take_command():
        hw.advance(10)
        hw.rx += command

    def imu_due():
        hw.advance(10000 - (hw.time_us % 10000))   # the next 10 ms boundary: IMU only
        if hw.time_us % 20000 == 0:
            hw.advance(10000)

    def all_due():
        hw.advance(100000)
        hw.rx += command

    for _ in range(50):
        all_due()
        core.poll()
    timed('idle', idle)
    timed('command', take_command)
    timed('IMU due', imu_due)
    timed('all due', all_due)
    total = 0.0
    for step in range(1000):   # one board second: 1 kHz loop, a command every 20 ms
        if step % 20 == 0:
            hw.rx += command
        hw.advance(1000)
        start = now()
        core.poll()
        total += now() - start
        hw.tx = bytearray()
    results['per board second'] = (total, None)
    return results
'''


def cpython_figures(repeat: int) -> dict:
    """Measure under this CPython."""
    namespace = {}
    exec(compile(MEASURE, 'measure', 'exec'), namespace)  # noqa: S102 - our code
    return namespace['measure'](robot_params(), repeat, lambda: time.perf_counter() * 1e3)


def micropython_figures(repeat: int) -> dict:
    """Measure under MicroPython 1.27 (WebAssembly, node)."""
    with MicroPython() as session:
        files = portable_firmware_files()
        files['/lib/sim_hardware.py'] = (REPO / 'firmware/test/sim_hardware.py').read_text()
        files['/lib/firmware_bench.py'] = MEASURE
        session.write_files(files)
        out = session.run(
            'import js\nimport firmware_bench\n'
            f'r = firmware_bench.measure({robot_params()!r}, {repeat}, js.performance.now)\n'
            'print(repr(r))')
    return ast.literal_eval(out)


def main() -> int:
    """Measure, print the table, optionally write JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--repeat', type=int, default=2000)
    parser.add_argument('--json', type=Path)
    args = parser.parse_args()
    columns = {'CPython ' + sys.version.split()[0]: cpython_figures(args.repeat)}
    reason = unavailable()
    if reason:
        print(f'MicroPython skipped: {reason}')
    else:
        columns['MicroPython 1.27 (wasm)'] = micropython_figures(args.repeat)
    names = ('idle', 'command', 'IMU due', 'all due')
    print(f'firmware loop: one poll of board_core, median (p90) in microseconds, '
          f'{args.repeat} polls each')
    print(f'{"iteration":<20}' + ''.join(f'{name:>26}' for name in columns))
    for row in names:
        cells = ''.join('{:>26}'.format(f'{r[row][0] * 1e3:.1f} ({r[row][1] * 1e3:.1f})')
                        for r in columns.values())
        print(f'{row:<20}{cells}')
    seconds = [r['per board second'][0] for r in columns.values()]
    cells = ''.join(f'{f"{ms:.1f} ms":>26}' for ms in seconds)
    print(f'{"CPU per board s":<20}{cells}   (1 kHz loop, 50 Hz commands, all reports)')
    if args.json:
        args.json.write_text(json.dumps(columns, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
