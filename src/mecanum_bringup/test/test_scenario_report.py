"""Tests of the scenario reports: table, JUnit XML, JSON summary and the PNG plot."""

import dataclasses
import json
import math
import textwrap
import xml.etree.ElementTree as ElementTree

from matplotlib.image import imread
from mecanum_bringup.scenario_judge import judge
from mecanum_bringup.scenario_loader import load_scenario
from mecanum_bringup.scenario_model import CriterionResult, RunRecord, StepResult, Verdict
from mecanum_bringup.scenario_report import (
    junit_xml, plot_run, results_table, ScenarioResult, summary_json)
from mecanum_map_server.map_io import OccupancyMap
from mecanum_safety.zone import make_zone
import numpy as np
import pytest
from robot_simulation.world import find_world, load_world

PNG_MAGIC = b'\x89PNG\r\n\x1a\n'


def verdict(name, expected, passed_flags):
    criteria = tuple(CriterionResult(f'c{i}', passed, f'criterion {i} {"ok" if passed else "bad"}')
                     for i, passed in enumerate(passed_flags))
    return Verdict(name, expected, 'pass' if all(passed_flags) else 'fail', criteria)


@pytest.fixture
def results():
    return [
        ScenarioResult('kitchen_run', 'pass', verdict('kitchen_run', 'pass', [True, True]),
                       41.25, 63.4),
        ScenarioResult('bedroom_and_back', 'pass',
                       verdict('bedroom_and_back', 'pass', [True, False, False]), 55.0, 80.0),
        ScenarioResult('pushed_into_wall', 'fail',
                       verdict('pushed_into_wall', 'fail', [True, False]), 6.0, 12.5),
        ScenarioResult('broken', 'pass', None, None, 0.5,
                       error='broken.yaml: steps[0].goal.yaw: must be a number <&> "x"\x1b[0m'),
    ]


def test_the_table_has_a_row_per_scenario_and_a_summary(results):
    table = results_table(results)
    lines = table.splitlines()
    assert lines[0].split()[:4] == ['scenario', 'expected', 'verdict', 'result']
    assert set(lines[1]) == {'-', ' '}
    rows = lines[2:-1]
    assert [row.split()[0] for row in rows] == [r.name for r in results]
    assert [row.split()[1:4] for row in rows] == [
        ['pass', 'pass', 'OK'], ['pass', 'fail', 'UNEXPECTED'], ['fail', 'fail', 'OK'],
        ['pass', '-', 'ERROR']]
    assert '41.2 s' in rows[0] and '63.4 s' in rows[0]
    assert rows[1].endswith('criterion 1 bad')  # the first failed, not the second
    assert rows[2].endswith('criterion 1 bad')  # failed as expected: still shown
    assert 'broken.yaml: steps[0].goal.yaw' in rows[3]
    assert '\x1b' not in table  # control characters are not sent to the terminal
    # Fixed width: every column starts at the same offset in every row.
    column = lines[0].index('expected')
    assert all(row[column:].startswith(('pass', 'fail')) for row in rows)
    assert lines[-1] == '4 scenarios: 2 as expected, 1 unexpected, 1 errors'


def test_long_details_are_cut_to_one_line():
    long = Verdict('x', 'pass', 'fail', (CriterionResult('c', False, 'word\n' * 40),))
    table = results_table([ScenarioResult('x', 'pass', long, 1.0, 1.0)])
    row = table.splitlines()[2]
    assert row.endswith('...') and '\n' not in row and len(row) < 150


def test_junit_xml_parses_and_counts_failures_and_errors(results):
    root = ElementTree.fromstring(junit_xml(results).encode('utf-8'))
    assert root.tag == 'testsuite' and root.get('name') == 'scenarios'
    assert (root.get('tests'), root.get('failures'), root.get('errors')) == ('4', '1', '1')
    assert float(root.get('time')) == pytest.approx(63.4 + 80.0 + 12.5 + 0.5)
    cases = root.findall('testcase')
    assert [c.get('name') for c in cases] == [r.name for r in results]
    assert {c.get('classname') for c in cases} == {'scenarios'}
    assert [c.get('time') for c in cases] == ['63.400', '80.000', '12.500', '0.500']
    assert [c.find('failure') is not None for c in cases] == [False, True, False, False]
    failure = cases[1].find('failure')
    assert failure.get('message') == 'expected pass, got fail: criterion 1 bad'
    assert failure.text.splitlines() == [
        '[PASS] criterion 0 ok', '[FAIL] criterion 1 bad', '[FAIL] criterion 2 bad']
    assert 'criterion 1 bad' in cases[2].find('system-out').text
    error = cases[3].find('error')
    assert error is not None and cases[3].find('failure') is None
    # Escaped markup survives; the escape character XML cannot hold is replaced.
    assert error.text == ('broken.yaml: steps[0].goal.yaw: must be a number <&> "x"'
                          '\ufffd[0m')


def test_junit_xml_of_no_results_is_an_empty_suite():
    root = ElementTree.fromstring(junit_xml([]))
    assert (root.get('tests'), root.get('failures'), len(root)) == ('0', '0', 0)


SCENARIO = """
scenario:
  name: summary
  description: 'Two goals'
  world: apartment
  steps:
  - goal: {x: 5.1, y: 6.2}
  - wait: {duration_s: 1.0}
  - goal: {x: 4.5, y: 1.5}
  criteria:
    stay_in_zone: false
"""


def test_summary_json_values_by_hand(tmp_path):
    path = tmp_path / 'summary.yaml'
    path.write_text(textwrap.dedent(SCENARIO))
    scenario = load_scenario(path)
    # True path (1, 1) -> (4, 5) -> (4, 5) -> (7, 9): 5 + 0 + 5 = 10 m.
    truth = np.array([[0.0, 1.0, 1.0, 0.0], [1.0, 4.0, 5.0, 0.0], [2.0, 4.0, 5.0, 0.0],
                      [3.0, 7.0, 9.0, 0.0]])
    # Estimate errors 0.3 m and 0.4 m: max 0.4, RMS sqrt((0.09 + 0.16) / 2) = 0.35355.
    estimate = np.array([[1.0, 4.3, 5.0, 0.0], [2.0, 4.0, 4.6, 0.0]])
    record = RunRecord(
        truth=truth, estimate=estimate, collision_times=[1.5, 2.5],
        step_results=[StepResult('goal', 'reached', 0, '', 0.0, 1.0),
                      StepResult('wait', 'done', 0, '', 1.0, 2.0),
                      StepResult('goal', 'failed', 9104, 'stuck', 2.0, 3.0)],
        duration_s=3.0)
    judged = judge(scenario, record)
    summary = summary_json(scenario, record, judged, {'wall_time_s': 7.5})
    assert summary['scenario'] == 'summary' and summary['description'] == 'Two goals'
    assert summary['world'] == 'apartment'
    assert (summary['goals_reached'], summary['goals_total']) == (1, 2)
    assert summary['distance_m'] == pytest.approx(10.0)
    assert summary['duration_s'] == 3.0
    assert summary['collisions'] == 2
    assert summary['localization_error_max_m'] == pytest.approx(0.4)
    assert summary['localization_error_rms_m'] == pytest.approx(math.sqrt(0.125), abs=1e-3)
    assert (summary['verdict'], summary['expected'], summary['as_expected']) == (
        'fail', 'pass', False)
    assert summary['wall_time_s'] == 7.5 and summary['aborted'] is None
    assert [c['name'] for c in summary['criteria']] == [c.name for c in judged.criteria]
    assert summary['steps'][2] == {'kind': 'goal', 'outcome': 'failed', 'error_code': 9104,
                                   'error_message': 'stuck', 'start_s': 2.0, 'end_s': 3.0}
    assert json.loads(json.dumps(summary, allow_nan=False)) == summary
    with pytest.raises(ValueError, match="extra key 'verdict'"):
        summary_json(scenario, record, judged, {'verdict': 'pass'})
    # Nothing recorded: the undefined values are None, still strict JSON.
    empty = summary_json(scenario, RunRecord(duration_s=float('nan')), judged)
    assert empty['localization_error_max_m'] is None and empty['distance_m'] == 0.0
    assert empty['duration_s'] is None
    json.dumps(empty, allow_nan=False)
    # stay_in_zone is off in SCENARIO: no clearance measured.
    assert summary['min_zone_clearance_m'] is None and summary['min_zone_clearance_at'] is None
    assert summary['footprint_radius_m'] is None


def test_summary_json_carries_the_least_zone_clearance(tmp_path):
    path = tmp_path / 'zoned.yaml'
    path.write_text(textwrap.dedent(SCENARIO).replace('stay_in_zone: false', 'stay_in_zone: true'))
    scenario = dataclasses.replace(load_scenario(path), authorised_zone=make_zone(
        [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]))
    # Centre 0.1 m from x = 4 at t = 1 with the 0.2 m footprint (motor_params.yaml):
    # clearance 0.1 - 0.2 = -0.1 m.
    record = RunRecord(truth=np.array([[0.0, 2.0, 2.0, 0.0], [1.0, 3.9, 2.0, 0.0]]),
                       duration_s=1.0)
    summary = summary_json(scenario, record, judge(scenario, record))
    assert summary['min_zone_clearance_m'] == -0.1
    assert summary['min_zone_clearance_at'] == {'t_s': 1.0, 'x_m': 3.9, 'y_m': 2.0}
    assert summary['footprint_radius_m'] == 0.2
    zone = next(c for c in summary['criteria'] if c['name'] == 'stay_in_zone')
    assert zone['passed'] is False and zone['detail'].startswith(
        'stay_in_zone: least clearance -0.100 m at t=1.0 s (3.90, 2.00)')
    assert json.loads(json.dumps(summary, allow_nan=False)) == summary


def red_pixels(image):
    return int(np.sum((image[:, :, 0] > 0.8) & (image[:, :, 1] < 0.2) & (image[:, :, 2] < 0.2)))


def test_plot_run_writes_a_png_of_the_run(tmp_path):
    world = load_world(find_world('apartment'))
    occupancy = world.to_occupancy_map(0.05)
    t = np.linspace(0.0, 20.0, 401)
    truth = np.column_stack([t, 2.95 + 0.1 * t, 2.0 + 0.05 * t, np.zeros_like(t)])
    estimate = truth[::10] + [0.0, 0.03, -0.02, 0.0]
    args = {'occupancy_map': occupancy, 'truth': truth, 'estimate': estimate,
            'planned_paths': [np.array([[2.95, 2.0], [4.0, 2.5], [4.95, 3.0]])],
            'goals': [(4.95, 3.0, 0.0), (5.1, 6.2)], 'zone': world.test_zone,
            'title': 'kitchen_run: pass'}
    with_collisions = tmp_path / 'run.png'
    plot_run(with_collisions, collision_points=[(4.0, 2.5)], **args)
    without = tmp_path / 'clean.png'
    plot_run(without, collision_points=[], **args)
    for path in (with_collisions, without):
        assert path.read_bytes()[:8] == PNG_MAGIC
        image = imread(path)
        assert image.shape[:2] == (650, 800)
        # The map is drawn: black (occupied), white (free) and grey pixels all exist.
        grey = image[:, :, :3].mean(axis=2)
        assert np.sum(grey < 0.1) > 1000 and np.sum(grey > 0.95) > 10000
    # The collision crosses are red; nothing else in the plot is.
    assert red_pixels(imread(with_collisions)) > 20
    assert red_pixels(imread(without)) == 0


def test_plot_run_copes_with_no_map_rotated_maps_and_empty_tracks(tmp_path):
    rotated = OccupancyMap(0.1, (1.0, 1.0, 0.5), np.full((20, 30), -1, dtype=np.int8))
    for name, occupancy in (('none.png', None), ('rotated.png', rotated)):
        path = tmp_path / name
        plot_run(path, occupancy, truth=np.zeros((0, 4)), estimate=[], planned_paths=[],
                 goals=[], collision_points=[], zone=None, title='')
        assert path.read_bytes()[:8] == PNG_MAGIC
        assert imread(path).shape[:2] == (650, 800)
