"""
Search for failures: choose a sweep's next variants from the results so far (pure).

``mode: search`` runs a budget of ``samples`` variants in rounds of ``search.batch``.
Round 0 draws its variants as random mode does; every later round draws from
distributions fitted to the *elite* variants so far: the ``search.elite_fraction`` of
the judged variants (at least MIN_ELITES) with the lowest objective, the margin of one
verdict line (scenario_judge: positive when it passed, <= 0 when it failed) or the least
of them. That is the cross-entropy method (Rubinstein; VerifAI's cross-entropy sampler
over Scenic scenarios is the reference), with memory: each round's elites are taken from
every variant run so far, and each fitted distribution is mixed with the axis's own by
``search.smoothing`` so that no value becomes impossible.

Per axis:

- ``uniform: [lo, hi]`` (floor friction, sensor noise, fault onset): a normal centred on
  the best variant so far with SPREAD_FACTOR times the elites' standard deviation (at
  least MIN_SIGMA_FRACTION of hi - lo), drawn with probability ``smoothing``, else
  uniform; clipped to [lo, hi]. Centred on the elites' mean with their own spread (the
  textbook fit), the search was slower than random sampling on the planted failure of
  bench/failure_search.py, which lies at the edge of the axis: the mean stays inside
  what was tried (offline, on that failure's measured error curve, 100 master seeds:
  median 44 runs against random's 74; centred on the best with twice the spread: 11.5).
- a list (worlds, spawns, persons, faults, numbers): each value's probability is
  ``smoothing`` x its share of the elites + (1 - smoothing) / len(list).
- ``range`` (seed) and ``sample`` (goals): drawn as in random mode (a seed has no
  neighbourhood: seed 41 is no more like 40 than like 900).

A variant that failed (its verdict not the expected one) counts as the lowest objective
(-inf) whatever its margins: the search is after failures. A variant that could not be
judged (ERROR) does not count. Everything is a function of the sweep (its master seed)
and the rows of the earlier rounds, so the same file and the same results give the same
variants: a search resumes from its store like every sweep.
"""

import copy
import json
import math
import random
import statistics
from typing import Any, List, Optional, Sequence

from mecanum_bringup.sweep import draw_value, LEAST, Sweep, Variant
from mecanum_bringup.sweep_stats import margin_groups
from mecanum_bringup.sweep_store import VariantRow

#: Elites per fit, at least (a standard deviation needs two).
MIN_ELITES = 2
#: A fitted normal's standard deviation is at least this fraction of the axis's range.
MIN_SIGMA_FRACTION = 0.02
#: A fitted normal's standard deviation is this many times the elites'.
SPREAD_FACTOR = 2.0


def objective_value(row: VariantRow, objective: str) -> Optional[float]:
    """
    Return a finished variant's objective (lower: closer to failing); None: not judged.

    -inf when its verdict was not the expected one (a failure found); otherwise its
    margin of the objective (margin_groups: 'steps' is its least step margin), or the
    least of them for 'least'; None when it has none (an ERROR row, or no such margin).
    """
    if row.status == 'ERROR':
        return None
    if row.status != 'OK':
        return -math.inf
    if objective == LEAST:
        return row.least_margin
    return margin_groups(row).get(objective)


def round_count(sweep: Sweep) -> int:
    """Return the number of rounds of a search sweep."""
    return math.ceil(sweep.samples / sweep.search.batch)


def round_indices(sweep: Sweep, round_number: int) -> range:
    """Return the variant indices of one round."""
    batch = sweep.search.batch
    return range(round_number * batch, min((round_number + 1) * batch, sweep.samples))


def elites(sweep: Sweep, rows: Sequence[VariantRow]) -> List[VariantRow]:
    """Return the elite rows: the elite_fraction with the lowest objective (ties: index)."""
    judged = [(value, row.index, row) for row in rows
              for value in [objective_value(row, sweep.search.objective)]
              if value is not None]
    if not judged:
        return []
    count = max(MIN_ELITES, math.ceil(sweep.search.elite_fraction * len(judged)))
    judged.sort(key=lambda item: (item[0], item[1]))
    return [row for _, _, row in judged[:count]]


def round_variants(sweep: Sweep, round_number: int,
                   earlier: Sequence[VariantRow]) -> List[Variant]:
    """
    Return the variants of one round, drawn from what the earlier rounds found.

    earlier: the rows of the variants of the rounds before (their indices below the
    round's first); rows of this round or later are ignored, so a resumed search draws
    the same variants. Round 0, or no judged row yet: as random mode.
    """
    indices = round_indices(sweep, round_number)
    first = indices.start
    best = elites(sweep, [row for row in earlier if row.index < first])
    if round_number == 0 or len(best) < MIN_ELITES:
        return [Variant(index, {axis: draw_value(axis, spec, sweep, index)
                                for axis, spec in sweep.axes.items()})
                for index in indices]
    return [Variant(index, {axis: _draw_fitted(axis, spec, sweep, index, best)
                            for axis, spec in sweep.axes.items()})
            for index in indices]


def _draw_fitted(axis: str, spec: Any, sweep: Sweep, index: int,
                 best: Sequence[VariantRow]) -> Any:
    """Draw one axis's value for variant index from the elites' fitted distribution."""
    rng = random.Random(f'{sweep.master_seed}/{index}/{axis}/search')
    smoothing = sweep.search.smoothing
    if isinstance(spec, list):
        keys = [_key(value) for value in spec]
        shares = [0.0] * len(spec)
        for row in best:
            value = row.values.get(axis)
            if _key(value) in keys:
                shares[keys.index(_key(value))] += 1.0 / len(best)
        weights = [smoothing * share + (1.0 - smoothing) / len(spec) for share in shares]
        return copy.deepcopy(spec[_choose(rng, weights)])
    if 'uniform' in spec:
        lo, hi = spec['uniform']
        values = [float(row.values[axis]) for row in best
                  if isinstance(row.values.get(axis), (int, float))]
        if len(values) < MIN_ELITES or rng.random() >= smoothing:
            return round(rng.uniform(lo, hi), 4)
        # Centred on the best variant so far (elites come best first), spread wider than
        # the elites: a failure region at the edge of what was tried is reached by
        # stepping beyond the best, which a normal about the elites' mean never does.
        sigma = max(SPREAD_FACTOR * statistics.pstdev(values), MIN_SIGMA_FRACTION * (hi - lo))
        return round(min(hi, max(lo, rng.gauss(values[0], sigma))), 4)
    return draw_value(axis, spec, sweep, index)


def _key(value: Any) -> str:
    """Return a list value's identity: canonical JSON (the store sorts mappings' keys)."""
    return json.dumps(value, sort_keys=True)


def _choose(rng: random.Random, weights: Sequence[float]) -> int:
    """Return an index drawn with the given weights (they sum to 1)."""
    point, total = rng.random() * sum(weights), 0.0
    for index, weight in enumerate(weights):
        total += weight
        if point < total:
            return index
    return len(weights) - 1
