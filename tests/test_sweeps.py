"""
Integration: one 10-variant sweep gives the same per-variant verdicts run one at a time
(killed half-way and resumed), two at a time, and on a 2-node Ray cluster (stopped with
Ctrl-C, then resumed while it loses a node).

The sweep (a grid: 2 seeds x 5 goal subsets) runs a scenario of quick refusals, in
lockstep with the whole simulated robot per variant: goals in a wall and on the dining
table are refused with GOAL_IN_OBSTACLE as the scenario expects, a goal outside the map
is refused with another code, so every variant with that goal is UNEXPECTED. The
verdicts are known in advance; each way of running must find exactly them, keep every
finished row when killed, redo none, and leave no process behind.
"""

import json
import os
from pathlib import Path
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time
import uuid

from mecanum_bringup.isolation import processes_with_variable
import pytest

pytestmark = pytest.mark.integration

SCENARIO = """
# Three refusals; the second expects the wrong code (the goal is outside the map).
scenario:
  name: refusals
  world: apartment
  steps:
  - goal: {x: 6.0, y: 1.5, timeout_s: 10, expect: refused, error: GOAL_IN_OBSTACLE}
  - goal: {x: 12.0, y: 3.0, timeout_s: 10, expect: refused, error: GOAL_IN_OBSTACLE}
  - goal: {x: 7.6, y: 1.9, timeout_s: 10, expect: refused, error: GOAL_IN_OBSTACLE}
  criteria: {max_duration_s: 30}
"""
SWEEP = """
sweep:
  name: refusals_sweep
  scenario: refusals.yaml
  axes:
    seed: [0, 1]
    goals: [[0], [1], [2], [0, 2], [1, 2]]
"""
GOALS = [[0], [1], [2], [0, 2], [1, 2]]
#: The expected status of each variant (index = 5 * seed + goal subset).
EXPECTED = {5 * seed + i: 'UNEXPECTED' if 1 in goals else 'OK'
            for seed in (0, 1) for i, goals in enumerate(GOALS)}
MARKER = 'MECANUM_SWEEP_TEST'
#: Wall seconds a stopping system may take to end by itself (the launch runner's SIGINT,
#: then SIGTERM, then SIGKILL of its nodes) before what is left counts as left running.
LEFTOVER_GRACE_S = 30.0


def describe_process(pid: int) -> str:
    """Return 'pid (parent ppid): command line' of a live process, for a failure message."""
    try:
        command = Path(f'/proc/{pid}/cmdline').read_bytes().replace(b'\0', b' ').decode()
        parent = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[1]
    except OSError:
        return f'{pid} (gone)'
    return f'{pid} (parent {parent}): {command.strip()[:300]}'


def store_rows(out: Path) -> dict:
    """Return {index: (status, finished_at, worker)} of a sweep's store (empty if none)."""
    path = out / 'results.sqlite'
    if not path.is_file():
        return {}
    db = sqlite3.connect(f'file:{path}?mode=ro', uri=True, timeout=30.0)
    try:
        return {index: (status, finished, worker) for index, status, finished, worker in
                db.execute('SELECT idx, status, finished_at, worker FROM variants')}
    except sqlite3.OperationalError:   # the table is not there yet
        return {}
    finally:
        db.close()


def wait_for_rows(out: Path, count: int, process: subprocess.Popen, timeout_s: float):
    """Wait until the store has count rows (the sweep's own progress, not the clock)."""
    deadline = time.monotonic() + timeout_s
    while len(store_rows(out)) < count:
        if process.poll() is not None:
            raise AssertionError(f'run_sweep ended early ({process.returncode}): '
                                 f'{process.communicate()[0]}')
        assert time.monotonic() < deadline, f'fewer than {count} rows in {timeout_s} s'
        time.sleep(0.5)


def run_sweep(sweep: Path, out: Path, env: dict, *extra: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, '-m', 'mecanum_bringup.sweep_runner', str(sweep), '--out', str(out),
         '--quiet', *extra], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True)


def start_ray_cluster(ray_cluster, attempts: int = 3):
    """
    Start Ray's 2-node test cluster (1 CPU a node); return (cluster, second node).

    Ray gives a starting node a fixed 30 s of wall time to register (ray/_private/node.py,
    not configurable); on a loaded 2-core machine that can run out, so the start is tried
    again (Ray's startup, not the system under test).
    """
    for attempt in range(1, attempts + 1):
        cluster = None
        try:
            cluster = ray_cluster.Cluster(initialize_head=True,
                                          head_node_args={'num_cpus': 1})
            node = cluster.add_node(num_cpus=1)
            cluster.wait_for_nodes()
            return cluster, node
        except Exception as error:  # noqa: B902 - Ray raises a bare Exception here
            if cluster is not None:
                cluster.shutdown()
            if attempt == attempts or 'timed out during startup' not in str(error):
                raise
            print(f'Ray cluster start {attempt} failed ({error}); again')


def statuses(out: Path) -> dict:
    return {index: row[0] for index, row in store_rows(out).items()}


@pytest.fixture
def sweep_env(tmp_path, marked_env):
    """Write the scenario and the sweep; return (sweep file, env, marker value)."""
    (tmp_path / 'refusals.yaml').write_text(textwrap.dedent(SCENARIO))
    sweep = tmp_path / 'sweep.yaml'
    sweep.write_text(textwrap.dedent(SWEEP))
    marker = uuid.uuid4().hex
    env = dict(marked_env.env, **{MARKER: marker})
    yield sweep, env, marker
    # A system whose Ray worker died with its node (cluster.remove_node, then the
    # cluster's shutdown) is still stopping itself when the test ends: its launch runner
    # got SIGTERM from the worker's death and gives its nodes SIGINT, then SIGTERM
    # (LEFTOVER_GRACE_S in all). A process still there after that never ends by itself.
    deadline = time.monotonic() + LEFTOVER_GRACE_S
    while processes_with_variable(MARKER, marker) and time.monotonic() < deadline:
        time.sleep(0.2)
    left = processes_with_variable(MARKER, marker)
    described = [describe_process(pid) for pid in left]
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    assert left == [], f'processes left running: {described}'


@pytest.mark.long
def test_the_same_verdicts_one_at_a_time_resumed_two_at_a_time_and_on_ray(
        tmp_path, sweep_env, monkeypatch):
    sweep, env, marker = sweep_env
    # --jobs 1, stopped by Ctrl-C after 5 rows, then run again: the rest only.
    one = tmp_path / 'jobs1'
    process = run_sweep(sweep, one, env, '--jobs', '1')
    wait_for_rows(one, 5, process, timeout_s=600)
    process.send_signal(signal.SIGINT)
    output = process.communicate(timeout=120)[0]
    assert process.returncode == 1, output
    assert 'interrupted (Ctrl-C): run the same command to resume' in output
    first = store_rows(one)
    assert 5 <= len(first) < 10, first
    assert processes_with_variable(MARKER, marker) == [], 'a run survived the Ctrl-C'
    process = run_sweep(sweep, one, env, '--jobs', '1')
    output = process.communicate(timeout=900)[0]
    assert process.returncode == 0, output
    assert f'10 of 10 variants done ({10 - len(first)} run now, {len(first)} from before)' \
        in output
    rows = store_rows(one)
    assert {i: rows[i] for i in first} == first, 'a finished variant was run again'
    assert statuses(one) == EXPECTED
    assert (one / 'report.html').is_file() and (one / 'junit.xml').is_file()

    # --jobs 2: the same verdicts.
    two = tmp_path / 'jobs2'
    process = run_sweep(sweep, two, env, '--jobs', '2')
    output = process.communicate(timeout=900)[0]
    assert process.returncode == 0, output
    assert statuses(two) == EXPECTED
    # compare_sweeps: no rate changed beyond its interval (exit 1 would mean 'worse').
    compared = subprocess.run(
        [sys.executable, '-c', 'import sys; from mecanum_bringup.sweep_runner import '
         'compare_main; sys.exit(compare_main(sys.argv[1:]))', str(one), str(two)],
        env=env, capture_output=True, text=True, timeout=60)
    assert compared.returncode == 0, compared.stdout + compared.stderr
    assert 'verdict' in compared.stdout
    # Steps named by what they do (the goal subsets make step 1 differ by variant).
    assert 'step 1 (differs by variant)' in compared.stdout, compared.stdout

    # Ray: a 2-node cluster on this machine (Ray's own test cluster, 1 CPU a node); the
    # second node dies while it runs a variant, Ray runs that variant again elsewhere.
    ray_cluster = pytest.importorskip('ray.cluster_utils')
    for name, value in env.items():
        monkeypatch.setenv(name, value)   # the cluster's workers get the ROS environment
    cluster, doomed = start_ray_cluster(ray_cluster)
    try:
        on_ray = tmp_path / 'ray'
        # Ctrl-C on the Ray path: the running variants' workers are stopped, their
        # simulated robots with them, and no row is written for them.
        process = run_sweep(sweep, on_ray, env, '--ray', cluster.address)
        wait_for_rows(on_ray, 1, process, timeout_s=600)
        process.send_signal(signal.SIGINT)
        output = process.communicate(timeout=120)[0]
        assert process.returncode == 1, output
        before = store_rows(on_ray)
        assert 1 <= len(before) < 10, before
        # Resumed; the second node dies while it runs a variant.
        process = run_sweep(sweep, on_ray, env, '--ray', cluster.address)
        wait_for_rows(on_ray, len(before) + 2, process, timeout_s=600)
        cluster.remove_node(doomed, allow_graceful=False)
        output = process.communicate(timeout=900)[0]
        assert process.returncode == 0, output
        assert statuses(on_ray) == EXPECTED
        rows = store_rows(on_ray)
        assert {i: rows[i] for i in before} == before, 'a finished variant was run again'
        workers = {row[2] for row in store_rows(on_ray).values()}
        print(output, json.dumps(sorted(workers), indent=1))
        assert len({worker.split(' ray node ')[-1] for worker in workers}) == 2, workers
    finally:
        import ray
        ray.shutdown()
        cluster.shutdown()


SEARCH = """
sweep:
  name: refusals_search
  scenario: refusals.yaml
  mode: search
  samples: 6
  master_seed: 4
  search: {objective: least, batch: 3}
  axes:
    goals: [[0], [1], [2], [0, 2], [1, 2]]
"""


def test_a_search_runs_its_rounds_two_at_a_time_and_resumes_to_the_same_variants(
        tmp_path, sweep_env):
    """
    mode: search, 2 rounds of 3 with --jobs 2: round 2 is drawn from round 1's rows.

    Every stored variant is the one sweep_search.round_variants draws from the stored
    rows of the rounds before it; a variant of round 2 deleted from the store runs again
    with the same values, and only it.
    """
    from mecanum_bringup.sweep import load_sweep
    from mecanum_bringup.sweep_search import round_variants
    from mecanum_bringup.sweep_store import read_rows
    _, env, _ = sweep_env
    sweep_path = tmp_path / 'search.yaml'
    sweep_path.write_text(textwrap.dedent(SEARCH))
    out = tmp_path / 'search'
    process = run_sweep(sweep_path, out, env, '--jobs', '2')
    output, _ = process.communicate(timeout=900)
    assert process.returncode == 0, output
    rows = read_rows(out / 'results.sqlite')
    assert [row.index for row in rows] == list(range(6))
    # The goal outside the map (1) is refused with another code than expected.
    assert {row.index for row in rows if row.status == 'UNEXPECTED'} == {
        row.index for row in rows if 1 in row.values['goals']}
    sweep = load_sweep(sweep_path)
    for number in (0, 1):
        drawn = round_variants(sweep, number, rows)
        assert [v.values for v in drawn] == [rows[v.index].values for v in drawn]
    db = sqlite3.connect(str(out / 'results.sqlite'))
    db.execute('DELETE FROM variants WHERE idx = 4')
    db.commit()
    db.close()
    process = run_sweep(sweep_path, out, env, '--jobs', '2')
    output, _ = process.communicate(timeout=600)
    assert process.returncode == 0, output
    again = read_rows(out / 'results.sqlite')
    assert again[4].values == rows[4].values and again[4].status == rows[4].status
    assert [row.finished_at for i, row in enumerate(again) if i != 4] == [
        row.finished_at for i, row in enumerate(rows) if i != 4]


ONE_FAILURE = """
sweep:
  name: one_failure
  scenario: refusals.yaml
  axes:
    seed: [1]
    goals: [[1, 2]]
"""


def test_a_failure_shrinks_to_the_goal_that_fails_and_replays_with_one_command(
        tmp_path, sweep_env):
    """
    run_sweep --shrink: the failing variant (seed 1, goals 1 and 2) shrinks to goal 1 alone.

    Goal 1 (outside the map) is refused with another code than the scenario expects;
    goal 2 is refused as expected. Worked out: the seed dropped still fails (kept), goal 1
    dropped passes, goal 2 dropped fails (kept): 3 runs. The command it prints replays
    the smallest variant, which fails the same way again.
    """
    _, env, _ = sweep_env
    sweep_path = tmp_path / 'one.yaml'
    sweep_path.write_text(textwrap.dedent(ONE_FAILURE))
    out = tmp_path / 'one'
    process = run_sweep(sweep_path, out, env)
    output, _ = process.communicate(timeout=600)
    assert process.returncode == 0 and statuses(out) == {0: 'UNEXPECTED'}, output
    shrinking = subprocess.run(
        [sys.executable, '-m', 'mecanum_bringup.sweep_runner', str(sweep_path), '--out',
         str(out), '--shrink', '0'], env=env, capture_output=True, text=True, timeout=900)
    assert shrinking.returncode == 0, shrinking.stdout + shrinking.stderr
    report = json.loads((out / 'shrink' / 'shrink.json').read_text())
    assert report['smallest'] == {'goals': [1]}, report
    assert [(a['change'], a['kept']) for a in report['attempts']] == [
        ('seed: dropped', True), ('goals: goal 1 dropped', False),
        ('goals: goal 2 dropped', True)]
    assert report['runs'] == 3
    command = next(line for line in shrinking.stdout.splitlines()
                   if line.startswith('replay it: '))[len('replay it: '):]
    assert command.startswith('ros2 run mecanum_bringup run_scenarios ')
    scenario_file, replay_out = command.split()[4], command.split()[-1]
    replay = subprocess.run(
        [sys.executable, '-m', 'mecanum_bringup.scenario_runner', scenario_file, '--record',
         '--out', replay_out], env=env, capture_output=True, text=True, timeout=600)
    name = Path(scenario_file).parent.name
    summary = json.loads((Path(replay_out) / name / 'summary.json').read_text())
    assert summary['verdict'] == 'fail' and summary['steps'][0]['error_code'] != 0, summary
    assert (Path(replay_out) / name / 'bag').is_dir()
    assert replay.returncode == 1, replay.stdout      # an unexpected verdict


UNTIL_FAILURE = """
sweep:
  name: until_failure
  scenario: refusals.yaml
  axes:
    goals: [[0], [1], [2]]
"""


def test_until_failure_stops_after_the_first_failing_variant(tmp_path, sweep_env):
    """run_sweep --until-failure: goal 0 passes, goal 1 fails, goal 2 never runs."""
    _, env, _ = sweep_env
    sweep_path = tmp_path / 'until.yaml'
    sweep_path.write_text(textwrap.dedent(UNTIL_FAILURE))
    out = tmp_path / 'until'
    process = run_sweep(sweep_path, out, env, '--until-failure')
    output, _ = process.communicate(timeout=600)
    assert process.returncode == 0, output
    assert statuses(out) == {0: 'OK', 1: 'UNEXPECTED'}, output
    assert 'first failure: until_failure_0001' in output
