"""
collision_monitor: nav2_collision_monitor's node for the pip setup (node collision_monitor).

Every command on ``cmd_vel_in_topic`` ('cmd_vel_smoothed'; geometry_msgs/Twist, body
twist in ``base_frame_id``, REP-103) is checked at once against the zones and the latest
laser data, and the allowed twist is published on ``cmd_vel_out_topic`` ('cmd_vel'), one
output per input, as Nav2 does; with no input nothing is published. The rules are those
of :mod:`mecanum_safety.collision_monitor`: zones in order, the most restrictive
wins, 'stop' zeroes any command but one that moves straight away from what is in the
zone (Nav2 zeroes every command there; see the core's docstring).

Observation sources (``observation_sources``, default ['scan']): ``SRC.type`` 'scan'
(the only one supported), ``SRC.topic`` ('scan'; sensor_msgs/LaserScan, sensor-data
QoS), ``SRC.enabled``. The scan's frame is placed in ``base_frame_id`` ('base_link')
with the latest transform from /tf_static (or /tf); -inf ranges (REP-117: too close)
count as range_min. ``transform_tolerance`` (s, >= 0) is accepted for Nav2 parameter
files: lookups here never wait, so it has no effect.

A source that cannot be trusted stops the robot, with a throttled warning saying why;
the state says 'invalid source' (as Nav2), the source and what is wrong, e.g.
"STOP invalid source: scan blinded". What is wrong (the rules are the core's): 'no
data' (no LaserScan yet), 'no transform' (none for its frame yet), 'malformed' (no
beams or inconsistent fields: angle_max not angle_min + (beams - 1) x angle_increment,
range limits), 'stale' (stamp older than ``source_timeout``, s, > 0; Nav2's 0 "no
timeout" is not supported), 'stamped in the future' (more than ``max_future_stamp_s``,
s, >= 0, ahead of the node's clock), 'blinded' (fewer than ``min_valid_beam_fraction``,
in [0, 1], of the beams usable: finite within [range_min, range_max], or -inf; 0: no
check), 'frozen' (``max_identical_scans``, an integer >= 0, scans in a row equal to the
one before, once the lidar has shown noise; 0: no check). Nothing is latched: as soon
as the source's data is good again, commands pass.

Zones (``polygons``, Nav2's format): ``NAME.type`` polygon | circle, ``NAME.points``
(polygon vertices x1, y1, x2, y2, ... in m: a list, or Nav2 Jazzy's string
"[[x1, y1], [x2, y2], ...]"), ``NAME.radius`` (circle, m, centred on base_link),
``NAME.action_type`` stop | slowdown | limit | approach, ``NAME.min_points`` (4),
``NAME.slowdown_ratio`` (0.5), ``NAME.linear_limit`` (m/s, 0.5), ``NAME.angular_limit``
(rad/s, 0.5), ``NAME.time_before_collision`` (s, 2.0), ``NAME.simulation_time_step``
(s, 0.1), ``NAME.enabled`` (true), ``NAME.visualize`` (true here; Nav2: false).
Visualized zones are published as geometry_msgs/PolygonStamped in base_frame_id on
``~/NAME`` (transient local; circles as 32-gons) at start and, while subscribed, with
every command.

State: Nav2 publishes nav2_msgs/CollisionMonitorState, which this setup does not have;
``state_topic`` ('collision_monitor_state', '' for none) carries a std_msgs/String
"ACTION polygon_name" instead, per command while subscribed, ACTION being Nav2's name of the action
(DO_NOTHING, STOP, SLOWDOWN, APPROACH, LIMIT), e.g. "STOP PolygonStop",
"STOP invalid source: scan stale", "DO_NOTHING". Nav2's footprint_topic, velocity_polygon,
base_shift_correction and stop_pub_timeout are not supported. ``/diagnostics``
(diagnostic_msgs/DiagnosticArray, every second): the last decision, OK for DO_NOTHING,
WARN for slowing (SLOWDOWN, APPROACH, LIMIT), ERROR for STOP, with its reason.

Run-time parameters (``ros2 param set /collision_monitor source_timeout 0.5``; checked
as at start-up, within the same ranges, logged, see
:mod:`mecanum_control.runtime_parameters`), taken from the next command on:
``source_timeout``, ``max_future_stamp_s``, ``min_valid_beam_fraction``,
``max_identical_scans`` and each zone's scalars ``NAME.min_points``,
``NAME.slowdown_ratio``, ``NAME.linear_limit``, ``NAME.angular_limit``,
``NAME.time_before_collision``, ``NAME.simulation_time_step``. Read-only (``ros2 param
set`` says why): the zones' list, shapes, actions, ``enabled`` and ``visualize`` (the
safety design, config/collision_monitor.yaml), the sources, frames and topics (wired up
at start-up) and ``transform_tolerance`` (no effect here).
"""

from dataclasses import replace
import math
import re
import sys
from typing import Dict, List, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point32, PolygonStamped, Twist
from mecanum_control.log_throttle import KeyedThrottle
from mecanum_control.messages import diagnostic_array
from mecanum_control.node_main import run_node
from mecanum_control.runtime_parameters import RuntimeParameters, WIRING_REASON
from mecanum_localization.tf_listener import stamp_to_s, TransformListener
from mecanum_localization.transforms import TransformBuffer, TransformError
from mecanum_safety.collision_monitor import (
    CollisionMonitor, MonitorResult, scan_to_points, scan_usable_fraction, ScanRepeats,
    SourceData, ZERO, Zone)
import numpy as np
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import LaserScan
from std_msgs.msg import String
import yaml

#: Seconds between two warnings of the same kind.
WARNING_PERIOD_S = 2.0
#: Vertices of the polygon a circle zone is drawn as.
CIRCLE_VERTICES = 32
#: The core's action -> Nav2's CollisionMonitorState action name.
NAV2_ACTION = {'none': 'DO_NOTHING', 'stop': 'STOP', 'slowdown': 'SLOWDOWN',
               'approach': 'APPROACH', 'limit': 'LIMIT'}
INVALID_SOURCE = 'invalid source'
INVALID_COMMAND = 'invalid command'
NAME_PATTERN = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')
#: The source checks (run-time parameters, checked together by CollisionMonitor).
SOURCE_CHECKS = (('source_timeout', 2.0), ('min_valid_beam_fraction', 0.5),
                 ('max_identical_scans', 5), ('max_future_stamp_s', 0.1))
#: A zone's scalar settings (run-time parameters NAME.KEY) and their defaults.
ZONE_SETTINGS = (('min_points', 4), ('slowdown_ratio', 0.5), ('linear_limit', 0.5),
                 ('angular_limit', 0.5), ('time_before_collision', 2.0),
                 ('simulation_time_step', 0.1))
#: Why the other parameters are read-only (the zones' and sources' own: see the node).
READ_ONLY_REASONS = {
    'polygons': ('the zones are the safety design (config/collision_monitor.yaml), not a '
                 'tuning: edit the file and restart'),
    'observation_sources': ('the sources are wired up at start-up: removing one at run '
                            'time would blind the monitor; edit the file and restart'),
    'transform_tolerance': ('accepted for Nav2 parameter files only: lookups here never '
                            'wait, so it has no effect'),
    'base_frame_id': WIRING_REASON,
    'cmd_vel_in_topic': WIRING_REASON,
    'cmd_vel_out_topic': WIRING_REASON,
    'state_topic': WIRING_REASON,
}
ZONE_REASON = ("a zone's shape, action and whether it acts are the safety design "
               '(config/collision_monitor.yaml), not a tuning: edit the file and restart')
SOURCE_REASON = ('an observation source is wired up at start-up (its subscription): '
                 'turning it off at run time would blind the monitor; restart to change it')


def zone_parameter_error(name: str, error: ValueError) -> ValueError:
    """Return a Zone's ValueError (zone 'NAME': key ...) as 'parameter NAME.key ...'."""
    text = str(error)
    prefix = f'zone {name!r}: '
    if text.startswith(prefix):
        text = f'parameter {name}.{text[len(prefix):]}'
    return ValueError(text)


def source_checks(values: Dict[str, float]) -> CollisionMonitor:
    """Return a CollisionMonitor without zones checking the source checks' values."""
    try:
        return CollisionMonitor([], **values)
    except ValueError as error:
        raise ValueError(f'parameter {error}') from None


def parse_points(name: str, value) -> List[Tuple[float, float]]:
    """
    Return the vertices [(x, y), ...] of Nav2's ``points`` parameter (not yet checked).

    value: a flat list x1, y1, x2, y2, ... (Nav2 Humble/Iron) or a string holding it or
    a list of [x, y] pairs (Nav2 Jazzy). Raises ValueError naming the parameter.
    """
    if isinstance(value, str):
        try:
            value = yaml.safe_load(value)
        except yaml.YAMLError:
            raise ValueError(f'parameter {name} is not a list of numbers: {value!r}') from None
    if isinstance(value, (str, bytes)) or not hasattr(value, '__len__'):
        raise ValueError(f'parameter {name} must be a list x1, y1, x2, y2, ... or '
                         f'"[[x1, y1], ...]", got {value!r}')
    items = list(value)
    if items and all(isinstance(item, (list, tuple)) for item in items):
        if any(len(item) != 2 for item in items):
            raise ValueError(f'parameter {name} must be [x, y] pairs, got {value!r}')
        return [(item[0], item[1]) for item in items]
    if len(items) % 2:
        raise ValueError(f'parameter {name} must hold an even number of values '
                         f'(x1, y1, x2, y2, ...), got {len(items)}')
    return [(items[i], items[i + 1]) for i in range(0, len(items), 2)]


def zone_outline(zone: Zone) -> List[Tuple[float, float]]:
    """Return a zone's outline vertices in base_link (a circle as a CIRCLE_VERTICES-gon)."""
    if zone.radius is None:
        return [(float(x), float(y)) for x, y in zone.points]
    angles = np.arange(CIRCLE_VERTICES) * (2.0 * math.pi / CIRCLE_VERTICES)
    return [(zone.radius * math.cos(a), zone.radius * math.sin(a)) for a in angles]


class _Source:
    """One observation source: its parameters, latest scan and that scan's health."""

    def __init__(self, name: str, topic: str, enabled: bool):
        self.name = name
        self.topic = topic
        self.enabled = enabled
        self.scan: Optional[LaserScan] = None
        self.received = 0
        self.cache_key: Optional[tuple] = None
        self.points = np.zeros((0, 2))
        self.repeats = ScanRepeats()
        self.identical_scans = 0
        self.usable_fraction = 0.0
        self.invalid = ''

    def on_scan(self, msg: LaserScan) -> None:
        """Keep the latest scan, how much of it is usable and how often it repeats."""
        self.scan = msg
        self.received += 1
        self.identical_scans = self.repeats.update(msg.ranges)
        try:
            self.usable_fraction = scan_usable_fraction(
                msg.ranges, msg.angle_min, msg.angle_max, msg.angle_increment,
                msg.range_min, msg.range_max)
            self.invalid = ''
        except ValueError as error:
            self.usable_fraction, self.invalid = 0.0, str(error)


class CollisionMonitorNode(Node):
    """Limits every command by the zones around the robot and the laser data."""

    def __init__(self, **node_options):
        super().__init__('collision_monitor', **node_options)
        self.runtime = RuntimeParameters(self, READ_ONLY_REASONS)
        dynamic = ParameterDescriptor(dynamic_typing=True)
        self.base_frame_id = str(self.declare_parameter('base_frame_id', 'base_link').value)
        cmd_in = str(self.declare_parameter('cmd_vel_in_topic', 'cmd_vel_smoothed').value)
        cmd_out = str(self.declare_parameter('cmd_vel_out_topic', 'cmd_vel').value)
        state_topic = str(self.declare_parameter('state_topic', 'collision_monitor_state')
                          .value)
        # CollisionMonitor checks them (kind None: as they are, as before).
        checks = {name: self.runtime.declare(name, default, kind=None)
                  for name, default in SOURCE_CHECKS}
        tolerance = self.declare_parameter('transform_tolerance', 0.1, dynamic).value
        if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) \
                or not (math.isfinite(tolerance) and tolerance >= 0.0):
            raise ValueError(f'parameter transform_tolerance must be a finite number >= 0, '
                             f'got {tolerance!r}')
        polygon_names = self.declare_parameter('polygons', Parameter.Type.STRING_ARRAY).value
        if not polygon_names:
            raise ValueError('parameter polygons is empty: list the zones (see '
                             'config/collision_monitor.yaml)')
        source_names = self.declare_parameter('observation_sources', ['scan']).value
        if not source_names:
            raise ValueError('parameter observation_sources is empty: list the sources')
        for key, names in (('polygons', polygon_names), ('observation_sources', source_names)):
            if len(set(names)) != len(names):
                raise ValueError(f'parameter {key} has a name twice: {list(names)}')
            for name in names:
                if not NAME_PATTERN.match(name):
                    raise ValueError(f'parameter {key}: names must be letters, digits and _, '
                                     f'starting with a letter, got {name!r}')
        zones, self.visualized = [], []
        for name in polygon_names:
            zone, visualize = self._declare_zone(name, dynamic)
            zones.append(zone)
            if visualize and zone.enabled:
                self.visualized.append(zone)
        try:
            self.monitor = CollisionMonitor(zones, **checks)
        except ValueError as error:
            raise ValueError(f'parameter {error}') from None
        self.runtime.joint(tuple(checks), check=source_checks, apply=self._set_source_checks)
        for zone in zones:
            self.runtime.joint(tuple(f'{zone.name}.{key}' for key, _ in ZONE_SETTINGS),
                               check=lambda values, name=zone.name: self._changed_zone(
                                   name, values),
                               apply=lambda values, name=zone.name: self._set_zone(
                                   self._changed_zone(name, values)))
        self.runtime.add_reasons({f'{name}.*': ZONE_REASON for name in polygon_names})
        self.runtime.add_reasons({f'{name}.*': SOURCE_REASON for name in source_names})
        self.sources = [self._declare_source(name) for name in source_names]
        self.frames = TransformBuffer()
        self._warnings = KeyedThrottle(WARNING_PERIOD_S)
        self._last_state: Optional[Tuple[str, str]] = None
        self._last_reason = ''
        self.commands = 0

        self.cmd_pub = self.create_publisher(Twist, cmd_out, 10)
        self.state_pub = (self.create_publisher(String, state_topic, 10)
                          if state_topic else None)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.polygon_pubs = {zone.name: self.create_publisher(PolygonStamped, f'~/{zone.name}',
                                                              latched)
                             for zone in self.visualized}
        self.tf_listener = TransformListener(self, self.frames)
        for source in self.sources:
            self.create_subscription(LaserScan, source.topic, source.on_scan,
                                     qos_profile_sensor_data)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.cmd_sub = self.create_subscription(Twist, cmd_in, self.on_command, 10)
        self.diag_timer = self.create_timer(1.0, self.publish_diagnostics)
        self.publish_polygons()
        self.runtime.start()
        zones_text = ', '.join(f'{z.name} ({z.action_type}{"" if z.enabled else ", disabled"})'
                               for z in zones)
        sources_text = ', '.join(f'{s.name} ({s.topic})' for s in self.sources)
        self.get_logger().info(
            f'Collision monitor started: {self.cmd_sub.topic_name} -> '
            f'{self.cmd_pub.topic_name}; zones {zones_text}; sources {sources_text} '
            f'in {self.base_frame_id}')

    # -- parameters ---------------------------------------------------------------------

    def _declare_zone(self, name: str, dynamic: ParameterDescriptor) -> Tuple[Zone, bool]:
        """Declare one polygon's parameters; return its Zone and whether to visualize it."""
        def declare(key: str, default):
            return self.declare_parameter(f'{name}.{key}', default, dynamic).value

        kind = declare('type', '')
        if kind not in ('polygon', 'circle'):
            raise ValueError(f'parameter {name}.type must be polygon or circle, got {kind!r}')
        points, radius = declare('points', None), declare('radius', None)
        shape = {}
        if kind == 'polygon':
            if points is None:
                raise ValueError(f'parameter {name}.points is required for a polygon')
            shape['points'] = parse_points(f'{name}.points', points)
        else:
            if radius is None:
                raise ValueError(f'parameter {name}.radius is required for a circle')
            shape['radius'] = radius
        values = {key: declare(key, default) for key, default in (
            ('action_type', ''), ('enabled', True))}
        # Zone checks them (kind None: as they are, as before).
        values.update({key: self.runtime.declare(f'{name}.{key}', default, kind=None)
                       for key, default in ZONE_SETTINGS})
        visualize = declare('visualize', True)
        if not isinstance(visualize, bool):
            raise ValueError(f'parameter {name}.visualize must be a bool, got {visualize!r}')
        try:
            return Zone(name, **shape, **values), visualize
        except ValueError as error:
            raise zone_parameter_error(name, error) from None

    def _changed_zone(self, name: str, values: Dict) -> Zone:
        """Return zone name with the settings values (NAME.KEY: value); ValueError if bad."""
        zone = next(zone for zone in self.monitor.zones if zone.name == name)
        settings = {key: values[f'{name}.{key}'] for key, _ in ZONE_SETTINGS}
        try:
            return replace(zone, **settings)
        except ValueError as error:
            raise zone_parameter_error(name, error) from None

    def _set_zone(self, zone: Zone) -> None:
        """Use a zone's new (checked) settings from the next command on."""
        self.monitor.zones = [zone if old.name == zone.name else old
                              for old in self.monitor.zones]
        self.visualized = [zone if old.name == zone.name else old for old in self.visualized]

    def _set_source_checks(self, values: Dict) -> None:
        """Use the new (checked) source checks from the next command on."""
        checked = source_checks(values)
        self.monitor.source_timeout = checked.source_timeout
        self.monitor.max_future_stamp_s = checked.max_future_stamp_s
        self.monitor.min_valid_beam_fraction = checked.min_valid_beam_fraction
        self.monitor.max_identical_scans = checked.max_identical_scans

    def _declare_source(self, name: str) -> _Source:
        """Declare one observation source's parameters."""
        kind = self.declare_parameter(f'{name}.type', 'scan').value
        if kind != 'scan':
            raise ValueError(f'parameter {name}.type: only scan (sensor_msgs/LaserScan) is '
                             f'supported, got {kind!r}')
        topic = str(self.declare_parameter(f'{name}.topic', 'scan').value)
        enabled = self.declare_parameter(f'{name}.enabled', True).value
        return _Source(name, topic, bool(enabled))

    # -- helpers ------------------------------------------------------------------------

    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _warn(self, key: str, text: str) -> None:
        """Log a warning, at most once per WARNING_PERIOD_S for the same key."""
        if self._warnings.ready(key):
            self.get_logger().warning(text)

    def _source_data(self, now_s: float) -> Tuple[List[SourceData], str, str]:
        """
        Return the enabled sources' data in base_frame_id, '', ''.

        Or [], what is wrong with a source ('scan no data') and why it is unusable.
        """
        data = []
        for source in self.sources:
            if not source.enabled:
                continue
            scan = source.scan
            if scan is None:
                return [], f'{source.name} no data', (
                    f'source {source.name!r}: no LaserScan on {source.topic} yet')
            if source.invalid:
                return [], f'{source.name} malformed', (
                    f'source {source.name!r}: invalid LaserScan: {source.invalid}')
            frame = scan.header.frame_id.lstrip('/') or self.base_frame_id
            try:
                mount = self.frames.lookup(self.base_frame_id, frame)
            except TransformError as error:
                return [], f'{source.name} no transform', (
                    f'source {source.name!r}: no transform {self.base_frame_id} <- {frame} '
                    f'yet (from /tf_static or /tf): {error}')
            cache_key = (source.received, mount)
            if cache_key != source.cache_key:
                try:
                    source.points = scan_to_points(
                        scan.ranges, scan.angle_min, scan.angle_increment, scan.range_min,
                        scan.range_max, (mount.x, mount.y, mount.yaw),
                        too_close_as_range_min=True)
                except ValueError as error:
                    return [], f'{source.name} malformed', (
                        f'source {source.name!r}: invalid LaserScan: {error}')
                source.cache_key = cache_key
            data.append(SourceData(source.name, source.points,
                                   now_s - stamp_to_s(scan.header.stamp),
                                   source.usable_fraction, source.identical_scans))
        return data, '', ''

    # -- commands -----------------------------------------------------------------------

    def on_command(self, msg: Twist) -> None:
        """Publish the allowed twist for one command, the state and the zones."""
        command = (msg.linear.x, msg.linear.y, msg.angular.z)
        self.commands += 1
        if not all(math.isfinite(v) for v in command):
            self._warn('command', f'non-finite command {command}: publishing zero')
            result, zone = MonitorResult(ZERO, 'stop'), INVALID_COMMAND
        else:
            sources, fault, problem = self._source_data(self._now_s())
            if problem:
                result = MonitorResult(ZERO, 'stop', reason=f'{problem}: stopping',
                                       fault=fault)
            else:
                result = self.monitor.process(command, sources)
            zone = result.zone
            if not zone and result.action == 'stop':
                zone = f'{INVALID_SOURCE}: {result.fault}' if result.fault else INVALID_SOURCE
                self._warn(zone, result.reason)
        out = Twist()
        out.linear.x, out.linear.y, out.angular.z = (float(v) for v in result.twist)
        self.cmd_pub.publish(out)
        action = NAV2_ACTION[result.action]
        self._last_reason = result.reason or zone
        if (action, zone) != self._last_state:
            self._last_state = (action, zone)
            if action == 'DO_NOTHING':
                self.get_logger().info('Robot to continue normal operation')
            else:
                self.get_logger().info(f'Robot to {result.action} due to {zone}: '
                                       f'{result.reason or zone}')
        if self.state_pub is not None and self.state_pub.get_subscription_count() > 0:
            self.state_pub.publish(String(data=f'{action} {zone}'.strip()))
        self.publish_polygons(only_if_subscribed=True)

    def publish_diagnostics(self) -> None:
        """Report the last decision on /diagnostics: OK, WARN (slowing) or ERROR (stopping)."""
        action, zone = self._last_state or ('DO_NOTHING', '')
        level = {'DO_NOTHING': DiagnosticStatus.OK, 'STOP': DiagnosticStatus.ERROR}.get(
            action, DiagnosticStatus.WARN)
        message = f'{action} {zone}'.strip() if self._last_state else 'no command yet'
        values = [KeyValue(key='commands', value=str(self.commands)),
                  KeyValue(key='reason', value=self._last_reason)]
        self.diag_pub.publish(diagnostic_array(
            self.get_clock().now().to_msg(), 'mecanum_safety: collision_monitor', level,
            message, values))

    def publish_polygons(self, only_if_subscribed: bool = False) -> None:
        """
        Publish the visualized zones in base_frame_id, stamped now.

        only_if_subscribed: skip zones nobody listens to (the per-command refresh;
        the publishers are latched, so a late subscriber still gets the first one).
        """
        stamp = self.get_clock().now().to_msg()
        for zone in self.visualized:
            publisher = self.polygon_pubs[zone.name]
            if only_if_subscribed and publisher.get_subscription_count() == 0:
                continue
            msg = PolygonStamped()
            msg.header.stamp = stamp
            msg.header.frame_id = self.base_frame_id
            msg.polygon.points = [Point32(x=x, y=y, z=0.0) for x, y in zone_outline(zone)]
            publisher.publish(msg)


def main(args=None) -> int:
    """Run the collision monitor until Ctrl-C or SIGTERM."""
    return run_node(CollisionMonitorNode, 'collision_monitor', args)


if __name__ == '__main__':
    sys.exit(main())
