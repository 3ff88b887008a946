"""
The pin map's check: which GPIOs board_config.py gives to what, and which clash (no hardware).

hardware_esp32.py calls :func:`check` before it touches a single pin, so a wiring
that would make one pin two things (a UART on a motor's direction pin drives that
motor), drive an input-only pin or use the flash's pins leaves every pin as the reset
left it and stops with a message naming the pins. Portable: it runs, and is tested,
under MicroPython and CPython. GPIO numbers are the ESP32's (ESP32-WROOM-32).
"""

#: GPIOs the ESP32 has (20, 24 and 28-31 do not exist).
ESP32_GPIOS = tuple(range(0, 20)) + (21, 22, 23, 25, 26, 27) + tuple(range(32, 40))
#: Input-only GPIOs: no output driver, no internal pull-up.
INPUT_ONLY = (34, 35, 36, 37, 38, 39)
#: GPIOs nothing of ours may use: the SPI flash's (6-11) and the USB serial port's
#: (1 TX, 3 RX: the REPL and the 'stdio' link).
RESERVED = {1: 'USB serial TX (UART0)', 3: 'USB serial RX (UART0)', 6: 'SPI flash',
            7: 'SPI flash', 8: 'SPI flash', 9: 'SPI flash', 10: 'SPI flash',
            11: 'SPI flash'}
#: A strapping pin no input may use: high at reset selects 1.8 V flash.
NO_INPUT = {12: 'strapping pin MTDI: high at reset selects 1.8 V flash'}

WHEELS = ('FL', 'FR', 'RL', 'RR')


def uses(config):
    """
    Return [(gpio, what, is_output)] for every pin board_config gives a job.

    ``what`` names the setting, e.g. ``'MOTORS[2] (RL) in2'``; ``is_output`` is True
    for a pin the board drives (motor inputs, STANDBY_PIN, UART_TX, the I2C lines).
    """
    out = []
    for index, wiring in enumerate(config.MOTORS):
        for key in ('pwm', 'in1', 'in2', 'dir'):
            if key in wiring:
                out.append((wiring[key], 'MOTORS[%d] (%s) %s' % (index, WHEELS[index], key),
                            True))
    for index, wiring in enumerate(config.ENCODERS):
        for key in ('a', 'b'):
            out.append((wiring[key], 'ENCODERS[%d] (%s) %s' % (index, WHEELS[index], key),
                        False))
    if config.IMU is not None:
        out.append((config.I2C_SCL, 'I2C_SCL', True))
        out.append((config.I2C_SDA, 'I2C_SDA', True))
    optional = (('STANDBY_PIN', True), ('BATTERY_ADC_PIN', False), ('ESTOP_PIN', False),
                ('DRIVER_FAULT_PIN', False), ('REPL_PIN', False))
    for name, is_output in optional:
        pin = getattr(config, name)
        if pin is not None:
            out.append((pin, name, is_output))
    if config.SERIAL == 'uart':
        out.append((config.UART_TX, 'UART_TX', True))
        out.append((config.UART_RX, 'UART_RX', False))
    return out


def problems(config):
    """Return the pin map's problems as sentences (an empty list: the map is sound)."""
    found = []
    keys = {'DRV8833': ('in1', 'in2'), 'PWM_DIR': ('pwm', 'dir')}.get(
        config.DRIVER, ('pwm', 'in1', 'in2'))
    for index, wiring in enumerate(config.MOTORS):
        if sorted(key for key in wiring if key != 'invert') != sorted(keys):
            found.append('MOTORS[%d] (%s): %s wants the pins %s' % (
                index, WHEELS[index], config.DRIVER, ', '.join(keys)))
    if config.SERIAL not in ('stdio', 'uart'):
        found.append("SERIAL must be 'stdio' or 'uart', not %r" % (config.SERIAL,))
    jobs = uses(config)
    if config.SERIAL == 'uart' and (config.UART_TX is None or config.UART_RX is None):
        jobs = [job for job in jobs if job[0] is not None]
        found.append("SERIAL = 'uart' needs UART_TX and UART_RX; pins free in this map: "
                     + (', '.join(str(pin) for pin in free_pins(config)) or 'none'))
    by_pin = {}
    for pin, what, is_output in jobs:
        by_pin.setdefault(pin, []).append(what)
        if pin not in ESP32_GPIOS:
            found.append('GPIO %r (%s): the ESP32 has no such GPIO' % (pin, what))
        elif pin in RESERVED:
            found.append('GPIO %d (%s): reserved, %s' % (pin, what, RESERVED[pin]))
        elif is_output and pin in INPUT_ONLY:
            found.append('GPIO %d (%s): input only, cannot drive an output' % (pin, what))
        elif not is_output and pin in NO_INPUT:
            found.append('GPIO %d (%s): %s' % (pin, what, NO_INPUT[pin]))
    for pin in sorted(by_pin):
        if len(by_pin[pin]) > 1:
            found.append('GPIO %d is used twice: %s' % (pin, ' and '.join(by_pin[pin])))
    return found


def free_pins(config):
    """Return the usable GPIOs that no setting of the map takes (input-only ones last)."""
    taken = {job[0] for job in uses(config)}
    usable = [pin for pin in ESP32_GPIOS
              if pin not in taken and pin not in RESERVED and pin not in NO_INPUT]
    return ([pin for pin in usable if pin not in INPUT_ONLY]
            + [pin for pin in usable if pin in INPUT_ONLY])


def check(config):
    """Raise ValueError naming every clash if the pin map has problems."""
    found = problems(config)
    if found:
        raise ValueError('board_config.py pin map refused, no pin driven:\n  '
                         + '\n  '.join(found))
