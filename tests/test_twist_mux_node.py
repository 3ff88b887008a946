"""
Integration: the twist_mux node with the project's config/twist_mux.yaml, on simulated time.

A launch file written into the test's folder starts the node as command_chain.launch.yaml
does (the installed config, use_sim_time, cmd_vel_out remapped to cmd_vel_mux). The test
node publishes on the sources' topics about every 50 ms of wall time (simulated time runs
at half speed, so every source speaks well within its 0.5 s timeout) and on
emergency_stop, and records cmd_vel_mux with the simulated time of each arrival, and
cmd_vel_mux_state. One writer's messages on one topic arrive in order, so "nothing
after the zero twist" and "only teleop's twists after its first" are exact checks;
silence is proved by /diagnostics showing the masked source still received.
"""

import math
from pathlib import Path
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Twist
import pytest
from std_msgs.msg import Bool, String
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
REAL_TIME_FACTOR = 0.5
NAV = (0.1, 0.0, 0.0)
TELEOP = (0.0, 0.2, 0.3)
ZERO = (0.0, 0.0, 0.0)


def write_launch(directory: Path) -> Path:
    """Write the test system: the twist_mux node as the command chain starts it."""
    launch = {'launch': [
        {'node': {'pkg': 'mecanum_safety', 'exec': 'twist_mux', 'name': 'twist_mux',
                  'param': [
                      {'from': '$(find-pkg-share mecanum_safety)/config/twist_mux.yaml'},
                      {'name': 'use_sim_time', 'value': True}],
                  'remap': [{'from': 'cmd_vel_out', 'to': 'cmd_vel_mux'}]}},
    ]}
    path = directory / 'twist_mux_test.launch.yaml'
    path.write_text(yaml.safe_dump(launch, sort_keys=False))
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

        # Released: teleop (the highest live source) drives again.
        mark_t = time.monotonic()
        lock_pub.publish(Bool(data=False))
        outputs.wait_for(TELEOP, stop + 1)
        states.wait_since(mark_t, lambda m: m.data == 'teleop_keyboard')
    finally:
        navigation.stop()
        teleop.stop()
    assert outputs.all_finite()
    assert 'Traceback' not in system.output()
