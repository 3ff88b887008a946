"""
velocity_smoother: nav2_velocity_smoother's node for the pip setup (node velocity_smoother).

Subscribes ``cmd_vel`` (geometry_msgs/Twist, body twist in base_link, REP-103: vx, vy
m/s, wz rad/s; Nav2's bringup remaps it to ``cmd_vel_nav``, so does our launch file) and,
with ``feedback`` CLOSED_LOOP, ``odom_topic`` (nav_msgs/Odometry, twist in base_link).
Publishes ``cmd_vel_smoothed`` (Twist) every ``1 / smoothing_frequency`` s from a timer
(the node's clock, so sim time with use_sim_time). The rules are those of
:mod:`mecanum_navigation.controller.velocity_smoother`: per-axis acceleration limits,
direction kept
with ``scale_velocities``, deadband, and after ``velocity_timeout`` s without a command a
ramp to zero, one zero published, then silence until the next command (as Nav2).
Non-finite commands count as zero, with a throttled warning.

Parameters (Nav2's names; arrays are [vx, vy, wz]): ``smoothing_frequency`` (Hz),
``scale_velocities``, ``feedback`` (OPEN_LOOP | CLOSED_LOOP), ``max_velocity``,
``min_velocity`` (default -max_velocity), ``max_accel``, ``max_decel`` (negative, as
Nav2), ``deadband_velocity``, ``velocity_timeout`` (s), ``odom_topic`` ('odom'),
``odom_duration`` (s: CLOSED_LOOP uses the mean odometry twist of this last span, as
Nav2's odometry smoother). Limits default to motor_params.yaml. ``enable_stamped_cmd_vel``
is accepted only as false (Twist, not TwistStamped).

Run-time parameters (``ros2 param set /velocity_smoother max_velocity "[0.5, 0.4,
2.0]"``; checked as at start-up, logged, see :mod:`mecanum_control.runtime_parameters`):
``max_velocity``, ``min_velocity``, ``max_accel``, ``max_decel``, ``deadband_velocity``,
``velocity_timeout``, ``scale_velocities``, ``smoothing_frequency`` (the timer follows at
once) and ``odom_duration``, from the next step on; the ramp goes on from the last
output, so a new limit brings no jump. The twists it smooths are still limited by the
command chain (twist_mux, with motor_params.yaml's limits) after it. Read-only
(``ros2 param set`` says why): ``feedback``, ``odom_topic`` and
``enable_stamped_cmd_vel`` (wired up at start-up).
"""

from collections import deque
import math
import sys
from typing import Deque, Dict, Optional, Tuple

from geometry_msgs.msg import Twist
from mecanum_control.log_throttle import KeyedThrottle
from mecanum_control.node_main import run_node
from mecanum_control.parameters import positive
from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_control.runtime_parameters import RuntimeParameters, WIRING_REASON
from mecanum_navigation.controller.velocity_smoother import SmootherParams, VelocitySmoother
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node

#: Seconds between two warnings of the same kind.
WARNING_PERIOD_S = 2.0
ARRAY_PARAMETERS = ('max_velocity', 'min_velocity', 'max_accel', 'max_decel',
                    'deadband_velocity')
#: SmootherParams' run-time parameters (all but feedback, which wires up odom_topic).
SMOOTHER_PARAMETERS = ('smoothing_frequency', 'scale_velocities', 'velocity_timeout',
                       *ARRAY_PARAMETERS)
READ_ONLY_REASONS = {
    'feedback': WIRING_REASON,
    'odom_topic': WIRING_REASON,
    'enable_stamped_cmd_vel': WIRING_REASON,
}


def _seconds(stamp) -> float:
    """Return a builtin_interfaces/Time in seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def smoother_params(values: Dict) -> SmootherParams:
    """Return SmootherParams of the parameters' values (ValueError naming the bad one)."""
    try:
        return SmootherParams(**values)
    except ValueError as error:
        raise ValueError(f'parameter {error}') from None


class VelocitySmootherNode(Node):
    """Ramps cmd_vel into cmd_vel_smoothed within acceleration limits."""

    def __init__(self, **node_options):
        super().__init__('velocity_smoother', **node_options)
        config = load_robot_config(default_config_path())
        defaults = SmootherParams.from_robot_config(config)
        self.runtime = RuntimeParameters(self, READ_ONLY_REASONS)
        dynamic = ParameterDescriptor(dynamic_typing=True)
        values = {'feedback': self.declare_parameter('feedback', defaults.feedback,
                                                     dynamic).value}
        for name in SMOOTHER_PARAMETERS:   # SmootherParams checks them, as they are
            default = getattr(defaults, name)
            default = (None if name == 'min_velocity' else
                       list(default) if name in ARRAY_PARAMETERS else default)
            values[name] = self.runtime.declare(name, default, kind=None)
        params = smoother_params(values)
        self.feedback = params.feedback
        self.runtime.joint(SMOOTHER_PARAMETERS, check=self._changed_params,
                           apply=self._set_params)
        odom_topic = str(self.declare_parameter('odom_topic', 'odom').value)
        self.odom_duration = self.runtime.declare(
            'odom_duration', 0.1, positive, lambda value: setattr(self, 'odom_duration', value))
        if self.declare_parameter('enable_stamped_cmd_vel', False).value:
            raise ValueError('parameter enable_stamped_cmd_vel: only false (geometry_msgs/'
                             'Twist) is supported')
        self.smoother = VelocitySmoother(params)
        self._odom: Deque[Tuple[float, Tuple[float, float, float]]] = deque()
        self._warnings = KeyedThrottle(WARNING_PERIOD_S)

        self.cmd_pub = self.create_publisher(Twist, 'cmd_vel_smoothed', 1)
        self.cmd_sub = self.create_subscription(Twist, 'cmd_vel', self.on_command, 1)
        self.odom_sub = (self.create_subscription(Odometry, odom_topic, self.on_odom, 10)
                         if params.feedback == 'CLOSED_LOOP' else None)
        self.timer = self.create_timer(1.0 / params.smoothing_frequency, self.on_timer)
        self.runtime.start()
        self.get_logger().info(
            f'Velocity smoother started: {self.cmd_sub.topic_name} -> '
            f'{self.cmd_pub.topic_name} at {params.smoothing_frequency:g} Hz, '
            f'{params.feedback}, max_accel {list(params.max_accel)}, max_decel '
            f'{list(params.max_decel)}, velocity_timeout {params.velocity_timeout:g} s')

    def _changed_params(self, values: Dict) -> SmootherParams:
        """Return the smoother's parameters with values (ValueError naming a bad one)."""
        return smoother_params(dict(values, feedback=self.feedback))

    def _set_params(self, values: Dict) -> None:
        """Use new (checked) limits from the next step on; the timer follows its rate."""
        params = self._changed_params(values)
        if params.smoothing_frequency != self.smoother.params.smoothing_frequency:
            self.timer.timer_period_ns = round(1e9 / params.smoothing_frequency)
            self.timer.reset()
        self.smoother.params = params

    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _warn(self, key: str, text: str) -> None:
        """Log a warning, at most once per WARNING_PERIOD_S for the same key."""
        if self._warnings.ready(key):
            self.get_logger().warning(text)

    def on_command(self, msg: Twist) -> None:
        """Take a new target (non-finite: zero, warned)."""
        reason = self.smoother.on_command((msg.linear.x, msg.linear.y, msg.angular.z),
                                          self._now_s())
        if reason:
            self._warn('command', reason)

    def on_odom(self, msg: Odometry) -> None:
        """Keep the odometry twists of the last odom_duration s (CLOSED_LOOP)."""
        twist = msg.twist.twist
        values = (twist.linear.x, twist.linear.y, twist.angular.z)
        if not all(math.isfinite(v) for v in values):
            self._warn('odom', f'{self.odom_sub.topic_name}: non-finite twist {values}: ignored')
            return
        stamp_s = _seconds(msg.header.stamp) or self._now_s()
        self._odom.append((stamp_s, values))
        while self._odom and self._odom[0][0] < stamp_s - self.odom_duration:
            self._odom.popleft()

    def measured_twist(self) -> Optional[Tuple[float, float, float]]:
        """Return the mean odometry twist of the last odom_duration s, or None."""
        if not self._odom:
            return None
        count = len(self._odom)
        vx, vy, wz = (sum(twist[i] for _, twist in self._odom) / count for i in range(3))
        return vx, vy, wz

    def on_timer(self) -> None:
        """Run one smoothing step and publish it unless waiting or stopped."""
        measured = self.measured_twist() if self.odom_sub is not None else None
        output = self.smoother.update(self._now_s(), measured)
        if output.warning:
            self._warn('feedback', output.warning)
        if not output.publish:
            return
        msg = Twist()
        msg.linear.x, msg.linear.y, msg.angular.z = (float(v) for v in output.twist)
        self.cmd_pub.publish(msg)


def main(args=None) -> int:
    """Run the velocity smoother until Ctrl-C or SIGTERM."""
    return run_node(VelocitySmootherNode, 'velocity_smoother', args)


if __name__ == '__main__':
    sys.exit(main())
