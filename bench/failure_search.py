"""
Failure search: runs needed to find a planted rare failure, random sampling vs mode: search.

The shipped sweep ``sweeps/planted_slip.yaml`` (scenario ``slip_one_goal``: one goal,
localisation within 0.3 m, which fails only on floors with friction below about 0.024,
under 1 % of the axis) runs as it is (``mode: search``) and as ``mode: random`` with the
same axes, for each master seed, each with ``run_sweep --until-failure`` (one variant at
a time, warm): the runs needed are the first failing variant's index + 1 (variants run in
index order), or more than the budget (``samples``) when none failed. The two ways of a
seed run at once (the machine's two cores); the number of runs, not the time, is what
is compared. Prints one line per seed and the median and spread of each way, and the
ratio of the medians (issue 35's goal: search needs at most a fifth of random's runs).

    ./mecanum exec python bench/failure_search.py [--seeds 1 2 ...] [--budget N] [--json OUT]
"""

import argparse
from concurrent.futures import ThreadPoolExecutor
import json
from pathlib import Path
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time

import yaml

REPO = Path(__file__).resolve().parents[1]
SWEEP = REPO / 'src/mecanum_bringup/sweeps/planted_slip.yaml'
WAYS = ('random', 'search')


def write_sweep(way: str, seed: int, budget: int, folder: Path) -> Path:
    """Write the shipped sweep as way (random or search) with master seed and budget."""
    document = yaml.safe_load(SWEEP.read_text())
    sweep = document['sweep']
    sweep['name'] = f'planted_slip_{way}_{seed}'
    sweep['scenario'] = str((SWEEP.parent / sweep['scenario']).resolve())
    sweep['master_seed'] = seed
    sweep['samples'] = budget
    sweep['mode'] = way
    if way == 'random':
        sweep.pop('search', None)
    path = folder / f'{sweep["name"]}.yaml'
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    return path


def runs_to_failure(out: Path) -> tuple:
    """Return (runs needed: first failure's index + 1, or None; runs made)."""
    db = sqlite3.connect(f'file:{out / "results.sqlite"}?mode=ro', uri=True)
    try:
        rows = list(db.execute('SELECT idx, status FROM variants ORDER BY idx'))
    finally:
        db.close()
    failed = [index for index, status in rows if status == 'UNEXPECTED']
    return (min(failed) + 1 if failed else None), len(rows)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seeds', type=int, nargs='+', default=list(range(1, 11)))
    parser.add_argument('--budget', type=int, default=200,
                        help='most runs per sweep (default 200)')
    parser.add_argument('--parallel', type=int, default=2,
                        help='sweeps at once (default 2)')
    parser.add_argument('--ways', nargs='+', choices=WAYS, default=list(WAYS),
                        help='which ways to run (default both)')
    parser.add_argument('--json', help='write the numbers to this file')
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix='failure_search_'))
    found = {way: {} for way in WAYS}
    started = time.monotonic()
    print(f'{SWEEP.name}: runs to the first failure (budget {args.budget})')
    # Every search first (they are short), then the random sweeps: a run cut short
    # still has each seed's search.
    jobs = [(way, seed) for way in ('search', 'random') if way in args.ways
            for seed in args.seeds]

    def run(job):
        way, seed = job
        sweep = write_sweep(way, seed, args.budget, work)
        subprocess.run([sys.executable, '-m', 'mecanum_bringup.sweep_runner', str(sweep),
                        '--out', str(work / sweep.stem), '--quiet', '--until-failure'],
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        found[way][seed] = runs_to_failure(work / sweep.stem)
        needed, made = found[way][seed]
        print(f'{way:>6} seed {seed:>3}: {needed or f">{made}"} runs', flush=True)

    with ThreadPoolExecutor(max_workers=args.parallel) as pool:
        list(pool.map(run, jobs))
    print(f'{"seed":>5} {"random":>8} {"search":>8}')
    for seed in args.seeds:
        cells = [str(found[way][seed][0] or f'>{found[way][seed][1]}')
                 if seed in found[way] else '-' for way in WAYS]
        print(f'{seed:>5} {cells[0]:>8} {cells[1]:>8}')
    summary = {}
    for way in args.ways:
        # Censored at the budget: a sweep that found nothing counts as budget + 1.
        runs = [needed or args.budget + 1 for needed, _ in found[way].values()]
        summary[way] = {'median': statistics.median(runs), 'min': min(runs),
                        'max': max(runs), 'not_found': sum(1 for n, _ in found[way].values()
                                                           if n is None),
                        'runs': runs}
        print(f'{way:>6}: median {summary[way]["median"]:g} runs, spread {min(runs)}-'
              f'{max(runs)}, not found within the budget: {summary[way]["not_found"]}')
    ratio = (summary['search']['median'] / summary['random']['median']
             if len(summary) == len(WAYS) else None)
    if ratio is not None:
        print(f'search / random (medians): {ratio:.2f} (goal <= 0.20)')
    print(f'{time.monotonic() - started:.0f} s of wall time')
    if args.json:
        Path(args.json).write_text(json.dumps({'ways': summary, 'ratio': ratio}, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
