"""
The ESP32 motor board's firmware entry point (MicroPython runs main.py after boot).

Order: motors off first (the hardware layer's constructor), then a REPL_WINDOW_MS
window in which holding REPL_PIN low (the BOOT button) leaves the board at the REPL
(to copy new files with mpremote; the flash script does it through the USB bridge's
DTR line), then the loop: board_core's poll, then wait for the host or the next report.
"""

import time

import board_config
from machine import Pin


def repl_requested(config):
    """Tell whether REPL_PIN is held low during the REPL window after boot."""
    if config.REPL_PIN is None:
        return False
    pin = Pin(config.REPL_PIN, Pin.IN, Pin.PULL_UP)
    start = time.ticks_ms()
    while time.ticks_diff(time.ticks_ms(), start) < config.REPL_WINDOW_MS:
        if pin.value() == 0:
            return True
        time.sleep_ms(10)
    return False


def run(hardware):
    """Start the board and loop for ever (the watchdog resets it if the loop stalls)."""
    hardware.start()
    import board_params
    from mecanum_control.board_core import BoardCore
    core = BoardCore(hardware, board_params.PARAMS)
    hardware.write(b'\x00')   # leading delimiter after boot (protocol doc, 1)
    try:
        while True:
            core.poll()
            hardware.idle(core.idle_us())
    finally:
        # A bug that ends the loop leaves the motors off (and the unfed watchdog resets
        # the board within WATCHDOG_MS).
        hardware.set_duties((0, 0, 0, 0))


def main():
    """Motors off, the REPL window, then the firmware."""
    from hardware_esp32 import Esp32Hardware
    hardware = Esp32Hardware(board_config)   # motors off
    if repl_requested(board_config):
        print('main.py: REPL pin held low: firmware not started, motors off')
    else:
        run(hardware)


main()
