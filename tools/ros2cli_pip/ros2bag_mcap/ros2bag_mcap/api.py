"""
Helpers shared by the verbs: argparse validators and rosbag2's message format (no rclpy).

A verb's ``main`` returns an error string made by :func:`print_error` for a failure: the
``ros2`` command exits with it (``sys.exit``), which prints it on stderr and gives exit
code 1, as rosbag2's verbs do.
"""

from argparse import ArgumentTypeError
import math
from typing import Any, List

#: The only storage this ros2 bag reads and writes.
STORAGE_ID = 'mcap'
SERVICE_EVENT_SUFFIX = '/_service_event'


def print_error(text: str) -> str:
    """Return an error line as rosbag2 prints it: '[ERROR] [ros2bag]: text'."""
    return f'[ERROR] [ros2bag]: {text}'


def print_warn(text: str) -> str:
    """Return a warning line as rosbag2 prints it: '[WARN] [ros2bag]: text'."""
    return f'[WARN] [ros2bag]: {text}'


def _float(value: Any) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ArgumentTypeError(f'{value} is not the valid type (float)') from None
    if not math.isfinite(number):
        raise ArgumentTypeError(f'{value} is not a finite number')
    return number


def check_positive_float(value: Any) -> float:
    """Argparse type: a float > 0 (rosbag2's check_positive_float)."""
    number = _float(value)
    if number <= 0.0:
        raise ArgumentTypeError(f'{value} is not in the valid range (> 0.0)')
    return number


def check_not_negative_float(value: Any) -> float:
    """Argparse type: a float >= 0 (rosbag2's check_not_negative_float)."""
    number = _float(value)
    if number < 0.0:
        raise ArgumentTypeError(f'Value {value} is less than zero.')
    return number


def check_not_negative_int(value: Any) -> int:
    """Argparse type: an integer >= 0 (rosbag2's check_not_negative_int)."""
    try:
        number = int(value)
    except (TypeError, ValueError):
        raise ArgumentTypeError(f'{value} is not the valid type (int)') from None
    if number < 0:
        raise ArgumentTypeError(f'Value {value} is less than zero.')
    return number


def service_event_topics(services: List[str]) -> List[str]:
    """Return the service event topics of service names ('/add' -> '/add/_service_event')."""
    return [absolute(s) + SERVICE_EVENT_SUFFIX for s in services or []]


def absolute(name: str) -> str:
    """Return a topic name given on the command line as an absolute name."""
    return name if name.startswith('/') else '/' + name
