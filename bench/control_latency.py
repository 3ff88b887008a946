#!/usr/bin/env python3
"""
Benchmark: cmd_vel -> /motor_speeds latency and control-loop period jitter, across processes.

Starts the emulated control stack (board emulator on a pty + the four control nodes,
wall clock, own ROS domain) and, as a baseline, a bare relay node that republishes
each Twist as a Float32MultiArray with no processing. From this process it then

* after 20 uncounted warm-up steps, publishes cmd_vel steps too small for the acceleration limit to delay, and times
  the first /motor_speeds carrying the matching wheel speeds (and the same for the
  relay), so the ratio shows what motor_controller adds to one DDS hop;
* records the arrival times of /motor_speeds, /motor_efforts (velocity_controller's
  PID period) and /wheel_ticks (board -> hardware_interface), and reports the
  deviation of each period from nominal.

Run:  ./mecanum exec python bench/control_latency.py [--samples 300]
Prints a table; --json FILE also writes the numbers.
"""

import argparse
import json
import os
from pathlib import Path
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time

REPO = Path(__file__).resolve().parents[1]
RELAY_CODE = '''
import rclpy
from geometry_msgs.msg import Twist
from std_msgs.msg import Float32MultiArray
rclpy.init()
node = rclpy.create_node('bench_relay')
pub = node.create_publisher(Float32MultiArray, 'relay_out', 10)
node.create_subscription(Twist, 'relay_in',
                         lambda m: pub.publish(Float32MultiArray(data=[m.linear.x] * 4)), 10)
try:
    rclpy.spin(node)
except KeyboardInterrupt:
    pass
'''


def percentile(values, fraction):
    """Nearest-rank percentile of a list of numbers."""
    ordered = sorted(values)
    index = min(len(ordered) - 1, max(0, int(round(fraction * (len(ordered) - 1)))))
    return ordered[index]


class ArrivalLog:
    """Arrival times (monotonic s) and messages of one topic."""

    def __init__(self, node, msg_type, topic):
        self.items = []
        self.lock = threading.Lock()
        node.create_subscription(msg_type, topic, self.on_message, 100)

    def on_message(self, msg):
        """Record one message with its arrival time."""
        with self.lock:
            self.items.append((time.monotonic(), msg))

    def wait_match(self, predicate, since, timeout=1.0):
        """Arrival time of the first message after `since` matching predicate, or None."""
        deadline = time.monotonic() + timeout
        seen = 0
        while time.monotonic() < deadline:
            with self.lock:
                fresh = [(t, m) for t, m in self.items[seen:] if t >= since]
                seen = len(self.items)
            for when, msg in fresh:
                if predicate(msg):
                    return when
            time.sleep(0.0002)
        return None

    def periods_ms(self, start, end):
        """Inter-arrival periods in ms of messages between monotonic times start and end."""
        with self.lock:
            times = [t for t, _ in self.items if start <= t <= end]
        return [(b - a) * 1e3 for a, b in zip(times, times[1:])]


def spin_quietly(executor):
    """Spin until shutdown; the context going away at the end is not an error."""
    try:
        executor.spin()
    except Exception:  # noqa: B902
        pass


def measure_latency(publisher, log, twist_type, make_value, expected, samples):
    """Publish `samples` steps; return the latencies in ms of the matching responses."""
    latencies, misses = [], 0
    for k in range(samples):
        value = make_value(k)
        msg = twist_type()
        msg.linear.x = value
        sent = time.monotonic()
        publisher.publish(msg)
        arrived = log.wait_match(lambda m, v=value: expected(m, v), sent)
        if arrived is None:
            misses += 1
        else:
            latencies.append((arrived - sent) * 1e3)
        time.sleep(0.02 + 0.01 * (k % 3))  # not phase-locked to the 50 Hz timers
    return latencies, misses


def main() -> int:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--samples', type=int, default=300)
    parser.add_argument('--jitter-seconds', type=float, default=10.0)
    parser.add_argument('--json', type=Path)
    args = parser.parse_args()

    sys.path.insert(0, str(REPO / 'src/mecanum_bringup'))
    from mecanum_bringup.isolation import isolated_environment, lease_domain_id
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from geometry_msgs.msg import Twist
    from mecanum_control.robot_config import default_config_path, load_robot_config
    from mecanum_interfaces.msg import WheelTicks
    from std_msgs.msg import Float32MultiArray

    config = load_robot_config(default_config_path())
    wheel_per_vx = 1.0 / config.geometry.wheel_radius_m
    with lease_domain_id() as lease, tempfile.TemporaryDirectory() as tmp:
        env = isolated_environment(os.environ, lease.domain_id)
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        os.environ.update(ROS_DOMAIN_ID=str(lease.domain_id),
                          ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
        system = subprocess.Popen(
            [sys.executable, '-m', 'mecanum_bringup.launch_runner', 'mecanum_control',
             'emulated_control.launch.yaml', f'port:={tmp}/ttyESP32'],
            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT,
            start_new_session=True)
        relay = subprocess.Popen([sys.executable, '-c', RELAY_CODE], env=env,
                                 start_new_session=True)
        try:
            rclpy.init()
            node = rclpy.create_node('bench_control_latency')
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            threading.Thread(target=spin_quietly, args=(executor,), daemon=True).start()
            speeds = ArrivalLog(node, Float32MultiArray, 'motor_speeds')
            efforts = ArrivalLog(node, Float32MultiArray, 'motor_efforts')
            ticks = ArrivalLog(node, WheelTicks, 'wheel_ticks')
            relayed = ArrivalLog(node, Float32MultiArray, 'relay_out')
            cmd_pub = node.create_publisher(Twist, 'cmd_vel', 10)
            relay_pub = node.create_publisher(Twist, 'relay_in', 10)
            deadline = time.monotonic() + 30
            while (cmd_pub.get_subscription_count() == 0 or relay_pub.get_subscription_count()
                   == 0 or not ticks.items or not efforts.items):
                if time.monotonic() > deadline:
                    raise RuntimeError('the control stack did not come up within 30 s')
                time.sleep(0.1)
            time.sleep(1.0)

            # Steps of 0.00001 m/s around 0.1 m/s: within one callback's acceleration
            # budget, so the first motor_speeds after a command already carries it.
            def wheel_match(msg, v):
                return abs(msg.data[0] - v * wheel_per_vx) < 5e-5

            # Warm-up (first-message allocations, DDS matching), not counted.
            measure_latency(cmd_pub, speeds, Twist, lambda k: 0.1 + 0.00001 * (k % 2),
                            wheel_match, 20)
            cmd_lat, cmd_miss = measure_latency(
                cmd_pub, speeds, Twist, lambda k: 0.1 + 0.00001 * (k % 2), wheel_match,
                args.samples)
            measure_latency(relay_pub, relayed, Twist, lambda k: 0.2 + 0.0005 * k,
                            lambda m, v: abs(m.data[0] - v) < 1e-6, 20)
            relay_lat, relay_miss = measure_latency(
                relay_pub, relayed, Twist, lambda k: 0.1 + 0.0005 * k,
                lambda m, v: abs(m.data[0] - v) < 1e-6, args.samples)

            # Jitter while driving (0.3 m/s forward): the PID works and ticks flow.
            drive = Twist()
            drive.linear.x = 0.3
            start = time.monotonic()
            while time.monotonic() - start < args.jitter_seconds:
                cmd_pub.publish(drive)
                time.sleep(0.05)
            end = time.monotonic()
            periods = {'motor_efforts (velocity_controller PID, 50 Hz)':
                           efforts.periods_ms(start, end),
                       'wheel_ticks (board -> hardware_interface, 50 Hz)':
                           ticks.periods_ms(start, end)}
        finally:
            for process in (system, relay):
                os.killpg(process.pid, signal.SIGINT)
            for process in (system, relay):
                try:
                    process.wait(timeout=15)
                except subprocess.TimeoutExpired:
                    os.killpg(process.pid, signal.SIGKILL)
            rclpy.try_shutdown()

    rows = []
    results = {}
    for name, values, misses in (('cmd_vel -> motor_speeds latency (ms)', cmd_lat, cmd_miss),
                                 ('baseline: bare relay hop latency (ms)', relay_lat, relay_miss)):
        rows.append((name, len(values), statistics.median(values), percentile(values, 0.99),
                     max(values), f'{misses} missed'))
        results[name] = {'median': statistics.median(values), 'p99': percentile(values, 0.99),
                         'max': max(values), 'n': len(values), 'missed': misses}
    ratio = statistics.median(cmd_lat) / statistics.median(relay_lat)
    for name, values in periods.items():
        deviation = [abs(p - 20.0) for p in values]
        rows.append((f'{name} |period-20ms| (ms)', len(values), statistics.median(deviation),
                     percentile(deviation, 0.99), max(deviation),
                     f'mean period {statistics.mean(values):.2f} ms'))
        results[name] = {'median_abs_jitter_ms': statistics.median(deviation),
                         'p99_abs_jitter_ms': percentile(deviation, 0.99),
                         'mean_period_ms': statistics.mean(values), 'n': len(values)}
    results['latency_ratio_motor_controller_to_bare_hop'] = ratio

    print(f'\nControl path benchmark ({os.cpu_count()} CPUs, wall clock, one run)\n')
    header = f'{"metric":<72} {"n":>5} {"median":>8} {"p99":>8} {"max":>8}  note'
    print(header)
    print('-' * len(header))
    for name, n, median, p99, worst, note in rows:
        print(f'{name:<72} {n:>5} {median:>8.2f} {p99:>8.2f} {worst:>8.2f}  {note}')
    print(f'\nmedian latency ratio motor_controller / bare relay hop: {ratio:.2f}')
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
