"""
The judging of scenario runs: the verdict of a run from what the runner recorded (pure).

:func:`judge` turns a :class:`~mecanum_bringup.scenario_model.RunRecord` (what the
runner recorded) into a :class:`~mecanum_bringup.scenario_model.Verdict`: one
:class:`~mecanum_bringup.scenario_model.CriterionResult` per step (``step 1`` is
``steps[0]``) and per enabled criterion; the verdict is 'pass' when every one passed.
Tracks are (N, 4) arrays of t, x, y, yaw in the map frame (simulated s, m, rad).

``stay_in_zone`` judges the robot's footprint, a circle of ``footprint_radius_m``
(motor_params.yaml, :mod:`mecanum_control.robot_config`) about each true pose: its
clearance is the signed distance from the centre to the zone's border (positive inside,
:meth:`mecanum_safety.zone.Zone.clearance`) minus the radius, and the criterion fails when
it is below 0 at any recorded pose (no tolerance). Its line is a :class:`ZoneResult`,
which carries the least clearance and where it was (:func:`min_zone_clearance_m`). Only
the recorded poses are judged (ground truth at 50 Hz): between two of them the robot
moves at most L = v * dt (16 mm at 0.8 m/s), so it can have been at most L / 2 deeper
than the two poses show.

Each line also carries a margin (CriterionResult.margin: positive when it passed, <= 0
when it failed, None where there is no measure), for the search of failures and the
reports: a step's time left before its timeout_s (s; a step that timed out: how late,
<= 0); max_duration_s's limit less the duration (s); no_collision's least footprint
clearance to any obstacle (m: :func:`obstacle_clearances`: static ones of the scenario's
world and the walking people as recorded, a collision making it <= 0); stay_in_zone's
least footprint clearance to the zone's border (m); max_localization_error_m's limit less
the largest error (m). 'completed' and 'fault_reaction' have none.
"""

from dataclasses import dataclass, replace
import functools
import math
from typing import Any, List, Optional, Tuple

from mecanum_bringup.fault_reactions import judge_reaction
from mecanum_bringup.scenario_model import (
    CommandStep, CriterionResult, ERROR_NAMES, GoalStep, RunRecord, Scenario, Step,
    StepResult, Verdict, WaypointsStep)
from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_safety.zone import Zone
import numpy as np
from robot_simulation.world import World


@dataclass(frozen=True)
class ZoneResult(CriterionResult):
    """
    The stay_in_zone line of a verdict, with its least footprint clearance.

    min_clearance_m: the least clearance (m; < 0: the footprint was out of the zone) over
    the true poses, first reached at t_s (simulated s) at (x_m, y_m) (map frame);
    footprint_radius_m: the radius judged. All None when nothing was measured (no zone
    declared, no ground truth).
    """

    min_clearance_m: Optional[float] = None
    t_s: Optional[float] = None
    x_m: Optional[float] = None
    y_m: Optional[float] = None
    footprint_radius_m: Optional[float] = None


@functools.lru_cache(maxsize=1)
def robot_footprint_radius_m() -> float:
    """Return the robot's footprint_radius_m (m) from motor_params.yaml (read once)."""
    return load_robot_config(default_config_path()).footprint_radius_m


def footprint_clearances(zone: Zone, truth: Any, footprint_radius_m: float) -> np.ndarray:
    """
    Return the footprint's clearance (m) to zone's border at each pose of a track.

    truth: (N, 4) t, x, y, yaw (as track_array: sorted by t, finite rows only). The
    clearance is the signed distance of (x, y) to the border (positive inside) minus
    footprint_radius_m: >= 0 exactly when the footprint circle is inside the zone.
    """
    track = track_array(truth, 'truth')
    return zone.clearance(track[:, 1], track[:, 2]) - float(footprint_radius_m)


def min_zone_clearance_m(verdict: Verdict) -> Optional[float]:
    """Return the least footprint clearance (m) of a verdict's stay_in_zone, or None."""
    line = zone_result(verdict)
    return None if line is None else line.min_clearance_m


def zone_result(verdict: Verdict) -> Optional[ZoneResult]:
    """Return the verdict's stay_in_zone line (None: the criterion was not judged)."""
    return next((c for c in verdict.criteria if isinstance(c, ZoneResult)), None)


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


#: The unit of each criterion's margin ('step N': 's').
MARGIN_UNITS = {'max_duration_s': 's', 'no_collision': 'm', 'stay_in_zone': 'm',
                'max_localization_error_m': 'm'}


def margin_unit(criterion: str) -> str:
    """Return the unit of a criterion's margin: 's', 'm', or '' (it has none)."""
    if criterion.startswith('step '):
        return 's'
    return MARGIN_UNITS.get(criterion, '')


#: Poses judged at once by obstacle_clearances (a chunk x segments array of distances).
_CLEARANCE_CHUNK = 256


def obstacle_clearances(world: World, truth: Any, footprint_radius_m: float,
                        movers: Any = None) -> np.ndarray:
    """
    Return the footprint's clearance (m) to the nearest obstacle at each pose of a track.

    truth: (N, 4) t, x, y, yaw (as track_array). The clearance is the distance from the
    centre to the nearest static edge (walls, furniture, map cell outlines, the world's
    bounds) or circle, or walking person's disc, minus footprint_radius_m: 0 where the
    footprint touches (the simulator's collision), as the simulator's physics sees the
    robot (a circle). movers: (M, 4) t, k, x, y, the people's recorded centres (k: index
    in world.moving_obstacles, whose radius_m is used), interpolated at the truth's
    times within each one's recorded span. Static distances are to the obstacles'
    boundaries, so a centre inside an obstacle (never in a run: the physics pushes out)
    would read as outside. :func:`nearest_obstacles` also names each one.
    """
    return nearest_obstacles(world, truth, footprint_radius_m, movers)[0]


def nearest_obstacles(world: World, truth: Any, footprint_radius_m: float,
                      movers: Any = None) -> Tuple[np.ndarray, List[str]]:
    """Return obstacle_clearances' array and the name of the obstacle nearest each pose."""
    track = track_array(truth, 'truth')
    if len(track) == 0:
        return np.zeros(0), []
    xs, ys = track[:, 1], track[:, 2]
    names = list(world.segment_names) + [circle.name for circle in world.circles] + [
        mover.name for mover in world.moving_obstacles]
    nearest = np.full(len(track), np.inf)
    which = np.full(len(track), -1, dtype=np.intp)

    def take(distances: np.ndarray, index: Any, where: Any = slice(None)) -> None:
        closer = distances < nearest[where]
        nearest[where] = np.where(closer, distances, nearest[where])
        which[where] = np.where(closer, index, which[where])

    segments = np.asarray(world.segments, dtype=np.float64).reshape(-1, 4)
    if len(segments):
        x1, y1, x2, y2 = (segments[:, i][np.newaxis, :] for i in range(4))
        dx, dy = x2 - x1, y2 - y1
        length2 = np.maximum(dx * dx + dy * dy, 1e-18)
        for start in range(0, len(track), _CLEARANCE_CHUNK):
            chunk = slice(start, start + _CLEARANCE_CHUNK)
            px, py = xs[chunk, np.newaxis], ys[chunk, np.newaxis]
            u = np.clip(((px - x1) * dx + (py - y1) * dy) / length2, 0.0, 1.0)
            distances = np.hypot(px - (x1 + u * dx), py - (y1 + u * dy))
            take(distances.min(axis=1), distances.argmin(axis=1), chunk)
    offset = len(segments)
    for number, circle in enumerate(world.circles):
        cx, cy = circle.center
        take(np.abs(np.hypot(xs - cx, ys - cy) - circle.radius_m), offset + number)
    offset += len(world.circles)
    recorded = np.asarray(movers if movers is not None else np.zeros((0, 4)),
                          dtype=np.float64).reshape(-1, 4)
    for number, mover in enumerate(world.moving_obstacles):
        rows = recorded[recorded[:, 1] == number]
        rows = rows[np.argsort(rows[:, 0], kind='stable')]
        if len(rows) == 0:
            continue
        inside = np.nonzero((track[:, 0] >= rows[0, 0]) & (track[:, 0] <= rows[-1, 0]))[0]
        mx = np.interp(track[inside, 0], rows[:, 0], rows[:, 2])
        my = np.interp(track[inside, 0], rows[:, 0], rows[:, 3])
        take(np.hypot(xs[inside] - mx, ys[inside] - my) - mover.radius_m, offset + number,
             inside)
    return nearest - float(footprint_radius_m), [names[i] if i >= 0 else '' for i in which]


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


def judge(scenario: Scenario, record: RunRecord,
          footprint_radius_m: Optional[float] = None) -> Verdict:
    """
    Judge a run: one CriterionResult per step and per enabled criterion.

    footprint_radius_m (m) is the radius stay_in_zone judges; None: the robot's, from
    motor_params.yaml. ValueError unless it is finite and >= 0.
    """
    radius_m = robot_footprint_radius_m() if footprint_radius_m is None \
        else float(footprint_radius_m)
    if not (math.isfinite(radius_m) and radius_m >= 0.0):
        raise ValueError(f'judge: footprint_radius_m must be finite and >= 0, got '
                         f'{footprint_radius_m!r}')
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
            f'max_duration_s: {duration:.1f} s {sign} {criteria.max_duration_s:g} s',
            _signed(criteria.max_duration_s - duration, passed), 's'))
    if criteria.no_collision:
        results.append(_judge_collisions(scenario.world, record, radius_m))
    if criteria.stay_in_zone:
        results.append(_judge_zone(scenario.authorised_zone, record.truth, radius_m))
    if criteria.max_localization_error_m is not None:
        results.append(_judge_localization(criteria.max_localization_error_m, record))
    if criteria.fault_reactions:
        results.append(_judge_fault_reactions(scenario, record))
    verdict = 'pass' if all(r.passed for r in results) else 'fail'
    return Verdict(scenario.name, scenario.expect, verdict, tuple(results))


def _signed(margin: float, passed: bool) -> Optional[float]:
    """Return margin as a criterion's: None unless finite; <= 0 when it failed."""
    if not math.isfinite(margin):
        return None
    return margin if passed else min(margin, 0.0)


def _judge_collisions(world: Optional[World], record: RunRecord,
                      radius_m: float) -> CriterionResult:
    name = 'no_collision'
    times = sorted(float(t) for t in record.collision_times)
    detail = f'{name}: {len(times)} collision{"" if len(times) == 1 else "s"}'
    if times:
        detail += f', first at t={times[0]:.1f} s'
    passed = not times
    track = track_array(record.truth, 'truth')
    if world is None or len(track) == 0:
        return CriterionResult(name, passed, detail)
    clearances, names = nearest_obstacles(world, track, radius_m, record.movers)
    least = int(np.argmin(np.round(clearances, 9)))
    clearance = float(clearances[least])
    detail += (f'; least footprint clearance {clearance:.3f} m to {names[least]} at '
               f't={track[least, 0]:.1f} s ({track[least, 1]:.2f}, {track[least, 2]:.2f})')
    return CriterionResult(name, passed, detail, _signed(clearance, passed), 'm')


def _step_margin(step: Step, result: StepResult, passed: bool) -> Optional[float]:
    """Return a step's time left before its timeout_s (s); one that timed out: <= 0."""
    timeout_s = getattr(step, 'timeout_s', None)
    if timeout_s is None or not (passed or result.outcome == 'timeout'):
        return None
    return _signed(float(timeout_s) - result.duration_s, passed)


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
        line = _judge_goal(name, head, step, result, took)
        return replace(line, margin=_step_margin(step, result, line.passed), margin_unit='s')
    expected = (step.expect if isinstance(step, CommandStep)
                else 'reached' if isinstance(step, WaypointsStep) else 'done')
    passed = expected == 'any' or outcome == expected
    detail = f'{head}: {outcome}{took}'
    if result.error_message:
        detail += f': {result.error_message}'
    margin = _step_margin(step, result, passed)
    return CriterionResult(name, passed,
                           detail if passed else detail + f' (expected {expected})',
                           margin, 's' if margin is not None else '')


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


def _judge_zone(zone: Optional[Zone], truth: Any, radius_m: float) -> ZoneResult:
    name = 'stay_in_zone'
    if zone is None:
        return ZoneResult(name, True, f'{name}: no zone declared')
    track = track_array(truth, 'truth')
    if len(track) == 0:
        return ZoneResult(name, False, f'{name}: no ground truth recorded')
    clearances = footprint_clearances(zone, track, radius_m)
    # The first pose within a nanometre of the least: ties go to the earliest.
    least = int(np.argmin(np.round(clearances, 9)))
    clearance = float(clearances[least])
    t, x, y, _ = (float(value) for value in track[least])
    passed = clearance >= 0.0
    detail = (f'{name}: least clearance {clearance:.3f} m at t={t:.1f} s ({x:.2f}, {y:.2f}): '
              f'the footprint (radius {radius_m:.2f} m) ')
    if passed:
        detail += f'stayed inside at all {len(track)} true poses'
    else:
        detail += 'left the zone'
        first = int(np.argmax(clearances < 0.0))
        if first != least:
            detail += f', first at t={track[first, 0]:.1f} s ({track[first, 1]:.2f}, ' \
                      f'{track[first, 2]:.2f})'
    return ZoneResult(name, passed, detail, margin=clearance, margin_unit='m',
                      min_clearance_m=clearance, t_s=t, x_m=x, y_m=y,
                      footprint_radius_m=radius_m)


def _judge_fault_reactions(scenario: Scenario, record: RunRecord) -> CriterionResult:
    name = 'fault_reaction'
    if not record.faults:
        return CriterionResult(name, True, f'{name}: no fault injected')
    goals = [result.outcome == 'reached' for step, result in
             zip(scenario.steps, record.step_results)
             if isinstance(step, (GoalStep, WaypointsStep))]
    if len(record.step_results) < len(scenario.steps) and any(
            isinstance(step, (GoalStep, WaypointsStep)) for step in scenario.steps):
        goals.append(False)     # a goal step that never ran was not reached
    reached = all(goals) if goals else None
    judged = [judge_reaction(fault, record.truth, record.chain_states, reached)
              for fault in record.faults]
    return CriterionResult(name, all(r.passed for r in judged),
                           f'{name}: ' + '; '.join(r.detail for r in judged))


def _judge_localization(limit_m: float, record: RunRecord) -> CriterionResult:
    errors = localization_errors(record.truth, record.estimate)
    if len(errors) == 0:
        return CriterionResult('max_localization_error_m', False,
                               'max_localization_error_m: no estimate within the ground '
                               "truth's time span")
    worst = int(np.argmax(errors[:, 1]))
    t, error = errors[worst]
    passed = bool(error <= limit_m)
    margin = _signed(limit_m - float(error), passed)
    if passed:
        return CriterionResult('max_localization_error_m', True,
                               f'max_localization_error_m: {error:.2f} m <= {limit_m:g} m '
                               f'({len(errors)} estimates)', margin, 'm')
    return CriterionResult('max_localization_error_m', False,
                           f'max_localization_error_m: {error:.2f} m at t={t:.1f} s > '
                           f'{limit_m:g} m', margin, 'm')
