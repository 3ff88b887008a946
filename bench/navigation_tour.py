#!/usr/bin/env python3
"""
Benchmark: the full-stack apartment tour's success rate, time and path length.

Runs the demo's tour (scenarios/apartment_tour.yaml: simulator, control stack on the
simulated ESP32, description, EKF, map_server + amcl, navigator, velocity smoother,
collision monitor, each in its own process, on simulated time) --runs times with the
scenario runner and prints, per goal, how often it was reached, the median time and
driven path length (ground truth), the final true position error and amcl's largest
error on the way; then the totals.

Run:  ./mecanum exec python bench/navigation_tour.py [--runs 1] [--json FILE]
"""

import argparse
import json
import math
from pathlib import Path
import statistics
import sys
import tempfile

from mecanum_bringup.scenario_loader import load_scenario
from mecanum_bringup.scenario_runner import run_scenario, RunOptions
import numpy as np

REPO = Path(__file__).resolve().parents[1]
TOUR = REPO / 'src/mecanum_bringup/scenarios/apartment_tour.yaml'


def goal_rows(scenario, report: Path):
    """Return one dict per goal of a finished run (from its report folder)."""
    summary = json.loads((report / 'summary.json').read_text())
    truth = np.loadtxt(report / 'truth.csv', delimiter=',', skiprows=1, ndmin=2)
    estimate = np.loadtxt(report / 'estimate.csv', delimiter=',', skiprows=1, ndmin=2)
    rows = []
    for goal, step in zip(scenario.goals, summary['steps']):
        part = truth[(truth[:, 0] >= step['start_s']) & (truth[:, 0] <= step['end_s'])]
        during = estimate[(estimate[:, 0] >= step['start_s'])
                          & (estimate[:, 0] <= step['end_s'])]
        errors = np.hypot(during[:, 1] - np.interp(during[:, 0], truth[:, 0], truth[:, 1]),
                          during[:, 2] - np.interp(during[:, 0], truth[:, 0], truth[:, 2]))
        rows.append({
            'goal': f'({goal.x:.2f}, {goal.y:.2f})', 'reached': step['outcome'] == 'reached',
            'time_s': step['end_s'] - step['start_s'],
            'path_m': float(np.sum(np.hypot(*np.diff(part[:, 1:3], axis=0).T)))
            if len(part) > 1 else 0.0,
            'final_error_m': math.hypot(part[-1, 1] - goal.x, part[-1, 2] - goal.y)
            if len(part) else math.nan,
            'amcl_max_error_m': float(errors.max()) if len(errors) else math.nan})
    return rows, summary


def main() -> int:
    """Run the tour, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--runs', type=int, default=1)
    parser.add_argument('--json', type=Path)
    options = parser.parse_args()
    scenario = load_scenario(TOUR)
    runs = []
    for run in range(options.runs):
        with tempfile.TemporaryDirectory() as directory:
            result = run_scenario(scenario, RunOptions(Path(directory)))
            rows, summary = goal_rows(scenario, Path(directory) / scenario.name)
        runs.append({'passed': result.status == 'OK', 'goals': rows,
                     'collisions': summary['collisions'], 'wall_s': result.wall_time_s})
        print(f'run {run + 1}: {"passed" if runs[-1]["passed"] else "FAILED"} '
              f'({result.first_failure or "all criteria met"}), '
              f'{sum(g["reached"] for g in rows)} goals reached, {summary["collisions"]} '
              f'collisions, {result.wall_time_s:.0f} s wall')
    print(f'\n{"goal":16} {"reached":>8} {"time s":>7} {"path m":>7} {"end err m":>9} '
          f'{"amcl max m":>10}')
    for index, goal in enumerate(scenario.goals):
        tries = [r['goals'][index] for r in runs if index < len(r['goals'])]
        ok = [g for g in tries if g['reached']]

        def median(key, rows=ok):
            return statistics.median(g[key] for g in rows) if rows else float('nan')
        print(f'({goal.x:5.2f}, {goal.y:5.2f})   {len(ok):3d}/{options.runs:<4d} '
              f'{median("time_s"):7.1f} {median("path_m"):7.2f} '
              f'{median("final_error_m"):9.3f} {median("amcl_max_error_m"):10.3f}')
    reached = sum(g['reached'] for r in runs for g in r['goals'])
    total_goals = options.runs * len(scenario.goals)
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
