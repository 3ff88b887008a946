"""
Shrink a failing variant: the simplest variant that still fails the same way (pure).

From a failing variant's axis values, :func:`shrink` tries simpler variants one at a
time and keeps each that still fails (:func:`same_failure`): an axis dropped (the
scenario's own value: its seed, world, spawn, person and floor; no fault), a number
moved halfway toward its nominal value (sensor_noise_scale 1, floor_friction_coefficient
the scenario's, or the robot's wheel friction when the scenario keeps its own), and one
goal step dropped (the goals axis, also for a sweep without it: a failure with fewer
goals is easier to look at). It starts again from each kept one until none of its
simplifications still fails, or the budget of runs is spent; greedy, as delta debugging
and property-based testing's shrinkers are, so the result is a local minimum, not the
least of all.

A variant's size (:func:`size`) is its axes not at their nominal value plus its goal
steps: every simplification is smaller. Runs are the caller's (``run(values)`` returns
the row of the variant run with those values), so this module runs nothing itself.
"""

from dataclasses import dataclass, field
import math
import re
from typing import Any, Callable, Dict, List, Optional, Sequence, Set, Tuple

from mecanum_bringup.sweep_store import VariantRow

#: The nominal value of each numeric axis (None: the scenario's own, see nominal_values).
NUMERIC_AXES = ('floor_friction_coefficient', 'sensor_noise_scale')
#: A number within this of its nominal value is not moved closer.
CLOSE_ENOUGH = 0.02
#: The axes that go together: dropping the fault drops its onset.
TOGETHER = {'fault': ('fault', 'fault_onset_s')}
_STEP = re.compile(r'step \d+')


@dataclass
class Attempt:
    """One simplification tried: what changed, its values, its row, whether it was kept."""

    change: str
    values: Dict[str, Any]
    row: Optional[VariantRow]
    kept: bool


@dataclass
class Shrunk:
    """A shrink's outcome: the smallest failing values found and every attempt, in order."""

    original: Dict[str, Any]
    values: Dict[str, Any]
    attempts: List[Attempt] = field(default_factory=list)
    budget_spent: bool = False

    @property
    def runs(self) -> int:
        """Return the variants run (every attempt is one run)."""
        return len(self.attempts)


def failure_signature(row: VariantRow) -> Set[str]:
    """Return the failed lines of a row, every step as 'step' (dropping goals renumbers)."""
    return {'step' if _STEP.fullmatch(name) else name
            for name, passed in row.criteria.items() if not passed}


def same_failure(original: VariantRow, row: Optional[VariantRow]) -> bool:
    """
    Tell whether a row fails as the original did: UNEXPECTED, with its first failure.

    The original's first failed line (by kind: any step for a step) must fail again;
    a run that could not be judged (ERROR, or no row) does not count.
    """
    if row is None or row.status != 'UNEXPECTED':
        return False
    first = next((name for name, passed in original.criteria.items() if not passed), None)
    if first is None:
        return bool(failure_signature(row))
    kind = 'step' if _STEP.fullmatch(first) else first
    return kind in failure_signature(row)


def size(values: Dict[str, Any], nominal: Dict[str, Any], goal_count: int) -> int:
    """Return the axes of values away from nominal, plus the goal steps kept."""
    away = sum(1 for axis, value in values.items()
               if axis != 'goals' and value != nominal.get(axis, _ABSENT))
    goals = len(values['goals']) if 'goals' in values else goal_count
    return away + goals


_ABSENT = object()


def simplifications(values: Dict[str, Any], nominal: Dict[str, Any],
                    goal_count: int) -> List[Tuple[str, Dict[str, Any]]]:
    """
    Return (change, values) for each one-step simplification of values, boldest first.

    Drops first (an axis gone: the scenario's own value), then numbers halfway toward
    nominal, then one goal step fewer (never none). goal_count: the scenario's goal
    steps (with every goal kept when values has no goals axis).
    """
    found: List[Tuple[str, Dict[str, Any]]] = []
    for axis in values:
        if axis in ('scenario', 'goals', 'fault_onset_s'):
            continue
        if axis in NUMERIC_AXES and values[axis] == nominal.get(axis):
            continue
        gone = TOGETHER.get(axis, (axis,))
        rest = {key: value for key, value in values.items() if key not in gone}
        found.append((f'{axis}: dropped', rest))
    for axis in NUMERIC_AXES:
        value, target = values.get(axis), nominal.get(axis)
        if isinstance(value, (int, float)) and isinstance(target, (int, float)) \
                and abs(value - target) > CLOSE_ENOUGH:
            halfway = round((value + target) / 2.0, 4)
            found.append((f'{axis}: {value:g} -> {halfway:g}', dict(values, **{axis: halfway})))
    kept = list(values['goals']) if 'goals' in values else list(range(goal_count))
    if len(kept) > 1:
        for goal in kept:
            fewer = [index for index in kept if index != goal]
            found.append((f'goals: goal {goal} dropped', dict(values, goals=fewer)))
    return found


def nominal_values(scenario_document: Dict[str, Any],
                   wheel_friction_coefficient: float) -> Dict[str, Any]:
    """
    Return the nominal value of each numeric axis for a variant of a scenario document.

    floor_friction_coefficient: the scenario's or, when it keeps the robot's own (0),
    wheel_friction_coefficient; sensor_noise_scale: the scenario's (1 by default).
    """
    document = scenario_document['scenario']
    friction = float(document.get('floor_friction_coefficient', 0.0) or 0.0)
    return {'floor_friction_coefficient': friction if friction > 0.0
            else float(wheel_friction_coefficient),
            'sensor_noise_scale': float(document.get('sensor_noise_scale', 1.0))}


def shrink(original: VariantRow, nominal: Dict[str, Any], goal_count: int,
           run: Callable[[Dict[str, Any]], Optional[VariantRow]],
           budget: int = 30) -> Shrunk:
    """
    Shrink original's values while run(values) fails the same way; at most budget runs.

    Greedy: the first simplification that still fails is kept and the search starts
    again from it; it ends when none does (a local minimum) or the budget is spent.
    """
    result = Shrunk(dict(original.values), dict(original.values))
    tried: Set[str] = set()
    while True:
        kept = False
        for change, values in simplifications(result.values, nominal, goal_count):
            key = repr(sorted(values.items(), key=lambda item: item[0]))
            smaller = size(values, nominal, goal_count) < size(result.values, nominal,
                                                               goal_count)
            if key in tried or not (smaller or _closer(values, result.values, nominal)):
                continue
            if result.runs >= budget:
                result.budget_spent = True
                return result
            tried.add(key)
            row = run(values)
            still = same_failure(original, row)
            result.attempts.append(Attempt(change, values, row, still))
            if still:
                result.values = values
                kept = True
                break
        if not kept:
            return result


def _closer(values: Dict[str, Any], before: Dict[str, Any], nominal: Dict[str, Any]) -> bool:
    """Tell whether values has a number nearer its nominal than before (a halfway move)."""
    for axis in NUMERIC_AXES:
        new, old, target = values.get(axis), before.get(axis), nominal.get(axis)
        if all(isinstance(v, (int, float)) for v in (new, old, target)) \
                and abs(new - target) < abs(old - target) - 1e-12:
            return True
    return False


def describe(values: Dict[str, Any]) -> str:
    """Return values as 'axis=value ...' ('(every axis nominal)' when empty)."""
    if not values:
        return '(every axis nominal)'
    return ' '.join(f'{axis}={_text(value)}' for axis, value in values.items())


def _text(value: Any) -> str:
    if isinstance(value, float) and math.isfinite(value):
        return f'{value:g}'
    return str(value).replace(' ', '')


def changes(result: Shrunk) -> Sequence[str]:
    """Return the kept changes, in order."""
    return [attempt.change for attempt in result.attempts if attempt.kept]
