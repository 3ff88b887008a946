"""
velocity_controller: per-wheel PID from wheel speed targets to motor efforts.

Subscribes ``motor_speeds`` (std_msgs/Float32MultiArray, target wheel speeds rad/s,
FL FR RL RR) and ``joint_states`` (sensor_msgs/JointState; measured wheel speeds
of the joints named in ``wheel_joint_names``). Publishes ``motor_efforts``
(std_msgs/Float32MultiArray, PWM duty -1..1, FL FR RL RR) every control period and
``/diagnostics``.

Each wheel runs :class:`mecanum_control.pid.PidController` with the real time step
(feedforward, anti-windup, output limit, derivative on measurement). A wheel whose
effort stays high without motion (stalled, or its encoder disconnected) or while it
turns against the effort (encoder wired reversed: positive feedback) is stopped by
:class:`mecanum_control.pid.StallDetector`, with every other wheel (on three wheels a
mecanum robot goes elsewhere than the command chain judged), and reported, until the
operator calls ``~/clear_wheel_faults`` (std_srvs/Trigger) once the wheel is seen to: an
automatic retry would drive a robot with a dead encoder again, at full effort, each
time. Stale targets (``target_timeout_s``) mean zero; stale measurements
(``measurement_timeout_s``) stop every wheel. While motor_efforts has no subscriber
(hardware_interface not matched yet), the loops are held at zero and judge no stall:
the wheels cannot follow efforts that reach no board. Measured wheel speeds beyond
``PLAUSIBLE_SPEED_FACTOR`` x ``max_wheel_speed_rad_s`` are rejected as garbage (the
message is ignored, so persistent garbage trips the measurement timeout), and a
non-finite PID output is sent as 0. Gains: ``config/pid_gains.yaml``.

Only the nodes named in ``motor_speeds_publishers`` (motor_controller),
``joint_states_publishers`` (encoder_reader) and ``motor_efforts_publishers`` (this
node; all set in pid_gains.yaml, '' = not checked) may publish those topics: their
publishers are looked up every ``publisher_check_period_s`` (steady clock), and while
another node publishes one (a stray script, a second controller, a
joint_state_publisher) every effort is zero, an ERROR names it and /diagnostics reports
it; once it has gone, control resumes with the targets and measurements received from
then on (mecanum_control.publisher_check). An intruder on motor_efforts also clears the
stall latches (hardware_interface holds the board at zero for it, so wheels that stood
still were not stalled), and control resumes one check after it has gone, when
hardware_interface has resumed. The same while hardware_interface says on /diagnostics
(its publisher check of motor_efforts, at most ``BOARD_HELD_S`` old) that it holds the
board at zero for a publisher this node may not see (a killed process's stale writer,
listed only by an older DDS participant: after a respawn of this node, all four wheels
latched as stalled against the held board, for good).

Run-time parameters (``ros2 param set /velocity_controller kp 0.04``; checked as at
start-up, logged, see :mod:`mecanum_control.runtime_parameters`): the gains ``kp``,
``ki``, ``kd``, ``kf``, ``static_effort``, ``max_effort``, ``derivative_filter_tau_s``,
``integral_freeze_rate_rad_s2`` (every wheel's controller takes them at once, without a
step in effort: :meth:`TunablePidController.retune` keeps each integrator and moves it by
the change of the other terms), the stall check's ``stall_effort_threshold``,
``stall_velocity_threshold_rad_s``, ``stall_time_s``, ``stall_target_threshold_rad_s``
(at once; a latched fault stays latched), ``target_timeout_s`` and
``measurement_timeout_s``. Read-only (``ros2 param set`` says why): ``control_rate_hz``,
the publisher checks' parameters and motor_params.yaml's.
"""

from dataclasses import fields
import math
import sys
from typing import Dict, List, Optional

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from mecanum_control.messages import wheel_array
from mecanum_control.node_main import run_node
from mecanum_control.parameters import declare_robot_config, positive
from mecanum_control.pid import (FAULT_WRONG_DIRECTION, PidController, PidGains, StallConfig,
                                 StallDetector)
from mecanum_control.publisher_check import other_check_holds
from mecanum_control.publisher_check_node import (
    declare_publisher_check, MatchWatch, poll_publisher_check, start_publisher_checks)
from mecanum_control.runtime_parameters import PUBLISHER_CHECK_REASON, RuntimeParameters
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.time import Time
from sensor_msgs.msg import JointState
from std_msgs.msg import Float32MultiArray
from std_srvs.srv import Trigger

WHEELS = ('FL', 'FR', 'RL', 'RR')

# A measured wheel speed beyond this many times max_wheel_speed_rad_s is not physical
# (the no-load speed is only about 1.2 x that): a decoding or transport glitch.
PLAUSIBLE_SPEED_FACTOR = 4.0
#: Seconds (node clock) hardware_interface's last word that it holds the board at zero
#: counts: it repeats it every check (1 s) while it holds; silence ends the hold.
BOARD_HELD_S = 3.0

#: The gains: PidGains' fields, run-time parameters of the same names.
GAIN_PARAMETERS = tuple(field.name for field in fields(PidGains))
#: The stall check's run-time parameters and the StallConfig fields they set.
STALL_PARAMETERS = {'stall_effort_threshold': 'effort_threshold',
                    'stall_velocity_threshold_rad_s': 'velocity_threshold_rad_s',
                    'stall_time_s': 'time_s',
                    'stall_target_threshold_rad_s': 'target_threshold_rad_s'}
#: Why the other parameters are read-only (motor_params.yaml's say why themselves).
READ_ONLY_REASONS = {
    'control_rate_hz': ("the control loop's rate, which the gains were tuned at; restart "
                        'the node to change it'),
    '*_publishers': PUBLISHER_CHECK_REASON,
    'publisher_check_period_s': PUBLISHER_CHECK_REASON,
}


def pid_gains(values: Dict[str, float]) -> PidGains:
    """Return the PidGains of the gain parameters (ValueError naming the bad one)."""
    try:
        return PidGains(**values)
    except ValueError as error:
        raise ValueError(str(error).replace('PidGains.', 'parameter ', 1)) from None


def stall_config(values: Dict[str, float]) -> StallConfig:
    """Return the StallConfig of the stall parameters (ValueError naming the bad one)."""
    try:
        return StallConfig(**{STALL_PARAMETERS[name]: value for name, value in values.items()})
    except ValueError as error:
        text = str(error)
        for name, field in STALL_PARAMETERS.items():
            text = text.replace(f'StallConfig.{field} ', f'parameter {name} ', 1)
        raise ValueError(text) from None


def _clip(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))


def _direct_effort(gains: PidGains, target: float, measured: float) -> float:
    """Return the feedforward and proportional terms of the effort (PidController's)."""
    feedforward = gains.kf * target + math.copysign(gains.static_effort, target)
    return feedforward + gains.kp * (target - measured)


class TunablePidController(PidController):
    """A wheel's PidController whose gains change while it runs, without a step in effort."""

    def retune(self, gains: PidGains) -> None:
        """
        Take new gains; the next effort at the last step's inputs is the last effort.

        Bumpless transfer: the integrator is kept (it holds the effort the wheel's load
        needs, and is in effort units: a change of ki alone moves nothing) and moved by
        the change of the feedforward, proportional and derivative terms at the last
        step's target and measurement; from there it settles where the new gains need it.
        The derivative state is scaled by the change of kd. Both are clipped to the new
        max_effort (as update() clips them). With ki = 0 nothing would ever take such an
        offset away, so the integrator is cleared instead: the effort then steps by the
        change of the other terms. A controller at rest (reset, or a zero target) has
        nothing to carry over.
        """
        old = self._gains
        self._gains = gains
        old_derivative = self._derivative
        self._derivative = (_clip(old_derivative * gains.kd / old.kd, 2.0 * gains.max_effort)
                            if old.kd > 0.0 else 0.0)
        if gains.ki == 0.0:
            self._integral = 0.0
            return
        target, measured = self._prev_target, self._prev_measured
        if measured is not None and target != 0.0:
            before = _direct_effort(old, target, measured) + old_derivative
            after = _direct_effort(gains, target, measured) + self._derivative
            if math.isfinite(before - after):
                self._integral += before - after
        self._integral = _clip(self._integral, gains.max_effort)


class TunableStallDetector(StallDetector):
    """A wheel's StallDetector whose thresholds change while it runs."""

    def reconfigure(self, config: StallConfig) -> None:
        """
        Use new thresholds from the next step on.

        The time the fault condition has held so far counts against the new time_s; a
        latched fault stays latched (only ~/clear_wheel_faults clears it).
        """
        self._config = config


class VelocityController(Node):
    """Closes the wheel speed loops."""

    def __init__(self, **node_options):
        super().__init__('velocity_controller', **node_options)
        config = declare_robot_config(self)
        self.joint_names = list(config.wheel_joint_names)
        self.max_wheel_speed_rad_s = config.max_wheel_speed_rad_s
        self.runtime = RuntimeParameters(self, READ_ONLY_REASONS)
        declare = self.runtime.declare
        defaults = {'kp': 0.03, 'ki': 0.3, 'kd': 0.0,
                    'kf': 1.0 / config.motor_no_load_speed_rad_s, 'static_effort': 0.0,
                    'max_effort': 1.0, 'derivative_filter_tau_s': 0.02,
                    'integral_freeze_rate_rad_s2': 10.0}
        # PidGains' own words at start-up ('PidGains.kp must be ...').
        gains = PidGains(**{name: declare(name, float(defaults[name]))
                            for name in GAIN_PARAMETERS})
        self.runtime.joint(GAIN_PARAMETERS, check=pid_gains, apply=self._set_gains)
        stall = stall_config({name: declare(name, default) for name, default in zip(
            STALL_PARAMETERS, (0.6, 0.5, 0.5, 3.0))})
        self.runtime.joint(tuple(STALL_PARAMETERS), check=stall_config,
                           apply=self._set_stall_config)
        control_rate_hz = positive('control_rate_hz',
                                   self.declare_parameter('control_rate_hz', 50.0).value)
        self.target_timeout_s = declare('target_timeout_s', 0.5, positive,
                                        lambda value: setattr(self, 'target_timeout_s', value))
        self.measurement_timeout_s = declare(
            'measurement_timeout_s', 0.25, positive,
            lambda value: setattr(self, 'measurement_timeout_s', value))
        self.pids = [TunablePidController(gains) for _ in WHEELS]
        self.stall_detectors = [TunableStallDetector(stall) for _ in WHEELS]
        self._all_stopped = False       # every wheel held at zero for a faulted one
        self.targets = [0.0] * 4
        self.target_time: Optional[Time] = None
        self.measured = [0.0] * 4
        self.measured_time: Optional[Time] = None
        self.efforts = [0.0] * 4
        self.last_update: Optional[Time] = None
        self.state = 'waiting for the first joint_states'
        self._reported = set()

        self.efforts_pub = self.create_publisher(Float32MultiArray, 'motor_efforts', 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        # A new publisher of an input is unvetted until a look at the graph has named it:
        # meanwhile its data must not latch a stall (a stray joint_states saying the
        # wheels stand still latched all four before the check could name it).
        self._unvetted = False
        self.match_watch = MatchWatch(self, self.check_publishers, self._inputs_unnamed,
                                      self._on_new_publisher)
        self.target_sub = self.create_subscription(
            Float32MultiArray, 'motor_speeds', self.on_targets, 10,
            event_callbacks=self.match_watch.event_callbacks())
        self.joint_sub = self.create_subscription(
            JointState, 'joint_states', self.on_joint_states, 20,
            event_callbacks=self.match_watch.event_callbacks())
        # Only the expected nodes feed the loops and drive the motors (publisher_check):
        # zero efforts meanwhile. On its own output, motor_efforts, it resumes one check
        # later than hardware_interface (which zeroes the board meanwhile, same period),
        # so that the loops never push against a board held at zero (a false stall).
        self.publisher_checks = [declare_publisher_check(
            self, parameter, topic.topic_name, 'all efforts zero',
            'control resumes with the data received from now on', resume_after)
            for topic, parameter, resume_after in (
                (self.target_sub, 'motor_speeds_publishers', 1),
                (self.joint_sub, 'joint_states_publishers', 1),
                (self.efforts_pub, 'motor_efforts_publishers', 2))]
        self.publisher_timer = start_publisher_checks(self, self.publisher_checks,
                                                      self.check_publishers)
        # hardware_interface may hold the board at zero for a publisher of motor_efforts
        # that this node cannot see (a killed process's stale writer, which only an older
        # DDS participant still lists): it says so on /diagnostics (its publisher check).
        # Meanwhile the loops do not push against the held board, nor judge stalls (the
        # wheels stand still on purpose), as for an intruder seen here.
        self._board_held_until: Optional[Time] = None
        self.diag_sub = self.create_subscription(DiagnosticArray, '/diagnostics',
                                                 self.on_diagnostics, 20)
        self.clear_srv = self.create_service(Trigger, '~/clear_wheel_faults',
                                             self.on_clear_wheel_faults)
        self.timer = self.create_timer(1.0 / control_rate_hz, self.on_control)
        self.diag_timer = self.create_timer(1.0, self.publish_diagnostics)
        self.runtime.start()
        self.get_logger().info(
            f'Velocity controller started: kp {gains.kp} ki {gains.ki} kd {gains.kd} '
            f'kf {gains.kf:.4f} at {control_rate_hz} Hz')

    def _set_gains(self, values: Dict[str, float]) -> None:
        """Give every wheel's controller the new (checked) gains, without a step in effort."""
        gains = pid_gains(values)
        for pid in self.pids:
            pid.retune(gains)

    def _set_stall_config(self, values: Dict[str, float]) -> None:
        """Give every wheel's stall detector the new (checked) thresholds."""
        config = stall_config(values)
        for stall in self.stall_detectors:
            stall.reconfigure(config)

    def on_targets(self, msg: Float32MultiArray) -> None:
        """Take wheel speed targets; malformed or non-finite ones mean stop."""
        if self._intruded():
            return  # an unexpected node publishes an input: nobody drives
        values = list(msg.data)
        if len(values) != 4 or not all(math.isfinite(v) for v in values):
            self.get_logger().warning(f'Rejecting motor_speeds {values}: need 4 finite '
                                      'wheel speeds (FL FR RL RR); stopping',
                                      throttle_duration_sec=1.0)
            values = [0.0] * 4
        limit = self.max_wheel_speed_rad_s
        self.targets = [max(-limit, min(limit, v)) for v in values]
        self.target_time = self.get_clock().now()

    def on_joint_states(self, msg: JointState) -> None:
        """
        Take measured wheel speeds of our joints (other joints are ignored).

        A message with a non-finite wheel speed, or one beyond PLAUSIBLE_SPEED_FACTOR x
        max_wheel_speed_rad_s, is ignored with a throttled warning (the previous
        measurement and its age stay, so garbage that persists trips the timeout).
        """
        if self._intruded() or len(msg.velocity) != len(msg.name):
            return
        speeds = dict(zip(msg.name, msg.velocity))
        if not all(name in speeds for name in self.joint_names):
            return
        values = [float(speeds[name]) for name in self.joint_names]
        if not all(math.isfinite(v) for v in values):
            self.get_logger().warning('Non-finite wheel speed in joint_states ignored',
                                      throttle_duration_sec=1.0)
            return
        bound = PLAUSIBLE_SPEED_FACTOR * self.max_wheel_speed_rad_s
        if any(abs(v) > bound for v in values):
            self.get_logger().warning(
                f'Implausible wheel speeds {values} rad/s in joint_states ignored (limit '
                f'+-{bound:g} rad/s = {PLAUSIBLE_SPEED_FACTOR:g} x max_wheel_speed_rad_s)',
                throttle_duration_sec=1.0)
            return
        self.measured = values
        self.measured_time = self.get_clock().now()

    def _age_s(self, stamp: Optional[Time], now: Time) -> float:
        # abs(): a clock stepping back must not make old data look fresh forever.
        return math.inf if stamp is None else abs((now - stamp).nanoseconds) * 1e-9

    def on_control(self) -> None:
        """One control period: PID per wheel with the measured dt, then publish."""
        now = self.get_clock().now()
        dt_s = 0.0 if self.last_update is None else (now - self.last_update).nanoseconds * 1e-9
        self.last_update = now
        targets = self.targets
        if self._age_s(self.target_time, now) > self.target_timeout_s:
            targets = [0.0] * 4
        if self._intruded():
            for pid in self.pids:
                pid.reset()
            self.efforts = [0.0] * 4
        elif self.measured_time is None:
            self.efforts = [0.0] * 4  # waiting for the first joint_states
        elif self._age_s(self.measured_time, now) > self.measurement_timeout_s:
            self._set_state('no wheel speed measurements (joint_states) for '
                            f'{self.measurement_timeout_s} s: all wheels stopped')
            for pid in self.pids:
                pid.reset()
            self.efforts = [0.0] * 4
        else:
            self._set_state('ok')
            if self.efforts_pub.get_subscription_count() == 0:
                # Nobody takes the efforts yet (hardware_interface has not matched this
                # publisher: just after a respawn, discovery takes a moment): the wheels
                # cannot follow them, so the loops neither push nor judge a stall (a
                # respawned controller latched all four wheels as stalled before its
                # first effort reached the board).
                for pid, stall in zip(self.pids, self.stall_detectors):
                    pid.reset()
                    if not stall.stalled:
                        stall.reset()
                self.efforts = [0.0] * 4
            else:
                self.efforts = self._run_pids(targets, dt_s)
        self.efforts_pub.publish(wheel_array(self.efforts))

    def _intruded(self) -> bool:
        """
        Tell whether an unexpected node publishes motor_speeds, joint_states or efforts.

        Or whether hardware_interface said (within BOARD_HELD_S) that it holds the board at
        zero for an unexpected publisher of motor_efforts.
        """
        if self._board_held_until is not None:
            if self.get_clock().now() < self._board_held_until:
                return True
            self._board_held_until = None
        return any(check.stopped for check in self.publisher_checks)

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        """Take hardware_interface's word that it holds the board at zero, or no longer."""
        for status in msg.status:
            held = other_check_holds(status.name, {kv.key: kv.value for kv in status.values},
                                     self.efforts_pub.topic_name, self.get_name())
            if held is None:
                continue
            if held:
                if self._board_held_until is None:
                    self.get_logger().warning(
                        f'{status.name.split(": ", 1)[-1]}: unexpected ones, so the board is '
                        'held at zero: all efforts zero, no stall judged, until it says they '
                        'are gone')
                    self._clear_stalls()
                self._board_held_until = self.get_clock().now() + Duration(
                    seconds=BOARD_HELD_S)
            elif self._board_held_until is not None:
                self._board_held_until = None
                self.target_time = self.measured_time = None   # only what comes from now
                self.get_logger().warning('hardware_interface no longer holds the board at '
                                          'zero: control resumes')

    def _on_new_publisher(self) -> None:
        """Judge no stall until the publisher of an input that just matched is named."""
        self._unvetted = True

    def _inputs_unnamed(self) -> bool:
        """Tell whether an input had a publisher of no known node at the last look."""
        return any(check.enabled and check.unknown_seen for check in self.publisher_checks
                   if check.topic != self.efforts_pub.topic_name)

    def check_publishers(self, may_resume: bool = True) -> None:
        """Stop every wheel while a node other than the expected ones publishes an input."""
        for check in self.publisher_checks:
            change = poll_publisher_check(self, check, self.diag_pub, may_resume)
            if change is not None:
                # Only what arrives from now on counts (none of the intruder's data).
                self.target_time = self.measured_time = None
            if change == 'stop' and check.topic == self.efforts_pub.topic_name:
                self._clear_stalls()
        if not self._inputs_unnamed():
            self._unvetted = False      # every publisher of the inputs has a name now

    def on_clear_wheel_faults(self, request, response):
        """Clear the latched wheel faults (std_srvs/Trigger): the wheels may drive again."""
        latched = [w for w, stall in zip(WHEELS, self.stall_detectors) if stall.stalled]
        for stall in self.stall_detectors:
            stall.reset()
        for pid in self.pids:
            pid.reset()
        self._reported.clear()
        response.success = True
        response.message = (f'cleared: {", ".join(latched)}' if latched
                            else 'no wheel fault was latched')
        if latched:
            self.get_logger().warning(f'Wheel fault of {", ".join(latched)} cleared by a call '
                                      f'of {self.clear_srv.srv_name}: driving again')
        self.publish_diagnostics()
        return response

    def _clear_stalls(self) -> None:
        """Forget stalls: hardware_interface may have held the board at zero already."""
        latched = [w for w, stall in zip(WHEELS, self.stall_detectors) if stall.stalled]
        for stall in self.stall_detectors:
            stall.reset()
        self._reported.clear()
        if latched:
            self.get_logger().warning(
                f'Stall of {", ".join(latched)} cleared: hardware_interface sends zero while '
                'motor_efforts has an unexpected publisher, so the wheels stood still')

    def _run_pids(self, targets: List[float], dt_s: float) -> List[float]:
        efforts = []
        # While a latched wheel has every wheel held at zero, the others stand still on
        # purpose: they are not judged (asked to turn and not turning, they would latch
        # as stalled 0.5 s later and a healthy wheel would be blamed). Nor while an input
        # has a publisher not yet named (its data may be a stray's).
        holding = self._unvetted or any(stall.stalled for stall in self.stall_detectors)
        for i, (pid, stall) in enumerate(zip(self.pids, self.stall_detectors)):
            effort = pid.update(targets[i], self.measured[i], dt_s)
            if not math.isfinite(effort):  # never expected; a NaN must not become duty
                pid.reset()
                effort = 0.0
            if holding and not stall.stalled:
                stall.reset()
            elif stall.update(effort, self.measured[i], targets[i], dt_s):
                pid.reset()
                effort = 0.0
                if WHEELS[i] not in self._reported:
                    self._reported.add(WHEELS[i])
                    if stall.fault == FAULT_WRONG_DIRECTION:
                        problem = (f'Wheel {WHEELS[i]} runs against its effort (encoder '
                                   'reversed?): high effort, wheel turning the other way')
                    else:
                        problem = (f'Wheel {WHEELS[i]} stalled or its encoder is '
                                   'disconnected: high effort without motion')
                    self.get_logger().error(
                        f'{problem}; every wheel stopped until you call '
                        f'{self.clear_srv.srv_name} (std_srvs/srv/Trigger) once it is '
                        'seen to')
                    self.publish_diagnostics()
            efforts.append(effort)
        faulted = [w for w, stall in zip(WHEELS, self.stall_detectors) if stall.stalled]
        if faulted:
            # A mecanum robot with a wheel off goes along another path than the one the
            # command chain judged (and its odometry is wrong): stop every wheel.
            if not self._all_stopped:
                self.get_logger().error(
                    f'Every wheel stopped while {", ".join(faulted)} is faulted: on three '
                    'wheels a mecanum robot does not go where it is told')
            self._all_stopped = True
            for pid in self.pids:
                pid.reset()
            return [0.0] * len(efforts)
        self._all_stopped = False
        return efforts

    def _set_state(self, state: str) -> None:
        if state != self.state:
            if state == 'ok':
                self.get_logger().info('Wheel speed measurements arriving: control active')
            else:
                self.get_logger().error(state)
            self.state = state
            self.publish_diagnostics()

    def publish_diagnostics(self) -> None:
        """Report control state and stopped (stalled / reversed) wheels on /diagnostics."""
        faults = [(w, s.fault) for w, s in zip(WHEELS, self.stall_detectors) if s.stalled]
        stalled = [w for w, fault in faults if fault != FAULT_WRONG_DIRECTION]
        reversed_ = [w for w, fault in faults if fault == FAULT_WRONG_DIRECTION]
        status = DiagnosticStatus(name='mecanum_control: velocity_controller')
        if self.state != 'ok':
            status.level, status.message = DiagnosticStatus.ERROR, self.state
        elif faults:
            status.level = DiagnosticStatus.ERROR
            parts = []
            if stalled:
                parts.append(f'stalled or encoder disconnected: {", ".join(stalled)}')
            if reversed_:
                parts.append('runs against its effort (encoder reversed?): '
                             f'{", ".join(reversed_)}')
            status.message = '; '.join(parts) + (
                f'; every wheel stopped until {self.clear_srv.srv_name}')
        else:
            status.level, status.message = DiagnosticStatus.OK, 'ok'
        status.values = [KeyValue(key=f'effort_{w}', value=f'{e:.3f}')
                         for w, e in zip(WHEELS, self.efforts)]
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(array)

    def close(self) -> None:
        """Publish zero efforts once more on the way out."""
        self.efforts_pub.publish(wheel_array([0.0] * 4))


def main(args=None) -> int:
    """Run the velocity_controller node until Ctrl-C or SIGTERM."""
    return run_node(VelocityController, 'velocity_controller', args)


if __name__ == '__main__':
    sys.exit(main())
