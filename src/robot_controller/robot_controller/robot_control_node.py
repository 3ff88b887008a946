"""
robot_control_node: text commands on ``control_command`` to velocity on ``cmd_vel``.

Subscribes ``control_command`` (std_msgs/String), e.g. "forward 0.5 m",
"strafe left 2 s", "rotate right 90 deg", "stop" (grammar in
:mod:`robot_controller.command_parser`). Publishes ``cmd_vel`` (geometry_msgs/Twist,
base_link frame, m/s and rad/s), as in the seed tutorial: ``ros2 run robot_controller
robot_control_node`` beside ``ros2 run robot_simulation simulation_node`` drives that
simulation. Every launch file with the command chain remaps it to ``cmd_vel_text``, the
chain's text-command input (twist_mux -> collision_monitor -> zone_guard ->
``cmd_vel_safe`` -> motor_controller); run by hand beside a chain, its ``cmd_vel`` is the
chain's ``external`` input, guarded all the same,
at ``publish_rate_hz`` while a motion lasts, then one zero twist; and ``control_status``
(std_msgs/String): ``accepted: <command>``, ``done: <motion>`` (finished, or
``done: stop``), ``interrupted: <motion>`` (replaced or stopped before its end),
``stopped: <motion> blocked by <reason>`` (the chain held it, below) and
``rejected: <reason>``; refusals and early stops also go to ``/diagnostics``
(diagnostic_msgs/DiagnosticArray, WARN with the status as the message). A new command
replaces the running one; a rejected command never moves the robot (the running motion,
if any, is stopped). Stop is never refused.

Motions are timed on the node's clock. On simulated time (``use_sim_time``) that clock
reads 0 until the first /clock message arrives, which on a loaded machine can be seconds
after the node is up (DDS discovery). A command accepted before then waits, without
moving the robot, and starts at the clock's first tick, so that it still lasts its full
duration. Likewise, without a watched chain (below), a motion starts only once something
subscribes to its ``cmd_vel`` (a warning says so while it waits): a base found late by
DDS discovery would otherwise miss the start of the motion.

The authorised zone: with a zone file (``zone_file``), a command is checked before it
starts: its motion (the constant twist for its duration, integrated from the robot's
pose; the zone guard's check, :mod:`robot_controller.zone_check`) must keep the
footprint (``footprint_radius_m``) at least ``zone_margin_m`` inside the zone along the
whole path. Otherwise it is rejected, with a warning and no twist sent: ``rejected:
<command>: the footprint would come within 0.05 m of the border of the authorised zone
at (x, y) after t s of the T s motion`` (the zone guard's words). The pose is
``global_frame`` -> ``robot_base_frame`` from /tf and /tf_static; with none, or one whose
oldest dynamic link's newest transform is older than ``pose_timeout_s``, the command
waits up to ``pose_timeout_s`` for a recent pose (localisation that has just started
may publish it a moment after the command came), then is rejected: ``rejected: cannot
check the authorised zone: no recent map -> base_link pose (is localisation
running?)``. With a zone, a command that arrives before the clock
starts is checked (and only then accepted) at the clock's first tick.

Stop short: while a motion runs, the node watches the chain's output
(``chain_output_topic``) and the stages' states (``collision_monitor_state``,
``zone_guard_state``; std_msgs/String). When the output stays below
``blocked_speed_ratio`` of the commanded speed for ``blocked_time_s`` without a break, or
the chain sends nothing for that long, the motion ends at once (zero twist, a warning,
``stopped: <motion> blocked by collision_monitor STOP PolygonStop``, or ``... blocked by
no output from the command chain``; rules in :mod:`robot_controller.blocked_detector`).
The watch starts once the chain has shown itself (a publisher of, or a message on,
``chain_output_topic``), so the minimal system, which has no chain, runs as before.
While the chain is watched, a motion is timed from the chain's first output: a chain
just started may take a while to find its stages (DDS discovery), and a motion timed
from the command would then be cut short by that delay. A chain that sends nothing for
``chain_start_timeout_s`` after the motion's start stops it (no output, as above).

Parameters (``config/robot_controller.yaml``): ``linear_speed_mps`` (0.2),
``angular_speed_radps`` (0.5), ``max_linear_speed_mps`` (0.5),
``max_angular_speed_radps`` (1.5), ``default_duration_s`` (2.0), ``max_duration_s``
(60.0), ``publish_rate_hz`` (20.0, > 0); ``zone_file`` ('' = no zone, no check; a zone
file of :mod:`mecanum_safety.zone`); ``footprint_radius_m`` (> 0; from
motor_params.yaml, which launch files pass; the installed file's value by default);
``zone_margin_m`` (0.05, >= 0); ``global_frame`` ('map'); ``robot_base_frame``
('base_link'); ``pose_timeout_s`` (1.0, > 0); ``chain_output_topic`` ('cmd_vel_safe';
'' = do not watch the chain, never stop short); ``blocked_speed_ratio`` (0.1, in (0, 1));
``blocked_time_s`` (0.5, > 0); ``chain_start_timeout_s`` (5.0, >= blocked_time_s). The
speeds and durations must be > 0, a default within its maximum (``linear_speed_mps`` <=
``max_linear_speed_mps``, ``angular_speed_radps`` <= ``max_angular_speed_radps``,
``default_duration_s`` <= ``max_duration_s``).

Run-time parameters (``ros2 param set /robot_controller linear_speed_mps 0.3``; checked
as at start-up, logged, see :mod:`mecanum_control.runtime_parameters`): the six speeds
and durations (from the next command on), ``publish_rate_hz`` (the timer follows at
once), ``zone_margin_m`` and ``pose_timeout_s`` (from the next zone check on),
``blocked_speed_ratio``, ``blocked_time_s`` and ``chain_start_timeout_s`` (at once, also
for the running motion; set blocked_time_s above chain_start_timeout_s together with it,
in one set_parameters_atomically call, or raise chain_start_timeout_s first). The others
are read-only, ``ros2 param set`` says why: ``zone_file`` (restart to change the
authorised zone), ``footprint_radius_m`` (motor_params.yaml's), the frames and
``chain_output_topic`` (wired up at start-up).
"""

from dataclasses import fields
import math
import sys
from typing import Dict, Optional

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Twist
from mecanum_control.messages import diagnostic_array
from mecanum_control.node_main import run_node
from mecanum_control.parameters import declare_typed
from mecanum_control.robot_config import default_config_path, parameters_from_yaml
from mecanum_control.runtime_parameters import RuntimeParameters, WIRING_REASON
from mecanum_localization.tf_listener import TransformListener
from mecanum_localization.transforms import TransformBuffer, TransformError
from mecanum_safety.zone import load_zone_file
from rclpy.duration import Duration
from rclpy.node import Node
from robot_controller.blocked_detector import BlockedDetector
from robot_controller.command_parser import CommandError, CommandLimits, Motion, parse_command
from robot_controller.zone_check import zone_refusal
from std_msgs.msg import String

#: Longest wait (s) on shutdown for the final zero twist to be acknowledged.
CLOSE_ACK_TIMEOUT_S = 0.5
#: The chain's stages whose state topics (std_msgs/String) explain a stop.
STATE_TOPICS = {'collision_monitor': 'collision_monitor_state',
                'zone_guard': 'zone_guard_state'}
#: The parameters of CommandLimits (run-time, checked together by check_command_limits).
LIMIT_PARAMETERS = tuple(field.name for field in fields(CommandLimits))
#: The stop-short watch's parameters (run-time, checked together by blocked_detector).
BLOCKED_PARAMETERS = ('blocked_speed_ratio', 'blocked_time_s', 'chain_start_timeout_s')
#: Why the other parameters are read-only (footprint_radius_m: motor_params.yaml's).
READ_ONLY_REASONS = {
    'zone_file': ('restart to change the authorised zone: a zone that changes under a '
                  'running robot is not what an operator expects'),
    'global_frame': WIRING_REASON,
    'robot_base_frame': WIRING_REASON,
    'chain_output_topic': WIRING_REASON,
}


def _positive(name: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f'parameter {name} must be finite and > 0, got {value}')
    return value


def _positive_rate(name: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f'{name} must be positive and finite, got {value}')
    return value


def _non_negative(name: str, value: float) -> float:
    if not (math.isfinite(value) and value >= 0.0):
        raise ValueError(f'parameter {name} must be finite and >= 0, got {value}')
    return value


def check_command_limits(limits: CommandLimits) -> CommandLimits:
    """
    Return limits if every speed and duration is finite and > 0 and within its maximum.

    Raises ValueError naming the parameter ('parameter linear_speed_mps must be > 0, got
    -1.0').
    """
    for name in LIMIT_PARAMETERS:
        value = getattr(limits, name)
        if not math.isfinite(value):
            raise ValueError(f'parameter {name} must be finite, got {value}')
        if not value > 0.0:
            raise ValueError(f'parameter {name} must be > 0, got {value}')
    for default, maximum in (('linear_speed_mps', 'max_linear_speed_mps'),
                             ('angular_speed_radps', 'max_angular_speed_radps'),
                             ('default_duration_s', 'max_duration_s')):
        if getattr(limits, default) > getattr(limits, maximum):
            raise ValueError(f'parameter {default} ({getattr(limits, default):g}) must be <= '
                             f'{maximum} ({getattr(limits, maximum):g})')
    return limits


def blocked_detector(values: Dict[str, float]) -> BlockedDetector:
    """Return a BlockedDetector of the stop-short parameters (ValueError naming the bad one)."""
    try:
        return BlockedDetector(values['blocked_speed_ratio'], values['blocked_time_s'],
                               values['chain_start_timeout_s'])
    except ValueError as error:   # the detector says start_timeout_s
        text = str(error)
        text = f'chain_{text}' if text.startswith('start_timeout_s') else text
        raise ValueError(f'parameter {text}') from None


def _frame(name: str, value: str) -> str:
    frame = value.strip().lstrip('/')
    if not frame:
        raise ValueError(f'parameter {name} must name a frame, got {value!r}')
    return frame


class RobotController(Node):
    """Turns text commands into timed velocity commands."""

    def __init__(self, **node_options):
        super().__init__('robot_controller', **node_options)
        self.runtime = RuntimeParameters(self, READ_ONLY_REASONS)
        defaults = CommandLimits()
        limits = {name: self.runtime.declare(name, getattr(defaults, name))
                  for name in LIMIT_PARAMETERS}
        self.runtime.joint(LIMIT_PARAMETERS,
                           check=lambda values: check_command_limits(CommandLimits(**values)),
                           apply=self._set_limits)
        self.limits = CommandLimits(**limits)
        publish_rate_hz = self.runtime.declare('publish_rate_hz', 20.0, _positive_rate,
                                               self._set_publish_rate)
        self._declare_zone_parameters()
        self._declare_chain_parameters()

        self.motion = None
        self.motion_text = ''
        self.motion_start_s = None   # None while a motion waits for the clock to start
        self.holding_for_subscriber = False  # warned that this motion has no subscriber yet
        self.accepted = False    # False while a motion waits for its zone check
        self.pose_deadline_s = None  # until when its zone check waits for a recent pose

        self.cmd_vel_pub = self.create_publisher(Twist, 'cmd_vel', 10)
        self.status_pub = self.create_publisher(String, 'control_status', 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.command_sub = self.create_subscription(
            String, 'control_command', self.on_command, 10)
        self.frames = None
        self.tf_listener = None
        if self.zone is not None:
            self.frames = TransformBuffer()
            self.tf_listener = TransformListener(self, self.frames)
        self.chain_seen = False
        self.chain_sub = None
        if self.chain_output_topic:
            self.chain_sub = self.create_subscription(
                Twist, self.chain_output_topic, self.on_chain_output, 10)
            for stage, topic in STATE_TOPICS.items():
                self.create_subscription(
                    String, topic, lambda msg, stage=stage: self.detector.on_state(
                        stage, msg.data), 10)
        self.timer = self.create_timer(1.0 / publish_rate_hz, self.on_timer)
        self.runtime.start()
        zone_text = (f'zone {self.zone_file} (footprint {self.footprint_radius_m:g} m + '
                     f'margin {self.zone_margin_m:g} m)' if self.zone is not None
                     else 'no authorised zone')
        chain_text = (f'watching {self.chain_sub.topic_name}' if self.chain_sub is not None
                      else 'not watching the command chain')
        self.get_logger().info(
            f'Robot controller ready; send text commands on control_command '
            f'({self.cmd_vel_pub.topic_name}; {zone_text}; {chain_text})')

    # -- parameters ---------------------------------------------------------------------

    def _declare_zone_parameters(self) -> None:
        """Declare and check the authorised zone's parameters; load the zone file."""
        self.zone_file = declare_typed(self, 'zone_file', '').strip()
        radius_default = parameters_from_yaml(default_config_path()).get('footprint_radius_m')
        self.footprint_radius_m = _positive(
            'footprint_radius_m', declare_typed(self, 'footprint_radius_m',
                                                float(radius_default), float))
        self.zone_margin_m = self.runtime.declare(
            'zone_margin_m', 0.05, _non_negative,
            lambda value: setattr(self, 'zone_margin_m', value))
        self.global_frame = _frame('global_frame', declare_typed(self, 'global_frame', 'map'))
        self.base_frame = _frame('robot_base_frame',
                                 declare_typed(self, 'robot_base_frame', 'base_link'))
        self.pose_timeout_s = self.runtime.declare(
            'pose_timeout_s', 1.0, _positive,
            lambda value: setattr(self, 'pose_timeout_s', value))
        # ZoneError (a ValueError) names the file and what is wrong with it.
        self.zone = (load_zone_file(self.zone_file)   # 'unrestricted': no zone, on purpose
                     if self.zone_file and self.zone_file != 'unrestricted' else None)
        if self.zone_file and self.zone is None:
            self.get_logger().info(f'{self.zone_file} declares no authorised zone: '
                                   'commands are not checked against one')

    def _declare_chain_parameters(self) -> None:
        """Declare and check the parameters of the stop-short watch of the chain."""
        self.chain_output_topic = declare_typed(
            self, 'chain_output_topic', 'cmd_vel_safe').strip()
        values = {name: self.runtime.declare(name, default) for name, default in zip(
            BLOCKED_PARAMETERS, (0.1, 0.5, 5.0))}
        self.runtime.joint(BLOCKED_PARAMETERS, check=blocked_detector,
                           apply=self._set_blocked_parameters)
        self.detector = blocked_detector(values)

    def _set_limits(self, values: Dict[str, float]) -> None:
        """Use new (checked) speeds and durations from the next command on."""
        self.limits = CommandLimits(**values)

    def _set_publish_rate(self, publish_rate_hz: float) -> None:
        """Publish a running motion's twist at publish_rate_hz from now on."""
        self.timer.timer_period_ns = round(1e9 / publish_rate_hz)
        self.timer.reset()

    def _set_blocked_parameters(self, values: Dict[str, float]) -> None:
        """Use new (checked) stop-short settings at once, also for the running motion."""
        checked = blocked_detector(values)
        self.detector.blocked_speed_ratio = checked.blocked_speed_ratio
        self.detector.blocked_time_s = checked.blocked_time_s
        self.detector.start_timeout_s = checked.start_timeout_s

    # -- commands -----------------------------------------------------------------------

    def on_command(self, msg: String) -> None:
        """Parse a command and start (or stop) the motion it describes."""
        text = msg.data.strip()
        try:
            motion = parse_command(text, self.limits)
        except CommandError as error:
            self.get_logger().warning(f'Rejected command {text!r}: {error}')
            self.interrupt()
            self.report(f'rejected: {error}')
            return
        self.interrupt()
        if motion.is_stop:
            self.finish('done: stop')
            return
        self.motion = motion
        self.motion_text = text
        self.holding_for_subscriber = False
        self.pose_deadline_s = None
        self.accepted = self.zone is None
        if self.accepted:
            self.report(f'accepted: {text}')
        if self.clock_started():
            self.begin()
        else:
            check = '' if self.accepted else ' (and its zone check)'
            self.get_logger().warning(
                f'Holding {text!r}{check} until the clock starts (use_sim_time is set and no '
                '/clock message has arrived yet)')

    def clock_started(self) -> bool:
        """Whether the node's clock runs: simulated time reads 0 until the first /clock."""
        return self.get_clock().now().nanoseconds > 0

    def begin(self) -> None:
        """Check the waiting motion against the zone (if not yet done), then start it."""
        if not self.accepted:
            problem = self.zone_problem()
            if problem is None:     # no recent pose yet: wait for one (on_timer calls again)
                return
            if problem:
                self.get_logger().warning(f'Rejected command {self.motion_text!r}: {problem}')
                self.motion = None
                self.report(f'rejected: {problem}')
                return
            self.accepted = True
            self.report(f'accepted: {self.motion_text}')
        if not self.watching_chain() and self.cmd_vel_pub.get_subscription_count() == 0:
            if not self.holding_for_subscriber:
                self.holding_for_subscriber = True
                self.get_logger().warning(
                    f'Holding {self.motion_text!r} until something subscribes to '
                    f'{self.cmd_vel_pub.topic_name} (a motion sent to nobody would be '
                    'timed out before it moved the robot)')
            return
        self.start_motion()

    def zone_problem(self) -> Optional[str]:
        """
        Return why the waiting motion may not run in the authorised zone, '' if it may.

        None while it waits for a recent pose (up to pose_timeout_s from its first
        check); after that, the no-pose refusal, with the reason logged.
        """
        now_s = self.now_s()
        first_check = self.pose_deadline_s is None
        if first_check:
            self.pose_deadline_s = now_s + self.pose_timeout_s
        pose, missing = self.recent_pose(now_s)
        if pose is not None:
            return zone_refusal(self.zone, (pose.x, pose.y, pose.yaw), self.motion,
                                self.motion_text, self.footprint_radius_m,
                                self.zone_margin_m)
        if now_s < self.pose_deadline_s:
            if first_check:
                self.get_logger().info(
                    f'Holding {self.motion_text!r} until a recent {self.global_frame} -> '
                    f'{self.base_frame} pose arrives (up to {self.pose_timeout_s:g} s)')
            return None
        self.get_logger().info(missing)
        return (f'cannot check the authorised zone: no recent {self.global_frame} -> '
                f'{self.base_frame} pose (is localisation running?)')

    def recent_pose(self, now_s: float):
        """
        Return (global_frame -> robot_base_frame pose, '') or (None, why there is none).

        None also when the pose's oldest dynamic link is older than pose_timeout_s.
        """
        try:
            pose = self.frames.lookup(self.global_frame, self.base_frame)
            oldest = self.frames.oldest_link(self.global_frame, self.base_frame)
        except TransformError as error:
            return None, f'No {self.global_frame} -> {self.base_frame} pose: {error}'
        if oldest is not None and now_s - oldest[0] > self.pose_timeout_s:
            return None, (f'The {self.global_frame} -> {self.base_frame} pose is '
                          f'{now_s - oldest[0]:.2f} s old (its link {oldest[1]}; '
                          f'pose_timeout_s {self.pose_timeout_s:g})')
        return pose, ''

    def now_s(self) -> float:
        """Return the node's clock in seconds (simulated time with use_sim_time)."""
        return self.get_clock().now().nanoseconds * 1e-9

    def start_motion(self) -> None:
        """Start the accepted motion now, and send its first twist."""
        motion = self.motion
        self.motion_start_s = self.now_s()
        self.detector.start(self.motion_start_s, motion.vx, motion.vy, motion.wz)
        self.get_logger().info(
            f'Executing {self.motion_text!r}: vx={motion.vx:.3f} m/s vy={motion.vy:.3f} m/s '
            f'wz={motion.wz:.3f} rad/s for {motion.duration_s:.2f} s')
        self.publish_twist(motion)

    def on_timer(self) -> None:
        """Keep publishing the running motion; end it when its time is up or it is held."""
        if self.motion is None:
            return
        if self.motion_start_s is None:   # waiting for the clock or for a subscriber
            if self.clock_started():
                self.begin()
            return
        now_s = self.now_s()
        watching = self.watching_chain()
        # Watching the chain, the motion runs from its first output (None: not yet).
        start_s = self.detector.first_output_s if watching else self.motion_start_s
        if start_s is not None and now_s >= start_s + self.motion.duration_s:
            self.finish(f'done: {self.motion.name}')
            return
        blocked = self.detector.check(now_s) if watching else None
        if blocked:
            self.get_logger().warning(
                f'Stopping {self.motion_text!r} short: the command chain holds the robot '
                f'({blocked})')
            self.finish(f'stopped: {self.motion.name} blocked by {blocked}')
            return
        self.publish_twist(self.motion)

    def watching_chain(self) -> bool:
        """
        Whether the chain's output is watched: there is one and it has shown itself.

        When it shows itself (a publisher appears) during a motion, the watch of that
        motion starts then, so that late discovery is not taken for a silent chain.
        """
        if self.chain_sub is None:
            return False
        if not self.chain_seen and self.count_publishers(self.chain_sub.topic_name) > 0:
            self.chain_seen = True
            motion = self.motion
            self.detector.start(self.now_s(), motion.vx, motion.vy, motion.wz)
        return self.chain_seen

    def on_chain_output(self, msg: Twist) -> None:
        """Take one output twist of the command chain."""
        self.chain_seen = True
        self.detector.on_output(self.now_s(), msg.linear.x, msg.linear.y, msg.angular.z)

    def interrupt(self) -> None:
        """End the running motion early, if there is one."""
        if self.motion is None:
            return
        if self.accepted:
            self.finish(f'interrupted: {self.motion.name}')
        else:   # still waiting for its zone check: it never was accepted
            self.get_logger().info(f'Dropping {self.motion_text!r} (replaced before its '
                                   'zone check)')
            self.motion = None

    def finish(self, status: str) -> None:
        """Stop the robot and report status."""
        self.motion = None
        self.motion_start_s = None
        self.detector.stop()
        self.cmd_vel_pub.publish(Twist())
        self.report(status)

    def publish_twist(self, motion: Motion) -> None:
        """Publish the motion's body twist on cmd_vel (cmd_vel_text in a chain)."""
        twist = Twist()
        twist.linear.x = motion.vx
        twist.linear.y = motion.vy
        twist.angular.z = motion.wz
        self.cmd_vel_pub.publish(twist)

    def report(self, status: str) -> None:
        """Publish a status line on control_status; a refusal or a stop also on /diagnostics."""
        self.status_pub.publish(String(data=status))
        if status.startswith(('rejected', 'stopped')):
            self.publish_diagnostics(DiagnosticStatus.WARN, status)

    def publish_diagnostics(self, level: bytes, message: str) -> None:
        """Publish one DiagnosticStatus of this node on /diagnostics."""
        values = [KeyValue(key='motion',
                           value=self.motion_text if self.motion is not None else '(none)'),
                  KeyValue(key='zone file', value=self.zone_file or '(none)')]
        self.diag_pub.publish(diagnostic_array(
            self.get_clock().now().to_msg(), 'robot_controller: robot_controller', level,
            message, values))

    def close(self) -> None:
        """
        Stop the robot: a final zero twist (while the context is still valid).

        The process may end right after this: wait (up to CLOSE_ACK_TIMEOUT_S) until the
        subscribers have acknowledged it, so the zero is not lost with the process.
        """
        if self.context.ok():
            self.cmd_vel_pub.publish(Twist())
            self.cmd_vel_pub.wait_for_all_acked(Duration(seconds=CLOSE_ACK_TIMEOUT_S))


def main(args=None) -> int:
    """Run the robot_controller node until Ctrl-C or SIGTERM, then stop the robot."""
    return run_node(RobotController, 'robot_controller', args)


if __name__ == '__main__':
    sys.exit(main())
