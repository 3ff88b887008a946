"""
motor_controller: body velocity commands -> wheel speed targets.

Subscribes ``cmd_vel`` (geometry_msgs/Twist, or TwistStamped with
``use_stamped_cmd_vel``; base_link, m/s and rad/s) and ``emergency_stop``
(std_msgs/Bool: true engages a latching stop). Publishes ``motor_speeds``
(std_msgs/Float32MultiArray, wheel angular velocities rad/s, FL FR RL RR) at
``publish_rate_hz`` and at once on every accepted command, and ``/diagnostics``.
Service ``~/release_emergency_stop`` (std_srvs/Trigger) releases the stop (refused
while ``emergency_stop`` is still true); the robot then waits for a new command. The
latch is published on ``emergency_stop_latched`` (std_msgs/Bool, transient local, on
every change and every second), which twist_mux locks on: this one service clears the
whole chain. With ``estop_latch_file`` set, an engaged stop is also recorded in that
file, so a restarted node (respawn, crash) starts engaged.

Limits come from motor_params.yaml (per-axis velocity and acceleration, wheel speed
with direction-keeping desaturation). NaN/inf or absurd commands (beyond
``absurd_factor`` times a limit) are rejected with a warning and stop the robot;
without a command for ``cmd_timeout_s`` the wheels ramp to zero. The logic lives in
:mod:`mecanum_control.command_limits`.

Only the nodes named in ``cmd_vel_publishers`` ('' = not checked; control.launch.yaml
sets zone_guard, the chain's last stage) may publish ``cmd_vel``: its publishers are
looked up every ``publisher_check_period_s`` (steady clock), and while another node
publishes it the wheel targets are zero and commands are ignored, an ERROR names it and
/diagnostics reports it, until it has gone (mecanum_control.publisher_check).

Run-time parameter (``ros2 param set /motor_controller cmd_timeout_s 0.3``; checked as
at start-up, logged, see :mod:`mecanum_control.runtime_parameters`): ``cmd_timeout_s``
only, from the next check on. Everything else is read-only (``ros2 param set`` says
why): the speed and acceleration limits come from motor_params.yaml, which the command
chain's twist_mux also uses to limit twists before the collision monitor and the zone
guard judge them, so changing them in this node only would let the motors run a twist
the chain did not judge; ``absurd_factor`` goes with them; the rest is wiring.
"""

from pathlib import Path
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Twist, TwistStamped
from mecanum_control.command_limits import (
    AxisLimits, CommandRejected, CommandWatchdog, MotorCommandCore, TwistLimits)
from mecanum_control.messages import diagnostic_array, wheel_array
from mecanum_control.node_main import run_node
from mecanum_control.parameters import declare_robot_config, positive
from mecanum_control.publisher_check_node import (
    declare_publisher_check, MatchWatch, poll_publisher_check, start_publisher_checks)
from mecanum_control.runtime_parameters import (
    PUBLISHER_CHECK_REASON, RuntimeParameters, WIRING_REASON)
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import Bool, Float32MultiArray
from std_srvs.srv import Trigger

STATUS_LEVELS = {'ok': DiagnosticStatus.OK, 'waiting': DiagnosticStatus.OK,
                 'timeout': DiagnosticStatus.WARN, 'estop': DiagnosticStatus.ERROR}
#: Why the other parameters are read-only (motor_params.yaml's say why themselves).
READ_ONLY_REASONS = {
    'absurd_factor': ("the bound (a multiple of motor_params.yaml's limits) beyond which a "
                      'command is refused, not limited: it goes with those limits, which the '
                      'command chain applies too; edit and restart the system'),
    'publish_rate_hz': ("the wheel-target rate the control stack's timeouts were set for; "
                        'restart the node to change it'),
    'use_stamped_cmd_vel': WIRING_REASON,
    'estop_latch_file': ('where an engaged emergency stop is recorded across restarts: '
                         'moved at run time, an engaged stop would be forgotten; restart to '
                         'change it'),
    'cmd_vel_publishers': PUBLISHER_CHECK_REASON,
    'publisher_check_period_s': PUBLISHER_CHECK_REASON,
}


class TunableCommandCore(MotorCommandCore):
    """MotorCommandCore whose command timeout changes while it runs."""

    @property
    def cmd_timeout_s(self) -> float:
        """Return the command timeout (s)."""
        return self._watchdog.timeout_s

    def set_cmd_timeout(self, timeout_s: float) -> None:
        """Use a new command timeout (finite, > 0) from the next check on; the last feed stays."""
        watchdog = CommandWatchdog(timeout_s)
        if self._watchdog.last_feed_s is not None:
            watchdog.feed(self._watchdog.last_feed_s)
        self._watchdog = watchdog


class MotorController(Node):
    """Limits cmd_vel and turns it into four wheel speed targets."""

    def __init__(self, **node_options):
        super().__init__('motor_controller', **node_options)
        config = declare_robot_config(self)
        self.runtime = RuntimeParameters(self, READ_ONLY_REASONS)
        cmd_timeout_s = self.runtime.declare(
            'cmd_timeout_s', 0.5, positive, lambda value: self.core.set_cmd_timeout(value))
        publish_rate_hz = positive('publish_rate_hz',
                                   self.declare_parameter('publish_rate_hz', 50.0).value)
        absurd_factor = positive('absurd_factor',
                                 self.declare_parameter('absurd_factor', 10.0).value)
        stamped = bool(self.declare_parameter('use_stamped_cmd_vel', False).value)
        latch = str(self.declare_parameter('estop_latch_file', '').value)
        self.estop_latch_file = Path(latch) if latch else None
        limits = TwistLimits(
            x=AxisLimits(config.max_velocity_x_m_s, config.max_acceleration_x_m_s2),
            y=AxisLimits(config.max_velocity_y_m_s, config.max_acceleration_y_m_s2),
            wz=AxisLimits(config.max_angular_velocity_rad_s,
                          config.max_angular_acceleration_rad_s2),
            absurd_factor=absurd_factor)
        self.core = TunableCommandCore(config.geometry, limits, config.max_wheel_speed_rad_s,
                                       cmd_timeout_s)
        self._reported_status = None
        self.release_service_name = self.resolve_service_name('~/release_emergency_stop')
        if self.estop_latch_file is not None and self.estop_latch_file.exists():
            self.core.engage_estop(f'latched before a restart ({self.estop_latch_file})')
            self.get_logger().error(
                'EMERGENCY STOP still engaged from before this node restarted '
                f'({self.estop_latch_file}): wheels held at zero until '
                f'{self.release_service_name} is called')

        self.speeds_pub = self.create_publisher(Float32MultiArray, 'motor_speeds', 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.match_watch = MatchWatch(self, self.check_publishers,
                                      lambda: self.cmd_check.unknown_seen)
        if stamped:
            self.cmd_sub = self.create_subscription(
                TwistStamped, 'cmd_vel', lambda msg: self.on_twist(msg.twist), 10,
                event_callbacks=self.match_watch.event_callbacks())
        else:
            self.cmd_sub = self.create_subscription(
                Twist, 'cmd_vel', self.on_twist, 10,
                event_callbacks=self.match_watch.event_callbacks())
        # Only the expected node(s) drive (publisher_check): wheels held at zero meanwhile.
        self.cmd_check = declare_publisher_check(
            self, 'cmd_vel_publishers', self.cmd_sub.topic_name,
            'wheel speed targets held at zero, commands ignored', 'commands accepted again')
        self.publisher_timer = start_publisher_checks(self, [self.cmd_check],
                                                      self.check_publishers)
        self.estop_sub = self.create_subscription(Bool, 'emergency_stop', self.on_estop, 10)
        self.release_srv = self.create_service(Trigger, '~/release_emergency_stop',
                                               self.on_release)
        # The latch for twist_mux's e_stop_latched lock (a restarted mux hears it within 1 s).
        self.latch_pub = self.create_publisher(
            Bool, 'emergency_stop_latched',
            QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.latch_timer = self.create_timer(1.0, self.publish_latch)
        self.publish_latch()
        self.timer = self.create_timer(1.0 / publish_rate_hz, self.publish_speeds)
        self.diag_timer = self.create_timer(1.0, self.publish_diagnostics)
        self.runtime.start()
        self.get_logger().info(
            f'Motor controller started: limits vx {config.max_velocity_x_m_s} m/s, '
            f'vy {config.max_velocity_y_m_s} m/s, wz {config.max_angular_velocity_rad_s} '
            f'rad/s, wheels {config.max_wheel_speed_rad_s} rad/s, cmd timeout {cmd_timeout_s} s')

    def now_s(self) -> float:
        """Node clock (sim time when use_sim_time) in seconds."""
        return self.get_clock().now().nanoseconds * 1e-9

    def on_twist(self, msg: Twist) -> None:
        """Take a body twist; reject NaN/inf or absurd ones (the robot then stops)."""
        if self.cmd_check.stopped:
            return  # an unexpected node publishes cmd_vel: nobody drives
        try:
            self.core.on_command(msg.linear.x, msg.linear.y, msg.angular.z, self.now_s())
        except CommandRejected as error:
            self.get_logger().warning(f'Rejected cmd_vel, stopping: {error}',
                                      throttle_duration_sec=1.0)
        self.publish_speeds()

    def on_estop(self, msg: Bool) -> None:
        """Engage the latching emergency stop on true; false does not release it."""
        if self.core.set_estop_input(msg.data, 'emergency_stop topic'):
            self.publish_latch()
            self._write_latch()
            self.get_logger().error('EMERGENCY STOP engaged: wheels held at zero until '
                                    f'{self.release_service_name} is called')
            self.publish_speeds()
            self.publish_diagnostics()

    def on_release(self, _request, response):
        """Release the emergency stop; motion resumes only with a new command."""
        was_engaged = self.core.status == 'estop'
        if not self.core.release_estop():
            response.success = False
            response.message = ('emergency stop NOT released: emergency_stop is still true '
                                '(let go of the e-stop, i.e. publish false, first)')
            self.get_logger().warning(response.message)
            return response
        self.publish_latch()
        if self.estop_latch_file is not None:
            self.estop_latch_file.unlink(missing_ok=True)
        response.success = True
        response.message = ('emergency stop released; waiting for a new cmd_vel'
                            if was_engaged else 'emergency stop was not engaged')
        self.get_logger().warning(response.message)
        self.publish_diagnostics()
        return response

    def publish_latch(self) -> None:
        """Publish whether the emergency stop is latched (emergency_stop_latched)."""
        self.latch_pub.publish(Bool(data=self.core.estop_engaged))

    def _write_latch(self) -> None:
        """Record the engaged stop so that a restarted node starts engaged too."""
        if self.estop_latch_file is None:
            return
        try:
            self.estop_latch_file.write_text(f'engaged at {time.time():.3f}\n')
        except OSError as error:
            self.get_logger().error(f'Cannot record the emergency stop in '
                                    f'{self.estop_latch_file}: {error}; a restart would '
                                    'forget it')

    def publish_speeds(self) -> None:
        """Publish the wheel speed targets for now."""
        speeds = self.core.update(self.now_s())
        if self.cmd_check.stopped:
            speeds = (0.0, 0.0, 0.0, 0.0)  # the core times out and ramps down meanwhile
        self.speeds_pub.publish(wheel_array(speeds))
        status = self.core.status
        if status != self._reported_status:
            if status == 'timeout':
                self.get_logger().warning('No cmd_vel within the timeout: stopping')
            self._reported_status = status
            self.publish_diagnostics()

    def check_publishers(self, may_resume: bool = True) -> None:
        """Hold the wheels while a node other than the expected ones publishes cmd_vel."""
        if poll_publisher_check(self, self.cmd_check, self.diag_pub, may_resume) == 'stop':
            self.publish_speeds()

    def close(self) -> None:
        """Publish zero wheel speeds once more on the way out."""
        self.speeds_pub.publish(wheel_array((0.0, 0.0, 0.0, 0.0)))

    def publish_diagnostics(self) -> None:
        """Report the command state on /diagnostics."""
        status = self.core.status
        self.diag_pub.publish(diagnostic_array(
            self.get_clock().now().to_msg(), 'mecanum_control: motor_controller',
            STATUS_LEVELS.get(status, DiagnosticStatus.WARN), status, hardware_id=''))


def main(args=None) -> int:
    """Run the motor_controller node until Ctrl-C or SIGTERM."""
    return run_node(MotorController, 'motor_controller', args)


if __name__ == '__main__':
    sys.exit(main())
