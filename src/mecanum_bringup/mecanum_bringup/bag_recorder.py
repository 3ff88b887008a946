"""
bag_recorder: ``ros2 bag record -s mcap`` for setups without rosbag2 (pip ROS).

Records topics into a rosbag2 bag (MCAP storage, :mod:`mecanum_bringup.bag_writer`):
``<output>/<name>_0.mcap`` and ``<output>/metadata.yaml``, readable by ``ros2 bag
info``/``play`` (Jazzy), the Foxglove app and the ``mcap`` tools. Messages are taken
serialized (raw CDR bytes, never deserialized). Topics are discovered every
``discovery_period_s`` (wall clock); a topic is subscribed once it has a publisher,
with a QoS matching every offer (rosbag2's rule: reliable only if all publishers are,
transient local only if all are, so latched /tf_static, /map, /robot_description
are recorded too), depth ``SUBSCRIPTION_DEPTH``.

Times: log time = receive time, from the node clock with ``use_sim_time``
(simulated time; messages received before the first /clock are kept and stamped with
the first simulated time), else the system clock when the message is taken; publish
time = log time (as rosbag2 before Jazzy; Jazzy's rosbag2 writes the publisher's send
time, which rclpy 7.1's EventsExecutor cannot hand to a callback: SystemError "null
argument"). The EventsExecutor, not rclpy's SingleThreadedExecutor: the latter rebuilt
its wait set for each message and took 85 % of the recorder's CPU (54 CPU s of the
demo's 196, recording 241 000 messages).
Ctrl-C/SIGTERM finish the bag (index, summary, metadata.yaml): nothing is lost.

Parameters: ``output`` (bag directory, must not exist; '' = rosbag2_YYYY_MM_DD-HH_MM_SS),
``topics`` (list of names; empty or unset = all), ``exclude`` (regex; matching topics
are not recorded), ``include_hidden_topics`` (false), ``discovery_period_s`` (1.0),
``max_cache_size`` (bytes buffered per MCAP chunk, 786432), ``compression``
('none', 'zstd', 'lz4').
"""

import functools
import importlib
import os
import sys
import time
from typing import Dict, List, Sequence

from mecanum_bringup.bag_writer import (
    adapted_request, BagWriter, compile_pattern, DEFAULT_MAX_CACHE_SIZE, is_hidden_topic,
    OfferedQos)
from mecanum_bringup.message_definitions import split_type_name
from mecanum_control.log_throttle import KeyedThrottle
from mecanum_control.node_main import run_node
from mecanum_control.parameters import declare_number, positive
from mecanum_control.runtime_parameters import read_only_parameters
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

#: History depth of each recording subscription (Python takes longer per message than C++).
SUBSCRIPTION_DEPTH = 100
#: Messages kept while waiting for the first /clock (use_sim_time); older ones are dropped.
MAX_PENDING = 10000
_OFFER_NAMES = {
    'history': ('system_default', 'keep_last', 'keep_all'),
    'reliability': ('system_default', 'reliable', 'best_effort', 'best_available'),
    'durability': ('system_default', 'transient_local', 'volatile', 'best_available'),
    'liveliness': ('system_default', 'automatic', 'manual_by_topic', 'best_available'),
}


def message_class(type_name: str):
    """Return the message class of 'pkg/msg/Type'; LookupError if it is not installed."""
    package, namespace, name = split_type_name(type_name)
    try:
        return getattr(importlib.import_module(f'{package}.{namespace}'), name)
    except (ImportError, AttributeError) as error:
        raise LookupError(f'message type {type_name} is not installed ({error})') from None


def offered_qos(profile: QoSProfile) -> OfferedQos:
    """Return the rosbag2 view of a publisher's offered rclpy QoSProfile."""
    def policy(kind: str) -> str:
        value = getattr(profile, kind)
        name = getattr(value, 'name', '').lower()
        return name if name in _OFFER_NAMES[kind] else 'unknown'

    def nanoseconds(duration) -> int:
        return max(0, int(getattr(duration, 'nanoseconds', 0)))

    return OfferedQos(
        history=policy('history'), depth=max(0, int(profile.depth)),
        reliability=policy('reliability'), durability=policy('durability'),
        deadline_ns=nanoseconds(profile.deadline), lifespan_ns=nanoseconds(profile.lifespan),
        liveliness=policy('liveliness'),
        liveliness_lease_duration_ns=nanoseconds(profile.liveliness_lease_duration),
        avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions))


def subscription_qos(offers: Sequence[OfferedQos], depth: int) -> QoSProfile:
    """Return a subscription QoS (keep last depth) matching every offer (latched data too)."""
    reliable, transient_local = adapted_request(offers)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if transient_local
                    else DurabilityPolicy.VOLATILE))


def raw_subscription(node: Node, msg_class, topic: str, callback, qos: QoSProfile):
    """
    Subscribe to serialized messages, without rclpy's default QoS event handlers.

    The QoS is chosen to match every publisher, so the incompatible-QoS warning has
    nothing to report, and each event handler costs the executor time per wait.
    """
    return node.create_subscription(
        msg_class, topic, callback, qos, raw=True,
        event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False))


def type_hash_string(type_hash) -> str:
    """Return an endpoint's type hash as 'RIHS01_<hex>', '' when unknown."""
    text = str(type_hash) if type_hash is not None else ''
    return text if text.startswith('RIHS') else ''


class BagRecorder(Node):
    """Records topics, serialized, into a rosbag2 MCAP bag."""

    def __init__(self):
        super().__init__('bag_recorder')
        output = self.declare_parameter('output', '').value
        topics = self.declare_parameter('topics', Parameter.Type.STRING_ARRAY).value or []
        exclude = self.declare_parameter('exclude', '').value
        self.include_hidden = self.declare_parameter('include_hidden_topics', False).value
        discovery_period_s = positive(
            'discovery_period_s', declare_number(self, 'discovery_period_s', 1.0))
        max_cache_size = self.declare_parameter('max_cache_size', DEFAULT_MAX_CACHE_SIZE).value
        compression = self.declare_parameter('compression', 'none').value
        for name, value, kind in (('output', output, str), ('exclude', exclude, str),
                                  ('include_hidden_topics', self.include_hidden, bool),
                                  ('compression', compression, str)):
            if not isinstance(value, kind):
                raise ValueError(f'parameter {name} must be a {kind.__name__}, got {value!r}')
        self.exclude = compile_pattern('exclude', exclude)
        self.topics = {self.absolute_name(t) for t in topics}
        self.use_sim_time = bool(self.get_parameter('use_sim_time').value)
        output = output or time.strftime('rosbag2_%Y_%m_%d-%H_%M_%S')
        try:
            self.writer = BagWriter(output, max_cache_size, compression,
                                    os.environ.get('ROS_DISTRO', 'jazzy'))
        except OSError as error:  # FileExistsError, permissions
            raise ValueError(f'parameter output: {error}') from None
        except ValueError as error:  # max_cache_size, compression
            raise ValueError(f'parameter {error}') from None
        self.recorded: Dict[str, object] = {}
        self.skipped = set()
        self.pending: List[tuple] = []
        self.throttle = KeyedThrottle(5.0)

        self.discover()
        self.discovery_timer = self.create_timer(
            discovery_period_s, self.discover, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(
            f'Recording to {self.writer.mcap_path}: '
            f'{", ".join(sorted(self.topics)) if self.topics else "all topics"}'
            f'{" on simulated time" if self.use_sim_time else ""}')
        read_only_parameters(self)

    def absolute_name(self, topic) -> str:
        """Return a topics entry as an absolute name (relative to the node's namespace)."""
        if not isinstance(topic, str) or not topic:
            raise ValueError(f'parameter topics must hold topic names, got {topic!r}')
        if topic.startswith('/'):
            return topic
        return self.get_namespace().rstrip('/') + '/' + topic

    def wanted(self, topic: str) -> bool:
        """Tell whether a topic is to be recorded."""
        if self.exclude is not None and self.exclude.search(topic):
            return False
        if self.topics:
            return topic in self.topics
        return self.include_hidden or not is_hidden_topic(topic)

    def discover(self) -> None:
        """Subscribe to wanted topics that appeared (with a publisher) since the last look."""
        self.write_pending()
        for topic, types in self.get_topic_names_and_types():
            if topic in self.recorded or topic in self.skipped or not self.wanted(topic):
                continue
            if len(types) != 1:
                if self.throttle.ready(topic):
                    self.get_logger().warning(
                        f'Not recording {topic} (yet): it has several types {types}')
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if not publishers:
                continue  # wait for a publisher, so the QoS matches its offer
            self.subscribe(topic, types[0], publishers)

    def subscribe(self, topic: str, type_name: str, publishers) -> None:
        """Add the topic to the bag and subscribe to its serialized messages."""
        try:
            msg_class = message_class(type_name)
        except LookupError as error:
            self.skipped.add(topic)
            self.get_logger().warning(f'Not recording {topic}: {error}')
            return
        offers = [offered_qos(p.qos_profile) for p in publishers]
        self.writer.add_topic(topic, type_name, offers,
                              type_hash_string(publishers[0].topic_type_hash))
        if type_name in self.writer.missing_definitions:
            self.get_logger().warning(
                f'{topic}: {self.writer.missing_definitions[type_name]}; recorded with an '
                f"'unknown' schema (readers without {type_name} cannot decode it)")
        qos = subscription_qos(offers, SUBSCRIPTION_DEPTH)
        self.recorded[topic] = raw_subscription(
            self, msg_class, topic, functools.partial(self.on_message, topic), qos)
        self.get_logger().info(
            f'Subscribed to topic {topic} ({type_name}, {qos.reliability.name.lower()}, '
            f'{qos.durability.name.lower()})')

    def on_message(self, topic: str, data: bytes) -> None:
        """Write one serialized message at its receive time."""
        if self.use_sim_time:
            log_time_ns = self.get_clock().now().nanoseconds
            if log_time_ns <= 0:  # simulated time has not started: keep it for later
                if len(self.pending) >= MAX_PENDING:
                    self.pending.pop(0)
                    if self.throttle.ready('pending'):
                        self.get_logger().warning(
                            f'No /clock yet: keeping only the last {MAX_PENDING} messages')
                self.pending.append((topic, data))
                return
            self.write_pending()
        else:
            log_time_ns = time.time_ns()
        self.write(topic, data, log_time_ns, log_time_ns)

    def write_pending(self, log_time_ns: int = 0) -> None:
        """Write the messages kept before simulated time started, at its first time."""
        if not self.pending:
            return
        log_time_ns = log_time_ns or self.get_clock().now().nanoseconds
        if log_time_ns <= 0:
            return
        pending, self.pending = self.pending, []
        for topic, data in pending:
            self.write(topic, data, log_time_ns, log_time_ns)

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int) -> None:
        """Write to the bag; a failure (disk full) is logged, throttled, not raised."""
        try:
            self.writer.write(topic, data, log_time_ns, publish_time_ns)
        except (OSError, ValueError) as error:
            if self.throttle.ready(('write', topic)):
                self.get_logger().error(f'Cannot record a message of {topic}: {error}')

    def close(self) -> None:
        """Write what is still held and finish the bag (summary, index, metadata.yaml)."""
        if self.writer.closed:
            return
        if self.pending:
            self.get_logger().warning(
                f'{len(self.pending)} messages arrived before simulated time started; '
                'recorded at time 0')
            for topic, data in self.pending:
                self.write(topic, data, 0, 0)
            self.pending = []
        missing = sorted(self.topics - set(self.recorded))
        if missing:
            self.get_logger().warning(f'Never recorded (no publisher seen): {", ".join(missing)}')
        metadata = self.writer.close()
        self.get_logger().info(
            f'Bag {self.writer.directory} closed: {metadata["message_count"]} messages on '
            f'{len(metadata["topics_with_message_count"])} topics, '
            f'{metadata["duration"]["nanoseconds"] * 1e-9:.3f} s')


def main(args=None) -> int:
    """Run the bag_recorder node until Ctrl-C or SIGTERM."""
    return run_node(BagRecorder, 'bag_recorder', args)


if __name__ == '__main__':
    sys.exit(main())
