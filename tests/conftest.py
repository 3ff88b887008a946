"""Fixtures for integration tests: real nodes, real processes, real DDS, isolated.

Every test gets its own ROS_DOMAIN_ID (leased, so parallel runs never meet),
localhost-only discovery, and drives simulated time by publishing /clock itself.
"""

import functools
import math
import os
from pathlib import Path
import re
import shlex
import shutil
import signal
import subprocess
import sys
import termios
import threading
import time
import uuid

from geometry_msgs.msg import Twist
from mecanum_bringup.isolation import (
    isolated_environment, lease_domain_id, processes_with_variable)
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from robot_simulation.lockstep import Lockstep, LockstepConfig
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Header

REPO = Path(__file__).resolve().parents[1]
RUN_MARKER = 'MECANUM_TEST_RUN'


def processes_with_marker(marker: str) -> list:
    """Return the PIDs of live processes whose environment has RUN_MARKER=marker."""
    return processes_with_variable(RUN_MARKER, marker)


#: The real `ros2` command that make setup builds (None where it found no upstream sources).
ROS2 = shutil.which('ros2')


@pytest.fixture
def needs_ros2():
    """Skip, saying why, where make setup could not build the ros2 command."""
    if ROS2 is None:
        pytest.skip('no ros2 command: make setup found no upstream ros2cli sources (see '
                    'tools/ros2_upstream.py)')


def native_stacks(pid: int) -> str:
    """Return every thread's native stack of a live process (gdb), or why there is none."""
    if shutil.which('gdb') is None:
        return f'{pid}: no gdb to show its stacks'
    try:
        result = subprocess.run(['gdb', '-p', str(pid), '-batch', '-ex', 'thread apply all bt 25'],
                                capture_output=True, text=True, timeout=60)
    except subprocess.TimeoutExpired:
        return f'{pid}: gdb took more than 60 s'
    frames = [line for line in result.stdout.splitlines() if line.startswith(('#', 'Thread'))]
    return f'--- native stacks of {pid}:\n' + '\n'.join(frames)


def interrupt_group(process: subprocess.Popen, timeout: float = 15.0) -> int:
    """
    Ctrl-C a process's group (as the shell does), SIGKILL it after timeout; return the code.

    Before the SIGKILL, the native stacks of the group's processes are printed (the test's
    captured output): a process stuck in C code (e.g. in its DDS participant's
    destruction) says where.
    """
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGINT)
        try:
            process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            group = subprocess.run(['pgrep', '-g', str(process.pid)], capture_output=True,
                                   text=True).stdout.split()
            print(f'{shlex.join(map(str, process.args))}: still running {timeout:g} s after '
                  'Ctrl-C')
            for pid in group:
                print(native_stacks(int(pid)))
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    return process.returncode


class OutputProcess:
    """A process whose output lines (stdout and stderr) are kept with their arrival times."""

    def __init__(self, command: list, env: dict, cwd=None):
        self.lines = []  # (monotonic arrival time s, line)
        self._lock = threading.Lock()
        self.process = subprocess.Popen(
            command, env=env, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True, start_new_session=True)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.process.stdout:
            with self._lock:
                self.lines.append((time.monotonic(), line.rstrip('\n')))

    def output(self) -> str:
        with self._lock:
            return '\n'.join(line for _, line in self.lines)

    def wait_for_line_at(self, pattern: str, timeout: float = 20.0) -> tuple:
        """Wait until an output line matches pattern; return (its arrival time, the match)."""
        regex = re.compile(pattern)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            exited = self.process.poll() is not None
            with self._lock:
                for when, line in self.lines:
                    match = regex.search(line)
                    if match:
                        return when, match
            if exited and not self._reader.is_alive():  # every line read, none matched
                break
            time.sleep(0.05)
        raise AssertionError(f'no output line matched {pattern!r}; output:\n{self.output()}')

    def wait_for_line(self, pattern: str, timeout: float = 20.0) -> re.Match:
        """Wait until an output line matches pattern; return the match."""
        return self.wait_for_line_at(pattern, timeout)[1]

    def lines_since(self, start: float) -> list:
        """Return (arrival time s, line) of the lines that arrived at or after start."""
        with self._lock:
            return [(when, line) for when, line in self.lines if when >= start]


class TerminalProcess:
    """A command as typed in a shell: a process group of its own, a pty as stdin."""

    def __init__(self, command: list, env: dict, cwd=None):
        """Start it; with a pseudo-terminal as stdin (teleop reads keys from it)."""
        self.master, self.slave = os.openpty()
        self.terminal_settings = termios.tcgetattr(self.slave)
        self.process = subprocess.Popen(
            command, stdin=self.slave, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True, env=env, cwd=cwd, start_new_session=True)
        self.lines = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.process.stdout:
            self.lines.append(line.rstrip('\n'))

    def output(self) -> str:
        """Return everything it printed so far."""
        return '\n'.join(self.lines)

    def wait_for_output(self, pattern: str, timeout: float = 30.0) -> None:
        """Wait until a line matches pattern; fail with the output if it exits first."""
        deadline = time.monotonic() + timeout
        while not re.search(pattern, self.output()):
            assert self.process.poll() is None, f'exited:\n{self.output()}'
            assert time.monotonic() < deadline, f'no {pattern!r} in:\n{self.output()}'
            time.sleep(0.02)

    def type_keys(self, keys: str) -> None:
        """Type keys on its terminal."""
        os.write(self.master, keys.encode())

    def terminal_restored(self) -> bool:
        """Tell whether the terminal settings are those from before the process started."""
        return termios.tcgetattr(self.slave) == self.terminal_settings

    def stop(self) -> int:
        """Ctrl-C, as in the shell; return the exit code."""
        interrupt_group(self.process)
        self.close()
        return self.process.returncode

    def close(self) -> None:
        """Kill the process group if it still runs; close the terminal."""
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGKILL)
            self.process.wait(timeout=5)
        if self.master is not None:
            os.close(self.master)
            os.close(self.slave)
            self.master = self.slave = None


class RunningSystem(OutputProcess):
    """A launch_runner process running a system description, with its output captured."""

    def __init__(self, launch_args: list, env: dict):
        self.marker = uuid.uuid4().hex
        super().__init__([sys.executable, '-m', 'mecanum_bringup.launch_runner', *launch_args],
                         dict(env, **{RUN_MARKER: self.marker}))

    def node_pid(self, label: str, start: int = 1) -> int:
        """PID of a node from the runner's 'started/restarted LABEL (... pid N)' lines."""
        if start == 1:
            pattern = rf'\[runner\] started {re.escape(label)} \(pid (\d+)\)'
        else:
            pattern = rf'\[runner\] restarted {re.escape(label)} \(start {start}, pid (\d+)\)'
        return int(self.wait_for_line(pattern).group(1))

    def stop(self, sig=signal.SIGINT, timeout: float = 15.0) -> int:
        """Signal the runner as Ctrl-C would and return its exit code."""
        if self.process.poll() is None:
            self.process.send_signal(sig)
        return self.process.wait(timeout=timeout)

    def kill_everything(self):
        """Last resort after a failed test: nothing of this run may survive."""
        for pid in processes_with_marker(self.marker) + [self.process.pid]:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


@pytest.fixture(name='processes_with_marker')
def processes_with_marker_fixture():
    """Return the function that lists a RunningSystem's live processes (by marker)."""
    return processes_with_marker


class MarkedEnvironment:
    """os.environ plus a marker of this test, to find the processes it left running."""

    def __init__(self):
        self.marker = uuid.uuid4().hex
        self.env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
                        **{RUN_MARKER: self.marker})

    def leftovers(self) -> list:
        """Return the PIDs of live processes started with this environment (or by them)."""
        return processes_with_marker(self.marker)

    def kill_leftovers(self) -> list:
        """SIGKILL every live process started with this environment; return their PIDs."""
        left = self.leftovers()
        for pid in left:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        return left


@pytest.fixture
def marked_env(ros_env):
    """
    Yield a MarkedEnvironment for this test's subprocesses (localhost-only discovery).

    Other tests may run beside this one (pytest-xdist), so a test looking for its
    leftover processes looks for its own marker only. Whatever the test's outcome, the
    processes it left are killed at the end, before its ROS domain (ros_env, torn down
    after this) goes back to the pool: a failed test's leftovers (CI once: launch
    killed, its nodes orphaned and still publishing on the wall clock) otherwise talked
    into the later tests that leased the same domain.
    """
    marked = MarkedEnvironment()
    yield marked
    marked.kill_leftovers()


@pytest.fixture
def ros_env():
    """Yield an environment with a leased ROS_DOMAIN_ID and localhost-only discovery."""
    with lease_domain_id() as lease:
        env = isolated_environment(os.environ, lease.domain_id)
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        yield env


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Keep each phase's report on the test item, so fixtures can tell a failed test."""
    outcome = yield
    report = outcome.get_result()
    setattr(item, f'report_{report.when}', report)


#: Lines of a system's output printed when its test failed (CI keeps nothing else).
FAILED_OUTPUT_LINES = 150


@pytest.fixture
def start_system(ros_env, request):
    """
    Start systems with launch_runner in the test's domain; kill leftovers at the end.

    When the test failed, the end of each system's output (its nodes' logs) is printed,
    so that the CI log shows what the nodes said.
    """
    systems = []

    def start(*launch_args: str) -> RunningSystem:
        system = RunningSystem(list(launch_args), ros_env)
        systems.append(system)
        return system
    yield start
    report = getattr(request.node, 'report_call', None)
    if report is not None and report.failed:
        for system in systems:
            tail = system.output().splitlines()[-FAILED_OUTPUT_LINES:]
            print(f'--- last {len(tail)} lines of {system.process.args[3:]} ---')
            print('\n'.join(tail))
    for system in systems:
        if system.process.poll() is None:
            system.stop(signal.SIGKILL)
        system.kill_everything()


class Recorder:
    """Collects messages of one topic from the test node."""

    def __init__(self, node, msg_type, topic, qos=50):
        """Subscribe node to topic (reliable, depth 50, unless qos says otherwise)."""
        self.messages = []
        self._lock = threading.Lock()
        node.create_subscription(msg_type, topic, self._on_message, qos)

    def _on_message(self, msg):
        with self._lock:
            self.messages.append((time.monotonic(), msg))

    def wait_for(self, predicate, timeout=20.0):
        """Return the first message (also among those already received) matching predicate."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                for _, msg in self.messages:
                    if predicate(msg):
                        return msg
            time.sleep(0.02)
        raise AssertionError(f'no matching message within {timeout} s '
                             f'({len(self.messages)} received)')

    def latest(self, received_by: float = math.inf):
        """Return the newest message received by monotonic time received_by, or None."""
        with self._lock:
            return next((msg for when, msg in reversed(self.messages) if when <= received_by),
                        None)

    def messages_between(self, start_s: float, end_s: float) -> list:
        """Messages whose header stamp lies in [start_s, end_s] (ROS time, s)."""
        with self._lock:
            return [msg for _, msg in self.messages
                    if start_s <= msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
                    <= end_s]

    def since(self, start: float) -> list:
        """Messages received at or after monotonic time start."""
        with self._lock:
            return [msg for when, msg in self.messages if when >= start]

    def received_since(self, start: float) -> list:
        """(monotonic arrival time s, message) of the messages received since start."""
        with self._lock:
            return [(when, msg) for when, msg in self.messages if when >= start]

    def wait_for_new(self, predicate, timeout=20.0):
        """Like wait_for, but only among messages received from now on."""
        return self.wait_since(time.monotonic(), predicate, timeout)

    def wait_since(self, start: float, predicate, timeout=20.0):
        """Return the first message received since monotonic time start matching predicate."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for msg in self.since(start):
                if predicate(msg):
                    return msg
            time.sleep(0.02)
        raise AssertionError(f'no new matching message within {timeout} s; the last ones: '
                             f'{[getattr(m, "data", m) for m in self.since(start)[-10:]]}')


#: The seed simulation's robot_status text (std_msgs/String).
SEED_POSITION = re.compile(r'Position: x=(-?\d+\.\d+), y=(-?\d+\.\d+), theta=(-?\d+\.\d+)')


def settled_seed_position(status: 'Recorder', since: float, timeout: float = 30.0,
                          moved_m: float = 0.0) -> tuple:
    """
    Return the seed simulation's (x, y, theta) once it has moved and stands still.

    Waits until two robot_status messages received after since (monotonic s) in a row
    give the same position (the simulation publishes it at 10 Hz), at least moved_m
    from the origin.
    """
    deadline = time.monotonic() + timeout
    while True:
        positions = [tuple(float(v) for v in match.groups()) for match in (
            SEED_POSITION.fullmatch(m.data) for m in status.since(since)) if match]
        if (len(positions) >= 2 and positions[-1] == positions[-2]
                and math.hypot(*positions[-1][:2]) >= moved_m):
            return positions[-1]
        assert time.monotonic() < deadline, f'robot_status never settled: {positions[-5:]}'
        time.sleep(0.05)


#: On the wall clock, robot_controller starts a held command once its publisher sees the
#: simulation's subscription; the simulation may match it a moment later and miss the
#: first twists (seen on the loaded CI machine), so an open-loop move there may come out
#: shorter than commanded, never longer.
SEED_SHORTFALL_M = 0.3


class LoopThread:
    """
    A daemon thread that runs the subclass's _run() from start() until stop().

    _run() loops while ``not self._stop.is_set()``; stop() waits up to 5 s for it.
    """

    def __init__(self):
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def start(self):
        """Start the thread."""
        self._thread.start()

    def stop(self):
        """Stop the thread."""
        self._stop.set()
        self._thread.join(timeout=5)

    def _run(self):
        raise NotImplementedError


class TwistRepeater(LoopThread):
    """
    Publishes one twist (vx, vy, wz) on a topic about every 50 ms (wall time) while set.

    ``twist`` None keeps it silent; ``last_sent_sim_s`` is the simulated time (the test
    node's clock) of the last twist sent. start() begins, stop() ends the thread.
    """

    def __init__(self, test_node: 'TestNode', topic: str):
        self.test_node = test_node
        self.publisher = test_node.node.create_publisher(Twist, topic, 10)
        self.twist = None
        self.last_sent_sim_s = math.nan
        super().__init__()

    def _run(self):
        while not self._stop.is_set():
            twist = self.twist
            if twist is not None:
                msg = Twist()
                msg.linear.x, msg.linear.y, msg.angular.z = (float(v) for v in twist)
                try:
                    self.publisher.publish(msg)
                except Exception:  # noqa: B902 - the context shut down
                    return
                self.last_sent_sim_s = self.test_node.clock_ns * 1e-9
            time.sleep(0.05)


#: A process that has neither answered a test /clock nor said it is alive (/clock_alive,
#: every 1 s from node_main.ClockAnswer's own thread) for this long (wall s) is not
#: waited for until it answers again: a killed or frozen one. A busy one is still
#: alive: dropping it after 1 s of silence on a loaded machine let simulated time run on
#: without it (a composed container's twist then drove 0.1 m too far).
CLOCK_ACK_TIMEOUT_S = 3.0
#: Wall seconds after which an unanswered test /clock is published again (the simulator's
#: robot_simulation.simulator_node.CLOCK_RESEND_S).
CLOCK_RESEND_S = 1.0


def publish_quietly(publisher, msg) -> None:
    """Publish msg; nothing if the context has shut down meanwhile."""
    try:
        publisher.publish(msg)
    except Exception:  # noqa: B902 - context shut down
        pass


class ClockAcks:
    """
    The /clock_ack answers of a system's processes, for a test clock to wait for.

    The simulator's own rule (robot_simulation.lockstep.Lockstep, no board): a process
    that owes the last /clock and has been silent (no answer, no /clock_alive) for
    CLOCK_ACK_TIMEOUT_S is gone until it answers again.
    """

    def __init__(self):
        self._condition = threading.Condition()
        self._lockstep = Lockstep(LockstepConfig(timeout_s=CLOCK_ACK_TIMEOUT_S))

    def on_ack(self, msg: Header):
        with self._condition:
            self._lockstep.ack(msg.frame_id, msg.stamp.sec + msg.stamp.nanosec * 1e-9,
                               time.monotonic())
            self._condition.notify_all()

    def on_alive(self, msg: Header):
        with self._condition:
            self._lockstep.alive(msg.frame_id, time.monotonic())

    def wait_for_participant(self, name_prefix: str, timeout: float = 30.0) -> str:
        """Wait until a process whose /clock_ack name starts with name_prefix answered."""
        def found():
            return next((name for name in self._lockstep.participants
                         if name.startswith(name_prefix)), None)
        with self._condition:
            assert self._condition.wait_for(found, timeout), (
                f'no /clock_ack from {name_prefix!r} within {timeout} s (answered: '
                f'{self._lockstep.participants})')
            return found()

    def wait_for(self, clock_ns: int, context, publish_again=None):
        """
        Wait until every live participant has answered clock_ns (or went silent).

        Every CLOCK_RESEND_S while someone still owes it, publish_again() sends that
        /clock again, as the simulator does: a process respawned under the same name
        says it is alive but missed the /clock (it subscribed after it went out).
        """
        with self._condition:
            self._lockstep.published(clock_ns * 1e-9, time.monotonic())
            resend_at = time.monotonic() + CLOCK_RESEND_S
            while context.ok() and self._lockstep.waiting_for(time.monotonic()):
                self._condition.wait(timeout=0.05)
                if publish_again is not None and time.monotonic() >= resend_at:
                    publish_again()
                    resend_at = time.monotonic() + CLOCK_RESEND_S
            self._lockstep.events()   # parts gone and back: nothing to log here


class ClockAnswerer:
    """
    A test node's part in the lockstep: each /clock answered on /clock_ack as name.

    :meth:`hold` keeps the answers back (simulated time waits, up to the simulator's
    lockstep timeout), :meth:`release` sends them. on_clock(clock_ns), if given, runs at
    each /clock before its answer: what it publishes goes out before time steps on.
    """

    def __init__(self, node, name: str, on_clock=None):
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.name = name
        self._on_clock_callback = on_clock
        self._publisher = node.create_publisher(Header, '/clock_ack', reliable)
        self._lock = threading.Lock()
        self._holding = False
        self._held = []
        node.create_subscription(Clock, '/clock', self._on_clock, reliable)

    def _on_clock(self, msg: Clock):
        if self._on_clock_callback is not None:
            self._on_clock_callback(msg.clock.sec * 10 ** 9 + msg.clock.nanosec)
        with self._lock:
            self._held.append(msg.clock)
            if not self._holding:
                self._answer()

    def _answer(self):
        for stamp in self._held:
            publish_quietly(self._publisher, Header(stamp=stamp, frame_id=self.name))
        self._held.clear()

    def hold(self):
        """Answer no /clock until release()."""
        with self._lock:
            self._holding = True

    def release(self):
        """Answer the /clock messages held back, and each new one at once again."""
        with self._lock:
            self._holding = False
            self._answer()


class TestNode:
    """An rclpy node of the test process, spun in a background thread."""

    def __init__(self, domain_id: int):
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node('integration_test', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()
        self.clock_ns = 0

    def _spin(self):
        while self.context.ok() and not self._closing.is_set():
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except Exception:  # noqa: B902 - shutting down mid-spin
                if self.context.ok():
                    raise

    def start_clock(self, real_time_factor: float = 1.0, step_s: float = 0.005,
                    follow_wall_clock: bool = False):
        """
        Publish /clock from a thread, one step_s of simulated time per step.

        By default simulated time advances by exactly step_s per step, and only once
        every process of the system on simulated time has answered the last /clock on
        /clock_ack (node_main.ClockAnswer: it has taken that /clock and done the work it
        starts), as the simulator's lockstep does. A busy machine (other
        tests beside this one) therefore slows simulated time down instead of making the
        system miss it. A process silent for CLOCK_ACK_TIMEOUT_S of wall time (killed,
        not started yet) is not waited for until it answers again. With
        follow_wall_clock simulated time is the elapsed wall time times
        real_time_factor and waits for nobody, for systems that also contain real-time
        parts (the board emulator).
        """
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        publisher = self.node.create_publisher(Clock, '/clock', reliable)
        acks = self.clock_acks = ClockAcks()
        if not follow_wall_clock:
            self.node.create_subscription(Header, '/clock_ack', acks.on_ack, reliable)
            self.node.create_subscription(Header, '/clock_alive', acks.on_alive, reliable)
        start = time.monotonic()

        def run():
            while self.context.ok():
                if follow_wall_clock:
                    self.clock_ns = int((time.monotonic() - start) * real_time_factor * 1e9)
                else:
                    self.clock_ns += int(step_s * 1e9)
                msg = Clock()
                msg.clock.sec, msg.clock.nanosec = divmod(self.clock_ns, 10 ** 9)
                published = time.monotonic()
                try:
                    publisher.publish(msg)
                except Exception:  # noqa: B902 - context shut down
                    return
                if follow_wall_clock:
                    time.sleep(step_s)
                    continue
                acks.wait_for(self.clock_ns, self.context, functools.partial(
                    publish_quietly, publisher, msg))
                time.sleep(max(0.0, step_s / real_time_factor - (time.monotonic() - published)))
        threading.Thread(target=run, daemon=True).start()

    def answer_clock(self, name: str, on_clock=None) -> 'ClockAnswerer':
        """
        Take part in a simulator's lockstep as name: answer each /clock on /clock_ack.

        The answer goes out from the spin thread once the messages that came before that
        /clock have been handled (callbacks of subscriptions made before this one run
        first in a round of the executor), so a test that commands the robot from what it
        receives is waited for and cannot fall behind simulated time on a loaded machine.
        on_clock: see ClockAnswerer.
        """
        return ClockAnswerer(self.node, name, on_clock)

    def wait_sim(self, sim_seconds: float, timeout: float = 60.0):
        """Wait until simulated time (clock_ns) has advanced by sim_seconds."""
        target = self.clock_ns + int(sim_seconds * 1e9)
        deadline = time.monotonic() + timeout
        while self.clock_ns < target:
            assert time.monotonic() < deadline, 'simulated time does not advance'
            time.sleep(0.01)

    def call(self, client, request, timeout: float = 15.0):
        """
        Call a service and return its response, retrying lost requests.

        A request sent before the client is matched with a (re)started server is lost
        (DDS discovery is asynchronous), so each attempt waits 2 s, then tries again.
        """
        assert client.wait_for_service(timeout_sec=timeout), f'{client.srv_name} not found'
        deadline = time.monotonic() + timeout
        while True:
            future = client.call_async(request)
            attempt_end = time.monotonic() + 2.0
            while not future.done() and time.monotonic() < attempt_end:
                time.sleep(0.02)
            if future.done():
                return future.result()
            client.remove_pending_request(future)
            assert time.monotonic() < deadline, f'{client.srv_name} did not answer'

    def record(self, msg_type, topic: str, latched: bool = False) -> 'Recorder':
        """Start recording a topic (latched: transient local, for latched topics)."""
        qos = QoSProfile(depth=50)
        if latched:
            qos.durability = DurabilityPolicy.TRANSIENT_LOCAL
        return Recorder(self.node, msg_type, topic, qos)

    def twist_repeater(self, topic: str) -> TwistRepeater:
        """Return a TwistRepeater on topic (not started)."""
        return TwistRepeater(self, topic)

    def close(self):
        # Stop spinning before destroying what the spin thread waits on (otherwise it
        # may touch a destroyed guard condition while the context is still valid).
        self._closing.set()
        self._thread.join(timeout=5)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def test_node(ros_env):
    """An rclpy node in the test's ROS domain."""
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    node = TestNode(int(ros_env['ROS_DOMAIN_ID']))
    yield node
    node.close()
