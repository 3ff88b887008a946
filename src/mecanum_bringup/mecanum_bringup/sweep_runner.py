r"""
run_sweep: run every variant of a sweep file and report failure rates.

Usage::

    ros2 run mecanum_bringup run_sweep src/mecanum_bringup/sweeps/tour_variants.yaml \\
        --jobs 2 [--out reports/sweeps/NAME] [--ray ADDRESS] [--real-time-factor max] \\
        [--until-failure]
    ros2 run mecanum_bringup run_sweep SWEEP --out DIR --shrink INDEX
    ros2 run mecanum_bringup compare_sweeps reports/sweeps/A reports/sweeps/B

Each variant (:mod:`mecanum_bringup.sweep`) is a scenario run exactly as run_scenarios
runs one: the whole simulated robot, isolated (its own ROS domain, processes and run
folder ``DIR/runs/NAME/``), judged, in lockstep at the real-time factor 'max' unless told
otherwise. Every finished variant becomes one row of ``DIR/results.sqlite``
(:mod:`mecanum_bringup.sweep_store`) at once, so a sweep that is stopped (Ctrl-C, SIGTERM,
a crash, a reboot) and started again runs only the variants without a row; an
interrupted run leaves no row and runs again. At the end (also after Ctrl-C) it writes
``DIR/report.html``, ``DIR/rates.png`` and ``DIR/junit.xml`` and prints the failure rate
of every criterion with its Wilson 95 % interval.

``--jobs N`` runs N variants at once on this machine (worker processes). ``--ray
ADDRESS`` runs them as Ray tasks on a cluster (``auto``, ``ray://host:10001``, or a
``host:port`` of ``ray start --head``; ``local:N`` starts Ray's own N-node test cluster on
this machine for the sweep, 1 CPU a node): each task is one whole variant run on one node
(1 CPU), its row streamed back into the store as it finishes; Ray runs the task again
elsewhere when its worker or node dies (``--ray-retries``, 3). The run folders stay on
the node that ran the variant (the row's worker names it). Ray is an extra: installed
by ``make setup``; the sweep imports it only with --ray.

A search (``mode: search``) runs in rounds, each drawn from the rows so far
(:mod:`mecanum_bringup.sweep_search`). ``--until-failure`` stops at the first variant
whose verdict is not the expected one; ``--shrink INDEX`` shrinks a stored failing
variant to the simplest that still fails (:mod:`mecanum_bringup.sweep_shrink`).

Exit codes: 0 every variant has a row (whatever their verdicts: a sweep measures rates),
or --until-failure found one; 1 interrupted or some variants could not run; 2 invalid
sweep file or store.
"""

import argparse
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
import contextlib
from dataclasses import dataclass
import json
import math
import multiprocessing
import os
from pathlib import Path
import re
import shutil
import signal
import socket
import sys
import time
from typing import Any, Callable, Dict, List, Optional, Sequence, TextIO

from mecanum_bringup.scenario_judge import min_zone_clearance_m
from mecanum_bringup.scenario_loader import load_scenario, ScenarioError
from mecanum_bringup.scenario_report import ScenarioResult
from mecanum_bringup.scenario_runner import (
    interrupt, INTERRUPTED, interrupted_by, parse_real_time_factor, release_kept_system,
    run_scenario, RunOptions, stopping_cleanly_on_signals)
from mecanum_bringup.sweep import (
    goal_steps, input_digests, load_sweep, Sweep, SweepError, Variant, variant_documents,
    variants)
from mecanum_bringup.sweep_store import read_rows, ResultsStore, StoreError, VariantRow
import yaml


@dataclass
class PreparedVariant:
    """A variant with the scenario (and world) documents it runs; checked by loading."""

    variant: Variant
    name: str
    scenario_document: Dict[str, Any]
    world_document: Optional[Dict[str, Any]]


def prepare(sweep: Sweep, check_dir: Path,
            chosen: Optional[Sequence[Variant]] = None) -> List[PreparedVariant]:
    """
    Return every variant's documents (or chosen's), each checked as a scenario file would be.

    The documents are written under check_dir and loaded with load_scenario, so a
    variant that is not a valid scenario (e.g. a spawn in a wall) raises SweepError
    naming the variant and its values, before anything runs. A search's variants are
    chosen a round at a time (sweep_search.round_variants).
    """
    return [prepare_one(sweep, variant, variant.name(sweep.name), check_dir)
            for variant in (variants(sweep) if chosen is None else chosen)]


def prepare_one(sweep: Sweep, variant: Variant, name: str, check_dir: Path) -> PreparedVariant:
    """Return one variant's documents as run name, checked (SweepError if not valid)."""
    world_source = None
    if 'person' in variant.values:
        world_source = _world_document(sweep, variant)
    scenario_doc, world_doc = variant_documents(sweep, variant, world_source)
    scenario_doc['scenario']['name'] = name
    _absolute_paths(scenario_doc, sweep.scenario_file.parent)
    try:
        write_variant_files(check_dir / name, scenario_doc, world_doc)
    except ScenarioError as error:
        raise SweepError(f'{sweep.source.name}: variant {variant.index} '
                         f'({variant.describe()}) is not a valid scenario: {error}'
                         ) from None
    return PreparedVariant(variant, name, scenario_doc, world_doc)


def _world_document(sweep: Sweep, variant: Variant) -> Dict[str, Any]:
    """Return the world file document of the variant's world (map path made absolute)."""
    from robot_simulation.world import find_world, WorldError
    value = variant.values.get('world', sweep.scenario_document['scenario'].get('world'))
    path = Path(str(value))
    if not path.is_absolute() and ('/' in str(value) or str(value).endswith('.yaml')):
        path = sweep.scenario_file.parent / path
    try:
        path = path if path.is_file() else find_world(str(value))
    except WorldError as error:
        raise SweepError(f'{sweep.source.name}: variant {variant.index}: {error}') from None
    document = yaml.safe_load(path.read_text(encoding='utf-8'))
    world = document.get('world', {}) if isinstance(document, dict) else {}
    world.setdefault('name', path.stem)
    map_value = world.get('map')
    if isinstance(map_value, str) and not map_value.startswith('package://') \
            and not Path(map_value).is_absolute():
        world['map'] = str((path.parent / map_value).resolve())
    return document


def _absolute_paths(scenario_doc: Dict[str, Any], folder: Path) -> None:
    """Make the scenario's world and map paths absolute (the variant lives elsewhere)."""
    scenario = scenario_doc['scenario']
    for key in ('world', 'map'):
        value = scenario.get(key)
        if isinstance(value, str) and ('/' in value or value.endswith(('.yaml', '.yml'))) \
                and not value.startswith('package://') and not Path(value).is_absolute():
            scenario[key] = str((folder / value).resolve())


def write_variant_files(folder: Path, scenario_doc: Dict[str, Any],
                        world_doc: Optional[Dict[str, Any]]):
    """Write a variant's scenario.yaml (and variant_world.yaml) into folder; load it."""
    folder = folder.resolve()
    folder.mkdir(parents=True, exist_ok=True)
    scenario_doc = json.loads(json.dumps(scenario_doc))   # a copy, plain types
    if world_doc is not None:
        world_file = folder / 'variant_world.yaml'
        world_file.write_text(yaml.safe_dump(world_doc, sort_keys=False), encoding='utf-8')
        scenario_doc['scenario']['world'] = str(world_file)
    path = folder / 'scenario.yaml'
    path.write_text(yaml.safe_dump(scenario_doc, sort_keys=False), encoding='utf-8')
    return load_scenario(path)


def run_variant(index: int, name: str, values: Dict[str, Any], scenario_doc: Dict[str, Any],
                world_doc: Optional[Dict[str, Any]], out_dir: str,
                options: Dict[str, Any]) -> Optional[VariantRow]:
    """
    Run one variant isolated and return its row (None: interrupted, so no result).

    A plain function of plain arguments, so that it runs the same in this process, in a
    --jobs worker and as a Ray task on another node; options: real_time_factor (0 =
    max), record, lockstep, warm (reuse the processes of this process's last variant:
    scenario_runner.KeptSystem; never on Ray, whose workers outlive the sweep).
    """
    _normal_priority()
    runs = Path(out_dir) / 'runs'
    shutil.rmtree(runs / name, ignore_errors=True)   # what an interrupted attempt left
    scenario = write_variant_files(runs / name, scenario_doc, world_doc)
    result = run_scenario(scenario, RunOptions(
        runs, real_time_factor=options.get('real_time_factor', 0.0),
        record=bool(options.get('record', False)),
        lockstep=bool(options.get('lockstep', True)),
        warm=bool(options.get('warm', False))))
    if INTERRUPTED.is_set():
        return None
    return variant_row(index, name, values, result, str(runs / name))


def variant_row(index: int, name: str, values: Dict[str, Any], result: ScenarioResult,
                run_dir: str) -> VariantRow:
    """
    Return the store's row of a finished variant: its status, criteria and least clearance.

    min_zone_clearance_m is the verdict's stay_in_zone least footprint clearance (m;
    None when not judged or not measured); margins each criterion's that has one;
    worker and finished_at are this process's.
    """
    verdict = result.verdict
    first = verdict.first_failure if verdict else None
    return VariantRow(
        index=index, name=name, values=values, status=result.status,
        verdict=verdict.verdict if verdict else None, expected=result.expected,
        criteria={c.name: bool(c.passed) for c in verdict.criteria} if verdict else {},
        first_failure=first.detail if first else '',
        sim_time_s=_finite(result.sim_time_s), wall_time_s=_finite(result.wall_time_s),
        run_dir=run_dir, error=result.error, worker=_worker_name(),
        finished_at=time.time(),
        min_zone_clearance_m=_finite(min_zone_clearance_m(verdict)) if verdict else None,
        margins={c.name: c.margin for c in verdict.criteria
                 if _finite(c.margin) is not None} if verdict else {})


def _worker_name() -> str:
    """Return where the variant ran: host:pid, plus the Ray node id in a Ray task."""
    name = f'{socket.gethostname()}:{os.getpid()}'
    ray = sys.modules.get('ray')
    if ray is not None and ray.is_initialized():
        name += f' ray node {ray.get_runtime_context().get_node_id()[:12]}'
    return name


def _normal_priority() -> None:
    """
    Run the variant at niceness 0 where allowed (Ray starts its workers at 15).

    A niced simulated robot beside busy processes starves: lockstep then waits, and a
    stack silent for lockstep's give_up_s of wall time (60 s) ends the run. Where the
    user may not lower niceness, the run stays niced (start the cluster with
    RAY_worker_niceness=0 to avoid it).
    """
    if os.getpriority(os.PRIO_PROCESS, 0) > 0:
        try:
            os.setpriority(os.PRIO_PROCESS, 0, 0)
        except PermissionError:
            pass


def _finite(value: Optional[float]) -> Optional[float]:
    return value if value is not None and math.isfinite(value) else None


# --- progress ------------------------------------------------------------------------

class ProgressBar:
    """A progress line with the ETA: redrawn in place on a terminal, else one per variant."""

    def __init__(self, total: int, already_done: int, stream: TextIO = sys.stderr):
        self.total = total
        self.done = already_done
        self.failed = 0
        self.started = time.monotonic()
        self.finished_here = 0
        self.stream = stream
        self.tty = stream.isatty()

    def advance(self, row: VariantRow) -> None:
        """Count a finished variant and redraw."""
        self.done += 1
        self.finished_here += 1
        self.failed += row.failed
        self.draw(f'{row.name}: {row.status}')

    def line(self, last: str = '') -> str:
        """Return the progress text."""
        width = 24
        filled = int(width * self.done / self.total) if self.total else width
        elapsed = time.monotonic() - self.started
        remaining = self.total - self.done
        if self.finished_here and remaining:
            eta = f'ETA {_clock(elapsed / self.finished_here * remaining)}'
        else:
            eta = 'ETA -' if remaining else 'done'
        text = (f'[{"#" * filled}{"." * (width - filled)}] {self.done}/{self.total} '
                f'({self.failed} failed) {_clock(elapsed)} elapsed, {eta}')
        return f'{text}  {last}' if last else text

    def draw(self, last: str = '') -> None:
        """Print the progress line."""
        if self.tty:
            self.stream.write('\r\033[K' + self.line(last))
        else:
            self.stream.write(self.line(last) + '\n')
        self.stream.flush()

    def close(self) -> None:
        """End the line on a terminal."""
        if self.tty:
            self.stream.write('\n')
            self.stream.flush()


def _clock(seconds: float) -> str:
    seconds = int(round(seconds))
    hours, rest = divmod(seconds, 3600)
    return f'{hours}:{rest // 60:02d}:{rest % 60:02d}' if hours else \
        f'{rest // 60}:{rest % 60:02d}'


# --- running -------------------------------------------------------------------------

def _arguments(item: PreparedVariant, out_dir: Path, options: Dict[str, Any]) -> tuple:
    return (item.variant.index, item.name, item.variant.values, item.scenario_document,
            item.world_document, str(out_dir), options)


def _worker_init() -> None:
    """Set up a --jobs worker: Ctrl-C or SIGTERM end its run cleanly (no row)."""
    for number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(number, interrupt)


def run_local(todo: Sequence[PreparedVariant], out_dir: Path, options: Dict[str, Any],
              jobs: int, on_row: Callable[[VariantRow], None],
              say: Callable[[str], None], keep_system: bool = False) -> List[str]:
    """
    Run the variants jobs at once in worker processes; return why some did not run.

    keep_system: with one job, the warm system stays for the next call (a search's next
    round; release_kept_system ends it), else it ends here. options['until_failure']:
    with one job, no variant starts after one whose verdict was not the expected one.
    """
    problems: List[str] = []
    if jobs <= 1:
        try:
            for item in todo:
                if INTERRUPTED.is_set():
                    break
                row = run_variant(*_arguments(item, out_dir, options))
                if row is not None:
                    on_row(row)
                    if options.get('until_failure') and row.status == 'UNEXPECTED':
                        break
        finally:
            if not keep_system or INTERRUPTED.is_set():
                release_kept_system()
        return problems
    # spawn: a fresh interpreter per worker (no forked rclpy or reader threads).
    with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context('spawn'),
                             initializer=_worker_init) as pool:
        futures = {pool.submit(run_variant, *_arguments(item, out_dir, options)): item
                   for item in todo}
        pending = set(futures)
        cancelled = False
        while pending:
            finished, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            for future in finished:
                if future.cancelled():
                    continue
                error = future.exception()
                if error is not None:
                    problems.append(f'{futures[future].name}: worker error: '
                                    f'{type(error).__name__}: {error}')
                elif future.result() is not None:
                    on_row(future.result())
            if INTERRUPTED.is_set() and not cancelled:
                cancelled = True
                for future in pending:
                    future.cancel()
                for worker in multiprocessing.active_children():
                    os.kill(worker.pid, signal.SIGTERM)
    return problems


def run_on_ray(address: str, todo: Sequence[PreparedVariant], out_dir: Path,
               options: Dict[str, Any], retries: int, on_row: Callable[[VariantRow], None],
               say: Callable[[str], None]) -> List[str]:
    """Run the variants as Ray tasks (1 CPU each) on the cluster at address."""
    try:
        import ray
    except ImportError:
        raise SystemExit('run_sweep: --ray needs Ray (pip install -r '
                         'requirements/ros-jazzy-pip.py3XX.lock.txt, as make setup does)')
    with _ray_cluster(address) as address:
        if not ray.is_initialized():
            ray.init(address=address, log_to_driver=False,
                     runtime_env={'env_vars': _ros_environment()})
        return _run_ray_tasks(ray, address, todo, out_dir, options, retries, on_row, say)


#: --ray local:N: a Ray test cluster of N nodes (1 CPU each) on this machine.
LOCAL_RAY = re.compile(r'local:([1-9][0-9]?)')


@contextlib.contextmanager
def _ray_cluster(address: str):
    """
    Yield the address to connect to: address itself, or a local N-node test cluster's.

    'local:N' starts ray.cluster_utils.Cluster (Ray's own multi-node cluster on one
    machine, N nodes of 1 CPU) for the sweep and shuts it down after: the cluster path,
    node failures included, without `ray start` on several machines.
    """
    match = LOCAL_RAY.fullmatch(address)
    if match is None:
        yield address
        return
    import ray
    from ray.cluster_utils import Cluster
    cluster = Cluster(initialize_head=True, head_node_args={'num_cpus': 1})
    try:
        for _ in range(int(match.group(1)) - 1):
            cluster.add_node(num_cpus=1)
        cluster.wait_for_nodes()
        yield cluster.address
    finally:
        if ray.is_initialized():
            ray.shutdown()
        cluster.shutdown()


def _run_ray_tasks(ray, address: str, todo: Sequence[PreparedVariant], out_dir: Path,
                   options: Dict[str, Any], retries: int,
                   on_row: Callable[[VariantRow], None],
                   say: Callable[[str], None]) -> List[str]:
    """Submit the variants as tasks to the connected cluster; stream rows back."""
    resources = ray.cluster_resources()
    say(f'Ray cluster at {address}: {len(ray.nodes())} node(s), '
        f'{resources.get("CPU", 0):g} CPUs')
    # By reference to the installed module (also when this file runs as __main__, whose
    # functions Ray would pickle by value, with their globals).
    from mecanum_bringup import sweep_runner
    task = ray.remote(num_cpus=1, max_retries=retries)(sweep_runner.run_variant)
    refs = {task.remote(*_arguments(item, out_dir, options)): item for item in todo}
    problems: List[str] = []
    pending = list(refs)
    cancelled = False
    while pending:
        finished, pending = ray.wait(pending, num_returns=1, timeout=0.2)
        for ref in finished:
            try:
                row = ray.get(ref)
            except (ray.exceptions.TaskCancelledError, ray.exceptions.WorkerCrashedError,
                    ray.exceptions.NodeDiedError) as error:
                problems.append(f'{refs[ref].name}: {type(error).__name__}')
                continue
            except ray.exceptions.RayError as error:
                problems.append(f'{refs[ref].name}: {type(error).__name__}: '
                                f'{str(error).splitlines()[0] if str(error) else ""}')
                continue
            if row is not None:
                on_row(row)
        if INTERRUPTED.is_set() and not cancelled:
            cancelled = True
            # force: the worker process is killed (Ray's KeyboardInterrupt did not reach
            # a running variant); its launch runner then stops the simulated robot
            # (die_with_parent), and a killed variant leaves no row.
            for ref in pending:
                ray.cancel(ref, force=True)
    return problems


def _ros_environment() -> Dict[str, str]:
    """Return the variables a Ray worker needs to run the ROS workspace like this process."""
    names = ('AMENT_PREFIX_PATH', 'PYTHONPATH', 'LD_LIBRARY_PATH', 'PATH', 'ROS_DISTRO',
             'ROS_VERSION', 'ROS_PYTHON_VERSION', 'RMW_IMPLEMENTATION', 'COLCON_PREFIX_PATH')
    return {name: os.environ[name] for name in names if name in os.environ}


def run_sweep(sweep: Sweep, out_dir: Path, jobs: int = 1, ray_address: Optional[str] = None,
              options: Optional[Dict[str, Any]] = None, retries: int = 3,
              say: Callable[[str], None] = print, progress_stream: TextIO = sys.stderr
              ) -> Dict[str, Any]:
    """
    Run the sweep's variants that have no row yet; return a summary dict.

    The summary: total, done (rows), ran (this time), skipped (rows from before),
    problems (variants that could not run), interrupted. Raises SweepError or StoreError
    for an invalid sweep or a store of another sweep.
    """
    options = dict(options or {'real_time_factor': 0.0, 'record': False, 'lockstep': True})
    out_dir.mkdir(parents=True, exist_ok=True)
    # The store first: one of another sweep, or of edited inputs, is refused before any
    # of its runs' documents is written over.
    with ResultsStore(out_dir / 'results.sqlite', sweep.name, sweep.fingerprint,
                      input_digests(sweep)) as store:
        run = _run_search if sweep.mode == 'search' else _run_all
        summary = run(sweep, store, out_dir, jobs, ray_address, options, retries, say,
                      progress_stream)
        rows = store.rows()
    write_outputs(sweep, rows, out_dir, say)
    return dict(summary, done=len(rows))


def _run_all(sweep: Sweep, store: ResultsStore, out_dir: Path, jobs: int,
             ray_address: Optional[str], options: Dict[str, Any], retries: int,
             say: Callable[[str], None], progress_stream: TextIO) -> Dict[str, Any]:
    """Run every variant of a grid or random sweep that has no row (all checked first)."""
    prepared = prepare(sweep, out_dir / 'runs')
    done_before = store.done_indices()
    todo = [item for item in prepared if item.variant.index not in done_before]
    say(f'{sweep.name}: {len(prepared)} variants, {len(done_before)} done before, '
        f'{len(todo)} to run ' + (f'on Ray at {ray_address}' if ray_address
                                  else f'{jobs} at once') + f'; results in {store.path}')
    bar = ProgressBar(len(prepared), len(done_before), progress_stream)
    ran: List[VariantRow] = []

    def on_row(row: VariantRow) -> None:
        store.add(row)
        ran.append(row)
        bar.advance(row)

    problems: List[str] = []
    if todo:
        bar.draw()
        problems = _run_batch(todo, out_dir, jobs, ray_address, options, retries, on_row, say)
        bar.close()
    return {'total': len(prepared), 'ran': len(ran), 'skipped': len(done_before),
            'problems': problems, 'found': _first_failure(store.rows()),
            'interrupted': interrupted_by() if INTERRUPTED.is_set() else None}


def _first_failure(rows: Sequence[VariantRow]) -> Optional[str]:
    """Return the name of the first (lowest index) variant that failed, or None."""
    failed = [row for row in rows if row.status == 'UNEXPECTED']
    return min(failed, key=lambda row: row.index).name if failed else None


def _run_batch(todo: Sequence[PreparedVariant], out_dir: Path, jobs: int,
               ray_address: Optional[str], options: Dict[str, Any], retries: int,
               on_row: Callable[[VariantRow], None], say: Callable[[str], None],
               keep_system: bool = False) -> List[str]:
    """Run prepared variants here (jobs at once) or on Ray; return why some did not run."""
    with stopping_cleanly_on_signals():
        if ray_address:
            return run_on_ray(ray_address, todo, out_dir, dict(options, warm=False), retries,
                              on_row, say)
        return run_local(todo, out_dir, options, jobs, on_row, say, keep_system)


def _run_search(sweep: Sweep, store: ResultsStore, out_dir: Path, jobs: int,
                ray_address: Optional[str], options: Dict[str, Any], retries: int,
                say: Callable[[str], None], progress_stream: TextIO) -> Dict[str, Any]:
    """
    Run a search's rounds (sweep_search): each drawn from the rows of the rounds before.

    A round runs its variants that have no row (all at once with --jobs or --ray); the
    next round starts when every variant of this one has a row. A round left with a
    variant that could not run (or interrupted) ends the search there, so that the next
    start, which runs that variant again, draws the later rounds from the same rows.
    """
    from mecanum_bringup.sweep_search import round_count, round_variants
    done_before = store.done_indices()
    batch = sweep.search.batch
    rounds = round_count(sweep)
    say(f'{sweep.name}: search of {sweep.samples} variants in {rounds} rounds of {batch} '
        f'(objective: {sweep.search.objective}), {len(done_before)} done before, '
        + (f'on Ray at {ray_address}' if ray_address else f'{jobs} at once')
        + f'; results in {store.path}')
    bar = ProgressBar(sweep.samples, len(done_before), progress_stream)
    ran: List[VariantRow] = []
    problems: List[str] = []

    def on_row(row: VariantRow) -> None:
        store.add(row)
        ran.append(row)
        bar.advance(row)

    # One Ray cluster for every round (local:N is started once, not per round).
    cluster = _ray_cluster(ray_address) if ray_address else contextlib.nullcontext(None)
    try:
        with cluster as address:
            for number in range(rounds):
                chosen = round_variants(sweep, number, store.rows())
                todo = [item for item in prepare(sweep, out_dir / 'runs', chosen)
                        if item.variant.index not in store.done_indices()]
                if todo:
                    bar.draw()
                    problems += _run_batch(todo, out_dir, jobs, address, options, retries,
                                           on_row, say, keep_system=True)
                found = _first_failure(store.rows()) if options.get('until_failure') else None
                if found:
                    say(f'{sweep.name}: {found} failed: the search stops here '
                        '(--until-failure)')
                    break
                missing = [item.name for item in todo
                           if item.variant.index not in store.done_indices()]
                if missing:
                    say(f'{sweep.name}: round {number + 1} of {rounds} has no result for '
                        f'{", ".join(missing)}: the search stops here (run it again to go '
                        'on)')
                    break
    finally:
        release_kept_system()
        bar.close()
    return {'total': sweep.samples, 'ran': len(ran), 'skipped': len(done_before),
            'problems': problems, 'found': _first_failure(store.rows()),
            'interrupted': interrupted_by() if INTERRUPTED.is_set() else None}


def write_outputs(sweep: Sweep, rows: List[VariantRow], out_dir: Path,
                  say: Callable[[str], None]) -> None:
    """Write the report (HTML, PNG, JUnit) and print the rates table."""
    from mecanum_bringup.sweep_report import rates_table, write_report
    if not rows:
        say('no finished variant yet: no report')
        return
    html = write_report(rows, sweep.name, out_dir, list(sweep.axes), sweep.description)
    say(rates_table(rows))
    say(f'report: {html}')


# --- shrinking a failure -------------------------------------------------------------

def shrink_variant(sweep: Sweep, out_dir: Path, index: int, options: Dict[str, Any],
                   budget: int, say: Callable[[str], None] = print) -> int:
    """
    Shrink the stored failing variant index (sweep_shrink); return the exit code.

    Each simplification runs as OUT/shrink/runs/NAME_IIII_sNN (warm, as the sweep ran);
    OUT/shrink/shrink.json keeps every attempt. 2: no such failing variant in the store.
    """
    from mecanum_bringup.sweep_shrink import (
        changes, describe, nominal_values, shrink)
    from mecanum_control.robot_config import default_config_path, load_robot_config
    rows = {row.index: row for row in read_rows(out_dir / 'results.sqlite')}
    original = rows.get(index)
    if original is None or original.status != 'UNEXPECTED':
        say(f'run_sweep: --shrink {index}: ' + (
            'no such variant in the store' if original is None else
            f'{original.name} did not fail (status {original.status})'))
        return 2
    values = original.values
    document = (sweep.scenarios[values['scenario']][1] if 'scenario' in values
                else sweep.scenario_document)
    nominal = nominal_values(document, load_robot_config(
        default_config_path()).wheel_friction_coefficient)
    shrink_dir = out_dir / 'shrink'
    say(f'{original.name}: {describe(values)}: {original.first_failure}')
    say(f'shrinking (at most {budget} runs): nominal {describe(nominal)}')
    attempt = [0]

    def run(candidate: Dict[str, Any]) -> Optional[VariantRow]:
        attempt[0] += 1
        name = f'{original.name}_s{attempt[0]:02d}'
        try:
            item = prepare_one(sweep, Variant(index, candidate), name, shrink_dir / 'runs')
        except SweepError as error:
            say(f'  {name}: not a valid scenario: {error}')
            return None
        row = run_variant(*_arguments(item, shrink_dir, options))
        if row is not None:
            say(f'  {name}: {row.status}: {describe(candidate)}'
                + (f': {row.first_failure}' if row.first_failure else ''))
        return row

    try:
        with stopping_cleanly_on_signals():
            result = shrink(original, nominal, goal_steps(document), run, budget)
    finally:
        release_kept_system()
    smallest = next((a for a in reversed(result.attempts) if a.kept), None)
    report = {
        'variant': original.name, 'index': index, 'original': original.values,
        'first_failure': original.first_failure, 'nominal': nominal,
        'smallest': result.values, 'runs': result.runs, 'budget_spent': result.budget_spent,
        'attempts': [{'change': a.change, 'values': a.values, 'kept': a.kept,
                      'status': a.row.status if a.row else None,
                      'first_failure': a.row.first_failure if a.row else None,
                      'run_dir': a.row.run_dir if a.row else None}
                     for a in result.attempts]}
    shrink_dir.mkdir(parents=True, exist_ok=True)
    (shrink_dir / 'shrink.json').write_text(json.dumps(report, indent=1) + '\n',
                                            encoding='utf-8')
    say(f'smallest failing variant after {result.runs} runs'
        + (' (the budget ran out)' if result.budget_spent else '') + ': '
        + describe(result.values) + (f' ({"; ".join(changes(result))})'
                                     if changes(result) else ' (nothing simpler still fails)'))
    replay = Path(smallest.row.run_dir) if smallest and smallest.row else Path(
        original.run_dir)
    say(f'replay it: ros2 run mecanum_bringup run_scenarios {replay / "scenario.yaml"} '
        f'--record --out {shrink_dir / "replay"}')
    say(f'every attempt: {shrink_dir / "shrink.json"}')
    return 1 if INTERRUPTED.is_set() else 0


# --- the command lines ---------------------------------------------------------------

def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run a sweep file (see the module docstring); return the exit code."""
    parser = argparse.ArgumentParser(
        prog='run_sweep', description='Run every variant of a sweep file with the simulated '
        'robot and report failure rates with 95 % intervals.')
    parser.add_argument('sweep_file', help='the sweep file (YAML, see mecanum_bringup.sweep)')
    parser.add_argument('--out', help='results folder (default reports/sweeps/NAME); '
                        'run again with the same folder to resume')
    where = parser.add_mutually_exclusive_group()
    where.add_argument('--jobs', type=int, default=1,
                       help='variants at once on this machine (default 1)')
    where.add_argument('--ray', metavar='ADDRESS',
                       help="run on a Ray cluster: 'auto', host:port or ray://host:10001; "
                       "'local:N' starts Ray's N-node test cluster on this machine")
    parser.add_argument('--ray-retries', type=int, default=3,
                        help='times Ray runs a task again when its worker or node dies')
    parser.add_argument('--real-time-factor', type=parse_real_time_factor, default=0.0,
                        help="a number, or 'max' (default: as fast as the stack answers)")
    parser.add_argument('--record', action='store_true',
                        help='record every topic of every run (DIR/runs/NAME/bag)')
    parser.add_argument('--cold', action='store_true',
                        help="start every variant's processes anew (by default, except "
                        'on Ray, a variant reuses those of the one before it in the same '
                        'process or worker, with new nodes; see run_scenarios)')
    parser.add_argument('--quiet', action='store_true', help='no progress line')
    parser.add_argument('--until-failure', action='store_true',
                        help='stop once a variant fails (its verdict not the expected one): '
                        'with --jobs 1, or between the rounds of a search')
    parser.add_argument('--shrink', type=int, metavar='INDEX',
                        help='shrink the stored failing variant INDEX: the simplest variant '
                        'that still fails the same way (DIR/shrink/)')
    parser.add_argument('--shrink-budget', type=int, default=30, metavar='RUNS',
                        help='most runs a shrink may take (default 30)')
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error(f'--jobs must be at least 1, got {args.jobs}')
    if args.ray and args.ray.startswith('local:') and not LOCAL_RAY.fullmatch(args.ray):
        parser.error(f'--ray local:N needs N from 1 to 99 nodes, got {args.ray!r}')
    try:
        sweep = load_sweep(args.sweep_file)
    except SweepError as error:
        print(f'run_sweep: {error}', file=sys.stderr)
        return 2
    out_dir = Path(args.out or Path('reports') / 'sweeps' / sweep.name).resolve()
    if args.until_failure and sweep.mode != 'search' and (args.jobs > 1 or args.ray):
        parser.error('--until-failure stops between variants: it needs --jobs 1 (without '
                     '--ray) unless the sweep is a search (which stops between rounds)')
    options = {'real_time_factor': args.real_time_factor, 'record': args.record,
               'lockstep': True, 'warm': not args.cold, 'until_failure': args.until_failure}
    if args.shrink is not None:
        try:
            return shrink_variant(sweep, out_dir, args.shrink, options, args.shrink_budget)
        except StoreError as error:
            print(f'run_sweep: {error}', file=sys.stderr)
            return 2
    stream = open(os.devnull, 'w') if args.quiet else sys.stderr
    try:
        summary = run_sweep(sweep, out_dir, args.jobs, args.ray, options, args.ray_retries,
                            progress_stream=stream)
    except (SweepError, StoreError) as error:
        print(f'run_sweep: {error}', file=sys.stderr)
        return 2
    finally:
        if args.quiet:
            stream.close()
    for problem in summary['problems']:
        print(f'run_sweep: not run: {problem}', file=sys.stderr)
    print(f'{summary["done"]} of {summary["total"]} variants done ({summary["ran"]} run now, '
          f'{summary["skipped"]} from before)'
          + (f'; interrupted ({summary["interrupted"]}): run the same command to resume'
             if summary['interrupted'] else '')
          + (f'; first failure: {summary["found"]}' if summary['found'] else ''))
    if args.until_failure and summary['found'] and not summary['interrupted']:
        return 0
    return 0 if summary['done'] == summary['total'] else 1


def compare_main(argv: Optional[Sequence[str]] = None) -> int:
    """Compare two sweeps' failure rates (before and after a change); return the exit code."""
    from mecanum_bringup.sweep_report import compare_table, step_labels, variant_changes_table
    from mecanum_bringup.sweep_stats import compare, variant_changes
    from mecanum_bringup.sweep_store import read_rows
    parser = argparse.ArgumentParser(
        prog='compare_sweeps', description='Say which failure rates changed between two '
        'sweeps beyond their 95 % intervals (A: before, B: after), and which variants of '
        'both got another status.')
    parser.add_argument('before', help='results folder (or results.sqlite) of sweep A')
    parser.add_argument('after', help='results folder (or results.sqlite) of sweep B')
    args = parser.parse_args(argv)
    try:
        rows = [read_rows(_store_path(Path(path))) for path in (args.before, args.after)]
    except StoreError as error:
        print(f'compare_sweeps: {error}', file=sys.stderr)
        return 2
    changes = compare(*rows)
    # Steps named by what they do, from each sweep's run folders (B's where both have one).
    labels = {}
    for path, sweep_rows in zip((args.before, args.after), rows):
        folder = _store_path(Path(path)).parent
        labels.update(step_labels(sweep_rows, None, folder))
    print(compare_table(changes, labels))
    print(variant_changes_table(*variant_changes(*rows)))
    return 1 if any(change.verdict == 'worse' for change in changes) else 0


def _store_path(path: Path) -> Path:
    return path / 'results.sqlite' if path.is_dir() else path


if __name__ == '__main__':
    sys.exit(main())
