"""
Firmware test cases, run unchanged by CPython and by MicroPython (test_firmware.py).

Each ``case_*`` function builds the firmware's core (mecanum_control/board_core.py) on
the simulated hardware of sim_hardware.py, plays the host with esp32_wire, and raises
AssertionError on a failure. ``PARAMS`` is set by the caller to the firmware
parameters of the robot config (mecanum_control.board_params). Times: microseconds
(``_us``) of the simulated clock; duties raw (10000 = full PWM); wheels FL, FR, RL, RR.
"""

from mecanum_control import board_core
from mecanum_control import esp32_wire as wire
from sim_hardware import run, SimHardware

PARAMS = None
TIMEOUT_MS = 150


class Host:
    """The host's end: encodes commands, decodes what the board sent."""

    def __init__(self, hw):
        self.hw = hw
        self.seq = 0
        self.decoder = wire.FrameDecoder()
        self.frames = []

    def efforts(self, duties, timeout_ms=TIMEOUT_MS):
        """Send MOTOR_EFFORTS."""
        self.seq += 1
        self.hw.rx += wire.encode_frame(wire.MOTOR_EFFORTS, self.seq,
                                        tuple(duties) + (timeout_ms,))

    def clear(self, bits):
        """Send CLEAR_FAULTS."""
        self.seq += 1
        self.hw.rx += wire.encode_frame(wire.CLEAR_FAULTS, self.seq, (bits,))

    def take(self):
        """Decode what the board sent since the last call; return those frames."""
        new = self.decoder.feed(bytes(self.hw.tx))
        self.hw.tx = bytearray()
        self.frames += new
        return new

    def last(self, msg_type):
        """Return the fields of the latest frame of a type received so far."""
        for frame in reversed(self.frames):
            if frame[0] == msg_type:
                return frame[2]
        raise AssertionError('no frame of type 0x%02x' % msg_type)


def make(**kwargs):
    """Return (hw, core, host): a booted board with nobody commanding it yet."""
    hw = SimHardware(**kwargs)
    core = board_core.BoardCore(hw, PARAMS)
    return hw, core, Host(hw)


def drive(core, hw, host, duties, us, period_us=20000):
    """Command duties every period_us (the host's 50 Hz) for us microseconds."""
    elapsed = 0
    while elapsed < us:
        host.efforts(duties)
        run(core, hw, period_us)
        elapsed += period_us


def count(frames, msg_type):
    """Return how many frames of a type are in a list."""
    return len([frame for frame in frames if frame[0] == msg_type])


# ------------------------------------------------------------------------------ cases


def case_boot_keeps_motors_off_and_reports_command_timeout():
    """At boot the motors are off and COMMAND_TIMEOUT is set, before any command."""
    hw, core, host = make()
    assert hw.duties == [0, 0, 0, 0] and hw.set_duties_calls == 1
    run(core, hw, 300000)
    host.take()
    status = host.last(wire.BOARD_STATUS)
    assert status[1] == wire.COMMAND_TIMEOUT, status
    assert status[4] == 0   # last_command_seq before any command
    assert hw.duties == [0, 0, 0, 0]
    assert host.last(wire.ENCODER_TICKS)[1:] == (0, 0, 0, 0)


def case_efforts_are_applied_and_acknowledged():
    """MOTOR_EFFORTS reach the motors; BOARD_STATUS carries their sequence number."""
    hw, core, host = make()
    host.efforts((5000, -2500, 10000, 0))
    run(core, hw, 1000)
    assert hw.duties == [5000, -2500, 10000, 0], hw.duties
    run(core, hw, 120000)
    host.take()
    status = host.last(wire.BOARD_STATUS)
    assert status[1] == 0 and status[4] == host.seq, status
    ticks = host.last(wire.ENCODER_TICKS)[1:]
    assert ticks[0] > 0 and ticks[1] < 0 and ticks[2] > ticks[0] and ticks[3] == 0, ticks


def case_watchdog_stops_the_motors_after_the_command_timeout():
    """No command for command_timeout_ms: duties zero, COMMAND_TIMEOUT; a command resumes."""
    hw, core, host = make()
    host.efforts((3000, 3000, 3000, 3000))
    run(core, hw, 1000)                    # taken at t = 1 ms
    run(core, hw, TIMEOUT_MS * 1000)       # exactly the timeout since: still driving
    assert hw.duties == [3000] * 4 and not core.faults & wire.COMMAND_TIMEOUT
    run(core, hw, 1000)                    # 1 ms past it
    assert hw.duties == [0] * 4, hw.duties
    assert core.faults & wire.COMMAND_TIMEOUT
    host.efforts((-2000, 0, 0, 0))
    run(core, hw, 1000)
    assert hw.duties == [-2000, 0, 0, 0] and not core.faults & wire.COMMAND_TIMEOUT


def case_reports_at_the_protocol_rates():
    """In 1 s: 50 ENCODER_TICKS, 100 IMU_SAMPLE, 10 BOARD_STATUS, numbered from 0."""
    hw, core, host = make()
    run(core, hw, 1000)
    host.take()   # the boot reports
    run(core, hw, 1000000)
    frames = host.take()
    assert count(frames, wire.ENCODER_TICKS) == 50, count(frames, wire.ENCODER_TICKS)
    assert count(frames, wire.IMU_SAMPLE) == 100
    assert count(frames, wire.BOARD_STATUS) == 10
    seqs = [frame[1] for frame in frames if frame[0] == wire.IMU_SAMPLE]
    assert seqs == list(range(1, 101)), seqs[:5]
    times = [frame[2][0] for frame in frames if frame[0] == wire.ENCODER_TICKS]
    steps = [b - a for a, b in zip(times, times[1:])]
    assert min(steps) == max(steps) == 20000, steps


def case_stalled_wheel_stops_every_motor_until_clear_faults():
    """FL blocked at high duty: ENCODER_FAULT after stall_time_ms, all motors off, latched."""
    hw, core, host = make()
    hw.blocked[0] = True
    drive(core, hw, host, (8000, 8000, 8000, 8000), PARAMS['stall_time_ms'] * 1000 - 100000)
    assert not core.faults & wire.ENCODER_FAULT and hw.duties == [8000] * 4
    drive(core, hw, host, (8000, 8000, 8000, 8000), 200000)
    assert core.faults & wire.ENCODER_FAULT
    assert core.encoder_fault_wheels == 1   # FL
    assert hw.duties == [0, 0, 0, 0]
    drive(core, hw, host, (8000, 8000, 8000, 8000), 500000)   # commands do not clear it
    assert hw.duties == [0, 0, 0, 0]
    host.take()
    assert host.last(wire.BOARD_STATUS)[1] & wire.ENCODER_FAULT
    hw.blocked[0] = False
    host.clear(0xFFFF)
    drive(core, hw, host, (8000, 8000, 8000, 8000), 40000)
    assert not core.faults & wire.ENCODER_FAULT and hw.duties == [8000] * 4


def case_runaway_wheel_turning_against_its_duty_trips_the_fault():
    """Trip ENCODER_FAULT when FR's reversed encoder counts against the duty."""
    hw, core, host = make()
    hw.reversed[1] = True
    drive(core, hw, host, (3000, 3000, 3000, 3000), PARAMS['runaway_time_ms'] * 1000 + 100000)
    assert core.faults & wire.ENCODER_FAULT
    assert core.encoder_fault_wheels == 2   # FR
    assert hw.duties == [0, 0, 0, 0]


def case_wheel_turning_fast_without_duty_trips_the_fault():
    """Trip ENCODER_FAULT on a wheel counting fast with no duty (encoders swapped)."""
    hw, core, host = make()
    hw.drift_counts_s[3] = PARAMS['free_speed_counts_s'] * 2
    drive(core, hw, host, (0, 0, 0, 0), PARAMS['free_time_ms'] * 1000 + 100000)
    assert core.encoder_fault_wheels == 8, core.encoder_fault_wheels   # RR
    assert core.faults & wire.ENCODER_FAULT


def case_normal_driving_trips_no_encoder_fault():
    """Accelerating, reversing and stopping healthy wheels never trips ENCODER_FAULT."""
    hw, core, host = make()
    for duties in ((10000, 10000, 10000, 10000), (-10000, 10000, -10000, 10000),
                   (0, 0, 0, 0), (2500, -2500, 2500, -2500)):
        drive(core, hw, host, duties, 1500000)
    run(core, hw, 2000000)   # commands stop: watchdog, then coasting at zero
    assert not core.faults & wire.ENCODER_FAULT, core.faults


def case_garbage_on_the_line_is_counted_and_costs_no_command():
    """Noise, an oversized run, another version and bad efforts: dropped, counted, RX_ERRORS."""
    hw, core, host = make()
    run(core, hw, 100000)
    host.take()
    hw.rx += b'\x13\x37\xff\x00'                     # noise, then a delimiter
    hw.rx += b'\x01' * 200 + b'\x00'                 # oversized
    spoilt = bytearray(wire.encode_frame(wire.CLEAR_FAULTS, 1, (0,)))
    spoilt[-2] ^= 0x02 if spoilt[-2] == 0x01 else 0x01   # a flipped CRC bit (never 0x00)
    hw.rx += spoilt
    hw.rx += wire.encode_frame(wire.MOTOR_EFFORTS, 9, (10001, 0, 0, 0, 100))   # beyond full
    run(core, hw, 1000)
    assert core.decoder.stats.frames_ok == 0
    assert wire.dropped_frames(core.decoder.stats) == 4, wire.dropped_frames(core.decoder.stats)
    assert hw.duties == [0, 0, 0, 0]
    host.efforts((1000, 1000, 1000, 1000))
    run(core, hw, 100000)
    assert hw.duties == [1000] * 4
    host.take()
    statuses = [frame[2] for frame in host.frames if frame[0] == wire.BOARD_STATUS]
    assert statuses[-1][3] == 4                       # rx_bad_frames
    flagged = [status for status in statuses if status[1] & wire.RX_ERRORS]
    assert len(flagged) == 1, statuses               # once, in the next status only


def case_host_that_goes_away_and_comes_back():
    """Time out when the host stops mid-frame; after its 0x00 it drives again."""
    hw, core, host = make()
    drive(core, hw, host, (4000, 4000, 4000, 4000), 200000)
    half = wire.encode_frame(wire.MOTOR_EFFORTS, 99, (9000, 9000, 9000, 9000, 150))
    hw.rx += half[:7]                                 # the cable is pulled mid-frame
    run(core, hw, 2000000)
    assert hw.duties == [0, 0, 0, 0] and core.faults & wire.COMMAND_TIMEOUT
    hw.rx += b'\x00'                                  # the host reopens: 0x00 first
    drive(core, hw, host, (-4000, -4000, -4000, -4000), 100000)
    assert hw.duties == [-4000] * 4 and not core.faults & wire.COMMAND_TIMEOUT
    assert core.decoder.stats.bad_cobs + core.decoder.stats.bad_crc + \
        core.decoder.stats.bad_length == 1


def case_imu_failure_sets_imu_fault_and_stops_samples():
    """Set IMU_FAULT and send no IMU_SAMPLE while the IMU fails; clear it when back."""
    hw, core, host = make()
    hw.imu_ok = False
    run(core, hw, 200000)
    frames = host.take()
    assert count(frames, wire.IMU_SAMPLE) == 0
    assert host.last(wire.BOARD_STATUS)[1] & wire.IMU_FAULT
    hw.imu_ok = True
    host.clear(wire.IMU_FAULT)
    run(core, hw, 200000)
    frames = host.take()
    assert count(frames, wire.IMU_SAMPLE) == 20
    assert not host.last(wire.BOARD_STATUS)[1] & wire.IMU_FAULT
    sample = host.last(wire.IMU_SAMPLE)
    assert sample[1:3] == (0.0, 0.0) and abs(sample[3] - 9.80665) < 1e-5, sample


def case_estop_and_driver_fault_keep_the_motors_off():
    """ESTOP_INPUT and MOTOR_DRIVER_FAULT latch until cleared with their cause gone."""
    hw, core, host = make()
    hw.estop = True
    drive(core, hw, host, (5000, 5000, 5000, 5000), 100000)
    assert hw.duties == [0] * 4 and core.faults & wire.ESTOP_INPUT
    hw.estop = False
    host.clear(wire.ESTOP_INPUT)
    drive(core, hw, host, (5000, 5000, 5000, 5000), 40000)
    assert hw.duties == [5000] * 4 and not core.faults & wire.ESTOP_INPUT
    hw.fault = True
    drive(core, hw, host, (5000, 5000, 5000, 5000), 40000)
    assert hw.duties == [0] * 4 and core.faults & wire.MOTOR_DRIVER_FAULT
    host.clear(wire.MOTOR_DRIVER_FAULT)               # the cause is still there
    drive(core, hw, host, (5000, 5000, 5000, 5000), 40000)
    assert core.faults & wire.MOTOR_DRIVER_FAULT
    hw.fault = False
    drive(core, hw, host, (5000, 5000, 5000, 5000), 40000)
    assert core.faults & wire.MOTOR_DRIVER_FAULT      # latched
    host.clear(wire.MOTOR_DRIVER_FAULT | wire.COMMAND_TIMEOUT | wire.ESTOP_INPUT)
    drive(core, hw, host, (5000, 5000, 5000, 5000), 40000)
    assert hw.duties == [5000] * 4 and core.faults == 0, core.faults


def case_estop_stays_latched_until_the_host_clears_it():
    """Keep the motors off after the e-stop is released; a clear resumes no old command."""
    hw, core, host = make()
    drive(core, hw, host, (6000, 6000, 6000, 6000), 100000)
    assert hw.duties == [6000] * 4
    hw.estop = True
    run(core, hw, 20000)
    assert hw.duties == [0] * 4 and core.faults & wire.ESTOP_INPUT
    hw.estop = False                                  # released: still latched
    drive(core, hw, host, (6000, 6000, 6000, 6000), 200000)
    assert hw.duties == [0] * 4 and core.faults & wire.ESTOP_INPUT
    hw.estop = True                                   # a clear while pressed: ignored
    host.clear(0xFFFF)
    run(core, hw, 20000)
    assert core.faults & wire.ESTOP_INPUT
    hw.estop = False
    host.efforts((6000, 6000, 6000, 6000))            # the last command before the clear
    run(core, hw, 10000)
    host.clear(0xFFFF)                                # within its command timeout
    run(core, hw, 10000)
    assert not core.faults & wire.ESTOP_INPUT
    assert hw.duties == [0] * 4, hw.duties            # not resumed: a new command needed
    host.efforts((-3000, -3000, -3000, -3000))
    run(core, hw, 10000)
    assert hw.duties == [-3000] * 4
    hw.estop = True                                   # again, and this time the last
    run(core, hw, 10000)                              # command and the clear arrive
    hw.estop = False                                  # in one read
    host.efforts((7000, 7000, 7000, 7000))
    host.clear(0xFFFF)
    run(core, hw, 1000)
    assert not core.faults & wire.ESTOP_INPUT and hw.duties == [0] * 4, hw.duties


def case_unplugged_encoder_trips_at_low_duty():
    """Trip ENCODER_FAULT on RL's silent counter at duty 0.2 after the weighted time."""
    hw, core, host = make()
    hw.unplugged[2] = True
    # dead_full_duty_ms of duty-weighted time at 0.2 duty: 500 ms / 0.2 = 2.5 s.
    trip_us = PARAMS['dead_full_duty_ms'] * 1000 * 10000 // 2000
    assert trip_us == 2500000, trip_us
    drive(core, hw, host, (2000, 2000, 2000, 2000), trip_us - 100000)
    assert not core.faults & wire.ENCODER_FAULT and hw.duties == [2000] * 4
    drive(core, hw, host, (2000, 2000, 2000, 2000), 200000)
    assert core.faults & wire.ENCODER_FAULT and core.encoder_fault_wheels == 4   # RL
    assert hw.duties == [0] * 4


def case_slow_healthy_wheels_trip_no_encoder_fault():
    """Healthy wheels held at low duties (0.1, 0.15) for 6 s never trip ENCODER_FAULT."""
    hw, core, host = make()
    drive(core, hw, host, (1000, -1000, 1500, -1500), 6000000)
    assert not core.faults & wire.ENCODER_FAULT, core.faults


def case_counters_and_clocks_wrap():
    """Drive on across counts wrapping at 2^31 and tick clocks wrapping at 2^30."""
    hw, core, host = make(start_us=(1 << 30) - 300000, start_counts=(1 << 31) - 500)
    drive(core, hw, host, (10000, 10000, 10000, 10000), 600000)
    assert not core.faults, core.faults
    host.take()
    ticks = host.last(wire.ENCODER_TICKS)[1:]
    assert all(tick < 0 for tick in ticks), ticks     # wrapped into negative int32
    run(core, hw, 200000)                             # the watchdog across the wrap
    assert hw.duties == [0] * 4 and core.faults & wire.COMMAND_TIMEOUT


def case_h_bridge_outputs():
    """h_bridge: direction pins and PWM levels for each sign, brake and coast."""
    import h_bridge
    assert h_bridge.direction_pins_outputs(5000, True) == (32767, 1, 0)
    assert h_bridge.direction_pins_outputs(-10000, True) == (65535, 0, 1)
    assert h_bridge.direction_pins_outputs(0, True) == (65535, 1, 1)
    assert h_bridge.direction_pins_outputs(0, False) == (0, 0, 0)
    assert h_bridge.two_pwm_outputs(2500, True) == (16383, 0)
    assert h_bridge.two_pwm_outputs(-2500, False) == (0, 16383)
    assert h_bridge.two_pwm_outputs(0, True) == (65535, 65535)
    assert h_bridge.pwm_dir_outputs(5000) == (32767, 1)
    assert h_bridge.pwm_dir_outputs(-2500) == (16383, 0)
    assert h_bridge.pwm_dir_outputs(0) == (0, 0)


class FakeI2c:
    """An MPU-6050 on a bus: remembers register writes, answers reads from a buffer."""

    def __init__(self, data, who_am_i=0x68):
        self.data = data
        self.who_am_i = who_am_i
        self.writes = []
        self.fail = False
        self.transfers = 0      # every bus access (each could cost an I2C timeout)

    def writeto_mem(self, address, register, data):
        """Record a register write."""
        self.transfers += 1
        if self.fail:
            raise OSError(19)
        self.writes.append((address, register, bytes(data)))

    def readfrom_mem(self, address, register, nbytes):
        """Answer WHO_AM_I (0x75), or fail like an absent chip."""
        self.transfers += 1
        if self.fail:
            raise OSError(19)
        assert register == 0x75 and nbytes == 1, (register, nbytes)
        return bytes((self.who_am_i,))

    def readfrom_mem_into(self, address, register, buffer):
        """Fill buffer from the sample, or fail like an absent chip."""
        self.transfers += 1
        if self.fail:
            raise OSError(19)
        buffer[:] = self.data


def case_mpu6050_scales_to_si_units():
    """MPU-6050: +-4 g and +-500 deg/s raw values to m/s^2 and rad/s; OSError passes."""
    import struct
    import imu_drivers
    raw = struct.pack('>7h', 8192, -4096, 8192, 0, 655, 0, -6550)
    bus = FakeI2c(raw)
    imu = imu_drivers.DRIVERS['MPU6050'](bus, 0x68)
    assert (0x68, 0x6B, b'\x01') in bus.writes
    ax, ay, az, gx, gy, gz = imu.read()
    assert abs(ax - 9.80665) < 1e-6 and abs(ay + 4.903325) < 1e-6 and abs(az - 9.80665) < 1e-6
    assert abs(gx - 0.17453292519943295) < 1e-9 and gy == 0 and abs(gz + 1.7453292519943295) < 1e-9
    bus.fail = True
    try:
        imu.read()
    except OSError:
        pass
    else:
        raise AssertionError('a failing bus must raise OSError')


class FakeClock:
    """MicroPython's ticks_ms, ticks_diff, ticks_add on a clock the test moves."""

    def __init__(self):
        self.ms = 0

    def ticks_ms(self):
        """Return the clock, ms."""
        return self.ms

    @staticmethod
    def ticks_diff(new, old):
        """Return new - old."""
        return new - old

    @staticmethod
    def ticks_add(ticks, delta):
        """Return ticks + delta."""
        return ticks + delta


def case_imu_absent_at_boot_is_retried_every_retry_ms():
    """Take in an IMU absent at boot at the next retry; between retries the bus rests."""
    import imu_drivers
    bus = FakeI2c(bytes(14))
    bus.fail = True
    clock = FakeClock()
    imu = imu_drivers.RetryingImu(lambda: imu_drivers.Mpu6050(bus, 0x68), clock, 1000)
    assert imu.read() is None and imu.attempts == 1
    used = bus.transfers
    clock.ms = 999
    assert imu.read() is None and bus.transfers == used   # no bus access before the retry
    bus.fail = False                                     # plugged in
    clock.ms = 1000
    assert imu.read() == (0.0, 0.0, 0.0, 0.0, 0.0, 0.0) and imu.attempts == 2


def case_imu_failing_later_costs_one_timeout_per_retry():
    """Cost a bus stuck mid-run one failed read per retry, then read again once it is back."""
    import imu_drivers
    bus = FakeI2c(bytes(14))
    clock = FakeClock()
    imu = imu_drivers.RetryingImu(lambda: imu_drivers.Mpu6050(bus, 0x68), clock, 1000)
    assert imu.read() is not None
    bus.fail = True
    clock.ms = 5000
    assert imu.read() is None
    used = bus.transfers
    for ms in range(5010, 6000, 10):                     # 99 reports' reads at 100 Hz
        clock.ms = ms
        assert imu.read() is None
    assert bus.transfers == used, bus.transfers - used
    bus.fail = False
    clock.ms = 6000
    assert imu.read() is not None and imu.attempts == 2


def case_imu_of_another_kind_is_refused_by_who_am_i():
    """WHO_AM_I 0x12 at the MPU-6050's address: no samples, the reason kept."""
    import imu_drivers
    bus = FakeI2c(bytes(14), who_am_i=0x12)
    imu = imu_drivers.RetryingImu(lambda: imu_drivers.Mpu6050(bus, 0x68), FakeClock(), 1000)
    assert imu.read() is None
    assert 'WHO_AM_I 0x12' in imu.last_error, imu.last_error
    assert bus.writes == []                              # never configured
    for who in (0x68, 0x70, 0x71, 0x73):
        imu_drivers.Mpu6050(FakeI2c(bytes(14), who_am_i=who), 0x68)


class Config:
    """A copy of board_config's settings that a case may change."""

    def __init__(self, **changes):
        import board_config
        for name in dir(board_config):
            if name.isupper():
                setattr(self, name, getattr(board_config, name))
        for name in changes:
            setattr(self, name, changes[name])


def case_pin_map_of_board_config_is_sound():
    """Find no clash in the shipped map; refuse 'uart' without pins, naming the free ones."""
    import pin_map
    assert pin_map.problems(Config()) == []
    assert pin_map.free_pins(Config()) == [37, 38]       # input only: no UART TX there
    found = pin_map.problems(Config(SERIAL='uart'))
    assert found == ["SERIAL = 'uart' needs UART_TX and UART_RX; pins free in this map: "
                     '37, 38'], found
    # IMU = None frees the I2C pins: a UART there clashes with nothing.
    assert pin_map.problems(Config(SERIAL='uart', IMU=None, UART_TX=21, UART_RX=22)) == []


def case_pin_map_names_every_clash():
    """UART on a motor's pins, outputs on input-only and flash pins, unknown GPIOs."""
    import pin_map
    found = pin_map.problems(Config(SERIAL='uart', UART_TX=17, UART_RX=16))
    assert found == ['GPIO 16 is used twice: MOTORS[2] (RL) in1 and UART_RX',
                     'GPIO 17 is used twice: MOTORS[2] (RL) in2 and UART_TX'], found
    motors = list(Config().MOTORS)
    motors[0] = {'pwm': 34, 'in1': 6, 'in2': 24, 'invert': False}
    found = pin_map.problems(Config(MOTORS=motors, ESTOP_PIN=12))
    assert found == ['GPIO 34 (MOTORS[0] (FL) pwm): input only, cannot drive an output',
                     'GPIO 6 (MOTORS[0] (FL) in1): reserved, SPI flash',
                     'GPIO 24 (MOTORS[0] (FL) in2): the ESP32 has no such GPIO',
                     'GPIO 12 (ESTOP_PIN): strapping pin MTDI: high at reset selects '
                     '1.8 V flash',
                     'GPIO 34 is used twice: MOTORS[0] (FL) pwm and ENCODERS[0] (FL) a'], found
    try:
        pin_map.check(Config(SERIAL='uart', UART_TX=17, UART_RX=16))
    except ValueError as error:
        assert 'GPIO 17 is used twice' in str(error), error
    else:
        raise AssertionError('check must refuse a clashing map')


def case_pin_map_wants_the_drivers_pins():
    """Check each motor's pins against the driver: PWM_DIR wants pwm and dir."""
    import pin_map
    motors = ({'pwm': 25, 'dir': 26, 'invert': False}, {'pwm': 32, 'dir': 33, 'invert': True},
              {'pwm': 4, 'dir': 16, 'invert': False}, {'pwm': 18, 'dir': 19, 'invert': True})
    assert pin_map.problems(Config(DRIVER='PWM_DIR', MOTORS=motors)) == []
    found = pin_map.problems(Config(DRIVER='PWM_DIR'))
    assert found[0] == 'MOTORS[0] (FL): PWM_DIR wants the pins pwm, dir', found
    assert len(found) == 4, found


def case_names():
    """Return the names of every case in this module."""
    return sorted(name for name in globals() if name.startswith('case_') and name != 'case_names')
