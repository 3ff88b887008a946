"""
The ESP32 hardware layer: the only firmware module that touches machine/esp32.

It gives board_core (mecanum_control/board_core.py) what its docstring lists: the
clock (time.ticks_us), the serial link to the host, four motors through an H-bridge
(h_bridge.py rules, PWM + direction pins), four quadrature encoders counted in
hardware and the IMU (imu_drivers.py), all as board_config.py wires them.

Encoders: MicroPython 1.26 and later (1.27 here) have machine.Encoder on the ESP32:
a Python shim over esp32.PCNT (one pulse counter unit per encoder, phases=4 for 4x
quadrature in the hardware, overflows at +-32000 counted by an interrupt handler so
value() is a full Python int). Wheel order everywhere FL, FR, RL, RR; duties are raw
protocol units (-10000 .. 10000), positive rolling the robot forward.
"""

import select
import sys
import time

import h_bridge
import imu_drivers
from machine import ADC, Encoder, I2C, Pin, PWM, UART, WDT
import micropython
import pin_map

#: While the loop waits for the host, it looks for input this often (microseconds).
#: select.poll with a timeout sleeps whole FreeRTOS ticks (10 ms at the default
#: 100 Hz) and serial input does not wake it, so the wait is poll(0) and sleep_us
#: slices: a frame is taken within about this long of its arrival.
WAIT_SLICE_US = 200
#: At most this many bytes (reads) of input left from before the start are dropped.
STALE_INPUT_MAX_BYTES = 4096


class Esp32Hardware:
    """The board's motors, encoders, IMU, inputs and serial link, as board_config says."""

    # MicroPython 1.27's machine.reset_cause() folds a brownout into PWRON_RESET
    # (ports/esp32/modmachine.c), so a brownout cannot be told apart: never reported.
    brownout_reset = False

    def __init__(self, config):
        """Check the pin map (ValueError: no pin touched), set up the motors, stopped."""
        pin_map.check(config)
        self.config = config
        self.ticks_us = time.ticks_us
        self.ticks_diff = time.ticks_diff
        self.ticks_add = time.ticks_add
        self.sleep_us = time.sleep_us
        self._brake = config.BRAKE_AT_ZERO
        if config.DRIVER not in h_bridge.DRIVERS:
            raise ValueError('board_config.DRIVER must be one of %s' % (h_bridge.DRIVERS,))
        self._motors = []
        for wiring in config.MOTORS:
            self._motors.append(self._make_motor(wiring, config.PWM_FREQ_HZ))
        self.set_duties((0, 0, 0, 0))   # motors off before anything else
        if config.STANDBY_PIN is not None:
            Pin(config.STANDBY_PIN, Pin.OUT, value=1)

    def start(self):
        """Set up the encoders, the IMU, the inputs, the serial link and the watchdog."""
        config = self.config
        pull = Pin.PULL_UP if config.ENCODER_PULL_UP else None
        self._encoders = []
        for unit, wiring in enumerate(config.ENCODERS):
            encoder = Encoder(unit, Pin(wiring['a'], Pin.IN, pull), Pin(wiring['b'], Pin.IN, pull),
                              phases=4, filter_ns=config.ENCODER_FILTER_NS)
            self._encoders.append((encoder, -1 if wiring['invert'] else 1))
        self._imu = None
        if config.IMU is not None:
            # timeout: the ESP32's hardware I2C takes it in microseconds (50000 if not
            # given: a stuck bus would cost 50 ms a read).
            i2c = I2C(config.I2C_ID, scl=Pin(config.I2C_SCL), sda=Pin(config.I2C_SDA),
                      freq=config.I2C_FREQ_HZ, timeout=config.I2C_TIMEOUT_US)
            driver = imu_drivers.DRIVERS[config.IMU]
            address = config.IMU_ADDRESS
            # Set up at the first read, and again every IMU_RETRY_MS while it fails:
            # an IMU absent at boot or lost later comes back (IMU_FAULT meanwhile).
            self._imu = imu_drivers.RetryingImu(lambda: driver(i2c, address), time,
                                                config.IMU_RETRY_MS)
        self._battery = None
        if config.BATTERY_ADC_PIN is not None:
            self._battery = ADC(Pin(config.BATTERY_ADC_PIN), atten=ADC.ATTN_11DB)
            self._divider = config.BATTERY_DIVIDER
        self._estop = None if config.ESTOP_PIN is None else Pin(
            config.ESTOP_PIN, Pin.IN, Pin.PULL_UP)
        self._fault = None if config.DRIVER_FAULT_PIN is None else Pin(
            config.DRIVER_FAULT_PIN, Pin.IN, Pin.PULL_UP)
        self._uart = None
        self._poll = select.poll()
        if config.SERIAL == 'uart':
            self._uart = UART(config.UART_ID, baudrate=config.UART_BAUD, tx=config.UART_TX,
                              rx=config.UART_RX, timeout=0, rxbuf=512)
            self._poll.register(self._uart, select.POLLIN)
        else:
            micropython.kbd_intr(-1)   # 0x03 in a frame is data, not Ctrl-C
            self._stdin = sys.stdin.buffer
            self._stdout = sys.stdout.buffer
            self._poll.register(sys.stdin, select.POLLIN)
        self._drop_stale_input()
        self._watchdog = WDT(timeout=config.WATCHDOG_MS)

    def _drop_stale_input(self):
        """
        Drop what the host sent before the loop runs (during the REPL window, a reset).

        Those commands are of unknown age: applied now they would drive the wheels for a
        command timeout on a command the host may no longer mean. The host streams its
        command, so the next one comes within a period.
        """
        for _ in range(STALE_INPUT_MAX_BYTES):
            if not self._poll.poll(0):
                return
            if self._uart is not None:
                self._uart.read()
            else:
                self._stdin.read(1)

    @staticmethod
    def _make_motor(wiring, freq_hz):
        """
        Return (first, second, third, sign): one motor's outputs and its invert.

        TB6612/L298N: (PWM, IN1, IN2); DRV8833: (PWM IN1, PWM IN2, None); PWM_DIR:
        (PWM, DIR, [DIR's level], kept here: an output pin's value() is not its level).
        """
        sign = -1 if wiring['invert'] else 1
        if 'dir' in wiring:
            pwm = PWM(Pin(wiring['pwm'], Pin.OUT), freq=freq_hz, duty_u16=0)
            return (pwm, Pin(wiring['dir'], Pin.OUT, value=0), [0], sign)
        if 'pwm' in wiring:
            pwm = PWM(Pin(wiring['pwm'], Pin.OUT), freq=freq_hz, duty_u16=0)
            return (pwm, Pin(wiring['in1'], Pin.OUT, value=0),
                    Pin(wiring['in2'], Pin.OUT, value=0), sign)
        return (PWM(Pin(wiring['in1'], Pin.OUT), freq=freq_hz, duty_u16=0),
                PWM(Pin(wiring['in2'], Pin.OUT), freq=freq_hz, duty_u16=0), None, sign)

    # --- board_core's hardware interface ----------------------------------------------
    def set_duties(self, duties):
        """Drive the motors: raw duties FL, FR, RL, RR (-10000 .. 10000)."""
        for motor, duty in zip(self._motors, duties):
            first, second, third, sign = motor
            if type(third) is list:   # PWM_DIR: never the old PWM the new way round
                level, direction = h_bridge.pwm_dir_outputs(duty * sign)
                if direction != third[0]:
                    first.duty_u16(0)
                    second.value(direction)
                    third[0] = direction
                first.duty_u16(level)
            elif third is None:   # DRV8833: two PWM inputs
                level_1, level_2 = h_bridge.two_pwm_outputs(duty * sign, self._brake)
                first.duty_u16(level_1)
                second.duty_u16(level_2)
            else:
                # Every pin write leaves the motor braking, coasting or driven the new
                # way at no more than the old or new level: braking sets the pins first
                # (from driving, one write brakes) and the PWM last; driving lowers the
                # PWM first. (Braking PWM-first, then IN1, then IN2 drove a stopped
                # motor at full PWM between the two pin writes.)
                level, in1, in2 = h_bridge.direction_pins_outputs(duty * sign, self._brake)
                if in1 and in2:
                    second.value(1)
                    third.value(1)
                    first.duty_u16(level)
                else:
                    if level < first.duty_u16():
                        first.duty_u16(level)
                    second.value(in1)
                    third.value(in2)
                    first.duty_u16(level)

    def read_counts(self):
        """Return the four encoder counts (forward positive), FL FR RL RR."""
        return [encoder.value() * sign for encoder, sign in self._encoders]

    def read_imu(self):
        """Return (ax, ay, az, gx, gy, gz) or None when the IMU fails (retried)."""
        if self._imu is None:
            return None
        return self._imu.read()

    def battery_mv(self):
        """Return the battery voltage in mV (0: not measured)."""
        if self._battery is None:
            return 0
        return int(self._battery.read_uv() * self._divider / 1000)

    def estop_active(self):
        """Tell whether the e-stop input is active (low)."""
        return self._estop is not None and self._estop.value() == 0

    def driver_fault(self):
        """Tell whether the motor driver reports a fault (low)."""
        return self._fault is not None and self._fault.value() == 0

    def read(self):
        """Return the bytes the host sent (b'' if none), without waiting."""
        if self._uart is not None:
            return self._uart.read() or b''
        data = b''
        while len(data) < 64 and self._poll.poll(0):
            data += self._stdin.read(1)
        return data

    def write(self, data):
        """Send bytes to the host."""
        if self._uart is not None:
            self._uart.write(data)
        else:
            self._stdout.write(data)

    # --- for main.py ----------------------------------------------------------------------
    def idle(self, wait_us):
        """
        Feed the watchdog, then wait up to wait_us for host bytes.

        Returns as soon as input is there (checked every WAIT_SLICE_US) or wait_us has
        passed; never blocks in poll, whose timeout the ESP32 rounds to whole ticks.
        """
        self._watchdog.feed()
        if wait_us <= 0:
            return
        start = self.ticks_us()
        poll = self._poll
        while not poll.poll(0):
            left = wait_us - self.ticks_diff(self.ticks_us(), start)
            if left <= 0:
                return
            self.sleep_us(WAIT_SLICE_US if left > WAIT_SLICE_US else left)
