"""Tests of shrinking a failing variant (pure: the simplifications and the greedy walk)."""

from mecanum_bringup.sweep_shrink import (
    changes, describe, same_failure, shrink, simplifications, size)
from mecanum_bringup.sweep_store import VariantRow

NOMINAL = {'floor_friction_coefficient': 0.6, 'sensor_noise_scale': 1.0}
FAULT = {'kind': 'lidar_blinded', 'duration_s': 5.0}


def row(status, **criteria):
    verdict = {'OK': 'pass', 'UNEXPECTED': 'fail', 'ERROR': None}[status]
    return VariantRow(0, 's_0000', {}, status, verdict, 'pass',
                      {name.replace('_', ' ') if name.startswith('step_') else name: passed
                       for name, passed in criteria.items()})


def test_the_simplifications_of_a_variant_boldest_first():
    values = {'seed': 5, 'floor_friction_coefficient': 0.3, 'goals': [0, 2], 'fault': FAULT,
              'fault_onset_s': 5.0}
    found = simplifications(values, NOMINAL, goal_count=3)
    assert [change for change, _ in found] == [
        'seed: dropped', 'floor_friction_coefficient: dropped', 'fault: dropped',
        'floor_friction_coefficient: 0.3 -> 0.45', 'goals: goal 0 dropped',
        'goals: goal 2 dropped']
    by_change = dict(found)
    # The fault goes with its onset; the other axes stay.
    assert by_change['fault: dropped'] == {'seed': 5, 'floor_friction_coefficient': 0.3,
                                           'goals': [0, 2]}
    assert by_change['goals: goal 0 dropped']['goals'] == [2]
    # Without a goals axis every goal is kept: one fewer each.
    assert [change for change, _ in simplifications({}, NOMINAL, 3)] == [
        'goals: goal 0 dropped', 'goals: goal 1 dropped', 'goals: goal 2 dropped']
    # One goal left, numbers at nominal: nothing simpler.
    assert simplifications({'goals': [1], 'sensor_noise_scale': 1.0}, NOMINAL, 3) == []
    assert size(values, NOMINAL, 3) == 4 + 2          # seed, friction, fault, onset + 2 goals


def test_the_same_failure_is_the_first_failed_line_again_steps_by_kind():
    original = row('UNEXPECTED', step_1=True, step_3=False, no_collision=True)
    # Goal steps dropped renumber the steps: a step failing is the same kind of failure.
    assert same_failure(original, row('UNEXPECTED', step_2=False, no_collision=True))
    assert not same_failure(original, row('UNEXPECTED', step_1=True, no_collision=False))
    assert not same_failure(original, row('OK', step_1=True))
    assert not same_failure(original, row('ERROR'))
    assert not same_failure(original, None)


def test_a_greedy_shrink_keeps_each_simpler_variant_that_still_fails():
    # The planted failure: friction below 0.5 with goal 2 kept (step 2 then fails).
    def run(values):
        goals = values.get('goals', [0, 1, 2])
        fails = values.get('floor_friction_coefficient', 0.6) < 0.5 and 2 in goals
        return row('UNEXPECTED' if fails else 'OK', step_1=True, step_2=not fails)

    original = VariantRow(4, 's_0004', {'seed': 5, 'floor_friction_coefficient': 0.3,
                                        'goals': [0, 2]}, 'UNEXPECTED', 'fail', 'pass',
                          {'step 1': True, 'step 2': False})
    result = shrink(original, NOMINAL, 3, run)
    assert result.values == {'floor_friction_coefficient': 0.45, 'goals': [2]}
    assert changes(result) == ['seed: dropped', 'floor_friction_coefficient: 0.3 -> 0.45',
                               'goals: goal 0 dropped']
    # Worked out: 3 kept, and each dead end run once: the friction dropped with goals
    # [0, 2] (the same variant from 0.3 and from 0.45: run once) and with [2], and moved
    # to 0.525 with each.
    assert result.runs == 7 and not result.budget_spent
    assert describe(result.values) == 'floor_friction_coefficient=0.45 goals=[2]'
    spent = shrink(original, NOMINAL, 3, run, budget=3)
    assert spent.runs == 3 and spent.budget_spent
    assert spent.values == {'floor_friction_coefficient': 0.45, 'goals': [0, 2]}
