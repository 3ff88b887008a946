"""Tests of sweep files, their variants and the results store (real files in tmp_path)."""

from pathlib import Path
import sqlite3
import textwrap

from mecanum_bringup.scenario_loader import load_scenario
from mecanum_bringup.sweep import (
    load_sweep, SweepError, variant_count, variant_documents, variants)
from mecanum_bringup.sweep_runner import prepare, ProgressBar
from mecanum_bringup.sweep_store import read_rows, ResultsStore, StoreError, VariantRow
import pytest

PACKAGE = Path(__file__).resolve().parents[1]
SCENARIO = """
scenario:
  name: three_goals
  world: apartment
  steps:
  - goal: {x: 5.1, y: 6.2}
  - wait: {duration_s: 1.0}
  - goal: {x: 8.0, y: 6.2}
  - goal: {x: 2.95, y: 2.0}
"""


def write(directory: Path, text: str, name: str = 'sweep.yaml') -> Path:
    path = directory / name
    path.write_text(textwrap.dedent(text))
    return path


@pytest.fixture
def folder(tmp_path):
    write(tmp_path, SCENARIO, 'three_goals.yaml')
    return tmp_path


def sweep_file(folder: Path, axes: str, head: str = '') -> Path:
    return write(folder, 'sweep:\n  name: s\n  scenario: three_goals.yaml\n' + head
                 + '  axes:\n' + textwrap.indent(textwrap.dedent(axes), '    '))


def test_a_grid_is_the_product_of_the_axes_in_axis_order(folder):
    sweep = load_sweep(sweep_file(folder, """\
        goals: [[0], [1, 2]]
        seed: [1, 2, 3]
        """))
    assert sweep.mode == 'grid' and variant_count(sweep) == 6
    found = [(v.index, v.values) for v in variants(sweep)]
    # seed comes before goals in AXES, so goals vary fastest.
    assert found == [(0, {'seed': 1, 'goals': [0]}), (1, {'seed': 1, 'goals': [1, 2]}),
                     (2, {'seed': 2, 'goals': [0]}), (3, {'seed': 2, 'goals': [1, 2]}),
                     (4, {'seed': 3, 'goals': [0]}), (5, {'seed': 3, 'goals': [1, 2]})]
    assert variants(sweep)[1].name('s') == 's_0001'
    assert variants(sweep)[1].describe() == 'seed=1 goals=[1,2]'


RANDOM = """\
    seed: {range: [10, 20]}
    floor_friction_coefficient: {uniform: [0.2, 0.4]}
    spawn: [{x: 2.95, y: 2.0}, {x: 4.8, y: 2.0, yaw: 1.0}]
    goals: {sample: 2}
    """


def test_random_variants_are_the_same_every_time_and_within_their_ranges(folder):
    head = '  mode: random\n  samples: 40\n  master_seed: 7\n'
    sweep = load_sweep(sweep_file(folder, RANDOM, head))
    first = variants(sweep)
    assert first == variants(load_sweep(sweep_file(folder, RANDOM, head)))
    assert len(first) == 40
    for variant in first:
        values = variant.values
        assert 10 <= values['seed'] < 20 and isinstance(values['seed'], int)
        assert 0.2 <= values['floor_friction_coefficient'] <= 0.4
        assert values['spawn'] in ({'x': 2.95, 'y': 2.0, 'yaw': 0.0},
                                   {'x': 4.8, 'y': 2.0, 'yaw': 1.0})
        assert len(values['goals']) == 2 and values['goals'] == sorted(set(values['goals']))
    # Draws spread over the ranges (40 draws of 10 seeds: all but a few seen).
    assert len({v.values['seed'] for v in first}) >= 7
    # More samples keep the first ones; another master seed gives other variants.
    more = variants(load_sweep(sweep_file(folder, RANDOM, head.replace('40', '60'))))
    assert more[:40] == first
    other = variants(load_sweep(sweep_file(folder, RANDOM, head.replace('7', '8'))))
    assert [v.values for v in other] != [v.values for v in first]
    # An axis's draws do not depend on the other axes.
    alone = variants(load_sweep(sweep_file(folder, 'seed: {range: [10, 20]}\n', head)))
    assert [v.values['seed'] for v in alone] == [v.values['seed'] for v in first]


def test_a_variant_becomes_a_scenario_with_its_values(folder):
    sweep = load_sweep(sweep_file(folder, """\
        seed: [5]
        floor_friction_coefficient: [0.3]
        sensor_noise_scale: [2.0]
        spawn: [{x: 4.8, y: 2.0, yaw: 1.0}]
        goals: [[0, 2]]
        person: [{speed_m_s: 1.2}]
        """))
    world = {'world': {'name': 'w', 'moving_obstacles': [
        {'name': 'person', 'radius_m': 0.25, 'speed_m_s': 0.8, 'path': [[1, 1], [2, 2]]}]}}
    document, world_document = variant_documents(sweep, variants(sweep)[0], world)
    scenario = document['scenario']
    assert scenario['name'] == 's_0000'
    assert (scenario['seed'], scenario['floor_friction_coefficient'],
            scenario['sensor_noise_scale']) == (5, 0.3, 2.0)
    assert scenario['spawn'] == scenario['initial_pose'] == {'x': 4.8, 'y': 2.0, 'yaw': 1.0}
    # Goals 0 and 2 kept, goal 1 dropped, the wait kept in its place.
    assert scenario['steps'] == [{'goal': {'x': 5.1, 'y': 6.2}}, {'wait': {'duration_s': 1.0}},
                                 {'goal': {'x': 2.95, 'y': 2.0}}]
    assert world_document['world']['moving_obstacles'][0]['speed_m_s'] == 1.2
    assert world['world']['moving_obstacles'][0]['speed_m_s'] == 0.8   # not changed
    assert sweep.scenario_document['scenario']['name'] == 'three_goals'
    missing = {'world': {'moving_obstacles': [{'name': 'cat'}]}}
    with pytest.raises(SweepError, match="no moving obstacle named 'person' .*'cat'"):
        variant_documents(sweep, variants(sweep)[0], missing)


def test_prepared_variants_load_as_scenarios_and_a_bad_one_names_the_variant(
        folder, monkeypatch):
    sweep = load_sweep(sweep_file(folder, """\
        person: [{speed_m_s: 0.4}]
        sensor_noise_scale: [0.0, 3.0]
        """))
    monkeypatch.chdir(folder)   # an output folder given relative to the working directory
    prepared = prepare(sweep, Path('check'))
    assert [p.name for p in prepared] == ['s_0000', 's_0001']
    scenario = load_scenario(folder / 'check' / 's_0001' / 'scenario.yaml')
    assert scenario.sensor_noise_scale == 3.0
    assert [m.speed_m_s for m in scenario.world.moving_obstacles
            if m.name == 'person'] == [0.4]
    bad = load_sweep(sweep_file(folder, """\
        spawn: [{x: 2.95, y: 2.0}, {x: 0.6, y: 2.0}]
        """))
    with pytest.raises(SweepError, match=r'variant 1 \(spawn=\(0.6,2,0\)\) is not a valid '
                       r'scenario: .*inside obstacle .sofa.'):
        prepare(bad, folder / 'check_bad')


BAD = [
    ('sweep: {name: s, scenario: three_goals.yaml}', "sweep.yaml:1: sweep: missing key 'axes'"),
    ('sweep:\n  name: s\n  scenario: nowhere.yaml\n  axes: {seed: [1]}\n',
     "sweep.yaml:3: sweep.scenario: no scenario file 'nowhere.yaml'"),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  axes:\n    seed: {range: [5, 5]}\n',
     'sweep.yaml:5: sweep.axes.seed: a distribution (range) needs mode: random'),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  mode: random\n  samples: 3\n'
     '  master_seed: 1\n  axes:\n    seed: {range: [5, 5]}\n',
     'sweep.yaml:8: sweep.axes.seed.range: must be [lo, hi] with lo < hi'),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  mode: random\n  axes:\n'
     '    seed: [1]\n', "sweep.yaml:1: sweep: missing key 'samples' (needed in random mode)"),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  samples: 4\n  axes: {seed: [1]}\n',
     'sweep.yaml:4: sweep.samples: is only allowed with mode: random'),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  axes:\n    seed: [1]\n'
     '    colour: [red]\n', 'sweep.yaml:6: sweep.axes.colour: unknown key'),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  axes:\n    goals: [[0, 3]]\n',
     'sweep.yaml:5: sweep.axes.goals[0]: goal index 3, but the scenario has 3 goal steps'),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  axes:\n    goals: [[2, 1]]\n',
     'sweep.yaml:5: sweep.axes.goals[0]: must be distinct indices in increasing order'),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  axes:\n    spawn:\n'
     '    - {x: 1, y: 2}\n    - {x: 1}\n', "sweep.yaml:7: sweep.axes.spawn[1]: missing key 'y'"),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  axes:\n'
     '    floor_friction_coefficient: [0.5, -1]\n',
     'sweep.yaml:5: sweep.axes.floor_friction_coefficient[1]: must be >= 0, not -1'),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  axes:\n'
     '    sensor_noise_scale: [0.5, high]\n',
     "sweep.yaml:5: sweep.axes.sensor_noise_scale[1]: must be a number, not 'high'"),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  search: {batch: 4}\n'
     '  axes: {seed: [1]}\n', 'sweep.yaml:4: sweep.search: is only allowed with mode: search'),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  mode: search\n  axes:\n'
     '    seed: [1]\n', "sweep.yaml:1: sweep: missing key 'samples' (needed in search mode)"),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  mode: search\n  samples: 8\n'
     '  master_seed: 1\n  search: {objective: luck}\n  axes: {seed: [1]}\n',
     'sweep.yaml:7: sweep.search.objective: must be one of least, steps, no_collision, '
     "stay_in_zone, max_localization_error_m, max_duration_s, not 'luck'"),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  mode: search\n  samples: 8\n'
     '  master_seed: 1\n  search: {elite_fraction: 0}\n  axes: {seed: [1]}\n',
     'sweep.yaml:7: sweep.search.elite_fraction: must be in (0, 1], not 0'),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  mode: search\n  samples: 8\n'
     '  master_seed: 1\n  search: {batch: 0}\n  axes: {seed: [1]}\n',
     'sweep.yaml:7: sweep.search.batch: must be an integer >= 1, not 0'),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  mode: sometimes\n'
     '  axes: {seed: [1]}\n',
     "sweep.yaml:4: sweep.mode: must be one of grid, random, search, not 'sometimes'"),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  axes: {seed: [1]}\nextra: 1\n',
     'sweep.yaml:5: extra: unknown top-level key (only "sweep:" is allowed)'),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  axes:\n    person: [{speed_m_s: 0}]\n',
     'sweep.yaml:5: sweep.axes.person[0].speed_m_s: must be > 0'),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  axes:\n    person: [{colour: red}]\n',
     'sweep.yaml:5: sweep.axes.person[0].colour: unknown key'),
    ('sweep:\n  name: my sweep\n  scenario: three_goals.yaml\n  axes: {seed: [1]}\n',
     "sweep.yaml:2: sweep.name: must be letters, digits, _ and - only, not 'my sweep'"),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  axes: {}\n',
     'sweep.yaml:4: sweep.axes: needs at least one axis'),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  axes:\n    seed: [1, 2\n',
     'sweep.yaml: YAML syntax error at line 6'),
    ('sweep:\n  name: s\n  scenario: three_goals.yaml\n  mode: random\n  samples: 20000\n'
     '  master_seed: 1\n  axes: {seed: [1]}\n',
     'sweep.yaml:5: sweep.samples: 20000 variants, more than the 10000 allowed'),
    ('[1, 2]', 'sweep.yaml:1: expected a top-level "sweep:" mapping'),
]


@pytest.mark.parametrize('text, message', BAD)
def test_a_bad_sweep_file_gets_a_message_naming_the_line_and_key(folder, text, message):
    with pytest.raises(SweepError) as caught:
        load_sweep(write(folder, text))
    assert str(caught.value).startswith(message), str(caught.value)


def test_a_missing_sweep_file_is_an_error(tmp_path):
    with pytest.raises(SweepError, match='no such sweep file'):
        load_sweep(tmp_path / 'nope.yaml')


def test_the_shipped_sweep_has_50_valid_variants_of_the_tour(tmp_path):
    sweep = load_sweep(PACKAGE / 'sweeps' / 'tour_variants.yaml')
    assert sweep.scenario_file.name == 'apartment_tour.yaml'
    prepared = prepare(sweep, tmp_path)
    assert len(prepared) == 50
    for item in prepared:
        steps = item.scenario_document['scenario']['steps']
        assert len([s for s in steps if 'goal' in s]) == 3


def row(index: int, status: str = 'OK') -> VariantRow:
    return VariantRow(index, f's_{index:04d}', {'seed': index}, status,
                      'pass' if status == 'OK' else 'fail', 'pass',
                      {'step 1': status == 'OK', 'no_collision': True}, '', 12.5, 30.0,
                      f'/runs/s_{index:04d}', '', 'host:1', 1000.0 + index)


def test_the_store_keeps_rows_across_opens_and_refuses_another_sweep(tmp_path):
    path = tmp_path / 'results.sqlite'
    with ResultsStore(path, 's', '{"axes": 1}') as store:
        store.add(row(0))
        store.add(row(3, 'UNEXPECTED'))
    with ResultsStore(path, 's', '{"axes": 1}') as store:
        assert store.done_indices() == {0, 3}
        assert store.rows() == [row(0), row(3, 'UNEXPECTED')]
        store.add(row(3))     # a row written again replaces the old one
        assert [r.status for r in store.rows()] == ['OK', 'OK']
    with pytest.raises(StoreError, match='holds the results of another sweep'):
        ResultsStore(path, 's', '{"axes": 2}')
    with pytest.raises(StoreError, match='holds the results of another sweep'):
        ResultsStore(path, 'other', '{"axes": 1}')
    garbage = tmp_path / 'garbage.sqlite'
    garbage.write_bytes(b'not a database at all' * 100)
    with pytest.raises(StoreError, match='not a sweep results store'):
        ResultsStore(garbage, 's', '{}')
    # Every row is committed when add returns: another connection sees it.
    with ResultsStore(path, 's', '{"axes": 1}') as store:
        store.add(row(7))
        count = sqlite3.connect(str(path)).execute('SELECT COUNT(*) FROM variants').fetchone()
        assert count == (3,)


def test_the_store_keeps_each_criterions_margin_and_reads_old_stores_without(tmp_path):
    path = tmp_path / 'results.sqlite'
    with_margins = row(1, 'UNEXPECTED')
    with_margins.margins = {'no_collision': 0.12, 'step 1': -2.5}
    with ResultsStore(path, 's', '{"axes": 1}') as store:
        store.add(with_margins)
        store.add(row(2))
    rows = read_rows(path)
    assert rows[0].margins == {'no_collision': 0.12, 'step 1': -2.5}
    assert rows[0].least_margin == -2.5
    assert (rows[1].margins, rows[1].least_margin) == ({}, None)
    # A store from before the column: read as no margins; opened, it gets the column.
    old = tmp_path / 'old.sqlite'
    db = sqlite3.connect(str(old))
    db.execute('CREATE TABLE sweep (key TEXT PRIMARY KEY, value TEXT)')
    db.executemany('INSERT INTO sweep VALUES (?, ?)', [('name', 's'), ('fingerprint', 'f')])
    db.execute('CREATE TABLE variants (idx INTEGER PRIMARY KEY, name TEXT, values_json TEXT, '
               'status TEXT, verdict TEXT, expected TEXT, criteria_json TEXT, '
               'first_failure TEXT, sim_time_s REAL, wall_time_s REAL, run_dir TEXT, '
               'error TEXT, worker TEXT, finished_at REAL)')
    db.execute("INSERT INTO variants VALUES (0, 'v', '{}', 'OK', 'pass', 'pass', '{}', '', "
               "1.0, 1.0, '', '', '', 1.0)")
    db.commit()
    db.close()
    assert read_rows(old)[0].margins == {}
    with ResultsStore(old, 's', 'f') as store:
        store.add(with_margins)
        assert [r.margins for r in store.rows()] == [{}, with_margins.margins]


def test_the_progress_line_counts_failures_and_estimates_the_rest(tmp_path):
    with open(tmp_path / 'progress.txt', 'w') as stream:
        bar = ProgressBar(10, 2, stream)
        bar.started -= 60.0     # one minute ago
        bar.advance(row(2))
        bar.advance(row(3, 'UNEXPECTED'))
    lines = (tmp_path / 'progress.txt').read_text().splitlines()
    assert lines[-1].startswith('[#########...............] 4/10 (1 failed) 1:00 elapsed, '
                                'ETA 3:00'), lines[-1]
    assert lines[-1].endswith('s_0003: UNEXPECTED')


@pytest.mark.parametrize('address', ['local:0', 'local:two', 'local:100'])
def test_a_bad_local_ray_cluster_size_is_refused_before_anything_runs(tmp_path, capsys,
                                                                      address):
    from mecanum_bringup.sweep_runner import main
    with pytest.raises(SystemExit) as stopped:
        main([str(tmp_path / 'never_read.yaml'), '--ray', address])
    assert stopped.value.code == 2
    assert f"--ray local:N needs N from 1 to 99 nodes, got '{address}'" in capsys.readouterr().err


def test_a_store_is_refused_once_a_file_its_variants_read_was_edited(folder, capsys):
    # A trap found by trying it: an edited scenario resumed from the old store gave
    # '4 variants, 4 done before, 0 to run' and the old verdicts.
    from mecanum_bringup.sweep import input_digests, input_files
    from mecanum_bringup.sweep_runner import main
    path = sweep_file(folder, 'seed: [1, 2]\n')
    sweep = load_sweep(path)
    files = input_files(sweep)
    scenario = str((folder / 'three_goals.yaml').resolve())
    world = str(load_scenario(folder / 'three_goals.yaml').world_file.resolve())
    assert {str(path.resolve()), scenario, world} <= set(files)
    assert any(name.endswith('apartment.yaml') and 'maps' in name for name in files)
    assert any(name.endswith('.pgm') for name in files)      # the map's image
    store_path = folder / 'out' / 'results.sqlite'
    with ResultsStore(store_path, sweep.name, sweep.fingerprint, input_digests(sweep)):
        pass
    # The same inputs: accepted.
    with ResultsStore(store_path, sweep.name, sweep.fingerprint, input_digests(sweep)):
        pass
    # The scenario edited (same name, same axes): refused, naming it.
    (folder / 'three_goals.yaml').write_text(
        (folder / 'three_goals.yaml').read_text().replace('x: 8.0', 'x: 7.5'))
    with pytest.raises(StoreError, match=rf'changed since .*{scenario} \(edited\)'):
        ResultsStore(store_path, sweep.name, sweep.fingerprint, input_digests(sweep))
    # And run_sweep says so and runs nothing (exit code 2).
    assert main([str(path), '--out', str(folder / 'out'), '--quiet']) == 2
    err = capsys.readouterr().err
    assert 'three_goals.yaml (edited)' in err and 'delete the store' in err
    assert not (folder / 'out' / 'runs').exists()


def test_until_failure_needs_one_job_unless_the_sweep_is_a_search(folder, capsys):
    from mecanum_bringup.sweep_runner import main
    path = sweep_file(folder, 'seed: [1, 2]\n')
    with pytest.raises(SystemExit) as stopped:
        main([str(path), '--until-failure', '--jobs', '2', '--out', str(folder / 'never')])
    assert stopped.value.code == 2
    assert '--until-failure stops between variants' in capsys.readouterr().err
    assert not (folder / 'never').exists()
