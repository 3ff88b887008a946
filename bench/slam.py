#!/usr/bin/env python3
"""
Benchmark: online SLAM time per scan and the real-time factor of mapping a recorded run.

Records a run first (pure simulator parts, no ROS): the robot drives a loop through
every room of the apartment twice at 0.4 m/s, with the simulator's 360-beam lidar
(1 cm noise, the walking person) at 10 Hz and wheel odometry that drifts (3 % scale
error, 0.02 rad/m yaw drift, noise), and saves it to an .npz file (scans, odometry,
ground truth, stamps). Then it maps the recording with mecanum_navigation.slam.slam.OnlineSlam
(config/slam_params.yaml's values) as fast as it can, with and without loop closing, and
prints: CPU time per scan (keyframes and the others: median, p95, max; the goal is well
under 100 ms, the scan period), the real-time factor (recorded seconds / CPU seconds
spent mapping), the trajectory RMS against the ground truth, and the dead-reckoning
error for comparison.

Run:  ./mecanum exec python bench/slam.py [--laps 2] [--json FILE]
"""

import argparse
import json
import math
from pathlib import Path
import sys
import tempfile
import time

from mecanum_control.angles import wrap_angle
from mecanum_navigation.slam.pose_graph import compose, relative
from mecanum_navigation.slam.slam import occupied_overlap, OnlineSlam, SlamConfig
import numpy as np
from robot_simulation.sensors import Lidar, LidarConfig
from robot_simulation.world import find_world, load_world
import yaml

REPO = Path(__file__).resolve().parents[1]
LOOP = [(2.95, 2.0), (4.6, 2.0), (5.2, 3.3), (6.8, 3.3), (8.5, 3.3), (8.5, 4.6), (5.1, 4.6),
        (5.1, 6.4), (3.2, 6.6), (5.1, 6.4), (5.1, 4.6), (1.5, 4.6), (1.5, 3.2), (2.6, 2.9),
        (2.95, 2.0)]
MOUNT = (0.05, 0.0, 0.0)


def record_run(path: Path, laps: int, seed: int = 1, speed: float = 0.4,
               rate_hz: float = 10.0) -> None:
    """Drive the loop `laps` times in the simulated apartment; save scans and odometry."""
    world = load_world(find_world('apartment'))
    lidar = Lidar(LidarConfig(beams=360, mount_x_m=MOUNT[0]), world.segments, seed=seed)
    rng = np.random.default_rng(seed)
    static = np.array([(c.center[0], c.center[1], c.radius_m)
                       for c in world.circles]).reshape(-1, 3)
    dt = 1.0 / rate_hz
    route = LOOP + LOOP[1:] * (laps - 1)
    truth = [world.robot_start]
    for (ax, ay), (bx, by) in zip(route[:-1], route[1:]):
        heading = math.atan2(by - ay, bx - ax)
        count = max(1, math.ceil(math.hypot(bx - ax, by - ay) / (speed * dt)))
        for k in range(1, count + 1):
            yaw = truth[-1][2] + max(-dt, min(dt, wrap_angle(heading - truth[-1][2])))
            truth.append((ax + (bx - ax) * k / count, ay + (by - ay) * k / count,
                          wrap_angle(yaw)))
    odom = [(0.0, 0.0, 0.0)]
    for a, b in zip(truth[:-1], truth[1:]):
        step = relative(a, b)
        distance = math.hypot(step[0], step[1])
        odom.append(compose(odom[-1], (1.03 * step[0] + rng.normal(0, 0.002),
                                       1.03 * step[1] + rng.normal(0, 0.002),
                                       step[2] + 0.02 * distance + rng.normal(0, 0.002))))
    scans = []
    for k, (x, y, yaw) in enumerate(truth):
        people = np.array([(*m.position_at(k * dt), m.radius_m)
                           for m in world.moving_obstacles]).reshape(-1, 3)
        scans.append(lidar.scan(x, y, yaw, np.vstack([static, people])))
    fields = lidar.scan_fields()
    np.savez_compressed(path, stamps=np.arange(len(truth)) * dt, truth=np.array(truth),
                        odom=np.array(odom), scans=np.array(scans, dtype=np.float32),
                        angle_min=fields['angle_min'],
                        angle_increment=fields['angle_increment'],
                        range_min=fields['range_min'], range_max=fields['range_max'])


def slam_config(**overrides) -> SlamConfig:
    """Return OnlineSlam's config from config/slam_params.yaml (the node's values)."""
    params = yaml.safe_load((REPO / 'src/mecanum_navigation/config/slam_params.yaml')
                            .read_text())['slam_toolbox']['ros__parameters']
    names = set(SlamConfig.__dataclass_fields__)
    values = {k: v for k, v in params.items() if k in names}
    values.update(overrides)
    return SlamConfig(**values)


def map_recording(path: Path, config: SlamConfig) -> dict:
    """Map a recording scan by scan; return timings and errors."""
    run = np.load(path)
    truth, odom, scans = run['truth'], run['odom'], run['scans']
    slam = OnlineSlam(config, initial_pose=tuple(truth[0]))
    keyframe_s, other_s, keyframes = [], [], []
    total_start = time.process_time()
    for k in range(len(truth)):
        start = time.process_time()
        added = slam.add_scan(odom[k], scans[k], float(run['angle_min']),
                              float(run['angle_increment']), float(run['range_min']),
                              float(run['range_max']), MOUNT)
        (keyframe_s if added else other_s).append(time.process_time() - start)
        if added:
            keyframes.append(k)
    grid = slam.occupancy_map()
    total_s = time.process_time() - total_start
    error = slam.trajectory()[:, :2] - truth[keyframes, :2]
    duration_s = float(run['stamps'][-1])
    precision, recall = occupied_overlap(grid, load_world(find_world('apartment'))
                                         .to_occupancy_map(config.resolution))
    return {
        'scans': len(truth), 'keyframes': slam.keyframe_count,
        'loop_closures': slam.loop_closure_count,
        'keyframe_ms': [1e3 * float(np.percentile(keyframe_s, q)) for q in (50, 95, 100)],
        'other_ms': [1e3 * float(np.percentile(other_s, q)) for q in (50, 95, 100)],
        'rtf': duration_s / total_s, 'duration_s': duration_s,
        'rms_m': float(np.sqrt(np.mean(np.sum(error ** 2, axis=1)))),
        'max_m': float(np.max(np.hypot(*error.T))),
        'precision': precision, 'recall': recall}


def main() -> int:
    """Record, map, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--laps', type=int, default=2)
    parser.add_argument('--json', type=Path)
    options = parser.parse_args()
    with tempfile.TemporaryDirectory() as directory:
        recording = Path(directory) / 'run.npz'
        record_run(recording, options.laps)
        run = np.load(recording)
        dead = np.array([compose(run['truth'][0], pose) for pose in run['odom']])
        odom_rms = float(np.sqrt(np.mean(np.sum((dead[:, :2] - run['truth'][:, :2]) ** 2, 1))))
        map_recording(recording, slam_config())   # numba warm-up (cache load)
        results = {'loop closing': map_recording(recording, slam_config()),
                   'no loop closing': map_recording(recording,
                                                    slam_config(do_loop_closing=False))}
    first = results['loop closing']
    print(f'Recorded run: {first["duration_s"]:.0f} s, {first["scans"]} scans of 360 beams '
          f'at 10 Hz; dead-reckoning RMS {odom_rms:.2f} m')
    print(f'{"mode":16} {"keyframes":>9} {"loops":>5} {"keyframe ms p50/p95/max":>24} '
          f'{"other ms p50/max":>17} {"RTF":>6} {"RMS cm":>7} {"max cm":>7} {"walls P/R":>10}')
    for name, r in results.items():
        k, o = r['keyframe_ms'], r['other_ms']
        print(f'{name:16} {r["keyframes"]:9d} {r["loop_closures"]:5d} '
              f'{k[0]:8.1f}/{k[1]:6.1f}/{k[2]:7.1f} {o[0]:8.2f}/{o[2]:7.2f} '
              f'{r["rtf"]:6.1f} {100 * r["rms_m"]:7.2f} {100 * r["max_m"]:7.2f} '
              f'{r["precision"]:.2f}/{r["recall"]:.2f}')
    print('Goal: keyframe time well under 100 ms (the scan period at 10 Hz).')
    if options.json:
        options.json.write_text(json.dumps({'dead_reckoning_rms_m': odom_rms, **results},
                                           indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
