"""
twist_mux: ros-teleop/twist_mux's node for the pip setup (node twist_mux).

Parameters are twist_mux's (a twist_mux YAML file works unchanged; nested keys, read
as twist_mux reads them, from the parameter file): ``topics.NAME.topic`` (input,
geometry_msgs/Twist), ``topics.NAME.timeout`` (s, >= 0; 0 = never times out),
``topics.NAME.priority`` (0-255, higher wins); ``locks.NAME.topic`` (std_msgs/Bool),
``locks.NAME.timeout`` (s, >= 0; > 0: a lock that sends nothing for that long engages),
``locks.NAME.priority`` (0-255: an engaged lock masks every topic of lower priority);
``use_stamped`` (false: Twist in and out; true: geometry_msgs/TwistStamped in and out,
forwarded unchanged). The rules are those of
:mod:`mecanum_safety.twist_mux`: the highest-priority live, unmasked topic is
selected, and each twist of the selected topic is forwarded on ``cmd_vel_out`` as it
arrives (nothing is published periodically).

Differences from twist_mux (see the core's docstring): when the selection becomes no
source (the selected topic timed out or sent NaN/inf, or a lock engaged) the node
publishes ONE zero twist at once, then nothing while no source is selected; a twist
with a NaN/inf component, or beyond ``absurd_factor`` (default 10) times a limit, is
not forwarded (throttled warning) and its source counts as silent; bad parameters stop
the node with a message naming the parameter. The node also publishes one zero twist
when it is closed (Ctrl-C, SIGTERM) while a source is selected.

The robot's limits: the node reads motor_params.yaml's parameters (mecanum_control's,
passed by command_chain.launch.yaml; those not given fall back to the installed file)
and forwards every twist limited by mecanum_control.command_limits.limit_scale, the
function motor_controller limits with: one over a velocity or wheel-speed limit is
scaled down as a whole (every component by one factor, direction kept; throttled
info), so that collision_monitor and zone_guard judge the twist the wheels will run.

After a lock (e.g. the emergency stop), a source that kept publishing while masked is
held until it sends a new command (a zero twist, or silence for its timeout): a stale
stream never resumes motion by itself. The project's config also locks on
motor_controller's ``emergency_stop_latched``, so the e-stop stays engaged here until
the operator calls ``/motor_controller/release_emergency_stop``.

Timeouts are measured on the node's clock (use_sim_time works) and checked by a timer
every ``CHECK_PERIOD_S`` s of that clock, since a silent source produces no callback.

Also published: ``cmd_vel_mux_state`` (std_msgs/String, transient local, depth 1: the
selected topic's NAME, 'locked by LOCK', 'held NAME' or 'none', on every change) and
``/diagnostics`` (diagnostic_msgs/DiagnosticArray, every second: per topic selected /
live / masked / held / silent, per lock engaged / free; twist_mux's "Twist mux
status").
Inputs and locks are subscribed reliable, volatile, depth 10 (twist_mux: system
defaults), so a latched (transient local) lock publisher matches too.
"""

import functools
import sys
from typing import List, Optional

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Twist, TwistStamped
from mecanum_control.command_limits import limit_scale, TwistLimits
from mecanum_control.log_throttle import KeyedThrottle
from mecanum_control.messages import diagnostic_array
from mecanum_control.node_main import run_node
from mecanum_control.robot_config import (
    default_config_path, PARAMETER_KINDS, parameters_from_yaml, robot_config_from_parameters,
    RobotConfig)
from mecanum_control.runtime_parameters import read_only_parameters
from mecanum_safety.twist_mux import Entry, parse_entries, Step, TwistMux
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import Bool, String

#: Seconds (node clock) between two looks at the timeouts.
CHECK_PERIOD_S = 0.05
#: Seconds (node clock) between two /diagnostics messages.
DIAGNOSTICS_PERIOD_S = 1.0
#: Seconds between two warnings of the same kind.
WARNING_PERIOD_S = 2.0
DIAGNOSTIC_NAME = 'twist_mux: Twist mux status'


def _components(twist: Twist) -> tuple:
    return (twist.linear.x, twist.linear.y, twist.linear.z,
            twist.angular.x, twist.angular.y, twist.angular.z)


def _scaled(msg, scale: float, stamped: bool):
    """Return a copy of a Twist (or TwistStamped, header kept) times scale."""
    out = TwistStamped() if stamped else Twist()
    twist_in, twist_out = (msg.twist, out.twist) if stamped else (msg, out)
    if stamped:
        out.header = msg.header
    for part in ('linear', 'angular'):
        vector_in, vector_out = getattr(twist_in, part), getattr(twist_out, part)
        for axis in ('x', 'y', 'z'):
            setattr(vector_out, axis, float(scale * getattr(vector_in, axis)))
    return out


def _describe(entries: List[Entry]) -> str:
    return ', '.join(f'{e.name} ({e.topic}, {e.timeout_s:g} s, priority {e.priority})'
                     for e in entries) or 'none'


class TwistMuxNode(Node):
    """Forwards the highest-priority live command source; stops when none is left."""

    def __init__(self, **node_options):
        # twist_mux's entries are nested parameters whose names only the parameter file
        # knows, so they are declared from it, as twist_mux's node does.
        node_options.setdefault('automatically_declare_parameters_from_overrides', True)
        super().__init__('twist_mux', **node_options)
        if self.has_parameter('use_stamped'):
            stamped = self.get_parameter('use_stamped').value
        else:
            stamped = self.declare_parameter('use_stamped', False).value
        if not isinstance(stamped, bool):
            raise ValueError(f'parameter use_stamped must be true or false, got {stamped!r}')
        self.stamped = stamped
        values = {name: parameter.value
                  for name, parameter in self.get_parameters_by_prefix('').items()}
        topics, topic_warnings = parse_entries('topics', values)
        locks, lock_warnings = parse_entries('locks', values)
        config = self._robot_config()
        absurd_factor = self._number('absurd_factor', 10.0)
        try:
            limits = TwistLimits.from_config(config, absurd_factor)
        except ValueError as error:
            raise ValueError(f'parameter {error}') from None
        limit = functools.partial(limit_scale, limits=limits, geometry=config.geometry,
                                  max_wheel_speed_rad_s=config.max_wheel_speed_rad_s)
        self.core = TwistMux(topics, locks, resolve=self.resolve_topic_name, limit=limit)
        for warning in topic_warnings + lock_warnings:
            self.get_logger().warning(warning)
        self._warnings = KeyedThrottle(WARNING_PERIOD_S)
        self._frame_id = ''
        self._engaged = set()
        self.twist_type = TwistStamped if stamped else Twist

        self.cmd_pub = self.create_publisher(self.twist_type, 'cmd_vel_out', 10)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.state_pub = self.create_publisher(String, 'cmd_vel_mux_state', latched)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        for entry in topics:
            self.create_subscription(self.twist_type, entry.topic,
                                     functools.partial(self.on_twist, entry), 10)
        for entry in locks:
            self.create_subscription(Bool, entry.topic,
                                     functools.partial(self.on_lock, entry), 10)
        self.check_timer = self.create_timer(CHECK_PERIOD_S, self.check_timeouts)
        self.diag_timer = self.create_timer(DIAGNOSTICS_PERIOD_S, self.publish_diagnostics)
        self.get_logger().info(
            f'Twist mux started: topics {_describe(topics)}; locks {_describe(locks)} '
            f'-> {self.cmd_pub.topic_name} '
            f'({"TwistStamped" if stamped else "Twist"}); limits vx '
            f'{config.max_velocity_x_m_s:g} m/s, vy {config.max_velocity_y_m_s:g} m/s, wz '
            f'{config.max_angular_velocity_rad_s:g} rad/s, wheels '
            f'{config.max_wheel_speed_rad_s:g} rad/s')
        self._apply(self.core.update(self._now_s()), None)
        read_only_parameters(self, {
            'topics.*': "the mux's inputs, subscribed when it started (as twist_mux's); "
                        'restart twist_mux to change them',
            'locks.*': "the mux's locks, subscribed when it started (as twist_mux's); "
                       'restart twist_mux to change them',
            'absurd_factor': 'a safety limit of the chain, read when it started; restart '
                             'twist_mux to change it'})

    # -- helpers ------------------------------------------------------------------------

    def _robot_config(self) -> RobotConfig:
        """
        Return the robot's parameters (motor_params.yaml), validated.

        Those in the parameter files are already declared (from the overrides); the
        others are declared read-only with the installed motor_params.yaml's values,
        as mecanum_control.parameters.declare_robot_config does.
        """
        defaults = parameters_from_yaml(default_config_path())
        values = {}
        for name in PARAMETER_KINDS:
            if self.has_parameter(name):
                values[name] = self.get_parameter(name).value
            else:
                descriptor = ParameterDescriptor(read_only=True,
                                                 description='see motor_params.yaml')
                values[name] = self.declare_parameter(
                    name, defaults.get(name), descriptor).value
        return robot_config_from_parameters(values)

    def _number(self, name: str, default: float) -> float:
        """Return a numeric parameter (declared from the overrides or with default)."""
        if self.has_parameter(name):
            value = self.get_parameter(name).value
        else:
            value = self.declare_parameter(
                name, default, ParameterDescriptor(dynamic_typing=True)).value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f'parameter {name} must be a number, got {value!r}')
        return float(value)

    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _warn(self, key: str, text: str) -> None:
        """Log a warning, at most once per WARNING_PERIOD_S for the same key."""
        if self._warnings.ready(key):
            self.get_logger().warning(text)

    def _zero(self):
        """Return a zero twist of the output type (stamped now, last frame)."""
        if not self.stamped:
            return Twist()
        msg = TwistStamped()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self._frame_id
        return msg

    def _apply(self, step: Step, msg) -> None:
        """Publish what a step asks for: the message (limited), one zero twist, the state."""
        if step.forward and msg is not None:
            if self.stamped:
                self._frame_id = msg.header.frame_id
            self.cmd_pub.publish(msg if step.scale == 1.0
                                 else _scaled(msg, step.scale, self.stamped))
        if step.stop:
            self.cmd_pub.publish(self._zero())
        now_s = self._now_s()
        engaged = {e.name for e in self.core.locks if self.core.lock_engaged(e.name, now_s)}
        for entry in self.core.locks:
            if (entry.name in engaged) != (entry.name in self._engaged):
                if entry.name in engaged:
                    self.get_logger().warning(
                        f'Lock {entry.name} {self.core.lock_status(entry.name, now_s)} '
                        f'({entry.topic}): topics below priority {entry.priority} masked')
                else:
                    self.get_logger().info(f'Lock {entry.name} released ({entry.topic})')
        self._engaged = engaged
        if step.changed:
            self.state_pub.publish(String(data=step.state))
            text = f'Command source: {step.state}'
            if step.stop:
                self.get_logger().warning(f'{text} (no live source left: one zero twist sent)')
            else:
                self.get_logger().info(text)

    # -- callbacks ----------------------------------------------------------------------

    def on_twist(self, entry: Entry, msg) -> None:
        """Take a twist of one input; forward it (limited) if that input is selected."""
        values = _components(msg.twist if self.stamped else msg)
        problem = self.core.rejection(values)
        if problem is not None:
            self._warn(f'nan {entry.name}',
                       f'{entry.name}: twist on {entry.topic} rejected ({problem}); the '
                       'source counts as silent')
        step = self.core.on_twist(entry.name, values, self._now_s())
        if step.forward and step.scale < 1.0 and self._warnings.ready(f'limit {entry.name}'):
            self.get_logger().info(
                f'{entry.name}: twist ({values[0]:g}, {values[1]:g}, {values[5]:g}) over the '
                f"robot's limits: scaled by {step.scale:.3g}, direction kept")
        self._apply(step, msg)

    def on_lock(self, entry: Entry, msg: Bool) -> None:
        """Take a lock's value."""
        self._apply(self.core.on_lock(entry.name, msg.data, self._now_s()), None)

    def check_timeouts(self) -> None:
        """Notice inputs and locks that timed out (a silent source sends no callback)."""
        self._apply(self.core.update(self._now_s()), None)

    def publish_diagnostics(self) -> None:
        """Report the selection and every input and lock on /diagnostics."""
        now_s = self._now_s()
        core = self.core
        values = [KeyValue(key=f'velocity {e.name}',
                           value=f'{core.topic_status(e.name, now_s)} (listening to {e.topic} '
                                 f'@ {e.timeout_s:g} s with priority #{e.priority})')
                  for e in core.topics]
        values += [KeyValue(key=f'lock {e.name}',
                            value=f'{core.lock_status(e.name, now_s)} (listening to '
                                  f'{e.topic} @ {e.timeout_s:g} s with priority '
                                  f'#{e.priority})')
                   for e in core.locks]
        lock_priority = core.lock_priority(now_s)
        values.append(KeyValue(key='current priority', value=str(lock_priority)))
        state = core.state_at(now_s)
        level = DiagnosticStatus.WARN if lock_priority > 0 else DiagnosticStatus.OK
        self.diag_pub.publish(diagnostic_array(
            self.get_clock().now().to_msg(), DIAGNOSTIC_NAME, level, state, values))

    def close(self) -> None:
        """Publish one zero twist on the way out if a source is selected."""
        source: Optional[str] = self.core.source
        if source is not None:
            self.cmd_pub.publish(self._zero())


def main(args=None) -> int:
    """Run the twist_mux node until Ctrl-C or SIGTERM."""
    return run_node(TwistMuxNode, 'twist_mux', args)


if __name__ == '__main__':
    sys.exit(main())
