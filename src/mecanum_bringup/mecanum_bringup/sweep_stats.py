"""
Statistics of a sweep: failure rates with Wilson intervals, per axis, and A/B compare (pure).

Inputs are the :class:`mecanum_bringup.sweep_store.VariantRow` s of a results store.
A variant fails when its status is not 'OK' (the verdict was not the expected one, or
the run could not be judged: an ERROR row counts as a failure). A criterion ('step 1',
'no_collision', ...) fails in a variant when the row's ``criteria`` maps it to False; its
n counts only the variants in which it was judged.

Every rate comes with its Wilson score interval (95 %), which stays inside [0, 1] and
is sensible for 0 or n failures and for small n, unlike the normal approximation.

The least zone clearance (a row's ``min_zone_clearance_m``: the footprint's least
clearance to the authorised zone's border, m, < 0 out of it) is summarised over all rows
and per value of each axis, in the same groups as the failure rates. Any axis works the
same way; an axis whose values are mappings with a ``kind`` (faults) is also summarised
per kind, as the axis ``AXIS.kind`` (:func:`summary_axes`).
"""

from dataclasses import dataclass
import json
import math
import re
from typing import Any, Dict, List, Optional, Sequence, Tuple

from mecanum_bringup.sweep_store import VariantRow

#: The normal quantile of a two-sided 95 % interval.
Z_95 = 1.959964
#: A numeric axis with more distinct values than this is binned.
MAX_DISTINCT_VALUES = 8
#: The number of equal-width bins of a binned numeric axis.
BINS = 5
#: The name of the overall rate (a variant's status is not 'OK').
VERDICT = 'verdict'
#: The key of a mapping value (a fault) that names its kind: 'AXIS.kind' groups by it.
KIND = 'kind'
_STEP = re.compile(r'step (\d+)')
_MISSING = object()


def wilson_interval(failures: int, n: int, z: float = Z_95) -> Tuple[float, float]:
    """
    Return the Wilson score interval (low, high) of the failure rate failures / n.

    With p = failures / n: centre = (p + z²/2n) / (1 + z²/n) and half width =
    z * sqrt(p(1 - p)/n + z²/4n²) / (1 + z²/n); z = 1.959964 gives 95 %. n = 0 gives
    (0.0, 1.0) (nothing known). Raise ValueError unless 0 <= failures <= n.
    """
    if n < 0 or failures < 0 or failures > n:
        raise ValueError(f'wilson_interval: need 0 <= failures <= n, got {failures}/{n}')
    if n == 0:
        return 0.0, 1.0
    p = failures / n
    z2 = z * z
    denominator = 1.0 + z2 / n
    centre = (p + z2 / (2.0 * n)) / denominator
    half = z * math.sqrt(p * (1.0 - p) / n + z2 / (4.0 * n * n)) / denominator
    # Exactly 0 and 1 at the ends (the formula gives them up to rounding).
    low = 0.0 if failures == 0 else max(0.0, centre - half)
    high = 1.0 if failures == n else min(1.0, centre + half)
    return low, high


@dataclass(frozen=True)
class Rate:
    """A failure count out of n runs (errors: how many of the failures were ERROR runs)."""

    name: str
    failures: int
    n: int
    errors: int = 0

    @property
    def rate(self) -> float:
        """Return failures / n (0.0 when n = 0)."""
        return self.failures / self.n if self.n else 0.0

    @property
    def low(self) -> float:
        """Return the low end of the Wilson 95 % interval."""
        return wilson_interval(self.failures, self.n)[0]

    @property
    def high(self) -> float:
        """Return the high end of the Wilson 95 % interval."""
        return wilson_interval(self.failures, self.n)[1]

    def describe(self) -> str:
        """Return e.g. '3/50 failed (6.0 %, 95 % CI 2.1-16.2 %)'."""
        if not self.n:
            return '0/0 failed (no runs)'
        text = (f'{self.failures}/{self.n} failed ({100 * self.rate:.1f} %, 95 % CI '
                f'{100 * self.low:.1f}-{100 * self.high:.1f} %)')
        if self.errors:
            text += f', {self.errors} of them not judged (ERROR)'
        return text


@dataclass(frozen=True)
class Change:
    """One rate in sweep A and in sweep B; verdict 'worse', 'better' or 'same' (for B)."""

    name: str
    a: Rate
    b: Rate
    verdict: str


@dataclass(frozen=True)
class VariantChange:
    """A variant of both sweeps (same index and values) whose status differs: A's, B's."""

    index: int
    name: str
    a: VariantRow
    b: VariantRow


def variant_changes(rows_a: Sequence[VariantRow], rows_b: Sequence[VariantRow]
                    ) -> Tuple[List[VariantChange], int]:
    """
    Return the variants run in both sweeps with another status in B, and how many are in both.

    Paired by index, and only when the variant's values are the same in both (the same
    sweep file, e.g. run before and after a change, or here and on a cluster); a
    variant in one sweep only is left out. Statuses: OK, UNEXPECTED, ERROR.
    """
    by_index = {row.index: row for row in rows_a}
    changes, both = [], 0
    for b in sorted(rows_b, key=lambda row: row.index):
        a = by_index.get(b.index)
        if a is None or a.values != b.values:
            continue
        both += 1
        if a.status != b.status:
            changes.append(VariantChange(b.index, b.name, a, b))
    return changes, both


def criterion_order(names: Sequence[str]) -> List[str]:
    """Return the names: 'verdict', 'step N' by N, then the others alphabetically."""
    def key(name: str) -> Tuple[int, int, str]:
        if name == VERDICT:
            return 0, 0, ''
        match = _STEP.fullmatch(name)
        if match:
            return 1, int(match.group(1)), name
        return 2, 0, name
    return sorted(set(names), key=key)


def criterion_rates(rows: Sequence[VariantRow]) -> List[Rate]:
    """
    Return the verdict's failure rate, then each criterion's, in criterion_order.

    The verdict fails when a row's status is not 'OK' (ERROR rows included; the Rate's
    errors counts them). A criterion's n is the rows that judged it, its failures the
    rows where it is False.
    """
    rates = [Rate(VERDICT, sum(row.failed for row in rows), len(rows),
                  sum(row.status == 'ERROR' for row in rows))]
    names = criterion_order([name for row in rows for name in row.criteria])
    for name in names:
        if name == VERDICT:   # a criterion of that name would shadow the verdict
            continue
        judged = [row.criteria[name] for row in rows if name in row.criteria]
        rates.append(Rate(name, sum(not passed for passed in judged), len(judged)))
    return rates


def _is_number(value: Any) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value))


def _number(value: float) -> str:
    return str(value) if isinstance(value, int) else f'{value:g}'


def value_label(value: Any) -> str:
    """
    Return a short label of one axis value.

    Numbers as '%g', strings as they are, poses as '(2.95, 2.00, 0)' (x, y, yaw), other
    dicts as 'key=value ...', lists as compact JSON ('[0,2,3]').
    """
    if _is_number(value):
        return _number(value)
    if isinstance(value, str):
        return value
    if (isinstance(value, dict) and {'x', 'y'} <= set(value) <= {'x', 'y', 'yaw'}
            and all(_is_number(v) for v in value.values())):
        return '({:.2f}, {:.2f}, {:g})'.format(value['x'], value['y'], value.get('yaw', 0))
    if isinstance(value, dict):
        return ' '.join(f'{key}={value_label(item)}' for key, item in value.items())
    return json.dumps(value, separators=(',', ':'), sort_keys=True)


def _bin_labels(low: float, high: float) -> List[str]:
    width = (high - low) / BINS
    digits = max(0, 1 - math.floor(math.log10(width)))
    edges = [low + k * width for k in range(BINS)] + [high]
    return [f'{edges[k]:.{digits}f}-{edges[k + 1]:.{digits}f}' for k in range(BINS)]


def _kinds(value: Any) -> Optional[str]:
    """Return a mapping's kind, a list of mappings' kinds joined by '+', or None."""
    if isinstance(value, dict) and isinstance(value.get(KIND), str):
        return value[KIND]
    if (isinstance(value, list) and value
            and all(isinstance(item, dict) and isinstance(item.get(KIND), str)
                    for item in value)):
        return '+'.join(item[KIND] for item in value)
    return None


def axis_value(row: VariantRow, axis: str) -> Any:
    """
    Return the row's value of axis, or _MISSING when the row has no such axis.

    axis is an axis name, or 'AXIS.kind': the kind of the axis's value (see _kinds;
    a value without a kind, e.g. null for no fault, stands for itself).
    """
    if axis in row.values:
        return row.values[axis]
    base, dot, key = axis.rpartition('.')
    if dot and key == KIND and base in row.values:
        value = row.values[base]
        kind = _kinds(value)
        return value if kind is None else kind
    return _MISSING


def summary_axes(rows: Sequence[VariantRow], axes: Sequence[str]) -> List[str]:
    """Return axes, each followed by 'AXIS.kind' when some row's value of it has a kind."""
    names: List[str] = []
    for axis in axes:
        names.append(axis)
        if any(_kinds(row.values.get(axis)) is not None for row in rows):
            names.append(f'{axis}.{KIND}')
    return names


def axis_groups(rows: Sequence[VariantRow], axis: str) -> List[Tuple[str, List[VariantRow]]]:
    """
    Return (label, rows) for each value of one axis (or 'AXIS.kind'), in value order.

    Rows without the axis are skipped. A numeric axis with more than 8 distinct values
    is cut into 5 equal-width bins between its smallest and largest value (labelled
    e.g. '0.20-0.36'; the last bin includes its upper edge; empty bins are left out);
    other numeric axes are sorted by value, and any other axis (worlds, poses, person
    changes, goal subsets, faults) keeps the order in which its values first appear by
    index.
    """
    pairs = sorted(((row, axis_value(row, axis)) for row in rows), key=lambda p: p[0].index)
    pairs = [(row, value) for row, value in pairs if value is not _MISSING]
    with_axis = [row for row, _ in pairs]
    values = [value for _, value in pairs]
    groups: Dict[str, List[VariantRow]] = {}
    numeric = bool(values) and all(_is_number(value) for value in values)
    distinct = sorted(set(values)) if numeric else []
    if numeric and len(distinct) > MAX_DISTINCT_VALUES:
        low, high = float(distinct[0]), float(distinct[-1])
        labels = _bin_labels(low, high)
        binned: List[List[VariantRow]] = [[] for _ in labels]
        for row, value in zip(with_axis, values):
            binned[min(BINS - 1, int((value - low) / (high - low) * BINS))].append(row)
        return [(label, group) for label, group in zip(labels, binned) if group]
    if numeric:
        order = sorted(range(len(values)), key=lambda i: values[i])
        with_axis = [with_axis[i] for i in order]
        values = [values[i] for i in order]
    for row, value in zip(with_axis, values):
        groups.setdefault(value_label(value), []).append(row)
    return list(groups.items())


def axis_rates(rows: Sequence[VariantRow], axis: str) -> List[Tuple[str, Rate]]:
    """Return (label, verdict failure rate) for each group of axis_groups(rows, axis)."""
    return [(label, Rate(label, sum(row.failed for row in group), len(group),
                         sum(row.status == 'ERROR' for row in group)))
            for label, group in axis_groups(rows, axis)]


@dataclass(frozen=True)
class LeastClearance:
    """
    The least zone clearance of a group of variants (label), and which variant had it.

    clearance_m: the least min_zone_clearance_m (m; None when no row of the group has
    one), variant: that row's name (the lowest index among ties; '' if none); measured:
    the rows with a clearance, below_zero: of them, those below 0 (the footprint left the
    zone; 0 is inside); n: the rows of the group.
    """

    label: str
    clearance_m: Optional[float]
    variant: str
    measured: int
    below_zero: int
    n: int


def _clearance(row: VariantRow) -> Optional[float]:
    value = row.min_zone_clearance_m
    return float(value) if value is not None and math.isfinite(value) else None


def clearance_order(rows: Sequence[VariantRow]) -> List[VariantRow]:
    """Return the rows with a clearance, the least first (ties by index)."""
    measured = [row for row in rows if _clearance(row) is not None]
    return sorted(measured, key=lambda row: (_clearance(row), row.index))


def least_clearance(rows: Sequence[VariantRow], label: str = 'all') -> LeastClearance:
    """Return the least clearance of rows (see LeastClearance), named label."""
    ordered = clearance_order(rows)
    if not ordered:
        return LeastClearance(label, None, '', 0, 0, len(rows))
    return LeastClearance(label, _clearance(ordered[0]), ordered[0].name, len(ordered),
                          sum(_clearance(row) < 0.0 for row in ordered), len(rows))


def axis_clearances(rows: Sequence[VariantRow], axis: str) -> List[LeastClearance]:
    """Return the least clearance of each group of axis_groups(rows, axis)."""
    return [least_clearance(group, label) for label, group in axis_groups(rows, axis)]


#: The margin group of every step: a variant's least step margin (time left, s).
STEPS_GROUP = 'steps'


def margin_groups(row: VariantRow) -> Dict[str, float]:
    """
    Return a row's margins by group: 'steps' (the least of its steps'), then the others.

    Each criterion's margin as stored (scenario_judge: positive when it passed, m or s);
    the steps become one group so that a sweep of scenarios with different steps has
    one line for them.
    """
    groups: Dict[str, float] = {}
    for name, margin in row.margins.items():
        if margin is None or not math.isfinite(margin):
            continue
        group = STEPS_GROUP if _STEP.fullmatch(name) else name
        groups[group] = min(margin, groups.get(group, math.inf))
    return groups


def margin_group_order(rows: Sequence[VariantRow]) -> List[str]:
    """Return the margin groups any row has: 'steps' first, then alphabetically."""
    names = {group for row in rows for group in margin_groups(row)}
    return sorted(names, key=lambda name: (name != STEPS_GROUP, name))


@dataclass(frozen=True)
class LeastMargin:
    """The least margin of a criterion (or 'steps') over rows, and which variant had it."""

    criterion: str
    margin: float
    variant: str
    n: int          # rows with a margin for it


def least_margins(rows: Sequence[VariantRow]) -> Dict[str, LeastMargin]:
    """Return each criterion's least margin over rows (ties: the lowest index)."""
    least: Dict[str, LeastMargin] = {}
    for row in sorted(rows, key=lambda row: row.index):
        for name, margin in row.margins.items():
            if margin is None or not math.isfinite(margin):
                continue
            best = least.get(name)
            count = best.n + 1 if best else 1
            if best is None or margin < best.margin:
                least[name] = LeastMargin(name, float(margin), row.name, count)
            else:
                least[name] = LeastMargin(name, best.margin, best.variant, count)
    return least


def axis_margins(rows: Sequence[VariantRow], axis: str,
                 group: str) -> List[Tuple[str, List[Tuple[float, bool]]]]:
    """
    Return (label, [(margin, failed), ...]) for each group of axis_groups(rows, axis).

    The margins of margin group ``group`` (margin_groups) of the rows that have it;
    failed: the row's verdict was not the expected one.
    """
    points = []
    for label, members in axis_groups(rows, axis):
        grouped = [(margin_groups(row), row.failed) for row in members]
        points.append((label, [(groups[group], failed) for groups, failed in grouped
                               if group in groups]))
    return points


def failed_criteria(row: VariantRow) -> List[str]:
    """Return the names of the row's failed criteria, in criterion_order."""
    return criterion_order([name for name, passed in row.criteria.items() if not passed])


def worst_variants(rows: Sequence[VariantRow], count: int = 5) -> List[VariantRow]:
    """Return up to count failed rows: ERROR first, then most failed criteria, then index."""
    failed = [row for row in rows if row.failed]
    failed.sort(key=lambda row: (row.status != 'ERROR', -len(failed_criteria(row)),
                                 row.index))
    return failed[:max(0, count)]


def compare(rows_a: Sequence[VariantRow], rows_b: Sequence[VariantRow]) -> List[Change]:
    """
    Return how each rate changed from sweep A (before) to sweep B (after).

    One Change for the verdict and for every criterion of either sweep (in
    criterion_order; a criterion missing from one sweep has n = 0 there, hence the
    interval [0, 1], and is 'same'). The rule is conservative: B is 'worse' only when
    its Wilson 95 % interval lies wholly above A's, 'better' only when wholly below;
    intervals that overlap (or touch) are 'same', even if the rates differ. (Two
    non-overlapping 95 % intervals mean a difference well beyond 5 % chance; some real
    differences are called 'same'.)
    """
    rates_a = {rate.name: rate for rate in criterion_rates(rows_a)}
    rates_b = {rate.name: rate for rate in criterion_rates(rows_b)}
    changes = []
    for name in criterion_order(list(rates_a) + list(rates_b)):
        a = rates_a.get(name, Rate(name, 0, 0))
        b = rates_b.get(name, Rate(name, 0, 0))
        if b.low > a.high:
            verdict = 'worse'
        elif b.high < a.low:
            verdict = 'better'
        else:
            verdict = 'same'
        changes.append(Change(name, a, b, verdict))
    return changes
