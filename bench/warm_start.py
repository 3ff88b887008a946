#!/usr/bin/env python3
"""
Benchmark: what starting the system for one scenario costs, cold and warm (issue 33).

Runs a short scenario (default: the refusals of scenarios/goal_in_wall_refused.yaml)
``--runs`` times in this process with cold starts (every run starts the launch runner
and its processes) and as many times warm (``RunOptions.warm``: the runs after the first
load their nodes into the processes of the run before), interleaved: cold, warm, cold,
warm... Per run it measures, from the scenario runner's hook once the system is up
(every node ready, amcl localised):

* ``start CPU s``: CPU seconds the system's processes (the launch runner and its node
  processes) used to get there: cold, their whole CPU so far; warm, their CPU since the
  end of the previous run's steps (so it includes the previous run's unload, and is an
  upper bound);
* ``up s``: wall seconds from the call of run_scenario to the system being up.

The first warm run starts cold (nothing to reuse) and is left out of the warm numbers.
Ratios, measured in one run, are what compares.

Run:  ./mecanum exec python bench/warm_start.py [--scenario FILE] [--runs N] [--json FILE]
"""

import argparse
import json
import os
from pathlib import Path
import statistics
import sys
import tempfile
import time

from full_stack import cpu_seconds   # bench/, this script's folder
from mecanum_bringup import scenario_runner
from mecanum_bringup.scenario_loader import load_scenario
from mecanum_bringup.scenario_runner import release_kept_system, run_scenario, RunOptions

REPO = Path(__file__).resolve().parents[1]


class StartMeter:
    """Scenario runner hook: the system's CPU when it is up and when the steps end."""

    def __init__(self):
        """Start with no run measured."""
        self.called_at = 0.0
        self.up_s = None
        self.start_cpu_s = None
        self._pids = []           # the system's processes (launch runner first)
        self._end_cpu = {}        # pid -> CPU s at the end of the last run's steps

    def begin(self) -> None:
        """Note the wall time at which run_scenario is called."""
        self.called_at = time.monotonic()

    def __call__(self, system) -> None:
        """Take the numbers when the system is up (system) or the steps end (None)."""
        if system is not None:
            self.up_s = time.monotonic() - self.called_at
            self._pids = [system.process.pid, *system.node_pids().values()]
            self.start_cpu_s = sum(cpu_seconds(pid) - self._end_cpu.get(pid, 0.0)
                                   for pid in self._pids)
        else:
            self._end_cpu = {pid: cpu_seconds(pid) for pid in self._pids}


def main() -> int:
    """Run the scenario cold and warm, interleaved; print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--scenario', type=Path,
                        default=REPO / 'src/mecanum_bringup/scenarios/goal_in_wall_refused.yaml')
    parser.add_argument('--runs', type=int, default=4, help='runs of each kind (default 4)')
    parser.add_argument('--json', type=Path)
    options = parser.parse_args()
    scenario = load_scenario(options.scenario)
    runs = {'cold': [], 'warm': []}
    meters = {'cold': StartMeter(), 'warm': StartMeter()}
    with tempfile.TemporaryDirectory() as directory:
        for number in range(options.runs + 1):   # + 1: the first warm run starts cold
            for kind in ('cold', 'warm'):
                if kind == 'cold' and number == options.runs:
                    continue
                meter = meters[kind]
                # The warm runs' kept system waits aside while a cold run runs.
                aside = scenario_runner._KEPT.pop('system', None) if kind == 'cold' else None
                meter.begin()
                result = run_scenario(scenario, RunOptions(
                    Path(directory) / f'{kind}{number}', real_time_factor=0.0,
                    on_system=meter, warm=kind == 'warm'))
                if aside is not None:
                    scenario_runner._KEPT['system'] = aside
                verdict = result.verdict.verdict if result.verdict else result.error
                if not (kind == 'warm' and number == 0):
                    runs[kind].append({'start_cpu_s': meter.start_cpu_s, 'up_s': meter.up_s,
                                       'verdict': verdict})
        release_kept_system()
    print(f'system start for one scenario: {scenario.name}, {options.runs} runs each, '
          f'{os.cpu_count()} cores')
    print(f'{"start":<6} {"start CPU s (median)":>21} {"min":>6} {"max":>6} '
          f'{"up s (median)":>14} {"verdicts":>10}')
    summary = {}
    for kind, items in runs.items():
        cpu = [item['start_cpu_s'] for item in items]
        up = [item['up_s'] for item in items]
        verdicts = sorted({str(item['verdict']) for item in items})
        summary[kind] = {'start_cpu_s': cpu, 'up_s': up, 'verdicts': verdicts}
        print(f'{kind:<6} {statistics.median(cpu):>21.2f} {min(cpu):>6.2f} {max(cpu):>6.2f} '
              f'{statistics.median(up):>14.2f} {",".join(verdicts):>10}')
    ratio = (statistics.median(summary['cold']['start_cpu_s'])
             / statistics.median(summary['warm']['start_cpu_s']))
    print(f'cold / warm start CPU: {ratio:.2f}x')
    if options.json:
        options.json.write_text(json.dumps(summary, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
