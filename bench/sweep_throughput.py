"""
Scenario sweep throughput: variants per hour with --jobs 1, --jobs 2 and on a Ray cluster.

One sweep file (default: 8 variants of a short navigation scenario, 2 goals each) runs
into fresh result folders: on this machine one variant at a time and two at a time, each
cold (``--cold``: every variant starts its processes anew) and warm (the default: a
variant reuses the processes of the one before it, with new nodes), and as Ray tasks on
Ray's own 2-node test cluster on this machine (1 CPU a node; always cold).
``CPU s``: the CPU time of the sweep and everything it started.
Each variant is a whole isolated run of the simulated robot in lockstep at 'max'. The
table gives wall time, variants per hour, the mean wall time of one variant and whether
the three runs agree on every variant's status. Ratios, measured in one run, are what
compares; the absolute numbers depend on the machine and its load.

    ./mecanum exec python bench/sweep_throughput.py [--sweep FILE] [--json OUT]
        [--ways jobs1_cold jobs1 jobs2_cold jobs2 ray]
"""

import argparse
import json
from pathlib import Path
import resource
import sqlite3
import subprocess
import sys
import tempfile
import textwrap
import time

#: The ways a sweep can run, as --ways names them.
WAYS = ['jobs1_cold', 'jobs1', 'jobs2_cold', 'jobs2', 'ray']
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


def run(sweep: Path, out: Path, *extra: str) -> tuple:
    """Run the sweep; return (wall s, CPU s of it and its children)."""
    started = time.monotonic()
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, '-m', 'mecanum_bringup.sweep_runner', str(sweep),
                    '--out', str(out), '--quiet', *extra], check=True,
                   stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    return time.monotonic() - started, cpu


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sweep', help='a sweep file (default: the built-in 8 variants)')
    parser.add_argument('--json', help='write the numbers to this file')
    parser.add_argument('--ways', nargs='+', choices=WAYS, default=WAYS,
                        help='which ways to run (default: all)')
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix='sweep_bench_'))
    if args.sweep:
        sweep = Path(args.sweep).resolve()
    else:
        (work / 'two_goals.yaml').write_text(textwrap.dedent(SCENARIO))
        sweep = work / 'sweep.yaml'
        sweep.write_text(textwrap.dedent(SWEEP))
    results = {}
    local = (('jobs1_cold', '--jobs 1 --cold', ('--jobs', '1', '--cold')),
             ('jobs1', '--jobs 1 (warm)', ('--jobs', '1')),
             ('jobs2_cold', '--jobs 2 --cold', ('--jobs', '2', '--cold')),
             ('jobs2', '--jobs 2 (warm)', ('--jobs', '2')))
    for way, label, extra in local:
        if way not in args.ways:
            continue
        out = work / way
        results[label] = (*run(sweep, out, *extra), rows(out))
    if 'ray' in args.ways:
        from ray.cluster_utils import Cluster
        import ray
        cluster = Cluster(initialize_head=True, head_node_args={'num_cpus': 1})
        cluster.add_node(num_cpus=1)
        cluster.wait_for_nodes()
        try:
            out = work / 'ray'
            results['Ray, 2 nodes x 1 CPU'] = (*run(sweep, out, '--ray', cluster.address),
                                               rows(out))
        finally:
            ray.shutdown()
            cluster.shutdown()
    first = next(iter(results))
    reference = results[first][2]
    print(f'sweep {sweep} ({len(reference)} variants), 2-core machine')
    print(f'{"how":<22} {"wall s":>8} {"CPU s":>7} {"variants/h":>11} {"s/variant":>10} '
          f'{"vs first":>10} {"same statuses":>14}')
    numbers = {}
    for label, (wall, cpu, found) in results.items():
        per_hour = len(found) / wall * 3600.0
        mean = sum(w for _, w in found.values()) / len(found)
        statuses = {i: status for i, (status, _) in found.items()}
        same = statuses == {i: status for i, (status, _) in reference.items()}
        ratio = results[first][0] / wall
        print(f'{label:<22} {wall:8.0f} {cpu:7.0f} {per_hour:11.1f} {mean:10.1f} '
              f'{ratio:9.2f}x {str(same):>14}')
        numbers[label] = {'wall_s': wall, 'cpu_s': cpu, 'variants_per_hour': per_hour,
                          'mean_variant_wall_s': mean, 'same_statuses': same}
    if args.json:
        Path(args.json).write_text(json.dumps(numbers, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
