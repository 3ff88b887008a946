"""
The judging of scenario runs: the verdict of a run from what the runner recorded (pure).

:func:`judge` turns a :class:`~mecanum_bringup.scenario_model.RunRecord` (what the
runner recorded) into a :class:`~mecanum_bringup.scenario_model.Verdict`: one
:class:`~mecanum_bringup.scenario_model.CriterionResult` per step (``step 1`` is
``steps[0]``) and per enabled criterion; the verdict is 'pass' when every one passed.
Tracks are (N, 4) arrays of t, x, y, yaw in the map frame (simulated s, m, rad).
"""

import math
from typing import Any, List, Optional

from mecanum_bringup.scenario_model import (
    CommandStep, CriterionResult, ERROR_NAMES, GoalStep, RunRecord, Scenario, Step,
    StepResult, Verdict, WaypointsStep)
from mecanum_safety.zone import Zone
import numpy as np


def track_array(values: Any, name: str = 'track') -> np.ndarray:
    """
    Return values as a float (N, 4) array of t, x, y, yaw sorted by t, finite rows only.

    Raises ValueError naming `name` when the shape is not (N, 4).
    """
    array = np.asarray(values, dtype=np.float64)
    if array.size == 0:
        return np.zeros((0, 4))
    if array.ndim != 2 or array.shape[1] != 4:
        raise ValueError(f'{name} must be an (N, 4) array of t, x, y, yaw, not shape '
                         f'{array.shape}')
    array = array[np.all(np.isfinite(array), axis=1)]
    return array[np.argsort(array[:, 0], kind='stable')]


def localization_errors(truth: Any, estimate: Any) -> np.ndarray:
    """
    Return a (K, 2) array of t, |estimate - truth| (m, x and y only) at each estimate time.

    The truth is interpolated linearly at the estimate times; estimates outside the
    truth's time span are left out.
    """
    truth = track_array(truth, 'truth')
    estimate = track_array(estimate, 'estimate')
    if len(truth) == 0 or len(estimate) == 0:
        return np.zeros((0, 2))
    inside = (estimate[:, 0] >= truth[0, 0]) & (estimate[:, 0] <= truth[-1, 0])
    estimate = estimate[inside]
    true_x = np.interp(estimate[:, 0], truth[:, 0], truth[:, 1])
    true_y = np.interp(estimate[:, 0], truth[:, 0], truth[:, 2])
    errors = np.hypot(estimate[:, 1] - true_x, estimate[:, 2] - true_y)
    return np.column_stack([estimate[:, 0], errors])


def distance_travelled_m(truth: Any) -> float:
    """Return the length in metres of the (t, x, y, yaw) track's x, y polyline."""
    truth = track_array(truth, 'truth')
    if len(truth) < 2:
        return 0.0
    return float(np.sum(np.hypot(np.diff(truth[:, 1]), np.diff(truth[:, 2]))))


def error_label(code: int) -> str:
    """Return e.g. 'GOAL_OUTSIDE_ZONE (9100)' for a NavigateToPose result code."""
    name = ERROR_NAMES.get(int(code))
    return f'{name} ({code})' if name else f'error {code}'


def judge(scenario: Scenario, record: RunRecord) -> Verdict:
    """Judge a run: one CriterionResult per step and per enabled criterion."""
    results: List[CriterionResult] = []
    for index, step in enumerate(scenario.steps):
        result = record.step_results[index] if index < len(record.step_results) else None
        results.append(_judge_step(index + 1, step, result, record.aborted))
    results.append(_judge_completion(scenario, record))
    criteria = scenario.criteria
    if criteria.max_duration_s is not None:
        duration = float(record.duration_s)
        passed = math.isfinite(duration) and duration <= criteria.max_duration_s
        sign = '<=' if passed else '>'
        results.append(CriterionResult(
            'max_duration_s', passed,
            f'max_duration_s: {duration:.1f} s {sign} {criteria.max_duration_s:g} s'))
    if criteria.no_collision:
        times = sorted(float(t) for t in record.collision_times)
        detail = f'no_collision: {len(times)} collision{"" if len(times) == 1 else "s"}'
        if times:
            detail += f', first at t={times[0]:.1f} s'
        results.append(CriterionResult('no_collision', not times, detail))
    if criteria.stay_in_zone:
        results.append(_judge_zone(scenario.authorised_zone, record.truth))
    if criteria.max_localization_error_m is not None:
        results.append(_judge_localization(criteria.max_localization_error_m, record))
    verdict = 'pass' if all(r.passed for r in results) else 'fail'
    return Verdict(scenario.name, scenario.expect, verdict, tuple(results))


def _judge_step(number: int, step: Step, result: Optional[StepResult],
                aborted: Optional[str]) -> CriterionResult:
    name = f'step {number}'
    head = f'{name} {step.describe()}'
    if result is None:
        why = f'run aborted: {aborted}' if aborted else 'no result recorded'
        return CriterionResult(name, False, f'{head}: not run ({why})')
    if result.kind != step.kind:
        return CriterionResult(name, False, f'{head}: the result recorded is for a '
                               f'{result.kind} step')
    outcome = result.outcome
    took = f' in {result.duration_s:.1f} s' if math.isfinite(result.duration_s) else ''
    if isinstance(step, GoalStep):
        return _judge_goal(name, head, step, result, took)
    expected = (step.expect if isinstance(step, CommandStep)
                else 'reached' if isinstance(step, WaypointsStep) else 'done')
    passed = expected == 'any' or outcome == expected
    detail = f'{head}: {outcome}{took}'
    if result.error_message:
        detail += f': {result.error_message}'
    return CriterionResult(name, passed,
                           detail if passed else detail + f' (expected {expected})')


def _judge_goal(name: str, head: str, step: GoalStep, result: StepResult,
                took: str) -> CriterionResult:
    outcome, code = result.outcome, int(result.error_code)
    said = f': {result.error_message}' if result.error_message else ''
    if outcome in ('refused', 'failed') and code:
        what = f'{outcome} with {error_label(code)}{said}'
    elif outcome == 'timeout':
        what = f'timeout after {result.duration_s:.1f} s'
    else:
        what = f'{outcome}{took}' + (f' ({error_label(code)}{said})' if code else '')
    if step.expect == 'any':
        return CriterionResult(name, True, f'{head}: {what} (any outcome accepted)')
    if step.expect == 'reached':
        passed = outcome == 'reached' and code == 0
        return CriterionResult(name, passed,
                               f'{head}: {what}' + ('' if passed else ' (expected reached)'))
    wanted = step.error_code
    refused = outcome in ('refused', 'failed') and code != 0
    passed = refused and (wanted is None or code == wanted)
    expected = 'refused' + (f' with {error_label(wanted)}' if wanted is not None else '')
    if passed:
        return CriterionResult(name, True, f'{head}: {what}, as expected')
    return CriterionResult(name, False, f'{head}: {what} (expected {expected})')


def _judge_completion(scenario: Scenario, record: RunRecord) -> CriterionResult:
    total = len(scenario.steps)
    done = min(len(record.step_results), total)
    if record.aborted:
        return CriterionResult('completed', False, f'completed: aborted after {done} of {total} '
                               f'steps: {record.aborted}')
    if done < total:
        return CriterionResult('completed', False,
                               f'completed: only {done} of {total} steps have a result')
    return CriterionResult('completed', True, f'completed: all {total} steps run in '
                           f'{float(record.duration_s):.1f} s')


def _judge_zone(zone: Optional[Zone], truth: Any) -> CriterionResult:
    if zone is None:
        return CriterionResult('stay_in_zone', True, 'stay_in_zone: no zone declared')
    track = track_array(truth, 'truth')
    if len(track) == 0:
        return CriterionResult('stay_in_zone', False, 'stay_in_zone: no ground truth recorded')
    inside = zone.contains(track[:, 1], track[:, 2])
    if np.all(inside):
        return CriterionResult('stay_in_zone', True,
                               f'stay_in_zone: inside at all {len(track)} true poses')
    t, x, y, _ = track[int(np.argmin(inside))]
    return CriterionResult('stay_in_zone', False,
                           f'stay_in_zone: left the zone at t={t:.1f} s ({x:.2f}, {y:.2f})')


def _judge_localization(limit_m: float, record: RunRecord) -> CriterionResult:
    errors = localization_errors(record.truth, record.estimate)
    if len(errors) == 0:
        return CriterionResult('max_localization_error_m', False,
                               'max_localization_error_m: no estimate within the ground '
                               "truth's time span")
    worst = int(np.argmax(errors[:, 1]))
    t, error = errors[worst]
    if error <= limit_m:
        return CriterionResult('max_localization_error_m', True,
                               f'max_localization_error_m: {error:.2f} m <= {limit_m:g} m '
                               f'({len(errors)} estimates)')
    return CriterionResult('max_localization_error_m', False,
                           f'max_localization_error_m: {error:.2f} m at t={t:.1f} s > '
                           f'{limit_m:g} m')
