"""
Integration: Ctrl-C (or SIGTERM) during a run stops everything cleanly and keeps the report.

The demo (``make demo``) runs kitchen_run until its first progress line (+10 s), then
gets SIGINT as from Ctrl-C: it must stop the robot, end with exit code 0 (the operator
stopped it: under ros2 launch a 1 is 'process has died', an ERROR), and still write
summary.json (aborted, fail, with the simulated time it ran: the step cut short ends at
the interruption, not where it began), run.png and a readable MCAP recording, and leave
no process behind. run_scenarios with --jobs 2 gets SIGTERM, which
reaches it alone (not its workers): both running scenarios must stop the same way.
"""

import json
from pathlib import Path
import signal
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / 'src/mecanum_bringup/scenarios'


def demo_command(out: Path, *extra: str):
    """Return the demo's command line (as `make demo` runs it) writing into out."""
    return [sys.executable, '-m', 'mecanum_bringup.demo', '--out', str(out), *extra]


@pytest.mark.long
def test_ctrl_c_stops_cleanly_and_keeps_the_report_and_the_recording(tmp_path, marked_env):
    from mcap.reader import make_reader
    process = subprocess.Popen(
        demo_command(tmp_path, '--scenario', str(SCENARIOS / 'kitchen_run.yaml')),
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=marked_env.env)
    lines = []
    deadline = time.monotonic() + 180
    for line in process.stdout:
        lines.append(line)
        if '+10 s:' in line or time.monotonic() > deadline:
            break
    assert any('+10 s:' in line for line in lines), ''.join(lines)
    process.send_signal(signal.SIGINT)
    rest, _ = process.communicate(timeout=90)
    output = ''.join(lines) + rest
    assert process.returncode == 0, output
    assert 'Ctrl-C: stopping the robot and writing the report' in output
    assert ' 0.00 s simulated' not in output and 'aborted in 0.0 s' not in output, output
    report = tmp_path / 'kitchen_run'
    summary = json.loads((report / 'summary.json').read_text())
    assert summary['aborted'] == 'interrupted (Ctrl-C)'
    assert summary['verdict'] == 'fail'
    # It ran past its +10 s progress line: the run and its cut step say so.
    assert summary['duration_s'] >= 10.0, summary['duration_s']
    cut = summary['steps'][-1]
    assert cut['outcome'] == 'aborted' and cut['end_s'] - cut['start_s'] > 0.0, cut
    assert (report / 'run.png').exists()
    with open(next((report / 'bag').glob('*.mcap')), 'rb') as stream:
        assert make_reader(stream).get_summary().statistics.message_count > 1000
    assert (report / 'bag' / 'metadata.yaml').exists()
    # Nothing of the run is left.
    assert marked_env.leftovers() == []


def test_sigterm_to_run_scenarios_stops_every_job_cleanly(tmp_path, marked_env):
    """
    SIGTERM stops both running scenarios of run_scenarios --jobs 2.

    The signal (a service manager, `timeout`, CI) reaches run_scenarios alone, not its
    workers; both scenarios still write their reports.
    """
    names = ('text_commands', 'bedroom_and_back')
    process = subprocess.Popen(
        [sys.executable, '-m', 'mecanum_bringup.scenario_runner',
         *(str(SCENARIOS / f'{name}.yaml') for name in names), '--out', str(tmp_path),
         '--jobs', '2'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=marked_env.env)
    lines = []
    deadline = time.monotonic() + 180
    for line in process.stdout:
        lines.append(line)
        if sum('step 1/' in seen for seen in lines) >= 2 or time.monotonic() > deadline:
            break
    assert sum('step 1/' in line for line in lines) >= 2, ''.join(lines)
    process.send_signal(signal.SIGTERM)
    rest, _ = process.communicate(timeout=90)
    output = ''.join(lines) + rest
    assert process.returncode == 1, output
    for name in names:
        summary = json.loads((tmp_path / name / 'summary.json').read_text())
        assert summary['aborted'] == 'interrupted (SIGTERM)', (name, output)
    assert marked_env.leftovers() == []
