#!/usr/bin/env python3
"""
Benchmark: the whole simulated robot's real-time factor and its CPU and memory per node.

Runs a scenario (default: the demo's apartment tour, scenarios/apartment_tour.yaml)
with the scenario runner on each clock: ``wall`` (the simulator paced by the wall
clock at each ``--rtf``, as the demo runs) and ``lockstep`` (simulated time waits for
the stack, robot_simulation.lockstep, at each ``--lockstep-rtf``: ``max`` = as fast as
the stack answers), and in each mode: standalone
(every node its own process: the table is per node) and composed (the scenario
runner's default: the control chain and navigation in one container process each,
mecanum_bringup config/composition.yaml: the table is per process). While the steps run
it samples every process (/proc: CPU time, resident memory) and the runner itself.
Prints, per run: the real-time factor achieved (simulated seconds of the steps / wall
seconds), the verdict, and the table: CPU (% of one core, mean over the steps), peak
RSS (MiB). The machine's core count bounds what the sum of CPU can be: a sum near
100 % x cores means the stack is CPU bound. ``start CPU s``: the CPU seconds the
stack's processes (not the runner) used from their start until the system was up
(every node ready), the price of starting it for one scenario.

Run:  ./mecanum exec python bench/full_stack.py [--scenario FILE] [--clocks wall lockstep]
      [--rtf 1 2] [--lockstep-rtf max 3] [--modes standalone composed] [--json FILE]
      [--out DIR]
"""

import argparse
import json
import os
from pathlib import Path
import sys
import tempfile
import threading
import time

from mecanum_bringup.scenario_loader import load_scenario
from mecanum_bringup.scenario_runner import parse_real_time_factor, run_scenario, RunOptions

REPO = Path(__file__).resolve().parents[1]
TICKS_PER_S = os.sysconf('SC_CLK_TCK')
PAGE_MIB = os.sysconf('SC_PAGE_SIZE') / 2 ** 20


def cpu_seconds(pid: int) -> float:
    """Return the user + system CPU seconds of a process (0 when gone)."""
    try:
        fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / TICKS_PER_S


def rss_mib(pid: int) -> float:
    """Return the resident memory of a process in MiB (0 when gone)."""
    try:
        return int(Path(f'/proc/{pid}/statm').read_text().split()[1]) * PAGE_MIB
    except OSError:
        return 0.0


class Sampler:
    """Samples the nodes of the running system while its steps run."""

    def __init__(self, period_s: float = 1.0):
        """Start idle."""
        self.period_s = period_s
        self.system = None
        self.start = {}
        self.end = {}
        self.peak_rss = {}
        self.wall = [0.0, 0.0]
        self._stop = threading.Event()
        self._thread = None

    def __call__(self, system) -> None:
        """Scenario runner hook: the system is up (start) or the steps ended (stop)."""
        if system is not None:
            self.system = system
            pids = dict(system.node_pids(), runner=os.getpid())
            self.start = {label: cpu_seconds(pid) for label, pid in pids.items()}
            self.pids = pids
            self.wall[0] = time.monotonic()
            self._thread = threading.Thread(target=self._run, daemon=True)
            self._thread.start()
        else:
            self.end = {label: cpu_seconds(pid) for label, pid in self.pids.items()}
            self.wall[1] = time.monotonic()
            self._stop.set()
            self._thread.join()

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            for label, pid in self.pids.items():
                self.peak_rss[label] = max(self.peak_rss.get(label, 0.0), rss_mib(pid))

    def start_cpu_s(self) -> float:
        """Return the CPU seconds the stack's processes used until the system was up."""
        return sum(cpu for label, cpu in self.start.items() if label != 'runner')

    def rows(self):
        """Return [(label, cpu %, peak rss MiB)], busiest first."""
        wall = max(self.wall[1] - self.wall[0], 1e-9)
        rows = [(label, 100.0 * (self.end.get(label, 0.0) - self.start[label]) / wall,
                 self.peak_rss.get(label, 0.0)) for label in self.start]
        return sorted(rows, key=lambda row: -row[1])


def main() -> int:
    """Run the scenario at each real-time factor and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--scenario', type=Path,
                        default=REPO / 'src/mecanum_bringup/scenarios/apartment_tour.yaml')
    parser.add_argument('--clocks', nargs='+', choices=['wall', 'lockstep'],
                        default=['wall', 'lockstep'])
    parser.add_argument('--rtf', type=parse_real_time_factor, nargs='+', default=[1.0],
                        help='real-time factors on the wall clock')
    parser.add_argument('--lockstep-rtf', type=parse_real_time_factor, nargs='+',
                        default=[0.0], help="upper bounds in lockstep ('max': none)")
    parser.add_argument('--modes', nargs='+', choices=['standalone', 'composed'],
                        default=['composed'])
    parser.add_argument('--json', type=Path)
    parser.add_argument('--out', type=Path,
                        help="keep each run's report folder under OUT/MODE_rtfX "
                             '(default: a temporary folder, removed)')
    options = parser.parse_args()
    scenario = load_scenario(options.scenario)
    results = []
    print(f'full stack: scenario {scenario.name} ({len(scenario.steps)} steps), '
          f'{os.cpu_count()} cores')
    runs = [(clock, mode, rtf) for clock in options.clocks
            for rtf in (options.rtf if clock == 'wall' else options.lockstep_rtf)
            for mode in options.modes]
    for clock, mode, rtf in runs:
        sampler = Sampler()
        with tempfile.TemporaryDirectory() as directory:
            out = (options.out / f'{clock}_{mode}_rtf{rtf or "max"}' if options.out
                   else Path(directory))
            result = run_scenario(scenario, RunOptions(
                out, real_time_factor=rtf, on_system=sampler, compose=mode == 'composed',
                lockstep=clock == 'lockstep'))
        wall = max(sampler.wall[1] - sampler.wall[0], 1e-9)
        sim = result.sim_time_s or 0.0
        rows = sampler.rows()
        results.append({'clock': clock, 'mode': mode, 'requested_rtf': rtf or 'max',
                        'achieved_rtf': sim / wall if wall else None,
                        'sim_s': sim, 'wall_s': wall,
                        'verdict': result.verdict.verdict if result.verdict else None,
                        'first_failure': result.first_failure,
                        'start_cpu_s': sampler.start_cpu_s(),
                        'processes': [{'process': n, 'cpu_percent': c, 'peak_rss_mib': m}
                                      for n, c, m in rows]})
        failure = f' ({result.first_failure})' if result.first_failure else ''
        print(f'\n{clock} clock, {mode}, requested real-time factor {rtf or "max"}: '
              f'achieved {sim / wall:.2f} '
              f'({sim:.1f} s simulated in {wall:.1f} s wall), verdict '
              f'{results[-1]["verdict"]}{failure}')
        unit = 'node' if mode == 'standalone' else 'process'
        print(f'{unit:<24} {"CPU % of a core":>16} {"peak RSS MiB":>13} {"start CPU s":>12}')
        print(f'{"-" * 24} {"-" * 16} {"-" * 13} {"-" * 12}')
        for name, cpu, rss in rows:
            print(f'{name:<24} {cpu:>16.1f} {rss:>13.1f} {sampler.start[name]:>12.2f}')
        print(f'{"total":<24} {sum(r[1] for r in rows):>16.1f} '
              f'{sum(r[2] for r in rows):>13.1f}')
    print(f'\n{"clock":<9} {"mode":<11} {"requested":>9} {"achieved":>8} {"verdict":>8} '
          f'{"CPU % of a core":>16} {"RSS MiB":>8} {"CPU per sim s":>14} '
          f'{"start CPU s":>12}')
    for run in results:
        cpu = sum(p['cpu_percent'] for p in run['processes'])
        rss = sum(p['peak_rss_mib'] for p in run['processes'])
        per_sim = cpu / 100.0 / run['achieved_rtf'] if run['achieved_rtf'] else float('nan')
        print(f'{run["clock"]:<9} {run["mode"]:<11} {str(run["requested_rtf"]):>9} '
              f'{run["achieved_rtf"]:>8.2f} '
              f'{str(run["verdict"]):>8} {cpu:>16.1f} {rss:>8.0f} {per_sim:>12.2f} s '
              f'{run["start_cpu_s"]:>10.2f} s')
    if options.json:
        options.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
