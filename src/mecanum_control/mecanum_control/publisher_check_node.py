"""
The ROS side of :mod:`mecanum_control.publisher_check`, shared by the nodes that use it.

motor_controller, velocity_controller and hardware_interface each watch the publishers
of their inputs: :func:`declare_publisher_check` declares a check's parameter
('<name>_publishers', the expected node names; '' turns it off),
:func:`start_publisher_checks` the period (``publisher_check_period_s``, steady clock)
and its timer, and :func:`poll_publisher_check` asks the ROS graph, logs a change
(ERROR when an unexpected publisher appears, WARN when it has gone) and reports the
check on /diagnostics. What a node does meanwhile (zero efforts, zero targets) is its own.

A new publisher of a checked input is not left to the next period: :class:`MatchWatch`
gives the input's subscription a ``matched`` event callback that runs the node's check
MATCH_RECHECK_DELAYS_S after the match (its node's name reaches the graph some 10-100 ms
after its endpoint), so a stray publisher is named and the wheels stopped within about
0.1 s of its first message instead of up to a period and more. While an endpoint still has
no node name (under load the name can come later than 0.3 s: CI saw it), the looks go on
every MATCH_UNNAMED_PERIOD_S up to MATCH_UNNAMED_LIMIT_S after the match; an endpoint of
no known node itself is judged by the periodic looks only (seen at two in a row, it
counts: PublisherCheck).
"""

from typing import Callable, Optional, Sequence

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from mecanum_control.messages import diagnostic_array
from mecanum_control.parameters import declare_number, positive
from mecanum_control.publisher_check import (
    match_look_due, MATCH_TIMER_PERIOD_S, match_watch_over, parse_expected_publishers,
    PublisherCheck)
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node


def declare_publisher_check(node: Node, parameter: str, topic: str, stopping: str,
                            resuming: str, resume_after: int = 1) -> PublisherCheck:
    """Declare parameter (expected publishers of topic) and return its check."""
    value = node.declare_parameter(
        parameter, '', ParameterDescriptor(dynamic_typing=True)).value
    return PublisherCheck(topic, parse_expected_publishers(parameter, value),
                          node.get_namespace(), stopping, resuming, resume_after)


def start_publisher_checks(node: Node, checks: Sequence[PublisherCheck],
                           callback: Callable[[], None]):
    """Declare publisher_check_period_s (s); start callback on it if a check is enabled."""
    period_s = positive('publisher_check_period_s', declare_number(
        node, 'publisher_check_period_s', 1.0))
    if not any(check.enabled for check in checks):
        return None
    return node.create_timer(period_s, callback, clock=Clock(clock_type=ClockType.STEADY_TIME))


def poll_publisher_check(node: Node, check: PublisherCheck, diag_pub,
                         may_resume: bool = True) -> Optional[str]:
    """
    Update check from the ROS graph, log a change, report it; return 'stop', 'resume'.

    may_resume False for the extra looks of :class:`MatchWatch` (PublisherCheck.update).
    """
    change = check.update(node.get_publishers_info_by_topic(check.topic), may_resume)
    if change == 'stop':
        node.get_logger().error(check.message)
    elif change == 'resume':
        node.get_logger().warning(check.gone_message)
    if check.enabled:
        diag_pub.publish(diagnostic_array(
            node.get_clock().now().to_msg(),
            f'mecanum_control: {node.get_name()} publishers of {check.topic}',
            DiagnosticStatus.ERROR if check.stopped else DiagnosticStatus.OK, check.message,
            [KeyValue(key=key, value=value) for key, value in check.values], hardware_id=''))
    return change


class MatchWatch:
    """
    Run a node's publisher check soon after a new publisher of a watched input matched.

    Pass ``event_callbacks()`` to the create_subscription of each checked input; the
    check (the node's callback, the same as its periodic one, called with
    ``may_resume=False``: these looks may stop, never resume) then runs at each of
    MATCH_RECHECK_DELAYS_S after a match, and on while ``unnamed()`` says a publisher has
    no node name yet (:func:`match_look_due`), on a steady timer that ends itself.
    """

    def __init__(self, node: Node, callback: Callable[..., None],
                 unnamed: Callable[[], bool], on_match: Optional[Callable[[], None]] = None):
        """
        Watch for node; callback runs its publisher checks; on_match runs at a match.

        unnamed: whether a checked input has a publisher of no known node (after a look).
        """
        self._node = node
        self._callback = callback
        self._unnamed = unnamed
        self._on_match = on_match
        self._timer = None
        self._since_s = 0.0
        self._done = 0

    def event_callbacks(self) -> SubscriptionEventCallbacks:
        """Return the subscription event callbacks that start the re-checks."""
        return SubscriptionEventCallbacks(matched=self._on_matched)

    def _on_matched(self, info) -> None:
        if info.current_count_change <= 0:
            return                      # a publisher left: the periodic check says so
        if self._on_match is not None:
            self._on_match()
        self._since_s, self._done = 0.0, 0
        if self._timer is None:
            self._timer = self._node.create_timer(
                MATCH_TIMER_PERIOD_S, self._on_timer,
                clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _on_timer(self) -> None:
        self._since_s += MATCH_TIMER_PERIOD_S
        if match_look_due(self._since_s, self._done, self._unnamed()):
            self._done += 1
            self._callback(may_resume=False)
        if match_watch_over(self._since_s, self._done, self._unnamed()):
            self._node.destroy_timer(self._timer)
            self._timer = None
