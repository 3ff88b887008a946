"""
The standard ``main()`` of the mecanum_control nodes.

rclpy's own signal handler would shut the context down before a node could send its
final zero command, so SIGINT (Ctrl-C) and SIGTERM are turned into KeyboardInterrupt
and the node's ``close()`` (if it has one) runs while the context is still valid.
A parameter error (bad value or type, unreadable parameter file) is logged as fatal
and gives exit code 2, without a traceback. The default spin returns to Python every
``WAKE_PERIOD_S``: a wait without a timeout never returns while no message arrives,
so the signal handlers would not run in an idle node without timers.

The executor is rclpy's EventsExecutor (rclpy.experimental, C++): on the simulated
clock every node wakes 50 times a second for /clock alone, and the SingleThreadedExecutor
rebuilds its wait set in Python on every wake; an idle node on sim time took 6.4 % of a
core with it and 2.6 % with the EventsExecutor. ``MECANUM_EXECUTOR=single`` in the
environment selects the SingleThreadedExecutor instead.
"""

import os
import signal
from typing import Callable, List, Optional

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions


#: The longest the default spin waits before returning to Python (to see signals), s.
WAKE_PERIOD_S = 0.2


def _raise_keyboard_interrupt(_signum, _frame):
    raise KeyboardInterrupt


def raise_keyboard_interrupt_on_signals() -> None:
    """Turn SIGTERM and SIGINT (also when inherited as ignored) into KeyboardInterrupt."""
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
    signal.signal(signal.SIGINT, _raise_keyboard_interrupt)


def close_node(node: Node) -> None:
    """Run the node's ``close()`` if it has one (errors logged, not raised), then destroy it."""
    close = getattr(node, 'close', None)
    if close is not None:
        try:
            close()
        except Exception as error:  # noqa: B902 - report, then still clean up
            node.get_logger().error(f'close failed: {error}')
    node.destroy_node()


def make_executor(context=None):
    """Return the executor for a node's process (see the module docstring)."""
    if os.environ.get('MECANUM_EXECUTOR', '').strip().lower() != 'single':
        try:
            from rclpy.experimental import EventsExecutor
        except ImportError:   # an rclpy without it
            pass
        else:
            return EventsExecutor(context=context)
    return SingleThreadedExecutor(context=context)


def spin_waking(node: Node, *more_nodes: Node) -> None:
    """Spin the nodes until their context shuts down, returning to Python every WAKE_PERIOD_S."""
    executor = make_executor(node.context)
    for each in (node, *more_nodes):
        executor.add_node(each)
    while node.context.ok():
        executor.spin_once(timeout_sec=WAKE_PERIOD_S)


def run_node(node_factory: Callable[[], Node], name: str,
             args: Optional[List[str]] = None,
             spin: Optional[Callable[[Node], None]] = None) -> int:
    """
    Create the node, spin it until Ctrl-C/SIGTERM, close it; return an exit code.

    ``spin`` replaces :func:`spin_waking` for nodes that drive their own loop.
    """
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RuntimeError as error:  # rcl failed, e.g. a parameter file that is not YAML
        rclpy.logging.get_logger(name).fatal(f'cannot start: {error}')
        return 2
    # SIGINT also when inherited as ignored (e.g. `cmd &` in a script).
    raise_keyboard_interrupt_on_signals()
    try:
        node = node_factory()
    except (ValueError, ParameterException) as error:
        rclpy.logging.get_logger(name).fatal(f'{error}')
        rclpy.try_shutdown()
        return 2
    except KeyboardInterrupt:
        rclpy.try_shutdown()
        return 0
    try:
        (spin or spin_waking)(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        close_node(node)
        rclpy.try_shutdown()
    return 0
