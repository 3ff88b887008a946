"""
The standard ``main()`` of the mecanum_control nodes.

rclpy's own signal handler would shut the context down before a node could send its
final zero command, so SIGINT (Ctrl-C) and SIGTERM end the spin with KeyboardInterrupt
and the node's ``close()`` (if it has one) runs while the context is still valid. While
the node spins they only set a flag that the spin loop checks (:func:`signals_deferred`);
before it does (construction) they raise KeyboardInterrupt at once.
A parameter error (bad value or type, unreadable parameter file) is logged as fatal
and gives exit code 2, without a traceback. The default spin returns to Python every
``WAKE_PERIOD_S``: a wait without a timeout never returns while no message arrives,
so the signal handlers would not run in an idle node without timers.

The executor is rclpy's EventsExecutor (rclpy.experimental, C++): on the simulated
clock every node wakes 50 times a second for /clock alone, and the SingleThreadedExecutor
rebuilds its wait set in Python on every wake; an idle node on sim time took 6.4 % of a
core with it and 2.6 % with the EventsExecutor. ``MECANUM_EXECUTOR=single`` in the
environment selects the SingleThreadedExecutor instead.

On simulated time (``use_sim_time``) every spinning process answers each /clock on
``/clock_ack`` (std_msgs/Header: stamp = that /clock, frame_id = the process's name), for
the simulator's lockstep (robot_simulation.lockstep), which waits for it before it steps
time on; only while someone subscribes, i.e. while a simulator runs in lockstep.
"""

from contextlib import contextmanager
import os
import signal
import threading
from typing import Callable, Iterator, List, Optional

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Header


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


@contextmanager
def signals_deferred() -> Iterator[threading.Event]:
    """
    Within: SIGINT and SIGTERM only set the yielded event; KeyboardInterrupt after, if one came.

    For spin loops, which check the event. A KeyboardInterrupt raised inside a callback
    that the C++ EventsExecutor runs comes out of spin_once as a RuntimeError ("Unable
    to convert call argument") with a traceback, and a callback cut half way may leave a
    message half handled. The previous handlers are back on leaving, so a second signal,
    while the nodes close, interrupts as usual.
    """
    stop = threading.Event()
    previous = {number: signal.signal(number, lambda *_: stop.set())
                for number in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
    if stop.is_set():
        raise KeyboardInterrupt


def answer_clock(node: Node, name: str) -> bool:
    """
    On simulated time, make node answer each /clock on /clock_ack as ``name``.

    Returns whether it does (False on the system clock). The answer goes out while the
    node's executor takes the /clock, after everything it had queued before; one per
    process is enough (the first node of a container).
    """
    if not node.get_parameter('use_sim_time').value:
        return False
    reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    publisher = node.create_publisher(Header, '/clock_ack', reliable)

    def on_clock(msg: Clock) -> None:
        if publisher.get_subscription_count() > 0:
            publisher.publish(Header(stamp=msg.clock, frame_id=name))

    node.create_subscription(Clock, '/clock', on_clock, reliable)
    return True


def spin_waking(node: Node, *more_nodes: Node, executor=None) -> None:
    """
    Spin the nodes until Ctrl-C/SIGTERM (then raise KeyboardInterrupt) or their context ends.

    Returns to Python every WAKE_PERIOD_S to look at the signals (see
    :func:`signals_deferred`). ``executor``: default :func:`make_executor`'s.
    """
    executor = executor or make_executor(node.context)
    for each in (node, *more_nodes):
        executor.add_node(each)
    answer_clock(node, node.get_name() if not more_nodes
                 else f'{node.get_name()} (+{len(more_nodes)} nodes)')
    with signals_deferred() as stop:
        while node.context.ok() and not stop.is_set():
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
