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
time on; only while someone subscribes, i.e. while a simulator runs in lockstep. The
answer goes out once the work that /clock starts in the process is done
(:class:`ClockAnswer`): every node's clock has taken it and every timer it made due has
run, so a controller's command for a period is computed in that period whatever the
machine's load.
"""

import atexit
from contextlib import contextmanager
import ctypes
import faulthandler
import functools
import os
import re
import signal
import sys
import threading
import time
from typing import Callable, Dict, Iterator, List, NoReturn, Optional, Sequence, Tuple

from mecanum_control import node_reload
import rclpy
from rclpy.event_handler import EventHandler
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Header


#: Wall seconds a node may take to close (its close(), destroy, rclpy shutdown) before
#: the process leaves anyway: launch escalates to SIGTERM after 5 s, then SIGKILL, and a
#: destroy stuck in rclpy (seen once in 3000 real-launch stops of motor_controller) made
#: every stop an ERROR. The node's own close() (its final zero) has run or is running.
CLOSE_TIMEOUT_S = 3.0
#: Seconds after CLOSE_TIMEOUT_S at which a close stuck in C code is ended (close_watchdog).
CLOSE_STUCK_GRACE_S = 1.0


def _leave_stuck_close(name: str) -> None:
    """Leave the process: its close has taken longer than CLOSE_TIMEOUT_S (a thread)."""
    print(f'[WARN] [{name}]: closing took more than {CLOSE_TIMEOUT_S:g} s (stuck in '
          f'{_closing_step}): leaving now', file=sys.stderr, flush=True)
    os._exit(0)


@contextmanager
def close_watchdog(name: str) -> Iterator[None]:
    """
    Within: a process whose close takes too long leaves instead of hanging.

    After CLOSE_TIMEOUT_S a thread prints a WARN and leaves (exit 0). That thread needs
    the GIL, which a call stuck in C code may hold (CI saw motor_controller wait in
    rclpy's destroy_node, inside rcl, with its watchdog thread never woken): one
    CLOSE_STUCK_GRACE_S later faulthandler's own C thread prints every thread's Python
    stack and ends the process (exit 1), so nothing is left to launch's SIGTERM and
    SIGKILL, and the report says where it was stuck.
    """
    watchdog = threading.Timer(CLOSE_TIMEOUT_S, _leave_stuck_close, args=(name,))
    watchdog.daemon = True
    watchdog.start()
    faulthandler.dump_traceback_later(CLOSE_TIMEOUT_S + CLOSE_STUCK_GRACE_S, exit=True)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()
        watchdog.cancel()


#: The longest the default spin waits before returning to Python (to see signals), s.
WAKE_PERIOD_S = 0.2


def _raise_keyboard_interrupt(_signum, _frame):
    raise KeyboardInterrupt


def raise_keyboard_interrupt_on_signals() -> None:
    """
    Turn SIGTERM and SIGINT (also inherited as ignored or blocked) into KeyboardInterrupt.

    SIGQUIT (Ctrl and backslash) first prints every thread's Python stack to stderr, then
    quits as by default (also when inherited as ignored, as `cmd &` in a script does). A
    C handler writes it, so it also shows where a process stuck in C code (which Python's
    SIGINT and SIGTERM handlers never reach) is waiting.
    """
    signal.signal(signal.SIGQUIT, signal.SIG_DFL)    # also when inherited as ignored
    faulthandler.register(signal.SIGQUIT, all_threads=True, chain=True)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGQUIT})
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
    signal.signal(signal.SIGINT, _raise_keyboard_interrupt)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})


def close_node(node: Node) -> None:
    """
    Run the node's ``close()`` if it has one (errors logged, not raised), then destroy it.

    Its waitables but the QoS event handlers (action servers and clients) are destroyed
    first: rclpy's destroy_node leaves them, and each holds the node's handle, so the
    node (its name in the graph, its action servers) lived on until garbage collection;
    a reload then had two /navigator nodes, the old one still serving navigate_to_pose.
    The event handlers of its publishers and subscriptions go with those, in
    destroy_node, as rclpy orders it. (Told apart by EventHandler, which rclpy.node
    imports anyway: importing rclpy.action here cost every node process 45 ms.)
    """
    close = getattr(node, 'close', None)
    if close is not None:
        try:
            close()
        except Exception as error:  # noqa: B902 - report, then still clean up
            node.get_logger().error(f'close failed: {error}')
    for waitable in list(node.waitables):
        destroy = getattr(waitable, 'destroy', None)
        if destroy is not None and not isinstance(waitable, EventHandler):
            destroy()
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


#: Most executor rounds one drain runs (a flood of messages cannot hold the answer back).
DRAIN_ROUNDS_MAX = 1000
#: Every how many /clock messages ClockAnswer looks for new subscriptions and timers.
INSTRUMENT_EVERY_CLOCKS = 50
#: Wall seconds after which an answer held back by work left is logged (what holds it).
STUCK_REPORT_S = 2.0
#: Wall seconds between two /clock_alive messages of a process.
ALIVE_PERIOD_S = 1.0


class ClockAnswer:
    """
    Answers each /clock on /clock_ack once the work it starts in this process is done.

    While a simulator in lockstep subscribes to /clock_ack, a /clock is taken in order:

    1. what came before it is handled first, at the time before: input from outside ROS
       (a node's ``catch_up()`` method, if it has one: hardware_interface reads the
       board's frames), the messages, and every message their callbacks publish to this
       process (:meth:`drain`). A message from another process that arrives meanwhile
       came after the /clock: its callback is held and runs once the new time is taken
       (the process's publishers are counted per local subscription, so what is left
       over is from outside);
    2. then the nodes' time source(s) take the new time (:func:`share_time_source`): the
       newest /clock only, when several came together (:meth:`_take_newest`; also
       outside lockstep, after each round of the executor);
    3. the timers that time made due run (the executor), then what they publish to this
       process is handled (drain again);
    4. then the answer goes out. What the process published for that time is then on its
       way before the simulator can publish the next /clock.

    So a command computed by a timer goes down a chain of callbacks within a process in the
    same period whatever the machine's load. The spin loop calls :meth:`after_spin` after
    each round of the executor. A drain runs the executor without waiting until a round
    calls no callback (the nodes' subscription and timer callbacks are counted); it is
    skipped when no callback has run since the queue was last seen empty (an empty round
    of the EventsExecutor costs ~80 us).

    A thread of its own says the process is alive on ``/clock_alive`` (std_msgs/Header,
    frame_id = its name) every ALIVE_PERIOD_S, also while a callback runs for long (a
    first JIT compile, a loop closure): the lockstep waits for a busy process and gives
    up only on a silent one (frozen or dead).
    """

    def __init__(self, nodes: Sequence[Node], name: str):
        """Advertise /clock_ack as ``name`` and take over the nodes' /clock callbacks."""
        self.nodes = list(nodes)
        self.name = name
        self.calls = 0            # subscription and timer callbacks run (not /clock)
        self._clock_calls = 0     # /clock callbacks run
        self._idle_at = 0         # self.calls when the executor's queue was last empty
        self._clocks_taken = 0
        self._deferred: List[Tuple[Callable, Callable, Clock]] = []   # held /clock
        self._free: Dict[Callable, Callable] = {}   # not in lockstep: newest /clock each
        self._held: List[Callable] = []                      # messages wait for it
        self._local_subscriptions: Dict[str, List[int]] = {}   # topic: subscription ids
        self._expected: Dict[int, int] = {}   # subscription id: own messages on the way
        self._pending: Optional[Clock] = None
        self._pending_ns = 0
        self._stuck_since: Optional[float] = None   # wall time the answer was first due
        self._stuck_clock_ns = -1
        self._stuck_reported = -1
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.publisher = self.nodes[0].create_publisher(Header, '/clock_ack', reliable)
        self.alive_publisher = self.nodes[0].create_publisher(Header, '/clock_alive', reliable)
        self._instrument()
        #: Nodes' catch_up(): take in input from outside ROS that came before a /clock.
        self._catch_ups = [node.catch_up for node in self.nodes
                           if callable(getattr(node, 'catch_up', None))]
        threading.Thread(target=self._say_alive, name='clock_alive', daemon=True).start()

    def _say_alive(self) -> None:
        """Publish /clock_alive every ALIVE_PERIOD_S while anyone listens (thread)."""
        context = self.nodes[0].context
        while context.ok():
            time.sleep(ALIVE_PERIOD_S)
            try:
                if self.alive_publisher.get_subscription_count() > 0:
                    self.alive_publisher.publish(Header(frame_id=self.name))
            except Exception:  # noqa: B902 - the node is being destroyed: stop saying it
                return

    def _instrument(self) -> None:
        """Count the nodes' callbacks and publications; hold each /clock (new ones too)."""
        for node in self.nodes:
            for entity in (*node.subscriptions, *node.timers):
                callback = entity.callback
                if getattr(callback, 'clock_answer', None) is self:
                    continue
                topic = getattr(entity, 'topic_name', None)
                if topic == '/clock' and not getattr(entity, 'raw', False):  # raw: recorder
                    wrapped = self._deferring(callback)
                elif topic is None:
                    wrapped = self._counting(callback)
                else:
                    self._local_subscriptions.setdefault(topic, []).append(id(entity))
                    wrapped = self._counting(callback, id(entity))
                wrapped.clock_answer = self
                entity.callback = wrapped
            for publisher in node.publishers:
                if getattr(publisher.publish, 'clock_answer', None) is not self:
                    publisher.publish = self._noting(publisher.publish,
                                                     publisher.topic_name)

    def _noting(self, publish: Callable, topic: str) -> Callable:
        """Wrap a publisher's publish: note the message for each local subscription."""
        def noted(msg):
            for key in self._local_subscriptions.get(topic, ()):
                self._expected[key] = self._expected.get(key, 0) + 1
            return publish(msg)
        noted.clock_answer = self
        return noted

    # functools.wraps: rclpy reads the callback's signature (through __wrapped__) to
    # decide whether to pass a subscription's MessageInfo too.
    def _counting(self, callback: Callable, key: Optional[int] = None) -> Callable:
        @functools.wraps(callback)
        def counted(*args):
            self.calls += 1
            if key is not None:
                if self._expected.get(key, 0) > 0:
                    self._expected[key] -= 1          # one of this process's own
                elif self._deferred:
                    self._held.append(functools.partial(callback, *args))
                    return None                       # from outside, after the /clock
            return callback(*args)
        return counted

    def _deferring(self, callback: Callable) -> Callable:
        @functools.wraps(callback)
        def deferred(msg: Clock, *info):
            self._clock_calls += 1
            if self.publisher.get_subscription_count() == 0:
                # Not in lockstep: taken after this round of the executor (the newest).
                self._free[callback] = functools.partial(callback, msg, *info)
                return None
            self._deferred.append((callback, functools.partial(callback, msg, *info), msg))
        return deferred

    @staticmethod
    def _take_newest(takes: Sequence[Tuple[Callable, Callable]]) -> None:
        """
        Take each time source's newest /clock only: one clock jump a round.

        rclpy's EventsExecutor dispatches a timer once per jump of its clock and calls it
        again even when it is no longer due, which pushes its next call as many periods
        ahead: after /clock messages taken together a 50 Hz timer ran 3 times, then
        skipped 2 periods (in lockstep hardware_interface then sent no command for the
        next /clock and simulated time stood still for 10 s).
        """
        newest: Dict[Callable, Callable] = {}
        for callback, take in takes:
            newest[callback] = take
        for take in newest.values():
            take()

    def drain(self, executor) -> None:
        """Run the executor without waiting until a round calls no callback."""
        if self.calls == self._idle_at:
            return      # nothing has run that could have queued more for this process
        for _ in range(DRAIN_ROUNDS_MAX):
            before = self.calls + self._clock_calls
            executor.spin_once(timeout_sec=0.0)
            if self.calls + self._clock_calls == before:
                break
        self._idle_at = self.calls

    def work_left(self) -> bool:
        """Whether a node's clock is behind the pending /clock or a timer is still due."""
        for node in self.nodes:
            if node.get_clock().now().nanoseconds < self._pending_ns:
                return True
            for timer in node.timers:
                left_ns = timer.time_until_next_call()   # None: cancelled
                if left_ns is not None and left_ns <= 0:
                    return True
        return False

    def _report_stuck(self) -> None:
        """Log (once per /clock) what holds the answer back after STUCK_REPORT_S of wall time."""
        now = time.monotonic()
        if self._stuck_since is None or self._stuck_clock_ns != self._pending_ns:
            self._stuck_since, self._stuck_clock_ns = now, self._pending_ns
            return
        if self._stuck_reported == self._pending_ns or now - self._stuck_since < STUCK_REPORT_S:
            return
        self._stuck_reported = self._pending_ns
        behind, due = [], []
        for node in self.nodes:
            if node.get_clock().now().nanoseconds < self._pending_ns:
                behind.append(node.get_name())
            for timer in node.timers:
                left_ns = timer.time_until_next_call()
                if left_ns is not None and left_ns <= 0:
                    callback = getattr(timer.callback, '__wrapped__', timer.callback)
                    due.append(f'{node.get_name()}.{getattr(callback, "__name__", callback)}'
                               f' ({left_ns * 1e-9:+.3f} s)')
        self.nodes[0].get_logger().warning(
            f'lockstep: /clock {self._pending_ns * 1e-9:.2f} s not answered after '
            f'{now - self._stuck_since:.1f} s: clocks behind {behind}, timers due but not '
            f'run {due}')

    def after_spin(self, executor) -> None:
        """Take a held /clock (1, 2 above) or answer the pending one once its work is done."""
        if self._free and not self._deferred:
            free, self._free = self._free, {}
            self._take_newest(list(free.items()))
        if self._deferred:
            for catch_up in self._catch_ups:
                if catch_up():
                    self._idle_at = -1     # it published: drain
            self.drain(executor)
            # Outside lockstep a moment ago (the simulator's subscription just matched):
            # those /clock are older, taken with these as one.
            free, self._free = self._free, {}
            deferred, self._deferred = self._deferred, []
            self._take_newest(list(free.items())
                              + [(callback, take) for callback, take, _ in deferred])
            held, self._held = self._held, []
            for run in held:      # outside messages that came after the /clock, at its time
                run()
            self._pending = deferred[-1][2]
            self._pending_ns = self._pending.clock.sec * 10 ** 9 + self._pending.clock.nanosec
            self._clocks_taken += 1
            if self._clocks_taken % INSTRUMENT_EVERY_CLOCKS == 0:
                self._instrument()     # entities created since (once a simulated second)
        if self._pending is None:
            return
        if self.work_left():
            self._report_stuck()
            return
        self.drain(executor)
        if self._deferred or self.work_left():
            return
        self.publisher.publish(Header(stamp=self._pending.clock, frame_id=self.name))
        self._pending = None


def share_time_source(nodes: Sequence[Node]) -> None:
    """
    On simulated time, let the first node's time source drive the clocks of all nodes.

    Every rclpy node has a time source with a /clock subscription of its own, so in a
    container of 11 nodes each /clock was delivered, converted and handled 11 times. The
    other nodes' time sources give up their subscription (``detach_node``) and their
    clocks follow the first node's (``attach_clock``), so all take a new time at once.
    rclpy offers no public accessor for a node's time source (``_time_source``); where
    it is missing, nothing changes. A later change of ``use_sim_time`` on the other
    nodes no longer takes effect.
    """
    first = nodes[0]
    source = getattr(first, '_time_source', None)
    if source is None or not first.get_parameter('use_sim_time').value:
        return
    for node in nodes[1:]:
        own = getattr(node, '_time_source', None)
        if own is None or not node.get_parameter('use_sim_time').value:
            continue
        own.detach_node()
        source.attach_clock(node.get_clock())


def answer_clock(nodes: Sequence[Node], name: str) -> Optional[ClockAnswer]:
    """
    On simulated time, return the :class:`ClockAnswer` of nodes as ``name``.

    None on the system clock (the first node's ``use_sim_time`` false). One per process
    is enough.
    """
    if not nodes[0].get_parameter('use_sim_time').value:
        return None
    return ClockAnswer(nodes, name)


def spin_waking(node: Node, *more_nodes: Node, executor=None,
                until: Optional[threading.Event] = None) -> None:
    """
    Spin the nodes until Ctrl-C/SIGTERM (then raise KeyboardInterrupt) or their context ends.

    Returns to Python every WAKE_PERIOD_S to look at the signals (see
    :func:`signals_deferred`). ``executor``: default :func:`make_executor`'s. ``until``:
    an event that ends the spin too, without KeyboardInterrupt (a reload's unload).
    """
    executor = executor or make_executor(node.context)
    for each in (node, *more_nodes):
        executor.add_node(each)
    share_time_source((node, *more_nodes))
    answer = answer_clock((node, *more_nodes), node.get_name() if not more_nodes
                          else f'{node.get_name()} (+{len(more_nodes)} nodes)')
    with signals_deferred() as stop:
        try:
            while node.context.ok() and not stop.is_set() and not (
                    until is not None and until.is_set()):
                executor.spin_once(timeout_sec=WAKE_PERIOD_S)
                if answer is not None:
                    answer.after_spin(executor)
        finally:
            release_executor(executor)
            executor = None


def release_executor(executor) -> None:
    """
    Shut the executor down now, while signals are still deferred (signals_deferred).

    Left to garbage collection after spin, the C++ EventsExecutor is torn down once the
    raising signal handlers are back; a second Ctrl-C (launch's SIGINT after the
    terminal's) arriving then raised KeyboardInterrupt inside its destructor, which
    aborts the process ("terminate called after throwing pybind11::error_already_set",
    exit -6, launch: "process has died").
    """
    try:
        executor.shutdown(timeout_sec=1.0)
    except Exception:  # noqa: B902 - the context may be shut down already
        pass


#: Set to 'full' for the interpreter's usual teardown at a node process's end (for tools
#: that need it, and bench/node_exit.py's comparison); otherwise leave_process.
TEARDOWN_VARIABLE = 'MECANUM_NODE_TEARDOWN'


#: The hidden node that holds this process's DDS participant (hold_participant).
_participant_holder: Optional[Node] = None
#: What a close is doing, for the close watchdog's message (e.g. the participant's end).
_closing_step = 'destroy or rclpy shutdown'


def hold_participant(name: str) -> None:
    """
    Hold the process's DDS participant with a hidden node, for release_participant.

    For a node process that ends with :func:`leave_process`. rmw_fastrtps destroys the
    participant with the process's last node, and Fast DDS 2.14 can deadlock there while
    a peer's endpoints are being removed (every process of a system stops at once): gdb
    of node processes stuck at Ctrl-C (1 stop in 15-30 under load) showed the main thread
    in rcl_node_fini -> destroy_participant -> DomainParticipant::set_listener, waiting
    for a discovery callback blocked on a lock held by the thread that waited for it.
    rclpy's destroy_node keeps the GIL through that, so the close watchdog's thread could
    not run and faulthandler ended the process with exit 1 and a stack dump. With this
    node (``_NAME_participant_PID``: hidden, no endpoints, no rosout, no parameter
    services) the real nodes' destroy never ends the participant; release_participant
    does, without the GIL. A reload keeps it (the next load needs no new participant).
    """
    global _participant_holder
    if _participant_holder is None:
        _participant_holder = Node(
            f'_{re.sub(r"[^A-Za-z0-9_]", "_", name)}_participant_{os.getpid()}',
            start_parameter_services=False, enable_rosout=False,
            use_global_arguments=False)


def _rcl_node_fini(pointer: int) -> int:
    """Finalise the rcl node at pointer (rcl_node_fini) without the GIL; return its code."""
    librcl = ctypes.CDLL('librcl.so')       # loaded already by rclpy: the same library
    librcl.rcl_node_fini.argtypes = [ctypes.c_void_p]
    librcl.rcl_node_fini.restype = ctypes.c_int
    return librcl.rcl_node_fini(pointer)    # ctypes.CDLL calls release the GIL


#: How release_participant finalises the holder's rcl node (a test makes it hang).
finalize_rcl_node: Callable[[int], int] = _rcl_node_fini


def release_participant() -> None:
    """
    End the DDS participant that hold_participant holds (its node's rcl_node_fini).

    Called once the process's nodes are closed, within close_watchdog: the call runs
    without the GIL, so when Fast DDS deadlocks in it the watchdog's thread still says so
    in a WARN and leaves with exit 0 (every node of the process had closed). rcl may
    finalise a node twice: rclpy's own finalisation of the handle later does nothing.
    """
    global _participant_holder, _closing_step
    holder, _participant_holder = _participant_holder, None
    if holder is None:
        return
    _closing_step = ("the DDS participant's destruction (Fast DDS 2.14 can deadlock there "
                     'at a system stop; every node of the process had closed)')
    try:
        code = finalize_rcl_node(holder.handle.pointer)
    except OSError:     # no librcl.so by that name: rclpy's own way, with the GIL
        holder.destroy_node()
    else:
        if code != 0:
            print(f'[WARN] [{holder.get_name()}]: rcl_node_fini returned {code}',
                  file=sys.stderr, flush=True)
    _closing_step = 'destroy or rclpy shutdown'


def leave_process(code: int) -> NoReturn:
    """
    End the process with code now, without the interpreter's teardown.

    For a node process whose node has closed and whose rclpy context has shut down: the
    teardown (collecting every module's objects) cost 0.15-0.35 s of wall time and up
    to 0.2 CPU s (ekf_node) per process at every stop (a system has a dozen), for
    nothing (bench/node_exit.py). What it did that matters is done first: threads that
    are not daemons are joined, the exit functions run (atexit), the ROS context is
    destroyed (its DDS participant has left: :func:`release_participant`), and stdout and
    stderr are flushed.
    """
    # What the interpreter's exit does first: threading's exit hooks (a thread pool's
    # workers told to end), then every thread that is not a daemon joined; atexit.
    threading._shutdown()
    atexit._run_exitfuncs()
    try:
        rclpy.get_default_context().destroy()
    except Exception:  # noqa: B902 - already destroyed: nothing left to do
        pass
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):   # closed or gone (a terminal that went away)
            pass
    os._exit(code)


def run_node(node_factory: Callable[..., Node], name: str,
             args: Optional[List[str]] = None,
             spin: Optional[Callable[..., None]] = None,
             leave: bool = True) -> int:
    """
    Create the node, spin it until Ctrl-C/SIGTERM, close it; return an exit code.

    ``spin`` replaces :func:`spin_waking` for nodes that drive their own loop; with
    reloads it is called as ``spin(node, until=event)`` and returns once the event is set
    (a reload's unload), else as ``spin(node)``. After a normal close, with ``leave`` (a
    node's own process), the process ends there with code 0 (:func:`leave_process`; not
    with $MECANUM_NODE_TEARDOWN=full); an error still raises, with its traceback. With
    MECANUM_RELOAD=stdin the process takes reload commands
    (:mod:`mecanum_control.node_reload`): the node is closed, and made anew
    (``node_factory(cli_args=..., use_global_arguments=False)``) from the arguments of
    the next ``load``.
    """
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RuntimeError as error:  # rcl failed, e.g. a parameter file that is not YAML
        rclpy.logging.get_logger(name).fatal(f'cannot start: {error}')
        return 2
    # SIGINT also when inherited as ignored (e.g. `cmd &` in a script).
    raise_keyboard_interrupt_on_signals()
    leaving = leave and os.environ.get(TEARDOWN_VARIABLE, '') != 'full'
    if leaving:
        hold_participant(name)
    channel = node_reload.reload_channel()
    until = channel.unload_requested if channel is not None else None
    node_args: Optional[List[str]] = None    # the first node: the process's arguments
    while True:
        try:
            node = (node_factory() if node_args is None else
                    node_factory(cli_args=node_args, use_global_arguments=False))
        except (ValueError, ParameterException, TypeError) as error:
            if isinstance(error, TypeError) and node_args is None:
                raise   # a bug, not a bad parameter (on a reload: a node without options)
            rclpy.logging.get_logger(name).fatal(f'{error}')
            if node_args is not None:
                node_reload.say(f'{node_reload.FAILED_PREFIX}{error}')
            rclpy.try_shutdown()
            return 2
        except KeyboardInterrupt:
            rclpy.try_shutdown()
            return 0
        if node_args is not None:
            node_reload.say(node_reload.LOADED_LINE)
        unloading = False   # True: the spin ended for a reload's unload, not for good
        try:
            if spin is None:
                spin_waking(node, until=until)
            elif until is None:
                spin(node)
            else:
                spin(node, until=until)
            unloading = until is not None and until.is_set()
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        finally:
            if not unloading:
                close_for_good(name, [node])
        if not unloading:
            break
        node_args = unload_and_wait(name, [node], channel)
        if node_args is None:
            rclpy.try_shutdown()
            break
    if leaving:
        with close_watchdog(name):
            leave_process(0)
    return 0


def close_for_good(name: str, nodes: Sequence[Node]) -> None:
    """
    Close the nodes (last first) and shut rclpy down: the process is ending.

    Within close_watchdog (a close stuck in rclpy or DDS does not keep the process).
    Ctrl-C in a terminal under ros2 launch reaches each node twice (the terminal's
    SIGINT to the process group, then launch's own): the second must not cut the close
    short with a traceback. SIGTERM (launch's escalation) still interrupts.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with close_watchdog(name):
        for node in reversed(nodes):
            close_node(node)
        release_participant()
        rclpy.try_shutdown()


def unload_and_wait(name: str, nodes: Sequence[Node], channel) -> Optional[List[str]]:
    """
    Close the nodes for a reload (last first), answer, wait for the next load.

    Return that load's arguments; None: the channel ended or Ctrl-C (the process ends).
    """
    with close_watchdog(name):
        for node in reversed(nodes):
            close_node(node)
    node_reload.say(node_reload.UNLOADED_LINE)
    try:
        return channel.next_load(threading.Event())
    except KeyboardInterrupt:
        return None
