"""
Integration: the shipped scenario suite runs headless and every verdict is the expected one.

run_scenarios runs each scenario file of mecanum_bringup/scenarios (but the demo's
12-goal tour, which tests/test_demo.py runs, and kitchen_run: see NOT_IN_CI) with the
whole simulated robot, each in its
own ROS domain and processes. One scenario must fail (a goal with too short a timeout)
and two expect refused goals (outside the authorised zone, in a wall): the harness must
report all of them as expected, in its table, its exit code, its JUnit XML and each
scenario's summary.json, and leave no process behind. A scenario given the wrong
expectation must be reported UNEXPECTED with exit code 1.

The safety scenarios of the command chain (issue 17) drive the robot by every
interface into walls and across zone borders: raw twists and teleop (through the mux),
text commands (stopped short, or refused when they would leave the zone), navigation
with a concave zone and an excluded doorway, a person stepping in front, localisation
hanging near the border. Across the whole suite: no collision and no zone exit.
"""

import json
from pathlib import Path
import subprocess
import sys
import xml.etree.ElementTree as ElementTree

import pytest

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / 'src/mecanum_bringup/scenarios'
#: Not in CI: apartment_tour (tests/test_demo.py runs it, the person at the kitchen door
#: included) and kitchen_run, whose person walks the robot's whole route in a 9 s loop:
#: the robot yields by backing off, and in one of three runs on 2026-11-23 it had not
#: got through the door after 60 s (a standoff, no collision). An open navigation
#: problem (see issue 8's notes); `make scenarios` still runs it.
NOT_IN_CI = {'apartment_tour', 'kitchen_run'}
SUITE = sorted(path for path in SCENARIOS.glob('*.yaml') if path.stem not in NOT_IN_CI)


def run_scenarios(paths, out: Path, timeout_s: float, marked_env):
    """
    Run run_scenarios on paths with marked_env; return the completed process (output
    captured).

    In lockstep (run_scenarios' default) at 'max': simulated time waits for the stack,
    so the verdicts do not depend on how fast this machine is or how busy; two at once
    (--jobs 2), each in its own worker, ROS domain and processes, and the expectations
    below are those of one run at a time.
    """
    return subprocess.run(
        [sys.executable, '-m', 'mecanum_bringup.scenario_runner', *map(str, paths),
         '--out', str(out), '--junit', str(out / 'junit.xml'), '--quiet',
         '--real-time-factor', 'max', '--jobs', '2'],
        capture_output=True, text=True, timeout=timeout_s, env=marked_env.env)


def summary(out: Path, name: str) -> dict:
    """Return a scenario's summary.json."""
    return json.loads((out / name / 'summary.json').read_text())


@pytest.mark.long
def test_the_suite_reports_every_scenario_as_expected(tmp_path, marked_env):
    assert len(SUITE) >= 8
    result = run_scenarios(SUITE, tmp_path, timeout_s=1500, marked_env=marked_env)
    print(result.stdout, result.stderr)
    assert result.returncode == 0, result.stdout[-3000:]
    assert f'{len(SUITE)} scenarios: {len(SUITE)} as expected, 0 unexpected, 0 errors' \
        in result.stdout
    # JUnit: one test case per scenario, none failed (a must-fail that failed is a pass).
    suite = ElementTree.parse(tmp_path / 'junit.xml').getroot()
    assert (suite.get('tests'), suite.get('failures'), suite.get('errors')) == (
        str(len(SUITE)), '0', '0')
    assert {case.get('name') for case in suite.iter('testcase')} == {p.stem for p in SUITE}
    # The must-fail scenario failed for the right reason.
    timeout = summary(tmp_path, 'must_fail_timeout')
    assert timeout['verdict'] == 'fail' and timeout['steps'][0]['outcome'] == 'timeout'
    # Its margin says so too: no time left (<= 0 s), and the unit is seconds.
    step_1 = timeout['criteria'][0]
    assert step_1['name'] == 'step 1' and step_1['margin'] <= 0.0
    assert step_1['margin_unit'] == 's'
    # The nearest obstacle of a run with a person walking across the robot's way is the
    # person, as recorded (ground_truth/moving_obstacles), with a clearance above 0.
    crossing = next(c for c in summary(tmp_path, 'person_before_text_command')['criteria']
                    if c['name'] == 'no_collision')
    assert ' to crossing_person at ' in crossing['detail'], crossing
    assert crossing['margin'] > 0.0 and crossing['margin_unit'] == 'm'
    # Refused goals carry the navigator's error codes; the next goals are still reached.
    zone = summary(tmp_path, 'goal_outside_zone_refused')
    assert zone['verdict'] == 'pass'
    assert zone['steps'][0]['outcome'] == 'refused'
    assert 'outside the authorised zone' in zone['steps'][0]['error_message']
    assert zone['steps'][1]['outcome'] == 'reached'
    wall = summary(tmp_path, 'goal_in_wall_refused')
    assert wall['verdict'] == 'pass'
    assert all(step['outcome'] == 'refused' for step in wall['steps'])
    # Nav2's FollowWaypoints (nav2_msgs types only) takes the robot through 3 waypoints.
    waypoints = summary(tmp_path, 'nav2_waypoints')
    assert [(step['kind'], step['outcome']) for step in waypoints['steps']] == [
        ('waypoints', 'reached')]
    # The whole robot on the firmware as flashed (main.py under MicroPython, lockstep).
    firmware = summary(tmp_path, 'flashed_firmware')
    assert firmware['board'] == 'firmware' and firmware['verdict'] == 'pass'
    assert [step['outcome'] for step in firmware['steps']] == ['reached', 'done', 'done']
    assert 'firmware/main.py as flashed' in (tmp_path / 'flashed_firmware'
                                             / 'system.log').read_text()
    assert summary(tmp_path, 'text_commands')['board'] == 'core'
    commands = summary(tmp_path, 'text_commands')
    assert [step['outcome'] for step in commands['steps']] == ['done'] * 7
    check_the_command_chain_scenarios(tmp_path)
    # Every passing scenario reached its goals without touching anything or leaving
    # the zone.
    for path in SUITE:
        result_summary = summary(tmp_path, path.stem)
        assert (tmp_path / path.stem / 'run.png').read_bytes()[:4] == b'\x89PNG'
        if result_summary['expected'] == 'pass':
            assert result_summary['collisions'] == 0, path.stem
            zone = [c for c in result_summary['criteria'] if c['name'] == 'stay_in_zone']
            assert zone and zone[0]['passed'], (path.stem, zone)
            # Every criterion passed by a margin above 0, where it has one.
            thin = [c for c in result_summary['criteria']
                    if c['passed'] and c['margin'] is not None and c['margin'] <= 0.0]
            assert thin == [], (path.stem, thin)
            assert result_summary['goals_reached'] == sum(
                1 for step in result_summary['steps'] if step['outcome'] == 'reached')
    assert marked_env.leftovers() == []


def truth_track(out: Path, name: str):
    """Return a scenario's truth.csv as rows of t, x, y, yaw."""
    lines = (out / name / 'truth.csv').read_text().splitlines()[1:]
    return [tuple(float(v) for v in line.split(',')) for line in lines]


def events(result_summary: dict, node: str) -> list:
    """Return the states of a node's safety events in a summary."""
    return [e['state'] for e in result_summary['safety_events'] if e['node'] == node]


def check_the_command_chain_scenarios(out: Path):
    """What each safety scenario of issue 17 must show beyond its verdict."""
    pushed = summary(out, 'pushed_into_wall')
    assert pushed['verdict'] == 'pass' and pushed['collisions'] == 0
    walls = summary(out, 'text_commands_into_walls')
    assert [step['outcome'] for step in walls['steps']] == [
        'stopped', 'stopped', 'done', 'rejected']
    assert 'blocked by collision_monitor' in walls['steps'][0]['error_message']
    assert 'authorised zone' in walls['steps'][3]['error_message']
    border = summary(out, 'text_commands_across_border')
    assert [step['outcome'] for step in border['steps']] == [
        'rejected', 'done', 'done', 'rejected']
    # Teleop pushed at the border x = 4.5 for 14 s in all: the footprint (0.2 m) stayed
    # inside, and the robot did get near it (it was held, not stopped far off).
    xs = [x for _, x, _, _ in truth_track(out, 'teleop_at_border')]
    assert 4.0 < max(xs) <= 4.5 - 0.2 + 0.01, max(xs)
    # Concave zone: the kitchen and the bathroom reached round the excluded doorway.
    excluded = summary(out, 'excluded_room_between')
    assert [step['outcome'] for step in excluded['steps']] == [
        'reached', 'reached', 'refused', 'reached']
    # amcl hung near the border: the zone guard stopped on the stale pose.
    lost = summary(out, 'localization_lost_near_border')
    assert any('no pose' in state for state in events(lost, 'zone_guard')), \
        lost['safety_events']


def test_a_wrong_expectation_is_reported_unexpected(tmp_path, marked_env):
    """The same refused goal, with `expect: fail` written in the file: exit code 1."""
    text = (SCENARIOS / 'goal_in_wall_refused.yaml').read_text()
    assert 'expect: pass' in text
    wrong = tmp_path / 'wrong_expectation.yaml'
    wrong.write_text(text.replace('name: goal_in_wall_refused', 'name: wrong_expectation')
                     .replace('expect: pass', 'expect: fail'))
    result = run_scenarios([wrong], tmp_path / 'out', timeout_s=300, marked_env=marked_env)
    assert result.returncode == 1, result.stdout
    assert 'UNEXPECTED' in result.stdout
    suite = ElementTree.parse(tmp_path / 'out' / 'junit.xml').getroot()
    assert suite.get('failures') == '1'
    assert marked_env.leftovers() == []


def test_an_invalid_scenario_file_is_a_clear_error(tmp_path, marked_env):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('scenario:\n  name: bad\n  world: apartment\n  steps:\n'
                   '  - goal: {x: 1.0, y: north}\n')
    result = run_scenarios([bad], tmp_path / 'out', timeout_s=120, marked_env=marked_env)
    assert result.returncode == 2
    assert "bad.yaml: steps[0].goal.y: must be a number, not 'north'" in result.stderr
    assert 'ERROR' in result.stdout
