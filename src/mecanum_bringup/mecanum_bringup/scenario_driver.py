"""
The scenario runner's ROS side: one rclpy node in the scenario's own domain.

It listens to the simulator's ground truth (``ground_truth/odom``, map frame; the walking
people's centres, ``ground_truth/moving_obstacles``, for the collision margin), amcl's
estimate (``amcl_pose``), the collision count (``simulation/collisions``), the global plans
(``plan``) and robot_controller's ``control_status``; it sends Nav2's NavigateToPose goals
on ``navigate_to_pose`` and FollowWaypoints goals on ``follow_waypoints``, text commands
on ``control_command`` and body twists (base_link, m/s and rad/s) on a command source's
topic of the command chain (``cmd_vel_scenario`` by default, ``cmd_vel_teleop``, ...:
mecanum_safety config/twist_mux.yaml), so they
go through the mux, the collision monitor and the zone guard like any other. It also
records every stop of the chain (``collision_monitor_state``, ``zone_guard_state``) and
every refusal or early stop of robot_controller, where the robot then was. Faults: it
sends the simulator's fault kinds on ``simulator/faults`` (std_msgs/String, reliable,
transient_local: each message the JSON mapping of robot_simulation.faults.parse_fault,
onset_s absolute in simulated seconds), keeps the simulator's reports of them
(``simulator/active_faults``: when each started and ended, what became of a kidnap) and
plays the operator's e-stop: std_msgs/Bool on
``emergency_stop`` (twist_mux's e_stop lock, motor_controller's latching stop), then on
release false and a call of ``motor_controller/release_emergency_stop`` (std_srvs/Trigger),
the reset without which motor_controller stays stopped. Its clock is the simulator's
(/clock). It spins in a background thread; the runner calls
its methods from the main thread.

In lockstep (:meth:`join_lockstep`) the runner is one of the parts simulated time waits
for: each /clock is held in the spin thread until the main thread has looked at that time
(:meth:`tick`), then answered on ``/clock_ack``. The main thread therefore sees, at each
simulated time, exactly what came in before that /clock (the spin thread takes nothing
after it meanwhile) and its commands for that time go out before time steps on, so the
machine's load does not move a step's start or end (a period or two of jitter remains
at some step changes: issue 19).
"""

import functools
import json
import math
import re
import threading
import time
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped, PoseWithCovarianceStamped, Twist
from mecanum_bringup.scenario_loader import command_sources
from mecanum_control.angles import quaternion_from_yaw, yaw_from_quaternion
from mecanum_control.node_main import make_executor
from mecanum_safety import zone_guard
from nav2_msgs.action import FollowWaypoints, NavigateToPose
from nav_msgs.msg import Odometry, Path
import numpy as np
import rclpy
from rclpy.action import ActionClient
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from robot_simulation.lockstep import PROCESS_DOWN_TOPIC
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Bool, Header, String, UInt32
from std_srvs.srv import Empty, Trigger

#: The command chain's stages whose STOP states are recorded as safety events.
SAFETY_STATE_TOPICS = ('collision_monitor_state', 'zone_guard_state')
#: twist_mux's state (the live source, 'none', 'locked by LOCK', 'held NAME'; latched).
MUX_STATE_TOPIC = 'cmd_vel_mux_state'
#: Numbers in a chain stage's state (a sigma, a distance) do not make a new state.
_NUMBER = re.compile(r'[-+]?\d+(\.\d*)?')
#: Wall seconds to wait for a goal's answer before sending it again (lost in discovery).
GOAL_RESEND_S = 2.0
#: Wall seconds to wait for an answer at all.
ANSWER_TIMEOUT_S = 30.0
#: Wall seconds :meth:`ScenarioDriver.tick` waits for time to go on (then the runner looks
#: at the system again); outside lockstep, the time it sleeps.
TICK_WAIT_S = 0.02
#: The runner's name on /clock_ack.
LOCKSTEP_NAME = 'scenario_runner'
#: The simulator's fault topic and the e-stop's (see the module docstring).
FAULT_TOPIC = 'simulator/faults'
FAULT_REPORT_TOPIC = 'simulator/active_faults'
#: amcl's service that spreads its particles over the map (the amcl_diverged fault).
GLOBAL_LOCALIZATION_SERVICE = 'reinitialize_global_localization'
ESTOP_TOPIC = 'emergency_stop'
ESTOP_RELEASE_SERVICE = 'motor_controller/release_emergency_stop'
#: History kept for late joiners of simulator/faults (a restarted simulator).
FAULT_HISTORY = 100

Poll = Callable[[], float]


def map_pose(x: float, y: float, yaw: float) -> PoseStamped:
    """Return a PoseStamped in the map frame (m, rad)."""
    pose = PoseStamped()
    pose.header.frame_id = 'map'
    pose.pose.position.x, pose.pose.position.y = float(x), float(y)
    q = pose.pose.orientation
    q.x, q.y, q.z, q.w = quaternion_from_yaw(yaw)
    return pose


def _stamp_s(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


class ScenarioDriver:
    """The runner's node: records what happens and sends the steps' commands."""

    def __init__(self, domain_id: int):
        """Create the node in domain_id on simulated time and start spinning it."""
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(
            'scenario_runner', context=self.context,
            parameter_overrides=[Parameter('use_sim_time', value=True)])
        self._lock = threading.Lock()
        self._truth: List[Tuple[float, float, float, float]] = []
        self._estimate: List[Tuple[float, float, float, float]] = []
        self._plans: List[np.ndarray] = []
        self._want_plan = False
        self._collision_count = 0
        self.collision_times: List[float] = []
        self._collision_points: List[Tuple[float, float]] = []
        self._statuses: List[str] = []
        latched = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        node = self.node
        node.create_subscription(Odometry, 'ground_truth/odom', self._on_truth, 50)
        self._movers: List[Tuple[float, int, float, float]] = []
        node.create_subscription(PoseArray, 'ground_truth/moving_obstacles',
                                 self._on_movers, 50)
        node.create_subscription(PoseWithCovarianceStamped, 'amcl_pose', self._on_estimate,
                                 latched)
        node.create_subscription(UInt32, 'simulation/collisions', self._on_collisions, latched)
        node.create_subscription(Path, 'plan', self._on_plan, 10)
        node.create_subscription(String, 'control_status', self._on_status, 20)
        self._safety_events: List[Tuple[float, str, str, float, float]] = []
        self._chain_state: Dict[str, str] = {}
        self._chain_states: List[Tuple[float, str, str]] = []
        for topic in SAFETY_STATE_TOPICS:
            node.create_subscription(String, topic, functools.partial(
                self._on_chain_state, topic.replace('_state', '')), 20)
        node.create_subscription(String, MUX_STATE_TOPIC, functools.partial(
            self._on_chain_state, 'twist_mux'), latched)
        # Until the first step: the pose the zone guard guards with (its /diagnostics).
        self._zone_guard_pose: Optional[str] = None
        self._diagnostics = node.create_subscription(
            DiagnosticArray, '/diagnostics', self._on_diagnostics, 50)
        self._twist_pubs = {topic: node.create_publisher(Twist, topic, 10)
                            for topic in command_sources().values()}
        self.command_pub = node.create_publisher(String, 'control_command', 10)
        self._fault_pub = node.create_publisher(String, FAULT_TOPIC, QoSProfile(
            depth=FAULT_HISTORY, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        # The button's state: a restarted twist_mux reads the latest one (its
        # subscription is volatile, depth 10, which a transient_local writer matches).
        self._estop_pub = node.create_publisher(Bool, ESTOP_TOPIC, QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self._estop_release = node.create_client(Trigger, ESTOP_RELEASE_SERVICE)
        self._down_pub = node.create_publisher(String, PROCESS_DOWN_TOPIC, QoSProfile(
            depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self._global_localization = node.create_client(Empty, GLOBAL_LOCALIZATION_SERVICE)
        self._release_answers: List[Any] = []
        self._release_wanted = False     # until motor_controller accepted a reset
        self._fault_reports: List[Dict[str, Any]] = []
        node.create_subscription(String, FAULT_REPORT_TOPIC, self._on_fault_report, QoSProfile(
            depth=FAULT_HISTORY, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.navigate = ActionClient(node, NavigateToPose, 'navigate_to_pose')
        self.follow_waypoints = ActionClient(node, FollowWaypoints, 'follow_waypoints')
        # Lockstep: the /clock the spin thread holds (arrived), the time the main thread
        # is at (held) and the last one it let go (released); nanoseconds.
        self._time = threading.Condition()
        self._in_lockstep = False
        self._arrived_ns: Optional[int] = None
        self._held_ns: Optional[int] = None
        self._released_ns = -1
        self._check: Callable[[], None] = lambda: None
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self._ack_pub = node.create_publisher(Header, '/clock_ack', reliable)
        node.create_subscription(Clock, '/clock', self._on_clock, reliable)
        self.executor = make_executor(self.context)
        self.executor.add_node(node)
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while self.context.ok() and not self._closing.is_set():
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except Exception:  # noqa: B902 - shutting down mid-spin
                if self.context.ok() and not self._closing.is_set():
                    raise

    # --- lockstep ------------------------------------------------------------------------

    def _on_clock(self, msg: Clock) -> None:
        """In lockstep, hold this /clock (spin thread) until the main thread let it go."""
        clock_ns = msg.clock.sec * 10 ** 9 + msg.clock.nanosec
        with self._time:
            if not self._in_lockstep:
                return
            self._arrived_ns = clock_ns
            self._time.notify_all()
            self._time.wait_for(lambda: not self._in_lockstep or self._closing.is_set()
                                or self._released_ns >= clock_ns)

    def join_lockstep(self, check: Callable[[], None] = lambda: None) -> None:
        """
        Take part in the lockstep from the next /clock on (see the module docstring).

        ``check`` is called while :meth:`tick` waits for time to go on (it may raise to
        end the wait: the system stopped, Ctrl-C).
        """
        self._check = check
        with self._time:
            self._in_lockstep = True
            self._arrived_ns = self._held_ns = None
            self._released_ns = -1

    def leave_lockstep(self) -> None:
        """Stop taking part: let go of any held /clock and no longer answer."""
        with self._time:
            self._in_lockstep = False
            self._held_ns = None
            self._time.notify_all()

    def holding_time(self) -> bool:
        """Whether the runner takes part in the lockstep and holds a /clock."""
        with self._time:
            return self._in_lockstep and self._held_ns is not None

    def tick(self) -> None:
        """
        Done with the current simulated time: let it go and wait for the next one.

        In lockstep: answers the held time on /clock_ack, lets the spin thread go on and
        returns once the next /clock has come (the spin thread holds it), calling the
        ``check`` given to :meth:`join_lockstep` every TICK_WAIT_S of wall time meanwhile.
        It never returns at the time it let go: the spin thread has taken what came after
        that /clock since, so a look at that time again would see messages of the next
        period, or not, by the wall clock's luck. Outside lockstep: sleeps TICK_WAIT_S.
        """
        with self._time:
            if not self._in_lockstep:
                self._time.wait(TICK_WAIT_S)
                return
            held = self._held_ns
            if held is not None and self._released_ns < held:
                self._released_ns = held
                sec, nanosec = divmod(held, 10 ** 9)
                self._ack_pub.publish(Header(stamp=Time(sec=sec, nanosec=nanosec),
                                             frame_id=LOCKSTEP_NAME))
                self._time.notify_all()
        while True:
            with self._time:
                if self._time.wait_for(
                        lambda: self._arrived_ns is not None
                        and (held is None or self._arrived_ns > held), TICK_WAIT_S):
                    self._held_ns = self._arrived_ns
                    return
                if held is None or not self._in_lockstep or self._closing.is_set():
                    return
            self._check()

    # --- what it records ---------------------------------------------------------------

    def _on_truth(self, msg: Odometry) -> None:
        pose, q = msg.pose.pose, msg.pose.pose.orientation
        with self._lock:
            self._truth.append((_stamp_s(msg.header.stamp), pose.position.x,
                                pose.position.y, yaw_from_quaternion(q.x, q.y, q.z, q.w)))

    def _on_movers(self, msg: PoseArray) -> None:
        t = _stamp_s(msg.header.stamp)
        with self._lock:
            self._movers.extend((t, index, pose.position.x, pose.position.y)
                                for index, pose in enumerate(msg.poses))

    def _on_estimate(self, msg: PoseWithCovarianceStamped) -> None:
        pose, q = msg.pose.pose, msg.pose.pose.orientation
        with self._lock:
            self._estimate.append((_stamp_s(msg.header.stamp), pose.position.x,
                                   pose.position.y, yaw_from_quaternion(q.x, q.y, q.z, q.w)))

    def _on_collisions(self, msg: UInt32) -> None:
        with self._lock:
            new = int(msg.data) - self._collision_count
            if new <= 0:
                return
            self._collision_count = int(msg.data)
            t, x, y, _ = self._truth[-1] if self._truth else (math.nan,) * 4
            self.collision_times.extend([t] * new)
            self._collision_points.extend([(x, y)] * new)

    def _on_plan(self, msg: Path) -> None:
        with self._lock:
            if not self._want_plan or not msg.poses:
                return
            self._want_plan = False
            self._plans.append(np.array([(p.pose.position.x, p.pose.position.y)
                                         for p in msg.poses]))

    def _on_status(self, msg: String) -> None:
        with self._lock:
            self._statuses.append(msg.data)
            if msg.data.startswith(('rejected', 'stopped')):
                self._add_safety_event('robot_controller', msg.data)

    def _on_chain_state(self, node_name: str, msg: String) -> None:
        """
        Record each change of a chain stage's state (not every message).

        Every change (numbers aside) goes into chain_states; a change into a STOP, a lock
        or a hold is also a safety event.
        """
        with self._lock:
            previous = self._chain_state.get(node_name)
            self._chain_state[node_name] = msg.data
            if previous is not None and _NUMBER.sub('#', previous) == _NUMBER.sub(
                    '#', msg.data):
                return
            t = self._truth[-1][0] if self._truth else math.nan
            self._chain_states.append((t, node_name, msg.data))
            stopping = ('STOP', 'locked', 'held')
            if msg.data.startswith(stopping) and not (previous or '').startswith(stopping):
                self._add_safety_event(node_name, msg.data)

    def chain_states(self) -> List[Tuple[float, str, str]]:
        """Return (t, node, state) at each change of a chain stage's state."""
        with self._lock:
            return list(self._chain_states)

    def _add_safety_event(self, node_name: str, text: str) -> None:
        """Append an event at the latest true pose (call with the lock held)."""
        t, x, y, _ = self._truth[-1] if self._truth else (math.nan,) * 4
        self._safety_events.append((t, node_name, text, x, y))

    def _on_fault_report(self, msg: String) -> None:
        try:
            report = json.loads(msg.data)
        except ValueError:
            return
        if isinstance(report, dict):
            with self._lock:
                self._fault_reports.append(report)

    def fault_reports(self) -> List[Dict[str, Any]]:
        """Return the simulator's fault reports so far ({time_s, started, ended, ...})."""
        with self._lock:
            return list(self._fault_reports)

    def safety_events(self) -> List[Tuple[float, str, str, float, float]]:
        """Return (t, node, state, x, y) of every stop or refusal of the command chain."""
        with self._lock:
            return list(self._safety_events)

    def sim_now(self) -> Optional[float]:
        """Return the simulated time (s) the runner is at, None before the first /clock."""
        with self._time:
            if self._in_lockstep and self._held_ns is not None:
                return self._held_ns * 1e-9
        nanoseconds = self.node.get_clock().now().nanoseconds
        return nanoseconds * 1e-9 if nanoseconds > 0 else None

    def latest_truth(self) -> Optional[Tuple[float, float, float, float]]:
        """Return the newest true pose (t, x, y, yaw), or None."""
        with self._lock:
            return self._truth[-1] if self._truth else None

    def truth_track(self) -> np.ndarray:
        """Return the ground truth so far as (N, 4) t, x, y, yaw."""
        with self._lock:
            return np.array(self._truth, dtype=np.float64).reshape(-1, 4)

    def movers_track(self) -> np.ndarray:
        """Return the walking people's true centres so far as (M, 4) t, k, x, y."""
        with self._lock:
            return np.array(self._movers, dtype=np.float64).reshape(-1, 4)

    def estimate_track(self) -> np.ndarray:
        """Return amcl's estimates so far as (N, 4) t, x, y, yaw."""
        with self._lock:
            return np.array(self._estimate, dtype=np.float64).reshape(-1, 4)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name == zone_guard.DIAGNOSTIC_NAME:
                pose = next((pair.value for pair in status.values
                             if pair.key == zone_guard.DIAGNOSTIC_POSE_KEY), None)
                with self._lock:
                    self._zone_guard_pose = pose

    def zone_guard_pose(self) -> Optional[str]:
        """
        Return the zone guard's last word on its pose (None: nothing heard yet).

        '(x, y, yaw)': it has map -> base_link, fresh; else why not ('no pose: ...').
        """
        with self._lock:
            return self._zone_guard_pose

    def stop_watching_diagnostics(self) -> None:
        """Drop the /diagnostics subscription (every node's, once a second: not needed)."""
        if self._diagnostics is not None:
            self.node.destroy_subscription(self._diagnostics)
            self._diagnostics = None

    def plans(self) -> List[np.ndarray]:
        """Return the first global plan (K, 2) of every goal."""
        with self._lock:
            return list(self._plans)

    def collision_points(self) -> List[Tuple[float, float]]:
        """Return where (true x, y) each collision began."""
        with self._lock:
            return list(self._collision_points)

    def status_line(self, elapsed_s: float) -> str:
        """Return a one-line progress report: time, true pose, amcl error, collisions."""
        with self._lock:
            truth = self._truth[-1] if self._truth else None
            estimate = self._estimate[-1] if self._estimate else None
            collisions = self._collision_count
            # amcl updates every update_min_d: compare with the truth of its time.
            then = None if estimate is None else next(
                (t for t in reversed(self._truth) if t[0] <= estimate[0]), None)
        if truth is None:
            return f'+{elapsed_s:.0f} s: no ground truth yet'
        text = (f'+{elapsed_s:.0f} s: at ({truth[1]:.2f}, {truth[2]:.2f}) m, '
                f'{math.degrees(truth[3]):.0f} deg')
        if then is not None:
            error = math.hypot(estimate[1] - then[1], estimate[2] - then[2])
            text += f', amcl off by {error:.2f} m'
        return text + f', collisions {collisions}'

    # --- what it sends -------------------------------------------------------------------

    def wait_for_navigator(self, timeout_s: float) -> bool:
        """Wait (wall s) for the navigate_to_pose action server."""
        return self.navigate.wait_for_server(timeout_sec=timeout_s)

    def send_goal(self, x: float, y: float, yaw: float, poll: Poll):
        """Send a NavigateToPose goal (map frame) and return its handle (None: no answer)."""
        goal = NavigateToPose.Goal()
        goal.pose = map_pose(x, y, yaw)
        return self._send(self.navigate, goal, poll)

    def send_waypoints(self, poses: Sequence[Tuple[float, float, float]], poll: Poll):
        """Send a FollowWaypoints goal (map frame poses) and return its handle (None: none)."""
        goal = FollowWaypoints.Goal()
        goal.poses = [map_pose(x, y, yaw) for x, y, yaw in poses]
        return self._send(self.follow_waypoints, goal, poll)

    def _send(self, client: ActionClient, goal, poll: Poll):
        """
        Send a goal and return its handle (None: no answer within ANSWER_TIMEOUT_S).

        A goal sent before the server matched this client's response reader is lost
        (DDS discovery is asynchronous): it is sent again after GOAL_RESEND_S; a resent
        goal preempts the lost one, if that one arrived.
        """
        with self._lock:
            self._want_plan = True
        deadline = time.monotonic() + ANSWER_TIMEOUT_S
        while time.monotonic() < deadline:
            future = client.send_goal_async(goal)
            attempt_end = min(deadline, time.monotonic() + GOAL_RESEND_S)
            while not future.done() and time.monotonic() < attempt_end:
                poll()
                self.tick()
            if future.done():
                return future.result()
        return None

    def cancel(self, handle, poll: Poll) -> None:
        """Cancel a goal and wait (up to 5 wall s) for the answer."""
        future = handle.cancel_goal_async()
        deadline = time.monotonic() + 5.0
        while not future.done() and time.monotonic() < deadline:
            poll()
            self.tick()

    def reach_robot_controller(self, poll: Poll) -> None:
        """
        Make sure text commands reach robot_controller at once: send 'stop' until answered.

        A message sent before its reader has matched the writer is dropped and sent again
        only on the writer's next heartbeat, wall seconds later (DDS discovery matches
        the two sides separately), so a scenario's first command could start a variable
        time late. An answer to 'stop' (harmless: the robot stands) shows both ways work.
        """
        deadline = time.monotonic() + ANSWER_TIMEOUT_S
        while True:
            statuses = self.send_command('stop', poll)
            resend = time.monotonic() + GOAL_RESEND_S / 4.0
            while time.monotonic() < resend:
                if 'done: stop' in statuses():
                    return
                if time.monotonic() > deadline:
                    raise RuntimeError('robot_controller does not answer on control_status')
                poll()
                self.tick()

    def send_command(self, text: str, poll: Poll) -> Callable[[], List[str]]:
        """
        Send a robot_controller text command once it has a subscriber.

        Returns a function giving the control_status messages that arrived since the
        previous call (starting from this send).
        """
        deadline = time.monotonic() + ANSWER_TIMEOUT_S
        while self.command_pub.get_subscription_count() == 0:
            if time.monotonic() > deadline:
                raise RuntimeError('robot_controller is not listening on control_command')
            poll()
            self.tick()
        with self._lock:
            seen = [len(self._statuses)]
        self.command_pub.publish(String(data=text))

        def new_statuses() -> List[str]:
            with self._lock:
                fresh = self._statuses[seen[0]:]
                seen[0] = len(self._statuses)
            return fresh
        return new_statuses

    def publish_twist(self, vx: float, vy: float, wz: float,
                      topic: str = 'cmd_vel_scenario') -> None:
        """Publish one body twist (m/s, m/s, rad/s) on a command source's topic."""
        publisher = self._twist_pubs[topic]
        msg = Twist()
        msg.linear.x, msg.linear.y, msg.angular.z = float(vx), float(vy), float(wz)
        publisher.publish(msg)

    def send_fault(self, fault: Mapping[str, Any]) -> None:
        """Send one fault to the simulator (parse_fault's mapping, onset_s absolute)."""
        self._fault_pub.publish(String(data=json.dumps(dict(fault), sort_keys=True)))

    def set_estop(self, engaged: bool) -> None:
        """
        Press (True) or release (False) the operator's e-stop.

        Release publishes false and asks motor_controller to reset its latched stop (the
        answer is not awaited: the call goes out now, at this simulated time). The call
        can overtake the false, which motor_controller then refuses ('emergency_stop is
        still true'): keep_releasing asks again, as an operator presses reset again.
        """
        self._estop_pub.publish(Bool(data=bool(engaged)))
        self._release_wanted = not engaged
        if not engaged:
            self._release_answers.append(self._estop_release.call_async(Trigger.Request()))

    def process_down(self, name: str) -> None:
        """Tell the simulator's lockstep that process name was just frozen or killed."""
        self._down_pub.publish(String(data=name))

    def reinitialize_global_localization(self) -> bool:
        """
        Ask amcl to spread its particles over the whole map (Nav2's std_srvs/Empty service).

        Returns False (nothing asked) when no amcl serves it. The answer is not awaited.
        """
        if not self._global_localization.service_is_ready():
            return False
        self._global_localization.call_async(Empty.Request())
        return True

    def keep_releasing(self) -> None:
        """Ask for the e-stop's reset again if the last call was refused; call every poll."""
        if not self._release_wanted or not self._release_answers:
            return
        last = self._release_answers[-1]
        if not last.done():
            return
        answer = last.result()
        if answer is not None and answer.success:
            self._release_wanted = False
            return
        self._release_answers.append(self._estop_release.call_async(Trigger.Request()))

    def close(self) -> None:
        """Stop spinning and shut the node's context down."""
        self._closing.set()
        self.leave_lockstep()
        self._thread.join(timeout=5.0)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
