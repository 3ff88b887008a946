"""
The ESP32 motor board's firmware logic, on any hardware layer (MicroPython and CPython).

One file, run unchanged by MicroPython on the board (``firmware/main.py`` gives it
the ESP32 hardware layer, ``firmware/hardware_esp32.py``) and by CPython in the board
emulator and the simulator (a simulated hardware layer, ``board_sim``). It keeps to
the subset both run (no dataclasses, enum, typing or f-strings) and touches no
hardware: everything goes through the hardware layer ``hw``, which provides

* ``ticks_us()``, ``ticks_diff(new, old)``, ``ticks_add(ticks, delta)``: a wrapping
  microsecond clock, as MicroPython's ``time`` module has;
* ``read()``: the bytes the host sent since the last call (``b''`` or None: none);
  ``write(data)``: send bytes to the host (the line may lose them);
* ``set_duties(duties)``: apply four duties FL, FR, RL, RR, ints in -10000 .. 10000
  (positive rolls the robot forward; the layer inverts motors as wired);
* ``read_counts()``: four quadrature counters FL, FR, RL, RR (ints, consistent
  modulo 2^32; positive when rolling forward);
* ``read_imu()``: (ax, ay, az in m/s^2, gx, gy, gz in rad/s), or None if the IMU failed;
* ``battery_mv()`` (0: not measured), ``estop_active()``, ``driver_fault()`` and the
  attribute ``brownout_reset`` (the last restart was a brownout).

:class:`BoardCore` speaks protocol version 1 (``doc/esp32_protocol.md``): it applies
MOTOR_EFFORTS under the command watchdog, honours CLEAR_FAULTS, sends ENCODER_TICKS
(50 Hz), IMU_SAMPLE (100 Hz) and BOARD_STATUS (10 Hz), and keeps the motors off at
boot, when commands stop for their ``command_timeout_ms``, on ESTOP_INPUT (latched:
the e-stop drops the host's last command, and only CLEAR_FAULTS once the input is
released ends it; the motors then wait for a new command), MOTOR_DRIVER_FAULT, and on
ENCODER_FAULT: a wheel driven hard that does not turn (stalled), one driven at any
duty that should move it whose counter does not count at all (encoder unplugged), one
that turns against its duty, or fast without one (a runaway: encoder or motor wired
reversed, encoders swapped). Garbage
on the line, a host that goes away and one that comes back cost nothing but the
frames they spoil: the decoder resynchronises at the next 0x00.
"""

from mecanum_control import esp32_wire as wire

#: Report periods (doc/esp32_protocol.md, 3), microseconds.
TICKS_PERIOD_US = 20000
IMU_PERIOD_US = 10000
STATUS_PERIOD_US = 100000

#: The firmware's parameters, every one required (``mecanum_control.board_params``
#: derives them from the robot config; the flash script writes them to the board as
#: ``board_params.py``). Duties are raw (10000 = full PWM), speeds in counts per second,
#: times in milliseconds:
#: stalled: |duty| >= stall_duty and |speed| < stall_speed_counts_s for stall_time_ms;
#: dead encoder: |duty| >= dead_duty and not one count, for a duty-weighted time
#: (sum of elapsed time x min(|duty|, stall_duty) / full duty) of dead_full_duty_ms:
#: with 500 ms and stall_duty 0.5, 1 s at duty 0.5 or more (as stalled), 5 s at 0.1;
#: runaway: |duty| >= runaway_duty and turning against it faster than
#: runaway_speed_counts_s for runaway_time_ms, or |duty| <= free_duty and
#: |speed| > free_speed_counts_s for free_time_ms; LOW_BATTERY below low_battery_mv
#: (0: never).
PARAM_NAMES = ('stall_duty', 'stall_speed_counts_s', 'stall_time_ms',
               'dead_duty', 'dead_full_duty_ms',
               'runaway_duty', 'runaway_speed_counts_s', 'runaway_time_ms',
               'free_duty', 'free_speed_counts_s', 'free_time_ms', 'low_battery_mv')

#: Faults that keep every motor off while set.
STOPPING_FAULTS = (wire.COMMAND_TIMEOUT | wire.ESTOP_INPUT | wire.MOTOR_DRIVER_FAULT
                   | wire.ENCODER_FAULT)
_ZERO = (0, 0, 0, 0)


def _wrap32(value):
    """Return the signed 32-bit difference of two counter readings."""
    return ((value + 0x80000000) & 0xFFFFFFFF) - 0x80000000


class BoardCore:
    """
    The firmware's main loop body: call :meth:`poll` as often as possible.

    State (read-only from outside): ``faults`` (fault bits), ``duties`` (applied,
    raw FL FR RL RR), ``commanded`` (the host's last efforts, raw),
    ``command_timeout_ms``, ``last_command_seq``, ``commands_received``,
    ``encoder_fault_wheels`` (bit i: wheel i tripped ENCODER_FAULT), ``counts``
    (the last counter sample) and ``decoder`` (its ``stats``).
    """

    def __init__(self, hw, params):
        missing = [name for name in PARAM_NAMES if name not in params]
        if missing:
            raise ValueError('board parameters missing: %s' % ', '.join(missing))
        self.hw = hw
        self.params = dict(params)
        self.decoder = wire.FrameDecoder()
        self.faults = wire.COMMAND_TIMEOUT
        if hw.brownout_reset:
            self.faults |= wire.BROWNOUT_RESET
        self.duties = list(_ZERO)
        self.commanded = list(_ZERO)
        self.command_timeout_ms = 0
        self.last_command_seq = 0
        self.commands_received = 0
        self.encoder_fault_wheels = 0
        self.battery_mv = 0
        self._commanded_at = 0
        self._live = False          # a command is in force (not timed out)
        self._tx_seq = {wire.ENCODER_TICKS: 0, wire.IMU_SAMPLE: 0, wire.BOARD_STATUS: 0}
        self._rx_bad_reported = 0
        self._out = []
        hw.set_duties(_ZERO)        # motors off at boot
        now = hw.ticks_us()
        self._clock_ticks = now
        self.board_time_us = 0
        self._due_ticks = now
        self._due_imu = now
        self._due_status = now
        self.counts = tuple(hw.read_counts())
        self._sample_at = now
        self._stall_us = [0, 0, 0, 0]
        self._against_us = [0, 0, 0, 0]
        self._free_us = [0, 0, 0, 0]
        self._dead_us = [0, 0, 0, 0]   # duty-weighted time without a count
        self._update_levels()

    # --- the loop --------------------------------------------------------------------
    def poll(self, report=True):
        """
        One loop iteration: take the host's frames, check safety, send what is due.

        With ``report`` False nothing is sent (a simulated board with nobody on its
        line); the watchdog and the encoder checks run all the same.
        """
        hw = self.hw
        now = hw.ticks_us()
        self.receive(now)
        diff = hw.ticks_diff
        if diff(now, self._due_ticks) >= 0:
            self._due_ticks = self._next_due(self._due_ticks, TICKS_PERIOD_US, now)
            self._sample_counts(now)
            if report:
                self._queue(wire.ENCODER_TICKS, (self._board_time(now),) + self.counts)
        if not report:
            self._due_imu = now     # the IMU is read only to be reported
        elif diff(now, self._due_imu) >= 0:
            self._due_imu = self._next_due(self._due_imu, IMU_PERIOD_US, now)
            sample = hw.read_imu()
            if sample is None:
                self.faults |= wire.IMU_FAULT
            else:
                self._queue(wire.IMU_SAMPLE, (self._board_time(now),) + tuple(sample))
        if diff(now, self._due_status) >= 0:
            self._due_status = self._next_due(self._due_status, STATUS_PERIOD_US, now)
            self._update_levels()
            if report:
                self._queue(wire.BOARD_STATUS, self._status_fields(now))
            else:
                self._board_time(now)   # keep the clock within ticks_diff's range
        self.enforce(now)
        if self._out:
            out, self._out = self._out, []
            hw.write(b''.join(out))   # reports due together go out in one write

    def receive(self, now=None):
        """Read the host's bytes and apply the frames they complete."""
        data = self.hw.read()
        if not data:
            return
        if now is None:
            now = self.hw.ticks_us()
        for msg_type, seq, fields in self.decoder.feed(data):
            if msg_type == wire.MOTOR_EFFORTS:
                self.command(fields[:4], fields[4], seq, now)
            elif msg_type == wire.CLEAR_FAULTS:
                self.clear_faults(fields[0])
        self.enforce(now)

    def idle_us(self):
        """Return how long the loop may wait for input before the next report is due."""
        hw = self.hw
        now = hw.ticks_us()
        wait = hw.ticks_diff(self._due_imu, now)
        for due in (self._due_ticks, self._due_status):
            wait = min(wait, hw.ticks_diff(due, now))
        return max(0, wait)

    # --- commands ----------------------------------------------------------------------
    def command(self, duties, command_timeout_ms, seq, now=None):
        """
        Apply MOTOR_EFFORTS: raw duties FL, FR, RL, RR (-10000 .. 10000), timeout, seq.

        The duties hold until ``command_timeout_ms`` passes without another command;
        they reach the motors unless a stopping fault is set.
        """
        if now is None:
            now = self.hw.ticks_us()
        if self.faults & wire.ESTOP_INPUT:
            self.commanded = list(_ZERO)   # latched e-stop: dropped, even in one batch
        else:                              # with the CLEAR_FAULTS that follows it
            self.commanded = [max(-wire.EFFORT_SCALE, min(wire.EFFORT_SCALE, int(d)))
                              for d in duties]
        self.command_timeout_ms = command_timeout_ms
        self.last_command_seq = seq
        self.commands_received += 1
        self._commanded_at = now
        self._live = True
        self.faults &= ~wire.COMMAND_TIMEOUT

    def clear_faults(self, bits):
        """CLEAR_FAULTS: clear these latched bits whose cause has gone; others are ignored."""
        bits &= wire.LATCHED_FAULTS
        if bits & wire.MOTOR_DRIVER_FAULT and self.hw.driver_fault():
            bits &= ~wire.MOTOR_DRIVER_FAULT
        if bits & wire.ENCODER_FAULT:
            self.encoder_fault_wheels = 0
            for index in range(4):
                self._stall_us[index] = self._against_us[index] = self._free_us[index] = 0
                self._dead_us[index] = 0
        if bits & wire.ESTOP_INPUT and self.hw.estop_active():
            bits &= ~wire.ESTOP_INPUT
        self.faults &= ~bits

    # --- safety --------------------------------------------------------------------------
    def enforce(self, now):
        """Zero the duties on a timed-out command or a stopping fault; apply changes."""
        hw = self.hw
        if self._live and hw.ticks_diff(now, self._commanded_at) > self.command_timeout_ms * 1000:
            self._live = False
            self.faults |= wire.COMMAND_TIMEOUT
        if hw.estop_active():
            self.faults |= wire.ESTOP_INPUT
        commanded = self.commanded
        if self.faults & wire.ESTOP_INPUT and (commanded[0] or commanded[1] or commanded[2]
                                               or commanded[3]):
            # Latched: commands in force or arriving meanwhile are dropped, so the
            # clear never resumes one; the host must command again after it.
            self.commanded = list(_ZERO)
        if hw.driver_fault():
            self.faults |= wire.MOTOR_DRIVER_FAULT
        wanted = _ZERO if self.faults & STOPPING_FAULTS else self.commanded
        duties = self.duties
        if (duties[0] != wanted[0] or duties[1] != wanted[1] or duties[2] != wanted[2]
                or duties[3] != wanted[3]):
            self.duties = list(wanted)
            hw.set_duties(self.duties)

    def _sample_counts(self, now):
        """Read the counters and check each wheel's counts against its duty."""
        counts = tuple(self.hw.read_counts())
        elapsed_us = self.hw.ticks_diff(now, self._sample_at)
        previous = self.counts
        self.counts = counts
        self._sample_at = now
        if elapsed_us <= 0:
            return
        params = self.params
        for index in range(4):
            duty = self.duties[index]
            moved = _wrap32(counts[index] - previous[index])
            speed = moved * 1000000 // elapsed_us if moved >= 0 else -(
                -moved * 1000000 // elapsed_us)
            magnitude = abs(duty)
            forward = speed if duty >= 0 else -speed
            tripped = self._judge(
                self._stall_us, index, elapsed_us, params['stall_time_ms'],
                magnitude >= params['stall_duty']
                and abs(speed) < params['stall_speed_counts_s'])
            tripped |= self._judge(
                self._against_us, index, elapsed_us, params['runaway_time_ms'],
                magnitude >= params['runaway_duty']
                and forward < -params['runaway_speed_counts_s'])
            if magnitude >= params['dead_duty'] and moved == 0:
                weight = min(magnitude, params['stall_duty'])   # never before stalled
                self._dead_us[index] += elapsed_us * weight // wire.EFFORT_SCALE
                tripped |= self._dead_us[index] >= params['dead_full_duty_ms'] * 1000
            else:
                self._dead_us[index] = 0
            tripped |= self._judge(
                self._free_us, index, elapsed_us, params['free_time_ms'],
                magnitude <= params['free_duty']
                and abs(speed) > params['free_speed_counts_s'])
            if tripped:
                self.faults |= wire.ENCODER_FAULT
                self.encoder_fault_wheels |= 1 << index

    @staticmethod
    def _judge(timers, index, elapsed_us, limit_ms, condition):
        """Accumulate how long a condition has held; True once it held limit_ms."""
        if not condition:
            timers[index] = 0
            return False
        timers[index] += elapsed_us
        return timers[index] >= limit_ms * 1000

    def _update_levels(self):
        """Refresh the level faults that are not checked every iteration (battery)."""
        self.battery_mv = self.hw.battery_mv()
        low = self.params['low_battery_mv']
        if low and 0 < self.battery_mv < low:
            self.faults |= wire.LOW_BATTERY
        else:
            self.faults &= ~wire.LOW_BATTERY

    # --- reports -------------------------------------------------------------------------
    def _next_due(self, due, period_us, now):
        """Return the next due time: one period on, or now if a beat was missed."""
        hw = self.hw
        due = hw.ticks_add(due, period_us)
        return now if hw.ticks_diff(due, now) < 0 else due

    def _board_time(self, now):
        """Return the board clock (u32 microseconds, wrapping) at now."""
        self.board_time_us = (self.board_time_us
                              + self.hw.ticks_diff(now, self._clock_ticks)) & 0xFFFFFFFF
        self._clock_ticks = now
        return self.board_time_us

    def _status_fields(self, now):
        """Return BOARD_STATUS's fields; RX_ERRORS if frames were dropped since the last."""
        bad = wire.dropped_frames(self.decoder.stats)
        faults = self.faults
        if bad > self._rx_bad_reported:
            faults |= wire.RX_ERRORS
            self._rx_bad_reported = bad
        return (self._board_time(now), faults, min(self.battery_mv, wire.U16_MAX),
                min(bad, wire.U16_MAX), self.last_command_seq)

    def _queue(self, msg_type, fields):
        """Encode one report with the next sequence number of its type."""
        seq = self._tx_seq[msg_type]
        self._tx_seq[msg_type] = (seq + 1) & 0xFFFF
        self._out.append(wire.encode_frame(msg_type, seq, fields))
