"""
Integration: the twist_mux node with the project's config/twist_mux.yaml, on simulated time.

A launch file written into the test's folder starts the node with command_chain.launch.yaml's
own entry for it (the installed config and motor_params.yaml, cmd_vel_out remapped to
cmd_vel_mux; use_sim_time), and for the emergency stop also motor_controller as
control.launch.yaml starts it, fed by cmd_vel_mux. The test node publishes on the sources'
topics about every 50 ms of wall time (simulated time runs at half speed, so every source
speaks well within its 0.5 s timeout) and on emergency_stop, and records cmd_vel_mux with
the simulated time of each arrival, and cmd_vel_mux_state. One writer's messages on one
topic arrive in order, so "nothing after the zero twist" and "only teleop's twists after
its first" are exact checks; silence is proved by /diagnostics showing the masked (or
held) source still received, and by motor_controller's 50 Hz motor_speeds all zero.
"""

import math
from pathlib import Path
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Twist
from mecanum_control.kinematics import inverse_kinematics
from mecanum_control.robot_config import load_robot_config
import pytest
from std_msgs.msg import Bool, Float32MultiArray, String
from std_srvs.srv import Trigger
import yaml

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
PARAMS = yaml.safe_load(
    (REPO / 'src/mecanum_safety/config/twist_mux.yaml').read_text()
)['twist_mux']['ros__parameters']
TOPICS = PARAMS['topics']
NAV_TOPIC = TOPICS['navigation']['topic']
TELEOP_TOPIC = TOPICS['teleop_keyboard']['topic']
TELEOP_TIMEOUT_S = TOPICS['teleop_keyboard']['timeout']
LOCK_TOPIC = PARAMS['locks']['e_stop']['topic']
LATCH_TOPIC = PARAMS['locks']['e_stop_latched']['topic']
REAL_TIME_FACTOR = 0.5
NAV = (0.1, 0.0, 0.0)
TELEOP = (0.0, 0.2, 0.3)
ZERO = (0.0, 0.0, 0.0)
ROBOT = load_robot_config(REPO / 'src/mecanum_control/config/motor_params.yaml')
RELEASE_SERVICE = '/motor_controller/release_emergency_stop'


def chain_mux_entry() -> dict:
    """Return command_chain.launch.yaml's twist_mux node, on simulated time, no respawn."""
    chain = yaml.safe_load(
        (REPO / 'src/mecanum_safety/launch/command_chain.launch.yaml').read_text())
    node = next(item['node'] for item in chain['launch']
                if 'node' in item and item['node']['name'] == 'twist_mux')
    params = [dict(param, value=True) if param.get('name') == 'use_sim_time' else param
              for param in node['param']]
    return {'pkg': node['pkg'], 'exec': node['exec'], 'name': node['name'],
            'param': params, 'remap': node['remap']}


def write_launch(directory: Path, motor_controller: bool = False) -> Path:
    """Write the test system: twist_mux as the command chain starts it (+ motor_controller)."""
    nodes = [{'node': chain_mux_entry()}]
    if motor_controller:
        share = '$(find-pkg-share mecanum_control)/config'
        nodes.append({'node': {
            'pkg': 'mecanum_control', 'exec': 'motor_controller', 'name': 'motor_controller',
            'remap': [{'from': 'cmd_vel', 'to': 'cmd_vel_mux'}],
            'param': [{'from': f'{share}/motor_params.yaml'},
                      {'from': f'{share}/mecanum_controllers.yaml'},
                      {'name': 'estop_latch_file', 'value': str(directory / 'estop_latched')},
                      {'name': 'use_sim_time', 'value': True}]}})
    path = directory / 'twist_mux_test.launch.yaml'
    path.write_text(yaml.safe_dump({'launch': nodes}, sort_keys=False))
    return path


class Outputs:
    """The twists received on a topic, each with the simulated time of its arrival."""

    def __init__(self, test_node, topic):
        """Subscribe."""
        self.test_node = test_node
        self._lock = threading.Lock()
        self.items = []   # (arrival sim time s, (vx, vy, wz), every component finite)
        test_node.node.create_subscription(Twist, topic, self._on_message, 50)

    def _on_message(self, msg):
        values = (msg.linear.x, msg.linear.y, msg.linear.z,
                  msg.angular.x, msg.angular.y, msg.angular.z)
        with self._lock:
            self.items.append((self.test_node.clock_ns * 1e-9,
                               (msg.linear.x, msg.linear.y, msg.angular.z),
                               all(math.isfinite(v) for v in values)))

    def count(self):
        """Return how many twists have arrived."""
        with self._lock:
            return len(self.items)

    def since(self, start):
        """Return the (sim time, twist) items from index start on."""
        with self._lock:
            return [(t, twist) for t, twist, _ in self.items[start:]]

    def all_finite(self):
        """Return whether every twist received was finite."""
        with self._lock:
            return all(finite for _, _, finite in self.items)

    def wait_for(self, twist, start, timeout=20.0):
        """Return the index of the first item from index start on equal to twist."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for offset, (_, value) in enumerate(self.since(start)):
                if value == pytest.approx(twist, abs=1e-9):
                    return start + offset
            time.sleep(0.02)
        raise AssertionError(f'no twist {twist} within {timeout} s; since index {start}: '
                             f'{self.since(start)[-10:]}')

    def wait_count(self, count, timeout=20.0):
        """Wait until count twists have arrived."""
        deadline = time.monotonic() + timeout
        while self.count() < count:
            assert time.monotonic() < deadline, f'fewer than {count} twists: {self.count()}'
            time.sleep(0.02)


def diagnostic_values(msg):
    """Return {key: value} of the twist_mux status in a DiagnosticArray ({} if absent)."""
    for status in msg.status:
        if status.name.startswith('twist_mux'):
            return {kv.key: kv.value for kv in status.values}
    return {}


def test_priorities_timeouts_nan_and_the_emergency_stop_lock(
        start_system, test_node, tmp_path):
    """
    Navigation passes; teleop overrides it; navigation is back 0.5 s after teleop stops.

    Then a NaN from navigation is dropped (one zero twist, then silence), and the
    emergency stop masks both sources (one zero twist, then silence) until released.
    """
    test_node.start_clock(real_time_factor=REAL_TIME_FACTOR)
    outputs = Outputs(test_node, 'cmd_vel_mux')
    states = test_node.record(String, 'cmd_vel_mux_state', latched=True)
    diagnostics = test_node.record(DiagnosticArray, '/diagnostics')
    lock_pub = test_node.node.create_publisher(Bool, LOCK_TOPIC, 10)
    system = start_system(str(write_launch(tmp_path)))
    system.wait_for_line(r'\[twist_mux\].*Twist mux started: topics external \(cmd_vel, '
                         r'0\.5 s, priority 90\), joystick')
    states.wait_for(lambda m: m.data == 'none')
    navigation = test_node.twist_repeater(NAV_TOPIC)
    teleop = test_node.twist_repeater(TELEOP_TOPIC)
    navigation.start()
    teleop.start()
    try:
        # Navigation alone passes through.
        navigation.twist = NAV
        first_nav = outputs.wait_for(NAV, 0)
        states.wait_for(lambda m: m.data == 'navigation')

        # Teleop (95) overrides navigation (10): after teleop's first twist, only its own.
        teleop.twist = TELEOP
        first_teleop = outputs.wait_for(TELEOP, first_nav)
        states.wait_for(lambda m: m.data == 'teleop_keyboard')
        outputs.wait_count(first_teleop + 15)
        assert all(v == TELEOP for _, v in outputs.since(first_teleop)), \
            outputs.since(first_teleop)

        # Teleop stops: navigation wins again once teleop's 0.5 s (sim) have passed,
        # with no zero twist in between (a live source was left).
        mark, mark_t = outputs.count(), time.monotonic()
        teleop.twist = None
        time.sleep(0.1)   # let a publish in progress finish before reading its time
        last_teleop_s = teleop.last_sent_sim_s
        back = outputs.wait_for(NAV, mark)
        back_s = outputs.since(back)[0][0]
        print(f'navigation back {back_s - last_teleop_s:.3f} s (sim) after the last teleop '
              'twist')
        assert TELEOP_TIMEOUT_S - 0.05 <= back_s - last_teleop_s <= TELEOP_TIMEOUT_S + 0.3
        assert all(v == TELEOP for _, v in outputs.since(mark)[:back - mark])
        states.wait_since(mark_t, lambda m: m.data == 'navigation')

        # A NaN twist from the only live source is not forwarded: the source counts as
        # silent, so one zero twist stops the robot, then nothing.
        mark, mark_t = outputs.count(), time.monotonic()
        navigation.twist = (math.nan, 0.0, 0.0)
        zero = outputs.wait_for(ZERO, mark)
        system.wait_for_line(r'\[WARN\].*\[twist_mux\].*navigation: twist on '
                             r'cmd_vel_smoothed rejected \(linear\.x is nan\)')
        states.wait_since(mark_t, lambda m: m.data == 'none')
        diagnostics.wait_for_new(
            lambda m: diagnostic_values(m).get('velocity navigation', '').startswith('silent'))
        assert all(v == NAV for _, v in outputs.since(mark)[:zero - mark])
        assert outputs.count() == zero + 1, outputs.since(zero)
        assert outputs.all_finite()

        # Finite again: forwarded again. Then the emergency stop engages: one zero twist
        # at once, and nothing while both sources keep publishing (masked).
        mark = outputs.count()
        navigation.twist = NAV
        outputs.wait_for(NAV, mark)
        teleop.twist = TELEOP
        resumed = outputs.wait_for(TELEOP, mark)
        deadline = time.monotonic() + 10.0
        while lock_pub.get_subscription_count() < 1:
            assert time.monotonic() < deadline, 'twist_mux does not subscribe emergency_stop'
            time.sleep(0.02)
        mark_t = time.monotonic()
        lock_pub.publish(Bool(data=True))
        stop = outputs.wait_for(ZERO, resumed)
        states.wait_since(mark_t, lambda m: m.data == 'locked by e_stop')
        system.wait_for_line(r'\[WARN\].*\[twist_mux\].*Lock e_stop engaged')
        diagnostics.wait_for_new(
            lambda m: diagnostic_values(m).get('velocity teleop_keyboard', '')
            .startswith('masked') and diagnostic_values(m).get('velocity navigation', '')
            .startswith('masked'))
        assert all(v != ZERO for _, v in outputs.since(resumed)[:stop - resumed])
        assert outputs.count() == stop + 1, outputs.since(stop)

        # Released while both keep publishing: their stale streams are held (no
        # motor_controller here, so no latch: the button alone locked the mux).
        mark_t = time.monotonic()
        lock_pub.publish(Bool(data=False))
        states.wait_since(mark_t, lambda m: m.data == 'held teleop_keyboard')
        diagnostics.wait_since(
            mark_t, lambda m: diagnostic_values(m).get('velocity teleop_keyboard', '')
            .startswith('held') and diagnostic_values(m).get('velocity navigation', '')
            .startswith('held'))
        assert outputs.count() == stop + 1, outputs.since(stop)
        # A new command (teleop lets go: a zero twist, then drives): forwarded.
        teleop.twist = ZERO
        rearmed = outputs.wait_for(ZERO, stop + 1)
        assert rearmed == stop + 1, outputs.since(stop)
        teleop.twist = TELEOP
        outputs.wait_for(TELEOP, rearmed)
        states.wait_since(mark_t, lambda m: m.data == 'teleop_keyboard')
    finally:
        navigation.stop()
        teleop.stop()
    assert outputs.all_finite()
    assert 'Traceback' not in system.output()


def test_an_over_limit_diagonal_leaves_the_mux_with_its_direction_within_limits(
        start_system, test_node, tmp_path):
    """
    (0.8, 0.8, 0) m/s on navigation comes out as (0.56, 0.56, 0): 45 deg, within limits.

    motor_params.yaml: vy <= 0.6 m/s scales it by 0.75, then the wheels (1.2 m/s / 0.04 m
    = 30 rad/s > 28) by 28 / 30. Before, the mux forwarded it as is and motor_controller
    clamped it per axis to (0.8, 0.6), then to (0.64, 0.48): 37 deg, another twist than
    the one collision_monitor and zone_guard had judged.
    """
    test_node.start_clock(real_time_factor=REAL_TIME_FACTOR)
    outputs = Outputs(test_node, 'cmd_vel_mux')
    system = start_system(str(write_launch(tmp_path)))
    navigation = test_node.twist_repeater(NAV_TOPIC)
    navigation.start()
    try:
        navigation.twist = NAV
        first = outputs.wait_for(NAV, 0)                  # within limits: unchanged
        navigation.twist = (0.8, 0.8, 0.0)
        limited = outputs.wait_for((0.56, 0.56, 0.0), first)
        vx, vy, wz = outputs.since(limited)[0][1]
        assert math.atan2(vy, vx) == pytest.approx(math.pi / 4, abs=1e-12)
        assert abs(vx) <= ROBOT.max_velocity_x_m_s and abs(vy) <= ROBOT.max_velocity_y_m_s
        wheels = inverse_kinematics(ROBOT.geometry, vx, vy, wz)
        assert max(abs(w) for w in wheels) <= ROBOT.max_wheel_speed_rad_s + 1e-9
        system.wait_for_line(r'\[twist_mux\].*navigation: twist \(0\.8, 0\.8, 0\) over '
                             r"the robot's limits: scaled by 0\.7, direction kept")
        # Nothing else came out in between: every output is NAV or the limited diagonal.
        assert all(v in (NAV, pytest.approx((0.56, 0.56, 0.0), abs=1e-9))
                   for _, v in outputs.since(0)), outputs.since(0)
        system.wait_for_line(r'\[twist_mux\].*Twist mux started: .*limits vx 0\.8 m/s, vy '
                             r'0\.6 m/s, wz 2\.5 rad/s, wheels 28 rad/s')
    finally:
        navigation.stop()
    assert 'Traceback' not in system.output()


def wait_subscribers(publisher, count, what):
    """Wait until publisher has count matched subscriptions."""
    deadline = time.monotonic() + 15.0
    while publisher.get_subscription_count() < count:
        assert time.monotonic() < deadline, f'{what}: {publisher.get_subscription_count()}'
        time.sleep(0.02)


def test_the_emergency_stop_latches_until_cleared_then_needs_a_new_command(
        start_system, test_node, tmp_path):
    """
    The e-stop latches (twist_mux and motor_controller): let go, cleared, still stopped.

    Pressed, then let go while navigation keeps driving: still stopped. A clear while
    pressed is refused; the clear (one service call) does not resume the stale stream
    either: only navigation's new command (a zero, then a twist) moves the wheels again.
    """
    test_node.start_clock(real_time_factor=REAL_TIME_FACTOR)
    outputs = Outputs(test_node, 'cmd_vel_mux')
    states = test_node.record(String, 'cmd_vel_mux_state', latched=True)
    diagnostics = test_node.record(DiagnosticArray, '/diagnostics')
    speeds = test_node.record(Float32MultiArray, 'motor_speeds')
    estop = test_node.node.create_publisher(Bool, LOCK_TOPIC, 10)
    release = test_node.node.create_client(Trigger, RELEASE_SERVICE)
    system = start_system(str(write_launch(tmp_path, motor_controller=True)))
    system.wait_for_line(r'\[twist_mux\].*Twist mux started')
    system.wait_for_line(r'\[motor_controller\].*Motor controller started')
    navigation = test_node.twist_repeater(NAV_TOPIC)
    navigation.start()

    def still_stopped(mark_t, status):
        """Navigation still reaches the mux (diagnostics), nothing reaches the wheels."""
        count = outputs.count()
        diagnostics.wait_since(mark_t, lambda m: diagnostic_values(m).get(
            'velocity navigation', '').startswith(status))
        deadline = time.monotonic() + 20.0
        while len(speeds.since(mark_t)) < 50:          # 1 s of 50 Hz motor_speeds
            assert time.monotonic() < deadline, 'motor_speeds stopped coming'
            time.sleep(0.02)
        assert all(all(v == 0.0 for v in m.data) for m in speeds.since(mark_t))
        assert outputs.count() == count, outputs.since(count - 1)

    try:
        navigation.twist = NAV
        outputs.wait_for(NAV, 0)
        speeds.wait_for(lambda m: min(m.data) > 1.0)     # 0.1 m/s = 2.5 rad/s per wheel
        wait_subscribers(estop, 2, 'emergency_stop subscribers (twist_mux, motor_controller)')

        # Pressed: one zero twist, the wheels at zero at once.
        mark_t = time.monotonic()
        estop.publish(Bool(data=True))
        stop = outputs.wait_for(ZERO, 0)
        system.wait_for_line(r'\[motor_controller\].*EMERGENCY STOP engaged')
        speeds.wait_since(mark_t, lambda m: all(v == 0.0 for v in m.data))
        states.wait_since(mark_t, lambda m: m.data == 'locked by e_stop')
        # A clear while the button is still pressed is refused.
        answer = test_node.call(release, Trigger.Request())
        assert not answer.success and 'still true' in answer.message, answer.message

        # Let go while navigation keeps publishing: still locked, by motor_controller's
        # latch (emergency_stop_latched), and the wheels stay at zero.
        mark_t = time.monotonic()
        estop.publish(Bool(data=False))
        states.wait_since(mark_t, lambda m: m.data == 'locked by e_stop_latched')
        still_stopped(mark_t, 'masked')
        assert outputs.count() == stop + 1, outputs.since(stop)

        # The one clear action: released, but navigation's stale stream is held.
        mark_t = time.monotonic()
        answer = test_node.call(release, Trigger.Request())
        assert answer.success and 'released' in answer.message, answer.message
        states.wait_since(mark_t, lambda m: m.data == 'held navigation')
        still_stopped(mark_t, 'held')
        assert outputs.count() == stop + 1, outputs.since(stop)

        # A new command from navigation (it stops: a zero twist, then drives): motion.
        mark_t = time.monotonic()
        navigation.twist = ZERO
        rearmed = outputs.wait_for(ZERO, stop + 1)
        assert rearmed == stop + 1, outputs.since(stop)
        navigation.twist = NAV
        outputs.wait_for(NAV, rearmed)
        states.wait_since(mark_t, lambda m: m.data == 'navigation')
        speeds.wait_since(mark_t, lambda m: min(m.data) > 1.0)
    finally:
        navigation.stop()
    assert 'Traceback' not in system.output()
