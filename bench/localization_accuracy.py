#!/usr/bin/env python3
"""
Benchmark: EKF (wheel odometry + IMU) against raw wheel odometry, in simulation with slip.

Starts `mecanum_bringup simulation.launch.yaml` (physics simulator with a simulated
ESP32, the unchanged control stack, robot description and EKF, all on simulated
time) in its own ROS domain, once per floor: a slippery one (friction 0.1: the wheels
slip whenever the robot accelerates harder than about 1 m/s^2), a dusty one (0.3) and
the robot's own (0.6: hardly any slip). A driver in this process steers the robot
around a 1 m x 1 m square in the apartment's living room for `--duration` simulated
seconds with hard starts and stops, strafing, diagonals, turning while translating and full spins,
using the simulator's ground truth only to stay inside the room. It records
ground_truth/odom, odom (wheel odometry, encoder_reader) and odometry/filtered (the
EKF), and reports each estimate's RMS, maximum and final position and yaw error
against ground truth (mecanum_localization.trajectory_error aligns the frames at the
start). Collisions are counted too (expected: none).

Run:  ./mecanum exec python bench/localization_accuracy.py [--duration 180] [--floors 0.1 0.3 0.6]
(about 11 minutes at the default real-time factor 1; a machine too busy to keep up
shows up as overload warnings under the table)
Prints a table; --json FILE also writes the numbers.
"""

import argparse
import json
import math
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time

from mecanum_control.angles import wrap_angle, yaw_from_quaternion

REPO = Path(__file__).resolve().parents[1]

#: The route, relative to the start pose (world frame): ('goto', dx m, dy m, yaw deg)
#: or ('spin', turns). It stays within +-0.55 m of the start, which the apartment's
#: living room leaves free (coffee table, bookshelf and the walking person are further).
ROUTE = [
    ('goto', 0.5, 0.0, 0.0),      # forward
    ('goto', 0.5, 0.5, 0.0),      # strafe left
    ('goto', -0.5, 0.5, 90.0),    # back and turn at once
    ('spin', 1.0),                # a full turn on the spot
    ('goto', -0.5, -0.5, 180.0),  # strafe while turning
    ('goto', 0.5, -0.5, -90.0),   # diagonal while turning
    ('spin', -1.0),
    ('goto', 0.0, 0.0, 0.0),      # home
]
REST_BEFORE_DRIVING_S = 5.0
MAX_SPEED_M_S = 0.5
MAX_TURN_RAD_S = 2.0
GAIN_PER_S = 2.5


class Driver:
    """Steers the robot along ROUTE from ground truth; records every estimate."""

    def __init__(self, node):
        """Subscribe to the three odometries and collisions; publish cmd_vel at 20 Hz."""
        from geometry_msgs.msg import Twist
        from nav_msgs.msg import Odometry
        from std_msgs.msg import UInt32
        from rclpy.qos import DurabilityPolicy, QoSProfile
        self.node = node
        self.twist_type = Twist
        self.lock = threading.Lock()
        self.tracks = {'truth': [], 'odom': [], 'ekf': []}
        self.truth = None
        self.collisions = 0
        self.start = None
        self.step = 0
        self.spin_from = None
        self.driving = False
        self.cmd_pub = node.create_publisher(Twist, 'cmd_vel', 10)
        for key, topic in (('truth', 'ground_truth/odom'), ('odom', 'odom'),
                           ('ekf', 'odometry/filtered')):
            node.create_subscription(Odometry, topic,
                                     lambda msg, key=key: self.on_odometry(key, msg), 50)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        node.create_subscription(UInt32, 'simulation/collisions', self.on_collisions, latched)
        node.create_timer(0.05, self.on_timer)

    def on_odometry(self, key, msg):
        """Record one pose (stamp s, x, y, yaw) of a track."""
        pose, q = msg.pose.pose, msg.pose.pose.orientation
        yaw = yaw_from_quaternion(q.x, q.y, q.z, q.w)
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        with self.lock:
            self.tracks[key].append((stamp, pose.position.x, pose.position.y, wrap_angle(yaw)))
            if key == 'truth':
                self.truth = (pose.position.x, pose.position.y, yaw)

    def on_collisions(self, msg):
        """Keep the simulator's collision count."""
        self.collisions = msg.data

    def on_timer(self):
        """Steer toward the current leg's goal (holonomic, saturated P control)."""
        if not self.driving or self.truth is None:
            return
        x, y, yaw = self.truth
        if self.start is None:
            self.start = self.truth
        sx, sy, syaw = self.start
        leg = ROUTE[self.step % len(ROUTE)]
        vx_world = vy_world = wz = 0.0
        done = False
        if leg[0] == 'goto':
            dx, dy = sx + leg[1] - x, sy + leg[2] - y
            dyaw = wrap_angle(syaw + math.radians(leg[3]) - yaw)
            distance = math.hypot(dx, dy)
            speed = min(MAX_SPEED_M_S, GAIN_PER_S * distance)
            if distance > 1e-9:
                vx_world, vy_world = speed * dx / distance, speed * dy / distance
            wz = max(-MAX_TURN_RAD_S, min(MAX_TURN_RAD_S, GAIN_PER_S * dyaw))
            done = distance < 0.03 and abs(dyaw) < 0.05
        else:
            if self.spin_from is None:
                self.spin_from, self.spun = yaw, 0.0
            self.spun += wrap_angle(yaw - self.spin_from)
            self.spin_from = yaw
            remaining = 2 * math.pi * leg[1] - self.spun
            wz = math.copysign(min(MAX_TURN_RAD_S, GAIN_PER_S * abs(remaining)), remaining)
            done = abs(remaining) < 0.05
        if done:
            self.step += 1
            self.spin_from = None
        cmd = self.twist_type()
        cmd.linear.x = math.cos(yaw) * vx_world + math.sin(yaw) * vy_world
        cmd.linear.y = -math.sin(yaw) * vx_world + math.cos(yaw) * vy_world
        cmd.angular.z = wz
        self.cmd_pub.publish(cmd)

    def sim_time(self):
        """Return the latest ground-truth stamp (simulated s), or None."""
        with self.lock:
            return self.tracks['truth'][-1][0] if self.tracks['truth'] else None


def run_floor(floor_friction, duration_s, real_time_factor, seed):
    """Run one simulation; return the error statistics of odom and the EKF."""
    import numpy as np
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from mecanum_bringup.isolation import isolated_environment, lease_domain_id
    from mecanum_localization.trajectory_error import trajectory_error

    with lease_domain_id() as lease, tempfile.TemporaryDirectory() as tmp:
        env = isolated_environment(os.environ, lease.domain_id)
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        log_path = Path(os.environ.get('BENCH_SYSTEM_LOG', Path(tmp) / 'system.log'))
        with open(log_path, 'w') as log:
            system = subprocess.Popen(
                [sys.executable, '-m', 'mecanum_bringup.launch_runner', 'mecanum_bringup',
                 'simulation.launch.yaml', f'floor_friction_coefficient:={floor_friction}',
                 f'real_time_factor:={real_time_factor}', f'seed:={seed}',
                 f'board_port:={tmp}/ttySIM', f'estop_latch_file:={tmp}/estop'],
                env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=lease.domain_id)
        node = rclpy.create_node('localization_bench', context=context, parameter_overrides=[
            Parameter('use_sim_time', Parameter.Type.BOOL, True)])
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        driver = Driver(node)
        spinner = threading.Thread(target=lambda: executor.spin(), daemon=True)
        spinner.start()
        try:
            deadline = time.monotonic() + 90.0
            while not (driver.tracks['ekf'] and driver.tracks['odom'] and driver.tracks['truth']
                       and 'IMU calibrated at rest' in log_path.read_text()):
                if time.monotonic() > deadline or system.poll() is not None:
                    raise RuntimeError('the system did not come up:\n'
                                       + log_path.read_text()[-3000:])
                time.sleep(0.2)
            # Like a robot just switched on, rest a few seconds: the IMU's bias estimate
            # keeps improving while it rests (its residual drifts the heading).
            rested = driver.sim_time() + REST_BEFORE_DRIVING_S
            while driver.sim_time() < rested:
                time.sleep(0.1)
            begin = driver.sim_time()
            driver.driving = True
            while driver.sim_time() < begin + duration_s:
                if system.poll() is not None:
                    raise RuntimeError('the system stopped:\n' + log_path.read_text()[-3000:])
                time.sleep(0.5)
            driver.driving = False
            driver.cmd_pub.publish(driver.twist_type())
        finally:
            system.send_signal(signal.SIGINT)
            try:
                system.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(system.pid, signal.SIGKILL)
            executor.shutdown()
            node.destroy_node()
            rclpy.try_shutdown(context=context)
        # Signs that this machine could not keep up (the numbers then say less).
        starved = len(re.findall(r'fell .* behind|no wheel speed measurements|Link to the board',
                                 log_path.read_text()))
        with driver.lock:
            tracks = {key: np.array(rows) for key, rows in driver.tracks.items()}
        truth = tracks['truth']
        results = {}
        for key in ('odom', 'ekf'):
            track = tracks[key]
            track = track[track[:, 0] >= begin]
            results[key] = trajectory_error(truth[:, 0], truth[:, 1:], track[:, 0], track[:, 1:])
        return results, driver.collisions, driver.step, starved


def main() -> int:
    """Run every floor and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--duration', type=float, default=180.0,
                        help='simulated seconds of driving per floor (default 180)')
    parser.add_argument('--floors', type=float, nargs='+', default=[0.1, 0.3, 0.6],
                        help='floor friction coefficients to run (default 0.1 0.3 0.6)')
    parser.add_argument('--real-time-factor', type=float, default=1.0)
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--json', type=Path, help='also write the numbers here')
    args = parser.parse_args()

    rows, report = [], []
    for floor in args.floors:
        started = time.monotonic()
        results, collisions, legs, starved = run_floor(
            floor, args.duration, args.real_time_factor, args.seed)
        wall_s = time.monotonic() - started
        for key, label in (('odom', 'wheel odometry'), ('ekf', 'EKF (odom + IMU)')):
            error = results[key]
            rows.append((f'{floor:.2f}', label, f'{error.rms_position_m:.3f}',
                         f'{error.max_position_m:.3f}', f'{error.final_position_m:.3f}',
                         f'{math.degrees(error.rms_yaw_rad):.2f}',
                         f'{math.degrees(error.final_yaw_rad):.2f}'))
        odom, ekf = results['odom'], results['ekf']

        def ratio(a, b):
            return f'{a / b:.2f}' if b > 0 else '-'
        rows.append((f'{floor:.2f}', 'EKF / odometry',
                     ratio(ekf.rms_position_m, odom.rms_position_m), '',
                     ratio(ekf.final_position_m, odom.final_position_m),
                     ratio(ekf.rms_yaw_rad, odom.rms_yaw_rad),
                     ratio(ekf.final_yaw_rad, odom.final_yaw_rad)))
        report.append({'floor_friction': floor, 'duration_s': args.duration,
                       'legs_driven': legs, 'collisions': collisions, 'wall_s': wall_s,
                       'overload_warnings': starved,
                       **{key: vars(value) for key, value in results.items()}})
        print(f'floor {floor}: {args.duration:.0f} s simulated, {legs} legs driven, '
              f'{collisions} collisions, {wall_s:.0f} s wall; ' + '; '.join(
                  ' '.join(row[1:]) for row in rows[-3:]), file=sys.stderr)

    header = ('floor mu', 'estimate', 'RMS pos m', 'max pos m', 'final pos m',
              'RMS yaw deg', 'final yaw deg')
    widths = [max(len(str(row[i])) for row in [header] + rows) for i in range(len(header))]
    print(f'\nLocalisation accuracy against ground truth ({args.duration:.0f} s simulated '
          f'per floor, seed {args.seed})')
    for row in [header] + rows:
        print('  '.join(str(cell).ljust(width) for cell, width in zip(row, widths)))
    for entry in report:
        print(f"floor {entry['floor_friction']}: {entry['legs_driven']} legs, "
              f"{entry['collisions']} collisions, {entry['overload_warnings']} overload "
              'warnings (simulation behind, control loop starved)')
    if args.json:
        args.json.write_text(json.dumps(report, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
