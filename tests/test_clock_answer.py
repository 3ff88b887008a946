"""
Integration: a process answers a /clock only once the work that /clock starts is done.

mecanum_control.node_main.ClockAnswer with real rclpy (EventsExecutor) and DDS, in one
test process: a "stack" context (two nodes, spun as node_main.spin_waking does) and a
"simulator" context that publishes /clock and listens to /clock_ack, as the simulator's
lockstep does.

1. A timer made due by a /clock starts a chain of four callbacks through both nodes:
   when the answer to that /clock arrives, the whole chain has run, at that time.
2. A message that came before a /clock, and the message its callback publishes within
   the process, are handled at the time before that /clock (the chain finishes first).
3. A message from another process sent just after a /clock is handled at that /clock's
   time, also when it arrives while the stack finishes the time before.
4. With node_main.share_time_source (as spin_waking does), one /clock subscription drives
   both nodes' clocks, and the chain of 1. still runs before the answer.
5. /clock messages that arrive together (a busy process) are taken as one: a timer runs
   once, and again at each following /clock (the EventsExecutor ran it once per /clock
   message, then skipped as many periods).
"""

import threading
import time

from builtin_interfaces.msg import Time
from mecanum_control.node_main import answer_clock, make_executor, share_time_source
import pytest
import rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Header, Int64

pytestmark = pytest.mark.integration

PERIOD_NS = 20_000_000     # 0.02 s of simulated time per /clock, the simulator's default
RELIABLE = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)


class Stack:
    """Two nodes on simulated time in one executor, answering /clock via ClockAnswer."""

    def __init__(self, domain_id: int, shared_time_source: bool = False):
        self.shared_time_source = shared_time_source
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        sim_time = [Parameter('use_sim_time', value=True)]
        self.first = Node('chain_start', context=self.context, parameter_overrides=sim_time)
        self.second = Node('chain_rest', context=self.context, parameter_overrides=sim_time)
        self.chain_done = []     # (simulated time ns when the chain's end ran, data)
        self.timer_calls = []    # simulated time ns of each call of the chain's timer
        self.forwarded = []      # (simulated time ns when 'forwarded' was handled, data)
        # Chain 1: timer (first) -> a (second) -> b (first) -> c (second) -> record.
        self.pub_a = self.first.create_publisher(Int64, 'a', RELIABLE)
        self.pub_b = self.second.create_publisher(Int64, 'b', RELIABLE)
        self.pub_c = self.first.create_publisher(Int64, 'c', RELIABLE)
        self.second.create_subscription(Int64, 'a', lambda m: self.pub_b.publish(m), RELIABLE)
        self.first.create_subscription(Int64, 'b', lambda m: self.pub_c.publish(m), RELIABLE)
        self.second.create_subscription(Int64, 'c', self._on_chain_end, RELIABLE)
        self.first.create_timer(PERIOD_NS * 1e-9, self._on_timer)
        # Chain 2: 'outside' from the simulator -> 'forwarded' within the process -> record.
        self.pub_forwarded = self.second.create_publisher(Int64, 'forwarded', RELIABLE)
        self.first.create_subscription(
            Int64, 'outside', lambda m: self.pub_forwarded.publish(m), RELIABLE)
        self.second.create_subscription(Int64, 'forwarded', self._on_forwarded, RELIABLE)
        # Chain 3: 'slow' from the simulator takes 20 ms, then goes on within the process.
        self.pub_slow_done = self.first.create_publisher(Int64, 'slow_done', RELIABLE)
        self.first.create_subscription(Int64, 'slow', self._on_slow, RELIABLE)
        self.second.create_subscription(Int64, 'slow_done', lambda m: None, RELIABLE)
        self.executor = make_executor(self.context)
        for node in (self.first, self.second):
            self.executor.add_node(node)
        if shared_time_source:
            share_time_source((self.first, self.second))
        self.answer = answer_clock((self.first, self.second), 'stack')
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _now_ns(self, node: Node) -> int:
        return node.get_clock().now().nanoseconds

    def _on_timer(self):
        self.timer_calls.append(self._now_ns(self.first))
        self.pub_a.publish(Int64(data=self._now_ns(self.first)))

    def _on_slow(self, msg: Int64):
        time.sleep(0.02)
        self.pub_slow_done.publish(msg)

    def _on_chain_end(self, msg: Int64):
        self.chain_done.append((self._now_ns(self.second), msg.data))

    def _on_forwarded(self, msg: Int64):
        self.forwarded.append((self._now_ns(self.second), msg.data))

    def forwarded_off_time(self, count: int) -> list:
        """Wait (5 s at most) for count 'forwarded'; return those not handled at their ns."""
        deadline = time.monotonic() + 5.0
        while len(self.forwarded) < count and time.monotonic() < deadline:
            time.sleep(0.01)
        assert len(self.forwarded) == count
        return [(handled, sent) for handled, sent in self.forwarded if handled != sent]

    def _spin(self):
        while self.context.ok() and not self._stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)
            self.answer.after_spin(self.executor)

    def close(self):
        self._stop.set()
        self._thread.join(timeout=5)
        self.executor.shutdown()
        for node in (self.first, self.second):
            node.destroy_node()
        rclpy.try_shutdown(context=self.context)


class Simulator:
    """Publishes /clock and 'outside'; notes each /clock_ack and what the stack had done."""

    def __init__(self, domain_id: int, stack: Stack):
        self.stack = stack
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = Node('simulator', context=self.context)
        self.clock_pub = self.node.create_publisher(Clock, '/clock', RELIABLE)
        self.outside_pub = self.node.create_publisher(Int64, 'outside', RELIABLE)
        self.slow_pub = self.node.create_publisher(Int64, 'slow', RELIABLE)
        self.acked = threading.Condition()
        self.acks = {}    # acked /clock ns -> the stack's chain_done at that moment
        self.node.create_subscription(Header, '/clock_ack', self._on_ack, RELIABLE)
        self.executor = make_executor(self.context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _on_ack(self, msg: Header):
        with self.acked:
            self.acks[msg.stamp.sec * 10 ** 9 + msg.stamp.nanosec] = list(
                self.stack.chain_done)
            self.acked.notify_all()

    def _spin(self):
        while self.context.ok() and not self._stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    def publish_clock(self, clock_ns: int):
        sec, nanosec = divmod(clock_ns, 10 ** 9)
        self.clock_pub.publish(Clock(clock=Time(sec=sec, nanosec=nanosec)))

    def wait_for_ack(self, clock_ns: int, timeout_s: float = 10.0) -> bool:
        with self.acked:
            return self.acked.wait_for(lambda: clock_ns in self.acks, timeout_s)

    def close(self):
        self._stop.set()
        self._thread.join(timeout=5)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture(params=[False, True], ids=['own_time_sources', 'shared_time_source'])
def stack_and_simulator(ros_env, monkeypatch, request):
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    domain_id = int(ros_env['ROS_DOMAIN_ID'])
    stack = Stack(domain_id, shared_time_source=request.param)
    simulator = Simulator(domain_id, stack)
    try:
        yield stack, simulator
    finally:
        simulator.close()
        stack.close()


def start_lockstep(stack: Stack, simulator: Simulator) -> int:
    """Publish /clock until the stack answers (discovery done); return the answered ns."""
    clock_ns = PERIOD_NS
    deadline = time.monotonic() + 20.0
    while True:
        simulator.publish_clock(clock_ns)
        if simulator.wait_for_ack(clock_ns, timeout_s=0.2):
            return clock_ns
        assert time.monotonic() < deadline, 'the stack never answered /clock'
        clock_ns += PERIOD_NS


def test_the_answer_comes_after_the_chain_a_timer_starts(stack_and_simulator):
    stack, simulator = stack_and_simulator
    clock_ns = start_lockstep(stack, simulator)
    first_checked = clock_ns + PERIOD_NS
    for _ in range(100):
        clock_ns += PERIOD_NS
        simulator.publish_clock(clock_ns)
        assert simulator.wait_for_ack(clock_ns), f'no answer to /clock {clock_ns} ns'
    for acked_ns in range(first_checked, clock_ns + 1, PERIOD_NS):
        done = simulator.acks[acked_ns]
        # The timer ran at acked_ns and its chain of four callbacks ended at that time,
        # before the answer went out.
        assert (acked_ns, acked_ns) in done, (
            f'answered /clock {acked_ns} before the chain its timer started had run: '
            f'chain ends so far {done[-3:]}')


def test_messages_before_a_clock_are_handled_at_the_time_before(stack_and_simulator):
    stack, simulator = stack_and_simulator
    clock_ns = start_lockstep(stack, simulator)
    for _ in range(50):
        # 'outside' goes out just before the next /clock, without waiting: the stack
        # must finish it (and what its callback publishes) at the time before.
        simulator.outside_pub.publish(Int64(data=clock_ns))
        clock_ns += PERIOD_NS
        simulator.publish_clock(clock_ns)
        assert simulator.wait_for_ack(clock_ns), f'no answer to /clock {clock_ns} ns'
    late = stack.forwarded_off_time(50)
    assert not late, f'handled after the next /clock (handled ns, sent at ns): {late[:5]}'


def test_messages_after_a_clock_are_handled_at_its_time(stack_and_simulator):
    stack, simulator = stack_and_simulator
    clock_ns = start_lockstep(stack, simulator)
    for _ in range(50):
        # 'slow' keeps the stack busy with the time before when the /clock comes, and
        # 'outside' goes out just after that /clock: it reaches the stack while it still
        # finishes the time before, and must wait for the new time.
        simulator.slow_pub.publish(Int64(data=clock_ns))
        clock_ns += PERIOD_NS
        simulator.publish_clock(clock_ns)
        simulator.outside_pub.publish(Int64(data=clock_ns))
        assert simulator.wait_for_ack(clock_ns), f'no answer to /clock {clock_ns} ns'
    early = stack.forwarded_off_time(50)
    assert not early, f'handled before its /clock (handled ns, sent at ns): {early[:5]}'


def test_a_shared_time_source_is_one_clock_subscription_for_every_node(stack_and_simulator):
    stack, simulator = stack_and_simulator
    clock_subscriptions = [sub for node in (stack.first, stack.second)
                           for sub in node.subscriptions if sub.topic_name == '/clock']
    assert len(clock_subscriptions) == (1 if stack.shared_time_source else 2)
    clock_ns = start_lockstep(stack, simulator)
    assert stack.first.get_clock().now().nanoseconds == clock_ns
    assert stack.second.get_clock().now().nanoseconds == clock_ns


def test_clocks_that_arrive_while_busy_run_a_timer_once_and_skip_no_period(
        stack_and_simulator):
    """Three /clock messages reach the stack while it is busy (the 'slow' callback)."""
    stack, simulator = stack_and_simulator
    clock_ns = start_lockstep(stack, simulator)
    for _ in range(5):
        simulator.slow_pub.publish(Int64(data=clock_ns))
        for _ in range(3):
            clock_ns += PERIOD_NS
            simulator.publish_clock(clock_ns)
        assert simulator.wait_for_ack(clock_ns), f'no answer to /clock {clock_ns} ns'
        together = clock_ns
        for _ in range(3):
            clock_ns += PERIOD_NS
            simulator.publish_clock(clock_ns)
            assert simulator.wait_for_ack(clock_ns), f'no answer to /clock {clock_ns} ns'
        calls = [stack.timer_calls.count(t) for t in range(together, clock_ns + 1, PERIOD_NS)]
        assert calls == [1, 1, 1, 1], (
            f'timer calls at /clock {together} ns (3 taken together) and the 3 after: {calls}')


class TimedProcess:
    """
    One node with a 50 Hz timer on simulated time, spun by hand as spin_waking does.

    The test hands /clock messages straight to the node's /clock callback (as the
    executor would), so several come in one round of the executor at will; a second node
    subscribes to /clock_ack when asked, which puts ClockAnswer in lockstep.
    """

    def __init__(self, domain_id: int):
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = Node('timed', context=self.context,
                         parameter_overrides=[Parameter('use_sim_time', value=True)])
        self.calls = []
        self.node.create_timer(PERIOD_NS * 1e-9, lambda: self.calls.append(
            self.node.get_clock().now().nanoseconds))
        self.listener = Node('simulator', context=self.context)
        self.executor = make_executor(self.context)
        self.executor.add_node(self.node)
        self.answer = answer_clock([self.node], 'timed')
        self._clock_callback = next(sub.callback for sub in self.node.subscriptions
                                    if sub.topic_name == '/clock')

    def clock(self, clock_ns: int) -> None:
        sec, nanosec = divmod(clock_ns, 10 ** 9)
        self._clock_callback(Clock(clock=Time(sec=sec, nanosec=nanosec)))

    def start_lockstep(self) -> None:
        """Subscribe to /clock_ack; return once ClockAnswer sees the subscription."""
        self.listener.create_subscription(Header, '/clock_ack', lambda msg: None, RELIABLE)
        deadline = time.monotonic() + 10.0
        while self.answer.publisher.get_subscription_count() == 0:
            assert time.monotonic() < deadline, 'the /clock_ack subscription was not matched'
            time.sleep(0.01)

    def run_round(self) -> int:
        """Run the executor and ClockAnswer as spin_waking does; return the timer's calls."""
        before = len(self.calls)
        for _ in range(20):
            self.answer.after_spin(self.executor)
            self.executor.spin_once(timeout_sec=0.0)
        return len(self.calls) - before

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.listener.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def timed_process(ros_env, monkeypatch):
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    process = TimedProcess(int(ros_env['ROS_DOMAIN_ID']))
    try:
        yield process
    finally:
        process.close()


@pytest.mark.parametrize('lockstep', [True, False], ids=['lockstep', 'free_running'])
def test_clocks_taken_in_one_round_run_a_timer_once_and_skip_no_period(timed_process,
                                                                       lockstep):
    """
    Three /clock messages come in one round of the executor (a busy process), 20 times.

    rclpy's EventsExecutor dispatches a timer once per jump of its clock and calls it
    again even when it is no longer due, which pushes its next call as many periods
    ahead: taking the three one after the other ran a 50 Hz timer 3 times, then skipped
    2 periods (in lockstep hardware_interface then sent no command for the next /clock
    and simulated time stood still for 10 s: 1 sweep run in 16). ClockAnswer takes the
    newest only, in lockstep and outside it.
    """
    if lockstep:
        timed_process.start_lockstep()
    clock_ns, counts = 10 ** 9, []
    for round_ in range(60):
        for _ in range(3 if round_ % 3 == 0 else 1):
            clock_ns += PERIOD_NS
            timed_process.clock(clock_ns)
        counts.append(timed_process.run_round())
    assert counts[1:] == [1] * 59, f'timer calls per round (3 clocks every third): {counts}'


def test_clocks_from_before_and_after_lockstep_begins_are_taken_as_one(timed_process):
    """
    The simulator's /clock_ack subscription matches between two /clock of one round.

    The first /clock came outside lockstep (taken after the round), the second in it
    (held): taking both jumped the clock twice, the timer ran twice and skipped the next
    period; in lockstep the board then got no command and time stood still 10 s (1 sweep
    run in 74, at its start).
    """
    clock_ns = 10 ** 9
    for _ in range(3):
        clock_ns += PERIOD_NS
        timed_process.clock(clock_ns)
        assert timed_process.run_round() == 1
    clock_ns += PERIOD_NS
    timed_process.clock(clock_ns)         # outside lockstep: waits for the round's end
    timed_process.start_lockstep()
    clock_ns += PERIOD_NS
    timed_process.clock(clock_ns)         # in lockstep: held
    counts = [timed_process.run_round()]
    for _ in range(5):
        clock_ns += PERIOD_NS
        timed_process.clock(clock_ns)
        counts.append(timed_process.run_round())
    assert counts == [1] * 6, f'timer calls per round from the transition on: {counts}'
