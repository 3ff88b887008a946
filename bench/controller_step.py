#!/usr/bin/env python3
"""
Benchmark: compute time of one LocalController.compute_velocity cycle (pure core, no ROS).

A closed-loop drive through the simulator's apartment world: the static map
(robot_simulation's World.to_occupancy_map at 0.05 m) feeds a 3 m x 3 m rolling local
costmap centred on the robot (mecanum_navigation.costmap.costmap_2d: StaticLayer, then
InflationLayer with Nav2's defaults, inflation_radius 0.55 m, cost_scaling_factor 3.0,
inscribed radius = footprint_radius_m of motor_params.yaml). When costmap.py lacks
those, or with --numpy-costmap, a plain numpy stand-in does the same (static cells,
then the same inflation law). The route, densified to 0.05 m like a global plan: living
room (robot start) -> doorway to the kitchen -> kitchen -> kitchen door -> hallway ->
bedroom door -> bedroom, ending with yaw +90 deg; about 12 m with five doorways and
corners. The robot tracks each command perfectly for one control period (20 Hz).

Only compute_velocity is timed (the costmap update is not); each configuration of the
sampler (vx x vy x vtheta samples) drives the whole route, and its cycles' times give
the median, p99 and maximum. The first cycle of each drive is a warm-up, not counted.
The machine is shared (2 cores): compare the rows with each other, measured in the
same run.

Run:  ./mecanum exec python bench/controller_step.py [--max-cycles 800] [--numpy-costmap]
Prints a table; --json FILE also writes the numbers.
"""

import argparse
from dataclasses import dataclass
import json
import math
import os
from pathlib import Path
import statistics
import sys
import time
from typing import List, Tuple

#: Route corners (x, y m) in the apartment; the last one carries the goal yaw.
ROUTE = [(2.95, 2.0), (4.8, 3.0), (6.0, 3.3), (8.5, 3.3), (8.5, 4.6), (5.1, 4.6),
         (5.1, 6.3)]
GOAL_YAW = math.pi / 2
LOCAL_SIZE_M = 3.0
RESOLUTION_M = 0.05
#: Sampler configurations: (label, vx_samples, vy_samples, vtheta_samples).
CONFIGS = [('coarse 7 x 7 x 5', 7, 7, 5), ('default 11 x 11 x 9', 11, 11, 9),
           ('fine 15 x 15 x 11', 15, 15, 11)]
TARGET_MS = 10.0


def densify(corners: List[Tuple[float, float]], spacing: float) -> List[Tuple[float, float]]:
    """Return the polyline through corners with points at most spacing (m) apart."""
    points = [corners[0]]
    for (x0, y0), (x1, y1) in zip(corners, corners[1:]):
        count = max(1, math.ceil(math.hypot(x1 - x0, y1 - y0) / spacing))
        points += [(x0 + (x1 - x0) * k / count, y0 + (y1 - y0) * k / count)
                   for k in range(1, count + 1)]
    return points


@dataclass
class NumpyCostmap:
    """Stand-in local costmap: the attributes compute_velocity reads."""

    costs: object
    resolution_m: float
    origin_x_m: float
    origin_y_m: float

    @property
    def size_x(self) -> int:
        """Return the number of columns."""
        return int(self.costs.shape[1])

    @property
    def size_y(self) -> int:
        """Return the number of rows."""
        return int(self.costs.shape[0])


class NumpyLocalCostmap:
    """A rolling window cut out of a whole-map costmap inflated once with numpy."""

    def __init__(self, occupancy, inscribed_m: float, inflation_m: float = 0.55,
                 scaling: float = 3.0):
        """Inflate the static map (cells >= 65 occupied) with Nav2's law."""
        import numpy as np

        lethal = occupancy.data >= 65
        rows, cols = lethal.shape
        costs = np.where(lethal, 254, 0).astype(np.uint8)
        reach = int(math.ceil(inflation_m / occupancy.resolution_m))
        padded = np.zeros((rows + 2 * reach, cols + 2 * reach), dtype=bool)
        padded[reach:reach + rows, reach:reach + cols] = lethal
        for dr in range(-reach, reach + 1):
            for dc in range(-reach, reach + 1):
                d = math.hypot(dr, dc) * occupancy.resolution_m
                if d == 0.0 or d > inflation_m + 1e-9:
                    continue
                cost = 253 if d <= inscribed_m + 1e-9 else int(
                    252 * math.exp(-scaling * (d - inscribed_m)))
                shifted = padded[reach + dr:reach + dr + rows, reach + dc:reach + dc + cols]
                np.maximum(costs, np.where(shifted, cost, 0).astype(np.uint8), out=costs)
        self.full = costs
        self.resolution_m = occupancy.resolution_m
        self.origin = occupancy.origin
        self.cells = int(round(LOCAL_SIZE_M / self.resolution_m))

    def around(self, x: float, y: float) -> NumpyCostmap:
        """Return the window centred (to the nearest cell) on (x, y); off-map cells 255."""
        import numpy as np

        col0 = int(round((x - self.origin[0]) / self.resolution_m - self.cells / 2))
        row0 = int(round((y - self.origin[1]) / self.resolution_m - self.cells / 2))
        window = np.full((self.cells, self.cells), 255, dtype=np.uint8)
        rows, cols = self.full.shape
        r0, c0 = max(row0, 0), max(col0, 0)
        r1, c1 = min(row0 + self.cells, rows), min(col0 + self.cells, cols)
        if r0 < r1 and c0 < c1:
            window[r0 - row0:r1 - row0, c0 - col0:c1 - col0] = self.full[r0:r1, c0:c1]
        return NumpyCostmap(window, self.resolution_m, self.origin[0] + col0 * self.resolution_m,
                            self.origin[1] + row0 * self.resolution_m)


class LayeredLocalCostmap:
    """The local costmap built with mecanum_navigation.costmap.costmap_2d's layers."""

    def __init__(self, occupancy, inscribed_m: float):
        """Make the rolling window and its static and inflation layers."""
        from mecanum_navigation.costmap.costmap_2d import (
            InflationLayer, LayeredCostmap, RollingWindow, StaticLayer)

        self.window = RollingWindow(LOCAL_SIZE_M, LOCAL_SIZE_M, RESOLUTION_M)
        self.layered = LayeredCostmap(self.window.costmap, [
            StaticLayer(occupancy), InflationLayer(inscribed_m, 0.55, 3.0)])

    def around(self, x: float, y: float):
        """Move the window to (x, y) and update it; return the costmap."""
        self.window.move_to(x, y)
        return self.layered.update()


def drive(params, local, path, max_cycles: int) -> dict:
    """Drive the route in closed loop; return the timings (s) and the outcome."""
    from mecanum_control.kinematics import integrate_pose
    from mecanum_navigation.controller.local_controller import LocalController

    controller = LocalController(params)
    start = ROUTE[0]
    pose, twist = (start[0], start[1], 0.0), (0.0, 0.0, 0.0)
    times, samples, valid, statuses = [], [], [], {}
    status = ''
    inscribed_hits = 0
    for cycle in range(max_cycles):
        costmap = local.around(pose[0], pose[1])
        begin = time.perf_counter()
        twist, status = controller.compute_velocity(pose, twist, path, costmap)
        elapsed = time.perf_counter() - begin
        if cycle > 0:
            times.append(elapsed)
        samples.append(controller.last.samples)
        valid.append(controller.last.valid_samples)
        statuses[status] = statuses.get(status, 0) + 1
        if status in ('goal_reached', 'no_valid_trajectory'):
            break
        pose = integrate_pose(*pose, *twist, params.control_period)
        cell = costmap.costs[int((pose[1] - costmap.origin_y_m) // costmap.resolution_m),
                             int((pose[0] - costmap.origin_x_m) // costmap.resolution_m)]
        inscribed_hits += int(cell >= 253)
    ordered = sorted(times)
    return {'cycles': len(times) + 1, 'median_ms': 1e3 * statistics.median(ordered),
            'p99_ms': 1e3 * ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))],
            'max_ms': 1e3 * ordered[-1], 'mean_samples': statistics.fmean(samples),
            'mean_valid': statistics.fmean(valid), 'final_status': status,
            'statuses': statuses, 'drive_time_s': len(samples) * params.control_period,
            'final_pose': pose, 'inscribed_cells_entered': inscribed_hits,
            'times_ms': [1e3 * t for t in times]}


def main() -> int:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--max-cycles', type=int, default=800,
                        help='cycles per drive at most (20 Hz: 800 = 40 s; default 800)')
    parser.add_argument('--numpy-costmap', action='store_true',
                        help='use the numpy stand-in instead of mecanum_navigation.costmap.costmap_2d')
    parser.add_argument('--json', type=Path)
    args = parser.parse_args()
    if args.max_cycles < 2:
        parser.error('--max-cycles must be >= 2')

    from mecanum_control.robot_config import default_config_path, load_robot_config
    from mecanum_navigation.controller.local_controller import ControllerParams
    from robot_simulation.world import find_world, load_world

    robot = load_robot_config(default_config_path())
    occupancy = load_world(find_world('apartment')).to_occupancy_map(RESOLUTION_M)
    backend = 'numpy stand-in'
    if args.numpy_costmap:
        local = NumpyLocalCostmap(occupancy, robot.footprint_radius_m)
    else:
        try:
            local = LayeredLocalCostmap(occupancy, robot.footprint_radius_m)
            local.around(*ROUTE[0])   # JIT warm-up of the layers, not timed
            backend = 'mecanum_navigation.costmap.costmap_2d (StaticLayer + InflationLayer)'
        except (ImportError, AttributeError, TypeError) as error:
            print(f'costmap.py not usable ({error}); using the numpy stand-in',
                  file=sys.stderr)
            local = NumpyLocalCostmap(occupancy, robot.footprint_radius_m)
    path = densify(ROUTE, RESOLUTION_M)
    path[-1] = (*path[-1], GOAL_YAW)
    route_m = sum(math.hypot(x1 - x0, y1 - y0)
                  for (x0, y0), (x1, y1) in zip(ROUTE, ROUTE[1:]))

    rows = []
    for label, vx, vy, vtheta in CONFIGS:
        params = ControllerParams.from_robot_config(robot, vx_samples=vx, vy_samples=vy,
                                                    vtheta_samples=vtheta)
        print(f'driving with {label} ...', file=sys.stderr, flush=True)
        rows.append(dict(drive(params, local, path, args.max_cycles), config=label,
                         grid=vx * vy * vtheta))

    print(f'\nLocalController.compute_velocity per cycle, apartment route {route_m:.1f} m '
          f'({len(path)} path points), local costmap {LOCAL_SIZE_M:g} m x {LOCAL_SIZE_M:g} m '
          f'at {RESOLUTION_M:g} m,\n{backend}, {os.cpu_count()} CPUs, load average '
          f'{os.getloadavg()[0]:.1f}\n')
    header = (f'{"sampler":<22} {"grid":>5} {"samples":>8} {"valid":>6} {"cycles":>7} '
              f'{"median ms":>10} {"p99 ms":>8} {"max ms":>8}  outcome')
    print(header)
    print('-' * len(header))
    for row in rows:
        outcome = (f'{row["final_status"]} after {row["drive_time_s"]:.1f} s'
                   + (f', {row["inscribed_cells_entered"]} inscribed cells entered'
                      if row['inscribed_cells_entered'] else ''))
        print(f'{row["config"]:<22} {row["grid"]:>5} {row["mean_samples"]:>8.0f} '
              f'{row["mean_valid"]:>6.0f} {row["cycles"]:>7} {row["median_ms"]:>10.2f} '
              f'{row["p99_ms"]:>8.2f} {row["max_ms"]:>8.2f}  {outcome}')
    print(f'\ngrid: sampled targets before the wheel-speed filter; samples: targets scored '
          f'per cycle\n(after it, plus the candidates); valid: those not entering cells >= '
          f'253. Target: median well\nunder {TARGET_MS:g} ms per cycle (the controller runs '
          f'at 20 Hz). Timings on a loaded machine have long tails.')
    if args.json:
        args.json.write_text(json.dumps({
            'route_m': route_m, 'backend': backend, 'cpus': os.cpu_count(),
            'load_average': os.getloadavg()[0], 'target_ms': TARGET_MS,
            'rows': rows}, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
