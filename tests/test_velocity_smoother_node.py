"""
Integration: the velocity_smoother node (velocity_smoother.launch.yaml) on simulated time.

The test node publishes commands on cmd_vel_nav (the launch file remaps the node's
cmd_vel there, as Nav2's bringup does) about every 50 ms of wall time and records
cmd_vel_smoothed with the simulated time at which each message arrived. Expected values
come from config/velocity_smoother.yaml: one output per 1 / smoothing_frequency s, each
at most max_accel / smoothing_frequency away from the one before. Simulated time runs at
half the wall clock's speed, so the delivery delays (wall time) count half in simulated
time; the slope measured from arrival times is checked to 20 %, the per-message steps
exactly.
"""

import math
from pathlib import Path
import re
import signal
import subprocess
import threading
import time

from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
import numpy as np
import pytest
import yaml

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
PARAMS = yaml.safe_load(
    (REPO / 'src/mecanum_navigation/config/velocity_smoother.yaml').read_text()
)['velocity_smoother']['ros__parameters']
FREQUENCY_HZ = PARAMS['smoothing_frequency']
MAX_ACCEL = np.array(PARAMS['max_accel'], dtype=float)
MAX_DECEL = np.array(PARAMS['max_decel'], dtype=float)
TIMEOUT_S = PARAMS['velocity_timeout']
REAL_TIME_FACTOR = 0.5


class Outputs:
    """The twists received on a topic, each with the simulated time of its arrival."""

    def __init__(self, test_node, topic):
        """Subscribe."""
        self.test_node = test_node
        self._lock = threading.Lock()
        self.items = []   # (arrival sim time s, np.array([vx, vy, wz]))
        test_node.node.create_subscription(Twist, topic, self._on_message, 50)

    def _on_message(self, msg):
        with self._lock:
            self.items.append((self.test_node.clock_ns * 1e-9,
                               np.array([msg.linear.x, msg.linear.y, msg.angular.z])))

    def count(self):
        """Return how many twists have arrived."""
        with self._lock:
            return len(self.items)

    def since(self, start):
        """Return the items from index start on."""
        with self._lock:
            return list(self.items[start:])

    def wait_for(self, predicate, start, timeout=30.0):
        """Return the index of the first twist from index start on matching predicate."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for offset, (_, twist) in enumerate(self.since(start)):
                if predicate(twist):
                    return start + offset
            time.sleep(0.02)
        raise AssertionError(f'no matching twist within {timeout} s; last: '
                             f'{self.since(max(start, self.count() - 5))}')


def ramp(outputs, start, end):
    """Return the (times, twists) of outputs[start:end + 1] as arrays."""
    items = outputs.since(start)[:end - start + 1]
    return np.array([t for t, _ in items]), np.array([v for _, v in items])


def test_ramps_keep_direction_reject_nan_and_time_out(start_system, test_node):
    test_node.start_clock(real_time_factor=REAL_TIME_FACTOR)
    outputs = Outputs(test_node, 'cmd_vel_smoothed')
    system = start_system('mecanum_navigation', 'velocity_smoother.launch.yaml',
                          'use_sim_time:=true')
    system.wait_for_line(r'\[velocity_smoother\].*Velocity smoother started: /cmd_vel_nav')
    commander = test_node.twist_repeater('cmd_vel_nav')
    commander.start()
    try:
        # At rest: zero commands give zero outputs (and show that discovery is done).
        commander.twist = (0.0, 0.0, 0.0)
        outputs.wait_for(lambda v: np.all(v == 0.0), 0)

        # Step 0 -> 0.5 m/s forward: a ramp of max_accel, max_accel / f per output.
        step = MAX_ACCEL / FREQUENCY_HZ
        mark = outputs.count()
        commander.twist = (0.5, 0.0, 0.0)
        first = outputs.wait_for(lambda v: v[0] > 0.0, mark)
        top = outputs.wait_for(lambda v: v[0] >= 0.5 - 1e-12, first)
        times, twists = ramp(outputs, first, top)
        expected_x = np.minimum(0.5, step[0] * np.arange(1, len(twists) + 1))
        assert twists[:, 0] == pytest.approx(expected_x, abs=1e-9)
        assert np.all(twists[:, 1:] == 0.0)
        rising = twists[:, 0] < 0.5 - 1e-12
        slope = np.polyfit(times[rising], twists[rising, 0], 1)[0]
        assert slope == pytest.approx(MAX_ACCEL[0], rel=0.2)

        # A NaN command counts as zero: braking at max_decel, and a warning.
        mark = outputs.count()
        commander.twist = (math.nan, 0.0, 0.0)
        first = outputs.wait_for(lambda v: v[0] < 0.5, mark)
        stopped = outputs.wait_for(lambda v: v[0] == 0.0, first)
        _, twists = ramp(outputs, first, stopped)
        expected_x = np.maximum(0.0, 0.5 + MAX_DECEL[0] / FREQUENCY_HZ
                                * np.arange(1, len(twists) + 1))
        assert twists[:, 0] == pytest.approx(expected_x, abs=1e-9)
        system.wait_for_line(r'\[WARN\].*\[velocity_smoother\].*cmd_vel rejected, treated '
                             r'as zero: linear\.x is nan')

        # Two axes (and the rotation) limited: the direction is kept all along the ramp.
        target = np.array([0.6, 0.3, 1.0])
        mark = outputs.count()
        commander.twist = tuple(target)
        first = outputs.wait_for(lambda v: v[0] > 0.0, mark)
        top = outputs.wait_for(lambda v: np.allclose(v, target, atol=1e-9), first)
        _, twists = ramp(outputs, first, top)
        eta = np.min(step / target)   # the most limiting axis sets every step
        assert len(twists) == math.ceil(1.0 / eta - 1e-9) >= 3
        for k, twist in enumerate(twists):
            assert twist == pytest.approx(target * min(1.0, eta * (k + 1)), abs=1e-9)

        # No command for velocity_timeout: ramp down, one zero, then silence.
        test_node.wait_sim(0.3)
        mark = outputs.count()
        commander.twist = None
        test_node.wait_sim(0.2)
        last_command_s = commander.last_sent_sim_s
        first = outputs.wait_for(lambda v: v[0] < target[0], mark)
        zero = outputs.wait_for(lambda v: np.all(v == 0.0), first)
        first_time, _ = outputs.since(first)[0]
        assert first_time - last_command_s == pytest.approx(TIMEOUT_S, abs=0.2)
        _, twists = ramp(outputs, first, zero)
        decel = np.min(-MAX_DECEL / FREQUENCY_HZ / target)
        for k, twist in enumerate(twists):
            assert twist == pytest.approx(target * max(0.0, 1.0 - decel * (k + 1)), abs=1e-9)
        test_node.wait_sim(1.5 * TIMEOUT_S)
        assert outputs.count() == zero + 1, outputs.since(zero)
    finally:
        commander.stop()
    assert 'Traceback' not in system.output()


def test_closed_loop_ramps_from_the_odometry_twist(ros_env, test_node):
    """CLOSED_LOOP: each output is one acceleration step above the odometry's twist."""
    test_node.start_clock(real_time_factor=REAL_TIME_FACTOR)
    outputs = Outputs(test_node, 'cmd_vel_smoothed')
    odom_pub = test_node.node.create_publisher(Odometry, 'odom', 10)
    node = subprocess.Popen(
        ['./mecanum', 'run', 'mecanum_navigation', 'velocity_smoother', '--ros-args',
         '--params-file', str(REPO / 'src/mecanum_navigation/config/velocity_smoother.yaml'),
         '-p', 'feedback:=CLOSED_LOOP', '-p', 'use_sim_time:=true'],
        env=ros_env, cwd=str(REPO), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True)
    commander = test_node.twist_repeater('cmd_vel')
    command, measured = np.array([0.5, 0.2, 0.0]), np.array([0.3, 0.1, 0.0])
    commander.twist = tuple(command)
    commander.start()
    try:
        # Both axes are limited (0.2 and 0.1 m/s to go, 0.075 m/s per step): x the most,
        # so the step is the change scaled by 0.075 / 0.2, direction kept.
        delta = command - measured
        eta = min(MAX_ACCEL[i] / FREQUENCY_HZ / abs(delta[i]) for i in range(2))
        assert eta < 1.0
        expected = measured + delta * eta
        deadline = time.monotonic() + 30.0
        mark = 0
        while time.monotonic() < deadline:
            odom = Odometry()
            odom.header.stamp.sec, odom.header.stamp.nanosec = divmod(test_node.clock_ns,
                                                                      10 ** 9)
            odom.twist.twist.linear.x, odom.twist.twist.linear.y = measured[:2]
            odom_pub.publish(odom)
            items = outputs.since(mark)
            matching = [v for _, v in items if np.allclose(v, expected, atol=1e-9)]
            if len(matching) >= 3:
                break
            time.sleep(0.02)
        else:
            raise AssertionError(f'outputs {outputs.since(0)[-5:]}, expected {expected}')
    finally:
        commander.stop()
        node.send_signal(signal.SIGINT)
        output, _ = node.communicate(timeout=20)
    assert node.returncode == 0, output
    assert 'Traceback' not in output


@pytest.mark.parametrize('arguments, message', [
    (['-p', 'max_decel:=[1.5, -1.5, -5.0]'],
     'parameter max_decel linear.x must be finite and < 0'),
    (['-p', 'feedback:=BOTH'], 'parameter feedback must be one of'),
    (['-p', 'odom_duration:=-0.1'], 'parameter odom_duration must be finite and > 0'),
])
def test_bad_parameters_stop_the_node_with_a_clear_message(ros_env, arguments, message):
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_navigation', 'velocity_smoother', '--ros-args',
         *arguments], env=ros_env, capture_output=True, text=True, timeout=60,
        cwd=str(REPO))
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert 'Traceback' not in output
    assert re.search(r'\[FATAL\].*' + message, output), output
