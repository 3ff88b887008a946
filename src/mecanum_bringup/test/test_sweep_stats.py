"""Tests of the sweep statistics: Wilson intervals, rates, axes, worst variants, compare."""

import sqlite3

from mecanum_bringup.sweep_stats import (
    axis_clearances, axis_margins, axis_rates, clearance_order, compare, criterion_order,
    criterion_rates, least_clearance, least_margins, LeastClearance, LeastMargin,
    margin_group_order, margin_groups, Rate, summary_axes, value_label, variant_changes,
    wilson_interval, worst_variants)
from mecanum_bringup.sweep_store import read_rows, ResultsStore, VariantRow
import pytest


def row(index, status, criteria=None, values=None, **extra):
    verdict = {'OK': 'pass', 'UNEXPECTED': 'fail', 'ERROR': None}[status]
    return VariantRow(index, f'tour_{index:04d}', values or {}, status, verdict, 'pass',
                      criteria or {}, **extra)


T, F = True, False
POSE_A = {'x': 2.95, 'y': 2.0, 'yaw': 0.0}
POSE_B = {'x': 4.8, 'y': 2.0}


@pytest.fixture
def rows():
    # index status      step 1  step 2  step 10  completed  no_collision
    # 0     OK          T       T       T        T          T
    # 1     UNEXPECTED  T       F       F        F          T
    # 2     UNEXPECTED  F       F       -        F          F
    # 3     ERROR       (no criteria: not judged)
    # 4     OK          T       T       T        T          T
    def crit(s1, s2, s10, completed, collision):
        names = ('step 1', 'step 2', 'step 10', 'completed', 'no_collision')
        return {n: v for n, v in zip(names, (s1, s2, s10, completed, collision))
                if v is not None}
    return [
        row(0, 'OK', crit(T, T, T, T, T), {'seed': 0, 'world': 'apartment', 'spawn': POSE_A}),
        row(1, 'UNEXPECTED', crit(T, F, F, F, T),
            {'seed': 1, 'world': 'apartment', 'spawn': POSE_B},
            first_failure='step 2 goal kitchen: aborted'),
        row(2, 'UNEXPECTED', crit(F, F, None, F, F),
            {'seed': 2, 'world': 'office', 'spawn': POSE_A},
            first_failure='step 1 goal hall: timed out'),
        row(3, 'ERROR', {}, {'seed': 3, 'world': 'office', 'spawn': POSE_B},
            error='simulator died'),
        row(4, 'OK', crit(T, T, T, T, T), {'seed': 4, 'world': 'apartment'}),
    ]


# --- Wilson ---------------------------------------------------------------------------
# By hand, z = 1.959964, z² = 3.841459; with p = f/n, d = 1 + z²/n:
#   centre = (p + z²/2n) / d, half = z * sqrt(p(1-p)/n + z²/4n²) / d.
# 0/10:  d = 1.384146, centre = 0.192073/d = 0.138767,
#        half = 1.959964 * sqrt(0.009604) / d = 0.192073/d = 0.138767 -> (0, 0.2775)
# 5/10:  centre = 0.692073/d = 0.5, half = 1.959964 * sqrt(0.025 + 0.009604) / d
#        = 0.364598/1.384146 = 0.263410 -> (0.2366, 0.7634)
# 10/10: the mirror of 0/10 -> (0.7225, 1)
# 1/50:  d = 1.076829, centre = (0.02 + 0.038415)/d = 0.054247,
#        half = 1.959964 * sqrt(0.000392 + 0.000384) / d = 0.054604/d = 0.050708
#        -> (0.0035, 0.1050)
# 3/50:  centre = (0.06 + 0.038415)/d = 0.091393,
#        half = 1.959964 * sqrt(0.001128 + 0.000384) / d = 0.076217/d = 0.070780
#        -> (0.0206, 0.1622)
@pytest.mark.parametrize('failures, n, low, high', [
    (0, 10, 0.0, 0.2775), (5, 10, 0.2366, 0.7634), (10, 10, 0.7225, 1.0),
    (1, 50, 0.0035, 0.1050), (3, 50, 0.0206, 0.1622)])
def test_wilson_interval_matches_the_hand_computed_cases(failures, n, low, high):
    interval = wilson_interval(failures, n)
    assert interval == pytest.approx((low, high), abs=5e-5)


def test_wilson_interval_edges():
    assert wilson_interval(0, 0) == (0.0, 1.0)
    assert wilson_interval(0, 7)[0] == 0.0 and wilson_interval(7, 7)[1] == 1.0
    low, high = wilson_interval(1, 1000)
    assert 0.0 < low < 0.001 < high < 0.01
    # A wider z gives a wider interval.
    assert wilson_interval(5, 10, z=2.575829)[0] < wilson_interval(5, 10)[0]
    for bad in ((-1, 5), (6, 5), (0, -1)):
        with pytest.raises(ValueError, match='failures <= n'):
            wilson_interval(*bad)


def test_rate_properties_and_description():
    rate = Rate('verdict', 3, 50)
    assert rate.rate == pytest.approx(0.06)
    assert (rate.low, rate.high) == pytest.approx((0.0206, 0.1622), abs=5e-5)
    assert rate.describe() == '3/50 failed (6.0 %, 95 % CI 2.1-16.2 %)'
    assert Rate('verdict', 3, 50, errors=1).describe() == (
        '3/50 failed (6.0 %, 95 % CI 2.1-16.2 %), 1 of them not judged (ERROR)')
    empty = Rate('step 1', 0, 0)
    assert (empty.rate, empty.low, empty.high) == (0.0, 0.0, 1.0)
    assert empty.describe() == '0/0 failed (no runs)'


# --- rates ----------------------------------------------------------------------------
def test_criterion_rates_count_each_judged_criterion_in_a_stable_order(rows):
    rates = criterion_rates(rows)
    assert [(r.name, r.failures, r.n) for r in rates] == [
        ('verdict', 3, 5),         # rows 1, 2 and the ERROR row 3
        ('step 1', 1, 4),          # row 3 judged nothing
        ('step 2', 2, 4),
        ('step 10', 1, 3),         # numerically after step 2; row 2 did not judge it
        ('completed', 2, 4),
        ('no_collision', 1, 4)]
    assert rates[0].errors == 1 and 'ERROR' in rates[0].describe()
    assert all(r.errors == 0 for r in rates[1:])
    # The order does not depend on the rows' order or on their dicts' order.
    assert criterion_rates(list(reversed(rows))) == rates


def test_criterion_order_and_empty_rows():
    assert criterion_order(['zone', 'step 10', 'completed', 'step 2', 'verdict',
                            'step 1', 'step 2']) == [
        'verdict', 'step 1', 'step 2', 'step 10', 'completed', 'zone']
    assert [(r.name, r.failures, r.n) for r in criterion_rates([])] == [('verdict', 0, 0)]


# --- axes -----------------------------------------------------------------------------
def test_axis_rates_of_strings_and_poses_keep_first_appearance_order(rows):
    assert [(label, r.failures, r.n) for label, r in axis_rates(rows, 'world')] == [
        ('apartment', 1, 3), ('office', 2, 2)]
    # Row 4 has no spawn: skipped.
    assert [(label, r.failures, r.n) for label, r in axis_rates(rows, 'spawn')] == [
        ('(2.95, 2.00, 0)', 1, 2), ('(4.80, 2.00, 0)', 2, 2)]
    assert axis_rates(rows, 'person') == []
    # Few numeric values: one group each, in numeric order.
    assert [label for label, _ in axis_rates(rows, 'seed')] == ['0', '1', '2', '3', '4']


def test_axis_rates_sorts_few_numbers_and_labels_lists_and_dicts():
    scales = [2.0, 0.5, 1.0, 0.5]
    rows = [row(i, 'OK' if i else 'UNEXPECTED', values={
        'sensor_noise_scale': s, 'goals': [[0, 1], [2, 3]][i % 2],
        'person': [{'speed_m_s': 0.5}, {'speed_m_s': 1.2, 'path': [[5.0, 2.9]]}][i % 2]})
        for i, s in enumerate(scales)]
    assert [(label, r.failures, r.n) for label, r in axis_rates(rows, 'sensor_noise_scale')] \
        == [('0.5', 0, 2), ('1', 0, 1), ('2', 1, 1)]
    assert [label for label, _ in axis_rates(rows, 'goals')] == ['[0,1]', '[2,3]']
    assert [label for label, _ in axis_rates(rows, 'person')] == [
        'speed_m_s=0.5', 'speed_m_s=1.2 path=[[5.0,2.9]]']
    assert value_label(True) == 'true' and value_label(7) == '7'


def test_a_numeric_axis_with_many_values_is_binned_in_five_equal_widths():
    # 10 distinct frictions from 0.2 to 1.0: bins of width 0.16; the two below 0.3 fail.
    frictions = [0.2, 0.25, 0.3, 0.4, 0.45, 0.6, 0.7, 0.75, 0.9, 1.0]
    rows = [row(i, 'UNEXPECTED' if f < 0.3 else 'OK',
                values={'floor_friction_coefficient': f}) for i, f in enumerate(frictions)]
    rows.append(row(99, 'OK', values={'seed': 1}))   # no friction: skipped
    binned = axis_rates(rows, 'floor_friction_coefficient')
    assert [(label, r.failures, r.n) for label, r in binned] == [
        ('0.20-0.36', 2, 3), ('0.36-0.52', 0, 2), ('0.52-0.68', 0, 1), ('0.68-0.84', 0, 2),
        ('0.84-1.00', 0, 2)]   # 1.0, the largest value, is in the last bin
    # Empty bins are left out; a wide integer axis gets integer labels.
    seeds = [0, 1, 2, 3, 4, 5, 6, 7, 8, 1000]
    rows = [row(i, 'OK', values={'seed': s}) for i, s in enumerate(seeds)]
    assert [(label, r.n) for label, r in axis_rates(rows, 'seed')] == [
        ('0-200', 9), ('800-1000', 1)]


# --- worst variants -------------------------------------------------------------------
def test_worst_variants_errors_first_then_most_failed_criteria_then_index(rows):
    assert [r.index for r in worst_variants(rows)] == [3, 2, 1]
    assert [r.index for r in worst_variants(rows, count=2)] == [3, 2]
    assert worst_variants(rows, count=0) == []
    ties = [row(7, 'UNEXPECTED', {'step 1': F}), row(5, 'UNEXPECTED', {'step 1': F}),
            row(6, 'ERROR'), row(2, 'ERROR'), row(1, 'OK', {'step 1': F})]
    # Row 1 failed a criterion but its status is OK (e.g. expected to fail): not listed.
    assert [r.index for r in worst_variants(ties)] == [2, 6, 5, 7]


# --- compare --------------------------------------------------------------------------
def sweep(failures, n, criterion='step 1'):
    return [row(i, 'UNEXPECTED' if i < failures else 'OK', {criterion: i >= failures})
            for i in range(n)]


def test_compare_says_worse_or_better_only_when_the_intervals_do_not_overlap():
    # 0/50: (0, 0.0713); 20/50: (0.2761, 0.5382): apart.
    changes = compare(sweep(0, 50), sweep(20, 50))
    assert [(c.name, c.verdict) for c in changes] == [('verdict', 'worse'), ('step 1', 'worse')]
    assert (changes[0].a.failures, changes[0].b.failures) == (0, 20)
    assert [c.verdict for c in compare(sweep(20, 50), sweep(0, 50))] == ['better', 'better']
    assert [c.verdict for c in compare(sweep(3, 50), sweep(3, 50))] == ['same', 'same']


def test_compare_calls_overlapping_intervals_the_same_although_the_rates_differ():
    # 2/20 = 10 %: (0.0279, 0.3010); 5/20 = 25 %: (0.1119, 0.4687): they overlap.
    changes = compare(sweep(2, 20), sweep(5, 20))
    assert changes[0].a.rate == pytest.approx(0.10) and changes[0].b.rate == pytest.approx(0.25)
    assert [c.verdict for c in changes] == ['same', 'same']


def test_compare_covers_criteria_of_either_sweep():
    a = sweep(0, 50, criterion='step 2')
    b = [row(i, 'OK', {'step 1': True, 'no_collision': True}) for i in range(50)]
    changes = compare(a, b)
    assert [c.name for c in changes] == ['verdict', 'step 1', 'step 2', 'no_collision']
    step_1 = changes[1]
    assert (step_1.a.n, step_1.b.n, step_1.verdict) == (0, 50, 'same')   # (0, 1) overlaps
    assert changes[2].b.n == 0 and changes[2].verdict == 'same'


def test_variant_changes_pair_the_same_variants_and_list_another_status(rows):
    other = [row(0, 'UNEXPECTED', values=rows[0].values, first_failure='step 1: STUCK'),
             row(1, 'UNEXPECTED', values=rows[1].values),         # same status
             row(2, 'OK', values={'seed': 99}),                    # other values: not paired
             row(3, 'ERROR', values=rows[3].values),               # same status
             row(4, 'OK', values=rows[4].values),                  # same status
             row(7, 'OK', values={'seed': 7})]                     # only in B
    changes, both = variant_changes(rows, other)
    assert both == 4
    assert [(c.index, c.a.status, c.b.status) for c in changes] == [(0, 'OK', 'UNEXPECTED')]
    assert changes[0].b.first_failure == 'step 1: STUCK'
    assert variant_changes(rows, rows) == ([], 5)
    assert variant_changes([], rows) == ([], 0)


# --- with the results store -----------------------------------------------------------
def test_rows_round_trip_through_the_results_store(rows, tmp_path):
    path = tmp_path / 'sweep' / 'results.sqlite'
    with ResultsStore(path, 'tour', '{"axes": {}}') as store:
        for each in reversed(rows):
            store.add(each)
    stored = read_rows(path)
    assert [r.index for r in stored] == [0, 1, 2, 3, 4]
    assert stored[2].criteria == {'step 1': False, 'step 2': False, 'completed': False,
                                  'no_collision': False}
    assert criterion_rates(stored) == criterion_rates(rows)
    assert axis_rates(stored, 'spawn') == axis_rates(rows, 'spawn')
    assert [r.index for r in worst_variants(stored)] == [3, 2, 1]
    assert [c.verdict for c in compare(stored, rows)] == ['same'] * 6


# --- the least zone clearance ---------------------------------------------------------
SLIP_FL = {'kind': 'wheel_slip', 'wheel': 'FL', 'traction_factor': 0.2}
SLIP_RR = {'kind': 'wheel_slip', 'wheel': 'RR', 'traction_factor': 0.1}


@pytest.fixture
def faulted():
    # index status      seed  fault                        least clearance (m)
    # 0     OK          0     wheel_slip FL                0.30
    # 1     UNEXPECTED  1     wheel_slip RR                -0.05
    # 2     OK          0     lidar_blinded at 5 s         0.12
    # 3     ERROR       1     lidar_blinded at 8 s         - (not judged)
    # 4     OK          0     none (null)                  0.50
    return [
        row(0, 'OK', {'stay_in_zone': T}, {'seed': 0, 'fault': SLIP_FL},
            min_zone_clearance_m=0.30),
        row(1, 'UNEXPECTED', {'stay_in_zone': F}, {'seed': 1, 'fault': SLIP_RR},
            min_zone_clearance_m=-0.05),
        row(2, 'OK', {'stay_in_zone': T},
            {'seed': 0, 'fault': {'kind': 'lidar_blinded', 'onset_s': 5.0}},
            min_zone_clearance_m=0.12),
        row(3, 'ERROR', {}, {'seed': 1, 'fault': {'kind': 'lidar_blinded', 'onset_s': 8.0}}),
        row(4, 'OK', {'stay_in_zone': T}, {'seed': 0, 'fault': None},
            min_zone_clearance_m=0.50),
    ]


def test_the_least_clearance_names_its_variant_and_counts_those_below_zero(faulted):
    assert least_clearance(faulted) == LeastClearance('all', -0.05, 'tour_0001', 4, 1, 5)
    assert least_clearance([], 'none') == LeastClearance('none', None, '', 0, 0, 0)
    assert least_clearance([faulted[3]]) == LeastClearance('all', None, '', 0, 0, 1)
    # A tie goes to the lower index; exactly 0 is not below 0 (the footprint touches).
    ties = [row(5, 'OK', min_zone_clearance_m=0.0), row(2, 'OK', min_zone_clearance_m=0.0)]
    assert least_clearance(ties) == LeastClearance('all', 0.0, 'tour_0002', 2, 0, 2)
    assert [r.index for r in clearance_order(faulted)] == [1, 2, 0, 4]


def test_the_least_clearance_per_axis_value_uses_the_groups_of_the_rates(faulted):
    assert axis_clearances(faulted, 'seed') == [
        LeastClearance('0', 0.12, 'tour_0002', 3, 0, 3),
        LeastClearance('1', -0.05, 'tour_0001', 1, 1, 2)]
    assert [c.label for c in axis_clearances(faulted, 'seed')] == [
        label for label, _ in axis_rates(faulted, 'seed')]
    assert axis_clearances(faulted, 'world') == []


def test_an_axis_of_faults_is_also_summarised_per_kind(faulted):
    # Any axis whose values are mappings with a kind gets an 'AXIS.kind' summary.
    assert summary_axes(faulted, ['seed', 'fault']) == ['seed', 'fault', 'fault.kind']
    assert summary_axes(faulted, ['seed']) == ['seed']
    assert axis_clearances(faulted, 'fault.kind') == [
        LeastClearance('wheel_slip', -0.05, 'tour_0001', 2, 1, 2),
        LeastClearance('lidar_blinded', 0.12, 'tour_0002', 1, 0, 2),
        LeastClearance('null', 0.50, 'tour_0004', 1, 0, 1)]
    assert [(label, r.failures, r.n) for label, r in axis_rates(faulted, 'fault.kind')] == [
        ('wheel_slip', 1, 2), ('lidar_blinded', 1, 2), ('null', 0, 1)]
    # Each whole value is still a group of the axis itself.
    assert [label for label, _ in axis_rates(faulted, 'fault')] == [
        'kind=wheel_slip wheel=FL traction_factor=0.2',
        'kind=wheel_slip wheel=RR traction_factor=0.1', 'kind=lidar_blinded onset_s=5',
        'kind=lidar_blinded onset_s=8', 'null']
    # A list of faults is summarised under its kinds joined.
    listed = [row(0, 'OK', values={'fault': [SLIP_FL, {'kind': 'imu_silent'}]},
                  min_zone_clearance_m=0.2)]
    assert summary_axes(listed, ['fault']) == ['fault', 'fault.kind']
    assert axis_clearances(listed, 'fault.kind') == [
        LeastClearance('wheel_slip+imu_silent', 0.2, 'tour_0000', 1, 0, 1)]


def test_the_least_clearance_round_trips_through_the_store(faulted, tmp_path):
    path = tmp_path / 'results.sqlite'
    with ResultsStore(path, 'faults', '{}') as store:
        for each in faulted:
            store.add(each)
    stored = read_rows(path)
    assert [r.min_zone_clearance_m for r in stored] == [0.30, -0.05, 0.12, None, 0.50]
    assert least_clearance(stored) == least_clearance(faulted)


def test_a_store_from_before_the_clearance_column_still_reads_and_resumes(tmp_path):
    path = tmp_path / 'results.sqlite'
    db = sqlite3.connect(str(path))
    with db:   # the layout of the first stores (schema 1, 14 columns)
        db.execute('CREATE TABLE sweep (key TEXT PRIMARY KEY, value TEXT)')
        db.executemany('INSERT INTO sweep VALUES (?, ?)', [
            ('schema', '1'), ('name', 'old'), ('fingerprint', 'fp'), ('created_at', '0')])
        db.execute('CREATE TABLE variants (idx INTEGER PRIMARY KEY, name TEXT, '
                   'values_json TEXT, status TEXT, verdict TEXT, expected TEXT, '
                   'criteria_json TEXT, first_failure TEXT, sim_time_s REAL, '
                   'wall_time_s REAL, run_dir TEXT, error TEXT, worker TEXT, finished_at REAL)')
        db.execute('INSERT INTO variants VALUES (0, "old_0000", \'{"seed": 0}\', "OK", '
                   '"pass", "pass", \'{"stay_in_zone": true}\', "", 10.0, 20.0, "", "", '
                   '"", 1.0)')
    db.close()
    (old,) = read_rows(path)
    assert (old.name, old.values, old.min_zone_clearance_m) == ('old_0000', {'seed': 0}, None)
    with ResultsStore(path, 'old', 'fp') as store:   # resumed: the column is added
        store.add(row(1, 'UNEXPECTED', {'stay_in_zone': F}, {'seed': 1},
                      min_zone_clearance_m=-0.02))
    assert [r.min_zone_clearance_m for r in read_rows(path)] == [None, -0.02]


def test_margins_by_group_least_per_criterion_and_along_an_axis():
    rows = [
        row(0, 'OK', values={'seed': 1},
            margins={'step 1': 30.0, 'step 2': 12.5, 'no_collision': 0.30}),
        row(1, 'UNEXPECTED', values={'seed': 2},
            margins={'step 1': -4.0, 'no_collision': 0.05, 'stay_in_zone': -0.1}),
        row(2, 'OK', values={'seed': 1}, margins={'no_collision': 0.05}),
        row(3, 'ERROR', values={'seed': 2}),
    ]
    # The steps as one group: the least of them.
    assert margin_groups(rows[0]) == {'steps': 12.5, 'no_collision': 0.30}
    assert margin_group_order(rows) == ['steps', 'no_collision', 'stay_in_zone']
    least = least_margins(rows)
    # A tie (0.05 twice) goes to the lower index.
    assert least['no_collision'] == LeastMargin('no_collision', 0.05, 'tour_0001', 3)
    assert least['step 1'] == LeastMargin('step 1', -4.0, 'tour_0001', 2)
    assert least['step 2'] == LeastMargin('step 2', 12.5, 'tour_0000', 1)
    assert axis_margins(rows, 'seed', 'no_collision') == [
        ('1', [(0.30, False), (0.05, False)]), ('2', [(0.05, True)])]
    assert axis_margins(rows, 'seed', 'stay_in_zone') == [('1', []), ('2', [(-0.1, True)])]
