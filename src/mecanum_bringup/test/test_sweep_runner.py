"""Tests of the sweep runner's rows: what a finished variant stores (no robot is run)."""

from mecanum_bringup import sweep_runner
from mecanum_bringup.scenario_judge import ZoneResult
from mecanum_bringup.scenario_model import CriterionResult, Verdict
from mecanum_bringup.scenario_report import ScenarioResult
from mecanum_bringup.sweep_runner import variant_row
import pytest


def test_a_judged_variant_stores_its_criteria_and_least_zone_clearance():
    # The footprint 0.1 m over the border at t = 2 s (radius 0.2 m): clearance -0.1 m.
    zone = ZoneResult('stay_in_zone', False, 'stay_in_zone: least clearance -0.100 m ...',
                      margin=-0.1, margin_unit='m', min_clearance_m=-0.1, t_s=2.0, x_m=3.9,
                      y_m=2.0, footprint_radius_m=0.2)
    verdict = Verdict('tour_0001', 'pass', 'fail',
                      (CriterionResult('step 1', True, 'step 1 goal: reached'), zone))
    result = ScenarioResult('tour_0001', 'pass', verdict, 12.5, 30.0)
    row = variant_row(1, 'tour_0001', {'seed': 1}, result, '/sweep/runs/tour_0001')
    assert (row.index, row.name, row.values, row.status, row.verdict, row.expected) == (
        1, 'tour_0001', {'seed': 1}, 'UNEXPECTED', 'fail', 'pass')
    assert row.criteria == {'step 1': True, 'stay_in_zone': False}
    assert row.first_failure == 'stay_in_zone: least clearance -0.100 m ...'
    assert row.min_zone_clearance_m == pytest.approx(-0.1)
    assert row.margins == {'stay_in_zone': -0.1}     # step 1 has none here
    assert (row.sim_time_s, row.wall_time_s, row.run_dir) == (12.5, 30.0,
                                                              '/sweep/runs/tour_0001')
    assert row.worker and row.finished_at > 0


def test_a_variant_without_zone_line_or_verdict_stores_no_clearance():
    verdict = Verdict('tour_0002', 'pass', 'pass',
                      (CriterionResult('step 1', True, 'step 1 goal: reached'),))
    row = variant_row(2, 'tour_0002', {}, ScenarioResult('tour_0002', 'pass', verdict,
                                                         float('nan'), 3.0), '')
    assert row.min_zone_clearance_m is None and row.status == 'OK'
    assert row.sim_time_s is None   # not finite: not stored
    error = variant_row(3, 'tour_0003', {}, ScenarioResult(
        'tour_0003', 'pass', None, None, 1.0, error='runner error: boom'), '')
    assert (error.status, error.verdict, error.criteria, error.error) == (
        'ERROR', None, {}, 'runner error: boom')
    assert error.min_zone_clearance_m is None


@pytest.mark.parametrize('command', [sweep_runner.main, sweep_runner.compare_main])
def test_the_help_says_95_percent_once(command, capsys):
    with pytest.raises(SystemExit) as exit_info:
        command(['--help'])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    assert '95 % intervals' in ' '.join(text.split()) and '%%' not in text
