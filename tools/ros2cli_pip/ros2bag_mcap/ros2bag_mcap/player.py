"""
``ros2 bag play``: publish a bag's messages, serialized as recorded, at their time spacing.

One rclpy node, ``rosbag2_player`` as rosbag2's, with one publisher per played topic,
of the recorded type (looked up by name, e.g. ``std_msgs/msg/String``) and the QoS
rosbag2 would offer (:mod:`ros2bag_mcap.offer`); each message's CDR bytes are published
as they are (rclpy's ``publish`` of bytes), never deserialized. When each message is
due and what /clock says are :mod:`ros2bag_mcap.timing`'s; the wait between messages
runs in this thread, which also publishes /clock (``--clock``, best effort, keep last 1
as rclcpp's ClockQoS) on its grid of ticks. Messages are read from the MCAP files as they
are needed (the reading is fast next to the waiting), so a bag of any size plays in
little memory. No executor spins: publishers need none.

Ctrl-C (SIGINT) or SIGTERM stop the playback at once; the node is destroyed and the
command exits 0 without a traceback.
"""

from dataclasses import dataclass, field
import signal
import time
from typing import Dict, List, Optional

import rclpy
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.logging import get_logger
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, InvalidQoSProfileException,
                       LivelinessPolicy, QoSProfile, ReliabilityPolicy)
from rclpy.signals import SignalHandlerOptions
from ros2bag_mcap.bag import Bag, BagError, iter_messages
from ros2bag_mcap.offer import describe, Offer, playback_offer
from ros2bag_mcap.selection import TopicFilter
from ros2bag_mcap.timing import (bag_time_ns, check_rate, clock_period_s, clock_stamp_ns,
                                 due_offset_s, next_tick_s, NO_LIMIT, NS_PER_S,
                                 play_until_ns, playback_start_ns, shall_stop)
from rosgraph_msgs.msg import Clock
from rosidl_runtime_py.utilities import get_message

NODE_NAME = 'rosbag2_player'
#: The longest single sleep, s (the clock grid and signals are looked at in between).
MAX_SLEEP_S = 0.1


@dataclass
class PlayOptions:
    """What to play and how; times in s unless named _ns (bag time, ns)."""

    rate: float = 1.0
    loop: bool = False
    start_offset_s: float = 0.0
    delay_s: float = 0.0
    clock_hz: float = 0.0                  # 0: no periodic /clock
    clock_topics: List[str] = field(default_factory=list)
    clock_topics_all: bool = False
    playback_duration_s: float = -1.0      # < 0: no limit
    playback_until_ns: int = NO_LIMIT
    wait_acked_ms: int = -1                # < 0: do not wait; 0: wait forever
    remap: List[str] = field(default_factory=list)
    qos_overrides: Dict[str, Offer] = field(default_factory=dict)
    topic_filter: TopicFilter = field(default_factory=TopicFilter)
    log_level: str = 'info'


def qos_profile(offer: Offer) -> QoSProfile:
    """Return an rclpy QoSProfile for an offer."""
    def nanoseconds(value: int) -> Duration:
        return Duration(nanoseconds=value)

    return QoSProfile(
        history=HistoryPolicy[offer.history.upper()], depth=offer.depth,
        reliability=ReliabilityPolicy[offer.reliability.upper()],
        durability=DurabilityPolicy[offer.durability.upper()],
        deadline=nanoseconds(offer.deadline_ns), lifespan=nanoseconds(offer.lifespan_ns),
        liveliness=LivelinessPolicy[offer.liveliness.upper()],
        liveliness_lease_duration=nanoseconds(offer.liveliness_lease_duration_ns),
        avoid_ros_namespace_conventions=offer.avoid_ros_namespace_conventions)


def clock_qos() -> QoSProfile:
    """Return rclcpp's ClockQoS: best effort, volatile, keep last 1."""
    return QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)


def _raise_keyboard_interrupt(_signum, _frame):
    raise KeyboardInterrupt


class Player:
    """Plays one bag with one node; :meth:`run` until the end, Ctrl-C or SIGTERM."""

    def __init__(self, bag: Bag, options: PlayOptions, context: Context):
        """Create the node, the topic publishers and the /clock publisher."""
        self.bag = bag
        self.options = options
        self.rate = check_rate(options.rate)
        cli_args = []
        for rule in options.remap:
            cli_args += ['--remap', rule]
        self.node = rclpy.create_node(
            NODE_NAME, context=context,
            cli_args=['--ros-args', *cli_args] if cli_args else None,
            start_parameter_services=False)
        self.logger = self.node.get_logger()
        self.publishers = {}
        self.count = 0
        self._create_publishers()
        self.clock_publisher = None
        if options.clock_hz > 0 or options.clock_topics or options.clock_topics_all:
            self.clock_publisher = self.node.create_publisher(Clock, '/clock', clock_qos())
        self.clock_topics = set(options.clock_topics)
        self.period_s = clock_period_s(options.clock_hz) if options.clock_hz > 0 else None
        self.start_ns = playback_start_ns(bag.metadata.starting_time_ns,
                                          options.start_offset_s)
        self.until_ns = play_until_ns(self.start_ns, options.playback_duration_s,
                                      options.playback_until_ns)
        self._tick_s = None
        self._origin_s = time.monotonic()
        self._held_ns: Optional[int] = self.start_ns   # /clock while not playing

    def _create_publishers(self) -> None:
        """One publisher per selected topic whose type is installed."""
        excluded = {'/clock'} if self.options.clock_hz > 0 else set()
        for topic in self.bag.metadata.topics:
            if topic.name in excluded or topic.name in self.publishers \
                    or not self.options.topic_filter.allows(topic.name, topic.type_name):
                continue
            if topic.serialization_format != 'cdr':
                self.logger.warning(
                    f"Ignoring a topic '{topic.name}', reason: its serialization format "
                    f"'{topic.serialization_format}' is not cdr.")
                continue
            try:
                msg_type = get_message(topic.type_name)
            except (AttributeError, ImportError, ValueError) as error:
                self.logger.warning(
                    f"Ignoring a topic '{topic.name}', reason: type {topic.type_name} is not "
                    f'installed ({error}).')
                continue
            offer = self.options.qos_overrides.get(topic.name)
            if offer is not None:
                self.logger.info(f'Overriding QoS profile for topic {topic.name}')
            else:
                try:
                    offer, warning = playback_offer(topic.offered_qos_profiles)
                except ValueError as error:
                    offer, warning = playback_offer([])[0], f'unreadable recorded QoS ({error})'
                if warning:
                    self.logger.warning(f'{topic.name}: {warning}')
            self.publishers[topic.name] = self.node.create_publisher(
                msg_type, topic.name, qos_profile(offer))
            self.count += topic.message_count
            self.logger.debug(f'Publishing {topic.name} ({topic.type_name}, {describe(offer)})')

    def _clock_now_ns(self, now_s: float, next_due_ns: Optional[int] = None) -> int:
        if self._held_ns is not None:
            return self._held_ns
        if next_due_ns is None:
            return bag_time_ns(now_s - self._origin_s, self.start_ns, self.rate)
        return clock_stamp_ns(now_s - self._origin_s, self.start_ns, self.rate, next_due_ns)

    def _publish_clock(self, stamp_ns: int) -> None:
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(max(0, stamp_ns), NS_PER_S)
        self.clock_publisher.publish(msg)

    def _wait_until(self, due_s: float, due_ns: Optional[int] = None) -> None:
        """
        Sleep until the monotonic time due_s, publishing /clock on its ticks meanwhile.

        due_ns: the log time of the message due then (/clock does not pass it).
        """
        while True:
            now = time.monotonic()
            if self.period_s is not None:
                if self._tick_s is None:
                    self._tick_s = now
                if now >= self._tick_s:
                    self._publish_clock(self._clock_now_ns(now, due_ns))
                    self._tick_s = next_tick_s(self._tick_s, self.period_s, now)
            if now >= due_s:
                return
            wake = due_s if self.period_s is None else min(due_s, self._tick_s)
            time.sleep(min(MAX_SLEEP_S, max(0.0, wake - now)))

    def _play_pass(self) -> int:
        """Play the bag once from the start (offset); return the number of messages played."""
        if self.options.delay_s > 0:
            self._held_ns = self.start_ns
            self._wait_until(time.monotonic() + self.options.delay_s)
        self._origin_s = time.monotonic()
        self._held_ns = None
        played = 0
        for message in iter_messages(self.bag, self.publishers.keys(), self.start_ns):
            if shall_stop(message.log_time_ns, self.until_ns):
                break
            self._wait_until(self._origin_s
                             + due_offset_s(message.log_time_ns, self.start_ns, self.rate),
                             message.log_time_ns)
            if self.clock_publisher is not None and (
                    self.options.clock_topics_all or message.topic in self.clock_topics):
                self._publish_clock(message.log_time_ns)
            self.publishers[message.topic].publish(message.data)
            played += 1
        return played

    def run(self) -> None:
        """Play once, or until interrupted with --loop; BagError if the bag is corrupt."""
        self.logger.info(
            f"Playing '{self.bag.path}': {self.count} messages on {len(self.publishers)} "
            f'topics at rate {self.rate:g}{", looping" if self.options.loop else ""}')
        while True:
            played = self._play_pass()
            if not self.options.loop:
                break
            if played == 0:
                self.logger.warning('Nothing to play: not looping')
                break
        if self.options.wait_acked_ms >= 0:
            timeout = Duration(nanoseconds=self.options.wait_acked_ms * 1_000_000
                               if self.options.wait_acked_ms > 0 else -1)
            for name, publisher in self.publishers.items():
                if not publisher.wait_for_all_acked(timeout):
                    self.logger.warning(f'Timed out waiting for all acks on {name}')

    def destroy(self) -> None:
        """Destroy the node (its publishers)."""
        self.node.destroy_node()


def play(bag: Bag, options: PlayOptions) -> Optional[str]:
    """Play a bag; return None when done or interrupted, an error text for a failure."""
    context = Context()
    previous = {number: signal.getsignal(number) for number in (signal.SIGINT, signal.SIGTERM)}
    signal.signal(signal.SIGINT, _raise_keyboard_interrupt)
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
    player = None
    try:
        rclpy.init(args=['ros2', '--ros-args', '--log-level', options.log_level],
                   context=context, signal_handler_options=SignalHandlerOptions.NO)
        player = Player(bag, options, context)
        player.run()
        return None
    except KeyboardInterrupt:
        return None
    except BagError as error:
        return str(error)
    except (InvalidQoSProfileException, RuntimeError, ValueError) as error:
        # rcl refusing a QoS (overrides file) or a topic name (remapping)
        return f'cannot play: {" ".join(str(error).split())}'
    finally:
        # A second Ctrl-C must not cut the clean-up short with a traceback.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        try:
            if player is not None:
                player.destroy()
            rclpy.try_shutdown(context=context)
        except Exception as error:  # noqa: B902 - report, the playback is over anyway
            get_logger(NODE_NAME).warning(f'clean-up: {error}')
        for number, handler in previous.items():
            signal.signal(number, handler)
