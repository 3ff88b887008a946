#!/usr/bin/env python3
"""
Where a test suite's time goes: read the timeline a run wrote, print tables.

Run the suite with the timeline on, then read it::

    MECANUM_TEST_TIMELINE=/tmp/timeline.jsonl make test
    python3 tools/test_timeline.py /tmp/timeline.jsonl

Each line of the file is one test (conftest.py `_timeline_entry`): its worker, when it
asked to run, started and ended (wall s since the epoch), the CPU seconds of the worker
itself and of the processes it started and waited for. Printed: the run's span and how
many tests ran at once through it (seconds with 0, 1, 2, ... running), the time
``alone`` tests ran and the time workers waited for them (the run's lock), and the files
with the most wall time and the most CPU.
"""

import argparse
from collections import defaultdict
import json
from pathlib import Path
import sys
from typing import Dict, List


def read_timeline(path: Path) -> List[dict]:
    """Return the timeline's entries (lines that are not JSON objects are skipped)."""
    entries = []
    for line in path.read_text().splitlines():
        try:
            entry = json.loads(line)
        except ValueError:
            continue
        if isinstance(entry, dict) and {'start', 'end', 'test'} <= entry.keys():
            entries.append(entry)
    return entries


def concurrency_seconds(entries: List[dict]) -> Dict[int, float]:
    """Return {tests running at once: wall seconds} over the run's span."""
    events = sorted([(entry['start'], 1) for entry in entries]
                    + [(entry['end'], -1) for entry in entries])
    seconds: Dict[int, float] = defaultdict(float)
    running, last = 0, events[0][0] if events else 0.0
    for moment, change in events:
        seconds[running] += moment - last
        running, last = running + change, moment
    return dict(seconds)


def per_file(entries: List[dict]) -> Dict[str, dict]:
    """Return {test file: wall s, CPU s (worker + children), tests}."""
    files: Dict[str, dict] = defaultdict(lambda: {'wall_s': 0.0, 'cpu_s': 0.0, 'tests': 0})
    for entry in entries:
        row = files[entry['test'].split('::')[0]]
        row['wall_s'] += entry['end'] - entry['start']
        row['cpu_s'] += entry.get('cpu_s', 0.0) + entry.get('children_cpu_s', 0.0)
        row['tests'] += 1
    return dict(files)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('timeline', type=Path, help='the file $MECANUM_TEST_TIMELINE named')
    parser.add_argument('--top', type=int, default=25, help='files to list (default 25)')
    args = parser.parse_args(argv)
    try:
        entries = read_timeline(args.timeline)
    except OSError as error:
        print(f'test_timeline: cannot read {args.timeline}: {error}', file=sys.stderr)
        return 2
    if not entries:
        print(f'test_timeline: no test in {args.timeline}', file=sys.stderr)
        return 2
    span = max(e['end'] for e in entries) - min(e['start'] for e in entries)
    cpu = sum(e.get('cpu_s', 0.0) + e.get('children_cpu_s', 0.0) for e in entries)
    alone = sum(e['end'] - e['start'] for e in entries if e.get('alone'))
    waited = sum(e['start'] - e.get('asked', e['start']) for e in entries)
    print(f'{len(entries)} tests in {span:.0f} s of wall time; {cpu:.0f} CPU s in tests '
          f'and the processes they waited for; alone tests {alone:.0f} s; workers waited '
          f'{waited:.0f} s for the run lock (an alone test running or waiting)')
    print('\n| tests running at once | wall s | share |\n|---|---|---|')
    for running, seconds in sorted(concurrency_seconds(entries).items()):
        print(f'| {running} | {seconds:.0f} | {100 * seconds / span:.0f} % |')
    files = per_file(entries)
    for key, title in (('wall_s', 'wall'), ('cpu_s', 'CPU')):
        print(f'\nFiles by {title} s:\n\n| file | tests | wall s | CPU s |\n|---|---|---|---|')
        for name, row in sorted(files.items(), key=lambda item: -item[1][key])[:args.top]:
            print(f"| {name} | {row['tests']} | {row['wall_s']:.1f} | {row['cpu_s']:.1f} |")
    return 0


if __name__ == '__main__':
    sys.exit(main())
