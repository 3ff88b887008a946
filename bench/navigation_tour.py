#!/usr/bin/env python3
"""
Benchmark: the full-stack apartment tour's success rate, time and path length.

Runs tests/test_navigation_tour.py (simulator, control stack on the simulated ESP32,
description, EKF, map_server + amcl, navigator, velocity smoother, collision monitor,
each in its own process, on simulated time at real_time_factor 1) --runs times and
prints, per goal, how often it was reached, the median time and driven path length
(ground truth), the final true position error and amcl's largest error on the way;
then the totals. A run stops at its first failed goal (later goals count as not tried).

Run:  ./mecanum exec python bench/navigation_tour.py [--runs 1] [--json FILE]
"""

import argparse
import json
import os
from pathlib import Path
import statistics
import subprocess
import sys
import tempfile
import time

REPO = Path(__file__).resolve().parents[1]


def main() -> int:
    """Run the tour, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--runs', type=int, default=1)
    parser.add_argument('--json', type=Path)
    options = parser.parse_args()
    runs = []
    for run in range(options.runs):
        with tempfile.TemporaryDirectory() as directory:
            out = Path(directory) / 'tour.json'
            start = time.monotonic()
            result = subprocess.run(
                [sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider',
                 'tests/test_navigation_tour.py'], cwd=REPO, capture_output=True, text=True,
                env=dict(os.environ, MECANUM_TOUR='1', MECANUM_TOUR_RESULTS=str(out)))
            wall_s = time.monotonic() - start
            data = json.loads(out.read_text()) if out.exists() else {'goals': []}
            data.update(passed=result.returncode == 0, wall_s=wall_s)
            runs.append(data)
            print(f'run {run + 1}: {"passed" if data["passed"] else "FAILED"}, '
                  f'{sum(g["error_code"] == 0 for g in data["goals"])} goals reached, '
                  f'{data.get("collisions", "?")} collisions, {wall_s:.0f} s wall')
    names = [g['goal'] for g in max(runs, key=lambda r: len(r['goals']))['goals']]
    print(f'\n{"goal":48} {"reached":>8} {"time s":>7} {"path m":>7} {"end err m":>9} '
          f'{"amcl max m":>10}')
    for name in names:
        tries = [g for r in runs for g in r['goals'] if g['goal'] == name]
        ok = [g for g in tries if g['error_code'] == 0]

        def median(key, rows=ok):
            return statistics.median(g[key] for g in rows) if rows else float('nan')
        print(f'{name[:48]:48} {len(ok):3d}/{options.runs:<4d} {median("time_s"):7.1f} '
              f'{median("path_m"):7.2f} {median("final_error_m"):9.3f} '
              f'{median("amcl_max_error_m"):10.3f}')
    reached = sum(g['error_code'] == 0 for r in runs for g in r['goals'])
    total_goals = options.runs * 12
    times = [sum(g['time_s'] for g in r['goals']) for r in runs if r['passed']]
    paths = [sum(g['path_m'] for g in r['goals']) for r in runs if r['passed']]
    print(f'\nsuccess: {reached}/{total_goals} goals ({100 * reached / total_goals:.0f} %), '
          f'{sum(r["passed"] for r in runs)}/{options.runs} complete tours without a '
          f'collision; tour time {statistics.median(times) if times else float("nan"):.0f} s '
          f'(simulated), path {statistics.median(paths) if paths else float("nan"):.1f} m')
    if options.json:
        options.json.write_text(json.dumps(runs, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
