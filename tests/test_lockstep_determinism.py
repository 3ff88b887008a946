"""
Integration: in lockstep, a busy machine does not change the scenario's verdict.

The same scenario with the same seed runs twice in lockstep at 'max' (as fast as the
stack answers), once on a quiet machine and once while a CPU hog keeps one core busy
(issue 19: "same scenario and seed, same verdict and the same step results, with or
without a CPU hog"). Simulated time waits for the stack each period, so the load only
stretches wall time: the verdict and every step's outcome and error code agree.

Each process answers a /clock once the work it starts is done (node_main.ClockAnswer:
the board's frames of the period, the messages before the /clock and their callbacks;
messages from other processes that come after it wait for it), the runner holds each
/clock until it has looked at that time and starts the first step on a whole simulated
second. Measured 2026-11-26 (text_commands): with and without a CPU hog, identical step
times and true tracks (0.0 mm apart); another pair of runs differed by 0.04 s from the
fourth step on (before this work: step ends 0.06-0.24 s apart, tracks up to 55 mm). Not
bounded yet: the test prints both; issue 19 keeps the period-exact comparison open.
"""

import json
import math
import os
from pathlib import Path
import subprocess
import sys

import pytest

#: alone: it loads the machine itself (the CPU hog), which would disturb other tests.
pytestmark = [pytest.mark.integration, pytest.mark.alone]

REPO = Path(__file__).resolve().parents[1]
SCENARIO = REPO / 'src/mecanum_bringup/scenarios/text_commands.yaml'


def run_scenario(out: Path) -> dict:
    """Run SCENARIO in lockstep at max into out; return its summary.json."""
    result = subprocess.run(
        [sys.executable, '-m', 'mecanum_bringup.scenario_runner', str(SCENARIO),
         '--out', str(out), '--quiet', '--real-time-factor', 'max'],
        capture_output=True, text=True, timeout=600,
        env=dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST'))
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return json.loads((out / SCENARIO.stem / 'summary.json').read_text())


def truth_track(out: Path) -> dict:
    """Return the true track as {simulated time rounded to 1 ms: (x, y, yaw)}."""
    lines = (out / SCENARIO.stem / 'truth.csv').read_text().splitlines()[1:]
    track = {}
    for line in lines:
        t, x, y, yaw = (float(v) for v in line.split(','))
        track[round(t, 3)] = (x, y, yaw)
    return track


def test_a_cpu_hog_does_not_change_the_verdict_in_lockstep(tmp_path):
    quiet = run_scenario(tmp_path / 'quiet')
    hog = subprocess.Popen([sys.executable, '-c', 'while True: pass'])
    try:
        loaded = run_scenario(tmp_path / 'loaded')
    finally:
        hog.kill()
        hog.wait()
    print('quiet wall time', quiet.get('wall_time_s'), 'loaded', loaded.get('wall_time_s'))
    assert quiet['verdict'] == loaded['verdict'] == 'pass'
    assert [(s['kind'], s['outcome'], s['error_code']) for s in quiet['steps']] == [
        (s['kind'], s['outcome'], s['error_code']) for s in loaded['steps']]
    assert quiet['collisions'] == loaded['collisions'] == 0
    # The first step starts when the runner has seen the stack ready, a wall-clock
    # moment (the simulator runs at real time at most until the board answers); from
    # there on simulated time is locked to the stack: compare from there.
    offset_s = loaded['steps'][0]['start_s'] - quiet['steps'][0]['start_s']
    worst_step_s = max(abs(b[key] - offset_s - a[key]) for a, b in zip(
        quiet['steps'], loaded['steps']) for key in ('start_s', 'end_s'))
    quiet_track, loaded_track = truth_track(tmp_path / 'quiet'), truth_track(tmp_path / 'loaded')
    shifted = {round(t - offset_s, 3): pose for t, pose in loaded_track.items()}
    common = sorted(set(quiet_track) & set(shifted))
    worst_m = max(math.dist(quiet_track[t][:2], shifted[t][:2]) for t in common)
    print(f'largest step time difference {worst_step_s:.2f} s, largest distance between '
          f'the true tracks {worst_m * 1000:.0f} mm ({len(common)} common samples)')
