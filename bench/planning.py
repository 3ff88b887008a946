#!/usr/bin/env python3
"""
Benchmark: costmap inflation and global planning times (pure cores, no ROS).

Builds two costmaps with mecanum_navigation.costmap.costmap_2d (static layer + inflation with
Nav2's defaults: inflation_radius 0.55 m, cost_scaling_factor 3.0, inscribed_radius =
the robot's footprint_radius_m from motor_params.yaml):

(a) the apartment world of the simulator (10 m x 8 m plus margins, walls and
    furniture rasterised at 0.05 m with robot_simulation's World.to_occupancy_map);
(b) a synthetic 100 m x 100 m map at 0.05 m (2000 x 2000 cells), seeded: outer walls,
    a 10 x 10 grid of 10 m rooms whose walls have 1.2 m doorways, and furniture
    (rectangles and round tables) inside the rooms, away from the doorways.

It times inflation (median of --inflation-runs), then plans a fixed set of start/goal
pairs on each map with mecanum_navigation.planner.planner.GridPlanner (default parameters:
cost_weight 1, smoothing on), including one whose path is about 75 m long, the length
of the published Nav2 Smac 2D figure (243 ms for a 75 m path), shown as the reference
line. Each pair is planned once untimed, then --runs times; the table shows the
median and maximum wall time, the median CPU time, the path length against the
straight-line distance and against the shortest path (cost_weight 0), and the cells
A* expanded. The JIT warm-up (first calls of the numba kernels: a
compile, or a load from numba's cache when it is warm) is timed separately, on a tiny
costmap, before anything else; --cold-jit points numba at an empty cache directory
to time a real compile.

Run:  ./mecanum exec python bench/planning.py [--runs 20] [--cold-jit]
Prints a table; --json FILE also writes the numbers.
"""

import argparse
import json
import math
import os
from pathlib import Path
import statistics
import sys
import tempfile
import time
from typing import List, Tuple

#: Nav2 Smac Planner 2D's published planning time for a ~75 m path (ms), the reference.
NAV2_SMAC_2D_MS = 243.0
NAV2_SMAC_2D_PATH_M = 75.0
#: Our target for that path after JIT warm-up (ms).
TARGET_MS = 100.0
RESOLUTION_M = 0.05
SYNTHETIC_SIZE_M = 100.0
ROOM_M = 10.0
DOOR_M = 1.2
#: Start/goal pairs (x, y m); each is moved to the nearest free cell of its costmap.
APARTMENT_PAIRS = [
    ('living room -> kitchen', (2.95, 2.0), (8.0, 2.0)),
    ('living room -> bedroom', (2.95, 2.0), (3.0, 6.5)),
    ('kitchen -> bathroom', (7.5, 1.5), (8.0, 6.5)),
    ('bedroom corner -> kitchen', (0.8, 5.6), (7.3, 1.3)),
    ('living room corner -> hallway end', (0.5, 0.5), (9.5, 4.5)),
]
SYNTHETIC_PAIRS = [
    ('same room', (4.0, 4.0), (8.0, 7.0)),
    ('next room', (4.0, 4.0), (15.0, 6.0)),
    ('~75 m path (Smac 2D reference length)', (5.0, 5.0), (54.0, 56.0)),
    ('corner to corner', (3.0, 3.0), (97.0, 97.0)),
    ('along a side', (3.0, 5.0), (97.0, 5.0)),
]


def synthetic_map(seed: int):
    """Return the seeded 100 m x 100 m OccupancyMap (see the module docstring)."""
    import numpy as np
    from mecanum_map_server.map_io import OccupancyMap

    rng = np.random.default_rng(seed)
    cells = int(round(SYNTHETIC_SIZE_M / RESOLUTION_M))
    data = np.zeros((cells, cells), dtype=np.int8)
    centres = (np.arange(cells) + 0.5) * RESOLUTION_M

    def fill(x0, y0, x1, y1):
        """Mark the cells whose centres are in [x0, x1] x [y0, y1] occupied."""
        cols = (centres >= x0) & (centres <= x1)
        rows = (centres >= y0) & (centres <= y1)
        data[np.ix_(rows, cols)] = 100

    half = 0.1
    fill(0.0, 0.0, SYNTHETIC_SIZE_M, 0.2)
    fill(0.0, SYNTHETIC_SIZE_M - 0.2, SYNTHETIC_SIZE_M, SYNTHETIC_SIZE_M)
    fill(0.0, 0.0, 0.2, SYNTHETIC_SIZE_M)
    fill(SYNTHETIC_SIZE_M - 0.2, 0.0, SYNTHETIC_SIZE_M, SYNTHETIC_SIZE_M)
    rooms = int(SYNTHETIC_SIZE_M / ROOM_M)
    for line in range(1, rooms):
        at = line * ROOM_M
        for span in range(rooms):
            lo, hi = span * ROOM_M, (span + 1) * ROOM_M
            # A wall segment between two junctions, with one doorway (two in 1/4 of them).
            doors = sorted(rng.uniform(lo + 1.5, hi - 1.5 - DOOR_M,
                                       size=2 if rng.random() < 0.25 else 1))
            edges = [lo] + [v for d in doors for v in (d, d + DOOR_M)] + [hi]
            for a, b in zip(edges[0::2], edges[1::2]):
                fill(a, at - half, b, at + half)   # horizontal wall y = at
                fill(at - half, a, at + half, b)   # vertical wall x = at
    grid_x, grid_y = np.meshgrid(centres, centres)
    for room_x in range(rooms):
        for room_y in range(rooms):
            x0, y0 = room_x * ROOM_M, room_y * ROOM_M
            for _ in range(rng.integers(2, 6)):
                if rng.random() < 0.7:
                    w, h = rng.uniform(0.4, 2.5), rng.uniform(0.4, 1.5)
                    x, y = rng.uniform(x0 + 2.0, x0 + 8.0 - w), rng.uniform(y0 + 2.0,
                                                                            y0 + 8.0 - h)
                    fill(x, y, x + w, y + h)
                else:
                    r = rng.uniform(0.2, 0.6)
                    cx, cy = rng.uniform(x0 + 2.5, x0 + 7.5), rng.uniform(y0 + 2.5, y0 + 7.5)
                    c0, c1 = int((cx - r) / RESOLUTION_M), int((cx + r) / RESOLUTION_M) + 1
                    r0, r1 = int((cy - r) / RESOLUTION_M), int((cy + r) / RESOLUTION_M) + 1
                    block = ((grid_x[r0:r1, c0:c1] - cx) ** 2
                             + (grid_y[r0:r1, c0:c1] - cy) ** 2) < r * r
                    data[r0:r1, c0:c1][block] = 100
    return OccupancyMap(RESOLUTION_M, (0.0, 0.0, 0.0), data)


def nearest_free(costmap, x: float, y: float) -> Tuple[float, float]:
    """Return the centre of the free cell (cost < 253) nearest (x, y)."""
    import numpy as np

    ys, xs = np.nonzero(costmap.costs < 253)
    gx, gy = costmap.world_to_grid(x, y)
    best = int(np.argmin((xs + 0.5 - gx) ** 2 + (ys + 0.5 - gy) ** 2))
    return costmap.map_to_world(int(ys[best]), int(xs[best]))


def build_costmap(occupancy, inscribed_radius: float, runs: int):
    """Return the inflated costmap and the static layer and inflation times (s, median)."""
    from mecanum_navigation.costmap.costmap_2d import Costmap2D, InflationLayer, StaticLayer

    costmap = Costmap2D.like_map(occupancy)
    static = StaticLayer(occupancy)
    inflation = InflationLayer(inscribed_radius)
    static_s, inflate_s = [], []
    for _ in range(runs):
        costmap.reset()
        start = time.perf_counter()
        static.update(costmap)
        middle = time.perf_counter()
        inflation.update(costmap)
        inflate_s.append(time.perf_counter() - middle)
        static_s.append(middle - start)
    return costmap, statistics.median(static_s), statistics.median(inflate_s)


def time_pairs(planner, costmap, pairs, runs: int) -> List[dict]:
    """Plan every pair once untimed, then `runs` times; return one row per pair."""
    from mecanum_navigation.planner.planner import GridPlanner, PlanningError

    shortest_planner = GridPlanner(cost_weight=0.0)

    rows = []
    for name, start, goal in pairs:
        start, goal = nearest_free(costmap, *start), nearest_free(costmap, *goal)
        straight = math.hypot(goal[0] - start[0], goal[1] - start[1])
        row = {'name': name, 'start': start, 'goal': goal, 'straight_m': straight}
        try:
            plan = planner.plan(costmap, start, goal)
        except PlanningError as error:
            rows.append(dict(row, error=str(error)))
            continue
        shortest = shortest_planner.plan(costmap, start, goal)
        times, cpu_times = [], []
        for _ in range(runs):
            begin, begin_cpu = time.perf_counter(), time.process_time()
            planner.plan(costmap, start, goal)
            times.append(time.perf_counter() - begin)
            cpu_times.append(time.process_time() - begin_cpu)
        rows.append(dict(row, length_m=plan.length_m, grid_length_m=plan.grid_length_m,
                         shortest_length_m=shortest.length_m,
                         expansions=plan.expansions, smoothed=plan.smoothed,
                         points=len(plan.points), median_ms=1e3 * statistics.median(times),
                         max_ms=1e3 * max(times),
                         median_cpu_ms=1e3 * statistics.median(cpu_times)))
    return rows


def warm_up() -> dict:
    """Time the first calls of the numba kernels on a tiny costmap (compile or cache load)."""
    begin = time.perf_counter()
    from mecanum_navigation.costmap import kernels
    from mecanum_navigation.planner import grid_search
    from mecanum_navigation.costmap.costmap_2d import Costmap2D, InflationLayer, ObstacleLayer
    from mecanum_navigation.planner.planner import GridPlanner
    imported = time.perf_counter()
    costmap = Costmap2D(40, 40, RESOLUTION_M)
    costmap.costs[5:35, 20] = 254
    InflationLayer(0.2).update(costmap)
    layer = ObstacleLayer()
    layer.add_scan(1.0, 1.0, 0.0, [0.5, math.inf], 0.0, 1.0)
    layer.update(costmap)
    GridPlanner().plan(costmap, (0.3, 1.0), (1.7, 1.0))
    done = time.perf_counter()
    hits = sum(sum(kernel.stats.cache_hits.values()) for kernel in (
        kernels.inflate, grid_search.astar, grid_search.shortcut, grid_search.smooth,
        kernels.raytrace))
    return {'import_s': imported - begin, 'first_calls_s': done - imported,
            'cache': 'loaded from cache' if hits else 'compiled',
            'numba_cache_dir': os.environ.get('NUMBA_CACHE_DIR', '(default: __pycache__)')}


def print_rows(title: str, rows: List[dict]) -> None:
    """Print the planning rows of one map."""
    print(f'\n{title}')
    header = (f'  {"pair":<40} {"straight m":>10} {"path m":>8} {"ratio":>6} {"vs w=0":>7} '
              f'{"grid m":>8} {"expanded":>9} {"median ms":>10} {"max ms":>8} {"cpu ms":>7}')
    print(header)
    print('  ' + '-' * (len(header) - 2))
    for row in rows:
        if 'error' in row:
            print(f'  {row["name"]:<40} {row["straight_m"]:>10.2f}  NO PLAN: {row["error"]}')
            continue
        print(f'  {row["name"]:<40} {row["straight_m"]:>10.2f} {row["length_m"]:>8.2f} '
              f'{row["length_m"] / row["straight_m"]:>6.3f} '
              f'{row["length_m"] / row["shortest_length_m"]:>7.3f} {row["grid_length_m"]:>8.2f} '
              f'{row["expansions"]:>9d} {row["median_ms"]:>10.2f} {row["max_ms"]:>8.2f} '
              f'{row["median_cpu_ms"]:>7.2f}')


def main() -> int:
    """Run the benchmark and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--runs', type=int, default=20,
                        help='timed plans per pair after one untimed (default 20)')
    parser.add_argument('--inflation-runs', type=int, default=5,
                        help='timed static layer + inflation passes per map (default 5)')
    parser.add_argument('--seed', type=int, default=7, help='seed of the synthetic map')
    parser.add_argument('--cold-jit', action='store_true',
                        help='use an empty numba cache directory: time a real JIT compile')
    parser.add_argument('--json', type=Path)
    args = parser.parse_args()
    if args.runs < 1 or args.inflation_runs < 1:
        parser.error('--runs and --inflation-runs must be >= 1')

    with tempfile.TemporaryDirectory(prefix='planning_jit_') as cache_dir:
        if args.cold_jit:
            os.environ['NUMBA_CACHE_DIR'] = cache_dir  # read when numba is imported
        jit = warm_up()

        from mecanum_control.robot_config import default_config_path, load_robot_config
        from mecanum_navigation.planner.planner import GridPlanner
        from robot_simulation.world import find_world, load_world

        robot = load_robot_config(default_config_path())
        radius = robot.footprint_radius_m
        planner = GridPlanner()
        maps = []
        apartment = load_world(find_world('apartment')).to_occupancy_map(RESOLUTION_M)
        begin = time.perf_counter()
        synthetic = synthetic_map(args.seed)
        synthetic_s = time.perf_counter() - begin
        for name, occupancy, pairs in (
                ('apartment (world rasterised at 0.05 m)', apartment, APARTMENT_PAIRS),
                (f'synthetic {SYNTHETIC_SIZE_M:g} m x {SYNTHETIC_SIZE_M:g} m, seed {args.seed}',
                 synthetic, SYNTHETIC_PAIRS)):
            costmap, static_s, inflate_s = build_costmap(occupancy, radius, args.inflation_runs)
            print(f'{name}: planning ...', file=sys.stderr, flush=True)
            rows = time_pairs(planner, costmap, pairs, args.runs)
            maps.append({'name': name, 'cells': [costmap.size_x, costmap.size_y],
                         'static_layer_ms': 1e3 * static_s, 'inflation_ms': 1e3 * inflate_s,
                         'rows': rows})

    print(f'\nCostmaps and global planning (pure cores, numba), {os.cpu_count()} CPUs; '
          f'inscribed_radius {radius} m, inflation_radius 0.55 m, cost_scaling_factor 3.0;'
          f'\nplanner: cost_weight {planner.cost_weight:g}, smoothing '
          f'{"on" if planner.smooth_path else "off"}; times: median and max of {args.runs} '
          'plans after one untimed\n')
    print(f'JIT warm-up (first calls on a tiny costmap, {jit["cache"]}): '
          f'{jit["first_calls_s"]:.2f} s (+ import {jit["import_s"]:.2f} s)')
    print(f'synthetic map generation: {synthetic_s:.2f} s (not a costmap cost)')
    print(f'\n  {"costmap":<50} {"cells":>11} {"static ms":>10} {"inflation ms":>13}')
    for entry in maps:
        size = f'{entry["cells"][0]}x{entry["cells"][1]}'
        print(f'  {entry["name"]:<50} {size:>11} {entry["static_layer_ms"]:>10.1f} '
              f'{entry["inflation_ms"]:>13.1f}')
    for entry in maps:
        print_rows(entry['name'], entry['rows'])
    print(f'  {"reference: Nav2 Smac 2D, ~75 m path":<40} {"":>10} '
          f'{NAV2_SMAC_2D_PATH_M:>8.2f} {"":>6} {"":>7} {"":>8} {"":>9} {NAV2_SMAC_2D_MS:>10.2f}')
    long = [row for row in maps[1]['rows'] if row['name'].startswith('~75 m')]
    if long and 'median_ms' in long[0]:
        row = long[0]
        verdict = 'met' if row['median_ms'] < TARGET_MS else 'NOT met'
        print(f'\n~75 m path: {row["length_m"]:.1f} m planned in {row["median_ms"]:.1f} ms '
              f'median ({row["max_ms"]:.1f} ms max): target < {TARGET_MS:.0f} ms {verdict}; '
              f'{NAV2_SMAC_2D_MS / row["median_ms"]:.1f}x faster than the Smac 2D reference'
              '\n  (published on other hardware: compare the order of magnitude only).')
    print('cpu ms = median process CPU time of a plan (less sensitive than wall time to other'
          '\n  load on a shared machine; the planner is single-threaded).')
    print('ratio = path length / straight-line distance; vs w=0 = path length / the length of'
          '\n  the shortest path (cost_weight 0, also shortcut and smoothed); grid m = the A* path'
          '\n  through cell centres before shortcutting and smoothing.')
    if args.json:
        args.json.write_text(json.dumps({
            'runs': args.runs, 'cpus': os.cpu_count(), 'jit': jit,
            'inscribed_radius_m': radius, 'cost_weight': planner.cost_weight,
            'nav2_smac_2d_reference_ms': NAV2_SMAC_2D_MS, 'target_ms': TARGET_MS,
            'synthetic_generation_s': synthetic_s, 'maps': maps}, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
