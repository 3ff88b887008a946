"""Tests of the sweep reports: rate tables, the per-axis plot, JUnit XML and the HTML page."""

import base64
import re
import xml.etree.ElementTree as ElementTree

from matplotlib.image import imread
from mecanum_bringup.sweep_report import (
    compare_table, junit_xml, plot_axis_rates, rates_table, step_labels, StepLabel,
    variant_changes_table, variant_steps, write_report)
from mecanum_bringup.sweep_stats import compare, variant_changes
from mecanum_bringup.sweep_store import read_rows, ResultsStore, VariantRow
import pytest
import yaml

PNG_MAGIC = b'\x89PNG\r\n\x1a\n'
POSE = {'x': 2.95, 'y': 2.0, 'yaw': 0.0}


def row(index, status, criteria=None, values=None, **extra):
    verdict = {'OK': 'pass', 'UNEXPECTED': 'fail', 'ERROR': None}[status]
    return VariantRow(index, f'tour_{index:04d}', values or {}, status, verdict, 'pass',
                      criteria or {}, **extra)


@pytest.fixture
def rows():
    return [
        row(0, 'OK', {'step 1': True, 'step 2': True, 'no_collision': True},
            {'seed': 0, 'world': 'apartment', 'spawn': POSE}, wall_time_s=40.0,
            run_dir='runs/tour_0000'),
        row(1, 'UNEXPECTED', {'step 1': True, 'step 2': False, 'no_collision': True},
            {'seed': 1, 'world': 'apartment', 'spawn': POSE}, wall_time_s=50.5,
            first_failure='step 2 goal <kitchen> & "sink": aborted', run_dir='runs/tour_0001'),
        row(2, 'ERROR', {}, {'seed': 2, 'world': 'office', 'spawn': POSE}, wall_time_s=3.0,
            error='office.yaml: spawn in a wall <x=1>\x1b[0m'),
        row(3, 'UNEXPECTED', {'step 1': False, 'step 2': False, 'no_collision': False},
            {'seed': 3, 'world': 'office', 'spawn': POSE}, wall_time_s=None,
            first_failure='step 1 goal hall: timed out'),
    ]


def test_rates_table_lists_every_rate_with_its_interval(rows):
    lines = rates_table(rows).splitlines()
    assert lines[0].split() == ['criterion', 'failures/n', 'rate', '95', '%', 'CI']
    assert set(lines[1]) == {'-', ' '}
    body = [line.split() for line in lines[2:-1]]
    # 3/4: Wilson (0.3006, 0.9544); 1/3: (0.0615, 0.7923); 2/3: (0.2077, 0.9385)
    assert body == [
        ['verdict', '3/4', '75.0', '%', '30.1-95.4', '%'],
        ['step', '1', '1/3', '33.3', '%', '6.1-79.2', '%'],
        ['step', '2', '2/3', '66.7', '%', '20.8-93.9', '%'],
        ['no_collision', '1/3', '33.3', '%', '6.1-79.2', '%']]
    assert lines[-1] == '4 variants: 1 as expected, 2 unexpected, 1 errors'
    # Right-aligned numbers: every rate ends in the same column.
    ends = {line.index(' %') for line in lines[2:-1]}
    assert len(ends) == 1


def test_compare_table_names_the_change(rows):
    before = [row(i, 'OK', {'step 1': True}) for i in range(50)]
    after = [row(i, 'UNEXPECTED' if i < 20 else 'OK', {'step 1': i >= 20}) for i in range(50)]
    table = compare_table(compare(before, after))
    lines = table.splitlines()
    assert lines[0].split()[:3] == ['criterion', 'A', 'failures/n']
    assert lines[2].startswith('verdict') and lines[2].endswith('worse')
    assert '0/50' in lines[2] and '20/50' in lines[2] and '40.0 % (27.6-53.8 %)' in lines[2]
    assert lines[-1] == '2 worse: verdict, step 1; 0 better (beyond the 95 % intervals)'
    same = compare_table(compare(rows, rows)).splitlines()
    assert all(line.endswith('same') for line in same[2:-1])
    assert same[-1] == '0 worse; 0 better (beyond the 95 % intervals)'


def test_compare_table_names_steps_by_what_they_do():
    before = [row(i, 'OK', {'step 1': True, 'step 2': True}) for i in range(4)]
    labels = {'step 1': StepLabel('step 1: goal (4.00, 2.30)'),
              'step 2': StepLabel('step 2 (differs by scenario)', 'scenario',
                                  ('a: goal (1.00, 1.00)', 'b: wait 2.0 s'))}
    lines = compare_table(compare(before, before), labels).splitlines()
    assert [line.split('  ')[0] for line in lines[2:5]] == [
        'verdict', 'step 1: goal (4.00, 2.30)', 'step 2 (differs by scenario)']
    assert lines[5] == 'step 2 by scenario: a: goal (1.00, 1.00); b: wait 2.0 s'


def test_variant_changes_table_lists_each_other_status_and_counts_the_same(rows):
    after = [row(0, 'UNEXPECTED', values=rows[0].values, first_failure='step 1:\n STUCK'),
             row(1, 'OK', values=rows[1].values), rows[2], rows[3]]
    lines = variant_changes_table(*variant_changes(rows, after)).splitlines()
    assert lines == [
        'tour_0000: A OK; B UNEXPECTED (step 1: STUCK)',
        'tour_0001: A UNEXPECTED (step 2 goal <kitchen> & "sink": aborted); B OK',
        '2 of 4 variants run in both sweeps have the same status; 2 another']


def test_plot_axis_rates_writes_one_png_subplot_per_axis(rows, tmp_path):
    one, three = tmp_path / 'one.png', tmp_path / 'three.png'
    plot_axis_rates(rows, ['world'], one)
    plot_axis_rates(rows, ['world', 'spawn', 'person'], three)   # person: no rows
    for path in (one, three):
        assert path.read_bytes()[:8] == PNG_MAGIC
    assert imread(str(three)).shape[0] > 2 * imread(str(one)).shape[0]
    empty = tmp_path / 'empty.png'
    plot_axis_rates([], [], empty)
    assert empty.read_bytes()[:8] == PNG_MAGIC


def test_junit_xml_has_a_testcase_per_variant(rows):
    root = ElementTree.fromstring(junit_xml(rows, 'tour_robustness').encode('utf-8'))
    assert root.tag == 'testsuite' and root.get('name') == 'tour_robustness'
    assert (root.get('tests'), root.get('failures'), root.get('errors')) == ('4', '2', '1')
    assert float(root.get('time')) == pytest.approx(93.5)
    cases = root.findall('testcase')
    assert [c.get('name') for c in cases] == [
        'tour_0000', 'tour_0001', 'tour_0002', 'tour_0003']
    assert {c.get('classname') for c in cases} == {'tour_robustness'}
    assert cases[3].get('time') == '0.000'   # unknown wall time
    assert cases[0].find('failure') is None and cases[0].find('error') is None
    assert cases[1].find('failure').get('message') == \
        'step 2 goal <kitchen> & "sink": aborted'
    assert cases[1].find('error') is None
    error = cases[2].find('error')
    assert error.get('message').startswith('office.yaml: spawn in a wall <x=1>')
    assert cases[2].find('failure') is None
    properties = {p.get('name'): p.get('value') for p in cases[0].find('properties')}
    # The command that runs the variant again, recorded (a relative run folder: relative
    # to the sweep folder).
    assert properties == {'index': '0', 'status': 'OK', 'seed': '0', 'world': 'apartment',
                          'spawn': '(2.95, 2.00, 0)',
                          'replay': 'ros2 run mecanum_bringup run_scenarios '
                                    'runs/tour_0000/scenario.yaml --record --out replay'}
    out = cases[3].find('system-out').text
    assert 'world = office' in out and 'failed criteria: step 1, step 2, no_collision' in out


def test_write_report_writes_the_page_the_plot_and_junit(rows, tmp_path):
    out = tmp_path / 'sweeps' / 'tour'
    # Run folders: one relative to out (all three files), one elsewhere (summary only).
    run_1 = out / 'runs' / 'tour_0001'
    (run_1 / 'bag').mkdir(parents=True)
    (run_1 / 'run.png').write_bytes(PNG_MAGIC)
    (run_1 / 'summary.json').write_text('{}')
    run_3 = tmp_path / 'elsewhere' / 'tour_0003'
    run_3.mkdir(parents=True)
    (run_3 / 'summary.json').write_text('{}')
    rows[3].run_dir = str(run_3)

    page = write_report(rows, 'tour<robust>', out, ['world', 'spawn'],
                        description='Friction & noise <on> the tour')
    assert page == out / 'report.html'
    text = page.read_text(encoding='utf-8')
    assert '<title>Sweep tour&lt;robust&gt;</title>' in text
    assert 'Friction &amp; noise &lt;on&gt; the tour' in text
    assert '4 variants: 1 as expected, 2 unexpected, 1 errors' in text
    assert 'step 2 goal &lt;kitchen&gt; &amp; &quot;sink&quot;: aborted' in text
    assert '<kitchen>' not in text and '<robust>' not in text and '\x1b' not in text
    # Every rate with its interval, and the per-axis numbers.
    assert '<td>verdict</td><td class="num">3/4</td><td class="num">75.0 %</td>' \
        '<td class="num">30.1-95.4 %</td>' in text
    assert '<td>office</td><td class="num">2/2</td>' in text
    # The embedded plot is the PNG written beside the page.
    match = re.search(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)"', text)
    assert match
    assert base64.b64decode(match.group(1)) == (out / 'rates.png').read_bytes()
    assert (out / 'rates.png').read_bytes()[:8] == PNG_MAGIC
    # The worst variants, ERROR first, with relative links to what exists.
    worst = text[text.index('<h2>Worst variants</h2>'):]
    assert worst.index('tour_0002') < worst.index('tour_0003') < worst.index('tour_0001')
    assert 'tour_0000' not in worst
    assert '<a href="runs/tour_0001/run.png">run.png</a>' in worst
    assert '<a href="runs/tour_0001/summary.json">summary.json</a>' in worst
    assert '<a href="runs/tour_0001/bag/">bag</a>' in worst
    assert '<a href="../../elsewhere/tour_0003/summary.json">summary.json</a>' in worst
    # Each worst variant's replay: the command that runs it again, recorded, into the
    # replay/ folder beside its runs/ folder (here tmp_path/elsewhere/tour_0003).
    assert (f'<code>ros2 run mecanum_bringup run_scenarios {run_3}/scenario.yaml --record '
            f'--out {tmp_path}/replay</code>') in worst
    assert 'elsewhere/tour_0003/run.png' not in worst
    # JUnit beside it.
    root = ElementTree.parse(str(out / 'junit.xml')).getroot()
    assert root.get('name') == 'tour<robust>' and len(root.findall('testcase')) == 4


def test_write_report_without_failures_and_from_a_store(tmp_path):
    store_path = tmp_path / 'out' / 'results.sqlite'
    with ResultsStore(store_path, 'calm', 'fingerprint') as store:
        for index in range(3):
            store.add(row(index, 'OK', {'step 1': True},
                          {'floor_friction_coefficient': 0.2 + 0.1 * index}))
    stored = read_rows(store_path)
    page = write_report(stored, 'calm', tmp_path / 'out', ['floor_friction_coefficient'])
    text = page.read_text(encoding='utf-8')
    assert '<p>No variant failed.</p>' in text
    assert '3 variants: 3 as expected, 0 unexpected, 0 errors' in text
    assert '<td>0.3</td><td class="num">0/3</td>' not in text   # one row per value
    assert '<td>0.3</td><td class="num">0/1</td>' in text
    root = ElementTree.parse(str(tmp_path / 'out' / 'junit.xml')).getroot()
    assert (root.get('tests'), root.get('failures'), root.get('errors')) == ('3', '0', '0')


# --- the least zone clearance ---------------------------------------------------------
SLIP = {'kind': 'wheel_slip', 'wheel': 'FL'}
BLIND = {'kind': 'lidar_blinded', 'onset_s': 5.0}


@pytest.fixture
def clearances():
    # index status      seed  fault          least clearance (m)
    # 0     OK          0     wheel_slip     0.30
    # 1     UNEXPECTED  1     wheel_slip     -0.05 (stay_in_zone failed)
    # 2     OK          0     lidar_blinded  0.12
    # 3     ERROR       1     lidar_blinded  - (not judged)
    return [
        row(0, 'OK', {'stay_in_zone': True}, {'seed': 0, 'fault': SLIP},
            min_zone_clearance_m=0.30, run_dir='runs/tour_0000'),
        row(1, 'UNEXPECTED', {'stay_in_zone': False}, {'seed': 1, 'fault': SLIP},
            min_zone_clearance_m=-0.05, first_failure='stay_in_zone: least clearance -0.050 m'),
        row(2, 'OK', {'stay_in_zone': True}, {'seed': 0, 'fault': BLIND},
            min_zone_clearance_m=0.12),
        row(3, 'ERROR', {}, {'seed': 1, 'fault': BLIND}, error='simulator died'),
    ]


def test_rates_table_ends_with_the_least_zone_clearance(clearances, rows):
    lines = rates_table(clearances).splitlines()
    assert lines[-2] == '4 variants: 2 as expected, 1 unexpected, 1 errors'
    assert lines[-1] == ('least zone clearance: -0.050 m in tour_0001; 1 of 3 measured '
                         'variants below 0 m')
    # No clearance measured: no such line.
    assert 'clearance' not in rates_table(rows)


def test_junit_xml_gives_each_variant_its_least_zone_clearance(clearances):
    root = ElementTree.fromstring(junit_xml(clearances, 'faults').encode('utf-8'))
    cases = root.findall('testcase')
    values = [{p.get('name'): p.get('value') for p in case.find('properties')}.get(
        'min_zone_clearance_m') for case in cases]
    assert values == ['0.300', '-0.050', '0.120', None]
    assert 'least zone clearance: -0.050 m' in cases[1].find('system-out').text
    assert 'least zone clearance: -' in cases[3].find('system-out').text


def test_write_report_shows_the_least_clearance_per_variant_axis_value_and_fault_kind(
        clearances, tmp_path):
    text = write_report(clearances, 'faults', tmp_path, ['seed', 'fault']).read_text(
        encoding='utf-8')
    # Per axis value (seed 0: rows 0 and 2; seed 1: row 1, row 3 not measured), and per
    # fault kind, an axis of its own that no code names.
    assert '<h3>fault.kind</h3>' in text
    assert ('<td>0</td><td class="num">0/2</td><td class="num">0.0 %</td>'
            '<td class="num">0.0-65.8 %</td><td class="num">0.120 m (tour_0002)</td>') in text
    assert '<td>1</td><td class="num">2/2</td>' in text
    assert '<td class="num">-0.050 m (tour_0001)</td>' in text
    kinds = text[text.index('<h3>fault.kind</h3>'):]
    assert kinds.index('<td>wheel_slip</td>') < kinds.index('<td>lidar_blinded</td>')
    # The zone clearance section: the overall least, then the variants, least first.
    zone = text[text.index('<h2>Zone clearance</h2>'):text.index('<h2>Worst variants</h2>')]
    assert 'least -0.050 m in tour_0001; 1 of 3 measured variants below 0 m; 1 not ' \
        'measured. The 3 least clearances' in zone
    assert zone.index('tour_0001') < zone.index('tour_0002') < zone.index('tour_0000')
    assert 'tour_0003' not in zone
    assert '<td class="num">-0.050 m</td><td>FAIL</td>' in zone
    # The worst variants carry it too.
    worst = text[text.index('<h2>Worst variants</h2>'):]
    assert '<td class="num">-0.050 m</td>' in worst


def test_a_report_without_clearances_has_no_clearance_section(rows, tmp_path):
    text = write_report(rows, 'tour', tmp_path, ['world']).read_text(encoding='utf-8')
    assert 'Zone clearance' not in text and 'least zone clearance' not in text


def test_a_report_gives_each_criterions_least_margin_and_plots_the_margins(rows, tmp_path):
    assert 'margin' not in rates_table(rows)        # no variant has margins: no column
    plain = write_report(rows, 'tour', tmp_path / 'plain', ['world']).read_text(
        encoding='utf-8')
    assert 'Margins along each axis' not in plain and not (tmp_path / 'plain' /
                                                           'margins.png').exists()
    rows[0].margins = {'no_collision': 0.30, 'step 1': 20.0}
    rows[1].margins = {'no_collision': 0.05, 'step 1': -3.0}
    table = rates_table(rows)
    assert 'least margin' in table.splitlines()[0]
    lines = {line.split()[0] + (' ' + line.split()[1] if line.startswith('step') else ''):
             line for line in table.splitlines()[1:]}
    assert lines['no_collision'].rstrip().endswith('0.050 m (tour_0001)')
    assert '-3.000 s (tour_0001)' in lines['step 1']
    assert lines['verdict'].rstrip().endswith('-')
    text = write_report(rows, 'tour', tmp_path / 'out', ['world']).read_text(encoding='utf-8')
    assert '0.050 m (tour_0001)' in text
    match = re.search(r'alt="margins along each axis"', text)
    assert match and (tmp_path / 'out' / 'margins.png').read_bytes()[:8] == PNG_MAGIC


# --- the steps named by what they do ---------------------------------------------------
GOAL_A = {'goal': {'x': 4.0, 'y': 1.2, 'yaw': -1.5708, 'expect': 'any'}}
GOAL_B = {'goal': {'x': 4.0, 'y': 2.3}}
FORWARD = {'command': 'forward 0.6 m', 'expect': 'any'}
WAIT = {'wait': {'duration_s': 1.0}}


def variant_row(folder, index, steps, criteria, values=None, status='OK', **extra):
    """Return a row whose run folder (folder/runs/NAME) holds its scenario.yaml."""
    result = row(index, status, criteria, values, **extra)
    run_dir = folder / 'runs' / result.name
    run_dir.mkdir(parents=True, exist_ok=True)
    document = {'scenario': {'name': result.name, 'world': 'apartment', 'steps': steps}}
    (run_dir / 'scenario.yaml').write_text(yaml.safe_dump(document), encoding='utf-8')
    result.run_dir = str(run_dir)
    return result


def rate_lines(table):
    """Return {first column: the rest} of the rates table's rows (two spaces apart)."""
    return {line.split('  ')[0]: line for line in table.splitlines()[2:]}


def test_the_rates_table_names_each_step_by_what_it_does(tmp_path):
    steps = [GOAL_A, GOAL_B, FORWARD, WAIT]
    rows = [variant_row(tmp_path, index, steps,
                        {'step 1': True, 'step 2': index != 1, 'step 3': True,
                         'step 4': True, 'no_collision': True},
                        {'seed': index}, status='UNEXPECTED' if index == 1 else 'OK')
            for index in range(3)]
    table = rates_table(rows)
    lines = table.splitlines()
    assert [line.split('  ')[0] for line in lines[2:7]] == [
        'verdict', 'step 1: goal (4.00, 1.20)', 'step 2: goal (4.00, 2.30)',
        "step 3: command 'forward 0.6 m'", 'step 4: wait 1.0 s']
    assert '1/3' in rate_lines(table)['step 2: goal (4.00, 2.30)']
    assert 'no_collision' in rate_lines(table)
    # Nothing differs: no line about differences; the summary line follows the table.
    assert 'differs' not in table and ' by ' not in table
    assert lines[8] == '3 variants: 2 as expected, 1 unexpected, 0 errors'


def test_the_store_keeps_the_criterion_names(tmp_path):
    store_path = tmp_path / 'results.sqlite'
    with ResultsStore(store_path, 'named', 'fingerprint') as store:
        store.add(variant_row(tmp_path, 0, [GOAL_A], {'step 1': False}, {'seed': 0},
                              status='UNEXPECTED'))
    stored = read_rows(store_path)
    assert stored[0].criteria == {'step 1': False}
    assert 'step 1: goal (4.00, 1.20)' in rates_table(stored)


def test_a_step_that_differs_by_scenario_names_each_scenarios_step(tmp_path):
    patrol = [GOAL_A, GOAL_B]
    teleop = [FORWARD, WAIT, WAIT]
    rows = [variant_row(tmp_path, 0, patrol, {'step 1': True, 'step 2': False},
                        {'scenario': 'patrol'}, status='UNEXPECTED'),
            variant_row(tmp_path, 1, teleop, {'step 1': True, 'step 2': True, 'step 3': True},
                        {'scenario': 'teleop'}),
            variant_row(tmp_path, 2, patrol, {'step 1': True, 'step 2': True},
                        {'scenario': 'patrol'})]
    table = rates_table(rows)
    names = rate_lines(table)
    assert '0/3' in names['step 1 (differs by scenario)']
    assert '1/3' in names['step 2 (differs by scenario)']
    # Only the teleop scenario has a step 3: the same wherever it is.
    assert '0/1' in names['step 3: wait 1.0 s']
    assert ('step 1 by scenario: patrol: goal (4.00, 1.20); teleop: command '
            "'forward 0.6 m'") in table.splitlines()
    assert 'step 2 by scenario: patrol: goal (4.00, 2.30); teleop: wait 1.0 s' in \
        table.splitlines()
    page = write_report(rows, 'mixed', tmp_path, ['scenario']).read_text(encoding='utf-8')
    assert ('<td>step 1 (differs by scenario)<br>patrol: goal (4.00, 1.20)<br>teleop: '
            'command &#x27;forward 0.6 m&#x27;</td><td class="num">0/3</td>') in page
    assert '<td>step 3: wait 1.0 s</td><td class="num">0/1</td>' in page


def test_a_step_that_differs_within_a_scenario_says_how_many_steps_it_stands_for(tmp_path):
    # A fault axis puts a fault step first: step 1 differs from variant to variant.
    faults = [{'fault': {'kind': 'lidar_blinded', 'onset_s': onset, 'duration_s': 5.0}}
              for onset in (1.0, 4.0)] + [{'fault': {'kind': 'estop', 'onset_s': 1.0}}]
    rows = [variant_row(tmp_path, index, [fault, GOAL_A], {'step 1': True, 'step 2': True},
                        {'fault': fault['fault']}) for index, fault in enumerate(faults)]
    rows.append(variant_row(tmp_path, 3, [GOAL_B, GOAL_A], {'step 1': True, 'step 2': True},
                            {'fault': None}))
    table = rates_table(rows)
    names = rate_lines(table)
    assert '0/4' in names['step 1 (differs by variant)']
    assert '0/4' in names['step 2: goal (4.00, 1.20)']
    assert 'step 1 by variant: 4 different steps (fault, goal)' in table.splitlines()
    three = rates_table(rows[:3])
    assert 'step 1 by variant: 3 different fault steps' in three.splitlines()
    page = write_report(rows[:3], 'faults', tmp_path, ['fault']).read_text(encoding='utf-8')
    assert '<td>step 1 (differs by variant)<br>3 different fault steps</td>' in page


def test_the_worst_variants_name_their_failed_steps(tmp_path):
    rows = [variant_row(tmp_path, 0, [GOAL_A, FORWARD],
                        {'step 1': True, 'step 2': False, 'no_collision': False},
                        {'seed': 0}, status='UNEXPECTED', first_failure='step 2 ...')]
    page = write_report(rows, 'tour', tmp_path, ['seed']).read_text(encoding='utf-8')
    worst = page[page.index('<h2>Worst variants</h2>'):]
    assert '<td>step 2: command &#x27;forward 0.6 m&#x27;<br>no_collision</td>' in worst


def test_steps_are_found_from_a_relative_run_dir_or_the_results_folder(tmp_path):
    out = tmp_path / 'out'
    moved = variant_row(out, 0, [GOAL_B], {'step 1': True}, {'seed': 0})
    moved.run_dir = '/nowhere/runs/tour_0000'      # the folder was moved: out/runs/NAME
    relative = variant_row(out, 1, [GOAL_B], {'step 1': True}, {'seed': 1})
    relative.run_dir = 'runs/tour_0001'
    assert variant_steps(moved) is None
    assert variant_steps(moved, out_dir=out) == ('goal (4.00, 2.30)',)
    assert variant_steps(relative, runs_base=out) == ('goal (4.00, 2.30)',)
    assert step_labels([moved, relative], out, out) == {
        'step 1': StepLabel('step 1: goal (4.00, 2.30)')}
    page = write_report([moved, relative], 'tour', out, ['seed']).read_text(encoding='utf-8')
    assert '<td>step 1: goal (4.00, 2.30)</td><td class="num">0/2</td>' in page
    # An unreadable or invalid scenario file names nothing: the plain criterion name.
    (out / 'runs' / 'tour_0001' / 'scenario.yaml').write_text('scenario: [', encoding='utf-8')
    broken = variant_row(out, 2, [{'goal': {'x': 'north', 'y': 1.0}}], {'step 1': True})
    assert variant_steps(relative, runs_base=out) is None
    assert variant_steps(broken) is None
    assert rate_lines(rates_table([relative, broken], runs_base=out))['step 1'].split()[2] \
        == '0/2'
