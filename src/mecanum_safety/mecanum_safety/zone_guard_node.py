"""
zone_guard: keeps every velocity command inside the authorised zone (node zone_guard).

The last stage of the command chain (twist_mux -> collision_monitor -> zone_guard ->
motor_controller). Every command on ``cmd_vel_in_topic`` ('cmd_vel_monitored';
geometry_msgs/Twist, body twist in base_link, REP-103) is checked against the authorised
zone and published on ``cmd_vel_out_topic`` ('cmd_vel_safe'), one output per input, as
the collision monitor does; with no input nothing is published. The rule is
:mod:`mecanum_safety.zone_guard`'s: the whole twist is scaled by the largest
factor in [0, 1] that keeps the footprint circle (``footprint_radius_m`` of
motor_params.yaml, declared read-only with the robot's other parameters) at least
``min(footprint_radius_m + margin, its clearance now)`` from the zone's border along the
motion predicted for ``horizon_s`` (1.0 s). The margin is ``margin_m`` (0.05 m) +
``covariance_factor`` (2.0) x the localisation's position standard deviation toward the
border (along the normals of the border edges within reach, the worst direction near a
vertex; of the x-y covariance of ``pose_covariance_topic``, 'amcl_pose' (amcl; SLAM's is
'pose'), geometry_msgs/PoseWithCovarianceStamped; '' = none), at most ``max_margin_m``
(0.5 m). That topic is read with a transient-local subscription (amcl's latched
amcl_pose, also after a restart of this node) and a volatile one (slam_toolbox's pose
is volatile: a transient-local subscription does not match it); a message heard on
both is taken once. Outside the zone (the footprint across its border) only motion
back in passes (see :mod:`mecanum_safety.zone_guard`).

The localisation's health: while the last message on ``pose_covariance_topic`` has NaN
or inf in its pose or covariance, a covariance that is not symmetric positive
semi-definite, or a position standard deviation above ``max_position_sigma_m`` (0.25
m), every command that moves the footprint is replaced by zero ('STOP localisation
unhealthy: <why>'); turning on the spot passes (it does not move the footprint circle,
and amcl updates after turning). The next healthy message lifts it. There is no timeout
on that topic: amcl publishes only after the robot moved (update_min_d, update_min_a),
so a robot standing still hears nothing; the pose's freshness is the /tf chain's
(pose_timeout_s), which amcl and SLAM refresh at every scan. Before any message the
localisation counts as healthy (margin_m alone).

The zone is read once from ``zone_file`` (a standalone zone file, see zones/apartment.yaml;
'unrestricted' = no zone, on purpose; '' = none declared: every command passes
unchanged, unless ``require_zone`` (false; the real robot's launch sets it) is true:
then every command is replaced by zero ('STOP no zone file: ...'), the log saying how
to give one). The robot's pose is the latest ``global_frame`` ('map') ->
``robot_base_frame`` ('base_link') transform from /tf and /tf_static (map -> odom from
amcl or SLAM, odom -> base_link from the EKF); lookups never wait. Its age is the node
clock's now minus the oldest stamp in the chain (amcl's future-dated map -> odom is
fine: it is never the oldest while the EKF runs). With no transform, one older than
``pose_timeout_s`` (0.5 s), or one whose oldest link is stamped more than
``pose_timeout_s`` in the future (a clock mismatch: such a pose would stay "fresh" long
after its publisher stopped), every command is replaced by zero (a throttled warning
says why). A NaN transform is refused by the transform listener (the pose then ages
out). Whatever the pose, a non-finite command is replaced by zero and a command that is
exactly zero passes.

``state_topic`` ('zone_guard_state', std_msgs/String, transient local; '' = none) says
what was done to the last command: 'ALLOW', 'SCALE 0.42 (0.31 m from the border)' (the
footprint's distance to it), 'STOP at the border', 'STOP outside the zone', 'ALLOW back
into the zone', 'SCALE 0.42 back into the zone (0.05 m over the border)', 'ALLOW
turning on the spot outside the zone', 'STOP localisation unhealthy: ...', 'ALLOW
turning on the spot (localisation unhealthy: ...)', 'ALLOW zero command (localisation
unhealthy: ...)', 'STOP no pose: ...', 'STOP invalid command', 'ALLOW zero command (no
pose)', 'ALLOW no zone declared', 'ALLOW unrestricted (no zone)', 'STOP no zone file:
...'; published when the kind of state changes (its words, not its numbers) and at
most every ``STATE_PERIOD_S`` while it does not. ``/diagnostics``
(diagnostic_msgs/DiagnosticArray, every second): OK (allowing), WARN (scaling, or no
pose or an unhealthy localisation while idle), ERROR (stopping), with the reason, the
pose's age, the localisation's health and the margin.

Run-time parameters (``ros2 param set /zone_guard margin_m 0.1``; checked as at
start-up, within the same ranges, logged, see :mod:`mecanum_control.runtime_parameters`),
taken from the next command on: ``margin_m``, ``covariance_factor``, ``max_margin_m``
(>= margin_m: lower margin_m first, or set both in one set_parameters_atomically call),
``horizon_s``, ``max_position_sigma_m`` (the last pose covariance is judged again at
once), ``pose_timeout_s``, ``max_localisation_jump_m``, ``max_localisation_jump_rad`` and
``initial_pose_grace_s``. Read-only (``ros2 param set`` says why): ``zone_file`` and
``require_zone`` (restart to change the authorised zone: a zone that changes under a
running robot is not what an operator expects), motor_params.yaml's, and the frames and
topics (wired up at start-up).
"""

from collections import deque
from dataclasses import replace
import math
import sys
import time
from typing import Dict, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseWithCovarianceStamped, Twist
from mecanum_control.log_throttle import KeyedThrottle
from mecanum_control.messages import diagnostic_array
from mecanum_control.node_main import run_node
from mecanum_control.parameters import declare_robot_config, declare_typed
from mecanum_control.runtime_parameters import RuntimeParameters, WIRING_REASON
from mecanum_localization.tf_listener import TransformListener
from mecanum_localization.transforms import TransformBuffer, TransformError
from mecanum_safety import zone_guard as guard
from mecanum_safety.zone import load_zone_file, Zone, ZoneError
import numpy as np
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import String

#: Seconds (node clock) between two /diagnostics messages.
DIAGNOSTICS_PERIOD_S = 1.0
#: Seconds (steady clock) between two state messages while the kind of state is unchanged.
STATE_PERIOD_S = 0.5
#: Seconds between two warnings of the same kind.
WARNING_PERIOD_S = 2.0
#: Seconds between two log lines announcing the same kind of state (a command hovering
#: between two kinds would log every command otherwise).
STATE_LOG_PERIOD_S = 1.0
#: zone_file value that declares, on purpose, that there is no zone.
UNRESTRICTED = 'unrestricted'
#: Messages taken on one pose-covariance subscription and not yet heard on the other,
#: remembered to take each once (a volatile publisher never reaches the other one).
PENDING_COVARIANCES = 8
DIAGNOSTIC_NAME = guard.DIAGNOSTIC_NAME
NO_ZONE_FILE = ('no zone file: give zone_file:=<zone file> (see mecanum_safety/zones) or '
                'zone_file:=unrestricted')
#: The guard's settings (run-time parameters, checked together by guard.ZoneGuard).
GUARD_SETTINGS = (('horizon_s', 1.0), ('margin_m', 0.05), ('covariance_factor', 2.0),
                  ('max_margin_m', 0.5), ('max_position_sigma_m', 0.25))
#: The localisation-jump detector's settings (run-time, checked by LocalisationJumps).
JUMP_SETTINGS = (('max_localisation_jump_m', 0.5), ('max_localisation_jump_rad', 0.5),
                 ('initial_pose_grace_s', 5.0))
ZONE_REASON = ('restart to change the authorised zone: a zone that changes under a '
               'running robot is not what an operator expects')
#: Why the other parameters are read-only (motor_params.yaml's say why themselves).
READ_ONLY_REASONS = {
    'zone_file': ZONE_REASON,
    'require_zone': ZONE_REASON,
    **{name: WIRING_REASON for name in (
        'global_frame', 'robot_base_frame', 'odom_frame', 'initial_pose_topic',
        'pose_covariance_topic', 'cmd_vel_in_topic', 'cmd_vel_out_topic', 'state_topic')},
}


def pose_timeout(name: str, value: float) -> float:
    """Return pose_timeout_s if finite and > 0, else raise ValueError naming it."""
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f'parameter {name} must be a finite number > 0, got {value!r}')
    return value


def localisation_jumps(values: Dict[str, float]) -> guard.LocalisationJumps:
    """Return a LocalisationJumps of the jump settings (ValueError naming the bad one)."""
    try:
        return guard.LocalisationJumps(values['max_localisation_jump_m'],
                                       values['max_localisation_jump_rad'],
                                       values['initial_pose_grace_s'])
    except ValueError as error:
        raise ValueError(f'parameter {error}') from None


def _components(msg: Twist) -> Tuple[float, ...]:
    return (msg.linear.x, msg.linear.y, msg.linear.z,
            msg.angular.x, msg.angular.y, msg.angular.z)


def _rotation_only(msg: Twist) -> Twist:
    """Return msg's rotation about z alone (its translation dropped)."""
    out = Twist()
    out.angular.z = float(msg.angular.z)
    return out


def _scaled(msg: Twist, scale: float) -> Twist:
    out = Twist()
    out.linear.x, out.linear.y, out.linear.z = (float(scale * v) for v in (
        msg.linear.x, msg.linear.y, msg.linear.z))
    out.angular.x, out.angular.y, out.angular.z = (float(scale * v) for v in (
        msg.angular.x, msg.angular.y, msg.angular.z))
    return out


class ZoneGuardNode(Node):
    """Scales every command so that the footprint stays inside the authorised zone."""

    def __init__(self, **node_options):
        super().__init__('zone_guard', **node_options)
        config = declare_robot_config(self)
        self.runtime = RuntimeParameters(self, READ_ONLY_REASONS)
        self.zone_file = declare_typed(self, 'zone_file', '')
        self.global_frame = declare_typed(self, 'global_frame', 'map').strip('/')
        self.base_frame = declare_typed(self, 'robot_base_frame', 'base_link').strip('/')
        for name, frame in (('global_frame', self.global_frame),
                            ('robot_base_frame', self.base_frame)):
            if not frame:
                raise ValueError(f'parameter {name} must not be empty')
        if self.global_frame == self.base_frame:
            raise ValueError(f'parameters global_frame and robot_base_frame must differ, '
                             f'both are {self.global_frame!r}')
        numbers = {name: self.runtime.declare(name, default) for name, default in GUARD_SETTINGS}
        self.require_zone = declare_typed(self, 'require_zone', False)
        self.odom_frame = declare_typed(self, 'odom_frame', 'odom').strip('/')
        jumps = {name: self.runtime.declare(name, default) for name, default in JUMP_SETTINGS}
        initial_pose_topic = declare_typed(self, 'initial_pose_topic', 'initialpose')
        self.pose_timeout_s = self.runtime.declare(
            'pose_timeout_s', 0.5, pose_timeout,
            lambda value: setattr(self, 'pose_timeout_s', value))
        covariance_topic = declare_typed(self, 'pose_covariance_topic', 'amcl_pose')
        cmd_in = declare_typed(self, 'cmd_vel_in_topic', 'cmd_vel_monitored')
        cmd_out = declare_typed(self, 'cmd_vel_out_topic', 'cmd_vel_safe')
        state_topic = declare_typed(self, 'state_topic', 'zone_guard_state')
        for name, topic in (('cmd_vel_in_topic', cmd_in), ('cmd_vel_out_topic', cmd_out)):
            if not topic:
                raise ValueError(f'parameter {name} must not be empty')
        zone: Optional[Zone] = None
        self.unrestricted = self.zone_file.strip() == UNRESTRICTED
        # The real robot (require_zone) never drives without a zone unless told so.
        self.zone_missing = self.require_zone and not self.zone_file.strip()
        if self.zone_file and not self.unrestricted:
            try:
                zone = load_zone_file(self.zone_file)
            except ZoneError as error:   # names the file and the key
                raise ValueError(f'parameter zone_file: {error}') from None
        try:
            self.guard = guard.ZoneGuard(zone, config.footprint_radius_m, **numbers)
        except ValueError as error:
            raise ValueError(f'parameter {error}') from None
        self.jumps = localisation_jumps(jumps)
        self.runtime.joint(tuple(numbers), check=self._changed_guard,
                           apply=lambda values: self._set_guard(self._changed_guard(values)))
        self.runtime.joint(tuple(jumps), check=localisation_jumps, apply=self._set_jumps)
        self.frames = TransformBuffer()
        self._warnings = KeyedThrottle(WARNING_PERIOD_S)
        self._state_logs = KeyedThrottle(STATE_LOG_PERIOD_S)
        self.sigma_xy_m = 0.0          # no covariance heard yet: margin_m alone
        self.covariance = None         # the last pose covariance heard (36 values)
        self._last_pose = None         # its (position, orientation, covariance)
        self.sigma_used_m = 0.0        # sigma toward the border of the last command
        self.covariance_count = 0
        # What is wrong with the localisation (None: healthy, or nothing heard yet).
        self.localisation: Optional[guard.LocalisationProblem] = None
        # Per subscription, the messages the other one took that it will hear too.
        self._pending = (deque(maxlen=PENDING_COVARIANCES),
                         deque(maxlen=PENDING_COVARIANCES))
        self.commands = 0
        self._state = ('', '')         # (kind, text) of the last command's state
        self._state_published_at = -math.inf
        self._level = DiagnosticStatus.OK
        self._last_result: Optional[guard.GuardResult] = None

        self.cmd_pub = self.create_publisher(Twist, cmd_out, 10)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.state_pub = (self.create_publisher(String, state_topic, latched)
                          if state_topic else None)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.tf_listener = TransformListener(self, self.frames)
        self.covariance_topic = covariance_topic
        self.covariance_subs = []
        if covariance_topic:
            # amcl's amcl_pose is latched (transient local: heard after a restart too);
            # slam_toolbox's pose is volatile, which a transient-local subscription does
            # not match (quietly: that is what the volatile one is for).
            quiet = SubscriptionEventCallbacks(incompatible_qos=lambda _event: None)
            self.covariance_subs = [
                self.create_subscription(PoseWithCovarianceStamped, covariance_topic,
                                         lambda msg: self.on_pose_covariance(msg, 0),
                                         latched, event_callbacks=quiet),
                self.create_subscription(PoseWithCovarianceStamped, covariance_topic,
                                         lambda msg: self.on_pose_covariance(msg, 1), 10)]
        self.initial_pose_sub = (self.create_subscription(
            PoseWithCovarianceStamped, initial_pose_topic, self.on_initial_pose, 10)
            if initial_pose_topic else None)
        self.cmd_sub = self.create_subscription(Twist, cmd_in, self.on_command, 10)
        self.diag_timer = self.create_timer(DIAGNOSTICS_PERIOD_S, self.publish_diagnostics)
        self.runtime.start()
        if self.zone_missing:
            zone_text = 'NO ZONE FILE: every command is stopped'
        elif self.unrestricted:
            zone_text = 'no zone: zone_file:=unrestricted (driving without a zone on purpose)'
        elif zone is None:
            zone_text = ('no zone declared (zone_file empty)' if not self.zone_file
                         else f'no zone declared in {self.zone_file}')
        else:
            zone_text = (f'zone from {self.zone_file} ({len(zone.include)} vertices, '
                         f'{len(zone.exclude)} exclusions)')
        self.get_logger().info(
            f'Zone guard started: {self.cmd_sub.topic_name} -> {self.cmd_pub.topic_name}; '
            f'{zone_text}; footprint {self.guard.footprint_radius_m:g} m, margin '
            f'{self.guard.margin_m:g} m (+ {self.guard.covariance_factor:g} sigma, at most '
            f'{self.guard.max_margin_m:g} m), horizon {self.guard.horizon_s:g} s; pose '
            f'{self.global_frame} -> {self.base_frame} within {self.pose_timeout_s:g} s; '
            f'localisation health from '
            f'{self.covariance_subs[0].topic_name if self.covariance_subs else "nothing"} '
            f'(position sigma at most {self.guard.max_position_sigma_m:g} m)')
        if self.zone_missing:
            self.get_logger().error(
                'zone_file is empty and require_zone is true (the real robot): every '
                'command is stopped. Give the authorised zone, zone_file:=/path/to/zone.yaml '
                '(a zone file in the map frame, like mecanum_safety zones/apartment.yaml), '
                'or drive without one on purpose: zone_file:=unrestricted')

    # -- run-time parameters ------------------------------------------------------------

    def _changed_guard(self, values: Dict[str, float]) -> guard.ZoneGuard:
        """Return the guard with the settings values; ValueError naming a bad one."""
        try:
            return replace(self.guard, **values)
        except ValueError as error:
            raise ValueError(f'parameter {error}') from None

    def _set_guard(self, new_guard: guard.ZoneGuard) -> None:
        """Use new (checked) settings; judge the last pose covariance again with them."""
        self.guard = new_guard
        if self._last_pose is None:
            return
        previous, self.localisation = (self.localisation,
                                       self.guard.localisation_problem(*self._last_pose))
        if (previous is None) != (self.localisation is None):
            self.get_logger().info(
                'localisation ' + (f'unhealthy: {self.localisation.text}'
                                   if self.localisation is not None else 'healthy again')
                + f' with max_position_sigma_m {self.guard.max_position_sigma_m:g}')

    def _set_jumps(self, values: Dict[str, float]) -> None:
        """Use new (checked) jump thresholds; a latched jump stays latched."""
        checked = localisation_jumps(values)
        self.jumps.max_jump_m = checked.max_jump_m
        self.jumps.max_jump_rad = checked.max_jump_rad
        self.jumps.grace_s = checked.grace_s

    # -- helpers ------------------------------------------------------------------------

    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _warn(self, key: str, text: str) -> None:
        """Log a warning, at most once per WARNING_PERIOD_S for the same key."""
        if self._warnings.ready(key):
            self.get_logger().warning(text)

    def robot_pose(self) -> Tuple[Optional[Tuple[float, float, float]], str, str]:
        """
        Return ((x, y, yaw) of robot_base_frame in global_frame, '', '') if fresh.

        Otherwise (None, the state's reason, a longer explanation for the log).
        """
        chain = f'{self.global_frame} -> {self.base_frame}'
        try:
            transform = self.frames.lookup(self.global_frame, self.base_frame)
        except TransformError as error:
            return None, f'no pose: no transform {chain} (localisation not running?)', (
                f'no transform {chain} yet: {error}')
        oldest = self.frames.oldest_link(self.global_frame, self.base_frame)
        if oldest is not None:
            age = self._now_s() - oldest[0]
            if age > self.pose_timeout_s:
                return None, (f'no pose: {chain} older than {self.pose_timeout_s:g} s '
                              '(localisation lost?)'), (
                    f'{chain} is {age:.2f} s old (its oldest link {oldest[1]}), more than '
                    f'pose_timeout_s {self.pose_timeout_s:g} s')
            if age < -self.pose_timeout_s:
                # It would stay "fresh" that much longer after its publisher stopped.
                return None, f'no pose: {chain} stamped in the future (clock mismatch?)', (
                    f'{chain} is stamped {-age:.2f} s in the future (its oldest link '
                    f'{oldest[1]}), more than pose_timeout_s {self.pose_timeout_s:g} s: '
                    'a clock mismatch?')
        return (transform.x, transform.y, transform.yaw), '', ''

    def _set_state(self, kind: str, text: str, level: bytes) -> None:
        """Publish the state when its kind changes, else at most every STATE_PERIOD_S."""
        now = time.monotonic()
        changed = kind != self._state[0]
        self._state = (kind, text)
        self._level = level
        if changed and self._state_logs.ready(kind):
            self.get_logger().info(f'Zone guard: {text}')
        if self.state_pub is not None and (
                changed or now - self._state_published_at >= STATE_PERIOD_S):
            self.state_pub.publish(String(data=text))
            self._state_published_at = now

    # -- callbacks ----------------------------------------------------------------------

    def on_pose_covariance(self, msg: PoseWithCovarianceStamped, source: int = 0) -> None:
        """
        Keep the localisation's position uncertainty (worst direction, m) and health.

        source: which subscription heard it (0 transient local, 1 volatile); a message
        the other one already took is skipped.
        """
        pose = msg.pose.pose
        position = (pose.position.x, pose.position.y, pose.position.z)
        orientation = (pose.orientation.x, pose.orientation.y, pose.orientation.z,
                       pose.orientation.w)
        key = (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id,
               np.array(position + orientation + tuple(msg.pose.covariance)).tobytes())
        if key in self._pending[source]:
            self._pending[source].remove(key)
            return   # the same message, already taken from the other subscription
        self._pending[1 - source].append(key)
        sigma = guard.sigma_xy(msg.pose.covariance)
        self.sigma_xy_m = sigma
        self.covariance = tuple(msg.pose.covariance)
        self._last_pose = (position, orientation, self.covariance)
        self.covariance_count += 1
        problem = self.guard.localisation_problem(position, orientation, msg.pose.covariance)
        previous, self.localisation = self.localisation, problem
        topic = self.covariance_subs[0].topic_name
        if problem is not None:
            if previous is None or previous.kind != problem.kind:
                self._warnings.ready(f'localisation {problem.kind}')   # this is the warning
                self.get_logger().warning(
                    f'localisation unhealthy ({topic}): {problem.text}: stopping every '
                    'motion but turning on the spot until it is healthy again (give a '
                    'closer initial pose, e.g. RViz 2D Pose Estimate, or turn on the spot '
                    'so that amcl updates)')
            else:
                self._warn(f'localisation {problem.kind}',
                           f'localisation still unhealthy ({topic}): {problem.text}')
        elif previous is not None:
            self.get_logger().info(
                f'localisation healthy again ({topic}): position sigma {sigma:.3f} m; '
                'commands pass')

    def on_initial_pose(self, msg: PoseWithCovarianceStamped) -> None:
        """Take the operator's pose: clear a latched jump and expect the next one."""
        latched = self.jumps.latched is not None
        self.jumps.initial_pose_set(self._now_s())
        self.get_logger().info(
            f'pose set on {self.initial_pose_sub.topic_name}: '
            + ('the localisation jump is cleared; ' if latched else '')
            + f'a jump of the localisation within {self.jumps.grace_s:g} s is expected')

    def localisation_jump(self) -> Optional[guard.LocalisationProblem]:
        """Feed map -> odom to the jump detector; return its latched problem, if any."""
        was = self.jumps.latched
        try:
            map_to_odom = self.frames.lookup(self.global_frame, self.odom_frame)
        except TransformError:
            return was     # no odom frame in this chain (or not yet): nothing to compare
        sigma_yaw = (math.sqrt(max(self.covariance[35], 0.0))
                     if self.covariance is not None and math.isfinite(self.covariance[35])
                     else 0.0)
        problem = self.jumps.update(self._now_s(), (map_to_odom.x, map_to_odom.y,
                                                    map_to_odom.yaw), self.sigma_xy_m,
                                    sigma_yaw)
        if problem is not None and was is None:
            self.get_logger().error(f'{problem.text}; stopping every motion but turning on '
                                    'the spot until then')
        return problem

    def on_command(self, msg: Twist) -> None:
        """Publish the allowed twist for one command and the state."""
        self.commands += 1
        values = _components(msg)
        if not all(math.isfinite(v) for v in values):
            self._warn('command', f'non-finite command {values}: publishing zero')
            self.cmd_pub.publish(Twist())
            self._set_state('STOP invalid', f'STOP {guard.REASON_INVALID_COMMAND}',
                            DiagnosticStatus.ERROR)
            return
        if self.zone_missing:
            self.cmd_pub.publish(Twist())
            self._warn('no zone file', f'{NO_ZONE_FILE}: stopping')
            self._set_state('STOP no zone file', f'STOP {NO_ZONE_FILE}',
                            DiagnosticStatus.ERROR)
            return
        if self.guard.zone is None:
            self.cmd_pub.publish(msg)
            if self.unrestricted:
                self._set_state('ALLOW unrestricted', 'ALLOW unrestricted (no zone)',
                                DiagnosticStatus.OK)
            else:
                self._set_state('ALLOW none', 'ALLOW no zone declared', DiagnosticStatus.OK)
            return
        pose, reason, explanation = self.robot_pose()
        if pose is None:
            self.cmd_pub.publish(Twist())
            if all(v == 0.0 for v in values):
                self._set_state('ALLOW zero', 'ALLOW zero command (no pose)',
                                DiagnosticStatus.WARN)
                return
            self._warn(f'pose {reason}', f'{explanation}: stopping')
            self._set_state(f'STOP {reason}', f'STOP {reason}', DiagnosticStatus.ERROR)
            return
        twist = (msg.linear.x, msg.linear.y, msg.angular.z)
        problem = self.localisation_jump() or self.localisation
        if problem is not None:
            self._command_while_unhealthy(msg, values, pose, twist, problem)
            return
        if self.covariance is not None:
            self.sigma_used_m = self.guard.sigma(pose, twist, self.covariance)
        else:
            self.sigma_used_m = self.sigma_xy_m
        result = self.guard.step(pose, twist, self.sigma_used_m)
        self._last_result = result
        if all(v == 0.0 for v in values) or result.scale >= 1.0:
            self.cmd_pub.publish(_rotation_only(msg) if result.rotation_only else msg)
            if result.reason in (guard.REASON_BACK_IN, guard.REASON_TURNING_OUTSIDE) \
                    and not all(v == 0.0 for v in values):
                self._set_state(f'ALLOW {result.reason}', f'ALLOW {result.reason}',
                                DiagnosticStatus.WARN)
            else:
                self._set_state('ALLOW', 'ALLOW', DiagnosticStatus.OK)
            return
        self.cmd_pub.publish(_scaled(msg, result.scale))
        gap = result.gap_m(self.guard.footprint_radius_m)
        if result.scale > 0.0 and result.reason == guard.REASON_BACK_IN:
            self._set_state('SCALE back', f'SCALE {result.scale:.2f} {result.reason} '
                            f'({-gap:.2f} m over the border)', DiagnosticStatus.WARN)
        elif result.scale > 0.0:
            self._set_state('SCALE', f'SCALE {result.scale:.2f} ({gap:.2f} m from the border)',
                            DiagnosticStatus.WARN)
        else:
            if result.reason == guard.REASON_OUTSIDE:
                self._warn('outside', f'the footprint is {-gap:.2f} m over the border of the '
                           'authorised zone: only motion back into it passes, stopping')
            self._set_state(f'STOP {result.reason}', f'STOP {result.reason}',
                            DiagnosticStatus.ERROR)

    def _command_while_unhealthy(self, msg: Twist, values: Tuple[float, ...],
                                 pose: Tuple[float, float, float],
                                 twist: Tuple[float, float, float],
                                 problem: guard.LocalisationProblem) -> None:
        """Stop every command but turning on the spot; the state says why."""
        result = self.guard.step(pose, twist, localisation=problem)
        self._last_result = result
        if all(v == 0.0 for v in values):
            self.cmd_pub.publish(msg)
            self._set_state('ALLOW zero unhealthy',
                            f'ALLOW zero command ({guard.REASON_LOCALISATION}: {problem.kind})',
                            DiagnosticStatus.WARN)
        elif result.scale >= 1.0:
            self.cmd_pub.publish(_rotation_only(msg) if result.rotation_only else msg)
            self._set_state(f'ALLOW turning unhealthy: {problem.kind}',
                            f'ALLOW turning on the spot ({guard.REASON_LOCALISATION}: '
                            f'{problem.text})', DiagnosticStatus.WARN)
        else:
            self.cmd_pub.publish(Twist())
            self._warn(f'stop {problem.kind}', f'{guard.REASON_LOCALISATION}: {problem.text}: '
                       'stopping')
            self._set_state(f'STOP {guard.REASON_LOCALISATION}: {problem.kind}',
                            f'STOP {guard.REASON_LOCALISATION}: {problem.text}',
                            DiagnosticStatus.ERROR)

    def publish_diagnostics(self) -> None:
        """Report the last decision, the pose and the margin on /diagnostics."""
        level, message = self._level, self._state[1] or 'no command yet'
        values = [KeyValue(key='zone file', value=self.zone_file or '(none)'),
                  KeyValue(key='commands', value=str(self.commands))]
        if self.zone_missing:
            level, message = DiagnosticStatus.ERROR, f'STOP {NO_ZONE_FILE}'
        if self.guard.zone is not None:
            pose, reason, _ = self.robot_pose()
            health = (f'{guard.REASON_LOCALISATION}: {self.localisation.text}'
                      if self.localisation is not None else 'healthy')
            values.append(KeyValue(key='localisation', value=health))
            if self.localisation is not None and level == DiagnosticStatus.OK:
                level, message = DiagnosticStatus.WARN, health
            if pose is None:
                values.append(KeyValue(key=guard.DIAGNOSTIC_POSE_KEY, value=reason))
                if level == DiagnosticStatus.OK:
                    level, message = DiagnosticStatus.WARN, reason
            else:
                clearance = float(self.guard.zone.clearance([pose[0]], [pose[1]])[0])
                values += [KeyValue(key=guard.DIAGNOSTIC_POSE_KEY,
                                    value=guard.pose_diagnostic(pose)),
                           KeyValue(key='distance to the border (m)',
                                    value=f'{clearance - self.guard.footprint_radius_m:.3f}')]
            values += [KeyValue(key='sigma_xy (m)', value=f'{self.sigma_xy_m:.3f}'),
                       KeyValue(key='sigma toward the border (m)',
                                value=f'{self.sigma_used_m:.3f}'),
                       KeyValue(key='covariance messages', value=str(self.covariance_count)),
                       KeyValue(key='margin (m)',
                                value=f'{self.guard.margin(self.sigma_used_m):.3f}')]
            if self._last_result is not None:
                values.append(KeyValue(key='last scale',
                                       value=f'{self._last_result.scale:.3f}'))
        self.diag_pub.publish(diagnostic_array(
            self.get_clock().now().to_msg(), DIAGNOSTIC_NAME, level, message, values))


def main(args=None) -> int:
    """Run the zone guard until Ctrl-C or SIGTERM."""
    return run_node(ZoneGuardNode, 'zone_guard', args)


if __name__ == '__main__':
    sys.exit(main())
