"""Tests of the sweep axes scenario, fault and fault_onset_s, and of sweeps/faults.yaml."""

from pathlib import Path
import textwrap

from mecanum_bringup.scenario_loader import load_scenario
from mecanum_bringup.scenario_model import FaultStep
from mecanum_bringup.sweep import (
    load_sweep, SweepError, variant_count, variant_documents, variants)
from mecanum_bringup.sweep_runner import prepare
import pytest
from robot_simulation.faults import FAULT_KINDS, FaultSpec

PACKAGE = Path(__file__).resolve().parents[1]
TWO_GOALS = """
scenario:
  name: two_goals
  world: apartment
  steps:
  - goal: {x: 5.1, y: 6.2}
  - wait: {duration_s: 1.0}
  - goal: {x: 2.95, y: 2.0}
"""
#: In a folder of its own, with its world given as a file relative to itself.
TELEOP = """
scenario:
  name: teleop
  world: ../worlds/flat.yaml
  map: apartment
  steps:
  - cmd_vel: {vx: 0.2, duration_s: 2.0}
  - goal: {x: 3.0, y: 2.0}
"""


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(text))
    return path


@pytest.fixture
def folder(tmp_path):
    write(tmp_path / 'two_goals.yaml', TWO_GOALS)
    write(tmp_path / 'more' / 'teleop.yaml', TELEOP)
    from robot_simulation.world import find_world
    write(tmp_path / 'worlds' / 'flat.yaml', find_world('apartment').read_text())
    (tmp_path / 'worlds' / 'flat.yaml').write_text(
        (tmp_path / 'worlds' / 'flat.yaml').read_text().replace(
            'name: apartment', 'name: flat'))
    return tmp_path


def sweep_file(folder: Path, body: str) -> Path:
    return write(folder / 'sweep.yaml', 'sweep:\n  name: s\n' + textwrap.indent(
        textwrap.dedent(body), '  '))


GRID = """\
    axes:
      scenario: [two_goals.yaml, more/teleop.yaml]
      fault:
      - {kind: lidar_blinded, duration_s: 5}
      - {kind: node_killed, node: amcl}
      - null
      fault_onset_s: [2, 10.5]
    """


def test_a_grid_crosses_scenarios_faults_and_onsets(folder):
    sweep = load_sweep(sweep_file(folder, GRID))
    # 2 scenarios x 3 faults x 2 onsets, the onset fastest, the scenario slowest.
    assert variant_count(sweep) == 12
    found = [v.values for v in variants(sweep)]
    assert found[:3] == [
        {'scenario': 'two_goals', 'fault': {'kind': 'lidar_blinded', 'duration_s': 5},
         'fault_onset_s': 2.0},
        {'scenario': 'two_goals', 'fault': {'kind': 'lidar_blinded', 'duration_s': 5},
         'fault_onset_s': 10.5},
        {'scenario': 'two_goals', 'fault': {'kind': 'node_killed', 'node': 'amcl'},
         'fault_onset_s': 2.0}]
    assert found[6]['scenario'] == 'teleop' and found[11]['fault'] is None
    assert variants(sweep)[1].describe() == (
        'scenario="two_goals" fault=lidar_blinded(duration_s=5) fault_onset_s=10.5')
    assert variants(sweep)[2].describe() == (
        'scenario="two_goals" fault=node_killed(node=amcl) fault_onset_s=2')
    assert variants(sweep)[4].describe().endswith('fault=none fault_onset_s=2')
    # The first scenario stands for the sweep's (the runner resolves paths from it).
    assert sweep.scenario_file == (folder / 'two_goals.yaml').resolve()
    assert sweep.scenario_document['scenario']['name'] == 'two_goals'
    assert sweep.goal_count == 1   # the least of the scenarios' (2 and 1)


def test_a_variant_gets_its_scenario_and_the_fault_step_first(folder):
    sweep = load_sweep(sweep_file(folder, GRID))
    all_variants = variants(sweep)
    document, world = variant_documents(sweep, all_variants[7])
    scenario = document['scenario']
    assert world is None and scenario['name'] == 's_0007'
    # The teleop scenario, its world file made absolute from its own folder.
    assert scenario['world'] == str((folder / 'worlds' / 'flat.yaml').resolve())
    assert scenario['steps'] == [
        {'fault': {'kind': 'lidar_blinded', 'duration_s': 5, 'onset_s': 10.5}},
        {'cmd_vel': {'vx': 0.2, 'duration_s': 2.0}}, {'goal': {'x': 3.0, 'y': 2.0}}]
    assert sweep.scenarios['teleop'][1]['scenario']['world'] == '../worlds/flat.yaml'
    # No fault: the scenario's own steps.
    document, _ = variant_documents(sweep, all_variants[4])
    assert [next(iter(step)) for step in document['scenario']['steps']] == [
        'goal', 'wait', 'goal']
    # Every variant is a valid scenario; the fault step loads as a FaultStep.
    prepared = prepare(sweep, folder / 'check')
    assert len(prepared) == 12
    loaded = load_scenario(folder / 'check' / 's_0002' / 'scenario.yaml')
    assert loaded.steps[0] == FaultStep(FaultSpec('node_killed', 2.0, 0.0,
                                                  (('node', 'amcl'),)))
    assert loaded.world.name == 'apartment'
    assert load_scenario(folder / 'check' / 's_0007' / 'scenario.yaml').world.name == 'flat'


def test_a_fault_without_the_onset_axis_keeps_its_own_onset(folder):
    sweep = load_sweep(sweep_file(folder, """\
        scenario: two_goals.yaml
        axes:
          goals: [[0], [1]]
          fault: [{kind: estop, onset_s: 4, duration_s: 2}]
        """))
    document, _ = variant_documents(sweep, variants(sweep)[1])
    assert document['scenario']['steps'] == [
        {'fault': {'kind': 'estop', 'onset_s': 4, 'duration_s': 2}},
        {'wait': {'duration_s': 1.0}}, {'goal': {'x': 2.95, 'y': 2.0}}]


def test_random_faults_and_onsets_are_drawn_from_their_axes(folder):
    body = """\
        scenario: two_goals.yaml
        mode: random
        samples: 30
        master_seed: 3
        axes:
          fault: [{kind: imu_silent}, {kind: lidar_silent, duration_s: 1}]
          fault_onset_s: {uniform: [5, 15]}
        """
    first = variants(load_sweep(sweep_file(folder, body)))
    assert first == variants(load_sweep(sweep_file(folder, body)))
    kinds = {v.values['fault']['kind'] for v in first}
    assert kinds == {'imu_silent', 'lidar_silent'}
    onsets = [v.values['fault_onset_s'] for v in first]
    assert all(5.0 <= onset <= 15.0 for onset in onsets)
    assert max(onsets) - min(onsets) > 5.0   # 30 draws spread over the 10 s


HEAD = 'sweep:\n  name: s\n'
BAD = [
    (HEAD + '  scenario: two_goals.yaml\n  axes:\n    fault: [{kind: laser_off}]\n',
     'sweep.yaml:5: sweep.axes.fault[0].kind: must be one of lidar_blinded, '),
    (HEAD + '  scenario: two_goals.yaml\n  axes:\n    fault:\n    - {kind: imu_silent}\n'
     '    - {kind: encoder_stuck}\n',
     'sweep.yaml:7: sweep.axes.fault[1].wheel: required for encoder_stuck'),
    (HEAD + '  scenario: two_goals.yaml\n  axes:\n    fault: [{kind: imu_silent, onset_s: 3}]\n'
     '    fault_onset_s: [1, 2]\n',
     'sweep.yaml:5: sweep.axes.fault[0].onset_s: is given by axes.fault_onset_s'),
    (HEAD + '  scenario: two_goals.yaml\n  axes:\n    fault_onset_s: [1, 2]\n',
     'sweep.yaml:5: sweep.axes.fault_onset_s: needs the fault axis'),
    (HEAD + '  scenario: two_goals.yaml\n  axes:\n    fault: [{kind: imu_silent}]\n'
     '    fault_onset_s: [1, -2]\n',
     'sweep.yaml:6: sweep.axes.fault_onset_s[1]: must be >= 0, not -2'),
    (HEAD + '  scenario: two_goals.yaml\n  axes:\n    fault: {kind: imu_silent}\n',
     'sweep.yaml:5: sweep.axes.fault: must be a non-empty list of values (no distribution '
     'for fault)'),
    (HEAD + '  scenario: two_goals.yaml\n  axes:\n    fault: [{kind: imu_silent}]\n'
     '    fault_onset_s: {uniform: [1, 2]}\n',
     'sweep.yaml:6: sweep.axes.fault_onset_s: a distribution (uniform) needs mode: random'),
    (HEAD + '  scenario: two_goals.yaml\n  axes:\n    scenario: [two_goals.yaml]\n',
     'sweep.yaml:3: sweep.scenario: is not allowed with axes.scenario'),
    (HEAD + '  axes:\n    seed: [1]\n', "sweep.yaml:1: sweep: missing key 'scenario'"),
    (HEAD + '  axes:\n    scenario: [two_goals.yaml, nowhere.yaml]\n',
     "sweep.yaml:4: sweep.axes.scenario[1]: no scenario file 'nowhere.yaml'"),
    (HEAD + '  axes:\n    scenario: [two_goals.yaml, ./two_goals.yaml]\n',
     "sweep.yaml:4: sweep.axes.scenario[1]: scenario 'two_goals' is already in the axis"),
    (HEAD + '  axes:\n    scenario: []\n',
     'sweep.yaml:4: sweep.axes.scenario: must be a non-empty list of scenario names'),
    (HEAD + '  axes:\n    scenario: [two_goals.yaml, more/teleop.yaml]\n'
     '    goals: [[0, 1]]\n',
     'sweep.yaml:5: sweep.axes.goals[0]: goal index 1, but the scenario has 1 goal steps'),
    (HEAD + '  axes:\n    scenario: [two_goals.yaml, more/teleop.yaml]\n'
     '    person: [{speed_m_s: 1.0}]\n',
     'sweep.yaml:5: sweep.axes.person: the scenarios of axes.scenario are in different '
     'worlds'),
]


@pytest.mark.parametrize('text, message', BAD)
def test_a_bad_fault_or_scenario_axis_names_the_line_and_key(folder, text, message):
    with pytest.raises(SweepError) as caught:
        load_sweep(write(folder / 'sweep.yaml', text))
    assert str(caught.value).startswith(message), str(caught.value)


def test_the_shipped_fault_sweep_has_every_kind_at_3_onsets_on_2_scenarios(tmp_path):
    sweep = load_sweep(PACKAGE / 'sweeps' / 'faults.yaml')
    assert list(sweep.axes) == ['scenario', 'fault', 'fault_onset_s']
    assert sweep.axes['scenario'] == ['fault_border_patrol', 'fault_teleop_near_walls']
    assert len(sweep.axes['fault_onset_s']) == 3
    faults = sweep.axes['fault']
    assert {fault['kind'] for fault in faults} == set(FAULT_KINDS)
    nodes = {'twist_mux', 'collision_monitor', 'zone_guard', 'amcl'}
    for kind in ('node_frozen', 'node_killed'):
        assert {f['node'] for f in faults if f['kind'] == kind} == nodes, kind
    # 12 simulator kinds, 8 node faults, amcl diverged, the e-stop
    assert len(faults) == 12 + 2 * 4 + 1 + 1
    assert variant_count(sweep) == 2 * 22 * 3 == 132
    prepared = prepare(sweep, tmp_path)
    assert len(prepared) == 132
    for item in prepared:
        scenario = item.scenario_document['scenario']
        first = scenario['steps'][0]['fault']
        assert first['onset_s'] == item.variant.values['fault_onset_s']
        assert first['kind'] == item.variant.values['fault']['kind']
    for name in sweep.axes['scenario']:
        criteria = sweep.scenarios[name][1]['scenario']['criteria']
        assert criteria['no_collision'] is True and criteria['stay_in_zone'] is True
        assert criteria['fault_reactions'] is True
