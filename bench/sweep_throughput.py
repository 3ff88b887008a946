"""
Scenario sweep throughput: variants per hour with --jobs 1, --jobs 2 and on a Ray cluster.

One sweep file (default: 8 variants of a short navigation scenario, 2 goals each) runs
three times into fresh result folders: on this machine one variant at a time, two at a
time, and as Ray tasks on Ray's own 2-node test cluster on this machine (1 CPU a node).
Each variant is a whole isolated run of the simulated robot in lockstep at 'max'. The
table gives wall time, variants per hour, the mean wall time of one variant and whether
the three runs agree on every variant's status. Ratios, measured in one run, are what
compares; the absolute numbers depend on the machine and its load.

    ./mecanum exec python bench/sweep_throughput.py [--sweep FILE] [--json OUT]
        [--ways jobs1 jobs2 ray]
"""

import argparse
import json
from pathlib import Path
import sqlite3
import subprocess
import sys
import tempfile
import textwrap
import time

#: The ways a sweep can run, as --ways names them.
WAYS = ['jobs1', 'jobs2', 'ray']
SCENARIO = """
scenario:
  name: two_goals
  world: apartment
  steps:
  - goal: {x: 3.5, y: 3.0, yaw: 0.0, timeout_s: 40}
  - goal: {x: 2.95, y: 2.0, yaw: 0.0, timeout_s: 40}
  criteria: {max_duration_s: 80}
"""
SWEEP = """
sweep:
  name: throughput
  scenario: two_goals.yaml
  mode: random
  samples: 8
  master_seed: 3
  axes:
    seed: {range: [0, 1000]}
    floor_friction_coefficient: {uniform: [0.4, 0.9]}
"""


def rows(out: Path) -> dict:
    db = sqlite3.connect(f'file:{out / "results.sqlite"}?mode=ro', uri=True)
    try:
        return {index: (status, wall) for index, status, wall in
                db.execute('SELECT idx, status, wall_time_s FROM variants')}
    finally:
        db.close()


def run(sweep: Path, out: Path, *extra: str) -> float:
    started = time.monotonic()
    subprocess.run([sys.executable, '-m', 'mecanum_bringup.sweep_runner', str(sweep),
                    '--out', str(out), '--quiet', *extra], check=True,
                   stdout=subprocess.DEVNULL)
    return time.monotonic() - started


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sweep', help='a sweep file (default: the built-in 8 variants)')
    parser.add_argument('--json', help='write the numbers to this file')
    parser.add_argument('--ways', nargs='+', choices=WAYS, default=WAYS,
                        help='which ways to run (default: all three)')
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix='sweep_bench_'))
    if args.sweep:
        sweep = Path(args.sweep).resolve()
    else:
        (work / 'two_goals.yaml').write_text(textwrap.dedent(SCENARIO))
        sweep = work / 'sweep.yaml'
        sweep.write_text(textwrap.dedent(SWEEP))
    results = {}
    for label, extra in (('--jobs 1', ('--jobs', '1')), ('--jobs 2', ('--jobs', '2'))):
        if label.replace(' ', '').replace('-', '') not in args.ways:
            continue
        out = work / label.replace(' ', '').replace('-', '')
        results[label] = (run(sweep, out, *extra), rows(out))
    if 'ray' in args.ways:
        from ray.cluster_utils import Cluster
        import ray
        cluster = Cluster(initialize_head=True, head_node_args={'num_cpus': 1})
        cluster.add_node(num_cpus=1)
        cluster.wait_for_nodes()
        try:
            out = work / 'ray'
            results['Ray, 2 nodes x 1 CPU'] = (run(sweep, out, '--ray', cluster.address),
                                               rows(out))
        finally:
            ray.shutdown()
            cluster.shutdown()
    first = next(iter(results))
    reference = results[first][1]
    print(f'sweep {sweep} ({len(reference)} variants), 2-core machine')
    print(f'{"how":<22} {"wall s":>8} {"variants/h":>11} {"s/variant":>10} {"vs first":>10} '
          f'{"same statuses":>14}')
    numbers = {}
    for label, (wall, found) in results.items():
        per_hour = len(found) / wall * 3600.0
        mean = sum(w for _, w in found.values()) / len(found)
        same = {i: s for i, (s, _) in found.items()} == {i: s for i, (s, _) in
                                                          reference.items()}
        ratio = results[first][0] / wall
        print(f'{label:<22} {wall:8.0f} {per_hour:11.1f} {mean:10.1f} {ratio:9.2f}x '
              f'{str(same):>14}')
        numbers[label] = {'wall_s': wall, 'variants_per_hour': per_hour,
                          'mean_variant_wall_s': mean, 'same_statuses': same}
    if args.json:
        Path(args.json).write_text(json.dumps(numbers, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
