"""
foxglove_bridge: the live view of the robot in the Foxglove app (foxglove_bridge's job).

Serves the Foxglove WebSocket protocol (foxglove-sdk) on ``address``:``port`` and
advertises every ROS topic whose name matches one of ``topic_whitelist`` (regular
expressions, whole name) and has a publisher, discovered every ``discovery_period_s``
(wall clock; topics that lose all publishers are unadvertised). Each channel carries
the ROS type as schema (encoding 'ros2msg', the complete definition) and the
messages as received (serialized CDR, never deserialized: message encoding 'cdr'),
so the app decodes them as it does with the ROS foxglove_bridge. Log times are the
node clock's receive times (simulated time with ``use_sim_time``, which also
broadcasts the simulated time to clients).

Latched topics (every publisher transient local: /tf_static, /map,
/robot_description): the latest messages are kept, as many as the topic has
publishers (one each when each publishes once, as latched publishers do), and
re-sent when a client subscribes, so a viewer that connects later still gets them.
foxglove-sdk cannot address one client from Python, so the re-send goes to every
client subscribed to that topic; the others get a duplicate of a latched message,
which changes nothing they show.

Parameters: ``port`` (8765; 0 = any free port, logged), ``address`` ('127.0.0.1':
this machine only; '0.0.0.0' to view from another computer, which then also sees
everything on the robot), ``topic_whitelist`` (['.*']), ``include_hidden_topics``
(false), ``discovery_period_s`` (1.0), ``use_sim_time``.
"""

from collections import deque
from dataclasses import dataclass
import functools
import re
import sys
from typing import Deque, Dict, List

import foxglove
from foxglove.websocket import Capability, ServerListener
from mecanum_bringup.bag_recorder import (
    message_class, offered_qos, raw_subscription, subscription_qos)
from mecanum_bringup.bag_writer import is_hidden_topic
from mecanum_bringup.message_definitions import message_definition
from mecanum_control.log_throttle import KeyedThrottle
from mecanum_control.node_main import run_node
from mecanum_control.parameters import declare_number, positive
from mecanum_control.runtime_parameters import read_only_parameters
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

#: History depth of the bridge's subscriptions (a viewer wants the newest).
SUBSCRIPTION_DEPTH = 10
#: Period of re-sending latched messages to new subscribers and of the time broadcast, s.
SERVICE_PERIOD_S = 0.1


@dataclass
class BridgedTopic:
    """A ROS topic shown as a Foxglove channel."""

    type_name: str
    channel: foxglove.Channel
    subscription: object
    latched: Deque[bytes]


class SubscribeListener(ServerListener):
    """foxglove-sdk server listener: notes which channels got a new subscriber."""

    def __init__(self):
        """Start with no subscription noted."""
        self.subscribed: Deque[int] = deque()

    def on_subscribe(self, client, channel) -> None:
        """Note the channel (called from the server's thread; handled by the node)."""
        self.subscribed.append(channel.id)


class FoxgloveBridge(Node):
    """Relays ROS topics, serialized, to Foxglove WebSocket clients."""

    def __init__(self):
        super().__init__('foxglove_bridge')
        port = self.declare_parameter('port', 8765).value
        address = self.declare_parameter('address', '127.0.0.1').value
        whitelist = self.declare_parameter('topic_whitelist', ['.*']).value or []
        self.include_hidden = self.declare_parameter('include_hidden_topics', False).value
        discovery_period_s = positive(
            'discovery_period_s', declare_number(self, 'discovery_period_s', 1.0))
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise ValueError(f'parameter port must be an integer 0..65535, got {port!r}')
        if not isinstance(address, str) or not address:
            raise ValueError(f'parameter address must be a host address, got {address!r}')
        if not isinstance(self.include_hidden, bool):
            raise ValueError('parameter include_hidden_topics must be a bool, '
                             f'got {self.include_hidden!r}')
        self.whitelist = []
        for pattern in whitelist:
            try:
                self.whitelist.append(re.compile(pattern))
            except (re.error, TypeError) as error:
                raise ValueError(f'parameter topic_whitelist: {pattern!r} is not a valid '
                                 f'regular expression ({error})') from None
        self.use_sim_time = bool(self.get_parameter('use_sim_time').value)
        self.foxglove_context = foxglove.Context()
        self.listener = SubscribeListener()
        try:
            self.server = foxglove.start_server(
                name='mecanum foxglove_bridge', host=address, port=port,
                capabilities=[Capability.Time] if self.use_sim_time else [],
                server_listener=self.listener, supported_encodings=['cdr'],
                context=self.foxglove_context)
        except Exception as error:  # noqa: B902 - the SDK's error types are not public
            raise ValueError(f'parameters address/port: cannot serve on {address}:{port} '
                             f'({error})') from None
        self.bridged: Dict[str, BridgedTopic] = {}
        self.skipped = set()
        self.throttle = KeyedThrottle(5.0)
        self.last_time_ns = 0

        self.discover()
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.discovery_timer = self.create_timer(discovery_period_s, self.discover, clock=steady)
        self.service_timer = self.create_timer(SERVICE_PERIOD_S, self.serve, clock=steady)
        if not self.whitelist:
            self.get_logger().warning('topic_whitelist is empty: no topic is shown')
        self.get_logger().info(
            f'Foxglove WebSocket server listening on ws://{address}:{self.server.port}'
            f'{" (simulated time)" if self.use_sim_time else ""}')
        read_only_parameters(self)

    def wanted(self, topic: str) -> bool:
        """Tell whether a topic is to be shown."""
        if not self.include_hidden and is_hidden_topic(topic):
            return False
        return any(pattern.fullmatch(topic) for pattern in self.whitelist)

    def discover(self) -> None:
        """Advertise topics that appeared, unadvertise those without publishers."""
        present = {}
        for topic, types in self.get_topic_names_and_types():
            if self.wanted(topic) and topic not in self.skipped:
                present[topic] = types
        for topic in list(self.bridged):
            types = present.get(topic)
            publishers = self.get_publishers_info_by_topic(topic) if types else []
            if not publishers or types != [self.bridged[topic].type_name]:
                self.remove(topic)
            else:
                self.update_latched_depth(topic, publishers)
        for topic, types in present.items():
            if topic in self.bridged:
                continue
            if len(types) != 1:
                if self.throttle.ready(topic):
                    self.get_logger().warning(f'Not showing {topic}: several types {types}')
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if publishers:
                self.add(topic, types[0], publishers)

    def add(self, topic: str, type_name: str, publishers: List) -> None:
        """Advertise a channel for the topic and subscribe to its serialized messages."""
        try:
            msg_class = message_class(type_name)
            definition = message_definition(type_name)
        except LookupError as error:
            self.skipped.add(topic)
            self.get_logger().warning(f'Not showing {topic}: {error}')
            return
        schema = foxglove.Schema(name=type_name, encoding='ros2msg',
                                 data=definition.encode('utf-8'))
        channel = foxglove.Channel(topic, schema=schema, message_encoding='cdr',
                                   context=self.foxglove_context)
        offers = [offered_qos(p.qos_profile) for p in publishers]
        subscription = raw_subscription(
            self, msg_class, topic, functools.partial(self.on_message, topic),
            subscription_qos(offers, SUBSCRIPTION_DEPTH))
        self.bridged[topic] = BridgedTopic(type_name, channel, subscription, deque(maxlen=0))
        self.update_latched_depth(topic, publishers)
        self.get_logger().info(f'Advertised {topic} ({type_name})')

    def update_latched_depth(self, topic: str, publishers: List) -> None:
        """Keep as many messages as a latched topic has publishers (none for other topics)."""
        entry = self.bridged[topic]
        latched = all(offered_qos(p.qos_profile).durability == 'transient_local'
                      for p in publishers)
        depth = len(publishers) if latched else 0
        if entry.latched.maxlen != depth:
            entry.latched = deque(entry.latched, maxlen=depth)

    def remove(self, topic: str) -> None:
        """Unadvertise a topic and drop its subscription."""
        entry = self.bridged.pop(topic)
        self.destroy_subscription(entry.subscription)
        entry.channel.close()
        self.get_logger().info(f'Unadvertised {topic} (no publisher)')

    def now_ns(self):
        """Node clock time in ns, or None (the SDK's wall time) before simulated time starts."""
        now = self.get_clock().now().nanoseconds
        return now if now > 0 else None

    def on_message(self, topic: str, data: bytes) -> None:
        """Relay one serialized message (and keep it if the topic is latched)."""
        entry = self.bridged.get(topic)
        if entry is None:
            return
        if entry.latched.maxlen:
            entry.latched.append(data)
        self.relay(topic, entry, data)

    def relay(self, topic: str, entry: BridgedTopic, data: bytes) -> None:
        """Log one message on the topic's channel; a failure is a throttled warning."""
        try:
            entry.channel.log(data, log_time=self.now_ns())
        except Exception as error:  # noqa: B902 - never let the viewer stop the node
            if self.throttle.ready(('log', topic)):
                self.get_logger().warning(f'Cannot relay {topic}: {error}')

    def serve(self) -> None:
        """Re-send latched messages to channels with a new subscriber; broadcast sim time."""
        resend = set()
        while self.listener.subscribed:
            resend.add(self.listener.subscribed.popleft())
        for topic, entry in self.bridged.items():
            if entry.channel.id() in resend:
                for data in list(entry.latched):
                    self.relay(topic, entry, data)
        if self.use_sim_time:
            now = self.now_ns()
            if now is not None and now != self.last_time_ns:
                self.last_time_ns = now
                self.server.broadcast_time(now)

    def close(self) -> None:
        """Stop the server (clients see the connection close)."""
        for entry in self.bridged.values():
            entry.channel.close()
        self.server.stop()


def main(args=None) -> int:
    """Run the foxglove_bridge node until Ctrl-C or SIGTERM."""
    return run_node(FoxgloveBridge, 'foxglove_bridge', args)


if __name__ == '__main__':
    sys.exit(main())
