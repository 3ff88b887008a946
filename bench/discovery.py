#!/usr/bin/env python3
"""
Benchmark: how long a node that joins a running system waits for its first message.

A publisher process (std_msgs/String at 20 Hz) runs; a second process starts into it
after a random 1-3 s, creates a node and a subscription, and reports the wall seconds
from its node's creation until its subscription matched the publisher and until the
first message arrived. That wait is DDS participant discovery: it is paid by every
node started into a running system (each scenario's processes, the runner's own node,
every integration test's test node, `ros2 topic echo`).

Two settings, trials interleaved in one run: Fast DDS's defaults (no profile file) and
this workspace's mecanum_bringup config/fastdds_discovery.xml (announcements every
0.5 s instead of 3 s), which tools/env.sh selects. Each trial has a ROS domain of its
own and localhost-only discovery.

Run:  ./mecanum exec python bench/discovery.py [--trials 12] [--json FILE]
Prints a table (mean, median, 90th percentile and largest wait per setting, and the
ratio of the means).
"""

import argparse
import json
import os
from pathlib import Path
import random
import statistics
import subprocess
import sys
import time

REPO = Path(__file__).resolve().parents[1]
PROFILE = REPO / 'src' / 'mecanum_bringup' / 'config' / 'fastdds_discovery.xml'
PUBLISHER = """
import rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node('bench_discovery_publisher')
publisher = node.create_publisher(String, 'bench_discovery', 10)
node.create_timer(0.05, lambda: publisher.publish(String(data='hello')))
print('up', flush=True)
try:
    rclpy.spin(node)
except KeyboardInterrupt:
    pass
"""
SUBSCRIBER = """
import time
import rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node('bench_discovery_subscriber')
start = time.monotonic()
first = []
subscription = node.create_subscription(
    String, 'bench_discovery', lambda _msg: first.append(time.monotonic()), 10)
matched = None
while not first and time.monotonic() - start < 10.0:
    rclpy.spin_once(node, timeout_sec=0.005)
    if matched is None and subscription.get_publisher_count() > 0:
        matched = time.monotonic() - start
print(f'{matched if matched is not None else -1} {first[0] - start if first else -1}')
"""


def trial(profile: bool, domain_id: int, delay_s: float) -> tuple:
    """Return (matched s, first message s) of one subscriber joining a running publisher."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    env.pop('FASTRTPS_DEFAULT_PROFILES_FILE', None)
    if profile:
        env['FASTRTPS_DEFAULT_PROFILES_FILE'] = str(PROFILE)
    publisher = subprocess.Popen([sys.executable, '-c', PUBLISHER], env=env, text=True,
                                 stdout=subprocess.PIPE)
    try:
        assert publisher.stdout.readline().strip() == 'up'
        time.sleep(delay_s)    # the system has been running for a while
        out = subprocess.run([sys.executable, '-c', SUBSCRIBER], env=env, text=True,
                             capture_output=True, timeout=60, check=True).stdout.split()
        return float(out[0]), float(out[1])
    finally:
        publisher.terminate()
        publisher.wait(timeout=10)


def summary(waits: list) -> dict:
    """Return the mean, median, 90th percentile and largest of a list of waits (s)."""
    ordered = sorted(waits)
    return {'mean_s': statistics.fmean(ordered), 'median_s': statistics.median(ordered),
            'p90_s': ordered[min(len(ordered) - 1, int(0.9 * len(ordered)))],
            'max_s': ordered[-1]}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--trials', type=int, default=12, help='trials per setting')
    parser.add_argument('--json', type=Path, help='also write the numbers here')
    args = parser.parse_args()
    generator = random.Random(2026)
    waits = {'Fast DDS defaults': [], 'fastdds_discovery.xml': []}
    for number in range(args.trials):
        for index, name in enumerate(waits):
            delay_s = generator.uniform(1.0, 3.0)
            _matched, first = trial(index == 1, 150 + (2 * number + index) % 50, delay_s)
            waits[name].append(first)
            print(f'  trial {number + 1}/{args.trials} {name}: first message after '
                  f'{first:.2f} s', file=sys.stderr)
    rows = {name: summary(values) for name, values in waits.items()}
    print(f'\nA node joining a publisher that runs for 1-3 s already: wall s from node '
          f'creation to the first message ({args.trials} trials each, interleaved)\n')
    print(f'{"setting":<24} {"mean":>8} {"median":>8} {"p90":>8} {"max":>8}')
    for name, row in rows.items():
        print(f'{name:<24} {row["mean_s"]:>8.2f} {row["median_s"]:>8.2f} {row["p90_s"]:>8.2f} '
              f'{row["max_s"]:>8.2f}')
    default, ours = rows.values()
    ratio = default['mean_s'] / max(ours['mean_s'], 1e-3)
    print(f'\nmean wait, defaults / fastdds_discovery.xml: {ratio:.1f}x')
    if args.json:
        args.json.write_text(json.dumps({'trials': args.trials, 'rows': rows,
                                         'waits': waits}, indent=1) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
