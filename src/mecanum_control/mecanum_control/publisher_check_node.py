"""
The ROS side of :mod:`mecanum_control.publisher_check`, shared by the nodes that use it.

motor_controller, velocity_controller and hardware_interface each watch the publishers
of their inputs: :func:`declare_publisher_check` declares a check's parameter
('<name>_publishers', the expected node names; '' turns it off),
:func:`start_publisher_checks` the period (``publisher_check_period_s``, steady clock)
and its timer, and :func:`poll_publisher_check` asks the ROS graph, logs a change
(ERROR when an unexpected publisher appears, WARN when it has gone) and reports the
check on /diagnostics. What a node does meanwhile (zero efforts, zero targets) is its own.
"""

from typing import Callable, Optional, Sequence

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from mecanum_control.messages import diagnostic_array
from mecanum_control.parameters import declare_number, positive
from mecanum_control.publisher_check import parse_expected_publishers, PublisherCheck
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.clock import Clock, ClockType
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


def poll_publisher_check(node: Node, check: PublisherCheck, diag_pub) -> Optional[str]:
    """Update check from the ROS graph, log a change, report it; return 'stop', 'resume'."""
    change = check.update(node.get_publishers_info_by_topic(check.topic))
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
