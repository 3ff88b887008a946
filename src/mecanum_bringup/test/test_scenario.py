"""Tests of the scenario files (real files in tmp_path and scenarios/) and of judge()."""

import dataclasses
import math
from pathlib import Path
import re
import shutil
import textwrap

from mecanum_bringup.scenario_judge import (
    footprint_clearances, judge, localization_errors, min_zone_clearance_m, nearest_obstacles,
    obstacle_clearances, track_array)
from mecanum_bringup.scenario_loader import (
    build_world, find_scenarios, load_scenario, scenario_world_document, ScenarioError)
from mecanum_bringup.scenario_model import (
    CmdVelStep, CommandStep, Criteria, FreezeStep, GoalStep, NAVIGATE_TO_POSE_ERRORS, RunRecord,
    StepResult, WaitStep, WaypointsStep)
from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_map_server.map_io import find_map_file
from mecanum_safety.zone import make_zone
import numpy as np
import pytest
from robot_simulation.world import find_world, load_world
import yaml

PACKAGE = Path(__file__).resolve().parents[1]
SCENARIOS = PACKAGE / 'scenarios'
APARTMENT = load_world(find_world('apartment'))
ROBOT = load_robot_config(default_config_path())
HALF_PI = math.pi / 2


def write(directory: Path, text: str, name: str = 'tour.yaml') -> Path:
    path = directory / name
    path.write_text(textwrap.dedent(text))
    return path


MINIMAL = """
scenario:
  name: minimal
  world: apartment
  steps:
  - goal: {x: 5.1, y: 6.2}
"""

FULL = """
scenario:
  name: apartment_tour
  description: 'Visits every room'
  world: apartment
  map: apartment
  spawn: {x: 4.8, y: 1.5, yaw: 1.5}
  initial_pose: {x: 4.9, y: 1.4, yaw: 1.4}
  floor_friction_coefficient: 0.3
  sensor_noise_scale: 2.5
  board: firmware
  real_time_factor: 2.0
  seed: 7
  authorised_zone: [[0.1, 0.1], [9.9, 0.1], [9.9, 7.9], [0.1, 7.9]]
  moving_obstacles:
  - {name: cat, radius_m: 0.15, speed_m_s: 0.3, path: [[3.0, 6.4], [5.5, 6.4]], loop: false}
  steps:
  - goal: {x: 5.1, y: 6.2, yaw: 0.0, timeout_s: 90}
  - goal: {x: 12.0, y: 3.0, yaw: 0.0, expect: refused, error: GOAL_OUTSIDE_ZONE}
  - command: 'forward 1.5 m'
    timeout_s: 20
  - cmd_vel: {vx: 0.3, vy: -0.1, wz: 0.5, duration_s: 3.0}
  - wait: {duration_s: 2.0}
  - goal: {x: 1.0, y: 1.0, expect: any}
  - goal: {x: 6.0, y: 1.0, expect: refused}
  - command: 'rotate left 90 deg'
  criteria:
    max_duration_s: 300
    no_collision: false
    stay_in_zone: true
    max_localization_error_m: 0.2
  expect: fail
"""


# --- loading valid files -------------------------------------------------------------


def test_a_minimal_file_gets_the_world_defaults(tmp_path):
    scenario = load_scenario(write(tmp_path, MINIMAL))
    assert scenario.name == 'minimal'
    assert scenario.world_file == find_world('apartment')
    assert scenario.map_name == 'apartment'
    assert scenario.spawn == (2.95, 2.0, 0.0) == APARTMENT.robot_start
    assert scenario.initial_pose == scenario.spawn
    assert scenario.authorised_zone == APARTMENT.test_zone
    assert (scenario.floor_friction_coefficient, scenario.sensor_noise_scale,
            scenario.real_time_factor, scenario.seed) == (0.0, 1.0, 1.0, 0)
    assert scenario.board == 'core'
    assert scenario.criteria == Criteria(None, True, True, None)
    assert scenario.expect == 'pass'
    assert scenario.steps == (GoalStep(5.1, 6.2, 0.0, 120.0, 'reached', None),)
    assert scenario.description == ''
    assert scenario.moving_obstacles == ()


def test_a_full_file_loads_every_field(tmp_path):
    scenario = load_scenario(write(tmp_path, FULL))
    assert scenario.name == 'apartment_tour'
    assert scenario.description == 'Visits every room'
    assert scenario.spawn == (4.8, 1.5, 1.5)
    assert scenario.initial_pose == (4.9, 1.4, 1.4)
    assert scenario.floor_friction_coefficient == 0.3
    assert scenario.sensor_noise_scale == 2.5
    assert scenario.board == 'firmware'
    assert scenario.real_time_factor == 2.0
    assert scenario.seed == 7
    assert scenario.authorised_zone == make_zone([(0.1, 0.1), (9.9, 0.1), (9.9, 7.9),
                                                  (0.1, 7.9)])
    goal, refused, command, cmd_vel, wait, any_goal, any_refusal, rotate = scenario.steps
    assert goal == GoalStep(5.1, 6.2, 0.0, 90.0, 'reached', None)
    assert refused.expect == 'refused' and refused.error_code == 9100
    assert any_goal.expect == 'any' and any_goal.error_code is None
    assert any_refusal.expect == 'refused' and any_refusal.error is None
    # forward 1.5 m at the default 0.2 m/s: 7.5 s; the file gives the timeout.
    assert isinstance(command, CommandStep) and command.text == 'forward 1.5 m'
    assert command.timeout_s == 20.0
    assert math.isclose(command.motion.duration_s, 7.5) and command.motion.vx == 0.2
    # rotate left 90 deg at 0.5 rad/s: pi/2 / 0.5 = 3.14 s, + 10 s default margin.
    assert math.isclose(rotate.timeout_s, math.pi + 10.0)
    assert cmd_vel == CmdVelStep(0.3, -0.1, 0.5, 3.0, 'scenario', 'cmd_vel_scenario')
    assert command.expect == 'done'
    assert wait == WaitStep(2.0)
    assert [s.kind for s in scenario.steps] == [
        'goal', 'goal', 'command', 'cmd_vel', 'wait', 'goal', 'goal', 'command']
    assert scenario.criteria == Criteria(300.0, False, True, 0.2)
    assert scenario.expect == 'fail'
    assert [m.name for m in scenario.world.moving_obstacles] == ['person', 'cat']
    assert scenario.world.robot_start == pytest.approx((4.8, 1.5, 1.5))
    assert len(scenario.goals) == 4


def test_the_world_document_is_the_base_world_with_spawn_zone_and_obstacles(tmp_path):
    scenario = load_scenario(write(tmp_path, FULL.replace(
        '[[0.1, 0.1], [9.9, 0.1], [9.9, 7.9], [0.1, 7.9]]',
        '[[0.1, 0.1], [9.9, 0.1], [9.9, 3.95], [0.1, 3.95]]')))
    document = scenario_world_document(scenario)
    base = yaml.safe_load(find_world('apartment').read_text())['world']
    world = document['world']
    assert world['robot_start'] == {'x_m': 4.8, 'y_m': 1.5,
                                    'yaw_deg': pytest.approx(math.degrees(1.5))}
    assert world['test_zone'] == {
        'frame_id': 'map', 'include': [[0.1, 0.1], [9.9, 0.1], [9.9, 3.95], [0.1, 3.95]]}
    assert world['moving_obstacles'] == base['moving_obstacles'] + [
        {'name': 'cat', 'radius_m': 0.15, 'speed_m_s': 0.3,
         'path': [[3.0, 6.4], [5.5, 6.4]], 'loop': False}]
    for key in ('name', 'bounds_m', 'walls', 'furniture'):
        assert world[key] == base[key]
    # The runner writes it anywhere: it loads as a world file.
    path = tmp_path / 'elsewhere' / 'scenario_world.yaml'
    path.parent.mkdir()
    path.write_text(yaml.safe_dump(document))
    loaded = load_world(path)
    assert loaded.name == 'apartment'
    assert loaded.in_test_zone(4.8, 1.5) and not loaded.in_test_zone(5.1, 6.2)


def test_world_and_map_paths_are_relative_to_the_file(tmp_path):
    worlds = tmp_path / 'worlds'
    worlds.mkdir()
    shutil.copy(find_world('apartment'), worlds / 'flat.yaml')
    map_yaml = find_map_file('apartment')
    maps = tmp_path / 'maps'
    maps.mkdir()
    for source in (map_yaml, map_yaml.with_suffix('.pgm')):
        shutil.copy(source, maps / source.name)
    scenarios = tmp_path / 'scenarios'
    scenarios.mkdir()
    path = write(scenarios, MINIMAL.replace('world: apartment',
                                            'world: ../worlds/flat.yaml\n  map: ../maps/'
                                            'apartment.yaml'))
    scenario = load_scenario(path)
    assert scenario.world_file == (worlds / 'flat.yaml').resolve()
    assert scenario.map_name == str((maps / 'apartment.yaml').resolve())
    assert scenario.world.name == 'apartment'  # the copy's name key, not its file name


def test_a_zone_with_an_exclusion_reaches_the_world_and_the_judge(tmp_path):
    text = MINIMAL + textwrap.indent(textwrap.dedent("""\
        authorised_zone:
          include: [[0.1, 0.1], [9.9, 0.1], [9.9, 3.95], [0.1, 3.95]]
          exclude:
          - [[5.5, 2.5], [6.5, 2.5], [6.5, 3.9], [5.5, 3.9]]
        """), '  ')
    scenario = load_scenario(write(tmp_path, text))
    zone = scenario.authorised_zone
    assert len(zone.exclude) == 1
    world = build_world(scenario_world_document(scenario))
    # The simulator's world holds the same zone: inside, in the excluded doorway, outside.
    assert world.test_zone == zone
    assert world.in_test_zone(3.0, 2.0) and not world.in_test_zone(6.0, 3.0)
    assert not world.in_test_zone(3.0, 5.0)
    # The judge: a true pose in the excluded doorway is a zone exit.
    record = RunRecord(truth=np.array([[0.0, 3.0, 2.0, 0.0], [4.0, 6.0, 3.0, 0.0]]),
                       step_results=[StepResult('goal', 'reached', 0, '', 0.0, 5.0)])
    failed = judge(scenario, record).first_failure
    assert failed.name == 'stay_in_zone'
    # (6, 3) is 0.5 m inside the exclusion: -0.5 - 0.2 = -0.7 m.
    assert failed.detail == ('stay_in_zone: least clearance -0.700 m at t=4.0 s (6.00, 3.00): '
                             'the footprint (radius 0.20 m) left the zone')


def test_new_steps_and_command_expectations_load(tmp_path):
    scenario = load_scenario(write(tmp_path, MINIMAL.replace(
        '  - goal: {x: 5.1, y: 6.2}\n', """\
  - cmd_vel: {vx: 0.3, duration_s: 2.0, source: teleop_keyboard}
  - freeze: {node: amcl, duration_s: 6.0}
  - command: 'forward 3 m'
    expect: stopped
  - command: 'strafe right 3 m'
    expect: rejected
""")))
    teleop, freeze, stopped, rejected = scenario.steps
    assert teleop == CmdVelStep(0.3, 0.0, 0.0, 2.0, 'teleop_keyboard', 'cmd_vel_teleop')
    assert freeze == FreezeStep('amcl', 6.0) and freeze.describe() == 'freeze amcl for 6.0 s'
    assert (stopped.expect, rejected.expect) == ('stopped', 'rejected')
    record = RunRecord(truth=np.array([[0.0, 3.0, 2.0, 0.0]]), step_results=[
        StepResult('cmd_vel', 'done', 0, '', 0.0, 2.0),
        StepResult('freeze', 'done', 0, '', 2.0, 2.0),
        StepResult('command', 'stopped', 0, 'stopped: forward blocked by collision_monitor '
                   'STOP PolygonStop', 2.0, 6.0),
        StepResult('command', 'done', 0, '', 6.0, 21.0)])
    verdict = judge(scenario, record)
    assert [c.passed for c in verdict.criteria[:4]] == [True, True, True, False]
    assert verdict.criteria[3].detail == (
        "step 4 command 'strafe right 3 m': done in 15.0 s (expected rejected)")


def test_a_waypoints_step_loads_and_is_judged_on_missed_waypoints(tmp_path):
    scenario = load_scenario(write(tmp_path, MINIMAL.replace(
        '  - goal: {x: 5.1, y: 6.2}\n', """\
  - waypoints:
      poses: [{x: 3.5, y: 3.0}, {x: 1.5, y: 1.2, yaw: -1.5708}]
  - goal: {x: 5.1, y: 6.2}
  - waypoints: {poses: [{x: 2.95, y: 2.0}], timeout_s: 30}
""")))
    first, goal, last = scenario.steps
    assert first == WaypointsStep(((3.5, 3.0, 0.0), (1.5, 1.2, -1.5708)), 240.0)
    assert last == WaypointsStep(((2.95, 2.0, 0.0),), 30.0)
    assert first.describe() == 'waypoints (3.50, 3.00) -> (1.50, 1.20)'
    assert scenario.goal_poses == [(3.5, 3.0, 0.0), (1.5, 1.2, -1.5708), (5.1, 6.2, 0.0),
                                   (2.95, 2.0, 0.0)]
    record = RunRecord(truth=np.array([[0.0, 3.0, 2.0, 0.0]]), step_results=[
        StepResult('waypoints', 'reached', 0, '', 0.0, 30.0),
        StepResult('goal', 'reached', 0, '', 30.0, 60.0),
        StepResult('waypoints', 'failed', 9103, 'waypoint 1 missed: NO_VALID_PATH (9103)',
                   60.0, 61.0)])
    verdict = judge(scenario, record)
    assert [c.passed for c in verdict.criteria[:3]] == [True, True, False]
    assert verdict.criteria[0].detail == (
        'step 1 waypoints (3.50, 3.00) -> (1.50, 1.20): reached in 30.0 s')
    assert verdict.criteria[2].detail == (
        'step 3 waypoints (2.95, 2.00): failed in 1.0 s: waypoint 1 missed: NO_VALID_PATH '
        '(9103) (expected reached)')


def test_an_empty_zone_means_no_zone(tmp_path):
    scenario = load_scenario(write(tmp_path, MINIMAL + '  authorised_zone: []\n'))
    assert scenario.authorised_zone is None
    assert 'test_zone' not in scenario_world_document(scenario)['world']


def test_find_scenarios_lists_yaml_files_sorted(tmp_path):
    for name in ('b.yaml', 'a.yaml', 'notes.txt'):
        (tmp_path / name).write_text('x')
    (tmp_path / 'sub.yaml').mkdir()
    assert find_scenarios(tmp_path) == [tmp_path / 'a.yaml', tmp_path / 'b.yaml']
    assert find_scenarios(tmp_path / 'notes.txt') == [tmp_path / 'notes.txt']
    with pytest.raises(ScenarioError, match='no such scenario file or folder'):
        find_scenarios(tmp_path / 'missing')


def test_the_error_table_matches_the_navigator_codes():
    from mecanum_navigation.navigator import navigator
    codes = {name: value for name, value in vars(navigator).items()
             if re.fullmatch(r'[A-Z_]+', name) and isinstance(value, int) and
             (value == 0 or value >= 9000)}
    assert codes == NAVIGATE_TO_POSE_ERRORS


# --- bad files -----------------------------------------------------------------------

BAD_CASES = [
    ('', 'expected a top-level "scenario:" mapping'),
    ('[1, 2]', 'expected a top-level "scenario:" mapping'),
    ('scenario: {name: a}\nextra: 1', 'extra: unknown top-level key'),
    ('scenario: [1]', 'must be a mapping'),
    ('scenario: {name: a, world: apartment, steps: [{wait: {duration_s: 1}}], colour: red}',
     'colour: unknown key (allowed: name, world, steps, description'),
    ('scenario: {world: apartment, steps: [{wait: {duration_s: 1}}]}',
     "scenario: missing key 'name'"),
    ('scenario: {name: a, world: apartment}', "scenario: missing key 'steps'"),
    ('scenario: {name: my tour, world: apartment, steps: [{wait: {duration_s: 1}}]}',
     "name: must be letters, digits, _ and - only, not 'my tour'"),
    ('scenario: {name: a, world: atlantis, steps: [{wait: {duration_s: 1}}]}',
     "world: unknown world 'atlantis'"),
    ('scenario: {name: a, world: worlds/nope.yaml, steps: [{wait: {duration_s: 1}}]}',
     "world: no world file 'worlds/nope.yaml'"),
    ('scenario: {name: a, world: apartment, map: nowhere, steps: [{wait: {duration_s: 1}}]}',
     "map: 'nowhere': no map file"),
    ('scenario: {name: a, world: apartment, map: maps/x.yaml, steps: [{wait: {duration_s: 1}}]}',
     "map: no map file 'maps/x.yaml'"),
    ('scenario: {name: a, world: apartment, description: 5, steps: [{wait: {duration_s: 1}}]}',
     'description: must be a string'),
]

# Bodies appended to a valid scenario header: (extra lines, expected message).
HEADER = 'scenario:\n  name: a\n  world: apartment\n'
STEPS = '  steps:\n  - wait: {duration_s: 1.0}\n'
BAD_BODIES = [
    ('  spawn: {x: 0.6, y: 2.0}\n' + STEPS, "spawn: (0.6, 2) is inside obstacle 'sofa'"),
    ('  spawn: {x: 20.0, y: 2.0}\n' + STEPS, 'spawn: (20, 2) is outside bounds_m'),
    ('  spawn: {x: 5.8, y: 2.0}\n' + STEPS, 'spawn: (5.8, 2) is only 0.150 m from obstacle'),
    ('  spawn: {x: 2.0, y: 2.0, yaw: north}\n' + STEPS,
     "spawn.yaw: must be a number, not 'north'"),
    ('  spawn: {x: 2.0}\n' + STEPS, "spawn: missing key 'y'"),
    ('  spawn: {x: 2.0, y: 2.0, z: 1}\n' + STEPS, 'spawn.z: unknown key (allowed: x, y, yaw)'),
    ('  spawn: {x: 5.0, y: 2.9}\n' + STEPS,
     "spawn: the world's moving obstacle 'person': path passes through robot_start"),
    ('  initial_pose: {x: .nan, y: 1}\n' + STEPS, 'initial_pose.x: must be a finite number'),
    ('  floor_friction_coefficient: -0.1\n' + STEPS, 'floor_friction_coefficient: must be >= 0'),
    ('  sensor_noise_scale: -1\n' + STEPS, 'sensor_noise_scale: must be >= 0, not -1'),
    ('  sensor_noise_scale: .nan\n' + STEPS, 'sensor_noise_scale: must be a finite number'),
    ('  board: esp32\n' + STEPS, "board: must be one of core, firmware, not 'esp32'"),
    ('  real_time_factor: 0\n' + STEPS, 'real_time_factor: must be > 0, not 0'),
    ('  real_time_factor: fast\n' + STEPS, "real_time_factor: must be a number, not 'fast'"),
    ('  seed: 1.5\n' + STEPS, 'seed: must be an integer >= 0, not 1.5'),
    ('  seed: true\n' + STEPS, 'seed: must be an integer >= 0, not True'),
    ('  seed: -1\n' + STEPS, 'seed: must be an integer >= 0, not -1'),
    ('  authorised_zone: [[0, 0], [1, 1]]\n' + STEPS,
     'authorised_zone: the polygon needs at least 3 points'),
    ('  authorised_zone: [[0, 0], [9, 7], [9, 0], [0, 7]]\n' + STEPS,
     'authorised_zone: the polygon is self-intersecting'),
    ('  authorised_zone: [[0, 0], [9, .inf], [0, 7]]\n' + STEPS,
     'authorised_zone[1]: coordinates must be finite'),
    ('  authorised_zone: [[0, 0], [9], [0, 7]]\n' + STEPS,
     'authorised_zone[1]: must be an [x, y] pair of numbers'),
    ('  authorised_zone: 5\n' + STEPS, 'authorised_zone: must be a list of [x, y] points'),
    ('  authorised_zone: {include: [[0, 0], [9, 0], [9, 7]], exclude: [[[8, 1], [12, 1], '
     '[8, 2]]]}\n' + STEPS, 'authorised_zone.exclude[0]: vertex 1 is outside the inclusion'),
    ('  authorised_zone: {exclude: []}\n' + STEPS, 'authorised_zone: include (the inclusion '
     'polygon) is required'),
    (STEPS + '  - freeze: {node: amcl}\n', "steps[1].freeze: missing key 'duration_s'"),
    (STEPS + '  - cmd_vel: {vx: 0.1, duration_s: 1, source: radio}\n',
     'steps[1].cmd_vel.source: must be one of'),
    (STEPS + "  - command: 'forward 1 m'\n    expect: crashed\n",
     'steps[1].expect: must be one of done, stopped, rejected, any'),
    ('  authorised_zone: [[5, 5], [9, 5], [9, 7]]\n' + STEPS,
     'spawn: (2.95, 2) is outside the authorised_zone'),
    ('  moving_obstacles: {name: cat}\n' + STEPS, 'moving_obstacles: must be a list'),
    ('  moving_obstacles: [cat]\n' + STEPS, 'moving_obstacles[0]: must be a mapping'),
    ('  moving_obstacles: [{name: cat, radius_m: -1, speed_m_s: 1, path: [[1, 1], [2, 2]]}]\n'
     + STEPS, "moving_obstacles[0]: 'cat': radius_m must be > 0, not -1"),
    ('  moving_obstacles: [{name: cat, radius_m: 0.2, speed_m_s: 1, path: [[1, 1], [2, 2]], '
     'colour: red}]\n' + STEPS, 'moving_obstacles[0].colour: unknown key (allowed: name, '
     'radius_m, speed_m_s, path, loop)'),
    ('  moving_obstacles: [{radius_m: 0.2, speed_m_s: 1, path: [[1, 1], [2, 2]]}]\n' + STEPS,
     "moving_obstacles[0]: missing key 'name'"),
    ('  moving_obstacles: [{name: cat, radius_m: 0.2, speed_m_s: 1, path: [[3, 6], [3, 3]]}]\n'
     + STEPS, "moving_obstacles[0]: 'cat': path runs into 'hallway_north_w'"),
    ('  moving_obstacles: [{name: cat, radius_m: 0.2, speed_m_s: 1, path: [[2, 3], [4, 1]]}]\n'
     + STEPS, "moving_obstacles[0]: 'cat': path passes through robot_start"),
    ('  steps: []\n', 'steps: must be a non-empty list of steps'),
    ('  steps: {goal: {x: 1, y: 1}}\n', 'steps: must be a non-empty list of steps'),
    ('  steps:\n  - goal: {x: 1, y: 1}\n    wait: {duration_s: 1}\n',
     'steps[0]: needs exactly one of goal, waypoints, command, cmd_vel, wait, freeze, fault, '
     'got goal, wait'),
    ('  steps:\n  - fly: {x: 1}\n', 'steps[0]: needs exactly one of goal, waypoints, command, '
     'cmd_vel, wait, freeze, fault, got none'),
    ('  steps:\n  - waypoints: {poses: []}\n',
     'steps[0].waypoints.poses: must be a non-empty list of poses {x, y, yaw}, not []'),
    ('  steps:\n  - waypoints: [{x: 1, y: 2}]\n',
     'steps[0].waypoints: must be a mapping with keys poses'),
    ('  steps:\n  - waypoints: {poses: [{x: 1, y: 2}, {x: 3}]}\n',
     "steps[0].waypoints.poses[1]: missing key 'y'"),
    ('  steps:\n  - waypoints: {poses: [{x: 1, y: 2}], timeout_s: -5}\n',
     'steps[0].waypoints.timeout_s: must be > 0, not -5'),
    ('  steps:\n  - waypoints: {poses: [{x: 1, y: 2}], expect: refused}\n',
     'steps[0].waypoints.expect: unknown key (allowed: poses, timeout_s)'),
    ('  steps:\n  - forward 1 m\n', 'steps[0]: must be a mapping with one of goal'),
    ('  steps:\n  - wait: {duration_s: 1}\n  - goal: {x: 1}\n', "steps[1].goal: missing key 'y'"),
    ('  steps:\n  - wait: {duration_s: 1}\n  - goal: {x: 1, y: 2, yaw: north}\n',
     "steps[1].goal.yaw: must be a number, not 'north'"),
    ('  steps:\n  - goal: {x: .nan, y: 2}\n', 'steps[0].goal.x: must be a finite number'),
    ('  steps:\n  - goal: {x: 1, y: 2, speed: 3}\n', 'steps[0].goal.speed: unknown key'),
    ('  steps:\n  - goal: {x: 1, y: 2, timeout_s: 0}\n',
     'steps[0].goal.timeout_s: must be > 0, not 0'),
    ('  steps:\n  - goal: {x: 1, y: 2, expect: arrived}\n',
     "steps[0].goal.expect: must be one of reached, refused, any, not 'arrived'"),
    ('  steps:\n  - goal: {x: 1, y: 2, error: GOAL_IN_OBSTACLE}\n',
     'steps[0].goal.error: is only allowed with expect: refused'),
    ('  steps:\n  - goal: {x: 1, y: 2, expect: refused, error: WALL}\n',
     'steps[0].goal.error: must be a NavigateToPose error code, one of UNKNOWN'),
    ('  steps:\n  - goal: {x: 1, y: 2, expect: refused, error: NONE}\n',
     'steps[0].goal.error: must be a NavigateToPose error code'),
    ('  steps:\n  - goal: {x: 1, y: 2}\n    timeout_s: 5\n',
     'steps[0].timeout_s: unknown key (allowed: goal)'),
    ('  steps:\n  - command: fly 2 m\n', "steps[0].command: 'fly 2 m': unknown command 'fly'"),
    ('  steps:\n  - command: forward 1 m at 3 m/s\n',
     "steps[0].command: 'forward 1 m at 3 m/s': speed 3 exceeds the limit 0.5"),
    ('  steps:\n  - command: 5\n', 'steps[0].command: must be a text command, not 5'),
    ('  steps:\n  - command: forward 1 m\n    timeout_s: -1\n',
     'steps[0].timeout_s: must be > 0, not -1'),
    ('  steps:\n  - cmd_vel: {vx: 0.1}\n', "steps[0].cmd_vel: missing key 'duration_s'"),
    ('  steps:\n  - cmd_vel: {vx: 5, duration_s: 1}\n',
     "steps[0].cmd_vel.vx: 5 exceeds the robot's max_velocity_x_m_s"),
    ('  steps:\n  - cmd_vel: {vy: -5, duration_s: 1}\n',
     "steps[0].cmd_vel.vy: -5 exceeds the robot's max_velocity_y_m_s"),
    ('  steps:\n  - cmd_vel: {wz: .inf, duration_s: 1}\n',
     'steps[0].cmd_vel.wz: must be a finite number'),
    ('  steps:\n  - cmd_vel: {vz: 1, duration_s: 1}\n', 'steps[0].cmd_vel.vz: unknown key'),
    ('  steps:\n  - wait: {duration_s: long}\n',
     "steps[0].wait.duration_s: must be a number, not 'long'"),
    ('  steps:\n  - wait: 2\n', 'steps[0].wait: must be a mapping with keys duration_s'),
    (STEPS + '  criteria: {max_speed: 1}\n', 'criteria.max_speed: unknown key'),
    (STEPS + '  criteria: {no_collision: yes please}\n',
     "criteria.no_collision: must be true or false, not 'yes please'"),
    (STEPS + '  criteria: {stay_in_zone: 1}\n', 'criteria.stay_in_zone: must be true or false'),
    (STEPS + '  criteria: {max_localization_error_m: -1}\n',
     'criteria.max_localization_error_m: must be > 0, not -1'),
    (STEPS + '  criteria: {max_duration_s: 0}\n', 'criteria.max_duration_s: must be > 0'),
    (STEPS + '  criteria: [no_collision]\n', 'criteria: must be a mapping'),
    (STEPS + '  expect: maybe\n', "expect: must be one of pass, fail, not 'maybe'"),
]


@pytest.mark.parametrize('text, message', BAD_CASES + [(HEADER + body, message)
                                                       for body, message in BAD_BODIES])
def test_a_bad_file_gets_a_message_naming_the_file_and_key(tmp_path, text, message):
    path = write(tmp_path, text, 'bad.yaml')
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    assert str(caught.value).startswith('bad.yaml: ')
    assert message in str(caught.value)


def test_yaml_syntax_errors_and_missing_files_are_reported(tmp_path):
    path = write(tmp_path, 'scenario:\n  name: [a\n', 'bad.yaml')
    with pytest.raises(ScenarioError, match=r'^bad.yaml: YAML syntax error at line \d+'):
        load_scenario(path)
    with pytest.raises(ScenarioError, match='no such scenario file'):
        load_scenario(tmp_path / 'missing.yaml')
    (tmp_path / 'binary.yaml').write_bytes(b'\xff\xfe\x00')
    with pytest.raises(ScenarioError, match='cannot read scenario file'):
        load_scenario(tmp_path / 'binary.yaml')


# --- judging -------------------------------------------------------------------------

JUDGED = """
scenario:
  name: judged
  world: apartment
  steps:
  - goal: {x: 5.1, y: 6.2, timeout_s: 90}
  - goal: {x: 3.5, y: 6.3, expect: refused, error: GOAL_OUTSIDE_ZONE}
  - command: 'forward 0.5 m'
  - cmd_vel: {vx: 0.2, duration_s: 1.0}
  - wait: {duration_s: 2.0}
  criteria:
    max_duration_s: 60
    max_localization_error_m: 0.2
  authorised_zone: [[0.1, 0.1], [9.9, 0.1], [9.9, 7.9], [0.1, 7.9]]
"""


@pytest.fixture
def judged(tmp_path):
    return load_scenario(write(tmp_path, JUDGED))


def good_record() -> RunRecord:
    """Return a run where everything went right: truth along y = 3.1 at 0.1 m/s, estimate on it."""
    times = np.arange(0.0, 50.1, 1.0)
    truth = np.column_stack([times, 2.0 + 0.1 * times, np.full_like(times, 3.1),
                             np.zeros_like(times)])
    estimate = truth[::5].copy()
    estimate[:, 2] += 0.05
    return RunRecord(
        truth=truth, estimate=estimate, collision_times=[],
        step_results=[
            StepResult('goal', 'reached', 0, '', 0.0, 31.2),
            StepResult('goal', 'refused', 9100, 'goal (3.50, 6.30) is outside the '
                       'authorised zone', 31.2, 31.3),
            StepResult('command', 'done', 0, '', 31.3, 34.0),
            StepResult('cmd_vel', 'done', 0, '', 34.0, 35.0),
            StepResult('wait', 'done', 0, '', 35.0, 37.0)],
        duration_s=37.0, aborted=None)


def details(verdict):
    return {c.name: c.detail for c in verdict.criteria}


def test_a_good_run_passes_with_one_line_per_step_and_criterion(judged):
    verdict = judge(judged, good_record())
    assert verdict.verdict == 'pass' and verdict.as_expected
    assert verdict.first_failure is None
    assert [c.name for c in verdict.criteria] == [
        'step 1', 'step 2', 'step 3', 'step 4', 'step 5', 'completed', 'max_duration_s',
        'no_collision', 'stay_in_zone', 'max_localization_error_m']
    assert all(c.passed for c in verdict.criteria)
    assert details(verdict) == {
        'step 1': 'step 1 goal (5.10, 6.20): reached in 31.2 s',
        'step 2': 'step 2 goal (3.50, 6.30): refused with GOAL_OUTSIDE_ZONE (9100): goal '
                  '(3.50, 6.30) is outside the authorised zone, as expected',
        'step 3': "step 3 command 'forward 0.5 m': done in 2.7 s",
        'step 4': 'step 4 cmd_vel (0.20, 0.00, 0.00) for 1.0 s: done in 1.0 s',
        'step 5': 'step 5 wait 2.0 s: done in 2.0 s',
        'completed': 'completed: all 5 steps run in 37.0 s',
        'max_duration_s': 'max_duration_s: 37.0 s <= 60 s',
        # The last pose, (7.0, 3.1), is hypot(0.075, 0.275) = 0.285 m from chair_3's
        # corner (7.075, 2.825): 0.285 - 0.2 m.
        'no_collision': 'no_collision: 0 collisions; least footprint clearance 0.085 m to '
                        'chair_3 at t=50.0 s (7.00, 3.10)',
        # The first pose is 1.9 m from x = 0.1 (the others farther): 1.9 - 0.2 m.
        'stay_in_zone': 'stay_in_zone: least clearance 1.700 m at t=0.0 s (2.00, 3.10): the '
                        'footprint (radius 0.20 m) stayed inside at all 51 true poses',
        'max_localization_error_m': 'max_localization_error_m: 0.05 m <= 0.2 m (11 estimates)',
    }


def small_world(tmp_path):
    """Return a 4 m x 4 m room with a post (circle) and a person walking (a world file)."""
    world = tmp_path / 'small.yaml'
    world.write_text(textwrap.dedent("""
        world:
          bounds_m: [0.0, 0.0, 4.0, 4.0]
          furniture:
          - {name: post, circle: {center: [3.0, 3.0], radius_m: 0.25}}
          moving_obstacles:
          - {name: person, radius_m: 0.25, speed_m_s: 0.5, path: [[0.5, 3.5], [2.0, 3.5]]}
          robot_start: {x_m: 1.0, y_m: 1.0}
        """))
    return load_world(world)


def test_obstacle_clearances_by_hand(tmp_path):
    world = small_world(tmp_path)
    truth = [[0.0, 1.0, 1.0, 0.0],     # 1.0 m from the south and west bounds
             [1.0, 2.0, 2.0, 0.0],     # hypot(1, 1) - 0.25 = 1.164 m from the post's rim
             [2.0, 3.0, 2.2, 0.0],     # 0.8 - 0.25 = 0.55 m from the post's rim
             [3.0, 1.0, 2.9, 0.0]]     # the person at (1.0, 3.5): 0.6 - 0.25 = 0.35 m
    movers = [[2.0, 0, 0.5, 3.5], [4.0, 0, 1.5, 3.5]]   # at t = 3 s halfway: (1.0, 3.5)
    clearances = obstacle_clearances(world, truth, 0.2, movers)
    np.testing.assert_allclose(
        clearances, [0.8, math.hypot(1.0, 1.0) - 0.25 - 0.2, 0.55 - 0.2, 0.35 - 0.2],
        atol=1e-9)
    assert nearest_obstacles(world, truth, 0.2, movers)[1] == ['bounds', 'post', 'post',
                                                               'person']
    # Without the person recorded, the last pose is 1.0 m from the west bound.
    np.testing.assert_allclose(obstacle_clearances(world, truth, 0.2)[3], 1.0 - 0.2)


def test_each_criterion_says_how_close_the_run_came(judged):
    margins = {c.name: (c.margin, c.margin_unit) for c in judge(judged, good_record()).criteria}
    assert margins == {
        'step 1': (pytest.approx(90.0 - 31.2), 's'),      # its timeout_s 90
        'step 2': (pytest.approx(120.0 - 0.1), 's'),      # the default 120 s
        'step 3': (pytest.approx(margins['step 3'][0]), 's'),
        'step 4': (None, ''), 'step 5': (None, ''), 'completed': (None, ''),
        'max_duration_s': (pytest.approx(60.0 - 37.0), 's'),
        'no_collision': (pytest.approx(0.085, abs=5e-4), 'm'),
        'stay_in_zone': (pytest.approx(1.7), 'm'),
        'max_localization_error_m': (pytest.approx(0.2 - 0.05), 'm')}
    step_3 = judged.steps[2]
    assert margins['step 3'][0] == pytest.approx(step_3.timeout_s - 2.7)
    # Failed: at most 0; a timeout says how late.
    record = good_record()
    record.step_results[0] = StepResult('goal', 'timeout', 0, '', 0.0, 92.5)
    record.estimate[:, 2] += 0.25   # 0.3 m off
    verdict = judge(judged, record)
    lines = {c.name: c for c in verdict.criteria}
    assert lines['step 1'].margin == pytest.approx(-2.5)
    assert lines['max_localization_error_m'].margin == pytest.approx(-0.1)
    record.step_results[0] = StepResult('goal', 'failed', 9104, 'stuck', 0.0, 20.0)
    assert {c.name: c for c in judge(judged, record).criteria}['step 1'].margin is None


def test_a_collision_fails_the_run(judged):
    record = good_record()
    record.collision_times = [20.5, 12.5]
    verdict = judge(judged, record)
    assert verdict.verdict == 'fail' and not verdict.as_expected
    assert verdict.first_failure.name == 'no_collision'
    assert verdict.first_failure.detail == (
        'no_collision: 2 collisions, first at t=12.5 s; least footprint clearance 0.085 m to '
        'chair_3 at t=50.0 s (7.00, 3.10)')
    # A collision: the margin is at most 0 whatever the recorded poses say.
    assert verdict.first_failure.margin == 0.0


def test_leaving_the_zone_fails_the_run_and_says_where(judged):
    record = good_record()
    record.truth = np.vstack([record.truth, [[12.3, 10.02, 3.1, 0.0]]])
    verdict = judge(judged, record)
    assert verdict.verdict == 'fail'
    # 0.12 m beyond x = 9.9: -0.12 - 0.2 = -0.32 m.
    assert verdict.first_failure.detail == (
        'stay_in_zone: least clearance -0.320 m at t=12.3 s (10.02, 3.10): the footprint '
        '(radius 0.20 m) left the zone')


def test_no_ground_truth_fails_stay_in_zone_and_no_zone_passes(tmp_path, judged):
    record = good_record()
    record.truth = np.zeros((0, 4))
    failed = {c.name: c for c in judge(judged, record).criteria if not c.passed}
    assert failed['stay_in_zone'].detail == 'stay_in_zone: no ground truth recorded'
    assert 'no estimate' in failed['max_localization_error_m'].detail
    unzoned = load_scenario(write(tmp_path, MINIMAL + '  authorised_zone: []\n', 'nz.yaml'))
    record = RunRecord(step_results=[StepResult('goal', 'reached', 0, '', 0, 5)],
                       duration_s=5.0)
    verdict = judge(unzoned, record)
    assert verdict.verdict == 'pass'
    assert details(verdict)['stay_in_zone'] == 'stay_in_zone: no zone declared'


@pytest.mark.parametrize('outcome, code, message, passed, detail', [
    ('refused', 9100, '', True,
     'step 2 goal (3.50, 6.30): refused with GOAL_OUTSIDE_ZONE (9100), as expected'),
    ('failed', 9100, '', True,
     'step 2 goal (3.50, 6.30): failed with GOAL_OUTSIDE_ZONE (9100), as expected'),
    ('refused', 9101, 'in an obstacle', False,
     'step 2 goal (3.50, 6.30): refused with GOAL_IN_OBSTACLE (9101): in an obstacle '
     '(expected refused with GOAL_OUTSIDE_ZONE (9100))'),
    ('reached', 0, '', False,
     'step 2 goal (3.50, 6.30): reached in 0.1 s (expected refused with GOAL_OUTSIDE_ZONE '
     '(9100))'),
    ('timeout', 0, '', False,
     'step 2 goal (3.50, 6.30): timeout after 0.1 s (expected refused with '
     'GOAL_OUTSIDE_ZONE (9100))'),
])
def test_a_goal_expected_refused(judged, outcome, code, message, passed, detail):
    record = good_record()
    record.step_results[1] = StepResult('goal', outcome, code, message, 31.2, 31.3)
    verdict = judge(judged, record)
    step = verdict.criteria[1]
    assert (step.passed, step.detail) == (passed, detail)
    assert verdict.verdict == ('pass' if passed else 'fail')


def test_refused_without_an_error_name_takes_any_nonzero_code(tmp_path):
    scenario = load_scenario(write(tmp_path, MINIMAL.replace(
        '{x: 5.1, y: 6.2}', '{x: 5.1, y: 6.2, expect: refused}')))
    for code, passed in ((9103, True), (9000, True), (0, False)):
        record = RunRecord(step_results=[StepResult('goal', 'failed', code, '', 0.0, 1.0)],
                           duration_s=1.0)
        assert judge(scenario, record).criteria[0].passed is passed, code
    record = RunRecord(step_results=[StepResult('goal', 'failed', 12345, 'odd', 0.0, 1.0)],
                       duration_s=1.0)
    assert judge(scenario, record).criteria[0].detail == (
        'step 1 goal (5.10, 6.20): failed with error 12345: odd, as expected')


def test_expect_any_accepts_every_outcome(tmp_path):
    scenario = load_scenario(write(tmp_path, MINIMAL.replace(
        '{x: 5.1, y: 6.2}', '{x: 5.1, y: 6.2, expect: any}')))
    truth = [[0.0, 2.95, 2.0, 0.0], [4.0, 3.5, 2.0, 0.0]]
    for outcome, code in (('reached', 0), ('timeout', 0), ('failed', 9104)):
        record = RunRecord(truth=truth, duration_s=4.0,
                           step_results=[StepResult('goal', outcome, code, '', 0.0, 4.0)])
        assert judge(scenario, record).verdict == 'pass', outcome
    record = RunRecord(duration_s=0.0)
    assert judge(scenario, record).criteria[0].detail == (
        'step 1 goal (5.10, 6.20): not run (no result recorded)')


def test_a_timeout_fails_the_step_and_a_must_fail_scenario_is_as_expected(tmp_path):
    scenario = load_scenario(write(tmp_path, MINIMAL + '  expect: fail\n'))
    record = RunRecord(step_results=[StepResult('goal', 'timeout', 0, '', 10.0, 100.0)],
                       duration_s=90.0)
    verdict = judge(scenario, record)
    assert verdict.verdict == 'fail' and verdict.expected == 'fail' and verdict.as_expected
    assert verdict.first_failure.detail == (
        'step 1 goal (5.10, 6.20): timeout after 90.0 s (expected reached)')


def test_a_failed_goal_names_the_error(judged):
    record = good_record()
    record.step_results[0] = StepResult('goal', 'failed', 9103, 'no path to the goal', 0.0,
                                        4.0)
    assert judge(judged, record).first_failure.detail == (
        'step 1 goal (5.10, 6.20): failed with NO_VALID_PATH (9103): no path to the goal '
        '(expected reached)')


def test_an_aborted_run_fails_with_the_reason_and_the_steps_not_run(judged):
    record = good_record()
    record.step_results = record.step_results[:2]
    record.aborted = 'a node crashed: navigator'
    verdict = judge(judged, record)
    assert verdict.verdict == 'fail'
    lines = details(verdict)
    assert lines['step 3'] == ("step 3 command 'forward 0.5 m': not run (run aborted: "
                               'a node crashed: navigator)')
    assert not verdict.criteria[2].passed and verdict.criteria[1].passed
    assert lines['completed'] == ('completed: aborted after 2 of 5 steps: a node crashed: '
                                  'navigator')
    record.aborted = None
    assert details(judge(judged, record))['completed'] == (
        'completed: only 2 of 5 steps have a result')


def test_command_and_step_kind_problems_fail(judged):
    record = good_record()
    record.step_results[2] = StepResult('command', 'rejected', 0, 'speed too high', 31.3,
                                        31.3)
    record.step_results[3] = StepResult('wait', 'done', 0, '', 34.0, 35.0)
    failed = [c.detail for c in judge(judged, record).criteria if not c.passed]
    assert failed == [
        "step 3 command 'forward 0.5 m': rejected in 0.0 s: speed too high (expected done)",
        'step 4 cmd_vel (0.20, 0.00, 0.00) for 1.0 s: the result recorded is for a wait step']


def test_too_long_a_run_fails_max_duration(judged):
    record = good_record()
    record.duration_s = 61.5
    assert judge(judged, record).first_failure.detail == 'max_duration_s: 61.5 s > 60 s'


def test_localization_error_is_measured_against_interpolated_truth(judged):
    record = good_record()
    # Truth at t = 2 and 3 is x = 2.2 and 2.3 (y = 3.1): at t = 2.5 it is (2.25, 3.1).
    # An estimate (2.25, 3.4) is 0.3 m off; against the nearest sample it would be more.
    record.estimate = np.array([[2.5, 2.25, 3.4, 0.0], [3.0, 2.3, 3.2, 0.0]])
    verdict = judge(judged, record)
    assert verdict.first_failure.detail == (
        'max_localization_error_m: 0.30 m at t=2.5 s > 0.2 m')
    errors = localization_errors(record.truth, record.estimate)
    np.testing.assert_allclose(errors, [[2.5, 0.3], [3.0, 0.1]], atol=1e-12)


def test_localization_errors_skip_estimates_outside_the_truth_and_bad_rows():
    truth = [[0.0, 0.0, 0.0, 0.0], [10.0, 10.0, 0.0, 0.0], [5.0, 5.0, float('nan'), 0.0]]
    estimate = [[-1.0, 0.0, 0.0, 0.0], [4.0, 4.0, 0.4, 0.0], [11.0, 0.0, 0.0, 0.0]]
    np.testing.assert_allclose(localization_errors(truth, estimate), [[4.0, 0.4]])
    assert localization_errors([], estimate).shape == (0, 2)
    with pytest.raises(ValueError, match=r'truth must be an \(N, 4\) array'):
        localization_errors(np.zeros((3, 3)), estimate)
    # Sorted by time, non-finite rows dropped.
    np.testing.assert_array_equal(track_array(truth)[:, 0], [0.0, 10.0])


# --- stay_in_zone: the footprint, and the least clearance ------------------------------
# clearance = signed distance from the centre to the zone's border (> 0 inside) minus the
# footprint radius (motor_params.yaml: 0.2 m); the criterion fails below 0.
SQUARE = make_zone([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
#: An L: the square 0..4 without its upper right quarter; (2, 2) is its concave corner.
ELL = make_zone([[0.0, 0.0], [4.0, 0.0], [4.0, 2.0], [2.0, 2.0], [2.0, 4.0], [0.0, 4.0]])


def zoned(tmp_path, zone):
    """Return MINIMAL (one goal) with zone as its authorised zone and only stay_in_zone."""
    scenario = load_scenario(write(tmp_path, MINIMAL, 'zoned.yaml'))
    return dataclasses.replace(scenario, authorised_zone=zone, criteria=Criteria(
        no_collision=False, stay_in_zone=True))


def zone_record(points):
    """Return a reached goal with a truth track through points (x, y), one a second."""
    truth = np.array([[float(t), x, y, 0.0] for t, (x, y) in enumerate(points)])
    return RunRecord(truth=truth, step_results=[StepResult('goal', 'reached', 0, '', 0.0, 5.0)],
                     duration_s=5.0)


def zone_line(verdict):
    return next(c for c in verdict.criteria if c.name == 'stay_in_zone')


def test_stay_in_zone_fails_when_the_footprint_leaves_the_zone_with_its_centre_inside(
        tmp_path):
    assert ROBOT.footprint_radius_m == 0.2   # the hand-worked numbers below use it
    scenario = zoned(tmp_path, SQUARE)
    # Centres 2.0, 1.0, 0.1, 0.1 m from the border x = 4 (y = 2 or 2.5: 1.5 m or more
    # from the others): clearances 1.8, 0.8, -0.1, -0.1 m; the least first at t = 2.
    verdict = judge(scenario, zone_record([(2.0, 2.0), (3.0, 2.0), (3.9, 2.0), (3.9, 2.5)]))
    line = zone_line(verdict)
    assert verdict.verdict == 'fail' and not line.passed
    assert line.min_clearance_m == pytest.approx(-0.1)
    assert (line.t_s, line.x_m, line.y_m) == (2.0, 3.9, 2.0)
    assert line.footprint_radius_m == 0.2
    assert line.detail == ('stay_in_zone: least clearance -0.100 m at t=2.0 s (3.90, 2.00): '
                           'the footprint (radius 0.20 m) left the zone')


def test_stay_in_zone_passes_with_the_footprint_inside_and_reports_the_least_clearance(
        tmp_path):
    scenario = zoned(tmp_path, SQUARE)
    # 0.3 m from x = 4: clearance 0.3 - 0.2 = 0.1 m.
    verdict = judge(scenario, zone_record([(2.0, 2.0), (3.0, 2.0), (3.7, 2.0), (3.7, 2.5)]))
    line = zone_line(verdict)
    assert verdict.verdict == 'pass' and line.passed
    assert line.min_clearance_m == pytest.approx(0.1)
    assert line.detail == ('stay_in_zone: least clearance 0.100 m at t=2.0 s (3.70, 2.00): '
                           'the footprint (radius 0.20 m) stayed inside at all 4 true poses')


def test_the_footprint_radius_comes_from_the_robot_unless_given(tmp_path):
    scenario = zoned(tmp_path, SQUARE)
    record = zone_record([(3.9, 2.0)])
    assert zone_line(judge(scenario, record)).passed is False
    # A 0.05 m radius fits in the 0.1 m left: clearance 0.05 m.
    line = zone_line(judge(scenario, record, footprint_radius_m=0.05))
    assert line.passed and line.min_clearance_m == pytest.approx(0.05)
    # Exactly on the border (clearance 0): inside, no tolerance either way.
    line = zone_line(judge(scenario, zone_record([(3.75, 2.0)]), footprint_radius_m=0.25))
    assert line.passed and line.min_clearance_m == 0.0
    for bad in (-0.1, math.nan, math.inf):
        with pytest.raises(ValueError, match='footprint_radius_m'):
            judge(scenario, record, footprint_radius_m=bad)


def test_stay_in_zone_near_a_concave_corner_measures_to_the_corner(tmp_path):
    scenario = zoned(tmp_path, ELL)
    # (1.85, 1.85) is 0.15 m from both lines x = 2 and y = 2, but the border there is
    # the corner (2, 2), 0.15 * sqrt(2) = 0.2121 m away: clearance 0.0121 m, inside.
    # (1, 1) and (1, 3) are 1 m from the border: 0.8 m.
    line = zone_line(judge(scenario, zone_record([(1.0, 1.0), (1.85, 1.85), (1.0, 3.0)])))
    assert line.passed
    assert line.min_clearance_m == pytest.approx(0.15 * math.sqrt(2.0) - 0.2)
    assert (line.t_s, line.x_m, line.y_m) == (1.0, 1.85, 1.85)
    # (1.9, 1.9): 0.1 * sqrt(2) = 0.1414 m from the corner: -0.0586 m, the footprint is out.
    line = zone_line(judge(scenario, zone_record([(1.0, 1.0), (1.9, 1.9), (1.0, 3.0)])))
    assert not line.passed
    assert line.min_clearance_m == pytest.approx(0.1 * math.sqrt(2.0) - 0.2)
    # In the bottom arm, 0.1 m below the edge y = 2 (x 2..4): -0.1 m.
    line = zone_line(judge(scenario, zone_record([(3.0, 1.0), (3.0, 1.9)])))
    assert not line.passed and line.min_clearance_m == pytest.approx(-0.1)


def test_the_first_exit_is_named_when_the_least_clearance_comes_later(tmp_path):
    scenario = zoned(tmp_path, SQUARE)
    # Out at t = 1 (-0.05 m), deeper at t = 2 (-0.15 m), back in at t = 3.
    line = zone_line(judge(scenario, zone_record([(2.0, 2.0), (3.85, 2.0), (3.95, 2.0),
                                                  (3.0, 2.0)])))
    assert line.min_clearance_m == pytest.approx(-0.15)
    assert line.detail == ('stay_in_zone: least clearance -0.150 m at t=2.0 s (3.95, 2.00): '
                           'the footprint (radius 0.20 m) left the zone, first at t=1.0 s '
                           '(3.85, 2.00)')


def test_no_zone_or_no_truth_gives_no_clearance(tmp_path):
    scenario = zoned(tmp_path, None)
    line = zone_line(judge(scenario, zone_record([(3.9, 2.0)])))
    assert line.passed and line.detail == 'stay_in_zone: no zone declared'
    assert line.min_clearance_m is None and min_zone_clearance_m(judge(
        scenario, zone_record([(3.9, 2.0)]))) is None
    line = zone_line(judge(zoned(tmp_path, SQUARE), zone_record([])))
    assert not line.passed and line.min_clearance_m is None
    # Disabled: no line, no clearance; enabled: the verdict carries the number.
    disabled = dataclasses.replace(zoned(tmp_path, SQUARE), criteria=Criteria(
        no_collision=False, stay_in_zone=False))
    assert min_zone_clearance_m(judge(disabled, zone_record([(3.9, 2.0)]))) is None
    assert min_zone_clearance_m(judge(zoned(tmp_path, SQUARE), zone_record(
        [(3.9, 2.0)]))) == pytest.approx(-0.1)


def test_footprint_clearances_are_vectorised():
    clearances = footprint_clearances(SQUARE, [[0.0, 2.0, 2.0, 0.0], [1.0, 4.5, 2.0, 0.0]],
                                      0.2)
    np.testing.assert_allclose(clearances, [1.8, -0.7])
    assert footprint_clearances(SQUARE, np.zeros((0, 4)), 0.2).shape == (0,)


# --- the shipped scenarios -----------------------------------------------------------

EXPECTED_FILES = {
    'kitchen_run', 'bedroom_and_back', 'strafe_behind_bed', 'goal_outside_zone_refused',
    'goal_in_wall_refused', 'pushed_into_wall', 'must_fail_timeout', 'slippery_floor',
    'text_commands', 'apartment_tour', 'nav2_waypoints'}
#: Goals nearer than 0.3 m to furniture (each more than the 0.2 m footprint radius): the
#: strip behind the bed is 0.6 m wide; the tour also stops by the hallway console and
#: the armchair. Every other goal has at least 0.3 m.
NARROW_GOALS = {('strafe_behind_bed', 0): 0.25, ('strafe_behind_bed', 1): 0.25,
                ('apartment_tour', 0): 0.25, ('apartment_tour', 1): 0.25,
                ('apartment_tour', 4): 0.24, ('apartment_tour', 8): 0.25}
CLEARANCE_M = 0.3


@pytest.fixture(scope='module')
def shipped():
    return [load_scenario(path) for path in find_scenarios(SCENARIOS)]


def test_every_shipped_scenario_is_valid_and_named_after_its_file(shipped):
    assert len(shipped) >= 8
    assert {s.name for s in shipped} >= EXPECTED_FILES
    for scenario in shipped:
        assert scenario.name == scenario.source.stem
        assert scenario.world_file == find_world('apartment')
        assert scenario.real_time_factor == 1.0


def test_shipped_spawns_and_goals_are_where_they_must_be(shipped):
    for scenario in shipped:
        world = scenario.world
        x, y, _ = scenario.spawn
        assert world.is_free(x, y, clearance_m=CLEARANCE_M), scenario.name
        assert scenario.initial_pose == scenario.spawn
        goal_index = 0
        for step in scenario.steps:
            if isinstance(step, WaypointsStep):
                for x, y, _ in step.poses:   # every waypoint is to be reached
                    assert world.is_free(x, y, clearance_m=0.25), (scenario.name, x, y)
                    assert scenario.authorised_zone.footprint_inside(
                        x, y, ROBOT.footprint_radius_m), (scenario.name, x, y)
            if not isinstance(step, GoalStep):
                continue
            where = f'{scenario.name} {step.describe()}'
            in_zone = scenario.authorised_zone.footprint_inside(
                step.x, step.y, ROBOT.footprint_radius_m)
            if step.expect in ('reached', 'any'):   # any: reachable, a fault may stop it
                clearance = NARROW_GOALS.get((scenario.name, goal_index), CLEARANCE_M)
                assert world.is_free(step.x, step.y, clearance_m=clearance), where
                assert in_zone, where
            elif step.error == 'GOAL_OUTSIDE_ZONE':
                assert world.is_free(step.x, step.y, clearance_m=CLEARANCE_M), where
                assert not in_zone, where
            elif step.error == 'GOAL_IN_OBSTACLE':
                name, distance = world.nearest_obstacle(step.x, step.y)
                assert (world.obstacle_at(step.x, step.y) is not None
                        or distance < ROBOT.footprint_radius_m), where
            else:
                pytest.fail(f'{where}: unexpected expectation {step.expect} {step.error}')
            goal_index += 1


def test_the_narrow_goals_fit_the_footprint(shipped):
    behind_bed = next(s for s in shipped if s.name == 'strafe_behind_bed')
    for index, goal in enumerate(behind_bed.goals):
        _, distance = behind_bed.world.nearest_obstacle(goal.x, goal.y)
        assert NARROW_GOALS[('strafe_behind_bed', index)] <= distance
        assert distance > ROBOT.footprint_radius_m
    assert behind_bed.goals[1].y > 7.4  # north of the bed's box (y 5.8..7.4)


def integrate(pose, vx, vy, wz, duration_s, dt=0.01):
    """Return the poses of a constant body twist held for duration_s (Euler, small dt)."""
    x, y, yaw = pose
    poses = [(x, y, yaw)]
    for _ in range(int(round(duration_s / dt))):
        x += (vx * math.cos(yaw) - vy * math.sin(yaw)) * dt
        y += (vx * math.sin(yaw) + vy * math.cos(yaw)) * dt
        yaw += wz * dt
        poses.append((x, y, yaw))
    return poses


def open_loop_poses(scenario):
    """Return the nominal poses of the command and cmd_vel steps from the spawn."""
    poses = [scenario.spawn]
    for step in scenario.steps:
        if isinstance(step, CommandStep):
            motion = step.motion
            poses += integrate(poses[-1], motion.vx, motion.vy, motion.wz, motion.duration_s)
        elif isinstance(step, CmdVelStep):
            poses += integrate(poses[-1], step.vx, step.vy, step.wz, step.duration_s)
    return poses


def test_text_commands_stay_in_open_space_away_from_the_person(shipped):
    scenario = next(s for s in shipped if s.name == 'text_commands')
    poses = open_loop_poses(scenario)
    assert len(poses) > 100
    person = scenario.world.moving_obstacles[0]
    loop = list(person.path) + [person.path[0]]
    for x, y, _ in poses:
        assert scenario.world.is_free(x, y, clearance_m=CLEARANCE_M), (x, y)
        assert scenario.world.in_test_zone(x, y)
        for (x1, y1), (x2, y2) in zip(loop, loop[1:]):
            t = np.clip(((x - x1) * (x2 - x1) + (y - y1) * (y2 - y1))
                        / ((x2 - x1) ** 2 + (y2 - y1) ** 2), 0.0, 1.0)
            distance = math.hypot(x1 + t * (x2 - x1) - x, y1 + t * (y2 - y1) - y)
            assert distance > person.radius_m + ROBOT.footprint_radius_m + 0.1, (x, y)
    # The comment's nominal end pose: (3.53, 1.22), yaw 0.
    x, y, yaw = poses[-1]
    assert (x, y) == pytest.approx((3.53, 1.22), abs=0.01)
    assert math.cos(yaw) == pytest.approx(1.0, abs=1e-3)
    kinds = {step.motion.name for step in scenario.steps}
    assert {'forward', 'strafe right', 'strafe left', 'rotate left', 'rotate right',
            'diagonal backward-right', 'stop'} <= kinds


def test_pushed_into_wall_really_drives_into_the_wall(shipped):
    # Without the command chain, the twist would hit the wall; the chain must stop it.
    scenario = next(s for s in shipped if s.name == 'pushed_into_wall')
    assert scenario.expect == 'pass' and scenario.criteria.no_collision
    poses = open_loop_poses(scenario)
    hits = [(x, y) for x, y, _ in poses
            if scenario.world.nearest_obstacle(x, y)[1] < ROBOT.footprint_radius_m]
    assert hits, 'the twist never brings the footprint onto an obstacle'
    assert scenario.world.nearest_obstacle(*hits[0])[0] == 'living_east_s'


def test_must_fail_timeout_cannot_be_reached_in_time(shipped):
    scenario = next(s for s in shipped if s.name == 'must_fail_timeout')
    (goal,) = scenario.goals
    assert scenario.expect == 'fail'
    distance = math.dist(scenario.spawn[:2], (goal.x, goal.y))
    assert distance / ROBOT.max_velocity_x_m_s > goal.timeout_s


def test_kitchen_run_crosses_the_kitchen_door_where_the_person_walks(shipped):
    scenario = next(s for s in shipped if s.name == 'kitchen_run')
    sides = [goal.x > 6.0 for goal in scenario.goals]
    assert scenario.spawn[0] < 6.0 and sides == [True, False]
    person = scenario.world.moving_obstacles[0]
    times = np.arange(0.0, person.lap_length_m / person.speed_m_s, 0.05)
    crossings = [person.position_at(t)[1] for t in times
                 if abs(person.position_at(t)[0] - 6.0) < 0.05]
    assert crossings and all(2.8 < y < 3.8 for y in crossings)


def test_slippery_floor_and_must_fail_expectations(shipped):
    by_name = {s.name: s for s in shipped}
    slippery = by_name['slippery_floor']
    assert slippery.floor_friction_coefficient == 0.2
    assert slippery.criteria.max_localization_error_m == 0.25
    assert {s.name for s in shipped if s.expect == 'fail'} == {'must_fail_timeout'}
