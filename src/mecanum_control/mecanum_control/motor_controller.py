"""
motor_controller: body velocity commands -> wheel speed targets.

Subscribes ``cmd_vel`` (geometry_msgs/Twist, or TwistStamped with
``use_stamped_cmd_vel``; base_link, m/s and rad/s) and ``emergency_stop``
(std_msgs/Bool: true engages a latching stop). Publishes ``motor_speeds``
(std_msgs/Float32MultiArray, wheel angular velocities rad/s, FL FR RL RR) at
``publish_rate_hz`` and at once on every accepted command, and ``/diagnostics``.
Service ``~/release_emergency_stop`` (std_srvs/Trigger) releases the stop; the robot
then waits for a new command. With ``estop_latch_file`` set, an engaged stop is also
recorded in that file, so a restarted node (respawn, crash) starts engaged.

Limits come from motor_params.yaml (per-axis velocity and acceleration, wheel speed
with direction-keeping desaturation). NaN/inf or absurd commands (beyond
``absurd_factor`` times a limit) are rejected with a warning and stop the robot;
without a command for ``cmd_timeout_s`` the wheels ramp to zero. The logic lives in
:mod:`mecanum_control.command_limits`.
"""

from pathlib import Path
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Twist, TwistStamped
from mecanum_control.command_limits import (
    AxisLimits, CommandRejected, MotorCommandCore, TwistLimits)
from mecanum_control.messages import diagnostic_array, wheel_array
from mecanum_control.node_main import run_node
from mecanum_control.parameters import declare_robot_config, positive
from rclpy.node import Node
from std_msgs.msg import Bool, Float32MultiArray
from std_srvs.srv import Trigger

STATUS_LEVELS = {'ok': DiagnosticStatus.OK, 'waiting': DiagnosticStatus.OK,
                 'timeout': DiagnosticStatus.WARN, 'estop': DiagnosticStatus.ERROR}


class MotorController(Node):
    """Limits cmd_vel and turns it into four wheel speed targets."""

    def __init__(self, **node_options):
        super().__init__('motor_controller', **node_options)
        config = declare_robot_config(self)
        cmd_timeout_s = positive('cmd_timeout_s',
                                 self.declare_parameter('cmd_timeout_s', 0.5).value)
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
        self.core = MotorCommandCore(config.geometry, limits, config.max_wheel_speed_rad_s,
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
        if stamped:
            self.cmd_sub = self.create_subscription(
                TwistStamped, 'cmd_vel', lambda msg: self.on_twist(msg.twist), 10)
        else:
            self.cmd_sub = self.create_subscription(Twist, 'cmd_vel', self.on_twist, 10)
        self.estop_sub = self.create_subscription(Bool, 'emergency_stop', self.on_estop, 10)
        self.release_srv = self.create_service(Trigger, '~/release_emergency_stop',
                                               self.on_release)
        self.timer = self.create_timer(1.0 / publish_rate_hz, self.publish_speeds)
        self.diag_timer = self.create_timer(1.0, self.publish_diagnostics)
        self.get_logger().info(
            f'Motor controller started: limits vx {config.max_velocity_x_m_s} m/s, '
            f'vy {config.max_velocity_y_m_s} m/s, wz {config.max_angular_velocity_rad_s} '
            f'rad/s, wheels {config.max_wheel_speed_rad_s} rad/s, cmd timeout {cmd_timeout_s} s')

    def now_s(self) -> float:
        """Node clock (sim time when use_sim_time) in seconds."""
        return self.get_clock().now().nanoseconds * 1e-9

    def on_twist(self, msg: Twist) -> None:
        """Take a body twist; reject NaN/inf or absurd ones (the robot then stops)."""
        try:
            self.core.on_command(msg.linear.x, msg.linear.y, msg.angular.z, self.now_s())
        except CommandRejected as error:
            self.get_logger().warning(f'Rejected cmd_vel, stopping: {error}',
                                      throttle_duration_sec=1.0)
        self.publish_speeds()

    def on_estop(self, msg: Bool) -> None:
        """Engage the latching emergency stop on true; false does not release it."""
        if msg.data and self.core.status != 'estop':
            self.core.engage_estop('emergency_stop topic')
            self._write_latch()
            self.get_logger().error('EMERGENCY STOP engaged: wheels held at zero until '
                                    f'{self.release_service_name} is called')
            self.publish_speeds()
            self.publish_diagnostics()

    def on_release(self, _request, response):
        """Release the emergency stop; motion resumes only with a new command."""
        was_engaged = self.core.status == 'estop'
        self.core.release_estop()
        if self.estop_latch_file is not None:
            self.estop_latch_file.unlink(missing_ok=True)
        response.success = True
        response.message = ('emergency stop released; waiting for a new cmd_vel'
                            if was_engaged else 'emergency stop was not engaged')
        self.get_logger().warning(response.message)
        self.publish_diagnostics()
        return response

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
        self.speeds_pub.publish(wheel_array(self.core.update(self.now_s())))
        status = self.core.status
        if status != self._reported_status:
            if status == 'timeout':
                self.get_logger().warning('No cmd_vel within the timeout: stopping')
            self._reported_status = status
            self.publish_diagnostics()

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
