"""
The board's wiring: motor driver type and pin map, encoders, IMU, serial port (edit me).

GPIO numbers are the ESP32's. The example is an ESP32 DevKit (ESP32-WROOM-32) with a
TB6612FNG driving the two left motors and another the two right ones, four hall
encoders (11 lines, read in 4x quadrature by the pulse counter) and an MPU-6050 on
I2C. GPIO 6-11 are the flash's, 1 and 3 the USB serial port's; 34-39 are inputs only
(fine for encoders, with external pull-ups); 0, 2, 5, 12 and 15 are strapping pins:
never 12 (high at reset selects 1.8 V flash), and the others only as encoder inputs
(if esptool cannot enter the bootloader, unplug the encoder on GPIO 2 while flashing).
Robot parameters (command timeout, counts per revolution, fault thresholds) are not
here: they come from the robot config (board_params.py, written by the flash script).
"""

#: Motor driver: 'TB6612', 'L298N', 'DRV8833' or 'PWM_DIR' (Cytron MDD10A; h_bridge.py).
DRIVER = 'TB6612'
#: PWM frequency, Hz (20 kHz: inaudible; L298N wants about 1 kHz).
PWM_FREQ_HZ = 20000
#: Zero duty brakes the motor (True) or lets it coast (False).
BRAKE_AT_ZERO = True
#: TB6612's STBY pin (held high while running), or None (STBY tied to 3.3 V).
STANDBY_PIN = None

#: Per wheel, order FL, FR, RL, RR: the driver pins and whether the motor turns
#: backward for a positive duty as wired (the right side usually does).
#: TB6612 / L298N: 'pwm', 'in1', 'in2'. DRV8833: 'in1', 'in2' (both PWM).
#: PWM_DIR: 'pwm', 'dir'.
MOTORS = (
    {'pwm': 25, 'in1': 26, 'in2': 27, 'invert': False},   # FL
    {'pwm': 32, 'in1': 33, 'in2': 14, 'invert': True},    # FR
    {'pwm': 4, 'in1': 16, 'in2': 17, 'invert': False},    # RL
    {'pwm': 18, 'in1': 19, 'in2': 23, 'invert': True},    # RR
)

#: Per wheel, order FL, FR, RL, RR: the encoder's A and B pins and whether it counts
#: down when the wheel rolls the robot forward as wired. Each uses one pulse counter
#: unit (machine.Encoder id 0..3; the ESP32 has 8, the S2/S3 4, the C3 none).
ENCODERS = (
    {'a': 34, 'b': 35, 'invert': False},   # FL
    {'a': 36, 'b': 39, 'invert': True},    # FR
    {'a': 13, 'b': 5, 'invert': False},    # RL
    {'a': 15, 'b': 2, 'invert': True},     # RR
)
#: Internal pull-ups on the encoder inputs (GPIO 34-39 have none: use 10 kohm to 3.3 V).
#: On the ESP32 the pulse counter driver (esp32.PCNT, under machine.Encoder) turns the
#: pull-ups on by itself, so False changes nothing there: open-collector encoders are
#: always pulled up on GPIOs that have pull-ups.
ENCODER_PULL_UP = True
#: Glitch filter of the pulse counter, ns (0: off).
ENCODER_FILTER_NS = 1000

#: IMU: a name of imu_drivers.DRIVERS, or None for no IMU; its I2C bus and address.
#: A read that times out (I2C_TIMEOUT_US) or an IMU absent or unidentified (WHO_AM_I)
#: is retried every IMU_RETRY_MS, so a stuck bus costs one timeout a retry, not a read.
IMU = 'MPU6050'
I2C_ID = 0
I2C_SCL = 22
I2C_SDA = 21
I2C_FREQ_HZ = 400000
I2C_TIMEOUT_US = 5000
IMU_ADDRESS = 0x68
IMU_RETRY_MS = 1000

#: Battery voltage: an ADC pin behind a divider (None: not measured), and the divider's
#: ratio (battery volts per ADC volt).
BATTERY_ADC_PIN = None
BATTERY_DIVIDER = 11.0
#: A hardware e-stop input, active low (None: none); a driver fault output, active low
#: (DRV8833 nFAULT; None: none).
ESTOP_PIN = None
DRIVER_FAULT_PIN = None

#: Serial link to the host: 'stdio' (the USB port of a DevKit: UART0 through its USB
#: bridge, the REPL's port) or 'uart' (another UART, e.g. to a Raspberry Pi's pins).
#: The wiring above takes every output-capable GPIO but the forbidden 12, so UART_TX and
#: UART_RX are None: for 'uart', free two pins (e.g. IMU = None frees 21 and 22) and
#: name them here. pin_map.py refuses any map where a pin has two jobs (a UART on a
#: motor's direction pin would drive that motor) and says which pins are free.
SERIAL = 'stdio'
UART_ID = 2
UART_BAUD = 115200
UART_TX = None
UART_RX = None

#: Hold this pin low (the BOOT button, GPIO 0) during the first REPL_WINDOW_MS after a
#: reset and main.py leaves the board at the REPL instead of taking the serial port.
REPL_PIN = 0
REPL_WINDOW_MS = 2000
#: Hardware watchdog: a loop stuck this long resets the board (motors off at boot).
WATCHDOG_MS = 2000
